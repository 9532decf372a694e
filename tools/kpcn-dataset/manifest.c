/* manifest.jsonl: one JSON object per line, one independent render job each, so the
 * same file drives `kpcn-dataset run`, a Slurm array (--shard $SLURM_ARRAY_TASK_ID/N)
 * or GNU parallel. */
#include "ds.h"

#include <cjson/cJSON.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

static const char *const g_kinds[] = {"preview", "noisy", "reference"};
const char *ds_kind_name(ds_kind k) { return g_kinds[k]; }

int ds_manifest_push(ds_manifest *m, const ds_job *j) {
  if (m->n == m->cap) {
    int cap = m->cap ? 2 * m->cap : 64;
    ds_job *n = realloc(m->jobs, sizeof *n * (size_t)cap);
    if (!n) return -1;
    m->jobs = n;
    m->cap = cap;
  }
  m->jobs[m->n++] = *j;
  return 0;
}

void ds_manifest_free(ds_manifest *m) {
  free(m->jobs);
  memset(m, 0, sizeof *m);
}

int ds_manifest_write(const char *dir, const ds_manifest *m) {
  size_t cap = 4096, len = 0;
  char *buf = malloc(cap);
  for (int i = 0; i < m->n; i++) {
    const ds_job *j = &m->jobs[i];
    cJSON *o = cJSON_CreateObject();
    cJSON_AddStringToObject(o, "id", j->id);
    cJSON_AddStringToObject(o, "kind", ds_kind_name(j->kind));
    cJSON_AddStringToObject(o, "scene", j->scene);
    cJSON_AddNumberToObject(o, "variant", j->variant);
    cJSON_AddStringToObject(o, "split", j->split);
    cJSON_AddStringToObject(o, "scene_file", j->scene_file);
    cJSON_AddNumberToObject(o, "spp", j->spp);
    char seed[32];
    snprintf(seed, sizeof seed, "%llu", (unsigned long long)j->seed);
    cJSON_AddStringToObject(o, "seed", seed); /* string: 64-bit exact */
    cJSON_AddNumberToObject(o, "width", j->width);
    cJSON_AddNumberToObject(o, "height", j->height);
    cJSON_AddStringToObject(o, "out", j->out);
    cJSON_AddStringToObject(o, "preview", j->preview);
    /* only when set, so manifests planned without it stay byte for byte what they were */
    if (j->albedo_footprint > 1)
      cJSON_AddNumberToObject(o, "albedo_footprint", j->albedo_footprint);
    char *line = cJSON_PrintUnformatted(o);
    cJSON_Delete(o);
    size_t l = strlen(line);
    while (len + l + 2 > cap) {
      cap *= 2;
      buf = realloc(buf, cap);
    }
    memcpy(buf + len, line, l);
    len += l;
    buf[len++] = '\n';
    free(line);
  }
  char path[DS_PATH];
  ds_join(path, sizeof path, dir, "manifest.jsonl");
  int r = ds_write_atomic(path, buf, len);
  free(buf);
  return r;
}

static int get_str(const cJSON *o, const char *k, char *dst, size_t n, int line, const char *path) {
  const cJSON *v = cJSON_GetObjectItemCaseSensitive(o, k);
  if (!cJSON_IsString(v) || strlen(v->valuestring) >= n) {
    ds_err("%s:%d: field \"%s\" missing, not a string, or too long", path, line, k);
    return 0;
  }
  strcpy(dst, v->valuestring);
  return 1;
}
/* An integral JSON number in [lo, hi]: valueint would truncate 4.9 to 4 and saturate 1e12
 * to INT_MAX, so a damaged manifest would render something nobody planned. */
static int get_int(const cJSON *o, const char *k, int lo, int hi, int *dst, int line,
                   const char *path) {
  const cJSON *v = cJSON_GetObjectItemCaseSensitive(o, k);
  if (!cJSON_IsNumber(v)) {
    ds_err("%s:%d: field \"%s\" missing or not a number", path, line, k);
    return 0;
  }
  double d = v->valuedouble;
  if (!(d >= lo && d <= hi) || d != floor(d)) {
    ds_err("%s:%d: field \"%s\": %.15g is not an integer in [%d, %d]", path, line, k, d, lo, hi);
    return 0;
  }
  *dst = (int)d;
  return 1;
}

/* "seed" is a string (64-bit exact in JSON) of decimal digits; plan writes 31-bit seeds. */
static int get_seed(const cJSON *o, uint64_t *dst, int line, const char *path) {
  char s[32];
  if (!get_str(o, "seed", s, sizeof s, line, path)) return 0;
  if (!ds_parse_u64(s, DS_MAX_SEED, dst)) {
    ds_err("%s:%d: field \"seed\": '%s' is not a decimal integer in [0, %u]", path, line, s,
           DS_MAX_SEED);
    return 0;
  }
  return 1;
}

static const ds_job *g_sort_jobs; /* job_id_cmp's jobs (qsort has no user pointer) */
static int job_id_cmp(const void *a, const void *b) {
  const int i = *(const int *)a, j = *(const int *)b;
  const int c = strcmp(g_sort_jobs[i].id, g_sort_jobs[j].id);
  return c ? c : (i > j) - (i < j);
}

int ds_manifest_read(const char *dir, ds_manifest *m) {
  memset(m, 0, sizeof *m);
  char path[DS_PATH];
  ds_join(path, sizeof path, dir, "manifest.jsonl");
  size_t len = 0;
  const char *why = NULL;
  char *text = ds_slurp(path, &len, &why);
  if (!text) {
    ds_err("cannot read '%s': %s%s", path, why ? why : "?",
           ds_exists(path) ? "" : " (run `kpcn-dataset plan` first)");
    return -1;
  }
  /* a NUL ends the C string early: the lines after it were silently dropped */
  const char *nul = memchr(text, 0, len);
  if (nul) {
    int at = 1;
    for (const char *c = text; c < nul; c++)
      at += *c == '\n';
    ds_err("%s:%d: a NUL byte (the file is damaged)", path, at);
    free(text);
    return -1;
  }
  int lineno = 0, ok = 1, *lines = NULL; /* lines[k]: the line of job k */
  /* Split by hand, not strtok: strtok skips empty lines, and errors must name the real line. */
  for (char *line = text, *next; line && *line && ok; line = next) {
    lineno++;
    next = strchr(line, '\n');
    if (next) *next++ = 0;
    if (!line[0]) continue;
    /* Require the object to end the line: cJSON_Parse ignores text after it. */
    cJSON *o = cJSON_ParseWithOpts(line, NULL, 1);
    if (!cJSON_IsObject(o)) {
      ds_err("%s:%d: not a JSON object (alone on its line)", path, lineno);
      cJSON_Delete(o);
      ok = 0;
      break;
    }
    ds_job j;
    memset(&j, 0, sizeof j);
    char kind[32];
    /* Ranges are those plan can write: --variants, --ref-spp, --resolution limits. */
    ok = get_str(o, "id", j.id, sizeof j.id, lineno, path) &&
         get_str(o, "kind", kind, sizeof kind, lineno, path) &&
         get_str(o, "scene", j.scene, sizeof j.scene, lineno, path) &&
         get_int(o, "variant", 0, DS_MAX_VARIANTS, &j.variant, lineno, path) &&
         get_str(o, "split", j.split, sizeof j.split, lineno, path) &&
         get_str(o, "scene_file", j.scene_file, sizeof j.scene_file, lineno, path) &&
         get_int(o, "spp", 1, DS_MAX_SPP, &j.spp, lineno, path) &&
         get_seed(o, &j.seed, lineno, path) &&
         get_int(o, "width", 1, DS_MAX_DIM, &j.width, lineno, path) &&
         get_int(o, "height", 1, DS_MAX_DIM, &j.height, lineno, path) &&
         get_str(o, "out", j.out, sizeof j.out, lineno, path) &&
         get_str(o, "preview", j.preview, sizeof j.preview, lineno, path) &&
         (!cJSON_HasObjectItem(o, "albedo_footprint") ||
          get_int(o, "albedo_footprint", 2, 16, &j.albedo_footprint, lineno, path));
    cJSON_Delete(o);
    if (!ok) break;
    int k = -1;
    for (int i = 0; i < 3; i++)
      if (!strcmp(kind, g_kinds[i])) k = i;
    if (k < 0) {
      ds_err("%s:%d: field \"kind\": '%s' is not preview, noisy or reference", path, lineno, kind);
      ok = 0;
      break;
    }
    j.kind = (ds_kind)k;
    int *nl = realloc(lines, sizeof *nl * (size_t)(m->n + 1));
    if (!nl || ds_manifest_push(m, &j) != 0) {
      free(nl ? nl : lines);
      lines = NULL;
      ds_err("out of memory reading %s", path);
      ok = 0;
      break;
    }
    lines = nl;
    lines[m->n - 1] = lineno;
  }
  free(text);
  if (ok && m->n == 0) {
    ds_err("%s holds no job (an empty manifest: plan again)", path);
    ok = 0;
  }
  /* a job twice (concatenated shard manifests, say) would be rendered once and cut into
   * patches twice: refused, as a dataset folder given twice is */
  int *by = ok ? malloc(sizeof *by * (size_t)m->n) : NULL;
  if (ok && !by) {
    ds_err("out of memory reading %s", path);
    ok = 0;
  }
  for (int i = 0; ok && i < m->n; i++)
    by[i] = i;
  if (ok) {
    g_sort_jobs = m->jobs;
    qsort(by, (size_t)m->n, sizeof *by, job_id_cmp);
  }
  for (int i = 1; ok && i < m->n; i++)
    if (!strcmp(m->jobs[by[i - 1]].id, m->jobs[by[i]].id)) {
      const int a = by[i - 1] < by[i] ? by[i - 1] : by[i], b = by[i - 1] ^ by[i] ^ a;
      ds_err("%s: job '%s' is listed twice (lines %d and %d): its pair would be cut twice", path,
             m->jobs[a].id, lines[a], lines[b]);
      ok = 0;
    }
  free(by);
  free(lines);
  if (!ok) ds_manifest_free(m);
  return ok ? 0 : -1;
}
