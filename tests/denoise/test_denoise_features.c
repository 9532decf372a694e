/* Feature preprocessing (kpcn/denoise.h §1) against a naive double-precision reference
 * written from the documented formulas; region == crop; patch inputs with the full
 * image's norm; inverse transforms and the recombination's derivatives by finite
 * differences; missing buffers named. */
#include <float.h>
#include <limits.h>
#include <stdlib.h>
#include <string.h>

#include "kpcn/denoise.h"
#include "synth.h"
#include "testutil.h"

static const float EPS = 0.01f;

/* Naive reference of feature channel ch at (x, y), straight from the header comment. */
static double pre(const kpcn_aov_set *a, int branch, double cs, int c, int x, int y) {
  size_t P = kpcn_aov_plane_size(a), i = (size_t)y * a->width + x;
  if (branch == KPCN_BRANCH_DIFFUSE)
    return cs * a->buf[KPCN_BUF_DIFFUSE][c * P + i] /
           ((double)a->buf[KPCN_BUF_ALBEDO][c * P + i] + EPS);
  double v = cs * a->buf[KPCN_BUF_SPECULAR][c * P + i];
  return log(1.0 + (v > 0 ? v : 0));
}
static double gsrc(const kpcn_aov_set *a, int branch, const kpcn_features_norm *n, int g, int x,
                   int y) {
  size_t P = kpcn_aov_plane_size(a), i = (size_t)y * a->width + x;
  if (g < 3) return pre(a, branch, n->color_scale, g, x, y);
  if (g < 6) return a->buf[KPCN_BUF_NORMAL][(g - 3) * P + i];
  if (g < 9) return a->buf[KPCN_BUF_ALBEDO][(g - 6) * P + i];
  return ((double)a->buf[KPCN_BUF_DEPTH][i] - n->depth_offset) * n->depth_scale;
}
static int clampi(int v, int lo, int hi) { return v < lo ? lo : v > hi ? hi : v; }

static double ref_feature(const kpcn_aov_set *a, int branch, const kpcn_features_norm *n, int ch,
                          int x, int y) {
  size_t P = kpcn_aov_plane_size(a), i = (size_t)y * a->width + x;
  int W = a->width, H = a->height;
  if (ch < 3) return pre(a, branch, n->color_scale, ch, x, y);
  if (ch == 3) {
    kpcn_buffer cb = branch == KPCN_BRANCH_DIFFUSE ? KPCN_BUF_DIFFUSE : KPCN_BUF_SPECULAR;
    const double cs = n->color_scale;
    double s = 0;
    for (int c = 0; c < 3; c++) {
      double d = branch == KPCN_BRANCH_DIFFUSE ? a->buf[KPCN_BUF_ALBEDO][c * P + i] + (double)EPS
                                               : 1.0 + fmax(0.0, cs * a->buf[cb][c * P + i]);
      s += 1.0 / (d * d);
    }
    return cs * cs * a->var[cb][i] * s / 3.0;
  }
  if (ch < 7) return a->buf[KPCN_BUF_NORMAL][(ch - 4) * P + i];
  if (ch == 7) return a->var[KPCN_BUF_NORMAL][i];
  if (ch < 11) return a->buf[KPCN_BUF_ALBEDO][(ch - 8) * P + i];
  if (ch == 11) return a->var[KPCN_BUF_ALBEDO][i];
  if (ch == 12) return gsrc(a, branch, n, 9, x, y);
  if (ch == 13) return a->var[KPCN_BUF_DEPTH][i] * (double)n->depth_scale * n->depth_scale;
  if (ch == 14) return a->buf[KPCN_BUF_VISIBILITY][i];
  if (ch == 15) return a->var[KPCN_BUF_VISIBILITY][i];
  int g = (ch - 16) % 10, dir = (ch - 16) / 10;
  if (dir == 0)
    return 0.5 * (gsrc(a, branch, n, g, clampi(x + 1, 0, W - 1), y) -
                  gsrc(a, branch, n, g, clampi(x - 1, 0, W - 1), y));
  return 0.5 * (gsrc(a, branch, n, g, x, clampi(y + 1, 0, H - 1)) -
                gsrc(a, branch, n, g, x, clampi(y - 1, 0, H - 1)));
}

/* Copy of the rectangle (x0,y0,w,h) of a as a new set (a training patch). */
static kpcn_aov_set *crop(const kpcn_aov_set *a, int x0, int y0, int w, int h) {
  kpcn_aov_set *o = NULL;
  if (kpcn_aov_create(&o, w, h) != KPCN_OK) return NULL;
  size_t P = kpcn_aov_plane_size(a), Q = (size_t)w * h;
  for (int b = 0; b < KPCN_BUF_COUNT; b++) {
    if (!a->buf[b]) continue;
    kpcn_aov_add(o, (kpcn_buffer)b, a->var[b] != NULL);
    int nc = kpcn_buffer_channels((kpcn_buffer)b);
    for (int y = 0; y < h; y++)
      for (int x = 0; x < w; x++) {
        size_t i = (size_t)(y + y0) * a->width + x + x0, j = (size_t)y * w + x;
        for (int c = 0; c < nc; c++)
          o->buf[b][c * Q + j] = a->buf[b][c * P + i];
        if (a->var[b]) o->var[b][j] = a->var[b][i];
      }
  }
  return o;
}

static void test_names(void) {
  const char *names[KPCN_FEATURES_COUNT];
  CHECK(kpcn_features_channel_names(KPCN_BRANCH_DIFFUSE, names, KPCN_FEATURES_COUNT) == 36);
  CHECK(kpcn_features_count(KPCN_BRANCH_SPECULAR) == 36);
  CHECK(kpcn_features_count(7) == -1);
  CHECK(strcmp(names[0], "color.R") == 0 && strcmp(names[3], "color.var") == 0);
  CHECK(strcmp(names[12], "Z") == 0 && strcmp(names[15], "visibility.var") == 0);
  CHECK(strcmp(names[16], "dx.color.R") == 0 && strcmp(names[25], "dx.Z") == 0);
  CHECK(strcmp(names[26], "dy.color.R") == 0 && strcmp(names[35], "dy.Z") == 0);
  /* arch round trip: the list written into a preset is accepted, a changed one is not */
  kpcn_arch arch;
  CHECK(kpcn_arch_preset("tiny", &arch) == KPCN_OK);
  CHECK(kpcn_features_check_arch(&arch) != KPCN_OK); /* presets carry no inputs */
  CHECK(kpcn_features_set_arch(&arch) == KPCN_OK);
  CHECK(kpcn_features_check_arch(&arch) == KPCN_OK);
  snprintf(arch.inputs[20], sizeof arch.inputs[20], "dx.N.W");
  CHECK(kpcn_features_check_arch(&arch) == KPCN_ERR_UNSUPPORTED);
  CHECK(strstr(kpcn_last_error(), "dx.N.W") != NULL);
}

static void test_values(void) {
  const int W = 23, H = 17;
  kpcn_aov_set *a = synth_aov(W, H, 7);
  CHECK(a != NULL);
  if (!a) return;
  a->buf[KPCN_BUF_SPECULAR][5] = -0.5f; /* negative specular is clamped before the log */
  kpcn_features_norm n;
  a->buf[KPCN_BUF_DEPTH][3] = NAN;
  CHECK(kpcn_features_norm_compute(a, &n) == KPCN_OK);
  a->buf[KPCN_BUF_DEPTH][3] = 1.0f;
  double lo = 1e30, hi = -1e30;
  for (int i = 0; i < W * H; i++)
    if (i != 3) {
      lo = fmin(lo, a->buf[KPCN_BUF_DEPTH][i]);
      hi = kt_worst(hi, a->buf[KPCN_BUF_DEPTH][i]);
    }
  CHECK_CLOSE(n.depth_offset, lo, 1e-6, 0);
  CHECK_CLOSE(n.depth_scale, 1.0 / (hi - lo), 1e-5, 0);
  CHECK(n.color_scale == 1.0f);

  size_t Q = (size_t)W * H;
  float *f = malloc(sizeof(float) * Q * 36), *f1 = malloc(sizeof(float) * Q * 36);
  float *noisy = malloc(sizeof(float) * Q * 3);
  /* as rendered, then at an exposure 7.5 times brighter (the colour scale) */
  for (int run = 0; run < 4; run++) {
    const int b = run % 2;
    n.color_scale = run < 2 ? 1.0f : 7.5f;
    CHECK(kpcn_features_build(a, b, EPS, &n, f, noisy, 2) == KPCN_OK);
    int bad = 0;
    double worst = 0;
    for (int ch = 0; ch < 36; ch++)
      for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
          double r = ref_feature(a, b, &n, ch, x, y), v = f[ch * Q + (size_t)y * W + x];
          /* float rounding: ~1e-7 relative; central differences of O(10) values lose
           * absolute precision, hence the absolute part */
          double e = fabs(v - r) / (2e-6 + 1e-5 * fabs(r));
          worst = kt_worst(worst, e);
          if (e > 1) bad++;
        }
    CHECK(bad == 0);
    if (bad) fprintf(stderr, "branch %d: %d mismatches, worst err/tolerance %g\n", b, bad, worst);
    CHECK(memcmp(noisy, f, sizeof(float) * 3 * Q) == 0);
    /* deterministic regardless of thread count */
    CHECK(kpcn_features_build(a, b, EPS, &n, f1, NULL, 1) == KPCN_OK);
    CHECK(memcmp(f, f1, sizeof(float) * Q * 36) == 0);

    /* region == crop of the full features, bit for bit */
    const int rx = 5, ry = 3, rw = 11, rh = 9;
    float *g = malloc(sizeof(float) * (size_t)rw * rh * 36);
    CHECK(kpcn_features_build_region(a, b, EPS, &n, rx, ry, rw, rh, g, 0, NULL, 2) == KPCN_OK);
    int diff = 0;
    for (int ch = 0; ch < 36; ch++)
      for (int y = 0; y < rh; y++)
        for (int x = 0; x < rw; x++)
          diff += g[(size_t)ch * rw * rh + (size_t)y * rw + x] !=
                  f[ch * Q + (size_t)(y + ry) * W + x + rx];
    CHECK(diff == 0);
    /* a training patch (a cropped set) with the full image's norm matches inside */
    kpcn_aov_set *pa = crop(a, rx, ry, rw, rh);
    CHECK(kpcn_features_build(pa, b, EPS, &n, g, NULL, 2) == KPCN_OK);
    diff = 0;
    for (int ch = 0; ch < 36; ch++)
      for (int y = 1; y < rh - 1; y++)
        for (int x = 1; x < rw - 1; x++)
          diff += g[(size_t)ch * rw * rh + (size_t)y * rw + x] !=
                  f[ch * Q + (size_t)(y + ry) * W + x + rx];
    CHECK(diff == 0);
    kpcn_aov_destroy(pa);
    free(g);
  }
  /* errors */
  CHECK(kpcn_features_build(a, 0, 0.0f, &n, f, NULL, 1) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(kpcn_features_build_region(a, 0, EPS, &n, 20, 0, 5, 5, f, 0, NULL, 1) ==
        KPCN_ERR_INVALID_ARGUMENT);
  /* x0 + w past INT_MAX must not wrap into a region that passes the bounds check */
  CHECK(kpcn_features_build_region(a, 0, EPS, &n, 1, 0, INT_MAX, 5, f, 0, NULL, 1) ==
        KPCN_ERR_INVALID_ARGUMENT);
  CHECK(kpcn_features_build_region_pixels(a, 0, EPS, &n, 0, 1, 1, INT_MAX, f, KPCN_FEATURES_COUNT,
                                          0, NULL, 1) == KPCN_ERR_INVALID_ARGUMENT);
  free(a->var[KPCN_BUF_VISIBILITY]);
  a->var[KPCN_BUF_VISIBILITY] = NULL;
  CHECK(kpcn_features_build(a, 1, EPS, &n, f, NULL, 1) == KPCN_ERR_MISSING_CHANNEL);
  CHECK(strstr(kpcn_last_error(), "visibility") != NULL);
  free(a->buf[KPCN_BUF_DIFFUSE]);
  a->buf[KPCN_BUF_DIFFUSE] = NULL;
  CHECK(kpcn_features_build(a, 0, EPS, &n, f, NULL, 1) == KPCN_ERR_MISSING_CHANNEL);
  CHECK(strstr(kpcn_last_error(), "diffuse") != NULL);
  free(f);
  free(f1);
  free(noisy);
  kpcn_aov_destroy(a);
}

/* Pixel-major output (a net's input buffer): the planar features, transposed, as floats or
 * as bf16 rounded the way vcvtneps2bf16 rounds; slots past the features untouched. A region
 * 33 pixels wide (two 16-pixel blocks and a tail) at an offset. The *_avx2 variant of this
 * test runs the scalar path, the default one the AVX-512 path where the CPU has it. */
static void test_pixels(void) {
  const int W = 37, H = 9, rx = 3, ry = 2, rw = 33, rh = 6, NF = KPCN_FEATURES_COUNT;
  kpcn_aov_set *a = synth_aov(W, H, 11);
  CHECK(a != NULL);
  if (!a) return;
  kpcn_features_norm n;
  CHECK(kpcn_features_norm_compute(a, &n) == KPCN_OK);
  const size_t Q = (size_t)rw * rh;
  float *pl = malloc(sizeof(float) * Q * NF), *np0 = malloc(sizeof(float) * Q * 3),
        *np1 = malloc(sizeof(float) * Q * 3);
  for (int b = 0; b < 2; b++) {
    CHECK(kpcn_features_build_region(a, b, EPS, &n, rx, ry, rw, rh, pl, 0, np0, 2) == KPCN_OK);
    for (int bf16 = 0; bf16 < 2; bf16++) {
      const int ps = bf16 ? 48 : 40;
      const size_t es = bf16 ? 2 : 4;
      unsigned char *px = malloc(es * Q * ps);
      memset(px, 0x5a, es * Q * ps); /* the sentinel in the slots past the features */
      CHECK(kpcn_features_build_region_pixels(a, b, EPS, &n, rx, ry, rw, rh, px, ps, bf16, np1,
                                              2) == KPCN_OK);
      CHECK(memcmp(np0, np1, sizeof(float) * Q * 3) == 0);
      int bad = 0, touched = 0;
      for (size_t q = 0; q < Q; q++) {
        for (int c = 0; c < NF; c++) {
          const float v = pl[(size_t)c * Q + q];
          if (bf16) {
            uint32_t u;
            memcpy(&u, &v, 4);
            const uint16_t want =
                fabsf(v) < FLT_MIN ? (uint16_t)((u >> 16) & 0x8000u) : kt_bf16_round(v);
            bad += ((const uint16_t *)px)[q * ps + c] != want;
          } else {
            bad += memcmp(px + 4 * (q * ps + c), &v, 4) != 0;
          }
        }
        for (size_t k = es * (q * ps + NF); k < es * (q + 1) * ps; k++)
          touched += px[k] != 0x5a;
      }
      if (bad || touched)
        fprintf(stderr, "pixels: branch %d bf16 %d: %d wrong, %d padding bytes written\n", b, bf16,
                bad, touched);
      CHECK(bad == 0 && touched == 0);
      free(px);
    }
  }
  float dummy[64];
  CHECK(kpcn_features_build_region_pixels(a, 0, EPS, &n, 0, 0, 1, 1, dummy, NF - 1, 0, NULL, 1) ==
        KPCN_ERR_INVALID_ARGUMENT);
  CHECK(kpcn_features_build_region_pixels(a, 0, EPS, &n, 0, 0, 1, 1, dummy, NF, 2, NULL, 1) ==
        KPCN_ERR_INVALID_ARGUMENT);
  CHECK(kpcn_features_build_region_pixels(a, 0, EPS, &n, 0, 0, 1, 1, NULL, NF, 0, NULL, 1) ==
        KPCN_ERR_INVALID_ARGUMENT);
  CHECK(kpcn_features_build_region_pixels(a, 0, EPS, &n, 30, 0, 8, 1, dummy, NF, 0, NULL, 1) ==
        KPCN_ERR_INVALID_ARGUMENT);
  free(pl), free(np0), free(np1);
  kpcn_aov_destroy(a);
}

/* log(1 + x) of the specular transform (features.c's own, vectorizable) against double
 * log1p: zero, denormals, a log-spaced sweep over [1e-38, 3.4e38] and every float in
 * [0.5, 8) at a stride; error in units of the float spacing at the exact value. Negative
 * input is clamped to 0 first. */
static void test_log1p(void) {
  const size_t n = 3000000;
  float *x = malloc(n * sizeof(float)), *y = malloc(n * sizeof(float));
  size_t k = 0;
  x[k++] = 0.0f, x[k++] = 1e-45f, x[k++] = FLT_MIN, x[k++] = FLT_MAX, x[k++] = -3.0f;
  for (size_t i = 0; i < 1000000; i++) /* log-spaced, 1e-38 .. 3.4e38 */
    x[k++] = (float)exp(-87.5 + 176.0 * (double)i / 1e6);
  for (uint32_t b = 0x3f000000u; k < n && b < 0x41000000u; b += 7) /* [0.5, 8): dense */
    memcpy(&x[k++], &b, 4);
  kpcn_log_specular(x, k, y);
  double worst = 0, at = 0;
  for (size_t i = 0; i < k; i++) {
    const double ref = log1p(x[i] > 0.0f ? (double)x[i] : 0.0);
    const double ulp = ref > 0 ? nextafterf((float)ref, INFINITY) - (float)ref : 1e-45;
    const double e = fabs((double)y[i] - ref) / ulp;
    if (!(e <= worst) && !isnan(worst)) worst = e, at = x[i]; /* NaN kept (kt_worst) */
  }
  printf("log1p (specular transform): %zu values, max error %.3f ulp (at x = %g)\n", k, worst, at);
  CHECK(worst <= 1.0);
  free(x), free(y);
}

/* Inverse transforms and the derivatives of the recombination by central differences. */
static void test_transforms(void) {
  enum { N = 64 };
  float d[N], s[N], alb[N], t[N], u[N], out[N], gd[N], gs[N], go[N];
  unsigned st = 3;
  for (int i = 0; i < N; i++) {
    d[i] = 2.0f * kt_randf(&st);
    s[i] = 4.0f * kt_randf(&st);
    alb[i] = kt_randf(&st);
    go[i] = kt_randf(&st) - 0.5f;
  }
  kpcn_demodulate_diffuse(d, alb, EPS, N, t);
  kpcn_remodulate_diffuse(t, alb, EPS, N, u);
  for (int i = 0; i < N; i++)
    CHECK_CLOSE(u[i], d[i], 1e-6, 1e-7);
  kpcn_log_specular(s, N, t);
  for (int i = 0; i < N; i++)
    CHECK_CLOSE(t[i], log1p(s[i]), 1e-6, 0);
  kpcn_exp_specular(t, N, u);
  for (int i = 0; i < N; i++)
    CHECK_CLOSE(u[i], s[i], 1e-5, 1e-7);
  /* recombination forward against the formula, backward against finite differences of
   * L = sum go * recombine(d, s) */
  kpcn_log_specular(s, N, t); /* spec_out in log space */
  kpcn_recombine(d, t, alb, EPS, N, out);
  for (int i = 0; i < N; i++)
    CHECK_CLOSE(out[i], d[i] * ((double)alb[i] + EPS) + expm1((double)t[i]), 1e-5, 1e-7);
  kpcn_recombine_backward(go, t, alb, EPS, N, gd, gs);
  for (int i = 0; i < N; i++) {
    const double h = 1e-3;
    double dd[2], ss[2];
    for (int k = 0; k < 2; k++) {
      double sg = k ? -h : h;
      /* the op is element-wise, so L's partial in element i only involves element i */
      float di = (float)(d[i] + sg), r;
      kpcn_recombine(&di, &t[i], &alb[i], EPS, 1, &r);
      dd[k] = go[i] * (double)r;
      float ti = (float)(t[i] + sg);
      kpcn_recombine(&d[i], &ti, &alb[i], EPS, 1, &r);
      ss[k] = go[i] * (double)r;
    }
    CHECK_CLOSE(gd[i], (dd[0] - dd[1]) / (2 * h), 2e-3, 2e-4);
    CHECK_CLOSE(gs[i], (ss[0] - ss[1]) / (2 * h), 2e-3, 2e-4);
  }
  /* NULL terms */
  kpcn_recombine(NULL, t, NULL, EPS, N, out);
  for (int i = 0; i < N; i++)
    CHECK_CLOSE(out[i], s[i], 1e-5, 1e-7);
}

int main(void) {
  test_names();
  test_values();
  test_pixels();
  test_log1p();
  test_transforms();
  return kt_summary("test_denoise_features");
}
