/* Helpers shared by the render tests: scene files with JSON edits, image error measures. */
#ifndef KPCN_RENDER_TESTUTIL_H
#define KPCN_RENDER_TESTUTIL_H
#include "kpcn/exr.h"
#include "kpcn/render.h"
#include "kpcn/scene.h"
#include <cjson/cJSON.h>

/* Reads a scene file into a cJSON tree (NULL on failure, message printed). */
cJSON *rt_read_json(const char *path);
/* Loads a scene from a (possibly edited) tree; base_dir resolves relative paths. */
kpcn_status rt_load(const cJSON *doc, const char *base_dir, kpcn_scene **out);
/* Sets doc.camera.<key> (number or string). */
void rt_set_camera_number(cJSON *doc, const char *key, double v);
void rt_set_camera_string(cJSON *doc, const char *key, const char *v);
/* Renders with spp/seed/threads/resolution; NULL on failure (message printed). */
kpcn_aov_set *rt_render(const kpcn_scene *s, int spp, long long seed, int threads, int w, int h,
                        kpcn_light_strategy lights, int max_bounces);
/* Writes a to the EXR at path and reads it back (header attributes included); NULL on failure
 * (message printed). */
kpcn_aov_set *rt_exr_roundtrip(const kpcn_aov_set *a, const char *path);
/* mean over pixels and channels of (a-b)^2/(b^2+0.01) for a 3-channel buffer */
double rt_relmse(const float *a, const float *b, size_t plane);
/* mean over pixels and channels of var/(ref^2+0.01) where var is the per-pixel
 * channel-averaged variance of the mean */
double rt_predicted_relmse(const float *var, const float *ref, size_t plane);
/* mean of a plane */
double rt_mean(const float *p, size_t n);
#endif
