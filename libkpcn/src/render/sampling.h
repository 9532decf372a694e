/* Sampling warps and piecewise-constant distributions (pbrt conventions).
 * All warps map uniform [0,1)^2 to the named domain; every *_pdf is with respect to the
 * natural measure of that domain (solid angle for directions, area for disk/triangle). */
#ifndef KPCN_RENDER_SAMPLING_H
#define KPCN_RENDER_SAMPLING_H

#include "kpcn/common.h"
#include "render/vec3.h"

#define KPCN_PI 3.14159265358979323846f
#define KPCN_INV_PI 0.31830988618379067154f
#define KPCN_INV_2PI 0.15915494309189533577f
#define KPCN_INV_4PI 0.07957747154594766788f

/* Shirley-Chiu concentric map to the unit disk: returns (x, y). pdf = 1/pi. Inline, with the
 * cosine warp below: they run at every diffuse bounce and on the lens. */
static inline void kpcn_warp_concentric_disk(float u1, float u2, float *x, float *y) {
  float ox = 2.0f * u1 - 1.0f, oy = 2.0f * u2 - 1.0f;
  if (ox == 0.0f && oy == 0.0f) {
    *x = *y = 0.0f;
    return;
  }
  float r, theta;
  if (fabsf(ox) > fabsf(oy)) {
    r = ox;
    theta = (KPCN_PI * 0.25f) * (oy / ox);
  } else {
    r = oy;
    theta = KPCN_PI * 0.5f - (KPCN_PI * 0.25f) * (ox / oy);
  }
  *x = r * cosf(theta);
  *y = r * sinf(theta);
}

/* Cosine-weighted hemisphere around +z (the concentric disk, lifted): pdf = cos(theta)/pi. */
static inline kpcn_vec3 kpcn_warp_cosine_hemisphere(float u1, float u2) {
  float x, y;
  kpcn_warp_concentric_disk(u1, u2, &x, &y);
  float z = sqrtf(kpcn_maxf(1.0f - x * x - y * y, 0.0f));
  return kv3(x, y, z);
}

static inline float kpcn_warp_cosine_hemisphere_pdf(kpcn_vec3 w) {
  return w.z > 0.0f ? w.z * KPCN_INV_PI : 0.0f;
}
/* Uniform hemisphere around +z: pdf = 1/(2pi). */
kpcn_vec3 kpcn_warp_uniform_hemisphere(float u1, float u2);
/* Uniform sphere: pdf = 1/(4pi). */
kpcn_vec3 kpcn_warp_uniform_sphere(float u1, float u2);
/* Uniform cone around +z with cos(theta_max) = cos_max: pdf = 1/(2pi(1-cos_max)). */
kpcn_vec3 kpcn_warp_uniform_cone(float u1, float u2, float cos_max);
static inline float kpcn_warp_uniform_cone_pdf(float cos_max) {
  return 1.0f / (2.0f * KPCN_PI * (1.0f - cos_max));
}
/* Uniform barycentrics (b0, b1) on a triangle (b2 = 1-b0-b1). pdf = 1/area. */
void kpcn_warp_uniform_triangle(float u1, float u2, float *b0, float *b1);

/* Piecewise-constant 1D distribution over [0,1) with n cells. */
typedef struct kpcn_distrib1d {
  int n;
  float *func;    /* n values (>= 0) */
  float *cdf;     /* n+1 values, cdf[0]=0, cdf[n]=1 */
  int *guide;     /* n+1 values: guide[k] = the cell that u = k/n falls in (sampling.c) */
  float integral; /* sum(func)/n */
} kpcn_distrib1d;

/* Builds from n >= 1 non-negative values (an all-zero function becomes uniform). Allocates. */
kpcn_status kpcn_distrib1d_init(kpcn_distrib1d *d, const float *func, int n);
void kpcn_distrib1d_free(kpcn_distrib1d *d);
/* Continuous sample in [0,1); *pdf = density (func/integral); *index = cell. */
float kpcn_distrib1d_sample(const kpcn_distrib1d *d, float u, float *pdf, int *index);
/* Discrete sample: cell index, *pmf = probability of that cell. */
int kpcn_distrib1d_sample_discrete(const kpcn_distrib1d *d, float u, float *pmf);
float kpcn_distrib1d_pdf(const kpcn_distrib1d *d, float x); /* density at x in [0,1) */

/* Piecewise-constant 2D distribution over [0,1)^2: nu columns x nv rows (row-major func[v*nu+u]).
 */
typedef struct kpcn_distrib2d {
  int nu, nv;
  kpcn_distrib1d *cond; /* nv conditionals p(u|v) */
  kpcn_distrib1d marg;  /* marginal p(v) */
} kpcn_distrib2d;

kpcn_status kpcn_distrib2d_init(kpcn_distrib2d *d, const float *func, int nu, int nv);
void kpcn_distrib2d_free(kpcn_distrib2d *d);
/* Samples (u, v) in [0,1)^2; *pdf is the density w.r.t. area on [0,1)^2. */
void kpcn_distrib2d_sample(const kpcn_distrib2d *d, float u1, float u2, float *u, float *v,
                           float *pdf);
float kpcn_distrib2d_pdf(const kpcn_distrib2d *d, float u, float v);

#endif
