/* Classical baselines: quality on the Tungsten Cornell pair (an independent renderer's
 * noisy/reference images), agreement with naive double-precision reference filters,
 * thread-count determinism, the strided C API, missing buffers named, cancellation. */
#include <stdlib.h>
#include <string.h>

#include "kpcn/denoise.h"
#include "kpcn/exr.h"
#include "synth.h"
#include "testutil.h"

static double relmse(const float *x, const float *ref, size_t n) {
  double s = 0;
  for (size_t i = 0; i < n; i++) {
    double d = (double)x[i] - ref[i];
    s += d * d / ((double)ref[i] * ref[i] + 0.01);
  }
  return s / (double)n;
}

static kpcn_status run(const kpcn_aov_set *a, const kpcn_denoiser_options *o, float *out) {
  kpcn_denoiser *d = NULL;
  kpcn_status s = kpcn_denoiser_create(&d, o);
  if (s == KPCN_OK) s = kpcn_denoiser_execute_aov(d, a, out);
  kpcn_denoiser_destroy(d);
  return s;
}

/* Reference filters: the documented weight formulas evaluated naively in double. The
 * colour distance's floor is 1e-10 times the image's mean |colour| squared. */
static double color_floor(const kpcn_aov_set *a) {
  size_t P = kpcn_aov_plane_size(a);
  double m = 0;
  for (size_t i = 0; i < 3 * P; i++)
    m += fabs(a->buf[KPCN_BUF_COLOR][i]);
  m /= 3.0 * (double)P;
  return 1e-10 * m * m;
}
static double cdist(const kpcn_aov_set *a, const kpcn_baseline_params *p, size_t i, size_t j) {
  size_t P = kpcn_aov_plane_size(a);
  const float *c = a->buf[KPCN_BUF_COLOR], *v = a->var[KPCN_BUF_COLOR];
  double s = 0;
  for (int k = 0; k < 3; k++)
    s += pow((double)c[k * P + i] - c[k * P + j], 2);
  double vmin = fmin(v[i], v[j]);
  return (s / 3 - (v[i] + vmin)) /
         (color_floor(a) + (double)p->k_color * p->k_color * (v[i] + v[j]));
}
static double fdist(const kpcn_aov_set *a, const kpcn_baseline_params *p,
                    const kpcn_features_norm *n, size_t i, size_t j) {
  size_t P = kpcn_aov_plane_size(a);
  double sn = 0, sa = 0,
         dz = ((double)a->buf[KPCN_BUF_DEPTH][i] - a->buf[KPCN_BUF_DEPTH][j]) * n->depth_scale;
  for (int k = 0; k < 3; k++) {
    sn += pow((double)a->buf[KPCN_BUF_NORMAL][k * P + i] - a->buf[KPCN_BUF_NORMAL][k * P + j], 2);
    sa += pow((double)a->buf[KPCN_BUF_ALBEDO][k * P + i] - a->buf[KPCN_BUF_ALBEDO][k * P + j], 2);
  }
  return sn / (2.0 * p->sigma_normal * p->sigma_normal) +
         sa / (2.0 * p->sigma_albedo * p->sigma_albedo) +
         dz * dz / (2.0 * p->sigma_depth * p->sigma_depth);
}
static int cl(int v, int n) { return v < 0 ? 0 : v >= n ? n - 1 : v; }

static void ref_filter(const kpcn_aov_set *a, const kpcn_baseline_params *p, int nlm, double *out) {
  int W = a->width, H = a->height, r = p->radius, f = p->patch_radius;
  size_t P = kpcn_aov_plane_size(a);
  kpcn_features_norm n;
  kpcn_features_norm_compute(a, &n);
  for (int y = 0; y < H; y++)
    for (int x = 0; x < W; x++) {
      size_t i = (size_t)y * W + x;
      double acc[3] = {0, 0, 0}, ws = 0;
      for (int qy = y - r; qy <= y + r; qy++)
        for (int qx = x - r; qx <= x + r; qx++) {
          if (qx < 0 || qy < 0 || qx >= W || qy >= H) continue;
          size_t j = (size_t)qy * W + qx;
          double e;
          if (nlm) { /* patch mean over pixels inside the image, partner clamped */
            double s = 0;
            int cnt = 0;
            for (int py = y - f; py <= y + f; py++)
              for (int px = x - f; px <= x + f; px++) {
                if (px < 0 || py < 0 || px >= W || py >= H) continue;
                size_t pi = (size_t)py * W + px;
                size_t pj = (size_t)cl(py + qy - y, H) * W + cl(px + qx - x, W);
                s += cdist(a, p, pi, pj);
                cnt++;
              }
            e = fmax(0.0, s / cnt);
          } else {
            e = ((qx - x) * (qx - x) + (qy - y) * (qy - y)) /
                    (2.0 * p->sigma_spatial * p->sigma_spatial) +
                fmax(0.0, cdist(a, p, i, j));
          }
          double w = exp(-(e + fdist(a, p, &n, i, j)));
          ws += w;
          for (int c = 0; c < 3; c++)
            acc[c] += w * a->buf[KPCN_BUF_COLOR][c * P + j];
        }
      for (int c = 0; c < 3; c++)
        out[c * P + i] = acc[c] / ws;
    }
}

static void test_against_reference(void) {
  /* 70x66 crosses the NL-means 64-pixel tile boundary in both directions */
  kpcn_aov_set *a = synth_aov(70, 66, 11);
  size_t P = kpcn_aov_plane_size(a);
  kpcn_denoiser_options o;
  kpcn_denoiser_options_defaults(&o);
  o.bilateral.radius = 3;
  o.nlmeans.radius = 3;
  o.nlmeans.patch_radius = 2;
  float *out = malloc(sizeof(float) * 3 * P), *out1 = malloc(sizeof(float) * 3 * P);
  double *ref = malloc(sizeof(double) * 3 * P);
  for (int m = KPCN_DENOISE_BILATERAL; m <= KPCN_DENOISE_NLMEANS; m++) {
    o.method = m;
    o.nthreads = 2;
    CHECK(run(a, &o, out) == KPCN_OK);
    ref_filter(a, m == KPCN_DENOISE_NLMEANS ? &o.nlmeans : &o.bilateral, m == KPCN_DENOISE_NLMEANS,
               ref);
    double worst = 0;
    for (size_t i = 0; i < 3 * P; i++)
      worst = kt_worst(worst, fabs(out[i] - ref[i]) / (1e-3 + fabs(ref[i])));
    CHECK(worst < 1e-4);
    if (worst >= 1e-4) fprintf(stderr, "method %d: worst rel err %g vs reference\n", m, worst);
    o.nthreads = 1;
    CHECK(run(a, &o, out1) == KPCN_OK);
    CHECK(memcmp(out, out1, sizeof(float) * 3 * P) == 0);
  }
  free(out);
  free(out1);
  free(ref);
  kpcn_aov_destroy(a);
}

/* The filters are exposure-invariant: a render scaled by 2^-15 (its variances by 2^-30, all
 * exact in float) gives the same result scaled by 2^-15. With the floor fixed at 1e-10 the
 * NL-means result differed by up to 6x per pixel (the floor outweighed variances < 1e-10). */
static void test_exposure_invariance(void) {
  kpcn_aov_set *a = synth_aov(40, 36, 5), *b = NULL;
  CHECK(kpcn_aov_clone(&b, a) == KPCN_OK);
  if (!b) return;
  size_t P = kpcn_aov_plane_size(a);
  const float k = 0x1p-15f;
  for (int buf = KPCN_BUF_COLOR; buf <= KPCN_BUF_SPECULAR; buf++) {
    if (b->buf[buf])
      for (size_t i = 0; i < 3 * P; i++)
        b->buf[buf][i] *= k;
    if (b->var[buf])
      for (size_t i = 0; i < P; i++)
        b->var[buf][i] *= k * k;
  }
  kpcn_denoiser_options o;
  kpcn_denoiser_options_defaults(&o);
  o.nthreads = 2;
  float *oa = malloc(sizeof(float) * 3 * P), *ob = malloc(sizeof(float) * 3 * P);
  for (int m = KPCN_DENOISE_BILATERAL; m <= KPCN_DENOISE_NLMEANS; m++) {
    o.method = m;
    CHECK(run(a, &o, oa) == KPCN_OK);
    CHECK(run(b, &o, ob) == KPCN_OK);
    double worst = 0;
    for (size_t i = 0; i < 3 * P; i++)
      worst = kt_worst(worst, fabs(ob[i] / k - oa[i]) / (1e-6 + fabs(oa[i])));
    if (worst > 1e-6) fprintf(stderr, "method %d: scaled result differs by %g\n", m, worst);
    CHECK(worst <= 1e-6);
  }
  free(oa);
  free(ob);
  kpcn_aov_destroy(a);
  kpcn_aov_destroy(b);
}

static int g_calls;
static int cancel_at_second(void *user, double f) {
  (void)user;
  (void)f;
  return ++g_calls >= 2;
}

static void test_errors_and_cancel(void) {
  kpcn_aov_set *a = synth_aov(80, 70, 5);
  size_t P = kpcn_aov_plane_size(a);
  float *out = malloc(sizeof(float) * 3 * P);
  kpcn_denoiser_options o;
  kpcn_denoiser_options_defaults(&o);
  for (int m = KPCN_DENOISE_BILATERAL; m <= KPCN_DENOISE_NLMEANS; m++) {
    o.method = m;
    kpcn_denoiser *d = NULL;
    CHECK(kpcn_denoiser_create(&d, &o) == KPCN_OK);
    g_calls = 0;
    kpcn_denoiser_set_progress(d, cancel_at_second, NULL);
    CHECK(kpcn_denoiser_execute_aov(d, a, out) == KPCN_ERR_CANCELLED);
    CHECK(g_calls == 2);
    kpcn_denoiser_destroy(d);
  }
  /* missing normal is named; disabling the normal guide makes it optional */
  float *nb = a->buf[KPCN_BUF_NORMAL];
  a->buf[KPCN_BUF_NORMAL] = NULL;
  o.method = KPCN_DENOISE_NLMEANS;
  CHECK(run(a, &o, out) == KPCN_ERR_MISSING_CHANNEL);
  CHECK(strstr(kpcn_last_error(), "normal") != NULL);
  o.nlmeans.sigma_normal = 0;
  CHECK(run(a, &o, out) == KPCN_OK);
  a->buf[KPCN_BUF_NORMAL] = nb;
  free(a->var[KPCN_BUF_COLOR]);
  a->var[KPCN_BUF_COLOR] = NULL;
  o.method = KPCN_DENOISE_BILATERAL;
  CHECK(run(a, &o, out) == KPCN_ERR_MISSING_CHANNEL);
  CHECK(strstr(kpcn_last_error(), "color.var") != NULL);
  o.method = KPCN_DENOISE_KPCN;
  kpcn_denoiser *d = NULL;
  CHECK(kpcn_denoiser_create(&d, &o) == KPCN_ERR_INVALID_ARGUMENT); /* no model path */
  CHECK(strstr(kpcn_last_error(), "model") != NULL);
  free(out);
  kpcn_aov_destroy(a);
}

/* Quality on the Tungsten Cornell pair, through the strided API with interleaved inputs. */
static void test_cornell(void) {
  char np[512], rp[512];
  snprintf(np, sizeof np, "%s/tungsten-cornell/noisy_16spp.exr", KPCN_TESTDATA);
  snprintf(rp, sizeof rp, "%s/tungsten-cornell/reference_2048spp.exr", KPCN_TESTDATA);
  kpcn_aov_set *a = NULL, *r = NULL;
  CHECK(kpcn_exr_read_aov(np, &a) == KPCN_OK);
  CHECK(kpcn_exr_read_aov(rp, &r) == KPCN_OK);
  if (!a || !r) return;
  const int W = a->width, H = a->height;
  const size_t P = kpcn_aov_plane_size(a);
  const float *ref = r->buf[KPCN_BUF_COLOR];
  double noisy = relmse(a->buf[KPCN_BUF_COLOR], ref, 3 * P);
  CHECK_NEAR(noisy, 1.06e-2, 0.01e-2); /* README figure: the data is what we think */

  /* interleaved copies: RGB + var as 4 floats per pixel, features packed */
  float *cv = malloc(sizeof(float) * 4 * P), *nb = malloc(sizeof(float) * 3 * P),
        *ab = malloc(sizeof(float) * 3 * P), *out = malloc(sizeof(float) * 3 * P),
        *pl = malloc(sizeof(float) * 3 * P);
  for (size_t i = 0; i < P; i++) {
    for (int c = 0; c < 3; c++) {
      cv[4 * i + c] = a->buf[KPCN_BUF_COLOR][c * P + i];
      nb[3 * i + c] = a->buf[KPCN_BUF_NORMAL][c * P + i];
      ab[3 * i + c] = a->buf[KPCN_BUF_ALBEDO][c * P + i];
    }
    cv[4 * i + 3] = a->var[KPCN_BUF_COLOR][i];
  }
  /* measured (2 threads): bilateral 1.16e-3, nlmeans 0.90e-3 vs noisy 1.06e-2; floors
   * 2.0e-3 (5.3x) and 1.5e-3 (7x) leave room for float/ordering changes yet fail if a
   * guide or the variance normalisation breaks (colour-only bilateral gives ~2.4e-3 at
   * k=1, no filtering 1.06e-2). */
  const double floor_[3] = {0, 2.0e-3, 1.5e-3};
  for (int m = KPCN_DENOISE_BILATERAL; m <= KPCN_DENOISE_NLMEANS; m++) {
    kpcn_denoiser_options o;
    kpcn_denoiser_options_defaults(&o);
    o.method = m;
    kpcn_denoiser *d = NULL;
    CHECK(kpcn_denoiser_create(&d, &o) == KPCN_OK);
    CHECK(kpcn_denoiser_set_buffer(d, "color", cv, W, H, 4 * sizeof(float), 0) == KPCN_OK);
    CHECK(kpcn_denoiser_set_buffer(d, "color.var", cv + 3, W, H, 4 * sizeof(float), 0) == KPCN_OK);
    CHECK(kpcn_denoiser_set_buffer(d, "normal", nb, W, H, 0, 0) == KPCN_OK);
    CHECK(kpcn_denoiser_set_buffer(d, "albedo", ab, W, H, 0, 0) == KPCN_OK);
    /* executing without depth fails naming it */
    CHECK(kpcn_denoiser_execute(d, out, W, H, 0, 0) == KPCN_ERR_MISSING_CHANNEL);
    CHECK(strstr(kpcn_last_error(), "depth") != NULL);
    CHECK(kpcn_denoiser_set_buffer(d, "depth", a->buf[KPCN_BUF_DEPTH], W, H, 0, 0) == KPCN_OK);
    CHECK(kpcn_denoiser_set_buffer(d, "specular.R", ab, W, H, 0, 0) == KPCN_ERR_INVALID_ARGUMENT);
    CHECK(kpcn_denoiser_execute(d, out, W, H, 0, 0) == KPCN_OK);
    CHECK(kpcn_denoiser_execute(d, out, W + 1, H, 0, 0) == KPCN_ERR_SIZE_MISMATCH);
    kpcn_denoiser_destroy(d);
    /* same as the planar path */
    kpcn_image *img = NULL;
    CHECK(kpcn_denoise_aov(a, &o, &img) == KPCN_OK);
    int diff = 0;
    for (size_t i = 0; i < P; i++)
      for (int c = 0; c < 3; c++)
        diff += out[3 * i + c] != img->data[c * P + i];
    CHECK(diff == 0);
    for (size_t i = 0; i < 3 * P; i++)
      pl[i] = img->data[i];
    double e = relmse(pl, ref, 3 * P);
    printf("%s: relMSE %.4g (noisy %.4g)\n", m == 1 ? "bilateral" : "nlmeans", e, noisy);
    CHECK(e < floor_[m]);
    kpcn_image_destroy(img);
  }
  free(cv);
  free(nb);
  free(ab);
  free(out);
  free(pl);
  kpcn_aov_destroy(a);
  kpcn_aov_destroy(r);
}

int main(void) {
  test_against_reference();
  test_exposure_invariance();
  test_errors_and_cancel();
  test_cornell();
  return kt_summary("test_denoise_baselines");
}
