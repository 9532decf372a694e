/* Pre-render perturbation: variant 0 is the identity, variants are deterministic and
 * distinct, every parameter stays within its documented range, geometry is untouched. */
#include "kpcn/dataset.h"
#include "testutil.h"

#include <cjson/cJSON.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static char *slurp(const char *path) {
  FILE *f = fopen(path, "rb");
  if (!f) return NULL;
  fseek(f, 0, SEEK_END);
  long n = ftell(f);
  fseek(f, 0, SEEK_SET);
  char *b = malloc((size_t)n + 1);
  size_t got = fread(b, 1, (size_t)n, f);
  b[got] = 0;
  fclose(f);
  return b;
}

static double vlen(const cJSON *a, const cJSON *b) {
  double s = 0;
  for (int i = 0; i < 3; i++) {
    double d = cJSON_GetArrayItem(a, i)->valuedouble - cJSON_GetArrayItem(b, i)->valuedouble;
    s += d * d;
  }
  return sqrt(s);
}

static const cJSON *path2(const cJSON *o, const char *a, const char *b) {
  return cJSON_GetObjectItemCaseSensitive(cJSON_GetObjectItemCaseSensitive(o, a), b);
}

static void test_scene(const char *file) {
  char *base = slurp(file);
  CHECK(base != NULL);
  if (!base) return;
  cJSON *orig = cJSON_Parse(base);
  char *v0 = NULL, sm[512];
  CHECK(kpcn_perturb_scene(&v0, base, 42, 0, NULL, sm, sizeof sm) == KPCN_OK);
  cJSON *j0 = cJSON_Parse(v0);
  CHECK(cJSON_Compare(orig, j0, 1));
  cJSON_Delete(j0);
  free(v0);
  const cJSON *ocam = cJSON_GetObjectItemCaseSensitive(orig, "camera");
  const cJSON *opos = path2(path2(orig, "camera", "transform"), "position", NULL);
  (void)opos;
  const cJSON *ot = cJSON_GetObjectItemCaseSensitive(ocam, "transform");
  double odist = vlen(cJSON_GetObjectItemCaseSensitive(ot, "position"),
                      cJSON_GetObjectItemCaseSensitive(ot, "look_at"));
  double ofov = cJSON_GetObjectItemCaseSensitive(ocam, "fov")->valuedouble;
  int distinct = 0, changed_fov = 0;
  char *prev = NULL;
  for (int v = 1; v <= 12; v++) {
    char *a = NULL, *b = NULL;
    CHECK(kpcn_perturb_scene(&a, base, 42, v, NULL, sm, sizeof sm) == KPCN_OK);
    CHECK(kpcn_perturb_scene(&b, base, 42, v, NULL, NULL, 0) == KPCN_OK);
    CHECK(a && b && strcmp(a, b) == 0);
    if (prev && strcmp(prev, a) != 0) distinct++;
    cJSON *j = cJSON_Parse(a);
    const cJSON *cam = cJSON_GetObjectItemCaseSensitive(j, "camera");
    const cJSON *t = cJSON_GetObjectItemCaseSensitive(cam, "transform");
    double d = vlen(cJSON_GetObjectItemCaseSensitive(t, "position"),
                    cJSON_GetObjectItemCaseSensitive(t, "look_at"));
    CHECK(d >= odist * exp(-0.2) * 0.999 && d <= odist * exp(0.2) * 1.001);
    /* look-at jitter: at most 4% of the distance per axis */
    CHECK(vlen(cJSON_GetObjectItemCaseSensitive(t, "look_at"),
               cJSON_GetObjectItemCaseSensitive(ot, "look_at")) <= 0.04 * sqrt(3.0) * odist + 1e-9);
    double fov = cJSON_GetObjectItemCaseSensitive(cam, "fov")->valuedouble;
    CHECK(fov >= ofov * exp(-0.25) - 1e-9 && fov <= ofov * exp(0.25) + 1e-9);
    changed_fov += fov != ofov;
    /* Albedo arrays within [0, 0.95]; null BSDFs untouched. */
    int ok = 1;
    const cJSON *bs, *obs = cJSON_GetObjectItemCaseSensitive(orig, "bsdfs");
    int i = 0;
    cJSON_ArrayForEach(bs, cJSON_GetObjectItemCaseSensitive(j, "bsdfs")) {
      const cJSON *al = cJSON_GetObjectItemCaseSensitive(bs, "albedo");
      const cJSON *ty = cJSON_GetObjectItemCaseSensitive(bs, "type");
      if (!strcmp(ty->valuestring, "null"))
        ok &= cJSON_Compare(bs, cJSON_GetArrayItem(obs, i), 1);
      else if (cJSON_IsArray(al))
        for (int c = 0; c < 3; c++) {
          double x = cJSON_GetArrayItem(al, c)->valuedouble;
          ok &= x >= 0 && x <= 0.95;
        }
      const cJSON *ro = cJSON_GetObjectItemCaseSensitive(bs, "roughness");
      if (ro) ok &= ro->valuedouble >= 0.01 && ro->valuedouble <= 1.0;
      i++;
    }
    CHECK(ok);
    /* Non-emitting primitives keep their transform and geometry file. */
    const cJSON *p, *op = cJSON_GetObjectItemCaseSensitive(orig, "primitives");
    i = 0;
    cJSON_ArrayForEach(p, cJSON_GetObjectItemCaseSensitive(j, "primitives")) {
      const cJSON *q = cJSON_GetArrayItem(op, i++);
      if (!cJSON_GetObjectItemCaseSensitive(q, "emission")) {
        ok &= cJSON_Compare(cJSON_GetObjectItemCaseSensitive(p, "transform"),
                            cJSON_GetObjectItemCaseSensitive(q, "transform"), 1) ||
              !cJSON_GetObjectItemCaseSensitive(q, "transform");
        ok &= cJSON_Compare(cJSON_GetObjectItemCaseSensitive(p, "file"),
                            cJSON_GetObjectItemCaseSensitive(q, "file"), 1) ||
              !cJSON_GetObjectItemCaseSensitive(q, "file");
      }
    }
    CHECK(ok);
    cJSON_Delete(j);
    free(prev);
    free(b);
    prev = a;
  }
  free(prev);
  CHECK(distinct == 11);
  CHECK(changed_fov >= 10);
  /* Strength 0 everywhere = unchanged. */
  kpcn_perturb_settings off = {0, 0, 0, 0, 0, 0};
  char *z = NULL;
  CHECK(kpcn_perturb_scene(&z, base, 42, 5, &off, NULL, 0) == KPCN_OK);
  cJSON *jz = cJSON_Parse(z);
  CHECK(cJSON_Compare(orig, jz, 1));
  cJSON_Delete(jz);
  free(z);
  cJSON_Delete(orig);
  free(base);
}

int main(void) {
  test_scene(KPCN_SHARED "/scenes/tungsten/cornell-box/scene.json");
  test_scene(KPCN_SHARED "/scenes/tungsten/materialtest/materialtest.json");
  char *o = NULL;
  CHECK(kpcn_perturb_scene(&o, "{\"camera\": [1,", 1, 1, NULL, NULL, 0) == KPCN_ERR_FORMAT);
  CHECK(o == NULL && strstr(kpcn_last_error(), "JSON") != NULL);
  CHECK(kpcn_perturb_scene(&o, "{}", 1, -1, NULL, NULL, 0) == KPCN_ERR_INVALID_ARGUMENT);
  return kt_summary("perturb");
}
