/* Metrics unit tests: every metric against (1) values recorded from numpy / scikit-image
 * (testdata/metrics/reference.json, made by make_reference.py) and (2) naive double loops
 * written here independently of libkpcn/src/metrics (2-D SSIM window, no separability).
 * Also: non-finite policy, channel selection, thread-count determinism, error cases. */
#include "kpcn/exr.h"
#include "kpcn/metrics.h"
#include "testutil.h"

#include <cjson/cJSON.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/* ---- the synthetic generator of make_reference.py, bit-exact ---- */
static uint32_t hash32(uint32_t x) {
  x ^= x >> 16;
  x *= 0x7feb352du;
  x ^= x >> 15;
  x *= 0x846ca68bu;
  x ^= x >> 16;
  return x;
}

static void synthetic(int w, int h, int nch, uint32_t seed, float scale, float *x, float *y) {
  for (int c = 0; c < nch; ++c)
    for (int j = 0; j < h; ++j)
      for (int i = 0; i < w; ++i) {
        uint32_t k = (uint32_t)((c * h + j) * w + i) + seed * 0x9E3779B9u;
        float u1 = (float)(hash32(k) >> 8) * 0x1p-24f;
        float u2 = (float)(hash32(k ^ 0x5bd1e995u) >> 8) * 0x1p-24f;
        volatile float ramp = (float)((3 * i + 5 * j + 7 * c) % 64) / 64.0f;
        volatile float r = ramp + (u1 * 0.5f - 0.25f);
        volatile float t = r + (u2 * 0.25f - 0.125f);
        size_t o = ((size_t)c * h + j) * w + i;
        y[o] = r * scale;
        x[o] = t * scale;
      }
}

/* ---- naive references (double, straightforward) ---- */
static double enc(double v, int srgb) {
  if (!srgb) return v;
  v = v < 0 ? 0 : v > 1 ? 1 : v;
  return v <= 0.0031308 ? 12.92 * v : 1.055 * pow(v, 1 / 2.4) - 0.055;
}

static int valid_px(const float *x, const float *y, size_t n, int nch, size_t i) {
  for (int c = 0; c < nch; ++c)
    if (!isfinite(x[c * n + i]) || !isfinite(y[c * n + i])) return 0;
  return 1;
}

static double naive_pointwise(kpcn_metric m, const float *x, const float *y, int w, int h, int nch,
                              int srgb, double range) {
  size_t n = (size_t)w * h;
  double s = 0;
  long cnt = 0;
  for (size_t i = 0; i < n; ++i) {
    if (!valid_px(x, y, n, nch, i)) continue;
    for (int c = 0; c < nch; ++c) {
      double a = enc(x[c * n + i], srgb), b = enc(y[c * n + i], srgb), d = a - b;
      switch (m) {
      case KPCN_METRIC_L1: s += fabs(d); break;
      case KPCN_METRIC_RELMSE: s += d * d / (b * b + 0.01); break;
      case KPCN_METRIC_RELL1: s += fabs(d) / (fabs(b) + 0.01); break;
      default: s += d * d;
      }
      cnt++;
    }
  }
  double mean = s / cnt;
  return m == KPCN_METRIC_PSNR ? 10 * log10(range * range / mean) : mean;
}

static int refl(int i, int n) { return i < 0 ? -i - 1 : i >= n ? 2 * n - 1 - i : i; }

/* Direct 11x11 window; non-finite values zeroed, pixels excluded (the documented policy).
 * map (optional) gets the per-pixel SSIM of every channel. */
static double naive_ssim(const float *x, const float *y, int w, int h, int nch, int srgb, double R,
                         double *map) {
  size_t n = (size_t)w * h;
  double g[11], gs = 0;
  for (int k = 0; k < 11; ++k)
    gs += g[k] = exp(-0.5 * (k - 5) * (k - 5) / 2.25);
  for (int k = 0; k < 11; ++k)
    g[k] /= gs;
  double C1 = 0.0001 * R * R, C2 = 0.0009 * R * R, total = 0;
  for (int c = 0; c < nch; ++c) {
    double s = 0;
    long cnt = 0;
    for (int py = 0; py < h; ++py)
      for (int px = 0; px < w; ++px) {
        /* two passes, the means first, then squared deviations from them (no cancellation
         * at values far above the range), in long double */
        long double mx = 0, my = 0, vx = 0, vy = 0, vxy = 0;
        for (int pass = 0; pass < 2; ++pass)
          for (int b = -5; b <= 5; ++b)
            for (int a = -5; a <= 5; ++a) {
              size_t i = (size_t)refl(py + b, h) * w + refl(px + a, w);
              int ok = valid_px(x, y, n, nch, i);
              double p = ok ? enc(x[c * n + i], srgb) : 0, q = ok ? enc(y[c * n + i], srgb) : 0;
              long double wt = (long double)g[a + 5] * g[b + 5];
              if (pass == 0) {
                mx += wt * p, my += wt * q;
              } else {
                long double dx = p - mx, dy = q - my;
                vx += wt * dx * dx, vy += wt * dy * dy, vxy += wt * dx * dy;
              }
            }
        double S = (double)((2 * mx * my + C1) / (mx * mx + my * my + C1) *
                            ((2 * vxy + C2) / (vx + vy + C2)));
        size_t i = (size_t)py * w + px;
        int ok = valid_px(x, y, n, nch, i);
        if (map) map[c * n + i] = ok ? S : NAN;
        if (ok && px >= 5 && px < w - 5 && py >= 5 && py < h - 5) s += S, cnt++;
      }
    total += s / cnt;
  }
  return total / nch;
}

static double naive(kpcn_metric m, const float *x, const float *y, int w, int h, int nch, int srgb,
                    double range) {
  return m == KPCN_METRIC_SSIM ? naive_ssim(x, y, w, h, nch, srgb, range, NULL)
                               : naive_pointwise(m, x, y, w, h, nch, srgb, range);
}

static double run(kpcn_metric m, const float *x, const float *y, int w, int h, int nch, int srgb,
                  double range, int nthreads, kpcn_metric_result *res, float *map) {
  kpcn_metric_options o;
  kpcn_metric_options_defaults(&o);
  o.display = srgb ? KPCN_DISPLAY_SRGB : KPCN_DISPLAY_LINEAR;
  o.data_range = range;
  o.nthreads = nthreads;
  kpcn_metric_result r;
  kpcn_status s = kpcn_metric_planar(m, x, y, w, h, nch, &o, &r, map);
  CHECK(s == KPCN_OK);
  if (s != KPCN_OK) fprintf(stderr, "  %s\n", kpcn_last_error());
  if (res) *res = r;
  return r.value;
}

/* Checks every metric of one reference case on planar x/y. */
static void check_case(const cJSON *cs, const float *x, const float *y, int w, int h, int nch) {
  const char *name = cJSON_GetObjectItem(cs, "name")->valuestring;
  int srgb = strcmp(cJSON_GetObjectItem(cs, "display")->valuestring, "srgb") == 0;
  double range = cJSON_GetObjectItem(cs, "data_range")->valuedouble;
  const cJSON *vals = cJSON_GetObjectItem(cs, "values");
  for (int m = 0; m < KPCN_METRIC_COUNT; ++m) {
    const cJSON *v = cJSON_GetObjectItem(vals, kpcn_metric_name((kpcn_metric)m));
    CHECK(v != NULL);
    if (!v) continue;
    double got = run((kpcn_metric)m, x, y, w, h, nch, srgb, range, 0, NULL, NULL);
    double ref = v->valuedouble, nv = naive((kpcn_metric)m, x, y, w, h, nch, srgb, range);
    CHECK_CLOSE(got, ref, 1e-8, 1e-12); /* recorded values agree to ~1e-15 (SSIM ~2e-10) */
    CHECK_CLOSE(got, nv, 1e-7, 1e-9);
    if (fabs(got - ref) > 1e-8 * fabs(ref) + 1e-12 || fabs(got - nv) > 1e-7 * fabs(nv) + 1e-9)
      fprintf(stderr, "  case %s metric %s: got %.12g ref %.12g naive %.12g\n", name,
              kpcn_metric_name((kpcn_metric)m), got, ref, nv);
  }
}

static void test_reference(void) {
  char path[1024];
  snprintf(path, sizeof path, "%s/metrics/reference.json", KPCN_TESTDATA);
  char *txt = kt_slurp(path, NULL);
  CHECK(txt != NULL);
  if (!txt) return;
  cJSON *root = cJSON_Parse(txt);
  free(txt);
  CHECK(root != NULL);
  if (!root) return;
  int ncases = 0;
  const cJSON *cs;
  cJSON_ArrayForEach(cs, cJSON_GetObjectItem(root, "cases")) {
    const cJSON *syn = cJSON_GetObjectItem(cs, "synthetic");
    if (syn) {
      int w = cJSON_GetObjectItem(syn, "w")->valueint, h = cJSON_GetObjectItem(syn, "h")->valueint;
      int nch = cJSON_GetObjectItem(syn, "nch")->valueint;
      uint32_t seed = (uint32_t)cJSON_GetObjectItem(syn, "seed")->valueint;
      float scale = (float)cJSON_GetObjectItem(syn, "scale")->valuedouble;
      size_t n = (size_t)w * h;
      float *x = malloc(sizeof(float) * n * nch), *y = malloc(sizeof(float) * n * nch);
      synthetic(w, h, nch, seed, scale, x, y);
      const cJSON *p;
      cJSON_ArrayForEach(p, cJSON_GetObjectItem(cs, "pixels")) { /* generator is bit-exact */
        int c = cJSON_GetArrayItem(p, 0)->valueint, i = cJSON_GetArrayItem(p, 1)->valueint,
            j = cJSON_GetArrayItem(p, 2)->valueint;
        CHECK(x[c * n + (size_t)j * w + i] == (float)cJSON_GetArrayItem(p, 3)->valuedouble);
        CHECK(y[c * n + (size_t)j * w + i] == (float)cJSON_GetArrayItem(p, 4)->valuedouble);
      }
      check_case(cs, x, y, w, h, nch);
      /* SSIM map entries recorded from skimage (full=True), borders included. */
      float *map = malloc(sizeof(float) * n * nch);
      int srgb = strcmp(cJSON_GetObjectItem(cs, "display")->valuestring, "srgb") == 0;
      run(KPCN_METRIC_SSIM, x, y, w, h, nch, srgb,
          cJSON_GetObjectItem(cs, "data_range")->valuedouble, 0, NULL, map);
      cJSON_ArrayForEach(p, cJSON_GetObjectItem(cs, "ssim_map")) {
        int c = cJSON_GetArrayItem(p, 0)->valueint, i = cJSON_GetArrayItem(p, 1)->valueint,
            j = cJSON_GetArrayItem(p, 2)->valueint;
        CHECK_NEAR(map[c * n + (size_t)j * w + i], cJSON_GetArrayItem(p, 3)->valuedouble,
                   1e-6); /* float map */
      }
      free(map);
      free(x);
      free(y);
    } else {
      char f0[1024], f1[1024];
      const cJSON *files = cJSON_GetObjectItem(cs, "files");
      snprintf(f0, sizeof f0, "%s/%s", KPCN_TESTDATA, cJSON_GetArrayItem(files, 0)->valuestring);
      snprintf(f1, sizeof f1, "%s/%s", KPCN_TESTDATA, cJSON_GetArrayItem(files, 1)->valuestring);
      kpcn_image *a = NULL, *b = NULL;
      CHECK(kpcn_exr_read_image(f0, &a) == KPCN_OK);
      CHECK(kpcn_exr_read_image(f1, &b) == KPCN_OK);
      if (a && b) {
        int srgb = strcmp(cJSON_GetObjectItem(cs, "display")->valuestring, "srgb") == 0;
        const char *rgb[3] = {"R", "G", "B"};
        kpcn_metric_options o;
        kpcn_metric_options_defaults(&o);
        o.display = srgb ? KPCN_DISPLAY_SRGB : KPCN_DISPLAY_LINEAR;
        const cJSON *vals = cJSON_GetObjectItem(cs, "values");
        for (int m = 0; m < KPCN_METRIC_COUNT; ++m) {
          kpcn_metric_result r;
          CHECK(kpcn_metric_image((kpcn_metric)m, a, b, rgb, 3, &o, &r, NULL) == KPCN_OK);
          double ref = cJSON_GetObjectItem(vals, kpcn_metric_name((kpcn_metric)m))->valuedouble;
          CHECK_CLOSE(r.value, ref, 1e-8, 1e-12);
          CHECK(r.nonfinite == 0 && r.nchannels == 3);
          /* default channel list = the reference's (R,G,B), matched by name in the AOV file */
          kpcn_metric_result r2;
          CHECK(kpcn_metric_image((kpcn_metric)m, a, b, NULL, 0, &o, &r2, NULL) == KPCN_OK);
          CHECK_CLOSE(r2.value, r.value, 1e-12, 0); /* file order B,G,R: other sum order */
        }
      }
      if (a) kpcn_image_destroy(a);
      if (b) kpcn_image_destroy(b);
    }
    ncases++;
  }
  CHECK(ncases >= 6);
  cJSON_Delete(root);
}

/* Error maps equal the naive per-pixel terms; SSIM's equals the naive 2-D window map. */
static void test_errormaps(void) {
  int w = 270, h = 14, nch = 2; /* wider than one 256-column SSIM strip */
  size_t n = (size_t)w * h;
  float *x = malloc(sizeof(float) * n * nch), *y = malloc(sizeof(float) * n * nch);
  float *map = malloc(sizeof(float) * n * nch);
  double *nmap = malloc(sizeof(double) * n * nch);
  synthetic(w, h, nch, 11, 1.0f, x, y);
  for (int srgb = 0; srgb <= 1; ++srgb) /* the display encoding applies to the maps too */
    for (int m = 0; m < KPCN_METRIC_COUNT; ++m) {
      run((kpcn_metric)m, x, y, w, h, nch, srgb, 1.0, 0, NULL, map);
      if (m == KPCN_METRIC_SSIM) naive_ssim(x, y, w, h, nch, srgb, 1.0, nmap);
      double maxerr = 0;
      for (size_t i = 0; i < n * nch; ++i) {
        const double p = enc(x[i], srgb), q = enc(y[i], srgb), d = p - q;
        double t;
        switch ((kpcn_metric)m) {
        case KPCN_METRIC_L1: t = fabs(d); break;
        case KPCN_METRIC_RELMSE: t = d * d / (q * q + 0.01); break;
        case KPCN_METRIC_RELL1: t = fabs(d) / (fabs(q) + 0.01); break;
        case KPCN_METRIC_SSIM: t = nmap[i]; break;
        default: t = d * d;
        }
        maxerr = kt_worst(maxerr, fabs(map[i] - t) / fmax(1.0, fabs(t)));
      }
      if (maxerr >= 1e-6) fprintf(stderr, "metric %d srgb %d: map off by %g\n", m, srgb, maxerr);
      CHECK(maxerr < 1e-6);
    }
  free(x), free(y), free(map), free(nmap);
}

/* NaN/Inf pixels are excluded and counted; maps hold NaN there; all-bad fails. */
static void test_nonfinite(void) {
  int w = 24, h = 20, nch = 3;
  size_t n = (size_t)w * h;
  float *x = malloc(sizeof(float) * n * nch), *y = malloc(sizeof(float) * n * nch);
  float *map = malloc(sizeof(float) * n * nch);
  synthetic(w, h, nch, 5, 1.0f, x, y);
  x[0 * n + 3] = NAN;           /* pixel 3 */
  y[2 * n + 50] = INFINITY;     /* pixel 50 */
  x[1 * n + 200] = -INFINITY;   /* pixel 200 */
  y[1 * n + 200] = NAN;         /* same pixel: counted once */
  x[0 * n + 12 * w + 12] = NAN; /* interior pixel, matters for SSIM */
  for (int m = 0; m < KPCN_METRIC_COUNT; ++m) {
    kpcn_metric_result r;
    double v = run((kpcn_metric)m, x, y, w, h, nch, m == KPCN_METRIC_RELL1, 1.0, 0, &r, map);
    CHECK(r.nonfinite == 4);
    CHECK(isfinite(v));
    CHECK_CLOSE(v, naive((kpcn_metric)m, x, y, w, h, nch, m == KPCN_METRIC_RELL1, 1.0), 1e-7, 1e-9);
    CHECK(isnan(map[3]) && isnan(map[2 * n + 50]) && isnan(map[n + 200]));
    CHECK(!isnan(map[4]));
    if (m != KPCN_METRIC_SSIM)
      CHECK(r.npixels == (int64_t)n - 4);
    else
      CHECK(r.npixels == (int64_t)(w - 10) * (h - 10) - 2); /* pixels 200 and 12*w+12 */
  }
  for (size_t i = 0; i < n; ++i)
    x[i] = NAN;
  kpcn_metric_options o;
  kpcn_metric_options_defaults(&o);
  kpcn_metric_result r;
  CHECK(kpcn_metric_planar(KPCN_METRIC_L1, x, y, w, h, nch, &o, &r, NULL) == KPCN_ERR_NONFINITE);
  CHECK(kpcn_metric_planar(KPCN_METRIC_SSIM, x, y, w, h, nch, &o, &r, NULL) == KPCN_ERR_NONFINITE);
  free(x), free(y), free(map);
}

/* metrics.md, "Channels" / "Non-finite values": SSIM averages only its interior (5 pixels in
 * from each edge), so an 11x11 image with a NaN (or Inf) centre has no valid SSIM pixel and
 * fails SSIM alone (KPCN_ERR_NONFINITE), while the pointwise metrics average the other 120
 * pixels; one more column (two interior pixels, one finite) is an ordinary SSIM of that one
 * pixel. And a figure beyond double range (relMSE / relL1 at eps = 1e-320 with a black
 * reference pixel: 1 / 1e-320) is +inf, a success, as PSNR of equal images is (kpcntool prints
 * both as JSON null; cli_metrics.sh). */
static void test_ssim_nan_centre_and_overflow(void) {
  const int nch = 3;
  float *x = malloc(sizeof(float) * 12 * 11 * nch), *y = malloc(sizeof(float) * 12 * 11 * nch);
  float *map = malloc(sizeof(float) * 12 * 11 * nch);
  kpcn_metric_options o;
  kpcn_metric_options_defaults(&o);
  kpcn_metric_result r;
  for (int k = 0; k < 3; k++) { /* NaN in x, +Inf in y, -Inf in x: the centre (5, 5) */
    const int w = 11, h = 11;
    const size_t n = (size_t)w * h;
    synthetic(w, h, nch, 21 + k, 1.0f, x, y);
    const size_t ctr = 5 * (size_t)w + 5;
    if (k == 0) x[0 * n + ctr] = NAN;
    if (k == 1) y[2 * n + ctr] = INFINITY;
    if (k == 2) x[1 * n + ctr] = -INFINITY;
    for (int m = 0; m < KPCN_METRIC_COUNT; ++m) {
      for (int withmap = 0; withmap < 2; withmap++) { /* without and with an error map */
        const kpcn_status s =
            kpcn_metric_planar((kpcn_metric)m, x, y, w, h, nch, &o, &r, withmap ? map : NULL);
        if (m == KPCN_METRIC_SSIM) {
          CHECK(s == KPCN_ERR_NONFINITE);
          CHECK(strstr(kpcn_last_error(), "ssim") != NULL);
          CHECK(r.nonfinite == 1 && r.npixels == 0 && !isfinite(r.value));
        } else {
          CHECK(s == KPCN_OK);
          CHECK(r.nonfinite == 1 && r.npixels == (int64_t)n - 1);
          CHECK_CLOSE(r.value, naive_pointwise((kpcn_metric)m, x, y, w, h, nch, 0, 1.0), 1e-12, 0);
          if (withmap) CHECK(isnan(map[ctr]) && isnan(map[2 * n + ctr]) && !isnan(map[ctr + 1]));
        }
      }
    }
  }
  /* 12 wide or 12 high: the interior is (5,5) and one more pixel, which is finite */
  const int sizes[2][2] = {{12, 11}, {11, 12}};
  for (int k = 0; k < 2; k++) {
    const int w = sizes[k][0], h = sizes[k][1];
    const size_t n = (size_t)w * h;
    synthetic(w, h, nch, 31 + k, 1.0f, x, y);
    x[0 * n + 5 * (size_t)w + 5] = NAN;
    CHECK(kpcn_metric_planar(KPCN_METRIC_SSIM, x, y, w, h, nch, &o, &r, NULL) == KPCN_OK);
    CHECK(r.nonfinite == 1 && r.npixels == 1);
    CHECK_CLOSE(r.value, naive_ssim(x, y, w, h, nch, 0, 1.0, NULL), 1e-9, 1e-12);
  }
  /* eps = 1e-320 (a denormal, so > 0 and accepted): a black reference pixel against a
   * non-black one is 1 / 1e-320 = +inf, beyond double range; elsewhere it is negligible */
  {
    const int w = 11, h = 11;
    const size_t n = (size_t)w * h;
    synthetic(w, h, 1, 41, 1.0f, x, y);
    for (size_t i = 0; i < n; i++) /* away from 0, so every other term is finite */
      x[i] = 0.5f + 0.25f * fabsf(x[i]), y[i] = 0.25f + 0.25f * fabsf(y[i]);
    o.eps = 1e-320;
    CHECK(o.eps > 0.0);
    double want[2] = {0, 0};
    for (size_t i = 0; i < n; i++) {
      const double d = (double)x[i] - y[i];
      want[0] += d * d / ((double)y[i] * y[i] + 1e-320);
      want[1] += fabs(d) / (fabs((double)y[i]) + 1e-320);
    }
    const kpcn_metric rel[2] = {KPCN_METRIC_RELMSE, KPCN_METRIC_RELL1};
    for (int j = 0; j < 2; j++) {
      CHECK(kpcn_metric_planar(rel[j], x, y, w, h, 1, &o, &r, NULL) == KPCN_OK);
      CHECK(isfinite(want[j]));
      CHECK_CLOSE(r.value, want[j] / (double)n, 1e-12, 0);
    }
    y[17] = 0.0f; /* x[17] = 0.5 or more */
    for (int j = 0; j < 2; j++) {
      const kpcn_status s = kpcn_metric_planar(rel[j], x, y, w, h, 1, &o, &r, NULL);
      CHECK(s == KPCN_OK);
      if (s != KPCN_OK)
        fprintf(stderr, "  %s at eps 1e-320: %s\n", kpcn_metric_name(rel[j]), kpcn_last_error());
      CHECK(isinf(r.value) && r.value > 0);
      CHECK(r.nonfinite == 0 && r.npixels == (int64_t)n);
    }
    o.eps = 0.01;
  }
  free(x), free(y), free(map);
}

/* Same bits for 1, 2, 3 and 7 threads (fixed-order reductions). */
static void test_determinism(void) {
  int w = 601, h = 131, nch = 3; /* 3 column strips x 3 row blocks for SSIM */
  size_t n = (size_t)w * h;
  float *x = malloc(sizeof(float) * n * nch), *y = malloc(sizeof(float) * n * nch);
  synthetic(w, h, nch, 9, 2.0f, x, y);
  for (int m = 0; m < KPCN_METRIC_COUNT; ++m) {
    double v1 = run((kpcn_metric)m, x, y, w, h, nch, 1, 2.0, 1, NULL, NULL);
    for (int t = 2; t <= 7; t += (t == 3 ? 4 : 1))
      CHECK(run((kpcn_metric)m, x, y, w, h, nch, 1, 2.0, t, NULL, NULL) == v1);
  }
  /* a negative count is all cores, one past KPCN_MAX_THREADS is capped to it (100000 crashed
   * inside OpenMP before session 58): the same figures */
  CHECK(kpcn_resolve_threads(-5) == kpcn_resolve_threads(0));
  CHECK(kpcn_resolve_threads(100000) == KPCN_MAX_THREADS);
  CHECK(kpcn_resolve_threads(KPCN_MAX_THREADS) == KPCN_MAX_THREADS);
  CHECK(run(KPCN_METRIC_SSIM, x, y, w, h, nch, 1, 2.0, -5, NULL, NULL) ==
        run(KPCN_METRIC_SSIM, x, y, w, h, nch, 1, 2.0, 1, NULL, NULL));
  /* identical images: SSIM 1, errors 0, PSNR +inf */
  CHECK(run(KPCN_METRIC_SSIM, x, x, w, h, nch, 0, 1.0, 0, NULL, NULL) == 1.0); /* exactly */
  CHECK(run(KPCN_METRIC_RELMSE, x, x, w, h, nch, 0, 1.0, 0, NULL, NULL) == 0.0);
  CHECK(isinf(run(KPCN_METRIC_PSNR, x, x, w, h, nch, 0, 1.0, 0, NULL, NULL)));
  free(x), free(y);
}

/* Values far above the data range (a flat emitter at range 1): E[x^2] - E[x]^2 cancels
 * (SSIM was 1.004 for flat 100010 against 100000), and extreme ranges (identical images gave
 * NaN at range 1e-80). Truth: the closed form of flat images (no contrast: S is the
 * luminance term alone) and the two-pass long-double naive_ssim. */
static void test_large_values(void) {
  const int w = 16, h = 16;
  const size_t n = (size_t)w * h;
  float *x = malloc(sizeof(float) * n * 3), *y = malloc(sizeof(float) * n * 3);
  const double C1 = 1e-4;
  for (double level = 1e3; level <= 1e7; level *= 10) {
    for (size_t i = 0; i < n; ++i)
      x[i] = (float)(level + level * 1e-4), y[i] = (float)level;
    long double a = x[0], b = y[0];
    double flat = (double)((2 * a * b + C1) / (a * a + b * b + C1));
    double v = run(KPCN_METRIC_SSIM, x, y, w, h, 1, 0, 1.0, 1, NULL, NULL);
    CHECK_NEAR(v, flat, 1e-12);
    CHECK(v <= 1.0);
  }
  /* texture on a bright base: 1e4 + noise of amplitude 2 (the contrast term matters) */
  int W = 40, H = 23;
  float *tx = malloc(sizeof(float) * W * H * 3), *ty = malloc(sizeof(float) * W * H * 3);
  synthetic(W, H, 3, 17, 2.0f, tx, ty);
  for (int i = 0; i < W * H * 3; ++i)
    tx[i] += 1e4f, ty[i] += 1e4f;
  float *map = malloc(sizeof(float) * W * H * 3);
  double *nmap = malloc(sizeof(double) * W * H * 3);
  double ref = naive_ssim(tx, ty, W, H, 3, 0, 1.0, nmap);
  CHECK_NEAR(run(KPCN_METRIC_SSIM, tx, ty, W, H, 3, 0, 1.0, 2, NULL, map), ref, 1e-9);
  double worst = 0;
  for (int i = 0; i < W * H * 3; ++i)
    worst = kt_worst(worst, fabs(map[i] - nmap[i]));
  CHECK(worst < 1e-6); /* the map is float */
  /* identical images are exactly 1 at any representable range, zeros included */
  memset(x, 0, sizeof(float) * n);
  CHECK(run(KPCN_METRIC_SSIM, x, x, w, h, 1, 0, 1e-80, 1, NULL, NULL) == 1.0);
  CHECK(run(KPCN_METRIC_SSIM, tx, tx, W, H, 3, 0, 1e79, 1, NULL, NULL) == 1.0);
  /* beyond that, C1 underflows and flat windows are 0/0: an error naming the range */
  kpcn_metric_options o;
  kpcn_metric_options_defaults(&o);
  o.display = KPCN_DISPLAY_LINEAR;
  o.data_range = 1e-200;
  kpcn_metric_result r;
  CHECK(kpcn_metric_planar(KPCN_METRIC_SSIM, x, x, w, h, 1, &o, &r, NULL) ==
        KPCN_ERR_INVALID_ARGUMENT);
  CHECK(strstr(kpcn_last_error(), "not finite at data range 1e-200") != NULL);
  free(x), free(y), free(tx), free(ty), free(map), free(nmap);
}

static void test_image_form_and_errors(void) {
  const char *na[4] = {"R", "G", "B", "Z"}, *nb[3] = {"B", "G", "R"};
  kpcn_image *a = NULL, *b = NULL, *small = NULL, *other = NULL;
  CHECK(kpcn_image_create(&a, 16, 12, 4, na) == KPCN_OK);
  CHECK(kpcn_image_create(&b, 16, 12, 3, nb) == KPCN_OK);
  CHECK(kpcn_image_create(&small, 15, 12, 3, nb) == KPCN_OK);
  CHECK(kpcn_image_create(&other, 16, 12, 2, NULL) == KPCN_OK);
  if (!a || !b || !small || !other) return;
  size_t n = 16 * 12;
  unsigned st = 7;
  for (size_t i = 0; i < 4 * n; ++i)
    a->data[i] = kt_randf(&st);
  for (size_t i = 0; i < 3 * n; ++i)
    b->data[i] = kt_randf(&st);
  kpcn_metric_options o;
  kpcn_metric_options_defaults(&o);
  kpcn_metric_result r;
  kpcn_image *map = NULL;
  /* by name: b's channel order is B,G,R; a's G is plane 1, b's G plane 1; a's R 0, b's R 2 */
  const char *g[1] = {"G"};
  CHECK(kpcn_metric_image(KPCN_METRIC_MSE, a, b, g, 1, &o, &r, &map) == KPCN_OK);
  CHECK_CLOSE(r.value, naive_pointwise(KPCN_METRIC_MSE, a->data + n, b->data + n, 16, 12, 1, 0, 1),
              1e-12, 0);
  CHECK(map && map->nchannels == 1 && strcmp(map->names[0], "G") == 0);
  if (map) kpcn_image_destroy(map);
  CHECK(kpcn_metric_image(KPCN_METRIC_L1, a, b, NULL, 0, &o, &r, NULL) == KPCN_OK);
  double s = 0;
  for (size_t i = 0; i < n; ++i)
    s += fabs(a->data[i] - b->data[2 * n + i]) + fabs(a->data[n + i] - b->data[n + i]) +
         fabs(a->data[2 * n + i] - b->data[i]);
  CHECK_CLOSE(r.value, s / (3.0 * n), 1e-12, 0);
  CHECK(r.nchannels == 3);
  /* errors name the problem */
  CHECK(kpcn_metric_image(KPCN_METRIC_L1, a, small, NULL, 0, &o, &r, NULL) ==
        KPCN_ERR_SIZE_MISMATCH);
  CHECK(strstr(kpcn_last_error(), "16x12") && strstr(kpcn_last_error(), "15x12"));
  CHECK(isnan(r.value) && r.npixels == 0 && r.nonfinite == 0); /* a failed call's result is empty */
  const char *zz[1] = {"Q"};
  CHECK(kpcn_metric_image(KPCN_METRIC_L1, a, b, zz, 1, &o, &r, NULL) == KPCN_ERR_MISSING_CHANNEL);
  CHECK(strstr(kpcn_last_error(), "'Q'") != NULL);
  /* the reference a has a Z beside R,G,B (an AOV image): without a list the pair is compared
   * on R,G,B, as kpcntool and the ImageBuf ops do (until session 58 the C form refused it) */
  CHECK(kpcn_metric_image(KPCN_METRIC_L1, b, a, NULL, 0, &o, &r, NULL) == KPCN_OK);
  CHECK_CLOSE(r.value, s / (3.0 * n), 1e-12, 0);
  CHECK(r.nchannels == 3);
  const char *rgb_names[4] = {"R", "G", "B", "Z"}, *rgba_names[4] = {"R", "G", "B", "A"};
  CHECK(kpcn_metric_default_rgb(rgb_names, 4, rgb_names, 3) == 1);
  CHECK(kpcn_metric_default_rgb(rgba_names, 4, rgba_names, 4) == 0);   /* RGBA: all four */
  CHECK(kpcn_metric_default_rgb(rgb_names + 3, 1, rgb_names, 4) == 0); /* no R,G,B in x */
  /* a list without its length, or a length without a list */
  CHECK(kpcn_metric_image(KPCN_METRIC_L1, a, b, g, 0, &o, &r, NULL) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(strstr(kpcn_last_error(), "a list needs its length") != NULL);
  CHECK(kpcn_metric_image(KPCN_METRIC_L1, a, b, NULL, 3, &o, &r, NULL) ==
        KPCN_ERR_INVALID_ARGUMENT);
  CHECK(kpcn_metric_image(KPCN_METRIC_L1, other, b, NULL, 0, &o, &r, NULL) != KPCN_OK);
  CHECK(kpcn_metric_planar(KPCN_METRIC_SSIM, a->data, a->data, 10, 12, 1, &o, &r, NULL) ==
        KPCN_ERR_INVALID_ARGUMENT);
  CHECK(strstr(kpcn_last_error(), "10x12") != NULL);
  CHECK(kpcn_metric_planar(KPCN_METRIC_L1, a->data, NULL, 16, 12, 1, &o, &r, NULL) ==
        KPCN_ERR_INVALID_ARGUMENT);
  CHECK(kpcn_metric_planar(KPCN_METRIC_L1, a->data, a->data, 0, 12, 1, &o, &r, NULL) != KPCN_OK);
  CHECK(kpcn_metric_planar(KPCN_METRIC_L1, a->data, a->data, 100000, 100000, 1, &o, &r, NULL) !=
        KPCN_OK);
  o.eps = 0; /* would divide by zero at a black reference pixel */
  CHECK(kpcn_metric_planar(KPCN_METRIC_RELMSE, a->data, a->data, 16, 12, 1, &o, &r, NULL) ==
        KPCN_ERR_INVALID_ARGUMENT);
  CHECK(strstr(kpcn_last_error(), "eps must be > 0") != NULL);
  o.eps = 0.01;
  o.data_range = 0;
  CHECK(kpcn_metric_planar(KPCN_METRIC_PSNR, a->data, a->data, 16, 12, 1, &o, &r, NULL) ==
        KPCN_ERR_INVALID_ARGUMENT);
  CHECK(kpcn_metric_from_name("SSIM") == KPCN_METRIC_SSIM);
  CHECK(kpcn_metric_from_name("relmse") == KPCN_METRIC_RELMSE);
  CHECK(kpcn_metric_from_name("ssimx") == -1);
  /* sRGB curve: analytic values */
  CHECK_NEAR(kpcn_srgb_encode(0.5), 1.055 * pow(0.5, 1 / 2.4) - 0.055, 1e-15);
  CHECK_NEAR(kpcn_srgb_encode(0.002), 12.92 * 0.002, 1e-15);
  CHECK(kpcn_srgb_encode(-1) == 0.0 && kpcn_srgb_encode(7) == 1.0);
  kpcn_image_destroy(a), kpcn_image_destroy(b), kpcn_image_destroy(small);
  kpcn_image_destroy(other);
}

int main(void) {
  test_reference();
  test_errormaps();
  test_nonfinite();
  test_ssim_nan_centre_and_overflow();
  test_determinism();
  test_large_values();
  test_image_form_and_errors();
  return kt_summary("test_metrics");
}
