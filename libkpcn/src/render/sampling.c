/* Sampling warps and piecewise-constant distributions (pbrt-v3 §13, §14.2). */
#include "render/sampling.h"

#include "core/internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

kpcn_vec3 kpcn_warp_uniform_hemisphere(float u1, float u2) {
  float z = u1;
  float r = sqrtf(fmaxf(0.0f, 1.0f - z * z));
  float phi = 2.0f * KPCN_PI * u2;
  return kv3(r * cosf(phi), r * sinf(phi), z);
}

kpcn_vec3 kpcn_warp_uniform_sphere(float u1, float u2) {
  float z = 1.0f - 2.0f * u1;
  float r = sqrtf(fmaxf(0.0f, 1.0f - z * z));
  float phi = 2.0f * KPCN_PI * u2;
  return kv3(r * cosf(phi), r * sinf(phi), z);
}

kpcn_vec3 kpcn_warp_uniform_cone(float u1, float u2, float cos_max) {
  float z = (1.0f - u1) + u1 * cos_max;
  float r = sqrtf(fmaxf(0.0f, 1.0f - z * z));
  float phi = 2.0f * KPCN_PI * u2;
  return kv3(r * cosf(phi), r * sinf(phi), z);
}

void kpcn_warp_uniform_triangle(float u1, float u2, float *b0, float *b1) {
  float s = sqrtf(u1);
  *b0 = 1.0f - s;
  *b1 = u2 * s;
}

/* ---- 1D ---- */

/* Largest index i in [lo, hi - 1] with cdf[i] <= u, given cdf[lo] <= u (or lo = 0). */
static int bisect(const float *cdf, int lo, int hi, float u) {
  while (hi - lo > 1) {
    int mid = (lo + hi) >> 1;
    if (cdf[mid] <= u)
      lo = mid;
    else
      hi = mid;
  }
  return lo;
}

/* See kpcn_distrib1d_sample. */
static int find_interval(const kpcn_distrib1d *d, float u) {
  const int n = d->n;
  const float x = u * (float)n;
  const int k = x >= 0.0f ? (x < (float)n ? (int)x : n - 1) : 0;
  const int i = bisect(d->cdf, d->guide[k], d->guide[k + 1] + 1 < n ? d->guide[k + 1] + 1 : n, u);
  if (d->cdf[i] <= u && (i == n - 1 || d->cdf[i + 1] > u)) return i;
  return bisect(d->cdf, 0, n, u);
}

kpcn_status kpcn_distrib1d_init(kpcn_distrib1d *d, const float *func, int n) {
  memset(d, 0, sizeof(*d));
  if (n < 1) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "distribution: %d cells (need >= 1)", n);
  d->n = n;
  d->func = kpcn_alloc(sizeof(float) * (size_t)n, "distribution function");
  d->cdf = kpcn_alloc(sizeof(float) * ((size_t)n + 1), "distribution cdf");
  d->guide = kpcn_alloc(sizeof(int) * ((size_t)n + 1), "distribution guide table");
  if (!d->func || !d->cdf || !d->guide) {
    kpcn_distrib1d_free(d);
    return KPCN_ERR_OUT_OF_MEMORY;
  }
  /* Accumulate in double so a 4k-wide row does not lose its small cells to rounding. */
  double acc = 0.0;
  double *tmp = kpcn_alloc(sizeof(double) * ((size_t)n + 1), "distribution cdf");
  if (!tmp) {
    kpcn_distrib1d_free(d);
    return KPCN_ERR_OUT_OF_MEMORY;
  }
  tmp[0] = 0.0;
  for (int i = 0; i < n; ++i) {
    float f = func[i];
    if (!(f >= 0.0f) || !isfinite(f)) f = 0.0f; /* NaN/negative/inf cells are never sampled */
    d->func[i] = f;
    acc += f;
    tmp[i + 1] = acc;
  }
  d->integral = (float)(acc / n);
  if (acc <= 0.0) {
    for (int i = 0; i <= n; ++i)
      d->cdf[i] = (float)i / (float)n;
    for (int i = 0; i < n; ++i)
      d->func[i] = 1.0f;
    d->integral = 1.0f;
  } else {
    for (int i = 0; i <= n; ++i)
      d->cdf[i] = (float)(tmp[i] / acc);
  }
  d->cdf[n] = 1.0f;
  free(tmp);
  for (int k = 0; k <= n; ++k)
    d->guide[k] = bisect(d->cdf, 0, n, (float)((double)k / n));
  return KPCN_OK;
}

void kpcn_distrib1d_free(kpcn_distrib1d *d) {
  if (!d) return;
  free(d->func);
  free(d->cdf);
  free(d->guide);
  d->func = d->cdf = NULL;
  d->guide = NULL;
  d->n = 0;
}

/* The cell u falls in: the largest i in [0, n-1] with cdf[i] <= u (0 for NaN; the cdf is
 * non-decreasing, so this is the one i with cdf[i] <= u < cdf[i + 1], or n - 1). A full
 * bisection is ~log2(n) dependent loads, each a cache miss in an environment map's rows
 * (1024 x 512: 4 MiB of cdf), which made it a quarter of a render's time. The guide table
 * narrows it to the cells between guide[k] and guide[k + 1] for k = floor(u n), usually one
 * or two; the answer is checked, and where rounding put u outside that range (or u is NaN)
 * the full bisection decides. The same cell either way, so the same image. */
float kpcn_distrib1d_sample(const kpcn_distrib1d *d, float u, float *pdf, int *index) {
  int i = find_interval(d, u);
  float w = d->cdf[i + 1] - d->cdf[i];
  float du = w > 0.0f ? (u - d->cdf[i]) / w : 0.5f;
  if (du >= 1.0f) du = 0x1.fffffep-1f;
  if (du < 0.0f) du = 0.0f;
  if (pdf) *pdf = d->func[i] / d->integral;
  if (index) *index = i;
  float x = ((float)i + du) / (float)d->n;
  return x < 1.0f ? x : 0x1.fffffep-1f;
}

int kpcn_distrib1d_sample_discrete(const kpcn_distrib1d *d, float u, float *pmf) {
  int i = find_interval(d, u);
  if (pmf) *pmf = d->func[i] / (d->integral * (float)d->n);
  return i;
}

float kpcn_distrib1d_pdf(const kpcn_distrib1d *d, float x) {
  int i = (int)(x * (float)d->n);
  if (i < 0 || i >= d->n) return 0.0f;
  return d->func[i] / d->integral;
}

/* ---- 2D ---- */

kpcn_status kpcn_distrib2d_init(kpcn_distrib2d *d, const float *func, int nu, int nv) {
  memset(d, 0, sizeof(*d));
  if (nu < 1 || nv < 1)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "2D distribution: %dx%d cells", nu, nv);
  d->nu = nu;
  d->nv = nv;
  d->cond = kpcn_calloc((size_t)nv, sizeof(kpcn_distrib1d), "2D distribution rows");
  float *marg = kpcn_alloc(sizeof(float) * (size_t)nv, "2D distribution marginal");
  if (!d->cond || !marg) {
    free(marg);
    kpcn_distrib2d_free(d);
    return KPCN_ERR_OUT_OF_MEMORY;
  }
  kpcn_status s = KPCN_OK;
  for (int v = 0; v < nv && s == KPCN_OK; ++v) {
    s = kpcn_distrib1d_init(&d->cond[v], func + (size_t)v * nu, nu);
    if (s == KPCN_OK) {
      /* a row that was all zero got a uniform stand-in; its marginal weight stays 0 */
      double sum = 0.0;
      for (int u = 0; u < nu; ++u) {
        float f = func[(size_t)v * nu + u];
        if (f >= 0.0f && isfinite(f)) sum += f;
      }
      marg[v] = (float)(sum / nu);
    }
  }
  if (s == KPCN_OK) s = kpcn_distrib1d_init(&d->marg, marg, nv);
  free(marg);
  if (s != KPCN_OK) kpcn_distrib2d_free(d);
  return s;
}

void kpcn_distrib2d_free(kpcn_distrib2d *d) {
  if (!d) return;
  if (d->cond)
    for (int v = 0; v < d->nv; ++v)
      kpcn_distrib1d_free(&d->cond[v]);
  free(d->cond);
  d->cond = NULL;
  kpcn_distrib1d_free(&d->marg);
}

void kpcn_distrib2d_sample(const kpcn_distrib2d *d, float u1, float u2, float *u, float *v,
                           float *pdf) {
  float pv, pu;
  int iv;
  *v = kpcn_distrib1d_sample(&d->marg, u2, &pv, &iv);
  *u = kpcn_distrib1d_sample(&d->cond[iv], u1, &pu, NULL);
  if (pdf) *pdf = pv * pu;
}

float kpcn_distrib2d_pdf(const kpcn_distrib2d *d, float u, float v) {
  int iu = (int)(u * (float)d->nu), iv = (int)(v * (float)d->nv);
  if (iu < 0 || iu >= d->nu || iv < 0 || iv >= d->nv) return 0.0f;
  /* p(u,v) = f(u,v) / integral over the whole domain; marg.integral is that integral */
  const kpcn_distrib1d *row = &d->cond[iv];
  if (d->marg.integral <= 0.0f) return 0.0f;
  float f = row->func[iu];
  /* an all-zero row was replaced by a uniform one but has zero marginal weight */
  if (d->marg.func[iv] == 0.0f) return 0.0f;
  return f / d->marg.integral;
}
