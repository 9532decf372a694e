/* kpcn/render.h — the Embree path tracer: scene -> AOV set (DESIGN.md §4).
 *
 *   kpcn_scene *s; kpcn_scene_load("scene.json", &s);
 *   kpcn_render_settings rs = kpcn_render_settings_defaults(); rs.spp = 16; rs.seed = 1;
 *   kpcn_aov_set *aov; kpcn_render(s, &rs, &aov);  ... kpcn_exr_write_aov(path, aov, NULL);
 *   kpcn_aov_destroy(aov); kpcn_scene_destroy(s);
 *
 * Output: buffers color, diffuse, specular, albedo, normal (camera space), depth, visibility
 * with their variance-of-the-mean planes (Welford per pixel, averaged over the channels);
 * color_only renders only color (+ color.var). Semantics in docs/renderer.md.
 *
 * Determinism: every pixel draws its own sample sequence (Owen-scrambled Sobol keyed on seed
 * and pixel) and accumulates its samples in order, so the result is bit-identical for a seed
 * whatever nthreads is.
 *
 * Ownership: *out is allocated by kpcn_render; free with kpcn_aov_destroy. Thread-safe: a
 * scene may be rendered concurrently by several calls.
 */
#ifndef KPCN_RENDER_H
#define KPCN_RENDER_H

#include "kpcn/common.h"
#include "kpcn/image.h"
#include "kpcn/scene.h"

#ifdef __cplusplus
extern "C" {
#endif

/* How direct light is estimated. SCENE follows integrator.enable_light_sampling (MIS when on,
 * BSDF sampling only when off); the others exist for tests and comparisons. */
typedef enum kpcn_light_strategy {
  KPCN_LIGHTS_SCENE = 0,
  KPCN_LIGHTS_MIS,       /* next-event estimation + BSDF sampling, power heuristic */
  KPCN_LIGHTS_BSDF_ONLY, /* emitters found only by BSDF sampling */
  KPCN_LIGHTS_NEE_ONLY   /* non-delta bounces see emitters only through shadow rays */
} kpcn_light_strategy;

typedef struct kpcn_render_settings {
  int spp;            /* samples per pixel; 0 = the scene's renderer.spp */
  int64_t seed;       /* sampler seed, 0 .. 2^63-1 */
  int nthreads;       /* 0 = all cores */
  int width, height;  /* resolution override (0 = scene's); Tungsten keeps the horizontal fov */
  int crop_x, crop_y; /* crop window in the (possibly overridden) resolution; */
  int crop_w, crop_h; /*   crop_w/crop_h 0 = whole image. Output is crop-sized. */
  int color_only;     /* 1: only color + color.var (fast references) */
  int max_bounces;    /* -1 = scene's integrator.max_bounces */
  /* > spp: the albedo buffer (and its variance) comes from this many camera samples of a
   * features-only pass (camera ray, delta bounces to the feature surface, its albedo: no
   * shading, no shadow rays), the first spp of them the colour's own. The albedo's sub-pixel
   * coverage noise at edges is what the denoiser's remodulation multiplies its result by
   * (docs/renderer.md). 0 (or = spp) = the colour's samples; 1 .. spp-1 is an error. */
  int albedo_spp;
  /* k >= 2: where a textured surface is seen directly, each sample's albedo is the mean of
   * k x k texture lookups over its pixel's footprint (its film point shifted by (i/k, j/k),
   * each point where its camera ray meets the hit's tangent plane; no rays traced), so the
   * albedo of a pixel inside a textured surface has the texture coverage of k*k times the
   * samples. Composes with albedo_spp. 0 or 1 = off; at most 16 (docs/renderer.md). */
  int albedo_footprint;
  kpcn_light_strategy lights;
  /* called from the calling thread after its rows and once with 1.0 when all rows are done;
   * a non-zero return cancels (that last answer too) */
  kpcn_progress_fn progress;
  void *progress_user;
  /* Checkpoints (DESIGN.md §9). When not NULL: if this file holds finished rows of the same
   * render (scene_key, every setting above that changes pixels, size, crop, kpcn version) the
   * render starts from them; a file of another render, or a damaged one, is an error naming
   * the difference, and nothing is rendered; so is a path that cannot be written. While
   * rendering, the finished rows are written to it (atomically) every checkpoint_every_s
   * seconds (0: only when cancelled), when the progress callback cancels, and once all rows
   * are done (so that a failure to write the result loses nothing). A periodic save
   * that fails (a full disk) does not stop the render: it is counted in
   * kpcn_render_stats.checkpoint_errors and tried again at the next interval; a save on cancel
   * that fails is the render's error. A resumed render is bit-identical to an uninterrupted one,
   * at any thread count. The file is left in place at the end: remove it once the result is
   * safe. */
  const char *checkpoint;
  double checkpoint_every_s; /* default 60 */
  /* What the checkpoint records as the scene's identity; the library cannot see the files a
   * scene was loaded from (kpcn-render: a hash of the scene file's bytes). */
  uint64_t scene_key;
} kpcn_render_settings;

kpcn_render_settings kpcn_render_settings_defaults(void);

/* Figures of the last render (optional). */
typedef struct kpcn_render_stats {
  double seconds;   /* wall time of the sampling loop */
  uint64_t samples; /* camera samples traced (by this call: not the rows a checkpoint held) */
  uint64_t rays;    /* Embree queries (intersect + occluded), by this call */
  /* samples with a NaN/Inf value (radiance beyond float range: an albedo above 1 multiplies
   * along a path), counted as black; in the whole image, resumed rows included */
  uint64_t nonfinite_samples;
  int rows_resumed;      /* rows taken from the checkpoint */
  int checkpoint_errors; /* periodic saves that failed (the render went on; see render.h) */
} kpcn_render_stats;

kpcn_status kpcn_render(const kpcn_scene *scene, const kpcn_render_settings *settings,
                        kpcn_aov_set **out);
/* Same, also filling *stats (may be NULL): zeroed first on every return; on a cancel
 * (KPCN_ERR_CANCELLED) seconds, rows_resumed and checkpoint_errors are filled too. */
kpcn_status kpcn_render_ex(const kpcn_scene *scene, const kpcn_render_settings *settings,
                           kpcn_aov_set **out, kpcn_render_stats *stats);

#ifdef __cplusplus
}
#endif
#endif
