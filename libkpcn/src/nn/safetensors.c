/* Model file I/O in the safetensors format (DESIGN.md §5):
 *   u64 LE header length | JSON header | raw little-endian tensor bytes.
 * The header maps tensor names to {"dtype","shape","data_offsets"} (offsets relative to the
 * data section) and "__metadata__" to string key/values holding the architecture.
 * Loading trusts nothing: every length, offset, shape and value is checked before use. */
#define _POSIX_C_SOURCE 200809L
#define _FILE_OFFSET_BITS 64
#include "core/internal.h"
#include "nn/model_internal.h"

#include <cjson/cJSON.h>
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__
#error "kpcn model I/O assumes a little-endian host"
#endif

#define KPCN_MODEL_FORMAT "kpcn-model-1"
#define MAX_HEADER ((uint64_t)64 << 20)
#define MAX_META_ENTRIES KPCN_MODEL_MAX_META_ENTRIES /* user metadata plus the kpcn.* keys */

void kpcn_model_tensor_name(char *buf, size_t n, kpcn_branch b, int layer, int is_bias) {
  if ((unsigned)b >= KPCN_N_BRANCHES) { /* no name: an empty string */
    if (buf && n) buf[0] = 0;
    return;
  }
  snprintf(buf, n, "%s.conv%d.%s", kpcn_nn_branch_names[b], layer, is_bias ? "bias" : "weight");
}

/* Every cJSON call is checked: a header missing an entry (out of memory) would be written and
 * renamed over a good model, which then no longer loads. */
static kpcn_status build_header(const kpcn_model *m, char **out_json) {
  *out_json = NULL;
  const kpcn_arch *a = &m->arch;
  cJSON *h = cJSON_CreateObject();
  cJSON *meta = h ? cJSON_AddObjectToObject(h, "__metadata__") : NULL;
  char *arch = kpcn_arch_to_json(a);
  cJSON *inputs = cJSON_CreateArray();
  int ok = meta && arch && inputs;
  for (int i = 0; ok && i < a->n_inputs; i++) {
    cJSON *in = cJSON_CreateString(a->inputs[i]);
    ok = in && cJSON_AddItemToArray(inputs, in);
    if (!ok) cJSON_Delete(in);
  }
  char *inputs_s = ok ? cJSON_PrintUnformatted(inputs) : NULL;
  cJSON_Delete(inputs);
  char eps[32];
  snprintf(eps, sizeof eps, "%.9g", (double)a->eps);
  ok = ok && inputs_s && cJSON_AddStringToObject(meta, "kpcn.format", KPCN_MODEL_FORMAT) &&
       cJSON_AddStringToObject(meta, "kpcn.architecture", arch) &&
       cJSON_AddStringToObject(meta, "kpcn.inputs", inputs_s) &&
       cJSON_AddStringToObject(meta, "kpcn.eps", eps) &&
       cJSON_AddStringToObject(meta, "kpcn.preprocess", a->preprocess) &&
       cJSON_AddStringToObject(meta, "kpcn.version", KPCN_VERSION_STRING);
  for (int i = 0; ok && i < m->n_meta; i++)
    ok = cJSON_AddStringToObject(meta, m->meta_key[i], m->meta_val[i]) != NULL;
  free(arch);
  free(inputs_s);
  uint64_t off = 0;
  char name[64];
  for (int b = 0; ok && b < KPCN_N_BRANCHES; b++)
    for (int l = 0; ok && l <= a->n_hidden; l++)
      for (int isb = 0; ok && isb < 2; isb++) {
        kpcn_model_tensor_name(name, sizeof name, (kpcn_branch)b, l, isb);
        int k = a->conv_size[l];
        int shape[4] = {kpcn_arch_layer_out(a, l), kpcn_arch_layer_in(a, l), k, k};
        size_t n = isb ? (size_t)shape[0] : kpcn_model_weight_count(a, l);
        cJSON *t = cJSON_AddObjectToObject(h, name);
        cJSON *sh = cJSON_CreateIntArray(shape, isb ? 1 : 4);
        ok = t && cJSON_AddStringToObject(t, "dtype", "F32") && sh &&
             cJSON_AddItemToObject(t, "shape", sh);
        if (!ok) {
          cJSON_Delete(sh);
          break;
        }
        cJSON *offs = cJSON_AddArrayToObject(t, "data_offsets");
        cJSON *o0 = cJSON_CreateNumber((double)off);
        off += n * 4;
        cJSON *o1 = cJSON_CreateNumber((double)off);
        ok = offs && o0 && cJSON_AddItemToArray(offs, o0);
        if (!ok) cJSON_Delete(o0);
        ok = ok && o1 && cJSON_AddItemToArray(offs, o1);
        if (!ok) cJSON_Delete(o1);
      }
  if (ok) *out_json = cJSON_PrintUnformatted(h);
  cJSON_Delete(h);
  if (!*out_json)
    return kpcn_fail(KPCN_ERR_OUT_OF_MEMORY, "out of memory for the safetensors header");
  return KPCN_OK;
}

kpcn_status kpcn_model_save(const kpcn_model *m, const char *path) {
  if (!m || !path) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_model_save: NULL argument");
  char *json;
  KPCN_TRY(build_header(m, &json));
  size_t jl = strlen(json);
  size_t padded = (jl + 7) & ~(size_t)7; /* data starts 8-byte aligned, padded with spaces */
  char tmp[4096];
  if (kpcn_temp_path(tmp, sizeof tmp, path) != KPCN_OK) {
    free(json);
    return kpcn_last_status();
  }
  FILE *f = fopen(tmp, "wb");
  if (!f) {
    free(json);
    return kpcn_fail(KPCN_ERR_IO, "cannot write model '%s': %s", path, strerror(errno));
  }
  uint8_t len8[8];
  for (int i = 0; i < 8; i++)
    len8[i] = (uint8_t)((uint64_t)padded >> (8 * i));
  int ok = fwrite(len8, 1, 8, f) == 8 && fwrite(json, 1, jl, f) == jl;
  for (size_t i = jl; ok && i < padded; i++)
    ok = fputc(' ', f) != EOF;
  free(json);
  const kpcn_arch *a = &m->arch;
  for (int b = 0; ok && b < KPCN_N_BRANCHES; b++)
    for (int l = 0; ok && l <= a->n_hidden; l++) {
      size_t nw = kpcn_model_weight_count(a, l), nb = (size_t)kpcn_arch_layer_out(a, l);
      ok = fwrite(m->w[b][l], 4, nw, f) == nw && fwrite(m->b[b][l], 4, nb, f) == nb;
    }
  if (fclose(f) != 0) ok = 0;
  if (!ok) {
    kpcn_abort_file(tmp);
    return kpcn_fail(KPCN_ERR_IO, "writing model '%s' failed: %s", path, strerror(errno));
  }
  return kpcn_commit_file(tmp, path);
}

/* ------------------------------------------------------------------ load */

typedef struct entry {
  uint64_t begin, end;
  float *dst;
  size_t count;
  char name[64];
} entry;

static int cmp_entry(const void *x, const void *y) {
  const entry *a = x, *b = y;
  return a->begin < b->begin ? -1 : a->begin > b->begin;
}

static kpcn_status meta_string(const cJSON *meta, const char *key, const char **out) {
  const cJSON *it = cJSON_GetObjectItemCaseSensitive(meta, key);
  if (!cJSON_IsString(it) || !it->valuestring)
    return kpcn_fail(KPCN_ERR_FORMAT, "__metadata__.\"%s\": missing or not a string", key);
  *out = it->valuestring;
  return KPCN_OK;
}

/* Reads the architecture and user metadata; creates the (zeroed) model. */
static kpcn_status parse_meta(const cJSON *h, uint64_t data_size, kpcn_model **out) {
  const cJSON *meta = cJSON_GetObjectItemCaseSensitive(h, "__metadata__");
  if (!cJSON_IsObject(meta))
    return kpcn_fail(KPCN_ERR_FORMAT, "__metadata__: missing or not an object");
  /* Before anything is looked up: a key given twice (cJSON would find the first copy, the
   * user entries keep the last), an empty key, or so many entries that storing them (each
   * one searched for among the earlier ones) would take hours. */
  int nmeta = 0;
  for (const cJSON *it = meta->child; it; it = it->next) {
    if (++nmeta > MAX_META_ENTRIES)
      return kpcn_fail(KPCN_ERR_FORMAT, "__metadata__: more than %d entries", MAX_META_ENTRIES);
    if (!it->string || !it->string[0])
      return kpcn_fail(KPCN_ERR_FORMAT, "__metadata__: an entry has an empty key");
    for (const cJSON *p = meta->child; p != it; p = p->next)
      if (!strcmp(p->string, it->string))
        return kpcn_fail(KPCN_ERR_FORMAT, "__metadata__: key '%s' appears twice", it->string);
  }
  const char *fmt = NULL, *arch_s = NULL, *inputs_s = NULL, *eps_s = NULL, *pre_s = NULL;
  KPCN_TRY(meta_string(meta, "kpcn.format", &fmt));
  if (strcmp(fmt, KPCN_MODEL_FORMAT))
    return kpcn_fail(KPCN_ERR_FORMAT, "__metadata__.\"kpcn.format\" = '%s', expected '%s'", fmt,
                     KPCN_MODEL_FORMAT);
  KPCN_TRY(meta_string(meta, "kpcn.architecture", &arch_s));
  KPCN_TRY(meta_string(meta, "kpcn.inputs", &inputs_s));
  KPCN_TRY(meta_string(meta, "kpcn.eps", &eps_s));
  KPCN_TRY(meta_string(meta, "kpcn.preprocess", &pre_s));
  kpcn_arch a;
  if (kpcn_arch_from_json(arch_s, &a) != KPCN_OK) /* message already names the field */
    return kpcn_fail_context("__metadata__.\"kpcn.architecture\"");
  /* The redundant copies must agree with the architecture (catches hand edits). */
  cJSON *in = cJSON_ParseWithOpts(inputs_s, NULL, 1); /* nothing may follow the array */
  int ok = cJSON_IsArray(in) && cJSON_GetArraySize(in) == a.n_inputs;
  for (int i = 0; ok && i < a.n_inputs; i++) {
    const cJSON *it = cJSON_GetArrayItem(in, i);
    ok = cJSON_IsString(it) && !strcmp(it->valuestring, a.inputs[i]);
  }
  cJSON_Delete(in);
  if (!ok)
    return kpcn_fail(KPCN_ERR_FORMAT,
                     "__metadata__.\"kpcn.inputs\" disagrees with the architecture's input list");
  char *end;
  double eps = strtod(eps_s, &end);
  if (end == eps_s || *end || (float)eps != a.eps)
    return kpcn_fail(KPCN_ERR_FORMAT,
                     "__metadata__.\"kpcn.eps\" = '%s' disagrees with "
                     "architecture eps %.9g",
                     eps_s, (double)a.eps);
  if (strcmp(pre_s, a.preprocess))
    return kpcn_fail(KPCN_ERR_FORMAT,
                     "__metadata__.\"kpcn.preprocess\" = '%s' disagrees with "
                     "architecture '%s'",
                     pre_s, a.preprocess);
  /* Before allocating: a few-KB header must not make us commit the memory of a huge
   * architecture whose weights the file does not hold (the F32 tensors fill the data section
   * exactly). Small mismatches are left to load_tensors, whose message names the tensor. */
  const uint64_t need = (uint64_t)KPCN_N_BRANCHES * kpcn_arch_param_count(&a) * sizeof(float);
  if (need > data_size && need > ((uint64_t)64 << 20))
    return kpcn_fail(KPCN_ERR_FORMAT,
                     "data section has %llu bytes, the architecture's F32 weights need %llu",
                     (unsigned long long)data_size, (unsigned long long)need);
  kpcn_model *m;
  KPCN_TRY(kpcn_model_alloc(&a, &m));
  for (const cJSON *it = meta->child; it; it = it->next) {
    if (!cJSON_IsString(it) || !it->string) {
      kpcn_model_destroy(m);
      return kpcn_fail(KPCN_ERR_FORMAT, "__metadata__.\"%s\": value is not a string",
                       it->string ? it->string : "?");
    }
    if (!strncmp(it->string, "kpcn.", 5)) continue;
    kpcn_status s = kpcn_model_set_meta(m, it->string, it->valuestring);
    if (s != KPCN_OK) {
      kpcn_model_destroy(m);
      return s;
    }
  }
  *out = m;
  return KPCN_OK;
}

/* Checks one tensor entry of the header against the architecture. */
static kpcn_status check_tensor(const cJSON *t, const char *name, const int *shape, int rank,
                                uint64_t data_size, entry *e) {
  if (!cJSON_IsObject(t)) return kpcn_fail(KPCN_ERR_FORMAT, "tensor '%s' is missing", name);
  const cJSON *dt = cJSON_GetObjectItemCaseSensitive(t, "dtype");
  if (!cJSON_IsString(dt) || strcmp(dt->valuestring, "F32"))
    return kpcn_fail(KPCN_ERR_FORMAT, "tensor '%s': dtype %s, expected \"F32\"", name,
                     cJSON_IsString(dt) ? dt->valuestring : "(missing)");
  const cJSON *sh = cJSON_GetObjectItemCaseSensitive(t, "shape");
  int ok = cJSON_IsArray(sh) && cJSON_GetArraySize(sh) == rank;
  for (int i = 0; ok && i < rank; i++) {
    const cJSON *it = cJSON_GetArrayItem(sh, i);
    ok = cJSON_IsNumber(it) && it->valuedouble == (double)shape[i];
  }
  if (!ok) {
    char *got = sh ? cJSON_PrintUnformatted(sh) : NULL;
    char want[96];
    if (rank == 1)
      snprintf(want, sizeof want, "[%d]", shape[0]);
    else
      snprintf(want, sizeof want, "[%d,%d,%d,%d]", shape[0], shape[1], shape[2], shape[3]);
    kpcn_status s = kpcn_fail(KPCN_ERR_FORMAT, "tensor '%s': shape %s, architecture needs %s", name,
                              got ? got : "(missing)", want);
    free(got);
    return s;
  }
  const cJSON *of = cJSON_GetObjectItemCaseSensitive(t, "data_offsets");
  const cJSON *b = cJSON_IsArray(of) && cJSON_GetArraySize(of) == 2 ? of->child : NULL;
  const cJSON *en = b ? b->next : NULL;
  if (!cJSON_IsNumber(b) || !cJSON_IsNumber(en) || b->valuedouble < 0 || en->valuedouble < 0 ||
      b->valuedouble != floor(b->valuedouble) || en->valuedouble != floor(en->valuedouble) ||
      b->valuedouble > 9e15 || en->valuedouble > 9e15)
    return kpcn_fail(KPCN_ERR_FORMAT, "tensor '%s': data_offsets missing or not two integers",
                     name);
  e->begin = (uint64_t)b->valuedouble;
  e->end = (uint64_t)en->valuedouble;
  if (e->end < e->begin)
    return kpcn_fail(KPCN_ERR_FORMAT, "tensor '%s': data_offsets end %llu before begin %llu", name,
                     (unsigned long long)e->end, (unsigned long long)e->begin);
  if (e->end > data_size)
    return kpcn_fail(KPCN_ERR_FORMAT,
                     "tensor '%s': data_offsets [%llu, %llu] outside the data section (%llu bytes)",
                     name, (unsigned long long)e->begin, (unsigned long long)e->end,
                     (unsigned long long)data_size);
  if (e->end - e->begin != (uint64_t)e->count * 4)
    return kpcn_fail(KPCN_ERR_FORMAT, "tensor '%s': data_offsets span %llu bytes, shape needs %llu",
                     name, (unsigned long long)(e->end - e->begin),
                     (unsigned long long)e->count * 4);
  snprintf(e->name, sizeof e->name, "%s", name);
  return KPCN_OK;
}

static kpcn_status load_tensors(const cJSON *h, kpcn_model *m, FILE *f, uint64_t data_start,
                                uint64_t data_size) {
  const kpcn_arch *a = &m->arch;
  int nl = a->n_hidden + 1, ne = KPCN_N_BRANCHES * nl * 2;
  entry *es = kpcn_calloc((size_t)ne, sizeof *es, "tensor table");
  if (!es) return KPCN_ERR_OUT_OF_MEMORY;
  kpcn_status s = KPCN_OK;
  int i = 0;
  char name[64];
  for (int b = 0; s == KPCN_OK && b < KPCN_N_BRANCHES; b++)
    for (int l = 0; s == KPCN_OK && l < nl; l++)
      for (int isb = 0; s == KPCN_OK && isb < 2; isb++, i++) {
        kpcn_model_tensor_name(name, sizeof name, (kpcn_branch)b, l, isb);
        int k = a->conv_size[l];
        int shape[4] = {kpcn_arch_layer_out(a, l), kpcn_arch_layer_in(a, l), k, k};
        es[i].dst = isb ? m->b[b][l] : m->w[b][l];
        es[i].count = isb ? (size_t)shape[0] : kpcn_model_weight_count(a, l);
        s = check_tensor(cJSON_GetObjectItemCaseSensitive(h, name), name, shape, isb ? 1 : 4,
                         data_size, &es[i]);
      }
  /* Every key must be a known tensor or __metadata__ (no silently ignored weights). */
  int nkeys = 0;
  int nmeta = 0;
  for (const cJSON *it = h->child; s == KPCN_OK && it; it = it->next) {
    if (it->string && !strcmp(it->string, "__metadata__")) {
      /* parse_meta read the first; a second one would be ignored */
      if (++nmeta > 1) s = kpcn_fail(KPCN_ERR_FORMAT, "__metadata__ appears twice in the header");
      continue;
    }
    nkeys++;
    int known = 0;
    for (int j = 0; j < ne && !known; j++)
      known = it->string && !strcmp(it->string, es[j].name);
    if (!known)
      s = kpcn_fail(KPCN_ERR_FORMAT, "unexpected tensor '%s' (not in the architecture)",
                    it->string ? it->string : "?");
  }
  if (s == KPCN_OK && nkeys != ne)
    s = kpcn_fail(KPCN_ERR_FORMAT, "header lists %d tensors, architecture has %d (duplicate key?)",
                  nkeys, ne);
  if (s == KPCN_OK) {
    qsort(es, (size_t)ne, sizeof *es, cmp_entry);
    uint64_t pos = 0;
    for (int j = 0; s == KPCN_OK && j < ne; j++) {
      if (es[j].begin < pos)
        s = kpcn_fail(KPCN_ERR_FORMAT, "tensor '%s' overlaps the previous tensor '%s'", es[j].name,
                      es[j - 1].name);
      else if (es[j].begin > pos)
        s = kpcn_fail(KPCN_ERR_FORMAT, "gap of %llu bytes in the data section before tensor '%s'",
                      (unsigned long long)(es[j].begin - pos), es[j].name);
      pos = es[j].end;
    }
    if (s == KPCN_OK && pos != data_size)
      s = kpcn_fail(KPCN_ERR_FORMAT, "data section has %llu bytes, tensors cover %llu",
                    (unsigned long long)data_size, (unsigned long long)pos);
  }
  for (int j = 0; s == KPCN_OK && j < ne; j++) {
    if (fseeko(f, (off_t)(data_start + es[j].begin), SEEK_SET) != 0 ||
        fread(es[j].dst, 4, es[j].count, f) != es[j].count) {
      s = kpcn_fail(KPCN_ERR_FORMAT, "tensor '%s': cannot read its data (truncated file?)",
                    es[j].name);
      break;
    }
    for (size_t q = 0; q < es[j].count; q++)
      if (!isfinite(es[j].dst[q])) {
        s = kpcn_fail(KPCN_ERR_FORMAT, "tensor '%s': element %zu is not finite", es[j].name, q);
        break;
      }
  }
  free(es);
  return s;
}

static kpcn_status load_file(FILE *f, const char *path, kpcn_model **out) {
  if (fseeko(f, 0, SEEK_END) != 0) return kpcn_fail(KPCN_ERR_IO, "cannot seek in '%s'", path);
  off_t fsz = ftello(f);
  rewind(f);
  uint8_t len8[8];
  if (fsz < 8 || fread(len8, 1, 8, f) != 8)
    return kpcn_fail(KPCN_ERR_FORMAT, "'%s' is too short for a safetensors file (%lld bytes)", path,
                     (long long)fsz);
  uint64_t hl = 0;
  for (int i = 0; i < 8; i++)
    hl |= (uint64_t)len8[i] << (8 * i);
  if (hl < 2 || hl > MAX_HEADER || hl > (uint64_t)fsz - 8)
    return kpcn_fail(KPCN_ERR_FORMAT,
                     "'%s': header length %llu is impossible for a file of %lld bytes", path,
                     (unsigned long long)hl, (long long)fsz);
  char *txt = kpcn_alloc((size_t)hl + 1, "safetensors header");
  if (!txt) return KPCN_ERR_OUT_OF_MEMORY;
  if (fread(txt, 1, (size_t)hl, f) != (size_t)hl) {
    free(txt);
    return kpcn_fail(KPCN_ERR_FORMAT, "'%s': truncated header", path);
  }
  txt[hl] = 0;
  if (strlen(txt) != (size_t)hl) {
    free(txt);
    return kpcn_fail(KPCN_ERR_FORMAT, "'%s': NUL byte inside the JSON header", path);
  }
  const char *end = NULL;
  cJSON *h = cJSON_ParseWithOpts(txt, &end, 0);
  /* after the object only the padding to 8 bytes (spaces) may follow */
  int trailing = h && end && end[strspn(end, " \t\r\n")] != 0;
  free(txt);
  if (!cJSON_IsObject(h) || trailing) {
    cJSON_Delete(h);
    return kpcn_fail(KPCN_ERR_FORMAT, "'%s': header is not a JSON object%s", path,
                     trailing ? " (text follows it)" : "");
  }
  kpcn_model *m = NULL;
  kpcn_status s = parse_meta(h, (uint64_t)fsz - 8 - hl, &m);
  if (s == KPCN_OK) s = load_tensors(h, m, f, 8 + hl, (uint64_t)fsz - 8 - hl);
  cJSON_Delete(h);
  if (s != KPCN_OK) {
    kpcn_model_destroy(m);
    return kpcn_fail_context("model '%s'", path);
  }
  *out = m;
  return KPCN_OK;
}

kpcn_status kpcn_model_load_memory(const void *data, size_t size, kpcn_model **out) {
  if (!data || !out)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_model_load_memory: NULL argument");
  *out = NULL;
  if (size < 8)
    return kpcn_fail(KPCN_ERR_FORMAT,
                     "model in memory: %zu bytes is too short for a safetensors file", size);
  /* the file reader over the bytes (read-only: fmemopen never writes in "rb") */
  FILE *f = fmemopen((void *)data, size, "rb");
  if (!f) return kpcn_fail(KPCN_ERR_IO, "model in memory: fmemopen failed: %s", strerror(errno));
  kpcn_status s = load_file(f, "(memory)", out);
  fclose(f);
  return s;
}

kpcn_status kpcn_model_load(const char *path, kpcn_model **out) {
  if (!path || !out) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_model_load: NULL argument");
  *out = NULL;
  const char *why;
  FILE *f = kpcn_fopen_input(path, &why);
  if (!f) return kpcn_fail(KPCN_ERR_IO, "cannot open model '%s': %s", path, why);
  kpcn_status s = load_file(f, path, out);
  fclose(f);
  return s;
}
