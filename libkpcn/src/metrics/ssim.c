/* SSIM (Wang et al. 2004) matching scikit-image's structural_similarity with
 * gaussian_weights=True, sigma=1.5, use_sample_covariance=False (see kpcn/metrics.h).
 *
 * Why this shape: skimage filters the five moments (x, y, xx, yy, xy) with a separable
 * Gaussian of radius int(3.5*1.5+0.5) = 5 in scipy's 'reflect' boundary mode, forms the SSIM
 * map, then averages it over the image cropped by (win_size-1)/2 = 5 pixels. Because the
 * crop equals the filter radius, the averaged pixels never touch the boundary rule; the
 * 'reflect' rule is reproduced anyway so the error map equals skimage's full map.
 *
 * Work is done in blocks of output rows; each thread filters the rows its block needs
 * horizontally into thread-local double buffers, then vertically. Per-row sums in double are
 * added in row order, so the result does not depend on the thread count. */
#include "core/internal.h"
#include "metrics/metrics_internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define SSIM_R 5 /* filter radius: int(truncate * sigma + 0.5) with truncate 3.5, sigma 1.5 */
#define SSIM_W (2 * SSIM_R + 1)
#define SSIM_BLOCK 32 /* output rows per work item */

static void gaussian_kernel(double g[SSIM_W]) {
  const double sigma = 1.5;
  double sum = 0.0;
  for (int k = -SSIM_R; k <= SSIM_R; ++k) {
    g[k + SSIM_R] = exp(-0.5 / (sigma * sigma) * (double)(k * k));
    sum += g[k + SSIM_R];
  }
  for (int k = 0; k < SSIM_W; ++k) g[k] /= sum;
}

/* scipy.ndimage 'reflect' (half-sample symmetric): d c b a | a b c d | d c b a. n >= R. */
static inline int reflect(int i, int n) {
  if (i < 0) return -i - 1;
  if (i >= n) return 2 * n - 1 - i;
  return i;
}

/* Thread-local scratch: padded source moments of one row, the five horizontally filtered
 * moments for SSIM_BLOCK + 2R rows, and five vertical accumulators of one output row. */
typedef struct scratch {
  double *p[5];                      /* x, y, xx, yy, xy of one padded row, w + 2R each */
  double *hm[5];                     /* filtered moments, (SSIM_BLOCK + 2R) rows of w */
  double *acc[5];                    /* vertical accumulators, w each */
  double *mem;
} scratch;

static int scratch_alloc(scratch *s, int w) {
  size_t rows = SSIM_BLOCK + 2 * SSIM_R;
  size_t pad = (size_t)w + 2 * SSIM_R;
  s->mem = malloc(sizeof(double) * 5 * (pad + rows * (size_t)w + (size_t)w));
  if (!s->mem) return 0;
  double *q = s->mem;
  for (int m = 0; m < 5; ++m, q += pad) s->p[m] = q;
  for (int m = 0; m < 5; ++m, q += rows * (size_t)w) s->hm[m] = q;
  for (int m = 0; m < 5; ++m, q += w) s->acc[m] = q;
  return 1;
}

/* Horizontal pass of source row `r` into scratch row `dst`. Loops are written tap-outer,
 * pixel-inner so they vectorise; each output still sums its taps in order k = 0..10. */
static void filter_row(scratch *s, const float *a, const float *b, int w, int r, int dst,
                       const double g[SSIM_W]) {
  const float *ar = a + (size_t)r * w, *br = b + (size_t)r * w;
  double *px = s->p[0], *py = s->p[1], *pxx = s->p[2], *pyy = s->p[3], *pxy = s->p[4];
  for (int i = -SSIM_R; i < w + SSIM_R; ++i) {
    int j = reflect(i, w);
    double u = ar[j], v = br[j];
    px[i + SSIM_R] = u;
    py[i + SSIM_R] = v;
    pxx[i + SSIM_R] = u * u;
    pyy[i + SSIM_R] = v * v;
    pxy[i + SSIM_R] = u * v;
  }
  for (int m = 0; m < 5; ++m) {
    double *restrict h = s->hm[m] + (size_t)dst * w;
    const double *restrict p = s->p[m];
    for (int i = 0; i < w; ++i) h[i] = g[0] * p[i];
    for (int k = 1; k < SSIM_W; ++k) {
      const double gk = g[k];
      for (int i = 0; i < w; ++i) h[i] += gk * p[i + k];
    }
  }
}

/* SSIM of one channel (planes a, b already encoded, non-finite values zeroed). Row sums of
 * the SSIM map over valid interior pixels go to rowsum[h]. Returns 0 on allocation failure. */
static int ssim_channel(const float *a, const float *b, const uint8_t *mask, int w, int h,
                        double C1, double C2, int nt, double *rowsum, float *map) {
  double g[SSIM_W];
  gaussian_kernel(g);
  const int nblocks = (h + SSIM_BLOCK - 1) / SSIM_BLOCK;
  int failed = 0;
#pragma omp parallel num_threads(nt) reduction(| : failed)
  {
    scratch s = {0};
    int ok = scratch_alloc(&s, w);
    if (!ok) failed = 1;
#pragma omp for schedule(static)
    for (int blk = 0; blk < nblocks; ++blk) {
      if (!ok) continue;
      int y0 = blk * SSIM_BLOCK, y1 = y0 + SSIM_BLOCK < h ? y0 + SSIM_BLOCK : h;
      for (int r = y0 - SSIM_R; r < y1 + SSIM_R; ++r)
        filter_row(&s, a, b, w, reflect(r, h), r - (y0 - SSIM_R), g);
      for (int y = y0; y < y1; ++y) {
        for (int m = 0; m < 5; ++m) {
          double *restrict acc = s.acc[m];
          const double *restrict hr = s.hm[m] + (size_t)(y - y0) * w;
          for (int x = 0; x < w; ++x) acc[x] = g[0] * hr[x];
          for (int k = 1; k < SSIM_W; ++k) {
            const double gk = g[k];
            hr = s.hm[m] + (size_t)(y - y0 + k) * w;
            for (int x = 0; x < w; ++x) acc[x] += gk * hr[x];
          }
        }
        const double *ux = s.acc[0], *uy = s.acc[1], *uxx = s.acc[2], *uyy = s.acc[3];
        const double *uxy = s.acc[4];
        const uint8_t *mrow = mask + (size_t)y * w;
        /* Reuse acc[0] for the map row: ux[x] is read before S is stored at x. */
        double *S = s.acc[0];
        for (int x = 0; x < w; ++x) {
          double mx = ux[x], my = uy[x];
          double vx = uxx[x] - mx * mx, vy = uyy[x] - my * my, vxy = uxy[x] - mx * my;
          S[x] = ((2 * mx * my + C1) * (2 * vxy + C2)) / ((mx * mx + my * my + C1) * (vx + vy + C2));
        }
        double sum = 0.0;
        if (y >= SSIM_R && y < h - SSIM_R)
          for (int x = SSIM_R; x < w - SSIM_R; ++x)
            if (mrow[x]) sum += S[x];
        if (map)
          for (int x = 0; x < w; ++x) map[(size_t)y * w + x] = mrow[x] ? (float)S[x] : NAN;
        rowsum[y] = sum;
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
                     "ssim: image of %dx%d is smaller than the %dx%d window", w, h, SSIM_W,
                     SSIM_W);
  int nt = kpcn_resolve_threads(opt->nthreads);
  int64_t nonfinite = 0;
  uint8_t *mask = kpcn_metric_valid_mask(x, y, w, h, nch, nt, &nonfinite);
  if (!mask) return kpcn_last_status();
  const size_t n = (size_t)w * (size_t)h;
  float *wa = kpcn_alloc(sizeof(float) * 2 * n, "ssim working planes");
  double *rowsum = kpcn_calloc((size_t)h, sizeof(double), "ssim row sums");
  kpcn_status st = KPCN_OK;
  if (!wa || !rowsum) {
    st = kpcn_last_status();
    goto done;
  }
  int64_t valid = 0;
  for (int r = SSIM_R; r < h - SSIM_R; ++r)
    for (int c = SSIM_R; c < w - SSIM_R; ++c) valid += mask[(size_t)r * w + c];
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
    double total = 0.0;
    for (int r = 0; r < h; ++r) total += rowsum[r];
    channel_sum += total / (double)valid; /* skimage: mean per channel, then over channels */
  }
  res->value = channel_sum / nch;
done:
  free(rowsum);
  free(wa);
  free(mask);
  return st;
}
