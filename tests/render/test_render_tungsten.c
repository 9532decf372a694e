/* Agreement with Tungsten (independent truth: renders made by Tungsten itself, see
 * the README.md files in testdata/tungsten-cornell and testdata/tungsten-materialtest).
 * relMSE(ours, ref) must not exceed 1.5 x (our own predicted error mean(var/(ref^2+0.01)) + the
 * reference's own noise). A wrong fov convention, filter, light unit, transform or BSDF shows up as
 * a bias far above that bound. Both are whole-image figures, so a local error (one object's albedo
 * 20 % off) can hide in them: block_check compares 16x16-pixel block means one by one. */
#include "render_testutil.h"
#include "testutil.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>

enum { REF_SPP = 2048, BLOCK = 16 };

/* Block means of ours against the reference's, as z-scores. Per pixel, var is the variance of
 * our mean averaged over the channels, so for the grey value (R+G+B)/3 it is an upper bound
 * (Cauchy-Schwarz) and for one channel 3*var is. The reference (Tungsten, 2048 spp, no variance
 * stored) contributes its own noise, taken as ours scaled by spp/2048 (no lower than its stated
 * noise: that scaling predicts relMSE 1.5e-4 cornell, 8e-4 materialtest; stated 1.6e-4, 1.2e-4).
 * Pixel errors are independent (per-pixel sampling), so a block mean's variance is the sum of its
 * pixels' over n^2. Returns the largest |z|, grey and per channel (partial blocks at the image's
 * edge included). */
static void block_check(const kpcn_aov_set *a, const kpcn_aov_set *ref, int spp, double *zgrey,
                        double *zchan) {
  const int w = a->width, h = a->height;
  const size_t plane = kpcn_aov_plane_size(a);
  const float *o = a->buf[KPCN_BUF_COLOR], *r = ref->buf[KPCN_BUF_COLOR];
  const double vscale = 1.0 + (double)spp / REF_SPP;
  int wx = 0, wy = 0;
  *zgrey = *zchan = 0.0;
  for (int by = 0; by < h; by += BLOCK)
    for (int bx = 0; bx < w; bx += BLOCK) {
      double d[3] = {0, 0, 0}, v = 0.0;
      int n = 0;
      for (int y = by; y < by + BLOCK && y < h; y++)
        for (int x = bx; x < bx + BLOCK && x < w; x++, n++) {
          const size_t i = (size_t)y * w + x;
          for (int c = 0; c < 3; c++)
            d[c] += (double)o[c * plane + i] - r[c * plane + i];
          v += a->var[KPCN_BUF_COLOR][i] * vscale;
        }
      const double sd = sqrt(v) / n + 1e-7; /* the sd of one channel's block mean, averaged */
      const double zg = fabs(d[0] + d[1] + d[2]) / 3.0 / n / sd;
      if (zg > *zgrey) *zgrey = zg, wx = bx, wy = by;
      for (int c = 0; c < 3; c++)
        *zchan = fmax(*zchan, fabs(d[c]) / n / (sqrt(3.0) * sd));
    }
  printf("  %dx%d block means: max |z| grey %.2f (block at %d,%d), per channel %.2f\n", BLOCK,
         BLOCK, *zgrey, wx, wy, *zchan);
}

/* Visibility against Tungsten's noisy render (vis_path, 16 spp, its visibility.V): the fraction
 * of the shadow rays traced from the first non-specular hit that reach the sampled light. The
 * image means agree to 0.0012 (ours 0.6821 at 16 and at 32 spp, Tungsten 0.6809; seed to seed ours
 * varies by 2e-5) and 16x16 block means to 0.031 (seed to seed 0.006; the few blocks above 0.01 lie
 * along the tall box's left edge and the floor's front rows). Counting the samples that trace
 * no shadow ray as 0, as kpcn did before session 38, gives 0.6295 and blocks 0.35 off. */
static void visibility_check(const kpcn_aov_set *a, const char *vis_path) {
  kpcn_aov_set *t = NULL;
  CHECK(kpcn_exr_read_aov(vis_path, &t) == KPCN_OK);
  if (!t) return;
  CHECK(t->width == a->width && t->height == a->height && t->buf[KPCN_BUF_VISIBILITY]);
  if (t->width == a->width && t->height == a->height && t->buf[KPCN_BUF_VISIBILITY]) {
    const int w = a->width, h = a->height;
    const float *o = a->buf[KPCN_BUF_VISIBILITY], *r = t->buf[KPCN_BUF_VISIBILITY];
    double worst = 0.0, all = 0.0;
    for (int by = 0; by < h; by += BLOCK)
      for (int bx = 0; bx < w; bx += BLOCK) {
        double d = 0.0;
        int n = 0;
        for (int y = by; y < by + BLOCK && y < h; y++)
          for (int x = bx; x < bx + BLOCK && x < w; x++, n++)
            d += (double)o[(size_t)y * w + x] - r[(size_t)y * w + x];
        all += d;
        worst = kt_worst(worst, fabs(d) / n);
      }
    all /= (double)w * h;
    printf("  visibility: mean %.4f vs Tungsten's %.4f, largest %dx%d block difference %.4f\n",
           rt_mean(o, (size_t)w * h), rt_mean(r, (size_t)w * h), BLOCK, BLOCK, worst);
    CHECK(fabs(all) < 0.005);
    CHECK(worst < 0.05);
  }
  kpcn_aov_destroy(t);
}

static void check_scene(const char *scene, const char *base, const char *ref_path, int w, int h,
                        int spp, long long seed, double ref_noise, int box_fov20,
                        const char *vis_path) {
  cJSON *doc = rt_read_json(scene);
  CHECK(doc != NULL);
  if (!doc) return;
  if (box_fov20) { /* the settings the reference was rendered with (README) */
    rt_set_camera_number(doc, "fov", 20);
    rt_set_camera_string(doc, "reconstruction_filter", "box");
  }
  kpcn_scene *s = NULL;
  CHECK(rt_load(doc, base, &s) == KPCN_OK);
  cJSON_Delete(doc);
  if (!s) return;
  kpcn_aov_set *a = rt_render(s, spp, seed, 0, w, h, KPCN_LIGHTS_SCENE, -1);
  kpcn_aov_set *ref = NULL;
  CHECK(kpcn_exr_read_aov(ref_path, &ref) == KPCN_OK);
  CHECK(a != NULL);
  if (a && ref) {
    CHECK(ref->width == w && ref->height == h);
    size_t plane = kpcn_aov_plane_size(a);
    double e = rt_relmse(a->buf[KPCN_BUF_COLOR], ref->buf[KPCN_BUF_COLOR], plane);
    double pred = rt_predicted_relmse(a->var[KPCN_BUF_COLOR], ref->buf[KPCN_BUF_COLOR], plane);
    double bound = 1.5 * (pred + ref_noise);
    double mo = 0, mr = 0;
    for (int c = 0; c < 3; c++) {
      mo += rt_mean(a->buf[KPCN_BUF_COLOR] + c * plane, plane);
      mr += rt_mean(ref->buf[KPCN_BUF_COLOR] + c * plane, plane);
    }
    printf("%s: relMSE %.3e, predicted %.3e + ref %.1e, bound %.3e; mean %.5f vs ref %.5f\n", scene,
           e, pred, ref_noise, bound, mo / 3, mr / 3);
    CHECK(e <= bound);
    CHECK_CLOSE(mo, mr, 0.02, 0.0);
    double zg, zc;
    block_check(a, ref, spp, &zg, &zc);
    CHECK(zg < 5.0 && zc < 5.0);
    if (vis_path) visibility_check(a, vis_path);
  }
  kpcn_aov_destroy(a);
  kpcn_aov_destroy(ref);
  kpcn_scene_destroy(s);
}

int main(int argc, char **argv) {
  int spp = argc > 1 ? atoi(argv[1]) : 32; /* keeps the test < 20 s on a loaded 2-core machine */
  long long seed = argc > 2 ? atoll(argv[2]) : 7;
  check_scene(KPCN_TESTDATA "/scenes/cornell-box/scene.json", KPCN_TESTDATA "/scenes/cornell-box",
              KPCN_TESTDATA "/tungsten-cornell/reference_2048spp.exr", 256, 256, spp, seed, 1.6e-4,
              1, KPCN_TESTDATA "/tungsten-cornell/noisy_16spp.exr");
  check_scene(KPCN_TESTDATA "/scenes/materialtest/materialtest.json",
              KPCN_TESTDATA "/scenes/materialtest",
              KPCN_TESTDATA "/tungsten-materialtest/reference_2048spp.exr", 320, 180, spp / 2, seed,
              1.2e-4, 0, NULL);
  return kt_summary("render_tungsten");
}
