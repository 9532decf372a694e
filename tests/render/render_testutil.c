#include "render_testutil.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

cJSON *rt_read_json(const char *path) {
  FILE *f = fopen(path, "rb");
  if (!f) {
    fprintf(stderr, "cannot open %s\n", path);
    return NULL;
  }
  fseek(f, 0, SEEK_END);
  long n = ftell(f);
  fseek(f, 0, SEEK_SET);
  char *t = malloc((size_t)n + 1);
  size_t got = fread(t, 1, (size_t)n, f);
  t[got] = 0;
  fclose(f);
  cJSON *doc = cJSON_Parse(t);
  free(t);
  if (!doc) fprintf(stderr, "bad JSON in %s\n", path);
  return doc;
}

kpcn_status rt_load(const cJSON *doc, const char *base_dir, kpcn_scene **out) {
  char *text = cJSON_PrintUnformatted(doc);
  kpcn_status st = kpcn_scene_load_json(text, base_dir, "test-scene", out);
  free(text);
  if (st != KPCN_OK) fprintf(stderr, "load failed: %s\n", kpcn_last_error());
  return st;
}

static cJSON *camera(cJSON *doc) {
  cJSON *c = cJSON_GetObjectItemCaseSensitive(doc, "camera");
  if (!c) {
    c = cJSON_CreateObject();
    cJSON_AddItemToObject(doc, "camera", c);
  }
  return c;
}

void rt_set_camera_number(cJSON *doc, const char *key, double v) {
  cJSON *c = camera(doc);
  cJSON_DeleteItemFromObjectCaseSensitive(c, key);
  cJSON_AddNumberToObject(c, key, v);
}

void rt_set_camera_string(cJSON *doc, const char *key, const char *v) {
  cJSON *c = camera(doc);
  cJSON_DeleteItemFromObjectCaseSensitive(c, key);
  cJSON_AddStringToObject(c, key, v);
}

kpcn_aov_set *rt_render(const kpcn_scene *s, int spp, long long seed, int threads, int w, int h,
                        kpcn_light_strategy lights, int max_bounces) {
  kpcn_render_settings rs = kpcn_render_settings_defaults();
  rs.spp = spp;
  rs.seed = seed;
  rs.nthreads = threads;
  rs.width = w;
  rs.height = h;
  rs.lights = lights;
  rs.max_bounces = max_bounces;
  kpcn_aov_set *out = NULL;
  if (kpcn_render(s, &rs, &out) != KPCN_OK) {
    fprintf(stderr, "render failed: %s\n", kpcn_last_error());
    return NULL;
  }
  return out;
}

double rt_relmse(const float *a, const float *b, size_t plane) {
  double acc = 0.0;
  for (size_t i = 0; i < 3 * plane; i++) {
    double d = (double)a[i] - b[i];
    acc += d * d / ((double)b[i] * b[i] + 0.01);
  }
  return acc / (3.0 * (double)plane);
}

double rt_predicted_relmse(const float *var, const float *ref, size_t plane) {
  double acc = 0.0;
  for (int c = 0; c < 3; c++)
    for (size_t i = 0; i < plane; i++) {
      double r = ref[c * plane + i];
      acc += var[i] / (r * r + 0.01);
    }
  return acc / (3.0 * (double)plane);
}

double rt_mean(const float *p, size_t n) {
  double acc = 0.0;
  for (size_t i = 0; i < n; i++)
    acc += p[i];
  return acc / (double)n;
}

kpcn_aov_set *rt_exr_roundtrip(const kpcn_aov_set *a, const char *path) {
  kpcn_aov_set *rd = NULL;
  if (kpcn_exr_write_aov(path, a, NULL) != KPCN_OK || kpcn_exr_read_aov(path, &rd) != KPCN_OK) {
    fprintf(stderr, "%s\n", kpcn_last_error());
    return NULL;
  }
  return rd;
}
