/* Patch selection with flat-patch culling (seed §4.4) and optional variance-proportional
 * sampling. The criterion is described in kpcn/augment.h and docs/dataset.md. */
#include "core/internal.h"
#include "kpcn/augment.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

void kpcn_patch_settings_defaults(kpcn_patch_settings *s) {
  memset(s, 0, sizeof *s);
  s->size = 65;
  s->count = 400;
  s->stride = 0;
  s->seed = 1;
  s->cull = 0.9;
  s->cull_tol = 0.05;
  s->cull_abs = 0.01;
}

/* k-th smallest of a (destroys order): Hoare quickselect, expected linear. */
static float select_kth(float *a, int n, int k) {
  int lo = 0, hi = n - 1;
  while (lo < hi) {
    float pivot = a[(lo + hi) / 2];
    int i = lo, j = hi;
    while (i <= j) {
      while (a[i] < pivot)
        i++;
      while (a[j] > pivot)
        j--;
      if (i <= j) {
        float t = a[i];
        a[i] = a[j];
        a[j] = t;
        i++;
        j--;
      }
    }
    if (k <= j)
      hi = j;
    else if (k >= i)
      lo = i;
    else
      return a[k];
  }
  return a[k];
}

double kpcn_patch_flat_fraction(const float *r, const float *g, const float *b, int stride, int x0,
                                int y0, int size, double cull_tol, double cull_abs) {
  const float *ch[3] = {r, g, b};
  int n = size * size;
  float *tmp = malloc(sizeof(float) * (size_t)n);
  if (!tmp) return 0.0; /* cannot judge: keep the patch */
  double m[3];
  for (int c = 0; c < 3; c++) {
    for (int y = 0; y < size; y++)
      for (int x = 0; x < size; x++)
        tmp[y * size + x] = ch[c][(size_t)(y0 + y) * (size_t)stride + (size_t)(x0 + x)];
    /* Lower median for even n; NaNs (should not occur) simply count as "not near". */
    m[c] = select_kth(tmp, n, (n - 1) / 2);
  }
  free(tmp);
  double tol = cull_tol * ((m[0] + m[1] + m[2]) / 3.0 + cull_abs);
  int near = 0;
  for (int y = 0; y < size; y++) {
    for (int x = 0; x < size; x++) {
      size_t i = (size_t)(y0 + y) * (size_t)stride + (size_t)(x0 + x);
      /* near when every channel is within the tolerance; a NaN difference (a non-finite value
       * or median) is far, so the patch is kept and reaches the writer's finiteness check */
      int is_near = 1;
      for (int c = 0; c < 3; c++)
        if (!(fabs((double)ch[c][i] - m[c]) <= tol)) is_near = 0;
      near += is_near;
    }
  }
  return (double)near / (double)n;
}

static uint64_t sm64(uint64_t *s) {
  uint64_t z = (*s += 0x9e3779b97f4a7c15ull);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  return z ^ (z >> 31);
}
static double unif(uint64_t *s) { return (double)(sm64(s) >> 11) * (1.0 / 9007199254740992.0); }

/* Cumulative weights over all valid origins: mean color.var in the window (summed-area
 * table) plus a floor of 10% of the image-mean weight. */
static double *importance_cdf(const kpcn_aov_set *noisy, int S, int nx, int ny) {
  int W = noisy->width, H = noisy->height;
  double *sat = kpcn_calloc((size_t)(W + 1) * (size_t)(H + 1), sizeof(double), "variance SAT");
  double *cdf = kpcn_alloc(sizeof(double) * (size_t)nx * (size_t)ny, "patch importance");
  if (!sat || !cdf) {
    free(sat);
    free(cdf);
    return NULL;
  }
  const float *v = noisy->var[KPCN_BUF_COLOR];
  for (int y = 0; y < H; y++) {
    double row = 0;
    for (int x = 0; x < W; x++) {
      double val = v[(size_t)y * W + x];
      row += isfinite(val) && val > 0 ? val : 0;
      sat[(size_t)(y + 1) * (W + 1) + x + 1] = sat[(size_t)y * (W + 1) + x + 1] + row;
    }
  }
  double total = 0;
  for (int y = 0; y < ny; y++)
    for (int x = 0; x < nx; x++) {
      size_t W1 = (size_t)W + 1;
      double s = sat[(size_t)(y + S) * W1 + x + S] - sat[(size_t)y * W1 + x + S] -
                 sat[(size_t)(y + S) * W1 + x] + sat[(size_t)y * W1 + x];
      cdf[(size_t)y * nx + x] = s > 0 ? s : 0;
      total += cdf[(size_t)y * nx + x];
    }
  double floor_w = 0.1 * total / ((double)nx * ny);
  if (total <= 0) floor_w = 1.0;
  double acc = 0;
  for (size_t i = 0; i < (size_t)nx * ny; i++) {
    acc += cdf[i] + floor_w;
    cdf[i] = acc;
  }
  free(sat);
  return cdf;
}

kpcn_status kpcn_patches_select(kpcn_patch_origin **out, int *nout, kpcn_patch_stats *stats,
                                const kpcn_aov_set *noisy, const kpcn_aov_set *ref,
                                const kpcn_patch_settings *s) {
  if (!out || !nout || !noisy || !s)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_patches_select: NULL argument");
  *out = NULL;
  *nout = 0;
  kpcn_patch_stats st0 = {0, 0, 0};
  if (stats) *stats = st0;
  int W = noisy->width, H = noisy->height, S = s->size;
  if (S <= 0 || S > W || S > H)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "patch size %d does not fit in the %dx%d image", S,
                     W, H);
  if (s->count < 0 || s->stride < 0)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "patch count %d / stride %d must be >= 0", s->count,
                     s->stride);
  if (!(s->cull_tol >= 0) || !(s->cull_abs >= 0) || !(s->cull >= 0))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "patch culling: cull %g, tol %g, abs %g must be >= 0", s->cull, s->cull_tol,
                     s->cull_abs);
  if (ref && (ref->width != W || ref->height != H))
    return kpcn_fail(KPCN_ERR_SIZE_MISMATCH, "reference is %dx%d but the noisy image is %dx%d",
                     ref->width, ref->height, W, H);
  const kpcn_aov_set *cs = ref ? ref : noisy;
  KPCN_TRY(kpcn_aov_require(cs, KPCN_BUF_COLOR, 0,
                            ref ? "reference (patch culling)" : "noisy (patch culling)"));
  if (s->importance)
    KPCN_TRY(kpcn_aov_require(noisy, KPCN_BUF_COLOR, 1, "noisy (importance sampling)"));
  size_t np = kpcn_aov_plane_size(cs);
  const float *cr = cs->buf[KPCN_BUF_COLOR], *cg = cr + np, *cb = cr + 2 * np;
  int nx = W - S + 1, ny = H - S + 1;

  int grid = s->count == 0;
  int stride = s->stride > 0 ? s->stride : S;
  int64_t maxc;
  if (grid)
    maxc = (int64_t)((W - S) / stride + 1) * ((H - S) / stride + 1);
  else
    maxc = s->max_candidates > 0 ? s->max_candidates : (int64_t)8 * s->count;
  int cap = grid ? (int)maxc : s->count;
  kpcn_patch_origin *o = kpcn_alloc(sizeof *o * (size_t)(cap > 0 ? cap : 1), "patch origins");
  if (!o) return KPCN_ERR_OUT_OF_MEMORY;
  double *cdf = NULL;
  if (s->importance && !grid) {
    cdf = importance_cdf(noisy, S, nx, ny);
    if (!cdf) {
      free(o);
      return KPCN_ERR_OUT_OF_MEMORY;
    }
  }
  uint64_t rng = s->seed * 0x2545f4914f6cdd1dull + 0x1234567ull;
  kpcn_patch_stats st = st0;
  int kept = 0;
  for (int64_t cidx = 0; cidx < maxc && kept < cap; cidx++) {
    int x, y;
    float weight = 1.0f;
    if (grid) {
      int per_row = (W - S) / stride + 1;
      x = (int)(cidx % per_row) * stride;
      y = (int)(cidx / per_row) * stride;
    } else if (cdf) {
      double total = cdf[(size_t)nx * ny - 1], u = unif(&rng) * total;
      size_t lo = 0, hi = (size_t)nx * ny - 1;
      while (lo < hi) {
        size_t mid = (lo + hi) / 2;
        if (cdf[mid] > u)
          hi = mid;
        else
          lo = mid + 1;
      }
      x = (int)(lo % (size_t)nx);
      y = (int)(lo / (size_t)nx);
      double p = cdf[lo] - (lo ? cdf[lo - 1] : 0);
      weight = (float)(p / total * ((double)nx * ny));
    } else {
      x = (int)(sm64(&rng) % (uint64_t)nx);
      y = (int)(sm64(&rng) % (uint64_t)ny);
    }
    st.candidates++;
    double frac = s->cull <= 1.0
                      ? kpcn_patch_flat_fraction(cr, cg, cb, W, x, y, S, s->cull_tol, s->cull_abs)
                      : 0.0;
    if (s->cull <= 1.0 && frac >= s->cull) {
      st.culled++;
      continue;
    }
    o[kept].x = x;
    o[kept].y = y;
    o[kept].flat_frac = (float)frac;
    o[kept].weight = weight;
    kept++;
  }
  st.kept = kept;
  free(cdf);
  *out = o;
  *nout = kept;
  if (stats) *stats = st;
  return KPCN_OK;
}
