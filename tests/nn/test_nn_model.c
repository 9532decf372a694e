/* Architecture presets/JSON, model init, safetensors round trip (bit-exact), and rejection
 * of malformed model files: every mutation must fail with KPCN_ERR_FORMAT and a message
 * naming the tensor or field, never crash or leak a half-built model. */
#include "kpcn/nn.h"
#include "testutil.h"

#include <cjson/cJSON.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

typedef struct blob {
  unsigned char *p;
  size_t n;
} blob;

static blob slurp(const char *path) {
  blob b = {0, 0};
  FILE *f = fopen(path, "rb");
  if (!f) return b;
  fseek(f, 0, SEEK_END);
  b.n = (size_t)ftell(f);
  rewind(f);
  b.p = malloc(b.n ? b.n : 1);
  if (fread(b.p, 1, b.n, f) != b.n) b.n = 0;
  fclose(f);
  return b;
}

static void spit(const char *path, const void *p, size_t n) {
  FILE *f = fopen(path, "wb");
  fwrite(p, 1, n, f);
  fclose(f);
}

/* Writes header json (with an explicit declared length) followed by data bytes. */
static void write_st(const char *path, uint64_t declared, const char *json, const void *data,
                     size_t dn) {
  FILE *f = fopen(path, "wb");
  unsigned char l8[8];
  for (int i = 0; i < 8; i++)
    l8[i] = (unsigned char)(declared >> (8 * i));
  fwrite(l8, 1, 8, f);
  fwrite(json, 1, strlen(json), f);
  fwrite(data, 1, dn, f);
  fclose(f);
}

static uint64_t hlen(const blob *b) {
  uint64_t h = 0;
  for (int i = 0; i < 8; i++)
    h |= (uint64_t)b->p[i] << (8 * i);
  return h;
}

/* Loads `path`, expects KPCN_ERR_FORMAT whose message contains `needle`. */
static void expect_reject(const char *what, const char *path, const char *needle) {
  kpcn_model *m = (kpcn_model *)(uintptr_t)1;
  kpcn_status s = kpcn_model_load(path, &m);
  const char *msg = kpcn_last_error();
  int named = needle == NULL || strstr(msg, needle) != NULL;
  printf("%-28s -> %s: %s\n", what, kpcn_status_string(s), msg);
  CHECK(s == KPCN_ERR_FORMAT);
  CHECK(m == NULL);
  CHECK(named);
}

/* Loads `path`, expects a model. */
static void expect_load(const char *what, const char *path) {
  kpcn_model *m = NULL;
  kpcn_status s = kpcn_model_load(path, &m);
  printf("%-28s -> %s%s%s\n", what, kpcn_status_string(s), s == KPCN_OK ? "" : ": ",
         s == KPCN_OK ? "" : kpcn_last_error());
  CHECK(s == KPCN_OK);
  CHECK(m != NULL);
  kpcn_model_destroy(m);
}

typedef void (*mutate_fn)(cJSON *h);
static void m_dtype(cJSON *h) {
  cJSON *t = cJSON_GetObjectItem(h, "specular.conv1.weight");
  cJSON_ReplaceItemInObject(t, "dtype", cJSON_CreateString("F16"));
}
static void m_shape(cJSON *h) {
  cJSON *t = cJSON_GetObjectItem(h, "diffuse.conv0.weight");
  int sh[4] = {8, 4, 3, 5};
  cJSON_ReplaceItemInObject(t, "shape", cJSON_CreateIntArray(sh, 4));
}
static void m_missing(cJSON *h) { cJSON_DeleteItemFromObject(h, "diffuse.conv2.bias"); }
static void m_extra(cJSON *h) {
  cJSON *t = cJSON_Duplicate(cJSON_GetObjectItem(h, "diffuse.conv2.bias"), 1);
  cJSON_AddItemToObject(h, "diffuse.conv9.bias", t);
}
static void set_offsets(cJSON *h, const char *name, double b, double e) {
  cJSON *t = cJSON_GetObjectItem(h, name);
  cJSON *o = cJSON_CreateArray();
  cJSON_AddItemToArray(o, cJSON_CreateNumber(b));
  cJSON_AddItemToArray(o, cJSON_CreateNumber(e));
  cJSON_ReplaceItemInObject(t, "data_offsets", o);
}
static double off0(cJSON *h, const char *name, int i) {
  return cJSON_GetArrayItem(cJSON_GetObjectItem(cJSON_GetObjectItem(h, name), "data_offsets"), i)
      ->valuedouble;
}
static void m_overlap(cJSON *h) { /* bias of conv0 points into the weight before it */
  double e = off0(h, "diffuse.conv0.bias", 1), b = off0(h, "diffuse.conv0.bias", 0);
  set_offsets(h, "diffuse.conv0.bias", b - 8, e - 8);
}
static void m_outofrange(cJSON *h) {
  double n = off0(h, "specular.conv2.bias", 1) - off0(h, "specular.conv2.bias", 0);
  set_offsets(h, "specular.conv2.bias", 1e12, 1e12 + n);
}
static void m_negative(cJSON *h) { set_offsets(h, "specular.conv0.bias", -32, 0); }
static void m_span(cJSON *h) { /* end before begin */
  set_offsets(h, "specular.conv0.bias", off0(h, "specular.conv0.bias", 1),
              off0(h, "specular.conv0.bias", 0));
}
/* The architecture in the header claims `channels` hidden channels. */
static void set_arch_channels(cJSON *h, int channels) {
  cJSON *meta = cJSON_GetObjectItem(h, "__metadata__");
  cJSON *a = cJSON_Parse(cJSON_GetObjectItem(meta, "kpcn.architecture")->valuestring);
  cJSON_ReplaceItemInObject(a, "channels", cJSON_CreateNumber(channels));
  char *s = cJSON_PrintUnformatted(a);
  cJSON_ReplaceItemInObject(meta, "kpcn.architecture", cJSON_CreateString(s));
  free(s);
  cJSON_Delete(a);
}
static void m_arch_channels(cJSON *h) { set_arch_channels(h, 9); }
static void m_arch_bad(cJSON *h) {
  cJSON *meta = cJSON_GetObjectItem(h, "__metadata__");
  cJSON_ReplaceItemInObject(meta, "kpcn.architecture", cJSON_CreateString("{\"n_hidden\": [}"));
}
static void m_arch_k(cJSON *h) {
  cJSON *meta = cJSON_GetObjectItem(h, "__metadata__");
  cJSON *a = cJSON_Parse(cJSON_GetObjectItem(meta, "kpcn.architecture")->valuestring);
  cJSON_ReplaceItemInObject(a, "kernel_size", cJSON_CreateNumber(4));
  char *s = cJSON_PrintUnformatted(a);
  cJSON_ReplaceItemInObject(meta, "kpcn.architecture", cJSON_CreateString(s));
  free(s);
  cJSON_Delete(a);
}
/* sets "key": <the JSON text v> in the stored architecture (replaced if present) */
static void arch_set_raw(cJSON *h, const char *key, const char *v) {
  cJSON *meta = cJSON_GetObjectItem(h, "__metadata__");
  cJSON *a = cJSON_Parse(cJSON_GetObjectItem(meta, "kpcn.architecture")->valuestring);
  if (cJSON_GetObjectItem(a, key))
    cJSON_ReplaceItemInObject(a, key, cJSON_Parse(v));
  else
    cJSON_AddItemToObject(a, key, cJSON_Parse(v));
  char *s = cJSON_PrintUnformatted(a);
  cJSON_ReplaceItemInObject(meta, "kpcn.architecture", cJSON_CreateString(s));
  free(s);
  cJSON_Delete(a);
}
static void arch_add(cJSON *h, const char *key, double v) {
  char num[32];
  snprintf(num, sizeof num, "%.17g", v);
  arch_set_raw(h, key, num);
}
static void m_arch_passes(cJSON *h) { arch_add(h, "kpa_passes", 0); }
/* eps 0 in both places the file records it (they must agree): refused as an architecture that
 * would divide by zero at albedo 0, not as a disagreement */
static void m_eps_zero(cJSON *h) {
  arch_set_raw(h, "eps", "0");
  cJSON_ReplaceItemInObject(cJSON_GetObjectItem(h, "__metadata__"), "kpcn.eps",
                            cJSON_CreateString("0"));
}
static void m_exp_zero(cJSON *h) { arch_set_raw(h, "exposure", "0"); }
static void m_exp_neg(cJSON *h) { arch_set_raw(h, "exposure", "-1"); }
static void m_exp_arr(cJSON *h) { arch_set_raw(h, "exposure", "[1]"); }
static void m_exp_str(cJSON *h) { arch_set_raw(h, "exposure", "\"a\""); }
static void m_arch_sw2(cJSON *h) { arch_add(h, "source_weight", 2); }
/* a source score channel the tensors do not have */
static void m_arch_sw1(cJSON *h) { arch_add(h, "source_weight", 1); }
static void m_inputs(cJSON *h) {
  cJSON *meta = cJSON_GetObjectItem(h, "__metadata__");
  cJSON_ReplaceItemInObject(meta, "kpcn.inputs", cJSON_CreateString("[\"R\",\"G\"]"));
}
static void m_nometa(cJSON *h) { cJSON_DeleteItemFromObject(h, "__metadata__"); }
static void m_format(cJSON *h) {
  cJSON *meta = cJSON_GetObjectItem(h, "__metadata__");
  cJSON_ReplaceItemInObject(meta, "kpcn.format", cJSON_CreateString("kpcn-model-999"));
}
static void m_meta_number(cJSON *h) {
  cJSON_AddNumberToObject(cJSON_GetObjectItem(h, "__metadata__"), "user", 3);
}

/* The architecture claims 1024 channels: the file's few weights cannot be them, and the loader
 * must say so before it allocates the 78 MB such a model would take. */
static void m_huge_arch(cJSON *h) { set_arch_channels(h, 1024); }

/* A key given twice in __metadata__ (cJSON finds the first copy, the user entries would keep
 * the last): refused, with the same value as much as with another. */
static void m_dup_format(cJSON *h) {
  cJSON_AddStringToObject(cJSON_GetObjectItem(h, "__metadata__"), "kpcn.format", "kpcn-model-1");
}
static void m_dup_user(cJSON *h) {
  cJSON_AddStringToObject(cJSON_GetObjectItem(h, "__metadata__"), "train.iterations", "9");
}
/* a second __metadata__ object (the loader reads the first; the second would be ignored) */
static void m_dup_meta(cJSON *h) {
  cJSON_AddItemToObject(h, "__metadata__",
                        cJSON_Duplicate(cJSON_GetObjectItem(h, "__metadata__"), 1));
}
/* replaces metadata string `key` with its value followed by `tail` */
static void meta_append(cJSON *h, const char *key, const char *tail) {
  cJSON *meta = cJSON_GetObjectItem(h, "__metadata__");
  const char *v = cJSON_GetObjectItem(meta, key)->valuestring;
  char *nv = malloc(strlen(v) + strlen(tail) + 1);
  strcpy(nv, v);
  strcat(nv, tail);
  cJSON_ReplaceItemInObject(meta, key, cJSON_CreateString(nv));
  free(nv);
}
static void m_arch_trailing(cJSON *h) { meta_append(h, "kpcn.architecture", " {\"x\":1}"); }
static void m_inputs_trailing(cJSON *h) { meta_append(h, "kpcn.inputs", "]"); }
static void m_meta_empty_key(cJSON *h) {
  cJSON_AddStringToObject(cJSON_GetObjectItem(h, "__metadata__"), "", "x");
}
/* 1e-60 is > 0 as a double but 0 as a float: "not recorded" if it were stored */
static void m_exp_tiny(cJSON *h) { arch_set_raw(h, "exposure", "1e-60"); }
static void m_exp_huge(cJSON *h) { arch_set_raw(h, "exposure", "1e31"); }
/* user metadata entries added until __metadata__ holds meta_fill_to entries */
static int meta_fill_to;
static void m_meta_fill(cJSON *h) {
  cJSON *meta = cJSON_GetObjectItem(h, "__metadata__");
  char key[32];
  for (int i = cJSON_GetArraySize(meta); i < meta_fill_to; i++) {
    snprintf(key, sizeof key, "user.k%d", i);
    cJSON_AddStringToObject(meta, key, "v");
  }
}

/* Writes good's file with its header passed through fn (when not NULL) and `after` appended
 * to the header JSON (the declared length counts it); returns the path. */
static const char *write_mutated(const blob *good, mutate_fn fn, const char *after) {
  uint64_t hl = hlen(good);
  char *txt = malloc(hl + 1);
  memcpy(txt, good->p + 8, hl);
  txt[hl] = 0;
  cJSON *h = cJSON_Parse(txt);
  free(txt);
  if (fn) fn(h);
  char *js = cJSON_PrintUnformatted(h);
  cJSON_Delete(h);
  const size_t jl = strlen(js), al = strlen(after);
  char *full = malloc(jl + al + 1);
  memcpy(full, js, jl);
  memcpy(full + jl, after, al + 1);
  free(js);
  const char *path = kt_tmpfile("mut.safetensors");
  write_st(path, jl + al, full, good->p + 8 + hl, good->n - 8 - hl);
  free(full);
  return path;
}

static void mutated(const blob *good, const char *what, mutate_fn fn, const char *needle) {
  expect_reject(what, write_mutated(good, fn, ""), needle);
}

static kpcn_model *tiny_model(uint64_t seed) {
  kpcn_arch a;
  kpcn_arch_preset("tiny", &a);
  const char *names[4] = {"color.R", "color.G", "color.B", "color.var"};
  kpcn_arch_set_inputs(&a, 4, names);
  kpcn_model *m = NULL;
  CHECK(kpcn_model_create(&a, seed, &m) == KPCN_OK);
  return m;
}

static void test_arch(void) {
  kpcn_arch a, b;
  CHECK(kpcn_arch_preset("paper", &a) == KPCN_OK);
  CHECK(a.n_hidden == 9 && a.channels == 100 && a.conv_size[0] == 5 && a.kernel_size == 21);
  CHECK(kpcn_arch_conv_radius(&a) == 20);
  const char *names[3] = {"a", "b", "c"};
  CHECK(kpcn_arch_validate(&a) == KPCN_ERR_INVALID_ARGUMENT); /* no inputs yet */
  CHECK(strstr(kpcn_last_error(), "n_inputs") != NULL);
  CHECK(kpcn_arch_set_inputs(&a, 3, names) == KPCN_OK);
  CHECK(kpcn_arch_validate(&a) == KPCN_OK);
  /* paper FLOPs per pixel per branch: 2*(3*100*25 + 8*100*100*25 + 100*441*25) */
  CHECK_NEAR(kpcn_arch_flops_per_pixel(&a), 2.0 * (3 * 2500 + 8 * 250000 + 100 * 441 * 25), 0.5);
  CHECK(kpcn_arch_param_count(&a) ==
        (size_t)(3 * 100 * 25 + 100) + 8 * (100 * 100 * 25 + 100) + (100 * 441 * 25 + 441));
  char *js = kpcn_arch_to_json(&a);
  CHECK(js && kpcn_arch_from_json(js, &b) == KPCN_OK);
  CHECK(memcmp(&a, &b, sizeof a) == 0);
  free(js);
  CHECK(kpcn_arch_preset("cpu", &a) == KPCN_OK);
  CHECK(kpcn_arch_conv_radius(&a) == 22);
  a.conv_size[2] = 4;
  kpcn_arch_set_inputs(&a, 3, names);
  CHECK(kpcn_arch_validate(&a) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(strstr(kpcn_last_error(), "conv_size[2]") != NULL);
  const char *dup[2] = {"x", "x"};
  kpcn_arch_preset("cpu", &a);
  kpcn_arch_set_inputs(&a, 2, dup);
  CHECK(kpcn_arch_validate(&a) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(kpcn_arch_preset("huge", &a) == KPCN_ERR_INVALID_ARGUMENT);
  /* kpa_passes: 1 in presets and absent from their JSON (files written before the field
   * keep loading as one pass); 2 round-trips; the receptive radius grows by K/2 a pass */
  kpcn_arch_preset("cpu", &a);
  kpcn_arch_set_inputs(&a, 3, names);
  CHECK(a.kpa_passes == 1 && kpcn_arch_receptive_radius(&a) == 22);
  js = kpcn_arch_to_json(&a);
  CHECK(js && !strstr(js, "kpa_passes"));
  free(js);
  a.kpa_passes = 2;
  CHECK(kpcn_arch_receptive_radius(&a) == 27); /* conv 22 + one K/2 of the first pass */
  js = kpcn_arch_to_json(&a);
  CHECK(js && strstr(js, "\"kpa_passes\":2") && kpcn_arch_from_json(js, &b) == KPCN_OK);
  CHECK(memcmp(&a, &b, sizeof a) == 0);
  free(js);
  a.kpa_passes = KPCN_NN_MAX_KPA_PASSES + 1;
  CHECK(kpcn_arch_validate(&a) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(strstr(kpcn_last_error(), "kpa_passes") != NULL);
  /* source_weight: absent from the JSON when 0; 1 round-trips, adds an output channel and
   * K/2 to the radius (scores are read where the first pass reads); 2 is rejected */
  kpcn_arch_preset("cpu", &a);
  kpcn_arch_set_inputs(&a, 3, names);
  const size_t params1 = kpcn_arch_param_count(&a);
  a.source_weight = 1;
  CHECK(kpcn_arch_layer_out(&a, a.n_hidden) == 122 && kpcn_arch_logit_channels(&a) == 122);
  CHECK(kpcn_arch_param_count(&a) == params1 + 48 * 9 + 1);
  CHECK(kpcn_arch_receptive_radius(&a) == 27);
  a.kpa_passes = 2;
  CHECK(kpcn_arch_receptive_radius(&a) == 32);
  js = kpcn_arch_to_json(&a);
  CHECK(js && strstr(js, "\"source_weight\":1") && kpcn_arch_from_json(js, &b) == KPCN_OK);
  CHECK(memcmp(&a, &b, sizeof a) == 0);
  free(js);
  a.source_weight = 2;
  CHECK(kpcn_arch_validate(&a) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(strstr(kpcn_last_error(), "source_weight") != NULL);
  /* exposure: absent when not recorded; recorded, it round-trips exactly */
  a.source_weight = 0;
  CHECK(kpcn_arch_validate(&a) == KPCN_OK);
  js = kpcn_arch_to_json(&a);
  CHECK(js && !strstr(js, "exposure"));
  free(js);
  a.exposure = 0.0123456789f;
  js = kpcn_arch_to_json(&a);
  CHECK(js && strstr(js, "\"exposure\":") && kpcn_arch_from_json(js, &b) == KPCN_OK);
  CHECK(memcmp(&a, &b, sizeof a) == 0);
  free(js);
  a.exposure = -1.0f;
  CHECK(kpcn_arch_validate(&a) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(strstr(kpcn_last_error(), "exposure") != NULL);
  kpcn_arch_preset("tiny", &a); /* conv radius 3 */
  kpcn_arch_set_inputs(&a, 3, names);
  a.kpa_passes = 3;
  CHECK(kpcn_arch_receptive_radius(&a) == 7); /* logits 2 + 2 from the output: 3 + 4 */
  a.kernel_size = 9;                          /* K/2 = 4 > 3: the noisy reads decide, 3 x 4 */
  CHECK(kpcn_arch_receptive_radius(&a) == 12);
  CHECK(kpcn_arch_from_json("{}", &a) == KPCN_ERR_FORMAT);
  CHECK(kpcn_arch_from_json("nope", &a) == KPCN_ERR_FORMAT);
  /* no architecture, no description; a branch out of range has no tensor name (the names
   * table has two entries: before the check it was read past its end) */
  CHECK(kpcn_arch_to_json(NULL) == NULL);
  char tn[64];
  kpcn_model_tensor_name(tn, sizeof tn, KPCN_BRANCH_SPECULAR, 2, 1);
  CHECK(!strcmp(tn, "specular.conv2.bias"));
  const int bad_branch[2] = {5, -1};
  for (int i = 0; i < 2; i++) {
    strcpy(tn, "unchanged");
    kpcn_model_tensor_name(tn, sizeof tn, (kpcn_branch)bad_branch[i], 0, 0);
    if (tn[0]) fprintf(stderr, "tensor name of branch %d: '%s', expected ''\n", bad_branch[i], tn);
    CHECK(tn[0] == 0);
  }
}

static void test_init(void) {
  kpcn_model *m1 = tiny_model(42), *m2 = tiny_model(42), *m3 = tiny_model(43);
  kpcn_layer_view v1, v2, v3;
  kpcn_model_layer(m1, KPCN_BRANCH_SPECULAR, 1, &v1);
  kpcn_model_layer(m2, KPCN_BRANCH_SPECULAR, 1, &v2);
  kpcn_model_layer(m3, KPCN_BRANCH_SPECULAR, 1, &v3);
  size_t n = (size_t)v1.out_ch * v1.in_ch * v1.size * v1.size;
  CHECK(memcmp(v1.weight, v2.weight, n * 4) == 0);
  CHECK(memcmp(v1.weight, v3.weight, n * 4) != 0);
  /* Glorot uniform: |w| <= sqrt(6/(fan_in+fan_out)), variance lim²/3 */
  double lim = sqrt(6.0 / ((v1.in_ch + v1.out_ch) * 9.0)), s2 = 0, mx = 0;
  for (size_t i = 0; i < n; i++) {
    s2 += (double)v1.weight[i] * v1.weight[i];
    mx = fabs(v1.weight[i]) > mx ? fabs(v1.weight[i]) : mx;
  }
  CHECK(mx <= lim);
  CHECK_CLOSE(s2 / n, lim * lim / 3, 0.35, 0);
  CHECK(kpcn_model_layer(m1, KPCN_BRANCH_DIFFUSE, 3, &v1) == KPCN_ERR_INVALID_ARGUMENT);
  kpcn_model_destroy(m1), kpcn_model_destroy(m2), kpcn_model_destroy(m3);
}

static void test_roundtrip(blob *good) {
  kpcn_model *m = tiny_model(7);
  kpcn_arch a = *kpcn_model_arch(m);
  /* non-trivial biases so they are part of the bit-exact comparison */
  for (int b = 0; b < 2; b++)
    for (int l = 0; l <= a.n_hidden; l++) {
      kpcn_layer_view v;
      kpcn_model_layer(m, (kpcn_branch)b, l, &v);
      for (int i = 0; i < v.out_ch; i++)
        v.bias[i] = (float)(i + 1) / 3.0f * (b ? -1.f : 1.f);
    }
  CHECK(kpcn_model_set_meta(m, "train.iterations", "1200") == KPCN_OK);
  CHECK(kpcn_model_set_meta(m, "kpcn.bad", "x") == KPCN_ERR_INVALID_ARGUMENT);
  const char *path = kt_tmpfile("good.safetensors");
  CHECK(kpcn_model_save(m, path) == KPCN_OK);
  kpcn_model *r = NULL;
  CHECK(kpcn_model_load(path, &r) == KPCN_OK);
  if (r) {
    CHECK(memcmp(kpcn_model_arch(r), &a, sizeof a) == 0);
    for (int b = 0; b < 2; b++)
      for (int l = 0; l <= a.n_hidden; l++) {
        kpcn_layer_view v, w;
        kpcn_model_layer(m, (kpcn_branch)b, l, &v);
        kpcn_model_layer(r, (kpcn_branch)b, l, &w);
        CHECK(memcmp(v.weight, w.weight, (size_t)v.out_ch * v.in_ch * v.size * v.size * 4) == 0);
        CHECK(memcmp(v.bias, w.bias, (size_t)v.out_ch * 4) == 0);
      }
    CHECK(kpcn_model_get_meta(r, "train.iterations") &&
          !strcmp(kpcn_model_get_meta(r, "train.iterations"), "1200"));
    kpcn_model_destroy(r);
  }
  /* a two-pass model saves and loads as one */
  CHECK(kpcn_model_set_kpa_passes(m, 0) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(kpcn_model_set_kpa_passes(m, 2) == KPCN_OK);
  const char *p2 = kt_tmpfile("two-pass.safetensors");
  CHECK(kpcn_model_save(m, p2) == KPCN_OK);
  CHECK(kpcn_model_load(p2, &r) == KPCN_OK);
  if (r) {
    CHECK(kpcn_model_arch(r)->kpa_passes == 2);
    kpcn_model_destroy(r);
  }
  CHECK(kpcn_model_set_kpa_passes(m, 1) == KPCN_OK);
  /* a source score channel added: old tensors are prefixes, the new row and bias are zero,
   * and the model saves and loads with it */
  kpcn_model *sw = NULL;
  CHECK(kpcn_model_add_source_weight(m, &sw) == KPCN_OK);
  if (sw) {
    const kpcn_arch *as = kpcn_model_arch(sw);
    const int L = as->n_hidden, K2 = as->kernel_size * as->kernel_size;
    kpcn_layer_view vo, vn;
    kpcn_model_layer(m, KPCN_BRANCH_SPECULAR, L, &vo);
    kpcn_model_layer(sw, KPCN_BRANCH_SPECULAR, L, &vn);
    const size_t row = (size_t)vo.in_ch * vo.size * vo.size;
    CHECK(as->source_weight == 1 && vn.out_ch == K2 + 1 && vo.out_ch == K2);
    CHECK(memcmp(vo.weight, vn.weight, sizeof(float) * row * K2) == 0);
    CHECK(memcmp(vo.bias, vn.bias, sizeof(float) * K2) == 0);
    int nz = vn.bias[K2] != 0.f;
    for (size_t i = 0; i < row; i++)
      nz += vn.weight[row * K2 + i] != 0.f;
    CHECK(nz == 0);
    vn.bias[K2] = 0.25f;
    const char *p3 = kt_tmpfile("source-weight.safetensors");
    CHECK(kpcn_model_save(sw, p3) == KPCN_OK);
    CHECK(kpcn_model_load(p3, &r) == KPCN_OK);
    if (r) {
      kpcn_layer_view vr;
      kpcn_model_layer(r, KPCN_BRANCH_SPECULAR, L, &vr);
      CHECK(kpcn_model_arch(r)->source_weight == 1 && vr.bias[K2] == 0.25f);
      kpcn_model_destroy(r);
    }
    kpcn_model_destroy(sw);
  }
  *good = slurp(path);
  CHECK(good->n > 8 && hlen(good) % 8 == 0);
  /* independent check of the layout: data section size = 4 bytes x parameter count x 2 */
  CHECK(good->n - 8 - hlen(good) == 4 * 2 * kpcn_arch_param_count(&a));
  kpcn_model_destroy(m);
  CHECK(kpcn_model_load(kt_tmpfile("does-not-exist.safetensors"), &r) == KPCN_ERR_IO);
}

/* kpcn_model_load_memory on a file's bytes: the same model as kpcn_model_load, bit for bit;
 * damaged bytes refused as the file reader refuses them, naming "(memory)" */
static void test_memory(const blob *good) {
  const char *path = kt_tmpfile("mem.safetensors");
  spit(path, good->p, good->n);
  kpcn_model *f = NULL, *m = NULL;
  CHECK(kpcn_model_load(path, &f) == KPCN_OK);
  CHECK(kpcn_model_load_memory(good->p, good->n, &m) == KPCN_OK);
  if (f && m) {
    const kpcn_arch *a = kpcn_model_arch(f);
    CHECK(memcmp(a, kpcn_model_arch(m), sizeof *a) == 0);
    for (int b = 0; b < 2; b++)
      for (int l = 0; l <= a->n_hidden; l++) {
        kpcn_layer_view v, w;
        kpcn_model_layer(f, (kpcn_branch)b, l, &v);
        kpcn_model_layer(m, (kpcn_branch)b, l, &w);
        CHECK(memcmp(v.weight, w.weight, (size_t)v.out_ch * v.in_ch * v.size * v.size * 4) == 0);
        CHECK(memcmp(v.bias, w.bias, (size_t)v.out_ch * 4) == 0);
      }
  }
  kpcn_model_destroy(f);
  kpcn_model_destroy(m);
  m = (kpcn_model *)(uintptr_t)1;
  CHECK(kpcn_model_load_memory(good->p, good->n - 10, &m) == KPCN_ERR_FORMAT && !m);
  CHECK(strstr(kpcn_last_error(), "(memory)") != NULL);
  CHECK(kpcn_model_load_memory(good->p, 5, &m) == KPCN_ERR_FORMAT);
  CHECK(kpcn_model_load_memory(NULL, 100, &m) == KPCN_ERR_INVALID_ARGUMENT);
}

static void test_malformed(const blob *good) {
  const char *p = kt_tmpfile("bad.safetensors");
  uint64_t hl = hlen(good);
  spit(p, good->p, good->n - 10);
  expect_reject("truncated data", p, "bytes");
  spit(p, good->p, 8 + hl / 2);
  expect_reject("truncated header", p, "header length");
  spit(p, good->p, 5);
  expect_reject("shorter than 8 bytes", p, "too short");
  blob b = {malloc(good->n), good->n};
  memcpy(b.p, good->p, good->n);
  for (int i = 0; i < 8; i++)
    b.p[i] = (unsigned char)(((uint64_t)1 << 62) >> (8 * i));
  spit(p, b.p, b.n);
  expect_reject("huge header length", p, "header length");
  for (int i = 0; i < 8; i++)
    b.p[i] = 0;
  spit(p, b.p, b.n);
  expect_reject("zero header length", p, "header length");
  /* NaN in a weight */
  memcpy(b.p, good->p, good->n);
  float nan = NAN;
  memcpy(b.p + 8 + hl + 12, &nan, 4);
  spit(p, b.p, b.n);
  expect_reject("NaN weight", p, "not finite");
  free(b.p);
  /* extra trailing data not covered by any tensor */
  unsigned char *ext = malloc(good->n + 16);
  memcpy(ext, good->p, good->n);
  memset(ext + good->n, 0, 16);
  spit(p, ext, good->n + 16);
  free(ext);
  expect_reject("trailing bytes", p, "cover");
  write_st(p, 24, "this is not json at all!", good->p + 8 + hl, good->n - 8 - hl);
  expect_reject("non-JSON header", p, "JSON");
  write_st(p, 8, "[1,2,3] ", good->p + 8 + hl, good->n - 8 - hl);
  expect_reject("JSON array header", p, "JSON object");
  mutated(good, "wrong dtype", m_dtype, "specular.conv1.weight");
  mutated(good, "architecture beyond the data", m_huge_arch, "the architecture's F32 weights need");
  mutated(good, "shape mismatch", m_shape, "diffuse.conv0.weight");
  mutated(good, "missing tensor", m_missing, "diffuse.conv2.bias");
  mutated(good, "unknown tensor", m_extra, "diffuse.conv9.bias");
  mutated(good, "overlapping offsets", m_overlap, "overlaps");
  mutated(good, "offsets out of range", m_outofrange, "specular.conv2.bias");
  mutated(good, "negative offset", m_negative, "specular.conv0.bias");
  mutated(good, "end before begin", m_span, "specular.conv0.bias");
  mutated(good, "arch channels vs shapes", m_arch_channels, "shape");
  mutated(good, "arch not JSON", m_arch_bad, "architecture");
  mutated(good, "arch even K", m_arch_k, "kernel_size");
  mutated(good, "arch kpa_passes 0", m_arch_passes, "kpa_passes");
  mutated(good, "arch source_weight 2", m_arch_sw2, "source_weight");
  mutated(good, "arch exposure 0", m_exp_zero, "exposure");
  mutated(good, "arch eps 0", m_eps_zero, "arch.eps = 0 not in (0, 1)");
  mutated(good, "arch exposure -1", m_exp_neg, "exposure");
  mutated(good, "arch exposure [1]", m_exp_arr, "exposure");
  mutated(good, "arch exposure \"a\"", m_exp_str, "exposure");
  mutated(good, "arch source_weight vs shapes", m_arch_sw1, "shape");
  mutated(good, "inputs disagree", m_inputs, "kpcn.inputs");
  mutated(good, "no __metadata__", m_nometa, "__metadata__");
  mutated(good, "unknown format version", m_format, "kpcn.format");
  mutated(good, "non-string metadata", m_meta_number, "user");
  mutated(good, "kpcn.format twice", m_dup_format, "key 'kpcn.format' appears twice");
  mutated(good, "user metadata key twice", m_dup_user, "key 'train.iterations' appears twice");
  mutated(good, "__metadata__ twice", m_dup_meta, "__metadata__ appears twice");
  mutated(good, "arch with text after it", m_arch_trailing, "kpcn.architecture");
  mutated(good, "inputs with text after them", m_inputs_trailing, "kpcn.inputs");
  mutated(good, "empty metadata key", m_meta_empty_key, "empty key");
  mutated(good, "arch exposure 1e-60", m_exp_tiny, "exposure");
  mutated(good, "arch exposure 1e31", m_exp_huge, "exposure");
  /* the header JSON is followed by the padding to 8 bytes (spaces) and nothing else */
  expect_load("header + 13 spaces", write_mutated(good, NULL, "             "));
  expect_reject("text after the header", write_mutated(good, NULL, "  x     "), "text follows it");
  expect_reject("object after the header", write_mutated(good, NULL, "{}"), "text follows it");
  /* at most 4096 __metadata__ entries (kpcn.* and user ones together); a header of very many
   * is refused at once, not after storing each (each searched among the earlier ones) */
  meta_fill_to = 4096;
  expect_load("4096 metadata entries", write_mutated(good, m_meta_fill, ""));
  meta_fill_to = 4097;
  mutated(good, "4097 metadata entries", m_meta_fill, "more than 4096 entries");
  meta_fill_to = 30000;
  const char *many = write_mutated(good, m_meta_fill, "");
  struct timespec t0, t1;
  clock_gettime(CLOCK_MONOTONIC, &t0);
  expect_reject("30000 metadata entries", many, "more than 4096 entries");
  clock_gettime(CLOCK_MONOTONIC, &t1);
  const double sec = (double)(t1.tv_sec - t0.tv_sec) + 1e-9 * (double)(t1.tv_nsec - t0.tv_nsec);
  printf("30000 metadata entries refused in %.3f s\n", sec);
  CHECK(sec < 2.0);
  /* random byte corruption of the header: never a crash, a model only if still valid */
  unsigned rs = 2024;
  blob c = {malloc(good->n), good->n};
  int rejected = 0;
  for (int t = 0; t < 300; t++) {
    memcpy(c.p, good->p, good->n);
    for (int k = 0; k < 3; k++) {
      size_t i = (size_t)(kt_randf(&rs) * (double)(8 + hl)) % (8 + hl);
      c.p[i] = (unsigned char)(kt_randf(&rs) * 256);
    }
    spit(p, c.p, c.n);
    kpcn_model *m = NULL;
    kpcn_status s = kpcn_model_load(p, &m);
    if (s != KPCN_OK) rejected++;
    CHECK((s == KPCN_OK) == (m != NULL));
    CHECK(s == KPCN_OK || s == KPCN_ERR_FORMAT);
    kpcn_model_destroy(m);
  }
  printf("random header corruption: %d/300 rejected, none crashed\n", rejected);
  free(c.p);
}

/* cJSON's allocator for test_save_oom: fails allocation number oom_fail_at (counted from 1
 * since the last reset), every other one is malloc's. */
static long oom_count, oom_fail_at;
static void *oom_malloc(size_t n) {
  if (++oom_count == oom_fail_at) return NULL;
  return malloc(n);
}

/* kpcn_model_save with each of its cJSON allocations failing in turn (the last run has none
 * fail): it never reports success for a file that does not load, and a refused save leaves the
 * model already at the path as it was. The model writes every optional field (two passes, a
 * source weight, an exposure, user metadata). */
static void test_save_oom(void) {
  kpcn_model *m0 = tiny_model(21), *m = NULL;
  CHECK(kpcn_model_set_kpa_passes(m0, 2) == KPCN_OK);
  CHECK(kpcn_model_set_exposure(m0, 0.25f) == KPCN_OK);
  CHECK(kpcn_model_add_source_weight(m0, &m) == KPCN_OK);
  kpcn_model_destroy(m0);
  if (!m) return;
  CHECK(kpcn_model_set_meta(m, "train.iterations", "77") == KPCN_OK);
  CHECK(kpcn_model_set_meta(m, "train.dataset", "store.kpcnp") == KPCN_OK);
  /* another model already at the path */
  const char *path = kt_tmpfile("oom.safetensors");
  kpcn_model *other = tiny_model(22);
  CHECK(kpcn_model_save(other, path) == KPCN_OK);
  kpcn_model_destroy(other);
  blob before = slurp(path);
  CHECK(before.n > 8);
  cJSON_Hooks hooks = {oom_malloc, free};
  int refused = 0, saved = 0, bad = 0;
  long n;
  for (n = 1; n < 100000; n++) {
    oom_count = 0, oom_fail_at = n;
    cJSON_InitHooks(&hooks);
    kpcn_status s = kpcn_model_save(m, path);
    cJSON_InitHooks(NULL);
    const int injected = oom_count >= n;
    if (s != KPCN_OK) {
      refused++;
      blob now = slurp(path);
      const int same = now.n == before.n && memcmp(now.p, before.p, now.n) == 0;
      if (s != KPCN_ERR_OUT_OF_MEMORY || !same || !injected) {
        fprintf(stderr, "allocation %ld failing: kpcn_model_save: %s (%s)%s\n", n,
                kpcn_status_string(s), kpcn_last_error(),
                same ? "" : ", and the model at the path changed");
        bad++;
      }
      CHECK(s == KPCN_ERR_OUT_OF_MEMORY);
      CHECK(same);
      free(now.p);
      continue;
    }
    saved += injected;
    kpcn_model *r = NULL;
    s = kpcn_model_load(path, &r);
    if (s != KPCN_OK) {
      fprintf(stderr,
              "allocation %ld failing: kpcn_model_save said OK, the file does not load: %s\n", n,
              kpcn_last_error());
      bad++;
    }
    CHECK(s == KPCN_OK);
    if (r) {
      CHECK(memcmp(kpcn_model_arch(r), kpcn_model_arch(m), sizeof(kpcn_arch)) == 0);
      CHECK(kpcn_model_get_meta(r, "train.dataset") &&
            !strcmp(kpcn_model_get_meta(r, "train.dataset"), "store.kpcnp"));
      kpcn_model_destroy(r);
    }
    if (!injected) break; /* every allocation the save makes has been failed once */
    spit(path, before.p, before.n);
  }
  printf("save with cJSON allocation k of %ld failing: %d refused, %d saved (and loaded), %d bad\n",
         n - 1, refused, saved, bad);
  CHECK(n < 100000);
  CHECK(refused > 0);
  free(before.p);
  kpcn_model_destroy(m);
}

/* A model takes at most the user entries a model file can be loaded with (4096 less the six
 * kpcn.* keys): a model of more was saved with KPCN_OK and then refused by the loader. */
static void test_meta_cap(void) {
  kpcn_model *m = tiny_model(3);
  if (!m) return;
  char k[32];
  int ok = 1;
  for (int i = 0; i < 4090 && ok; i++) {
    snprintf(k, sizeof k, "u%d", i);
    ok = kpcn_model_set_meta(m, k, "v") == KPCN_OK;
  }
  CHECK(ok);
  CHECK(kpcn_model_set_meta(m, "one.more", "v") == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(strstr(kpcn_last_error(), "4090 user entries") != NULL);
  CHECK(kpcn_model_set_meta(m, "u7", "updated") == KPCN_OK); /* an existing key still changes */
  const char *path = kt_tmpfile("meta_cap.safetensors");
  CHECK(kpcn_model_save(m, path) == KPCN_OK);
  kpcn_model *r = NULL;
  CHECK(kpcn_model_load(path, &r) == KPCN_OK);
  CHECK(r && kpcn_model_get_meta(r, "u7") && !strcmp(kpcn_model_get_meta(r, "u7"), "updated"));
  kpcn_model_destroy(r);
  kpcn_model_destroy(m);
}

int main(void) {
  test_arch();
  test_meta_cap();
  test_init();
  blob good = {0, 0};
  test_roundtrip(&good);
  if (good.p) test_memory(&good);
  if (good.p) test_malformed(&good);
  test_save_oom();
  free(good.p);
  return kt_summary("test_nn_model");
}
