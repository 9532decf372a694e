/* Per-pixel metrics (L1, MSE, relMSE, relL1, PSNR), dispatch and the image form.
 * SSIM lives in ssim.c. Definitions and the non-finite policy are in kpcn/metrics.h. */
#include "kpcn/metrics.h"

#include "core/internal.h"
#include "metrics/metrics_internal.h"

#include <ctype.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

static const char *const g_names[KPCN_METRIC_COUNT] = {"l1",    "mse",  "relmse",
                                                       "rell1", "psnr", "ssim"};

const char *kpcn_metric_name(kpcn_metric m) {
  return (m >= 0 && m < KPCN_METRIC_COUNT) ? g_names[m] : "unknown";
}

int kpcn_metric_from_name(const char *name) {
  if (!name) return -1;
  for (int m = 0; m < KPCN_METRIC_COUNT; ++m) {
    const char *a = g_names[m], *b = name;
    while (*a && *b && tolower((unsigned char)*b) == *a)
      ++a, ++b;
    if (!*a && !*b) return m;
  }
  return -1;
}

void kpcn_metric_options_defaults(kpcn_metric_options *opt) {
  if (!opt) return;
  opt->display = KPCN_DISPLAY_LINEAR;
  opt->data_range = 1.0;
  opt->eps = 0.01;
  opt->nthreads = 0;
}

double kpcn_srgb_encode(double v) {
  if (!(v > 0.0)) return 0.0; /* also maps NaN to 0, but callers exclude NaN pixels first */
  if (v >= 1.0) return 1.0;
  return v <= 0.0031308 ? 12.92 * v : 1.055 * pow(v, 1.0 / 2.4) - 0.055;
}

uint8_t *kpcn_metric_valid_mask(const float *x, const float *y, int w, int h, int nch, int nthreads,
                                int64_t *nonfinite) {
  size_t n = (size_t)w * (size_t)h;
  uint8_t *mask = kpcn_alloc(n, "metric validity mask");
  if (!mask) return NULL;
  int64_t bad = 0;
#pragma omp parallel for num_threads(nthreads) schedule(static) reduction(+ : bad)
  for (int r = 0; r < h; ++r) {
    for (int c0 = 0; c0 < w; ++c0) {
      size_t i = (size_t)r * w + c0;
      uint8_t ok = 1;
      for (int c = 0; c < nch; ++c) {
        size_t j = (size_t)c * n + i;
        if (!isfinite(x[j]) || !isfinite(y[j])) ok = 0;
      }
      mask[i] = ok;
      bad += !ok;
    }
  }
  *nonfinite = bad;
  return mask;
}

/* The per-pixel term of metric m (PSNR uses the squared error). */
static inline double term(kpcn_metric m, double a, double b, double eps) {
  double d = a - b;
  switch (m) {
  case KPCN_METRIC_L1: return fabs(d);
  case KPCN_METRIC_RELMSE: return d * d / (b * b + eps);
  case KPCN_METRIC_RELL1: return fabs(d) / (fabs(b) + eps);
  default: return d * d; /* MSE, PSNR */
  }
}

static kpcn_status pointwise(kpcn_metric m, const float *x, const float *y, int w, int h, int nch,
                             const kpcn_metric_options *opt, kpcn_metric_result *res,
                             float *errormap) {
  int nt = kpcn_resolve_threads(opt->nthreads);
  int64_t nonfinite = 0;
  uint8_t *mask = kpcn_metric_valid_mask(x, y, w, h, nch, nt, &nonfinite);
  if (!mask) return kpcn_last_status();
  double *rows = kpcn_calloc((size_t)h, sizeof(double), "metric row sums");
  if (!rows) {
    free(mask);
    return kpcn_last_status();
  }
  const size_t n = (size_t)w * (size_t)h;
  const int srgb = opt->display == KPCN_DISPLAY_SRGB;
  const double eps = opt->eps;
#pragma omp parallel for num_threads(nt) schedule(static)
  for (int r = 0; r < h; ++r) {
    double rowsum = 0.0; /* fixed order within a row: channel, then x */
    for (int c = 0; c < nch; ++c) {
      const float *xp = x + (size_t)c * n + (size_t)r * w;
      const float *yp = y + (size_t)c * n + (size_t)r * w;
      const uint8_t *mp = mask + (size_t)r * w;
      float *ep = errormap ? errormap + (size_t)c * n + (size_t)r * w : NULL;
      for (int i = 0; i < w; ++i) {
        if (!mp[i]) {
          if (ep) ep[i] = NAN;
          continue;
        }
        double a = xp[i], b = yp[i];
        if (srgb) {
          a = kpcn_srgb_encode(a);
          b = kpcn_srgb_encode(b);
        }
        double t = term(m, a, b, eps);
        rowsum += t;
        if (ep) ep[i] = (float)t;
      }
    }
    rows[r] = rowsum;
  }
  double total = 0.0;
  for (int r = 0; r < h; ++r)
    total += rows[r];
  free(rows);
  free(mask);
  int64_t valid = (int64_t)n - nonfinite;
  res->nonfinite = nonfinite;
  res->npixels = valid;
  res->nchannels = nch;
  if (valid <= 0) {
    res->value = NAN;
    return kpcn_fail(KPCN_ERR_NONFINITE, "%s: every one of the %lld pixels is non-finite",
                     kpcn_metric_name(m), (long long)n);
  }
  double mean = total / ((double)valid * (double)nch);
  if (m == KPCN_METRIC_PSNR)
    /* 20 log10(R) - 10 log10(MSE): R^2 overflowed (range 1e155 printed inf) or lost its digits
     * as a denormal (range 1e-161) where the figure itself is an ordinary number */
    res->value = mean > 0.0 ? 20.0 * log10(opt->data_range) - 10.0 * log10(mean) : INFINITY;
  else
    res->value = mean;
  return KPCN_OK;
}

kpcn_status kpcn_metric_planar(kpcn_metric m, const float *x, const float *y, int w, int h, int nch,
                               const kpcn_metric_options *opt_in, kpcn_metric_result *res,
                               float *errormap) {
  kpcn_metric_options opt;
  if (opt_in)
    opt = *opt_in;
  else
    kpcn_metric_options_defaults(&opt);
  if (!res) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "metric: result pointer is NULL");
  memset(res, 0, sizeof *res);
  res->value = NAN;
  if (m < 0 || m >= KPCN_METRIC_COUNT)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "metric: unknown metric id %d", (int)m);
  if (!x || !y)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s: image pointer is NULL", kpcn_metric_name(m));
  KPCN_TRY(kpcn_check_size(w, h, kpcn_metric_name(m)));
  if (nch <= 0)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s: no channels to compare (%d)",
                     kpcn_metric_name(m), nch);
  if (!(opt.data_range > 0.0) || !isfinite(opt.data_range))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s: data range must be positive (got %g)",
                     kpcn_metric_name(m), opt.data_range);
  /* eps = 0 would divide by zero at every black reference pixel (relMSE, relL1). */
  if (!(opt.eps > 0.0) || !isfinite(opt.eps))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s: eps must be > 0 (got %g)", kpcn_metric_name(m),
                     opt.eps);
  if (m == KPCN_METRIC_SSIM) return kpcn_ssim_planar(x, y, w, h, nch, &opt, res, errormap);
  return pointwise(m, x, y, w, h, nch, &opt, res, errormap);
}

static const char *const k_rgb[3] = {"R", "G", "B"};

static int has_name(const char *const *names, int n, const char *want) {
  for (int i = 0; i < n; i++)
    if (names[i] && !strcmp(names[i], want)) return 1;
  return 0;
}

static int names_aov(const char *const *names, int n) {
  for (int i = 0; i < n; i++)
    if (names[i] && strcmp(names[i], "R") && strcmp(names[i], "G") && strcmp(names[i], "B") &&
        strcmp(names[i], "A"))
      return 1;
  return 0;
}

int kpcn_metric_default_rgb(const char *const *xnames, int nx, const char *const *ynames, int ny) {
  if (!xnames || !ynames) return 0;
  for (int c = 0; c < 3; c++)
    if (!has_name(xnames, nx, k_rgb[c]) || !has_name(ynames, ny, k_rgb[c])) return 0;
  return names_aov(xnames, nx) || names_aov(ynames, ny);
}

/* Channel indices of the compared channels in x and y (see the header's matching rules). */
static kpcn_status match_channels(const kpcn_image *x, const kpcn_image *y,
                                  const char *const *channels, int nnames, int *ix, int *iy,
                                  int *count, const char *what) {
  if (!channels && kpcn_metric_default_rgb((const char *const *)x->names, x->nchannels,
                                           (const char *const *)y->names, y->nchannels))
    channels = k_rgb, nnames = 3;
  if (channels) {
    for (int k = 0; k < nnames; ++k) {
      if (!channels[k])
        return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s: channel name %d is NULL", what, k);
      ix[k] = kpcn_image_find_channel(x, channels[k]);
      iy[k] = kpcn_image_find_channel(y, channels[k]);
      if (ix[k] < 0 || iy[k] < 0)
        return kpcn_fail(KPCN_ERR_MISSING_CHANNEL, "%s: channel '%s' is missing from the %s image",
                         what, channels[k], ix[k] < 0 ? "test (first)" : "reference (second)");
    }
    *count = nnames;
    return KPCN_OK;
  }
  int all_named = 1;
  for (int k = 0; k < y->nchannels; ++k) {
    iy[k] = k;
    ix[k] = kpcn_image_find_channel(x, y->names[k]);
    if (ix[k] < 0 && all_named) all_named = -(k + 1);
  }
  if (all_named < 0) {
    if (x->nchannels != y->nchannels)
      return kpcn_fail(KPCN_ERR_SIZE_MISMATCH,
                       "%s: channel counts differ (test image %d, reference %d) and the "
                       "reference channel '%s' is not in the test image",
                       what, x->nchannels, y->nchannels, y->names[-all_named - 1]);
    return kpcn_fail(KPCN_ERR_MISSING_CHANNEL,
                     "%s: reference channel '%s' is missing from the test image", what,
                     y->names[-all_named - 1]);
  }
  *count = y->nchannels;
  return KPCN_OK;
}

kpcn_status kpcn_metric_image(kpcn_metric m, const kpcn_image *x, const kpcn_image *y,
                              const char *const *channels, int nnames,
                              const kpcn_metric_options *opt, kpcn_metric_result *res,
                              kpcn_image **errormap) {
  const char *what = kpcn_metric_name(m);
  if (errormap) *errormap = NULL;
  if (!x || !y || !res) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s: NULL argument", what);
  /* As kpcn_metric_planar: a failed call leaves a defined, empty result. */
  memset(res, 0, sizeof *res);
  res->value = NAN;
  if (x->width != y->width || x->height != y->height)
    return kpcn_fail(KPCN_ERR_SIZE_MISMATCH, "%s: image sizes differ (%dx%d vs %dx%d)", what,
                     x->width, x->height, y->width, y->height);
  /* a list and its length go together: one without the other was silently "every channel" */
  if (!channels != !nnames || nnames < 0)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "%s: channels %s with nnames %d (a list needs its length, NULL needs 0)", what,
                     channels ? "given" : "NULL", nnames);
  int maxn = channels ? nnames : y->nchannels > 3 ? y->nchannels : 3;
  if (maxn <= 0) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s: no channels to compare", what);
  int *ix = kpcn_alloc(sizeof(int) * 2 * (size_t)maxn, "channel map");
  if (!ix) return kpcn_last_status();
  int *iy = ix + maxn;
  int nch = 0;
  kpcn_status s = match_channels(x, y, channels, nnames, ix, iy, &nch, what);
  if (s != KPCN_OK) {
    free(ix);
    return s;
  }
  /* Gather the compared planes contiguously unless they already are (the common case of
   * identical layouts avoids the copy). */
  size_t n = (size_t)x->width * (size_t)x->height;
  int contiguous = 1;
  for (int k = 0; k < nch; ++k)
    if (ix[k] != ix[0] + k || iy[k] != iy[0] + k) contiguous = 0;
  float *bx = NULL;
  const float *px, *py;
  if (contiguous) {
    px = kpcn_image_plane(x, ix[0]);
    py = kpcn_image_plane(y, iy[0]);
  } else {
    bx = kpcn_alloc(sizeof(float) * 2 * n * (size_t)nch, "metric channel copy");
    if (!bx) {
      free(ix);
      return kpcn_last_status();
    }
    for (int k = 0; k < nch; ++k) {
      memcpy(bx + (size_t)k * n, kpcn_image_plane(x, ix[k]), n * sizeof(float));
      memcpy(bx + (size_t)(nch + k) * n, kpcn_image_plane(y, iy[k]), n * sizeof(float));
    }
    px = bx;
    py = bx + (size_t)nch * n;
  }
  kpcn_image *em = NULL;
  if (errormap) {
    const char **names = kpcn_alloc(sizeof(char *) * (size_t)nch, "channel names");
    if (!names) {
      s = kpcn_last_status();
      goto done;
    }
    for (int k = 0; k < nch; ++k)
      names[k] = y->names[iy[k]];
    s = kpcn_image_create(&em, x->width, x->height, nch, names);
    free(names);
    if (s != KPCN_OK) goto done;
  }
  s = kpcn_metric_planar(m, px, py, x->width, x->height, nch, opt, res, em ? em->data : NULL);
  if (s == KPCN_OK && errormap) {
    *errormap = em;
    em = NULL;
  }
done:
  if (em) kpcn_image_destroy(em);
  free(bx);
  free(ix);
  return s;
}
