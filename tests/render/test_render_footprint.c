/* The albedo footprint (kpcn_render_settings.albedo_footprint) against independent truth:
 *  - a pinhole straight in front of a fine checker quad, box filter: a pixel's albedo is the
 *    checker's average over the pixel's square on the quad, computed here in closed form. The
 *    footprint's error must be far below the point-sampled albedo's at the same spp and close
 *    to that of k*k times as many real camera rays (settings.albedo_spp);
 *  - on the textures scene (tilted planes, a cube, a sphere: silhouettes, and the sphere's
 *    per-point lookups) against an albedo pass of 4096 real camera rays: a lower error over the
 *    image, and no higher at the pixels whose samples see more than one surface (extending
 *    each surface over the whole pixel there doubled it);
 *  - it changes only the albedo (and its variance): every other buffer is the plain render's
 *    bit for bit, k = 1 is the plain render, the header records k, bad values are refused. */
#include "render_testutil.h"
#include "testutil.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

enum { W = 32, H = 32, CELLS = 45 };
static const double ON = 0.8, OFF = 0.1;
/* camera at z = DIST looking at the quad z = 0, [-1, 1]^2; the view spans x, y in +-HALF_VIEW */
static const double DIST = 4.0, HALF_VIEW = 0.8;

/* measure of the odd cells of a unit-width stripe pattern in [0, t] */
static double odd_measure(double t) {
  double f = floor(t / 2.0);
  return f + fmax(0.0, t - 2.0 * f - 1.0);
}

/* the fraction of [a, b] (in cell units) covered by odd cells */
static double odd_fraction(double a, double b) {
  return (odd_measure(b) - odd_measure(a)) / (b - a);
}

/* Closed form: the checker's mean over pixel (px, py)'s square. With an odd cell count the
 * pattern is the same under u -> 1 - u, v -> 1 - v and u <-> v, so the quad's uv orientation
 * does not matter. */
static double exact_albedo(int px, int py) {
  const double pix = 2.0 * HALF_VIEW / W;
  const double x0 = -HALF_VIEW + px * pix, y1 = HALF_VIEW - py * pix;
  const double cu = CELLS / 2.0; /* world x -> cell units: u = (x + 1) / 2 */
  double fu = odd_fraction((x0 + 1.0) * cu, (x0 + pix + 1.0) * cu);
  double fv = odd_fraction((y1 - pix + 1.0) * cu, (y1 + 1.0) * cu);
  double on = fu * (1.0 - fv) + (1.0 - fu) * fv; /* (iu ^ iv) odd */
  return on * ON + (1.0 - on) * OFF;
}

static kpcn_scene *checker_scene(void) {
  char json[1024];
  const double fov = 2.0 * atan(HALF_VIEW / DIST) * 180.0 / 3.14159265358979;
  snprintf(json, sizeof(json),
           "{\"bsdfs\":[{\"name\":\"c\",\"type\":\"lambert\",\"albedo\":{\"type\":\"checker\","
           "\"on_color\":[%g,%g,%g],\"off_color\":[%g,%g,%g],\"res_u\":%d,\"res_v\":%d}}],"
           "\"primitives\":[{\"type\":\"quad\",\"bsdf\":\"c\",\"transform\":{\"position\":[0,0,0],"
           "\"scale\":[2,1,2],\"rotation\":[90,0,0]}}],"
           "\"camera\":{\"type\":\"pinhole\",\"fov\":%.12g,\"resolution\":[%d,%d],"
           "\"reconstruction_filter\":\"box\",\"transform\":{\"position\":[0,0,%g],"
           "\"look_at\":[0,0,0],\"up\":[0,1,0]}},\"integrator\":{\"type\":\"path_tracer\"}}",
           ON, ON, ON, OFF, OFF, OFF, CELLS, CELLS, fov, W, H, DIST);
  kpcn_scene *s = NULL;
  if (kpcn_scene_load_json(json, NULL, "checker", &s) != KPCN_OK)
    fprintf(stderr, "%s\n", kpcn_last_error());
  return s;
}

static kpcn_aov_set *render(const kpcn_scene *s, int w, int h, int spp, int albedo_spp, int k) {
  kpcn_render_settings st = kpcn_render_settings_defaults();
  st.width = w, st.height = h, st.spp = spp, st.seed = 5, st.nthreads = 2;
  st.albedo_spp = albedo_spp, st.albedo_footprint = k;
  kpcn_aov_set *a = NULL;
  if (kpcn_render(s, &st, &a) != KPCN_OK) fprintf(stderr, "%s\n", kpcn_last_error());
  return a;
}

/* mean squared albedo error over the pixels with mask[i] (all when mask is NULL) */
static double albedo_mse(const kpcn_aov_set *a, const float *truth, const unsigned char *mask) {
  const size_t plane = kpcn_aov_plane_size(a);
  double e = 0.0;
  for (int c = 0; c < 3; c++)
    for (size_t i = 0; i < plane; i++) {
      if (mask && !mask[i]) continue;
      double d = a->buf[KPCN_BUF_ALBEDO][c * plane + i] - truth[c * plane + i];
      e += d * d;
    }
  return e / (3.0 * (double)plane);
}

static void test_checker(void) {
  kpcn_scene *s = checker_scene();
  CHECK(s != NULL);
  if (!s) return;
  float *truth = malloc(3 * W * H * sizeof(float));
  for (int c = 0; c < 3; c++)
    for (int py = 0; py < H; py++)
      for (int px = 0; px < W; px++)
        truth[c * W * H + py * W + px] = (float)exact_albedo(px, py);
  kpcn_aov_set *point = render(s, W, H, 16, 0, 0), *rays = render(s, W, H, 16, 256, 0),
               *fp = render(s, W, H, 16, 0, 4), *ref = render(s, W, H, 16, 4096, 0);
  CHECK(point && rays && fp && ref);
  if (point && rays && fp && ref) {
    double ep = albedo_mse(point, truth, NULL), er = albedo_mse(rays, truth, NULL),
           ef = albedo_mse(fp, truth, NULL), e4096 = albedo_mse(ref, truth, NULL);
    printf("checker quad, albedo MSE vs the closed form: 16 point samples %.3g, 256 camera rays "
           "%.3g, 16 samples x footprint 4x4 %.3g (4096 camera rays %.3g)\n",
           ep, er, ef, e4096);
    CHECK(e4096 < 0.05 * ep);              /* the closed form is the renderer's truth */
    CHECK(ef < 0.1 * ep && ef < 2.0 * er); /* k*k = 16 lookups ~ 16x the rays */
    CHECK(fp->albedo_footprint == 4 && point->albedo_footprint == 0);
  }
  kpcn_aov_destroy(point), kpcn_aov_destroy(rays), kpcn_aov_destroy(fp), kpcn_aov_destroy(ref);
  free(truth);
  kpcn_scene_destroy(s);
}

static void test_textures_scene(void) {
  kpcn_scene *s = NULL;
  CHECK(kpcn_scene_load(KPCN_TESTDATA "/scenes/textures/scene.json", &s) == KPCN_OK);
  if (!s) return;
  const int w = 80, h = 60;
  kpcn_aov_set *point = render(s, w, h, 16, 0, 0), *one = render(s, w, h, 16, 0, 1),
               *fp = render(s, w, h, 16, 0, 4), *ref = render(s, w, h, 16, 4096, 0);
  CHECK(point && one && fp && ref);
  if (point && one && fp && ref) {
    const size_t plane = kpcn_aov_plane_size(point);
    int same_other = 1, same_one = 1;
    for (int b = 0; b < KPCN_BUF_COUNT; b++) {
      const size_t n = plane * (size_t)kpcn_buffer_channels((kpcn_buffer)b);
      same_one &= !memcmp(one->buf[b], point->buf[b], n * sizeof(float)) &&
                  !memcmp(one->var[b], point->var[b], plane * sizeof(float));
      if (b == KPCN_BUF_ALBEDO) continue;
      same_other &= !memcmp(fp->buf[b], point->buf[b], n * sizeof(float)) &&
                    !memcmp(fp->var[b], point->var[b], plane * sizeof(float));
    }
    CHECK(same_one && same_other && one->albedo_footprint == 0);
    CHECK(memcmp(fp->buf[KPCN_BUF_ALBEDO], point->buf[KPCN_BUF_ALBEDO], 3 * plane * 4) != 0);
    /* pixels whose samples see more than one surface: depth or normal vary within them */
    unsigned char *edge = calloc(plane, 1), *rest = calloc(plane, 1);
    size_t nedge = 0;
    for (size_t i = 0; i < plane; i++) {
      const double z = point->buf[KPCN_BUF_DEPTH][i];
      edge[i] =
          point->var[KPCN_BUF_NORMAL][i] > 1e-4f || point->var[KPCN_BUF_DEPTH][i] > 1e-6 * z * z;
      rest[i] = !edge[i];
      nedge += edge[i];
    }
    const float *truth = ref->buf[KPCN_BUF_ALBEDO];
    double pe = albedo_mse(point, truth, edge), fe = albedo_mse(fp, truth, edge);
    double pr = albedo_mse(point, truth, rest), fr = albedo_mse(fp, truth, rest);
    printf("textures scene, albedo MSE vs 4096 camera rays (as parts of the image mean): "
           "%zu edge pixels: point %.3g, footprint 4x4 %.3g; the rest: point %.3g, "
           "footprint %.3g\n",
           nedge, pe, fe, pr, fr);
    CHECK(nedge > plane / 50);
    CHECK(fe <= pe);      /* silhouettes: never worse than point samples */
    CHECK(fr < 0.4 * pr); /* inside surfaces: the texture's coverage noise mostly gone */
    /* and the header keeps k */
    kpcn_aov_set *rd = rt_exr_roundtrip(fp, kt_tmpfile("footprint.exr"));
    CHECK(rd && rd->albedo_footprint == 4 && rd->albedo_spp == 0);
    kpcn_aov_destroy(rd);
    free(edge), free(rest);
  }
  kpcn_aov_destroy(point), kpcn_aov_destroy(one), kpcn_aov_destroy(fp), kpcn_aov_destroy(ref);
  /* bad values */
  kpcn_render_settings st = kpcn_render_settings_defaults();
  st.width = 8, st.height = 8, st.spp = 1;
  kpcn_aov_set *bad = NULL;
  st.albedo_footprint = 17;
  CHECK(kpcn_render(s, &st, &bad) == KPCN_ERR_INVALID_ARGUMENT && !bad);
  CHECK(strstr(kpcn_last_error(), "albedo_footprint: 17") != NULL);
  st.albedo_footprint = -1;
  CHECK(kpcn_render(s, &st, &bad) == KPCN_ERR_INVALID_ARGUMENT && !bad);
  st.albedo_footprint = 2, st.color_only = 1; /* no albedo buffer */
  CHECK(kpcn_render(s, &st, &bad) == KPCN_ERR_INVALID_ARGUMENT && !bad);
  CHECK(strstr(kpcn_last_error(), "colour-only") != NULL);
  kpcn_scene_destroy(s);
}

int main(void) {
  test_checker();
  test_textures_scene();
  return kt_summary("render_footprint");
}
