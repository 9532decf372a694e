/* The predicted-kernel export (kpcn_denoiser_kernels_aov): the exported weights and
 * preprocessed colour, applied by a naive clamped weighted sum as many times as the model's
 * kernel passes and recombined as documented, reproduce the denoiser's own result; every kernel
 * is normalised; tiles do not change it; what cannot be exported is refused by name. */
#include <stdlib.h>
#include <string.h>

#include "kpcn/denoise.h"
#include "model_fixture.h"
#include "synth.h"
#include "testutil.h"

static kpcn_denoiser *make_denoiser(kpcn_model *m, int tile, int ensemble) {
  kpcn_denoiser_options o;
  kpcn_denoiser_options_defaults(&o);
  o.tile = tile;
  o.ensemble = ensemble;
  o.nthreads = 2;
  kpcn_denoiser *d = NULL;
  if (kpcn_denoiser_create_with_model(&d, m, &o) != KPCN_OK)
    fprintf(stderr, "denoiser_create: %s\n", kpcn_last_error());
  return d;
}

/* passes x: f <- sum_t w[t] f(p + off(t)), clamped reads, in double: res [3][H][W] */
static void apply_kernels(const float *w, const float *pre, int K, int passes, int W, int H,
                          double *res) {
  const size_t P = (size_t)W * H;
  double *src = malloc(sizeof(double) * 3 * P);
  for (size_t i = 0; i < 3 * P; i++)
    res[i] = pre[i];
  for (int pass = 0; pass < passes; pass++) {
    memcpy(src, res, sizeof(double) * 3 * P);
    for (int y = 0; y < H; y++)
      for (int x = 0; x < W; x++) {
        const size_t i = (size_t)y * W + x;
        double acc[3] = {0, 0, 0};
        for (int t = 0; t < K * K; t++) {
          int yy = y + t / K - K / 2, xx = x + t % K - K / 2;
          yy = yy < 0 ? 0 : yy >= H ? H - 1 : yy;
          xx = xx < 0 ? 0 : xx >= W ? W - 1 : xx;
          for (int c = 0; c < 3; c++)
            acc[c] += (double)w[(size_t)t * P + i] * src[(size_t)c * P + (size_t)yy * W + xx];
        }
        for (int c = 0; c < 3; c++)
          res[(size_t)c * P + i] = acc[c];
      }
  }
  free(src);
}

static void test_reproduces_denoiser(int passes) {
  kpcn_model *m = make_model_chain(17, passes, 0);
  CHECK(m != NULL);
  if (!m) return;
  kpcn_aov_set *a = synth_aov(31, 22, 5);
  const int W = a->width, H = a->height;
  const size_t P = kpcn_aov_plane_size(a);
  kpcn_denoiser *d = make_denoiser(m, 4096, 1);
  CHECK(d != NULL);
  int K = 0, np = 0;
  float eps = 0.0f;
  CHECK(kpcn_denoiser_kernel_info(d, &K, &np, &eps) == KPCN_OK);
  CHECK(K == kpcn_model_arch(m)->kernel_size && np == passes && eps == kpcn_model_arch(m)->eps);
  float *out = malloc(sizeof(float) * 3 * P), *again = malloc(sizeof(float) * 3 * P);
  float *w[2], *pre[2];
  double *res[2];
  CHECK(kpcn_denoiser_execute_aov(d, a, out) == KPCN_OK);
  kpcn_denoise_stats st;
  kpcn_denoiser_get_stats(d, &st);
  const double scale = st.exposure_scale;
  CHECK(scale != 1.0); /* the fixture's model records an exposure: the scale is exercised */
  for (int b = 0; b < 2; b++) {
    w[b] = malloc(sizeof(float) * (size_t)K * K * P);
    pre[b] = malloc(sizeof(float) * 3 * P);
    res[b] = malloc(sizeof(double) * 3 * P);
    CHECK(kpcn_denoiser_kernels_aov(d, a, b, w[b], pre[b]) == KPCN_OK);
    kpcn_denoiser_get_stats(d, &st);
    CHECK(st.exposure_scale == scale);
    apply_kernels(w[b], pre[b], K, passes, W, H, res[b]);
  }
  /* every kernel: weights >= 0 summing to 1 */
  double worst_sum = 0;
  int negative = 0;
  for (int b = 0; b < 2; b++)
    for (size_t i = 0; i < P; i++) {
      double sum = 0;
      for (int t = 0; t < K * K; t++) {
        negative += w[b][(size_t)t * P + i] < 0.0f;
        sum += w[b][(size_t)t * P + i];
      }
      worst_sum = kt_worst(worst_sum, fabs(sum - 1.0));
    }
  printf("%d pass(es): kernels' |sum - 1| <= %.3g, %d negative weights\n", passes, worst_sum,
         negative);
  CHECK(worst_sum < 1e-5);
  CHECK(negative == 0);
  /* recombined as kpcn/denoise.h documents: the denoiser's own result */
  const float *alb = a->buf[KPCN_BUF_ALBEDO];
  double worst = 0;
  for (size_t i = 0; i < 3 * P; i++) {
    const double c = (res[0][i] * ((double)alb[i] + eps) + expm1(res[1][i])) / scale;
    worst = kt_worst(worst, fabs(c - out[i]) / (1e-3 + fabs(c)));
  }
  printf("%d pass(es): exported kernels applied and recombined vs the denoiser: max rel err %.3g\n",
         passes, worst);
  CHECK(worst < 1e-5);
  /* the kernels in tiles of 8 are the untiled ones; the denoiser is unchanged by the export */
  kpcn_denoiser *dt = make_denoiser(m, 8, 1);
  float *wt = malloc(sizeof(float) * (size_t)K * K * P);
  CHECK(dt && kpcn_denoiser_kernels_aov(dt, a, 1, wt, NULL) == KPCN_OK);
  double e = max_rel(wt, w[1], (size_t)K * K * P);
  printf("%d pass(es): specular kernels in tiles of 8 vs untiled: max rel diff %.3g\n", passes, e);
  CHECK(e < 2e-6);
  CHECK(kpcn_denoiser_execute_aov(d, a, again) == KPCN_OK);
  CHECK(memcmp(again, out, sizeof(float) * 3 * P) == 0);
  kpcn_denoiser_destroy(dt);
  free(wt);
  for (int b = 0; b < 2; b++) {
    free(w[b]);
    free(pre[b]);
    free(res[b]);
  }
  free(out);
  free(again);
  kpcn_denoiser_destroy(d);
  kpcn_aov_destroy(a);
  kpcn_model_destroy(m);
}

static void expect_error(kpcn_status got, kpcn_status want, const char *needle) {
  CHECK(got == want);
  const char *msg = kpcn_last_error();
  printf("refused (%d): %s\n", (int)got, msg);
  CHECK(strstr(msg, needle) != NULL);
}

static void test_refusals(void) {
  kpcn_model *m = make_model_chain(3, 1, 0), *msw = make_model_chain(3, 1, 1);
  CHECK(m && msw);
  if (!m || !msw) return;
  kpcn_aov_set *a = synth_aov(12, 10, 2);
  const size_t P = kpcn_aov_plane_size(a);
  const int K = kpcn_model_arch(m)->kernel_size;
  float *w = malloc(sizeof(float) * (size_t)K * K * P);
  kpcn_denoiser *d = make_denoiser(m, 0, 1), *de = make_denoiser(m, 0, 2);
  kpcn_denoiser *ds = make_denoiser(msw, 0, 1);
  expect_error(kpcn_denoiser_kernels_aov(d, a, 2, w, NULL), KPCN_ERR_INVALID_ARGUMENT, "branch 2");
  expect_error(kpcn_denoiser_kernels_aov(d, a, 0, NULL, NULL), KPCN_ERR_INVALID_ARGUMENT, "NULL");
  expect_error(kpcn_denoiser_kernels_aov(de, a, 0, w, NULL), KPCN_ERR_INVALID_ARGUMENT,
               "ensemble = 2");
  expect_error(kpcn_denoiser_kernels_aov(ds, a, 0, w, NULL), KPCN_ERR_UNSUPPORTED, "source_weight");
  kpcn_denoiser_options o;
  kpcn_denoiser_options_defaults(&o);
  o.method = KPCN_DENOISE_NLMEANS;
  kpcn_denoiser *dn = NULL;
  CHECK(kpcn_denoiser_create(&dn, &o) == KPCN_OK);
  int k = 0;
  expect_error(kpcn_denoiser_kernel_info(dn, &k, NULL, NULL), KPCN_ERR_INVALID_ARGUMENT, "nlmeans");
  expect_error(kpcn_denoiser_kernels_aov(dn, a, 0, w, NULL), KPCN_ERR_INVALID_ARGUMENT,
               "denoiser_kernels: only the KPCN predicts kernels, not the nlmeans");
  /* a missing buffer is named as an execute names it */
  kpcn_aov_set *b = synth_aov(12, 10, 2);
  free(b->var[KPCN_BUF_SPECULAR]);
  b->var[KPCN_BUF_SPECULAR] = NULL;
  expect_error(kpcn_denoiser_kernels_aov(d, b, 1, w, NULL), KPCN_ERR_MISSING_CHANNEL,
               "specular.var");
  kpcn_aov_destroy(b);
  kpcn_denoiser_destroy(dn);
  kpcn_denoiser_destroy(d);
  kpcn_denoiser_destroy(de);
  kpcn_denoiser_destroy(ds);
  free(w);
  kpcn_aov_destroy(a);
  kpcn_model_destroy(m);
  kpcn_model_destroy(msw);
}

int main(void) {
  test_reproduces_denoiser(1);
  test_reproduces_denoiser(2);
  test_refusals();
  return kt_summary("test_denoise_kernels");
}
