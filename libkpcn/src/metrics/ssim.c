/* SSIM (Wang et al. 2004) matching scikit-image's structural_similarity with
 * gaussian_weights=True, sigma=1.5, use_sample_covariance=False (see kpcn/metrics.h).
 *
 * Why this shape: skimage filters the five moments (x, y, xx, yy, xy) with a separable
 * Gaussian of radius int(3.5*1.5+0.5) = 5 in scipy's 'reflect' boundary mode, forms the SSIM
 * map, then averages it over the image cropped by (win_size-1)/2 = 5 pixels. Because the
 * crop equals the filter radius, the averaged pixels never touch the boundary rule; the
 * 'reflect' rule is reproduced anyway so the error map equals skimage's full map.
 *
 * Work items are column strips x row blocks; each thread filters the rows its item needs
 * horizontally into a thread-local ring of double rows, then vertically. Partial sums per
 * (row, strip) in double are added in a fixed order, so the result does not depend on the
 * thread count.
 *
 * Precision: sigma^2 = E[x^2] - E[x]^2 cancels where values are large against the data range
 * (a flat 1e5 region at range 1 gave SSIM 1.004: E[x^2]'s rounding alone exceeds C2). Such
 * pixels, where the moments' possible rounding could move the denominator by more than 1e-9
 * of itself, are computed again directly from their window, deviations from the window mean
 * first (exact_moments); elsewhere (values below ~16x the range) the filtered moments are
 * kept. The two factors of S are divided separately, so C1 * C2 never overflows or
 * underflows (identical images gave NaN at range 1e-80), and nothing here is contracted to
 * an FMA, so mx*mx + my*my equals 2*mx*my when x == y and SSIM(x, x) is exactly 1. */
#include "core/internal.h"
#include "metrics/metrics_internal.h"

#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC optimize("fp-contract=off")
#endif

#define SSIM_R 5 /* filter radius: int(truncate * sigma + 0.5) with truncate 3.5, sigma 1.5 */
#define SSIM_W (2 * SSIM_R + 1)

static void gaussian_kernel(double g[SSIM_W]) {
  const double sigma = 1.5;
  double sum = 0.0;
  for (int k = -SSIM_R; k <= SSIM_R; ++k) {
    g[k + SSIM_R] = exp(-0.5 / (sigma * sigma) * (double)(k * k));
    sum += g[k + SSIM_R];
  }
  for (int k = 0; k < SSIM_W; ++k)
    g[k] /= sum;
}

/* scipy.ndimage 'reflect' (half-sample symmetric): d c b a | a b c d | d c b a. n >= R. */
static inline int reflect(int i, int n) {
  if (i < 0) return -i - 1;
  if (i >= n) return 2 * n - 1 - i;
  return i;
}

/* Work is split into column strips x row blocks so the 11 horizontally filtered rows a
 * vertical tap needs stay in L2 (a ring buffer of 11 rows x 5 moments x SSIM_SW doubles,
 * ~110 KB) instead of streaming whole 4K-wide rows from memory. */
#define SSIM_SW 256 /* output columns per strip */
#define SSIM_BH 64  /* output rows per block */

typedef struct scratch {
  double *p[5];    /* x, y, xx, yy, xy of one padded input row segment, SSIM_SW + 2R */
  double *ring[5]; /* filtered moments, SSIM_W rows of SSIM_SW (row r at r % SSIM_W) */
  double *acc[5];  /* vertical accumulators, SSIM_SW */
  double *mem;
} scratch;

static int scratch_alloc(scratch *s) {
  const size_t pad = SSIM_SW + 2 * SSIM_R;
  s->mem = malloc(sizeof(double) * 5 * (pad + (size_t)SSIM_W * SSIM_SW + SSIM_SW));
  if (!s->mem) return 0;
  double *q = s->mem;
  for (int m = 0; m < 5; ++m, q += pad)
    s->p[m] = q;
  for (int m = 0; m < 5; ++m, q += (size_t)SSIM_W * SSIM_SW)
    s->ring[m] = q;
  for (int m = 0; m < 5; ++m, q += SSIM_SW)
    s->acc[m] = q;
  return 1;
}

/* Horizontal pass of source row r, output columns [x0, x0+n), into ring slot `slot`. Loops
 * are tap-outer, pixel-inner so they vectorise; each output sums its taps in order 0..10. */
static void filter_row(scratch *s, const float *a, const float *b, int w, int r, int x0, int n,
                       int slot, const double g[SSIM_W]) {
  const float *ar = a + (size_t)r * w, *br = b + (size_t)r * w;
  double *px = s->p[0], *py = s->p[1], *pxx = s->p[2], *pyy = s->p[3], *pxy = s->p[4];
  for (int i = 0; i < n + 2 * SSIM_R; ++i) {
    int j = reflect(x0 - SSIM_R + i, w);
    double u = ar[j], v = br[j];
    px[i] = u;
    py[i] = v;
    pxx[i] = u * u;
    pyy[i] = v * v;
    pxy[i] = u * v;
  }
  for (int m = 0; m < 5; ++m) {
    double *restrict hrow = s->ring[m] + (size_t)slot * SSIM_SW;
    const double *restrict p = s->p[m];
    for (int i = 0; i < n; ++i)
      hrow[i] = g[0] * p[i];
    for (int k = 1; k < SSIM_W; ++k) {
      const double gk = g[k];
      for (int i = 0; i < n; ++i)
        hrow[i] += gk * p[i + k];
    }
  }
}

/* The moments of pixel (px, py)'s window taken directly: the weighted means first, then the
 * weighted squared deviations from them, so nothing of the values' magnitude cancels. */
static void exact_moments(const float *a, const float *b, int w, int h, int px, int py,
                          const double g[SSIM_W], double m[5]) {
  double sx = 0.0, sy = 0.0;
  for (int l = 0; l < SSIM_W; ++l) {
    const size_t row = (size_t)reflect(py - SSIM_R + l, h) * w;
    for (int k = 0; k < SSIM_W; ++k) {
      const double gw = g[l] * g[k];
      const size_t j = row + reflect(px - SSIM_R + k, w);
      sx += gw * a[j];
      sy += gw * b[j];
    }
  }
  double vx = 0.0, vy = 0.0, vxy = 0.0;
  for (int l = 0; l < SSIM_W; ++l) {
    const size_t row = (size_t)reflect(py - SSIM_R + l, h) * w;
    for (int k = 0; k < SSIM_W; ++k) {
      const double gw = g[l] * g[k];
      const size_t j = row + reflect(px - SSIM_R + k, w);
      const double dx = a[j] - sx, dy = b[j] - sy;
      vx += gw * dx * dx;
      vy += gw * dy * dy;
      vxy += gw * dx * dy;
    }
  }
  m[0] = sx, m[1] = sy, m[2] = vx, m[3] = vy, m[4] = vxy;
}

/* Vertical pass for output row y (ring holds source rows y-R .. y+R), then the SSIM map
 * segment. Adds the valid interior values to *sum, writes the map segment if requested.
 * a, b are the channel's planes (for exact_moments). */
static void finish_row(scratch *s, const float *a, const float *b, int y, int x0, int n, int w,
                       int h, const uint8_t *mask, double C1, double C2, const double g[SSIM_W],
                       float *map, double *sum) {
  for (int m = 0; m < 5; ++m) {
    double *restrict acc = s->acc[m];
    const double *restrict hr = s->ring[m] + (size_t)((y - SSIM_R + SSIM_W) % SSIM_W) * SSIM_SW;
    for (int i = 0; i < n; ++i)
      acc[i] = g[0] * hr[i];
    for (int k = 1; k < SSIM_W; ++k) {
      const double gk = g[k];
      hr = s->ring[m] + (size_t)((y - SSIM_R + k + SSIM_W) % SSIM_W) * SSIM_SW;
      for (int i = 0; i < n; ++i)
        acc[i] += gk * hr[i];
    }
  }
  const double *ux = s->acc[0], *uy = s->acc[1], *uxx = s->acc[2], *uyy = s->acc[3];
  const double *uxy = s->acc[4];
  double *S = s->acc[0]; /* ux[i] is read before S[i] overwrites it */
  for (int i = 0; i < n; ++i) {
    double mx = ux[i], my = uy[i];
    double vx = uxx[i] - mx * mx, vy = uyy[i] - my * my, vxy = uxy[i] - mx * my;
    /* the moments' rounding is about eps * (E[x^2] + E[y^2] + 2|E[xy]|) (a few ulps of
     * the sums of 121 positive terms); where that is not negligible against the contrast
     * term's denominator, the window is summed again directly */
    if (4.0 * DBL_EPSILON * (uxx[i] + uyy[i] + 2.0 * fabs(uxy[i])) > 1e-9 * (vx + vy + C2)) {
      double em[5];
      exact_moments(a, b, w, h, x0 + i, y, g, em);
      mx = em[0], my = em[1], vx = em[2], vy = em[3], vxy = em[4];
    }
    S[i] = ((2 * mx * my + C1) / (mx * mx + my * my + C1)) * ((2 * vxy + C2) / (vx + vy + C2));
  }
  const uint8_t *mrow = mask + (size_t)y * w + x0;
  if (y >= SSIM_R && y < h - SSIM_R) {
    int lo = x0 < SSIM_R ? SSIM_R - x0 : 0;
    int hi = x0 + n > w - SSIM_R ? w - SSIM_R - x0 : n;
    double t = 0.0;
    for (int i = lo; i < hi; ++i)
      if (mrow[i]) t += S[i];
    *sum = t;
  } else {
    *sum = 0.0;
  }
  if (map) {
    float *mp = map + (size_t)y * w + x0;
    for (int i = 0; i < n; ++i)
      mp[i] = mrow[i] ? (float)S[i] : NAN;
  }
}

/* SSIM of one channel (planes a, b already encoded, non-finite values zeroed). Partial row
 * sums per strip go to part[strip * h + y]. Returns 0 on allocation failure. */
static int ssim_channel(const float *a, const float *b, const uint8_t *mask, int w, int h,
                        double C1, double C2, int nt, double *part, float *map) {
  double g[SSIM_W];
  gaussian_kernel(g);
  const int nstrips = (w + SSIM_SW - 1) / SSIM_SW, nblocks = (h + SSIM_BH - 1) / SSIM_BH;
  int failed = 0;
#pragma omp parallel num_threads(nt) reduction(| : failed)
  {
    scratch s = {0};
    int ok = scratch_alloc(&s);
    if (!ok) failed = 1;
#pragma omp for schedule(dynamic)
    for (int item = 0; item < nstrips * nblocks; ++item) {
      if (!ok) continue;
      int strip = item % nstrips, blk = item / nstrips;
      int x0 = strip * SSIM_SW, n = x0 + SSIM_SW < w ? SSIM_SW : w - x0;
      int y0 = blk * SSIM_BH, y1 = y0 + SSIM_BH < h ? y0 + SSIM_BH : h;
      /* Ring slots are indexed by (row + SSIM_W) % SSIM_W so negative rows work. */
      for (int r = y0 - SSIM_R; r < y1 + SSIM_R; ++r) {
        filter_row(&s, a, b, w, reflect(r, h), x0, n, (r + SSIM_W) % SSIM_W, g);
        int y = r - SSIM_R;
        if (y >= y0)
          finish_row(&s, a, b, y, x0, n, w, h, mask, C1, C2, g, map, &part[(size_t)strip * h + y]);
      }
    }
    free(s.mem);
  }
  return !failed;
}

kpcn_status kpcn_ssim_planar(const float *x, const float *y, int w, int h, int nch,
                             const kpcn_metric_options *opt, kpcn_metric_result *res,
                             float *errormap) {
  if (w < SSIM_W || h < SSIM_W)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "ssim: image of %dx%d is smaller than the %dx%d window", w, h, SSIM_W, SSIM_W);
  int nt = kpcn_resolve_threads(opt->nthreads);
  int64_t nonfinite = 0;
  uint8_t *mask = kpcn_metric_valid_mask(x, y, w, h, nch, nt, &nonfinite);
  if (!mask) return kpcn_last_status();
  const size_t n = (size_t)w * (size_t)h;
  float *wa = kpcn_alloc(sizeof(float) * 2 * n, "ssim working planes");
  const int nstrips = (w + SSIM_SW - 1) / SSIM_SW;
  double *rowsum = kpcn_calloc((size_t)h * nstrips, sizeof(double), "ssim row sums");
  kpcn_status st = KPCN_OK;
  if (!wa || !rowsum) {
    st = kpcn_last_status();
    goto done;
  }
  int64_t valid = 0;
  for (int r = SSIM_R; r < h - SSIM_R; ++r)
    for (int c = SSIM_R; c < w - SSIM_R; ++c)
      valid += mask[(size_t)r * w + c];
  res->nonfinite = nonfinite;
  res->npixels = valid;
  res->nchannels = nch;
  if (valid == 0) {
    st = kpcn_fail(KPCN_ERR_NONFINITE,
                   "ssim: no finite pixel in the interior (%lld non-finite pixels)",
                   (long long)nonfinite);
    goto done;
  }
  const double R = opt->data_range;
  const double C1 = (0.01 * R) * (0.01 * R), C2 = (0.03 * R) * (0.03 * R);
  const int srgb = opt->display == KPCN_DISPLAY_SRGB;
  float *wb = wa + n;
  double channel_sum = 0.0;
  for (int c = 0; c < nch; ++c) {
    const float *xc = x + (size_t)c * n, *yc = y + (size_t)c * n;
#pragma omp parallel for num_threads(nt) schedule(static)
    for (int r = 0; r < h; ++r)
      for (int i = r * w; i < (r + 1) * w; ++i) {
        /* Non-finite pixels become 0 in both images: equal values, no NaN spreading. */
        double p = mask[i] ? xc[i] : 0.0, q = mask[i] ? yc[i] : 0.0;
        if (srgb) {
          p = kpcn_srgb_encode(p);
          q = kpcn_srgb_encode(q);
        }
        wa[i] = (float)p;
        wb[i] = (float)q;
      }
    if (!ssim_channel(wa, wb, mask, w, h, C1, C2, nt, rowsum,
                      errormap ? errormap + (size_t)c * n : NULL)) {
      st = kpcn_fail(KPCN_ERR_OUT_OF_MEMORY, "ssim: cannot allocate filter scratch (%d wide)", w);
      goto done;
    }
    double total = 0.0; /* fixed order: rows, and strips within a row */
    for (int r = 0; r < h; ++r)
      for (int st = 0; st < nstrips; ++st)
        total += rowsum[(size_t)st * h + r];
    channel_sum += total / (double)valid; /* skimage: mean per channel, then over channels */
  }
  res->value = channel_sum / nch;
  /* C1 = (0.01 R)^2 underflows to 0 or overflows for R beyond about 1e-160 .. 1e150: flat
   * windows then give 0/0 */
  if (!isfinite(res->value))
    st = kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                   "ssim: the result is not finite at data range %g (C1 = %g, C2 = %g): choose a "
                   "range nearer the images' values",
                   R, C1, C2);
done:
  free(rowsum);
  free(wa);
  free(mask);
  return st;
}
