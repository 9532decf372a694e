/* Classical baselines (seed §2.3): feature-guided cross-bilateral filter and non-local
 * means with variance-normalised colour distances (Rousselle et al. 2012/2013).
 *
 * Both filter the `color` buffer. Weight of neighbour q for pixel p:
 *   bilateral: exp(-|p-q|^2 / (2 sigma_s^2)) * exp(-max(0, dc(p,q))) * wf(p,q)
 *   nlmeans:   exp(-max(0, mean over the (2f+1)^2 patch of dc(p+n, q+n)))   * wf(p,q)
 * with the variance-cancelled colour distance (v = color.var, variance of the mean)
 *   dc(p,q) = (mean_c (c_p - c_q)^2 - (v_p + min(v_p, v_q))) / (1e-10 + k^2 (v_p + v_q))
 * (the subtracted term removes the expected noise part of the squared difference, so
 * equal underlying colours give dc ~ 0), and the feature weight
 *   wf = exp(-|dN|^2/(2 sn^2) - |dA|^2/(2 sa^2) - dZ^2/(2 sz^2))
 * over normal, albedo and depth normalised per image (a sigma <= 0 disables a feature).
 * Deterministic: each output pixel is accumulated by one thread in a fixed order. */
#include "core/internal.h"
#include "denoise_internal.h"

#include <float.h>
#include <math.h>
#include <string.h>
#ifdef _OPENMP
#include <omp.h>
#endif

typedef struct guide {
  int W, H;
  const float *c[3], *v;
  const float *n[3], *a[3], *z;
  float in, ia, iz; /* 1/(2 sigma^2) or 0 */
  float zoff, zscale;
  float k2;
  float veps; /* the colour distance's denominator floor, in the image's units squared */
} guide;

/* 1 / (2 sigma^2) for a sigma > 0, refused where it overflows (a sigma of 1e-30 gave Inf
 * weights, then NaN pixels, reported as a damaged model). */
static kpcn_status inv_two_sq(float sigma, const char *what, const char *name, float *out) {
  const float v = 0.5f / (sigma * sigma);
  if (!isfinite(v))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "%s: %s %g is too small (1 / (2 %s^2) overflows a float)", what, name,
                     (double)sigma, name);
  *out = v;
  return KPCN_OK;
}

static const char *baseline_name(int nlmeans) {
  return nlmeans ? "non-local means" : "bilateral filter";
}

kpcn_status kpcn_baseline_params_check(const kpcn_baseline_params *p, int nlmeans) {
  const char *what = baseline_name(nlmeans);
  float v;
  if (!p) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s: parameters are NULL", what);
  if (p->radius < 0 || p->radius > 64)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s: radius %d outside [0, 64]", what, p->radius);
  if (!(p->k_color > 0.0f) || !isfinite(p->k_color * p->k_color))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s: k_color must be > 0 with a finite square",
                     what);
  if (p->sigma_normal > 0.0f) KPCN_TRY(inv_two_sq(p->sigma_normal, what, "sigma_normal", &v));
  if (p->sigma_albedo > 0.0f) KPCN_TRY(inv_two_sq(p->sigma_albedo, what, "sigma_albedo", &v));
  if (p->sigma_depth > 0.0f) KPCN_TRY(inv_two_sq(p->sigma_depth, what, "sigma_depth", &v));
  if (nlmeans && (p->patch_radius < 0 || p->patch_radius > 16))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "non-local means: patch_radius %d outside [0, 16]",
                     p->patch_radius);
  if (!nlmeans && !(p->sigma_spatial > 0.0f))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "bilateral filter: sigma_spatial must be > 0");
  if (!nlmeans) KPCN_TRY(inv_two_sq(p->sigma_spatial, what, "sigma_spatial", &v));
  return KPCN_OK;
}

/* the parameters checked (kpcn_baseline_params_check), the guide buffers taken from aov */
static kpcn_status guide_init(guide *g, const kpcn_aov_set *aov, const kpcn_baseline_params *p,
                              int nlmeans) {
  const char *what = baseline_name(nlmeans);
  memset(g, 0, sizeof *g);
  KPCN_TRY(kpcn_baseline_params_check(p, nlmeans));
  KPCN_TRY(kpcn_aov_require(aov, KPCN_BUF_COLOR, 1, what));
  g->W = aov->width;
  g->H = aov->height;
  const size_t P = kpcn_aov_plane_size(aov);
  for (int c = 0; c < 3; c++)
    g->c[c] = aov->buf[KPCN_BUF_COLOR] + c * P;
  g->v = aov->var[KPCN_BUF_COLOR];
  g->k2 = p->k_color * p->k_color;
  /* Rousselle's floor 1e-10 assumes colours near 1; taken relative to the image's mean
   * |colour| squared it scales with the render's units, so the filters are exposure-invariant
   * as documented (a render scaled by 2^-15 with its variances by 2^-30 came out up to 6x
   * different per pixel: the fixed floor outweighed variances below ~1e-10). Kept a normal
   * float (a black image: any positive floor; distances are 0 there). */
  double msum = 0.0;
  for (int c = 0; c < 3; c++)
    for (size_t i = 0; i < P; i++)
      msum += fabs((double)g->c[c][i]);
  const double m = msum / (3.0 * (double)P);
  const double veps = 1e-10 * m * m;
  g->veps = veps >= FLT_MIN ? (float)veps : FLT_MIN;
  if (p->sigma_normal > 0.0f) {
    KPCN_TRY(kpcn_aov_require(aov, KPCN_BUF_NORMAL, 0, what));
    for (int c = 0; c < 3; c++)
      g->n[c] = aov->buf[KPCN_BUF_NORMAL] + c * P;
    KPCN_TRY(inv_two_sq(p->sigma_normal, what, "sigma_normal", &g->in));
  }
  if (p->sigma_albedo > 0.0f) {
    KPCN_TRY(kpcn_aov_require(aov, KPCN_BUF_ALBEDO, 0, what));
    for (int c = 0; c < 3; c++)
      g->a[c] = aov->buf[KPCN_BUF_ALBEDO] + c * P;
    KPCN_TRY(inv_two_sq(p->sigma_albedo, what, "sigma_albedo", &g->ia));
  }
  if (p->sigma_depth > 0.0f) {
    kpcn_features_norm nm;
    KPCN_TRY(kpcn_features_norm_compute(aov, &nm));
    g->z = aov->buf[KPCN_BUF_DEPTH];
    g->zoff = nm.depth_offset;
    g->zscale = nm.depth_scale;
    KPCN_TRY(inv_two_sq(p->sigma_depth, what, "sigma_depth", &g->iz));
  }
  return KPCN_OK;
}

/* Exponent of the feature weight between pixel indices i and j. */
static inline float feat_dist(const guide *g, size_t i, size_t j) {
  float d = 0.0f;
  if (g->in > 0.0f) {
    float s = 0.0f;
    for (int c = 0; c < 3; c++) {
      float t = g->n[c][i] - g->n[c][j];
      s += t * t;
    }
    d += s * g->in;
  }
  if (g->ia > 0.0f) {
    float s = 0.0f;
    for (int c = 0; c < 3; c++) {
      float t = g->a[c][i] - g->a[c][j];
      s += t * t;
    }
    d += s * g->ia;
  }
  if (g->iz > 0.0f) {
    float t = (g->z[i] - g->z[j]) * g->zscale;
    d += t * t * g->iz;
  }
  return d;
}

static inline float color_dist(const guide *g, size_t i, size_t j) {
  float s = 0.0f;
  for (int c = 0; c < 3; c++) {
    float t = g->c[c][i] - g->c[c][j];
    s += t * t;
  }
  float vi = g->v[i], vj = g->v[j];
  float vmin = vi < vj ? vi : vj;
  return (s * (1.0f / 3.0f) - (vi + vmin)) / (g->veps + g->k2 * (vi + vj));
}

/* Both filters run offset-major over square tiles: for every offset o of the search
 * window, the per-pixel colour distance image of the tile (plus the patch margin) is
 * computed in contiguous, vectorisable loops and box-filtered with the patch size (NL-means;
 * f = 0 for the bilateral filter), which makes the patch distance O(1) per pixel and
 * offset. Each output pixel is accumulated by one thread in a fixed offset order. */
#define NLM_TILE 64

static kpcn_status offset_filter(const guide *gp, int r, int f, float is, const char *what,
                                 float *out, int nthreads, kpcn_progress *prog) {
  const guide g = *gp;
  const int W = g.W, H = g.H;
  const int nt = kpcn_resolve_threads(nthreads);
  const size_t P = (size_t)W * H;
  const int tx = (W + NLM_TILE - 1) / NLM_TILE, ty = (H + NLM_TILE - 1) / NLM_TILE;
  const int ntiles = tx * ty;
  const int M = NLM_TILE + 2 * f; /* tile plus patch margin */
  /* Per-thread scratch: distance image, row-summed image, accumulators. */
  const size_t per = (size_t)M * M * 2 + (size_t)NLM_TILE * NLM_TILE * 4;
  float *scratch = kpcn_aligned_alloc(per * (size_t)nt * sizeof(float), "baseline filter scratch");
  if (!scratch) return KPCN_ERR_OUT_OF_MEMORY;
  int done = 0, cancelled = 0;
#pragma omp parallel num_threads(nt)
  {
#ifdef _OPENMP
    float *s = scratch + per * (size_t)omp_get_thread_num();
#else
    float *s = scratch;
#endif
    float *D = s, *R = s + (size_t)M * M, *acc = R + (size_t)M * M;
#pragma omp for schedule(dynamic, 1)
    for (int t = 0; t < ntiles; t++) {
      int stop;
#pragma omp atomic read
      stop = cancelled;
      if (stop) continue;
      const int x0 = (t % tx) * NLM_TILE, y0 = (t / tx) * NLM_TILE;
      const int x1 = x0 + NLM_TILE < W ? x0 + NLM_TILE : W,
                y1 = y0 + NLM_TILE < H ? y0 + NLM_TILE : H;
      const int tw = x1 - x0, th = y1 - y0;
      /* margin region clipped to the image */
      const int mx0 = x0 - f > 0 ? x0 - f : 0, my0 = y0 - f > 0 ? y0 - f : 0;
      const int mx1 = x1 + f < W ? x1 + f : W, my1 = y1 + f < H ? y1 + f : H;
      const int mw = mx1 - mx0, mh = my1 - my0;
      memset(acc, 0, sizeof(float) * 4 * (size_t)NLM_TILE * NLM_TILE);
      for (int oy = -r; oy <= r; oy++) {
        for (int ox = -r; ox <= r; ox++) {
          const float sp = (float)(ox * ox + oy * oy) * is; /* bilateral spatial term */
          /* distance image over the margin region; partner coordinates clamped */
          for (int yy = 0; yy < mh; yy++) {
            const int y = my0 + yy;
            int qy = y + oy;
            qy = qy < 0 ? 0 : qy >= H ? H - 1 : qy;
            for (int xx = 0; xx < mw; xx++) {
              const int x = mx0 + xx;
              int qx = x + ox;
              qx = qx < 0 ? 0 : qx >= W ? W - 1 : qx;
              D[yy * mw + xx] = color_dist(&g, (size_t)y * W + x, (size_t)qy * W + qx);
            }
          }
          /* horizontal box sums (window clipped to the margin region) */
          for (int yy = 0; yy < mh; yy++) {
            const float *d = D + yy * mw;
            float *o = R + yy * mw;
            for (int xx = 0; xx < mw; xx++) {
              int a = xx - f < 0 ? 0 : xx - f, b = xx + f >= mw ? mw - 1 : xx + f;
              float sum = 0.0f;
              for (int k = a; k <= b; k++)
                sum += d[k];
              o[xx] = sum;
            }
          }
          for (int y = y0; y < y1; y++) {
            const int qy = y + oy;
            if (qy < 0 || qy >= H) continue;
            const int yy = y - my0;
            const int a = yy - f < 0 ? 0 : yy - f, b = yy + f >= mh ? mh - 1 : yy + f;
            for (int x = x0; x < x1; x++) {
              const int qx = x + ox;
              if (qx < 0 || qx >= W) continue;
              const int xx = x - mx0;
              const int ca = xx - f < 0 ? 0 : xx - f, cb = xx + f >= mw ? mw - 1 : xx + f;
              float sum = 0.0f;
              for (int k = a; k <= b; k++)
                sum += R[k * mw + xx];
              const float dp = sum / (float)((b - a + 1) * (cb - ca + 1));
              const size_t i = (size_t)y * W + x, j = (size_t)qy * W + qx;
              const float w = expf(-(sp + (dp > 0.0f ? dp : 0.0f) + feat_dist(&g, i, j)));
              float *ac = acc + 4 * ((size_t)(y - y0) * NLM_TILE + (x - x0));
              ac[0] += w * g.c[0][j];
              ac[1] += w * g.c[1][j];
              ac[2] += w * g.c[2][j];
              ac[3] += w;
            }
          }
        }
      }
      for (int yy = 0; yy < th; yy++)
        for (int xx = 0; xx < tw; xx++) {
          const float *ac = acc + 4 * ((size_t)yy * NLM_TILE + xx);
          const size_t i = (size_t)(y0 + yy) * W + x0 + xx;
          for (int c = 0; c < 3; c++)
            out[c * P + i] = ac[c] / ac[3];
        }
#pragma omp critical(kpcn_nlm_progress)
      {
        done++;
        if (kpcn_progress_report(prog, (double)done / ntiles)) {
#pragma omp atomic write
          cancelled = 1;
        }
      }
    }
  }
  kpcn_aligned_free(scratch);
  if (cancelled)
    return kpcn_fail(KPCN_ERR_CANCELLED, "%s: cancelled by the progress callback", what);
  return KPCN_OK;
}

kpcn_status kpcn_baseline_bilateral(const kpcn_aov_set *aov, const kpcn_baseline_params *p,
                                    float *out, int nthreads, kpcn_progress *prog) {
  guide g;
  KPCN_TRY(guide_init(&g, aov, p, 0));
  float is = 0.0f;
  KPCN_TRY(inv_two_sq(p->sigma_spatial, "bilateral filter", "sigma_spatial", &is));
  /* a bilateral filter is the offset filter with 1x1 "patches" plus the spatial term */
  return offset_filter(&g, p->radius, 0, is, "bilateral filter", out, nthreads, prog);
}

kpcn_status kpcn_baseline_nlmeans(const kpcn_aov_set *aov, const kpcn_baseline_params *p,
                                  float *out, int nthreads, kpcn_progress *prog) {
  guide g;
  KPCN_TRY(guide_init(&g, aov, p, 1));
  return offset_filter(&g, p->radius, p->patch_radius, 0.0f, "non-local means", out, nthreads,
                       prog);
}
