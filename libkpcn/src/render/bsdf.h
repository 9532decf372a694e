/* BSDFs with Tungsten's definitions and parameter names (lambert, mirror, conductor,
 * rough_conductor, dielectric, rough_dielectric, plastic, rough_plastic, smooth_coat, null).
 *
 * CONVENTIONS (read these before calling)
 *  - Every direction is in the LOCAL shading frame: z = shading normal (kpcn_frame in vec3.h).
 *    Both wo (towards the previous vertex / camera) and wi (towards the next vertex / light)
 *    point AWAY from the surface.
 *  - Sidedness: for BSDFs that are NOT transmissive (kpcn_bsdf_is_transmissive() == 0) the
 *    integrator should flip the frame so that wo.z > 0 (Tungsten's enable_two_sided_shading);
 *    they return zero for wo.z <= 0 or wi.z <= 0. Transmissive BSDFs (dielectric,
 *    rough_dielectric, null) must get the frame of the geometric OUTWARD normal: wo.z < 0 means
 *    the ray arrives from inside the object and the ior is inverted accordingly.
 *  - sample() returns weight = f * |cos(wi)| / pdf for the WHOLE bsdf (all lobes, one-sample
 *    MIS over lobes, like Tungsten), so throughput *= weight. For a delta lobe (mirror, smooth
 *    glass, the smooth coat's reflection, smooth plastic's specular) it is the lobe's throughput
 *    divided by its selection probability, is_delta = 1 and pdf is that probability (useless
 *    for MIS: do not MIS-weight delta bounces).
 *  - eval() returns f * |cos(wi)| and the pdf sample() would have produced wi with; delta lobes
 *    are never part of eval().
 *  - Diffuse/specular split (AOVs, DESIGN.md §4): the diffuse part of a scattering event is the
 *    light that went through a DIFFUSE lobe (lambert, the diffuse base of plastic/rough_plastic,
 *    a lambert substrate under smooth_coat). sample() gives weight_diffuse (<= weight
 *    componentwise) and eval() gives f_cos_diffuse, so the integrator can carry two throughputs
 *    from the first non-delta bounce (diffuse = weight_diffuse, specular = weight -
 *    weight_diffuse) with no bias in either buffer. `lobe` additionally says which lobe was
 *    picked, for integrators that prefer classifying by the sampled lobe.
 *  - Texture lookups use kpcn_shading_point (surface uv as in Tungsten: quads/meshes carry their
 *    uvs; textures are evaluated at (u, v)).
 *  - A kpcn_bsdf is immutable after creation and safe to share between threads.
 *  - Ownership: BSDFs and textures created by the JSON parser are owned by the kpcn_material_lib
 *    that parsed them (see bsdf_json below); destroy the lib after the last render.
 */
#ifndef KPCN_RENDER_BSDF_H
#define KPCN_RENDER_BSDF_H

#include "kpcn/common.h"
#include "render/texture.h"
#include "render/vec3.h"

typedef enum kpcn_bsdf_type {
  KPCN_BSDF_LAMBERT,
  KPCN_BSDF_MIRROR,
  KPCN_BSDF_CONDUCTOR,
  KPCN_BSDF_ROUGH_CONDUCTOR,
  KPCN_BSDF_DIELECTRIC,
  KPCN_BSDF_ROUGH_DIELECTRIC,
  KPCN_BSDF_PLASTIC,
  KPCN_BSDF_ROUGH_PLASTIC,
  KPCN_BSDF_SMOOTH_COAT,
  KPCN_BSDF_NULL,
  KPCN_BSDF_TYPE_COUNT
} kpcn_bsdf_type;

/* Lobe flags (bitmask). SPECULAR means a Dirac delta lobe. */
enum {
  KPCN_LOBE_DIFFUSE = 1,
  KPCN_LOBE_GLOSSY = 2,
  KPCN_LOBE_SPECULAR = 4,
  KPCN_LOBE_TRANSMISSION = 8, /* set together with one of the above for refracted lobes */
  KPCN_LOBE_FORWARD = 16      /* null bsdf: the ray continues unchanged */
};

typedef enum kpcn_microfacet_dist {
  KPCN_MF_BECKMANN = 0,
  KPCN_MF_GGX = 1,
  KPCN_MF_PHONG = 2
} kpcn_microfacet_dist;

typedef struct kpcn_shading_point {
  float u, v; /* surface texture coordinates */
} kpcn_shading_point;

typedef struct kpcn_bsdf_sample_result {
  kpcn_vec3 wi;             /* sampled direction, local frame, away from the surface */
  kpcn_vec3 weight;         /* f * |cos wi| / pdf, all lobes */
  kpcn_vec3 weight_diffuse; /* the part of weight carried by diffuse lobes */
  float pdf;                /* solid-angle pdf (non-delta) or lobe probability (delta) */
  int lobe;                 /* KPCN_LOBE_* flags of the sampled lobe */
  int is_delta;             /* 1 when the sampled lobe is a delta (no MIS) */
} kpcn_bsdf_sample_result;

typedef struct kpcn_bsdf_eval_result {
  kpcn_vec3 f_cos;         /* f * |cos wi| over all non-delta lobes */
  kpcn_vec3 f_cos_diffuse; /* the diffuse-lobe part of f_cos */
  float pdf;               /* pdf of sample() producing wi (solid angle) */
} kpcn_bsdf_eval_result;

typedef struct kpcn_bsdf kpcn_bsdf;

/* ---- parameters for programmatic construction (tests, pre-render augmentation) ---- */
typedef struct kpcn_bsdf_params {
  kpcn_bsdf_type type;
  const kpcn_texture *albedo;    /* multiplies the result (Tungsten "albedo"); NULL = 1 */
  const kpcn_texture *roughness; /* scalar texture (first channel); NULL = constant below */
  float roughness_value;         /* Tungsten default 0.1 for rough_* types */
  kpcn_microfacet_dist distribution;
  kpcn_vec3 eta, k;           /* conductors: complex IOR per channel (default Cu) */
  float ior;                  /* dielectrics, plastic, smooth_coat (Tungsten default 1.5 / 1.3) */
  int enable_refraction;      /* dielectrics: 0 = reflection only (Tungsten enable_refraction) */
  float thickness;            /* plastic, rough_plastic, smooth_coat */
  kpcn_vec3 sigma_a;          /* plastic, rough_plastic, smooth_coat */
  const kpcn_bsdf *substrate; /* smooth_coat; not owned */
} kpcn_bsdf_params;

/* Tungsten's defaults for `type` (albedo NULL = white). */
void kpcn_bsdf_params_defaults(kpcn_bsdf_params *p, kpcn_bsdf_type type);
/* Creates a bsdf (caller owns it: kpcn_bsdf_destroy). Validates the parameters. */
kpcn_status kpcn_bsdf_create(const kpcn_bsdf_params *p, kpcn_bsdf **out);
void kpcn_bsdf_destroy(kpcn_bsdf *b);

kpcn_bsdf_type kpcn_bsdf_get_type(const kpcn_bsdf *b);
const char *kpcn_bsdf_type_name(kpcn_bsdf_type t); /* Tungsten's JSON name */
int kpcn_bsdf_lobes(const kpcn_bsdf *b);           /* union of KPCN_LOBE_* flags */
int kpcn_bsdf_is_delta_only(const kpcn_bsdf *b);   /* mirror, conductor, dielectric, null */
int kpcn_bsdf_is_transmissive(const kpcn_bsdf *b); /* dielectrics and null */
int kpcn_bsdf_is_null(const kpcn_bsdf *b);         /* pass-through: ignore the hit */

/* Samples wi given wo. u1, u2, ulobe uniform in [0,1). Returns 1 on success, 0 when the
 * sample is absorbed / invalid (then *out is unspecified and the path ends). */
int kpcn_bsdf_sample(const kpcn_bsdf *b, const kpcn_shading_point *sp, kpcn_vec3 wo, float u1,
                     float u2, float ulobe, kpcn_bsdf_sample_result *out);
/* f*|cos|, its diffuse part and the sampling pdf, for the non-delta lobes. */
void kpcn_bsdf_eval(const kpcn_bsdf *b, const kpcn_shading_point *sp, kpcn_vec3 wo, kpcn_vec3 wi,
                    kpcn_bsdf_eval_result *out);
float kpcn_bsdf_pdf(const kpcn_bsdf *b, const kpcn_shading_point *sp, kpcn_vec3 wo, kpcn_vec3 wi);
/* Reflectance for the albedo AOV: the "albedo" texture value at sp (for plastic/coat the
 * base albedo; for a smooth_coat the substrate's). Delta-only BSDFs return their albedo too,
 * but the AOVs are meant to follow them to the next hit. */
kpcn_vec3 kpcn_bsdf_albedo(const kpcn_bsdf *b, const kpcn_shading_point *sp);
/* 1 when kpcn_bsdf_albedo depends on sp (a non-constant texture). */
int kpcn_bsdf_albedo_is_textured(const kpcn_bsdf *b);

/* ---- Tungsten's named conductors (fresnel.c) ---- */
/* Looks up "Cu", "Au", "Ag", "Al", ... (Tungsten's ComplexIorData names, case-sensitive as
 * Tungsten). Returns 1 and fills eta/k on success, 0 for an unknown name. */
int kpcn_conductor_lookup(const char *name, kpcn_vec3 *eta, kpcn_vec3 *k);

/* ---- JSON (bsdf_json.c) ---- */
/* A material library owns every texture and bsdf parsed from one scene file, and the table of
 * named bsdfs from the scene's "bsdfs" array (Tungsten refers to them by "name"). */
typedef struct kpcn_material_lib kpcn_material_lib;
typedef struct cJSON cJSON;

/* scene_dir resolves relative texture paths (may be "" for the cwd). */
kpcn_status kpcn_material_lib_create(const char *scene_dir, kpcn_material_lib **out);
void kpcn_material_lib_destroy(kpcn_material_lib *lib);
/* Parses the scene's "bsdfs" array (json_path e.g. "bsdfs"); entries may refer to each other
 * by name (e.g. smooth_coat "substrate") in any order. NULL array = nothing to do. */
kpcn_status kpcn_material_lib_parse_bsdfs(kpcn_material_lib *lib, const cJSON *array,
                                          const char *json_path);
/* Parses a primitive's "bsdf" value: a string naming an entry of the "bsdfs" array, or an
 * inline object. The lib owns *out. Errors name json_path, e.g.
 * "primitives[2].bsdf.distribution: unknown value 'foo'". */
kpcn_status kpcn_bsdf_parse(kpcn_material_lib *lib, const cJSON *node, const char *json_path,
                            const kpcn_bsdf **out);
/* Looks up a named bsdf; NULL when absent. */
const kpcn_bsdf *kpcn_material_lib_find(const kpcn_material_lib *lib, const char *name);
/* Parses a texture value (number, [r,g,b], "file.png", or {"type": "checker"|"bitmap"|
 * "constant", ...}). `scalar` asks for a 1-channel texture (roughness). The lib owns *out. */
kpcn_status kpcn_texture_parse(kpcn_material_lib *lib, const cJSON *node, const char *json_path,
                               int scalar, const kpcn_texture **out);
/* Texture cache of the lib, to load emission maps for lights / environment maps. */
kpcn_texture_cache *kpcn_material_lib_textures(kpcn_material_lib *lib);
/* Takes ownership of a bsdf created with kpcn_bsdf_create (e.g. a default lambert). */
kpcn_status kpcn_material_lib_adopt(kpcn_material_lib *lib, kpcn_bsdf *b);

#endif
