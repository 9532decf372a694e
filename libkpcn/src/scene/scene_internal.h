/* The loaded scene, shared by libkpcn/src/scene (loading) and libkpcn/src/render
 * (tracing). Not installed. Geometry is kept both as Embree geometries (for ray queries) and
 * as the small analytic descriptions below (for hit-point shading and light sampling). */
#ifndef KPCN_SCENE_INTERNAL_H
#define KPCN_SCENE_INTERNAL_H

#include "kpcn/scene.h"
#include "render/bsdf.h"
#include "render/envmap.h"
#include "render/sampling.h"
#include "render/vec3.h"

typedef enum kpcn_prim_type {
  KPCN_PRIM_QUAD,
  KPCN_PRIM_CUBE,
  KPCN_PRIM_SPHERE,
  KPCN_PRIM_DISK,
  KPCN_PRIM_MESH,
  KPCN_PRIM_INFINITE_SPHERE
} kpcn_prim_type;

/* 3x4 affine transform, row-major: world = M[0..2][0..2] * local + M[.][3]. */
typedef struct kpcn_xform {
  float m[3][4];
} kpcn_xform;

typedef struct kpcn_mesh {
  int nverts, ntris;
  float *pos;              /* 3 * nverts, world space */
  float *nrm;              /* 3 * nverts world-space vertex normals or NULL */
  float *uv;               /* 2 * nverts or NULL */
  unsigned *idx;           /* 3 * ntris */
  int smooth;              /* interpolate nrm */
  kpcn_distrib1d area_cdf; /* triangle selection by area (emissive meshes only) */
} kpcn_mesh;

typedef struct kpcn_prim {
  kpcn_prim_type type;
  char name[64];
  const kpcn_bsdf *bsdf; /* never NULL except for infinite_sphere */
  int emissive;
  kpcn_vec3 emission;               /* constant radiance (area lights) */
  const kpcn_texture *emission_tex; /* non-constant emission (texture at the hit uv) or NULL */
  float area;
  /* quad: base corner, edges (Tungsten: uv (l0, 1-l1)), unit normal = e1 x e0 normalised */
  kpcn_vec3 base, e0, e1, n;
  float inv_e0sq, inv_e1sq;
  /* cube: centre, unit axes (rows of rot), half extents; face cdf for sampling */
  kpcn_vec3 center, axis[3], half;
  float face_cdf[3];
  /* sphere / disk: centre = center, radius; disk normal = n with tangent frame (the disk's
   * light samples); disk uv: Tungsten's TangentFrame(n) in axis[0] (tangent), axis[1]
   * (bitangent), u = atan2(r.tangent, r.bitangent) / 2pi + 0.5, v = |r| / radius */
  float radius;
  kpcn_frame frame;
  kpcn_mesh mesh;
  unsigned geom_id; /* Embree geometry id (RTC_INVALID_GEOMETRY_ID for env) */
  int light_index;  /* index in scene->lights or -1 */
} kpcn_prim;

typedef enum kpcn_filter_type {
  KPCN_FILTER_BOX,
  KPCN_FILTER_TENT,
  KPCN_FILTER_GAUSSIAN
} kpcn_filter_type;

typedef struct kpcn_camera {
  int thinlens;
  kpcn_vec3 pos, right, up, fwd; /* Tungsten lookAt basis: right = fwd x up */
  float fov_deg;
  float plane_dist;           /* 1/tan(fov/2): image plane spans x in [-1, 1] */
  float aperture, focus_dist; /* thinlens */
  int width, height;
  kpcn_filter_type filter;
} kpcn_camera;

typedef struct kpcn_light {
  int prim; /* index into prims, or -1 for the environment */
  float select_pdf;
} kpcn_light;

struct kpcn_scene {
  char name[256];
  char base_dir[4096]; /* PATH_MAX: a longer one is refused, never truncated */
  kpcn_material_lib *mats;
  kpcn_prim *prims;
  int nprims;
  unsigned *geom_to_prim; /* Embree geomID -> prim index */
  int ngeoms;
  kpcn_light *lights;
  int nlights;
  kpcn_distrib1d light_cdf; /* selection over lights[] */
  int env_prim;             /* index of the infinite_sphere or -1 */
  kpcn_envmap *env;
  int env_light; /* index in lights[] or -1 */
  kpcn_camera cam;
  int spp, min_bounces, max_bounces, light_sampling;
  long long ntriangles;
  float scene_radius; /* bounding sphere radius of finite geometry (ray epsilons) */
  void *rtc_device;   /* RTCDevice */
  void *rtc_scene;    /* RTCScene */
};

/* Smallest camera.fov in degrees: 1/tan(fov/2) stays ~1e5 (a tiny float fov made it Inf). */
#define KPCN_MIN_FOV 1e-3
/* Thin-lens focus_distance range: [KPCN_MIN_FOCUS_DISTANCE, KPCN_SCENE_MAX_EXTENT]. */
#define KPCN_MIN_FOCUS_DISTANCE 1e-6f
/* Largest emitted radiance (any channel, constant or texel): its square (1e30) and a pixel's
 * sample variance stay within float range. */
#define KPCN_MAX_EMISSION 1e15f

/* ---- json_check.c ---- */
/* Fails on a key that occurs twice in one object anywhere in the document, naming its JSON
 * path (cJSON keeps both and every lookup finds the first). */
kpcn_status kpcn_json_check_duplicates(const void *cjson_root);

/* ---- transform.c ---- */
/* Parses a Tungsten transform object (position, scale, rotation, look_at, up, x_axis, y_axis,
 * z_axis) or a 16-number matrix. Errors name json_path. */
kpcn_status kpcn_xform_parse(const void *cjson_node, const char *json_path, kpcn_xform *out);
void kpcn_xform_identity(kpcn_xform *x);
kpcn_vec3 kpcn_xform_point(const kpcn_xform *x, kpcn_vec3 p);
kpcn_vec3 kpcn_xform_vector(const kpcn_xform *x, kpcn_vec3 v);
/* Normal transform (inverse transpose), normalised. */
kpcn_vec3 kpcn_xform_normal(const kpcn_xform *x, kpcn_vec3 n);
/* Column i of the linear part. */
kpcn_vec3 kpcn_xform_column(const kpcn_xform *x, int i);

/* ---- mesh_io.c ---- */
/* Loads .wo3 natively, .obj/.ply/.gltf/.glb through assimp, into object space (pos, nrm, uv
 * arrays in m). Errors name the file and json_path. */
kpcn_status kpcn_mesh_load(const char *path, const char *json_path, kpcn_mesh *m);
void kpcn_mesh_free(kpcn_mesh *m);
/* Smooth normals with hard creases, as Tungsten computes them (mesh_normals.c); may add
 * vertices (a corner past a crease gets its own). */
kpcn_status kpcn_mesh_smooth_normals(kpcn_mesh *m);

/* ---- scene_embree.c ---- */
/* Largest |coordinate| a scene may reach (vertices, sphere/disc extents, camera position plus
 * aperture): far enough inside Embree's valid ray range (|origin| < 1.8e18) that ray offsets
 * and hit points computed from it stay finite and valid. */
#define KPCN_SCENE_MAX_EXTENT 1e15f

/* Checks the scene's extent, then creates the Embree device/scene from scene->prims. */
kpcn_status kpcn_scene_build_embree(struct kpcn_scene *scene);
void kpcn_scene_release_embree(struct kpcn_scene *scene);

/* ---- scene_lights.c ---- */
/* Builds scene->lights (emissive primitives + environment) and their selection cdf;
 * rejects zero-area emitters naming the primitive's JSON path. */
kpcn_status kpcn_scene_build_lights(struct kpcn_scene *scene);

#endif
