/* Checks on the scene's JSON document that cJSON does not make. A key given twice in one
 * object is kept twice, and every lookup finds the first: {"spp": 1, "spp": 0} rendered with
 * 1 spp, while other readers (Python's json, most JSON libraries) take the last value. The
 * scene file is ambiguous, so it is an error naming the key's JSON path. */
#include "core/internal.h"
#include "scene/scene_internal.h"

#include <cjson/cJSON.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Objects with more members than this are checked by sorting their keys: pairwise comparison
 * is quadratic, and a generated or hostile file may hold one huge object. */
#define PAIRWISE_MAX 32

static int cmp_keys(const void *a, const void *b) {
  return strcmp(*(const char *const *)a, *(const char *const *)b);
}

/* Sets *dup to a key of obj that occurs more than once (NULL when none). */
static kpcn_status find_duplicate(const cJSON *obj, const char **dup) {
  *dup = NULL;
  size_t n = 0;
  for (const cJSON *it = obj->child; it; it = it->next)
    n++;
  if (n <= PAIRWISE_MAX) {
    for (const cJSON *a = obj->child; a; a = a->next)
      for (const cJSON *b = a->next; b; b = b->next)
        if (a->string && b->string && strcmp(a->string, b->string) == 0) {
          *dup = a->string;
          return KPCN_OK;
        }
    return KPCN_OK;
  }
  const char **keys = kpcn_alloc(n * sizeof(*keys), "JSON object keys");
  if (!keys) return KPCN_ERR_OUT_OF_MEMORY;
  size_t m = 0;
  for (const cJSON *it = obj->child; it; it = it->next)
    if (it->string) keys[m++] = it->string;
  qsort(keys, m, sizeof(*keys), cmp_keys);
  for (size_t i = 1; i < m && !*dup; i++)
    if (strcmp(keys[i - 1], keys[i]) == 0) *dup = keys[i];
  free(keys);
  return KPCN_OK;
}

/* path[0..len) is node's JSON path; children append to it in place. Only objects and arrays
 * are visited, so a long array of numbers (a matrix, an inline mesh) costs one pass. */
static kpcn_status walk(const cJSON *node, char *path, size_t len, size_t cap) {
  if (cJSON_IsObject(node)) {
    const char *dup;
    KPCN_TRY(find_duplicate(node, &dup));
    if (dup)
      return kpcn_fail(KPCN_ERR_FORMAT, "%s%s%s: duplicate key (a field may appear only once)",
                       path, len ? "." : "", dup);
  } else if (!cJSON_IsArray(node)) {
    return KPCN_OK;
  }
  int index = 0;
  for (const cJSON *c = node->child; c; c = c->next, index++) {
    if (!cJSON_IsObject(c) && !cJSON_IsArray(c)) continue;
    int k = cJSON_IsObject(node) ? snprintf(path + len, cap - len, "%s%s", len ? "." : "",
                                            c->string ? c->string : "?")
                                 : snprintf(path + len, cap - len, "[%d]", index);
    size_t sub = len + (k > 0 ? (size_t)k : 0);
    if (sub >= cap) sub = cap - 1; /* truncated path: still a useful prefix */
    kpcn_status st = walk(c, path, sub, cap);
    path[len] = 0;
    if (st != KPCN_OK) return st;
  }
  return KPCN_OK;
}

kpcn_status kpcn_json_check_duplicates(const void *cjson_root) {
  char path[512] = "";
  if (!cjson_root) return KPCN_OK;
  return walk((const cJSON *)cjson_root, path, 0, sizeof(path));
}
