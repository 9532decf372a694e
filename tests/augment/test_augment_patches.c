/* Patch selection: the flat-patch criterion on constructed flat and textured patches
 * (values computed by hand from the documented rule), culling statistics, grid mode,
 * determinism and variance-proportional sampling. */
#include "kpcn/augment.h"
#include "testutil.h"

#include <stdlib.h>
#include <string.h>

/* Left half (x < W/2) flat grey with 1% jitter, right half a checkerboard. */
static kpcn_aov_set *half_flat(int W, int H) {
  kpcn_aov_set *s = NULL;
  kpcn_aov_create(&s, W, H);
  kpcn_aov_add(s, KPCN_BUF_COLOR, 1);
  unsigned rng = 3;
  size_t np = kpcn_aov_plane_size(s);
  for (int y = 0; y < H; y++)
    for (int x = 0; x < W; x++) {
      for (int c = 0; c < 3; c++) {
        float v = x < W / 2 ? 0.5f * (1 + 0.01f * (kt_randf(&rng) - 0.5f))
                            : (((x / 2) + (y / 2)) & 1 ? 0.9f : 0.1f);
        s->buf[KPCN_BUF_COLOR][c * np + (size_t)y * W + x] = v;
      }
      s->var[KPCN_BUF_COLOR][(size_t)y * W + x] = x < W / 2 ? 0.001f : 0.1f;
    }
  return s;
}

static void test_flat_fraction(void) {
  /* 4x4 patch: 12 pixels at 1.0, 4 at 1.2 (relative deviation 0.2). Median 1.0, L(m)=1. */
  float r[16], g[16], b[16];
  for (int i = 0; i < 16; i++)
    r[i] = g[i] = b[i] = i < 12 ? 1.0f : 1.2f;
  CHECK_NEAR(kpcn_patch_flat_fraction(r, g, b, 4, 0, 0, 4, 0.05, 0.01), 12.0 / 16, 1e-12);
  /* tol 0.25*(1+0.01) = 0.2525 covers the 0.2 deviation: all near. */
  CHECK_NEAR(kpcn_patch_flat_fraction(r, g, b, 4, 0, 0, 4, 0.25, 0.01), 1.0, 1e-12);
  /* Only one channel deviating is enough to be "far" (max over channels). */
  for (int i = 0; i < 16; i++)
    r[i] = g[i] = 1.0f, b[i] = i % 2 ? 2.0f : 1.0f;
  /* median of b (lower median of 8x1.0, 8x2.0) = 1.0: half the pixels far */
  CHECK_NEAR(kpcn_patch_flat_fraction(r, g, b, 4, 0, 0, 4, 0.05, 0.01), 0.5, 1e-12);
  /* Black patch: L(m) = 0, tol = 0.05*0.01; exact zeros are near. */
  memset(r, 0, sizeof r);
  memset(g, 0, sizeof g);
  memset(b, 0, sizeof b);
  CHECK_NEAR(kpcn_patch_flat_fraction(r, g, b, 4, 0, 0, 4, 0.05, 0.01), 1.0, 1e-12);
  /* A non-finite channel is never near, whichever channel holds it: a patch of an image with
   * an infinite red channel is kept, so the store writer's finiteness check names the channel
   * (a NaN difference in R or G was overwritten by the next channel's finite one, and such an
   * image had every patch culled, silently). */
  for (int c = 0; c < 3; c++) {
    float *ch[3] = {r, g, b};
    for (int i = 0; i < 16; i++)
      r[i] = g[i] = b[i] = 0.5f;
    for (int i = 0; i < 16; i++)
      ch[c][i] = INFINITY;
    CHECK_NEAR(kpcn_patch_flat_fraction(r, g, b, 4, 0, 0, 4, 0.05, 0.01), 0.0, 1e-12);
    ch[c][3] = NAN;
    CHECK_NEAR(kpcn_patch_flat_fraction(r, g, b, 4, 0, 0, 4, 0.05, 0.01), 0.0, 1e-12);
  }
}

static void test_select_culls_flat(void) {
  kpcn_aov_set *img = half_flat(128, 64);
  kpcn_patch_settings s;
  kpcn_patch_settings_defaults(&s);
  s.size = 16;
  s.count = 30;
  kpcn_patch_origin *o = NULL;
  int n = 0;
  kpcn_patch_stats st;
  CHECK(kpcn_patches_select(&o, &n, &st, img, NULL, &s) == KPCN_OK);
  CHECK(n == 30);
  CHECK(st.kept == 30 && st.candidates == st.kept + st.culled);
  CHECK(st.culled > 5); /* about half the candidates fall in the flat half */
  int ok = 1;
  for (int i = 0; i < n; i++)
    ok &= o[i].x + 16 > 64 && o[i].flat_frac < 0.9f;
  CHECK(ok); /* every kept patch overlaps the textured half */
  /* Determinism. */
  kpcn_patch_origin *o2 = NULL;
  int n2 = 0;
  CHECK(kpcn_patches_select(&o2, &n2, NULL, img, NULL, &s) == KPCN_OK);
  CHECK(n2 == n && memcmp(o, o2, sizeof *o * (size_t)n) == 0);
  free(o);
  free(o2);
  /* Culling disabled: flat patches kept too. */
  s.cull = 2.0;
  CHECK(kpcn_patches_select(&o, &n, &st, img, NULL, &s) == KPCN_OK);
  CHECK(st.culled == 0 && n == 30);
  int flat = 0;
  for (int i = 0; i < n; i++)
    flat += o[i].x + 16 <= 64;
  CHECK(flat > 3);
  free(o);
  /* Grid mode: stride 16 over 128x64 gives 8x4 candidates; left 4 columns flat. */
  s.cull = 0.9;
  s.count = 0;
  s.stride = 16;
  CHECK(kpcn_patches_select(&o, &n, &st, img, NULL, &s) == KPCN_OK);
  CHECK(st.candidates == 32 && st.culled == 16 && n == 16);
  free(o);
  /* Errors. */
  s.size = 100;
  CHECK(kpcn_patches_select(&o, &n, &st, img, NULL, &s) == KPCN_ERR_INVALID_ARGUMENT);
  kpcn_aov_destroy(img);
}

/* A reference decides flatness when given: a flat reference culls even if noisy is not. */
static void test_reference_decides(void) {
  kpcn_aov_set *noisy = half_flat(64, 32), *ref = NULL;
  kpcn_aov_create(&ref, 64, 32);
  kpcn_aov_add(ref, KPCN_BUF_COLOR, 0);
  for (size_t i = 0; i < 3 * kpcn_aov_plane_size(ref); i++)
    ref->buf[KPCN_BUF_COLOR][i] = 0.3f;
  kpcn_patch_settings s;
  kpcn_patch_settings_defaults(&s);
  s.size = 16;
  s.count = 5;
  kpcn_patch_origin *o = NULL;
  int n = -1;
  kpcn_patch_stats st;
  CHECK(kpcn_patches_select(&o, &n, &st, noisy, ref, &s) == KPCN_OK);
  CHECK(n == 0 && st.culled == st.candidates && st.candidates == 40);
  free(o);
  kpcn_aov_destroy(ref);
  kpcn_aov_create(&ref, 32, 32);
  CHECK(kpcn_patches_select(&o, &n, &st, noisy, ref, &s) == KPCN_ERR_SIZE_MISMATCH);
  kpcn_aov_destroy(ref);
  kpcn_aov_destroy(noisy);
}

static void test_importance(void) {
  kpcn_aov_set *img = half_flat(128, 64);
  kpcn_patch_settings s;
  kpcn_patch_settings_defaults(&s);
  s.size = 8;
  s.count = 200;
  s.cull = 2.0; /* isolate the sampling */
  s.importance = 1;
  kpcn_patch_origin *o = NULL;
  int n = 0;
  CHECK(kpcn_patches_select(&o, &n, NULL, img, NULL, &s) == KPCN_OK);
  int right = 0;
  for (int i = 0; i < n; i++)
    right += o[i].x >= 64;
  /* Variance 100x higher on the right: with the 10% floor, P(right) ~ 0.9. */
  CHECK(right > 150);
  free(o);
  kpcn_aov_destroy(img);
}

int main(void) {
  test_flat_fraction();
  test_select_culls_flat();
  test_reference_decides();
  test_importance();
  return kt_summary("augment_patches");
}
