/* kpcn/scene.h — Tungsten-format scene files (scene.json) for the Embree path tracer.
 *
 * The supported subset of Tungsten's format is documented in docs/renderer.md. Anything
 * outside it (an unknown primitive/bsdf/camera type, an unknown field) is an error whose
 * message names the JSON path (e.g. "primitives[3].transform.rotation: expected 3 numbers"),
 * never silently ignored. Fields that only affect Tungsten's own UI/output (tonemap,
 * output_file, spp_step, ...) are accepted and ignored; docs/renderer.md lists them.
 *
 * Ownership: kpcn_scene_load* allocate *out; free with kpcn_scene_destroy. A loaded scene is
 * immutable and may be rendered by several threads / calls at once.
 */
#ifndef KPCN_SCENE_H
#define KPCN_SCENE_H

#include "kpcn/common.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct kpcn_scene kpcn_scene;

/* Loads a scene file; relative paths inside it (meshes, textures) resolve against the
 * file's directory. */
kpcn_status kpcn_scene_load(const char *path, kpcn_scene **out);

/* Loads a scene from an in-memory JSON document. base_dir resolves relative paths (NULL or
 * "" = current directory); name is what error messages and the kpcn:scene header call it
 * (NULL = "<memory>"). */
kpcn_status kpcn_scene_load_json(const char *json_text, const char *base_dir, const char *name,
                                 kpcn_scene **out);

void kpcn_scene_destroy(kpcn_scene *scene);

/* Summary of what was loaded (for tools and tests). */
typedef struct kpcn_scene_info {
  int width, height;    /* camera resolution */
  int spp;              /* renderer.spp (default 32, as Tungsten; 64 before session 60) */
  int min_bounces;      /* integrator.min_bounces */
  int max_bounces;      /* integrator.max_bounces */
  int light_sampling;   /* integrator.enable_light_sampling */
  int nprimitives;      /* including infinite_sphere */
  int nlights;          /* emissive primitives + environment */
  long long ntriangles; /* triangles in meshes (analytic shapes not counted) */
  float fov_deg;        /* horizontal field of view */
  char camera[16];      /* "pinhole" / "thinlens" */
  char filter[16];      /* "box" / "tent" / "gaussian" */
  char name[256];       /* file name (or the name given to kpcn_scene_load_json) */
} kpcn_scene_info;

kpcn_status kpcn_scene_get_info(const kpcn_scene *scene, kpcn_scene_info *info);

#ifdef __cplusplus
}
#endif
#endif
