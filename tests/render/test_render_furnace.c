/* Furnace tests of the whole integrator against closed-form answers:
 *  1. a lambert sphere (albedo a) under a constant environment L: every sphere pixel is a*L
 *     (convex: one bounce, then the ray escapes), every other pixel L;
 *  2. a closed box whose inward-facing walls are all lambert (albedo a) and emit E: every
 *     pixel is E / (1 - a) (all bounce orders; tests Russian roulette, NEE and MIS on area
 *     lights, and emission of every surface);
 * with MIS, NEE-only and BSDF-only (the box: MIS and BSDF-only; NEE-only is unbiased there but
 * has infinite variance next to the box's edges, where uniform area sampling of the adjacent
 * wall meets the 1/d^2 singularity, so no finite-sample bound holds for it). */
#include "render_testutil.h"
#include "testutil.h"

#include <math.h>
#include <stdio.h>

static const char *names[3] = {"MIS", "NEE only", "BSDF only"};
static const kpcn_light_strategy strat[3] = {KPCN_LIGHTS_MIS, KPCN_LIGHTS_NEE_ONLY,
                                             KPCN_LIGHTS_BSDF_ONLY};

static void check_image(const char *what, const kpcn_aov_set *a, const float *want,
                        double tol_sigma) {
  size_t plane = kpcn_aov_plane_size(a);
  double maxz = 0.0, sum = 0.0, sumw = 0.0, var = 0.0;
  for (size_t i = 0; i < plane; i++)
    for (int c = 0; c < 3; c++) {
      double v = a->buf[KPCN_BUF_COLOR][c * plane + i], w = want[i];
      double sd = sqrt(a->var[KPCN_BUF_COLOR][i]) + 1e-6;
      maxz = fmax(maxz, fabs(v - w) / sd);
      sum += v;
      sumw += w;
      var += a->var[KPCN_BUF_COLOR][i];
    }
  double n = 3.0 * plane, sdm = sqrt(var * 3.0) / n;
  printf("%-32s image mean %.5f (expected %.5f, sd %.5f), max |z| per pixel %.2f\n", what, sum / n,
         sumw / n, sdm, maxz);
  CHECK(fabs(sum - sumw) / n <= 4.0 * sdm + 1e-6);
  CHECK(maxz <= tol_sigma);
}

static void sphere_in_env(void) {
  const char *json =
      "{\"primitives\":[{\"type\":\"sphere\",\"bsdf\":{\"type\":\"lambert\",\"albedo\":0.5},"
      "\"transform\":{\"scale\":1}},{\"type\":\"infinite_sphere\",\"emission\":0.8}],"
      "\"camera\":{\"type\":\"pinhole\",\"fov\":45,\"resolution\":[24,24],\"reconstruction_"
      "filter\":\"box\","
      "\"transform\":{\"position\":[0,0,4],\"look_at\":[0,0,0],\"up\":[0,1,0]}}}";
  kpcn_scene *s = NULL;
  CHECK(kpcn_scene_load_json(json, NULL, "furnace-sphere", &s) == KPCN_OK);
  if (!s) return;
  for (int k = 0; k < 3; k++) {
    kpcn_aov_set *a = rt_render(s, 64, 3 + k, 0, 0, 0, strat[k], -1);
    CHECK(a != NULL);
    if (!a) continue;
    size_t plane = kpcn_aov_plane_size(a);
    float want[24 * 24];
    int inside = 0;
    /* classify pixels by their albedo AOV (sphere: 0.5, env: 0); skip silhouette pixels */
    for (size_t i = 0; i < plane; i++) {
      float al = a->buf[KPCN_BUF_ALBEDO][i];
      want[i] = al > 0.499f ? 0.4f : (al < 1e-6f ? 0.8f : -1.0f);
      inside += al > 0.499f;
    }
    CHECK(inside > 50);
    /* drop mixed pixels from the comparison by copying their value */
    for (size_t i = 0; i < plane; i++)
      if (want[i] < 0.0f) want[i] = a->buf[KPCN_BUF_COLOR][i];
    /* every colour channel equal: compare channel R only through a grey image */
    char what[64];
    snprintf(what, sizeof(what), "sphere in env, %s", names[k]);
    check_image(what, a, want, 6.0);
    kpcn_aov_destroy(a);
  }
  kpcn_scene_destroy(s);
}

static void emissive_box(void) {
#define WALL(pos, rot)                                                                             \
  "{\"type\":\"quad\",\"bsdf\":\"w\",\"emission\":1,\"transform\":{\"position\":" pos              \
  ",\"scale\":[2.02,1,2.02],\"rotation\":" rot "}}"
  const char *json =
      "{\"bsdfs\":[{\"name\":\"w\",\"type\":\"lambert\",\"albedo\":0.5}],\"primitives\":"
      "[" WALL("[0,-1,0]", "[0,0,0]") "," WALL("[0,1,0]", "[0,0,180]") "," WALL(
          "[0,0,-1]",
          "[90,0,0]") "," WALL("[0,0,1]",
                               "[-90,0,0]") "," WALL("[-1,0,0]",
                                                     "[0,0,-90]") "," WALL("[1,0,0]",
                                                                           "[0,0,90]") "],"
                                                                                       "\"ca"
                                                                                       "mera"
                                                                                       "\":{"
                                                                                       "\"ty"
                                                                                       "pe\""
                                                                                       ":\"p"
                                                                                       "inho"
                                                                                       "le\""
                                                                                       ",\"f"
                                                                                       "ov\""
                                                                                       ":90,"
                                                                                       "\"re"
                                                                                       "solu"
                                                                                       "tion"
                                                                                       "\":["
                                                                                       "16,"
                                                                                       "16],"
                                                                                       "\"tr"
                                                                                       "ansf"
                                                                                       "orm"
                                                                                       "\":{"
                                                                                       "\"po"
                                                                                       "siti"
                                                                                       "on\""
                                                                                       ":[0."
                                                                                       "1,0."
                                                                                       "2,0."
                                                                                       "3],"
                                                                                       "\"lo"
                                                                                       "ok_"
                                                                                       "at\""
                                                                                       ":[0,"
                                                                                       "0,-"
                                                                                       "1],"
                                                                                       "\"up"
                                                                                       "\":["
                                                                                       "0,1,"
                                                                                       "0]}}"
                                                                                       ","
                                                                                       "\"in"
                                                                                       "tegr"
                                                                                       "ator"
                                                                                       "\":{"
                                                                                       "\"ty"
                                                                                       "pe\""
                                                                                       ":\"p"
                                                                                       "ath_"
                                                                                       "trac"
                                                                                       "er\""
                                                                                       ",\"m"
                                                                                       "ax_"
                                                                                       "boun"
                                                                                       "ces"
                                                                                       "\":"
                                                                                       "64}"
                                                                                       "}";
  kpcn_scene *s = NULL;
  CHECK(kpcn_scene_load_json(json, NULL, "furnace-box", &s) == KPCN_OK);
  if (!s) {
    fprintf(stderr, "%s\n", kpcn_last_error());
    return;
  }
  float want[16 * 16];
  for (int i = 0; i < 16 * 16; i++)
    want[i] = 2.0f; /* E / (1 - a) */
  for (int k = 0; k < 3; k += 2) {
    kpcn_aov_set *a = rt_render(s, 64, 7 + k, 0, 0, 0, strat[k], -1);
    CHECK(a != NULL);
    if (!a) continue;
    char what[64];
    snprintf(what, sizeof(what), "emissive box, %s", names[k]);
    check_image(what, a, want, 6.0);
    kpcn_aov_destroy(a);
  }
  kpcn_scene_destroy(s);
}

int main(void) {
  sphere_in_env();
  emissive_box();
  return kt_summary("render_furnace");
}
