/* Scene loading from several threads at once, as an embedding renderer may do: each thread's
 * error message must name its own problem. Two process-wide variables of the libraries the
 * loader uses made them cross (session 61): cJSON's error pointer (a syntax error's line came
 * from another thread's parse, and a pointer into another thread's text made the line count
 * read far past this one: a crash) and assimp's error string (a mesh's reason was another
 * thread's mesh's). Rates before the fixes: about 1e-4 and 5e-3 per message, so the
 * iteration counts below would see several. */
#include "kpcn/scene.h"
#include "testutil.h"

#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define JSON_ITERS 20000
#define MESH_ITERS 1000

static char g_doc[2][8192];
static const char *g_want_json[2] = {"near line 3", "near line 60"};
static char g_scene[2][512];
static const char *g_want_mesh[2] = {"No output meshes", "vertex index out of range"};
static int g_wrong[2];

static void *json_thread(void *p) {
  const int id = (int)(long)p;
  for (int it = 0; it < JSON_ITERS; it++) {
    kpcn_scene *s = NULL;
    kpcn_status st = kpcn_scene_load_json(g_doc[id], NULL, id ? "b.json" : "a.json", &s);
    const char *m = kpcn_last_error();
    if (st != KPCN_ERR_FORMAT || !strstr(m, g_want_json[id]) ||
        !strstr(m, id ? "b.json" : "a.json")) {
      if (g_wrong[id]++ == 0) fprintf(stderr, "thread %d: '%s'\n", id, m);
    }
    kpcn_scene_destroy(s);
  }
  return NULL;
}

static void *mesh_thread(void *p) {
  const int id = (int)(long)p;
  for (int it = 0; it < MESH_ITERS; it++) {
    kpcn_scene *s = NULL;
    kpcn_status st = kpcn_scene_load(g_scene[id], &s);
    const char *m = kpcn_last_error();
    if (st != KPCN_ERR_FORMAT || !strstr(m, g_want_mesh[id])) {
      if (g_wrong[id]++ == 0) fprintf(stderr, "thread %d: '%s'\n", id, m);
    }
    kpcn_scene_destroy(s);
  }
  return NULL;
}

static void run_pair(void *(*fn)(void *)) {
  pthread_t t[2];
  g_wrong[0] = g_wrong[1] = 0;
  for (int i = 0; i < 2; i++)
    CHECK(pthread_create(&t[i], NULL, fn, (void *)(long)i) == 0);
  for (int i = 0; i < 2; i++)
    pthread_join(t[i], NULL);
  CHECK(g_wrong[0] == 0 && g_wrong[1] == 0);
}

static void write_file(const char *path, const char *text) {
  FILE *f = fopen(path, "w");
  CHECK(f != NULL);
  if (f) fputs(text, f), fclose(f);
}

int main(void) {
  /* syntax errors on line 3 of a short document and on line 60 of a longer one */
  snprintf(g_doc[0], sizeof g_doc[0],
           "{\n  \"primitives\": [\n    {\"type\": \"quad\",, }\n  ]\n}\n");
  char *q = g_doc[1];
  q += sprintf(q, "{\n");
  for (int i = 0; i < 58; i++)
    q += sprintf(q, "  \"k%d\": [1, 2, 3, 4, 5, 6, 7, 8],\n", i);
  sprintf(q, "  \"bad\": [1 2]\n}\n");
  for (int id = 0; id < 2; id++) { /* each message as loaded alone */
    kpcn_scene *s = NULL;
    CHECK(kpcn_scene_load_json(g_doc[id], NULL, "x.json", &s) == KPCN_ERR_FORMAT);
    CHECK(strstr(kpcn_last_error(), g_want_json[id]) != NULL);
  }
  run_pair(json_thread);

  /* two meshes assimp refuses for different reasons */
  const char *dir = kt_tmpdir();
  char path[512];
  snprintf(path, sizeof path, "%s/a.ply", dir);
  write_file(path, "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n1\n");
  snprintf(path, sizeof path, "%s/d.obj", dir);
  write_file(path, "v 0 0 0\nf 1 2 3\n");
  const char *mesh[2] = {"a.ply", "d.obj"};
  for (int id = 0; id < 2; id++) {
    char json[512];
    snprintf(json, sizeof json,
             "{\"bsdfs\": [{\"name\": \"m\", \"type\": \"lambert\", \"albedo\": 0.5}], "
             "\"primitives\": [{\"type\": \"mesh\", \"file\": \"%s\", \"bsdf\": \"m\"}], "
             "\"camera\": {\"type\": \"pinhole\", \"resolution\": [8, 8]}}",
             mesh[id]);
    snprintf(g_scene[id], sizeof g_scene[id], "%s/scene_%d.json", dir, id);
    write_file(g_scene[id], json);
    kpcn_scene *s = NULL;
    CHECK(kpcn_scene_load(g_scene[id], &s) == KPCN_ERR_FORMAT);
    CHECK(strstr(kpcn_last_error(), g_want_mesh[id]) != NULL);
  }
  run_pair(mesh_thread);
  return kt_summary("test_scene_threads");
}
