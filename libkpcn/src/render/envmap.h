/* Environment light for Tungsten's "infinite_sphere" primitive (and constant backgrounds).
 *
 * MAPPING (Tungsten InfiniteSphere): a world direction d is first rotated into the sphere's
 * local frame (inverse of the primitive's transform rotation), then
 *   u = atan2(d.z, d.x) / (2 pi) + 0.5,  v = acos(-d.y) / pi     (v = 1 at the zenith +y)
 * and the emission texture is looked up at (u, v) (bitmaps: v up, so the top row of the
 * image is the zenith). Sampling inverts this: theta = v pi, phi = (u - 0.5) 2 pi,
 * local d = (cos phi sin theta, -cos theta, sin phi sin theta); the solid-angle pdf is
 * p(u,v) / (2 pi^2 sin theta).
 *
 * Importance sampling uses a 2D piecewise-constant distribution over the texels weighted by
 * max(R,G,B) * sin(theta), each texel's weight dilated to its 3x3 neighbourhood maximum because
 * lookups are bilinear (as Tungsten). Constant/checker emission samples the sphere uniformly.
 */
#ifndef KPCN_RENDER_ENVMAP_H
#define KPCN_RENDER_ENVMAP_H

#include "kpcn/common.h"
#include "render/sampling.h"
#include "render/texture.h"
#include "render/vec3.h"

typedef struct kpcn_envmap kpcn_envmap;

/* emission: constant or bitmap texture (not owned; must outlive the envmap).
 * rot: 3x3 row-major rotation world-from-local (the primitive transform's rotation part; a
 *      scale in it is removed by normalising the columns). NULL = identity.
 * importance: 1 to build the sampling distribution (Tungsten "sample": true). When 0,
 *      sample() draws uniformly over the sphere. */
kpcn_status kpcn_envmap_create(const kpcn_texture *emission, const float rot[9], int importance,
                               kpcn_envmap **out);
void kpcn_envmap_destroy(kpcn_envmap *e);

/* Radiance arriving from world direction `dir` (unit, pointing away from the scene). */
kpcn_vec3 kpcn_envmap_eval(const kpcn_envmap *e, kpcn_vec3 dir);
/* Solid-angle pdf that sample() produces `dir`. */
float kpcn_envmap_pdf(const kpcn_envmap *e, kpcn_vec3 dir);
/* Samples a world direction; returns radiance and solid-angle pdf; 0 when pdf = 0. */
int kpcn_envmap_sample(const kpcn_envmap *e, float u1, float u2, kpcn_vec3 *dir,
                       kpcn_vec3 *radiance, float *pdf);
/* Direction <-> (u, v) in the map (exposed for tests and the kpcn-dataset augmenter). */
void kpcn_envmap_dir_to_uv(const kpcn_envmap *e, kpcn_vec3 dir, float *u, float *v);
kpcn_vec3 kpcn_envmap_uv_to_dir(const kpcn_envmap *e, float u, float v);

#endif
