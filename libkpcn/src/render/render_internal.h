/* Internals of the path tracer shared by render.c (film, threads), integrator.c (paths) and
 * geometry.c (hit shading, light sampling). Not installed; no Embree types leak out of the
 * .c files that trace rays. */
#ifndef KPCN_RENDER_INTERNAL_H
#define KPCN_RENDER_INTERNAL_H

#include "kpcn/render.h"
#include "render/sampler.h"
#include "scene/scene_internal.h"

#include <emmintrin.h> /* kpcn_offset_ray: SSE2, part of every x86-64 */

/* Everything known about a surface hit. */
typedef struct kpcn_hit {
  const kpcn_prim *prim;
  kpcn_vec3 p;  /* position */
  kpcn_vec3 ng; /* unit geometric normal, the primitive's outward/front orientation */
  kpcn_vec3 ns; /* unit shading normal, same hemisphere as ng */
  float u, v;   /* texture coordinates */
  float t;      /* ray distance */
} kpcn_hit;

/* A point sampled on an area light. */
typedef struct kpcn_light_point {
  kpcn_vec3 p, n; /* position and front normal */
  float pdf_area; /* area density (1/area for uniform sampling) */
  float u, v;     /* texture coordinates there (as kpcn_hit_fill would report) */
} kpcn_light_point;

/* Filter importance sampling tables (Gaussian uses an inverted tabulated CDF). */
#define KPCN_FILTER_TABLE 2048
typedef struct kpcn_filter_table {
  kpcn_filter_type type;
  float inv_cdf[KPCN_FILTER_TABLE + 1]; /* gaussian: offset for u = i / N */
} kpcn_filter_table;

/* Per-sample outputs (DESIGN.md §4). */
typedef struct kpcn_sample_out {
  kpcn_vec3 diffuse, specular, albedo, normal;
  float depth, visibility;
  uint32_t rays;       /* Embree queries issued */
  uint32_t vis_traced; /* 1 if a shadow ray left the feature surface (visibility is defined) */
} kpcn_sample_out;

typedef struct kpcn_render_ctx {
  const kpcn_scene *scene;
  int width, height; /* full image (after override) */
  float ratio;       /* height / width */
  int max_bounces, min_bounces;
  int nee, bsdf_emission; /* what direct light estimators are active */
  int mis;                /* power-heuristic weights (both estimators on) */
  int color_only;
  int features_only; /* 1: a path ends once it has recorded its features (albedo pass) */
  /* > 1: a textured albedo seen directly is the mean of k x k lookups over the pixel's
   * footprint (kpcn_render_settings.albedo_footprint) */
  int albedo_footprint;
  uint64_t seed;
  kpcn_filter_table filter;
  /* kpcn_trace_pixel or its GFNI build, whichever this CPU runs (kpcn_render_ctx_init) */
  void (*trace)(const struct kpcn_render_ctx *ctx, int px, int py, kpcn_sampler *smp, int n,
                kpcn_sample_out *out);
} kpcn_render_ctx;

/* render.c: fails with KPCN_ERR_OUT_OF_MEMORY, naming both sizes, when `planes` float planes
 * of width x height exceed avail_bytes (0: the memory this machine has available now,
 * kpcn_available_memory). */
kpcn_status kpcn_render_check_memory(int width, int height, int planes, uint64_t avail_bytes);

/* render_ckpt.c: which rows of a render are finished, their statistics and, when path is not
 * NULL, its checkpoint file (kpcn_render_settings.checkpoint). `what` is the JSON object that
 * identifies the render (a resume refuses a file whose object differs); set receives the
 * saved rows. Without a path, load and save do nothing. */
typedef struct kpcn_render_ckpt kpcn_render_ckpt;
struct cJSON;
kpcn_status kpcn_render_ckpt_create(kpcn_render_ckpt **out, const char *path,
                                    const struct cJSON *what, kpcn_aov_set *set);
void kpcn_render_ckpt_destroy(kpcn_render_ckpt *c);
/* Loads the file if it exists (*rows: rows it held; 0 and KPCN_OK when there is none); a file
 * of another render, or a damaged one, is an error naming it, with nothing loaded. */
kpcn_status kpcn_render_ckpt_load(kpcn_render_ckpt *c, int *rows);
/* Marks row finished (its pixels are in the set), from any thread. */
void kpcn_render_ckpt_row_done(kpcn_render_ckpt *c, int row, uint64_t rays, uint64_t nonfinite);
int kpcn_render_ckpt_is_done(const kpcn_render_ckpt *c, int row);
void kpcn_render_ckpt_totals(const kpcn_render_ckpt *c, uint64_t *rays, uint64_t *nonfinite);
/* Fails (KPCN_ERR_IO, naming it) if a checkpoint cannot be written where path says. */
kpcn_status kpcn_render_ckpt_probe(const kpcn_render_ckpt *c);
/* Writes the finished rows, atomically; safe while other threads render other rows. */
kpcn_status kpcn_render_ckpt_save(const kpcn_render_ckpt *c);

/* geometry.c */
void kpcn_hit_fill(const kpcn_scene *s, const kpcn_prim *p, kpcn_vec3 o, kpcn_vec3 d, float t,
                   unsigned prim_id, float bu, float bv, kpcn_hit *h);
/* Texture coordinates at x, a point of hit h's tangent plane (h on primitive p; prim_id its
 * triangle for meshes), from p's own parametrisation carried past the hit: the plane of the
 * quad, cube face, disk or triangle (not clamped to the surface's edges, as kpcn_hit_fill's
 * quads and cubes are), the direction from a sphere's centre. For texture lookups over a pixel's
 * footprint (the albedo footprint, integrator.c). */
void kpcn_hit_uv_at(const kpcn_prim *p, unsigned prim_id, const kpcn_hit *h, kpcn_vec3 x, float *u,
                    float *v);
/* Emitted radiance leaving the hit towards -d (one-sided: front face only). */
kpcn_vec3 kpcn_prim_emission(const kpcn_prim *p, const kpcn_hit *h, kpcn_vec3 d);
/* Uniform-area sample of a point on an emissive primitive. */
void kpcn_prim_sample_point(const kpcn_prim *p, float u1, float u2, kpcn_light_point *lp);
/* Float-robust ray origin: p pushed off the surface along n (Waechter & Binder 2019): by 256 n
 * units in the last place of each coordinate, or by n / 65536 near the origin where ulps are
 * tiny. All three coordinates at once in SSE2 lanes and inline: the scalar version, a call
 * that moved every coordinate between the float and integer units, was ~4 % of the render
 * time (three calls per bounce). Exact integer and power-of-two arithmetic, so the lanes give
 * the scalar formula's bits. */
static inline kpcn_vec3 kpcn_offset_ray(kpcn_vec3 p, kpcn_vec3 n) {
  const __m128 vp = _mm_setr_ps(p.x, p.y, p.z, 0.0f), vn = _mm_setr_ps(n.x, n.y, n.z, 0.0f);
  const __m128 sign = _mm_set1_ps(-0.0f);
  __m128i off = _mm_cvttps_epi32(_mm_mul_ps(vn, _mm_set1_ps(256.0f)));
  __m128i neg = _mm_castps_si128(_mm_cmplt_ps(vp, _mm_setzero_ps()));
  off = _mm_sub_epi32(_mm_xor_si128(off, neg), neg); /* p < 0 ? -off : off */
  __m128 far_p = _mm_castsi128_ps(_mm_add_epi32(_mm_castps_si128(vp), off));
  __m128 near_p = _mm_add_ps(vp, _mm_mul_ps(vn, _mm_set1_ps(1.0f / 65536.0f)));
  __m128 is_near = _mm_cmplt_ps(_mm_andnot_ps(sign, vp), _mm_set1_ps(1.0f / 32.0f));
  __m128 r = _mm_or_ps(_mm_and_ps(is_near, near_p), _mm_andnot_ps(is_near, far_p));
  float o[4];
  _mm_storeu_ps(o, r);
  return kv3(o[0], o[1], o[2]);
}

/* render.c: the context of a render with these settings (resolution checked, filter table and
 * sampler tables ready). */
kpcn_status kpcn_render_ctx_init(kpcn_render_ctx *ctx, const kpcn_scene *scene,
                                 const kpcn_render_settings *settings);

/* integrator.c */
void kpcn_filter_table_init(kpcn_filter_table *t, kpcn_filter_type type);
/* Traces samples smp[0..n-1] (n <= 16, started by the caller) of pixel (px, py). */
void kpcn_trace_pixel(const kpcn_render_ctx *ctx, int px, int py, kpcn_sampler *smp, int n,
                      kpcn_sample_out *out);
/* The same function compiled with GFNI enabled (integrator_gfni.c): identical results, for
 * CPUs that have it (ctx->trace picks it). Built where the compiler supports -mgfni. */
#ifdef KPCN_HAVE_GFNI_VARIANT
void kpcn_trace_pixel_gfni(const kpcn_render_ctx *ctx, int px, int py, kpcn_sampler *smp, int n,
                           kpcn_sample_out *out);
#endif

#endif
