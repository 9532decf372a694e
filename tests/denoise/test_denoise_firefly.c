/* kpcn_aov_bound_fireflies and the denoiser's use of it: a single-sample firefly at a partly
 * covered pixel is bounded to the documented value (computed here from the definition),
 * smooth images, well-sampled bright detail and bright clusters are left alone, the result is
 * equivariant to mirrors / rotations and to exposure, the denoiser applies it to a copy
 * (denoise(x) == denoise with it off of bound(x)), and bad arguments are refused. */
#include <stdlib.h>
#include <string.h>

#include "kpcn/augment.h"
#include "kpcn/denoise.h"
#include "synth.h"
#include "testutil.h"

#define EPS 0.00316f

/* A dim, well-sampled 24x24 wall: grey albedo 0.8, irradiance 0.05 with 1 % noise, relative
 * variance 1e-3, a little specular (the other buffers from synth_aov). */
static kpcn_aov_set *wall(unsigned seed) {
  kpcn_aov_set *a = synth_aov(24, 24, seed);
  if (!a) return NULL;
  const size_t P = kpcn_aov_plane_size(a);
  unsigned st = seed;
  for (size_t i = 0; i < P; i++) {
    float m = 0.0f;
    for (int c = 0; c < 3; c++) {
      const float alb = 0.8f, d = alb * 0.05f * (0.99f + 0.02f * kt_randf(&st));
      a->buf[KPCN_BUF_ALBEDO][c * P + i] = alb;
      a->buf[KPCN_BUF_DIFFUSE][c * P + i] = d;
      a->buf[KPCN_BUF_SPECULAR][c * P + i] = 0.002f;
      a->buf[KPCN_BUF_COLOR][c * P + i] = d + 0.002f;
      m += d / 3.0f;
    }
    a->var[KPCN_BUF_DIFFUSE][i] = 1e-3f * m * m;
  }
  return a;
}

/* Puts a diffuse value d (all channels) at pixel (x, y) with albedo alb and relative
 * variance rv. */
static void put(kpcn_aov_set *a, int x, int y, float d, float alb, float rv) {
  const size_t P = kpcn_aov_plane_size(a), i = (size_t)y * a->width + x;
  for (int c = 0; c < 3; c++) {
    a->buf[KPCN_BUF_ALBEDO][c * P + i] = alb;
    a->buf[KPCN_BUF_DIFFUSE][c * P + i] = d;
    a->buf[KPCN_BUF_COLOR][c * P + i] = d + a->buf[KPCN_BUF_SPECULAR][c * P + i];
  }
  a->var[KPCN_BUF_DIFFUSE][i] = rv * d * d;
}

static int same_planes(const kpcn_aov_set *a, const kpcn_aov_set *b) {
  const size_t P = kpcn_aov_plane_size(a);
  for (int k = 0; k < KPCN_BUF_COUNT; k++) {
    const size_t n = (size_t)kpcn_buffer_channels((kpcn_buffer)k) * P;
    if ((a->buf[k] == NULL) != (b->buf[k] == NULL)) return 0;
    if (a->buf[k] && memcmp(a->buf[k], b->buf[k], n * sizeof(float))) return 0;
    if (a->var[k] && memcmp(a->var[k], b->var[k], P * sizeof(float))) return 0;
  }
  return 1;
}

static double irradiance(const kpcn_aov_set *a, size_t i) {
  const size_t P = kpcn_aov_plane_size(a);
  double e = 0.0;
  for (int c = 0; c < 3; c++)
    e += a->buf[KPCN_BUF_DIFFUSE][c * P + i] / ((double)a->buf[KPCN_BUF_ALBEDO][c * P + i] + EPS);
  return e / 3.0;
}

static void test_untouched(void) {
  kpcn_aov_set *a = wall(1), *ref = NULL;
  CHECK(a && kpcn_aov_clone(&ref, a) == KPCN_OK);
  int n = -1;
  CHECK(kpcn_aov_bound_fireflies(a, 4.0f, EPS, 0.0, &n) == KPCN_OK && n == 0);
  CHECK(same_planes(a, ref));
  /* a bright pixel that many samples agree on (an emitter's edge seen in diffuse, a sharp
   * caustic at high spp): relative variance 0.01, left alone however bright */
  put(a, 7, 9, 5.0f, 0.8f, 0.01f);
  put(ref, 7, 9, 5.0f, 0.8f, 0.01f);
  CHECK(kpcn_aov_bound_fireflies(a, 4.0f, EPS, 0.0, &n) == KPCN_OK && n == 0);
  CHECK(same_planes(a, ref));
  /* a bright noisy 2x2 cluster: each pixel has bright neighbours, so none is isolated */
  for (int k = 0; k < 4; k++) {
    put(a, 12 + (k & 1), 12 + (k >> 1), 1.0f, 0.8f, 1.0f);
    put(ref, 12 + (k & 1), 12 + (k >> 1), 1.0f, 0.8f, 1.0f);
  }
  CHECK(kpcn_aov_bound_fireflies(a, 4.0f, EPS, 0.0, &n) == KPCN_OK && n == 0);
  CHECK(same_planes(a, ref));
  kpcn_aov_destroy(a);
  kpcn_aov_destroy(ref);
}

/* glossy-mirror v001 in small: one bright sample (1.93) in a pixel the wall covers a fifth of
 * (albedo 0.19); a single-sample value has relative variance ~1. */
static void test_partial_coverage(void) {
  kpcn_aov_set *a = wall(2), *in = NULL;
  put(a, 10, 6, 1.93f, 0.19f, 1.0f);
  CHECK(kpcn_aov_clone(&in, a) == KPCN_OK);
  double exposure = 0.0;
  CHECK(kpcn_aov_exposure(in, &exposure) == KPCN_OK && exposure > 0.0);
  const int W = a->width;
  const size_t P = kpcn_aov_plane_size(a), i = (size_t)6 * W + 10;
  double nb = 0.0;
  for (int dy = -1; dy <= 1; dy++)
    for (int dx = -1; dx <= 1; dx++)
      if (dx || dy) nb = fmax(nb, irradiance(in, (size_t)(6 + dy) * W + 10 + dx));
  const double bound = 4.0 * nb + 0.01 * exposure, e0 = irradiance(in, i);
  CHECK(e0 > 100.0 * nb);
  int n = -1;
  CHECK(kpcn_aov_bound_fireflies(a, 4.0f, EPS, 0.0, &n) == KPCN_OK && n == 1);
  CHECK_CLOSE(irradiance(a, i), bound, 1e-5, 0.0);
  const double s = bound / e0;
  for (int c = 0; c < 3; c++) {
    CHECK_CLOSE(a->buf[KPCN_BUF_DIFFUSE][c * P + i], 1.93 * s, 1e-5, 0.0);
    CHECK_CLOSE(a->buf[KPCN_BUF_COLOR][c * P + i],
                a->buf[KPCN_BUF_DIFFUSE][c * P + i] + a->buf[KPCN_BUF_SPECULAR][c * P + i], 1e-5,
                1e-7);
  }
  CHECK_CLOSE(a->var[KPCN_BUF_DIFFUSE][i], in->var[KPCN_BUF_DIFFUSE][i] * s * s, 1e-4, 0.0);
  /* everything else as it was */
  put(a, 10, 6, 1.93f, 0.19f, 1.0f);
  CHECK(same_planes(a, in));
  /* a ratio above the firefly's own leaves it */
  CHECK(kpcn_aov_bound_fireflies(a, (float)(1.01 * e0 / nb), EPS, 0.0, &n) == KPCN_OK && n == 0);
  kpcn_aov_destroy(a);
  kpcn_aov_destroy(in);
}

/* Many fireflies on the noisy synthetic image: bounding commutes with the ensemble's eight
 * transforms (bit for bit: every decision is per pixel over a symmetric neighbourhood) and
 * with a power-of-two exposure change. */
static void test_equivariance(void) {
  kpcn_aov_set *a = synth_aov(20, 14, 3);
  unsigned st = 9;
  for (int k = 0; k < 12; k++)
    put(a, (int)(kt_randf(&st) * 20) % 20, (int)(kt_randf(&st) * 14) % 14, 3.0f, 0.1f, 1.0f);
  kpcn_aov_set *b = NULL;
  CHECK(kpcn_aov_clone(&b, a) == KPCN_OK);
  int n = 0;
  CHECK(kpcn_aov_bound_fireflies(b, 4.0f, EPS, 0.0, &n) == KPCN_OK && n >= 6);
  for (int t = 1; t < KPCN_DENOISE_MAX_ENSEMBLE; t++) {
    kpcn_augment_xform x;
    kpcn_denoise_ensemble_xform(t, &x);
    kpcn_aov_set *ta = NULL, *tb = NULL;
    CHECK(kpcn_augment_aov(&ta, a, &x, 1) == KPCN_OK && kpcn_augment_aov(&tb, b, &x, 1) == KPCN_OK);
    int m = -1;
    CHECK(kpcn_aov_bound_fireflies(ta, 4.0f, EPS, 0.0, &m) == KPCN_OK && m == n);
    CHECK(same_planes(ta, tb));
    kpcn_aov_destroy(ta);
    kpcn_aov_destroy(tb);
  }
  /* exposure x 4: the same pixels, every value x 4 (variances x 16) */
  kpcn_aov_set *s = NULL;
  CHECK(kpcn_aov_clone(&s, a) == KPCN_OK);
  const size_t P = kpcn_aov_plane_size(a);
  const kpcn_buffer lit[3] = {KPCN_BUF_COLOR, KPCN_BUF_DIFFUSE, KPCN_BUF_SPECULAR};
  for (int k = 0; k < 3; k++) {
    for (size_t i = 0; i < 3 * P; i++)
      s->buf[lit[k]][i] *= 4.0f;
    for (size_t i = 0; i < P; i++)
      s->var[lit[k]][i] *= 16.0f;
  }
  int m = -1;
  CHECK(kpcn_aov_bound_fireflies(s, 4.0f, EPS, 0.0, &m) == KPCN_OK && m == n);
  int exact = 1;
  for (size_t i = 0; i < 3 * P; i++)
    exact &= s->buf[KPCN_BUF_DIFFUSE][i] == 4.0f * b->buf[KPCN_BUF_DIFFUSE][i];
  CHECK(exact);
  kpcn_aov_destroy(s);
  kpcn_aov_destroy(a);
  kpcn_aov_destroy(b);
}

static kpcn_status denoise(kpcn_model *m, const kpcn_aov_set *a, float firefly, float *out,
                           int *bounded) {
  kpcn_denoiser_options o;
  kpcn_denoiser_options_defaults(&o);
  if (firefly >= 0.0f) o.firefly = firefly;
  o.nthreads = 2;
  kpcn_denoiser *d = NULL;
  kpcn_status s = kpcn_denoiser_create_with_model(&d, m, &o);
  if (s == KPCN_OK) s = kpcn_denoiser_execute_aov(d, a, out);
  kpcn_denoise_stats st;
  if (s == KPCN_OK && bounded) {
    kpcn_denoiser_get_stats(d, &st);
    *bounded = st.fireflies;
  }
  kpcn_denoiser_destroy(d);
  return s;
}

static void test_denoiser(void) {
  kpcn_arch arch;
  kpcn_model *m = NULL;
  CHECK(kpcn_arch_preset("tiny", &arch) == KPCN_OK && kpcn_features_set_arch(&arch) == KPCN_OK);
  CHECK(kpcn_model_create(&arch, 5, &m) == KPCN_OK);
  kpcn_aov_set *a = wall(4), *in = NULL, *pre = NULL;
  put(a, 10, 6, 1.93f, 0.19f, 1.0f);
  put(a, 3, 17, 0.9f, 0.05f, 0.8f);
  CHECK(kpcn_aov_clone(&in, a) == KPCN_OK && kpcn_aov_clone(&pre, a) == KPCN_OK);
  int n = 0, nd = -1;
  CHECK(kpcn_aov_bound_fireflies(pre, KPCN_DENOISE_DEFAULT_FIREFLY, arch.eps, 0.0, &n) == KPCN_OK);
  CHECK(n == 2);
  const size_t N = 3 * kpcn_aov_plane_size(a);
  float *x = malloc(sizeof(float) * N), *y = malloc(sizeof(float) * N),
        *z = malloc(sizeof(float) * N);
  CHECK(denoise(m, a, -1.0f, x, &nd) == KPCN_OK && nd == 2); /* the default: on */
  CHECK(same_planes(a, in));                                 /* on a copy */
  CHECK(denoise(m, pre, 0.0f, y, NULL) == KPCN_OK);
  CHECK(memcmp(x, y, sizeof(float) * N) == 0);
  CHECK(denoise(m, a, 0.0f, z, &nd) == KPCN_OK && nd == 0); /* off: the firefly goes in */
  CHECK(memcmp(x, z, sizeof(float) * N) != 0);
  /* bad ratios are refused at create, with the option named */
  kpcn_denoiser_options o;
  kpcn_denoiser_options_defaults(&o);
  kpcn_denoiser *d = NULL;
  const float bad[3] = {0.5f, -1.0f, NAN};
  for (int k = 0; k < 3; k++) {
    o.firefly = bad[k];
    CHECK(kpcn_denoiser_create_with_model(&d, m, &o) == KPCN_ERR_INVALID_ARGUMENT && !d);
    CHECK(strstr(kpcn_last_error(), "firefly") != NULL);
  }
  /* the method and the baselines' options are ignored by create_with_model (denoise.h), so
   * also not refused: a baseline method with zeroed baseline options */
  kpcn_denoiser_options_defaults(&o);
  o.method = KPCN_DENOISE_BILATERAL;
  memset(&o.bilateral, 0, sizeof o.bilateral);
  CHECK(kpcn_denoiser_create_with_model(&d, m, &o) == KPCN_OK && d);
  kpcn_denoiser_destroy(d);
  /* switches are 0 or 1 (2 acted as 1), named; a failed create leaves *out NULL, a NULL
   * model included (it kept the caller's value), and names the argument */
  kpcn_denoiser_options_defaults(&o);
  o.bf16 = 2;
  d = (kpcn_denoiser *)&o;
  CHECK(kpcn_denoiser_create_with_model(&d, m, &o) == KPCN_ERR_INVALID_ARGUMENT && !d &&
        strstr(kpcn_last_error(), "bf16 2 must be 0 or 1"));
  o.bf16 = 0, o.direct_conv = -1;
  CHECK(kpcn_denoiser_create_with_model(&d, m, &o) == KPCN_ERR_INVALID_ARGUMENT &&
        strstr(kpcn_last_error(), "direct_conv -1 must be 0 or 1"));
  d = (kpcn_denoiser *)&o;
  CHECK(kpcn_denoiser_create_with_model(&d, NULL, NULL) == KPCN_ERR_INVALID_ARGUMENT && !d &&
        strstr(kpcn_last_error(), "model is NULL"));
  free(x);
  free(y);
  free(z);
  kpcn_aov_destroy(a);
  kpcn_aov_destroy(in);
  kpcn_aov_destroy(pre);
  kpcn_model_destroy(m);
}

/* A 1x1 image has no neighbour: nothing marks its pixel a firefly (the bound fell to the
 * floor, 0.01 x the exposure, and darkened it ~700-fold). */
static void test_single_pixel(void) {
  kpcn_aov_set *a = synth_aov(1, 1, 3), *b = NULL;
  put(a, 0, 0, 0.09f, 0.2f, 0.3f);
  CHECK(kpcn_aov_clone(&b, a) == KPCN_OK);
  int n = -1;
  CHECK(kpcn_aov_bound_fireflies(b, KPCN_DENOISE_DEFAULT_FIREFLY, EPS, 0.0, &n) == KPCN_OK);
  CHECK(n == 0 && same_planes(a, b));
  kpcn_aov_destroy(a);
  kpcn_aov_destroy(b);
}

/* The exposure scale a model asks for must be formable in float: an input near the float
 * limit (scale below FLT_MIN, which flushed to 0 and failed inside the features) is the
 * documented non-finite error; one so dim that cs^2 overflows is refused naming its
 * exposure, not denoised from Inf/NaN variances. */
static void test_exposure_range(void) {
  kpcn_arch arch;
  kpcn_model *m = NULL;
  CHECK(kpcn_arch_preset("tiny", &arch) == KPCN_OK && kpcn_features_set_arch(&arch) == KPCN_OK);
  CHECK(kpcn_model_create(&arch, 5, &m) == KPCN_OK);
  CHECK(kpcn_model_set_exposure(m, 0.25f) == KPCN_OK);
  const double level[2] = {5e37, 1e-18};
  const kpcn_status want[2] = {KPCN_ERR_NONFINITE, KPCN_ERR_INVALID_ARGUMENT};
  const char *msg[2] = {"near the float limit", "too dim"};
  for (int k = 0; k < 2; k++) {
    kpcn_aov_set *a = wall(8);
    const size_t P = kpcn_aov_plane_size(a);
    for (size_t i = 0; i < 3 * P; i++) {
      a->buf[KPCN_BUF_COLOR][i] = a->buf[KPCN_BUF_DIFFUSE][i] = (float)level[k];
      a->buf[KPCN_BUF_SPECULAR][i] = 0.0f;
    }
    for (int b = 0; b < KPCN_BUF_COUNT; b++)
      if (a->var[b]) memset(a->var[b], 0, sizeof(float) * P);
    float *out = malloc(sizeof(float) * 3 * P);
    CHECK(denoise(m, a, 0.0f, out, NULL) == want[k]);
    CHECK(strstr(kpcn_last_error(), msg[k]) != NULL);
    free(out);
    kpcn_aov_destroy(a);
  }
  kpcn_model_destroy(m);
}

static void test_errors(void) {
  kpcn_aov_set *a = wall(6);
  int n = 7;
  CHECK(kpcn_aov_bound_fireflies(a, 0.9f, EPS, 0.0, &n) == KPCN_ERR_INVALID_ARGUMENT && n == 0);
  CHECK(kpcn_aov_bound_fireflies(a, 4.0f, 0.0f, 0.0, NULL) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(kpcn_aov_bound_fireflies(NULL, 4.0f, EPS, 0.0, NULL) == KPCN_ERR_INVALID_ARGUMENT);
  free(a->var[KPCN_BUF_DIFFUSE]);
  a->var[KPCN_BUF_DIFFUSE] = NULL;
  CHECK(kpcn_aov_bound_fireflies(a, 4.0f, EPS, 0.0, NULL) == KPCN_ERR_MISSING_CHANNEL);
  CHECK(strstr(kpcn_last_error(), "diffuse.var") != NULL);
  kpcn_aov_destroy(a);
}

int main(void) {
  test_single_pixel();
  test_exposure_range();
  test_untouched();
  test_partial_coverage();
  test_equivariance();
  test_denoiser();
  test_errors();
  return kt_summary("test_denoise_firefly");
}
