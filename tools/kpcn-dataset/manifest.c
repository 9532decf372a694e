/* manifest.jsonl: one JSON object per line, one independent render job each, so the
 * same file drives `kpcn-dataset run`, a Slurm array (--shard $SLURM_ARRAY_TASK_ID/N)
 * or GNU parallel. */
#include "ds.h"

#include <cjson/cJSON.h>
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
static int get_int(const cJSON *o, const char *k, int *dst, int line, const char *path) {
  const cJSON *v = cJSON_GetObjectItemCaseSensitive(o, k);
  if (!cJSON_IsNumber(v)) {
    ds_err("%s:%d: field \"%s\" missing or not a number", path, line, k);
    return 0;
  }
  *dst = v->valueint;
  return 1;
}

int ds_manifest_read(const char *dir, ds_manifest *m) {
  memset(m, 0, sizeof *m);
  char path[DS_PATH];
  ds_join(path, sizeof path, dir, "manifest.jsonl");
  char *text = ds_slurp(path, NULL);
  if (!text) {
    ds_err("cannot read '%s' (run `kpcn-dataset plan` first)", path);
    return -1;
  }
  int lineno = 0, ok = 1;
  char *save = NULL;
  for (char *line = strtok_r(text, "\n", &save); line && ok; line = strtok_r(NULL, "\n", &save)) {
    lineno++;
    if (!line[0]) continue;
    cJSON *o = cJSON_Parse(line);
    if (!cJSON_IsObject(o)) {
      ds_err("%s:%d: not a JSON object", path, lineno);
      cJSON_Delete(o);
      ok = 0;
      break;
    }
    ds_job j;
    memset(&j, 0, sizeof j);
    char kind[32], seed[32];
    ok = get_str(o, "id", j.id, sizeof j.id, lineno, path) &&
         get_str(o, "kind", kind, sizeof kind, lineno, path) &&
         get_str(o, "scene", j.scene, sizeof j.scene, lineno, path) &&
         get_int(o, "variant", &j.variant, lineno, path) &&
         get_str(o, "split", j.split, sizeof j.split, lineno, path) &&
         get_str(o, "scene_file", j.scene_file, sizeof j.scene_file, lineno, path) &&
         get_int(o, "spp", &j.spp, lineno, path) &&
         get_str(o, "seed", seed, sizeof seed, lineno, path) &&
         get_int(o, "width", &j.width, lineno, path) &&
         get_int(o, "height", &j.height, lineno, path) &&
         get_str(o, "out", j.out, sizeof j.out, lineno, path) &&
         get_str(o, "preview", j.preview, sizeof j.preview, lineno, path);
    cJSON_Delete(o);
    if (!ok) break;
    j.seed = strtoull(seed, NULL, 10);
    int k = -1;
    for (int i = 0; i < 3; i++)
      if (!strcmp(kind, g_kinds[i])) k = i;
    if (k < 0 || j.spp <= 0 || j.width <= 0 || j.height <= 0) {
      ds_err("%s:%d: bad kind '%s' or non-positive spp/size", path, lineno, kind);
      ok = 0;
      break;
    }
    j.kind = (ds_kind)k;
    ds_manifest_push(m, &j);
  }
  free(text);
  if (!ok) ds_manifest_free(m);
  return ok ? 0 : -1;
}
