/* scene.json loading (Tungsten's format, the subset in docs/renderer.md). Every object's
 * fields are checked against the list this loader understands, so an unsupported feature is
 * an error naming its JSON path instead of a silently different image. */
#include "core/internal.h"
#include "scene/scene_internal.h"

#include <cjson/cJSON.h>
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define JP 384 /* JSON path buffer */

/* Fails on any member of obj not listed in `known` (NULL-terminated). */
static kpcn_status check_fields(const cJSON *obj, const char *path, const char *const *known) {
  for (const cJSON *it = obj->child; it; it = it->next) {
    int ok = 0;
    for (const char *const *k = known; *k; k++)
      if (it->string && strcmp(it->string, *k) == 0) ok = 1;
    if (!ok)
      return kpcn_fail(KPCN_ERR_UNSUPPORTED, "%s.%s: unsupported field", path,
                       it->string ? it->string : "?");
  }
  return KPCN_OK;
}

/* Fields accepted without effect (Tungsten's own output and scheduling settings) must still
 * have Tungsten's types: a number where a file name belongs is a broken scene file, not
 * something to ignore. */
enum { JT_STR = 1, JT_BOOL = 2, JT_NUM = 4, JT_ARR = 8 };
typedef struct kpcn_typed_field {
  const char *key;
  int types; /* JT_* mask */
  const char *what;
} kpcn_typed_field;

static kpcn_status check_types(const cJSON *obj, const char *path, const kpcn_typed_field *f) {
  for (; f->key; f++) {
    const cJSON *it = cJSON_GetObjectItemCaseSensitive(obj, f->key);
    if (!it) continue;
    int t = cJSON_IsString(it)   ? JT_STR
            : cJSON_IsBool(it)   ? JT_BOOL
            : cJSON_IsNumber(it) ? JT_NUM
            : cJSON_IsArray(it)  ? JT_ARR
                                 : 0;
    if (!(t & f->types))
      return kpcn_fail(KPCN_ERR_FORMAT, "%s.%s: expected %s", path, f->key, f->what);
  }
  return KPCN_OK;
}

static kpcn_status get_number(const cJSON *obj, const char *key, const char *path, double *v,
                              int *found) {
  const cJSON *it = cJSON_GetObjectItemCaseSensitive(obj, key);
  if (found) *found = it != NULL;
  if (!it) return KPCN_OK;
  if (!cJSON_IsNumber(it)) return kpcn_fail(KPCN_ERR_FORMAT, "%s.%s: expected a number", path, key);
  if (!isfinite(it->valuedouble))
    return kpcn_fail(KPCN_ERR_NONFINITE, "%s.%s: non-finite value", path, key);
  *v = it->valuedouble;
  return KPCN_OK;
}

static kpcn_status get_int(const cJSON *obj, const char *key, const char *path, int *v, int lo,
                           int hi) {
  double d = *v;
  int f;
  KPCN_TRY(get_number(obj, key, path, &d, &f));
  if (!f) return KPCN_OK;
  if (d != floor(d) || d < lo || d > hi)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s.%s: expected an integer in [%d, %d], got %g",
                     path, key, lo, hi, d);
  *v = (int)d;
  return KPCN_OK;
}

static kpcn_status get_bool(const cJSON *obj, const char *key, const char *path, int *v) {
  const cJSON *it = cJSON_GetObjectItemCaseSensitive(obj, key);
  if (!it) return KPCN_OK;
  if (!cJSON_IsBool(it))
    return kpcn_fail(KPCN_ERR_FORMAT, "%s.%s: expected true or false", path, key);
  *v = cJSON_IsTrue(it);
  return KPCN_OK;
}

/* A field accepted only with the value Tungsten's default behaviour matches. */
static kpcn_status require_bool(const cJSON *obj, const char *key, const char *path, int want) {
  int v = want;
  KPCN_TRY(get_bool(obj, key, path, &v));
  if (v != want)
    return kpcn_fail(KPCN_ERR_UNSUPPORTED, "%s.%s: only %s is supported", path, key,
                     want ? "true" : "false");
  return KPCN_OK;
}

static const char *get_string(const cJSON *obj, const char *key) {
  const cJSON *it = cJSON_GetObjectItemCaseSensitive(obj, key);
  return cJSON_IsString(it) ? it->valuestring : NULL;
}

/* ---- primitives ---- */

/* Emission is radiance in [0, KPCN_MAX_EMISSION], for a constant and for every value of a
 * texture alike (a checker with a negative on_color was accepted while a negative constant was
 * not). The bound keeps a sample's square in float range: emission 1e30 wrote Inf into the
 * colour variance. */
static kpcn_status check_emission(float lo, float hi, const char *path) {
  if (!(lo >= 0.0f))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s: negative emission %g (must be >= 0)", path,
                     (double)lo);
  if (!(hi <= KPCN_MAX_EMISSION))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s: emission %g is above the supported maximum %g",
                     path, (double)hi, (double)KPCN_MAX_EMISSION);
  return KPCN_OK;
}

static kpcn_status parse_emission(kpcn_scene *s, kpcn_prim *p, const cJSON *e, const char *path) {
  if (cJSON_IsNumber(e) || cJSON_IsArray(e)) {
    float v[3];
    if (cJSON_IsNumber(e)) {
      v[0] = v[1] = v[2] = (float)e->valuedouble;
    } else {
      if (cJSON_GetArraySize(e) != 3)
        return kpcn_fail(KPCN_ERR_FORMAT, "%s: expected 3 numbers", path);
      for (int i = 0; i < 3; i++) {
        const cJSON *c = cJSON_GetArrayItem(e, i);
        if (!cJSON_IsNumber(c))
          return kpcn_fail(KPCN_ERR_FORMAT, "%s[%d]: expected a number", path, i);
        v[i] = (float)c->valuedouble;
      }
    }
    KPCN_TRY(check_emission(fminf(v[0], fminf(v[1], v[2])), fmaxf(v[0], fmaxf(v[1], v[2])), path));
    p->emission = kv3(v[0], v[1], v[2]);
    p->emissive = !kv3_is_zero(p->emission);
    return KPCN_OK;
  }
  /* a texture (bitmap, checker): looked up at the surface uv; its mean drives light selection */
  KPCN_TRY(kpcn_texture_parse(s->mats, e, path, 0, &p->emission_tex));
  float lo, hi;
  kpcn_texture_range(p->emission_tex, &lo, &hi);
  KPCN_TRY(check_emission(lo, hi, path));
  p->emission = p->emission_tex->average;
  p->emissive = 1;
  return KPCN_OK;
}

/* Fills the analytic description of p from its transform. */

/* Tungsten's TangentFrame(n) (the frame its disks take their uv in): tangent (0, 1, 0) when
 * |n.x| > |n.y|, else (1, 0, 0); bitangent = normalize(n x tangent), tangent = bitangent x n.
 * It equals kpcn_frame_from_normal for normals along +-y and +-z only; other disks got their
 * texture turned (session 60). */
static void disk_uv_frame(kpcn_vec3 n, kpcn_vec3 *tangent, kpcn_vec3 *bitangent) {
  kpcn_vec3 t = fabsf(n.x) > fabsf(n.y) ? kv3(0.0f, 1.0f, 0.0f) : kv3(1.0f, 0.0f, 0.0f);
  *bitangent = kv3_normalize(kv3_cross(n, t));
  *tangent = kv3_cross(*bitangent, n);
}

static kpcn_status setup_shape(kpcn_prim *p, const kpcn_xform *x, const char *path) {
  kpcn_vec3 c = kpcn_xform_point(x, kv3s(0));
  kpcn_vec3 cx = kpcn_xform_column(x, 0), cy = kpcn_xform_column(x, 1),
            cz = kpcn_xform_column(x, 2);
  p->center = c;
  switch (p->type) {
  case KPCN_PRIM_QUAD: {
    p->e0 = cx;
    p->e1 = cz;
    p->base = kv3_sub(kv3_sub(c, kv3_scale(cx, 0.5f)), kv3_scale(cz, 0.5f));
    kpcn_vec3 n = kv3_cross(p->e1, p->e0);
    p->area = kv3_length(n);
    if (!(p->area > 0.0f))
      return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s.transform: quad has zero area", path);
    p->n = kv3_scale(n, 1.0f / p->area);
    p->inv_e0sq = 1.0f / kv3_length2(p->e0);
    p->inv_e1sq = 1.0f / kv3_length2(p->e1);
    break;
  }
  case KPCN_PRIM_CUBE: {
    kpcn_vec3 cols[3] = {cx, cy, cz};
    float h[3];
    for (int i = 0; i < 3; i++) {
      h[i] = 0.5f * kv3_length(cols[i]);
      if (!(h[i] > 0.0f))
        return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s.transform: cube has zero size", path);
      p->axis[i] = kv3_normalize(cols[i]);
    }
    p->half = kv3(h[0], h[1], h[2]);
    p->face_cdf[0] = 4.0f * h[1] * h[2];
    p->face_cdf[1] = p->face_cdf[0] + 4.0f * h[2] * h[0];
    p->face_cdf[2] = p->face_cdf[1] + 4.0f * h[0] * h[1];
    p->area = 2.0f * p->face_cdf[2];
    break;
  }
  case KPCN_PRIM_SPHERE:
    p->radius = fmaxf(kv3_length(cx), fmaxf(kv3_length(cy), kv3_length(cz)));
    if (!(p->radius > 0.0f))
      return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s.transform: sphere has zero radius", path);
    p->area = 4.0f * KPCN_PI * p->radius * p->radius;
    p->frame.t = kv3_normalize(cx);
    p->frame.b = kv3_normalize(cy);
    p->frame.n = kv3_normalize(cz);
    break;
  case KPCN_PRIM_DISK:
    p->radius = fmaxf(kv3_length(cx), kv3_length(cz));
    if (!(p->radius > 0.0f))
      return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s.transform: disk has zero radius", path);
    p->n = kv3_normalize(cy);
    if (kv3_length2(p->n) == 0.0f) p->n = kpcn_xform_normal(x, kv3(0, 1, 0));
    p->frame = kpcn_frame_from_normal(p->n);
    disk_uv_frame(p->n, &p->axis[0], &p->axis[1]);
    p->area = KPCN_PI * p->radius * p->radius;
    break;
  case KPCN_PRIM_MESH: {
    kpcn_mesh *m = &p->mesh;
    double area = 0.0;
    for (int i = 0; i < m->nverts; i++) {
      kpcn_vec3 v = kpcn_xform_point(x, kv3(m->pos[3 * i], m->pos[3 * i + 1], m->pos[3 * i + 2]));
      m->pos[3 * i] = v.x, m->pos[3 * i + 1] = v.y, m->pos[3 * i + 2] = v.z;
      if (m->nrm) {
        kpcn_vec3 n =
            kpcn_xform_normal(x, kv3(m->nrm[3 * i], m->nrm[3 * i + 1], m->nrm[3 * i + 2]));
        m->nrm[3 * i] = n.x, m->nrm[3 * i + 1] = n.y, m->nrm[3 * i + 2] = n.z;
      }
    }
    for (int t = 0; t < m->ntris; t++) {
      const unsigned *id = m->idx + 3 * t;
      kpcn_vec3 a = kv3(m->pos[3 * id[0]], m->pos[3 * id[0] + 1], m->pos[3 * id[0] + 2]);
      kpcn_vec3 b = kv3(m->pos[3 * id[1]], m->pos[3 * id[1] + 1], m->pos[3 * id[1] + 2]);
      kpcn_vec3 cc = kv3(m->pos[3 * id[2]], m->pos[3 * id[2] + 1], m->pos[3 * id[2] + 2]);
      area += 0.5 * kv3_length(kv3_cross(kv3_sub(b, a), kv3_sub(cc, a)));
    }
    p->area = (float)area;
    break;
  }
  case KPCN_PRIM_INFINITE_SPHERE: break;
  }
  return KPCN_OK;
}

static kpcn_status parse_primitive_into_slot(kpcn_scene *s, const cJSON *pj, int index) {
  char path[JP], sub[JP + 64];
  snprintf(path, sizeof(path), "primitives[%d]", index);
  if (!cJSON_IsObject(pj)) return kpcn_fail(KPCN_ERR_FORMAT, "%s: expected an object", path);
  const char *type = get_string(pj, "type");
  if (!type) return kpcn_fail(KPCN_ERR_FORMAT, "%s.type: missing or not a string", path);
  kpcn_prim *p = &s->prims[s->nprims];
  memset(p, 0, sizeof(*p));
  p->geom_id = ~0u;
  const cJSON *nj = cJSON_GetObjectItemCaseSensitive(pj, "name");
  if (nj && !cJSON_IsString(nj))
    return kpcn_fail(KPCN_ERR_FORMAT, "%s.name: expected a string", path);
  const char *name = get_string(pj, "name");
  snprintf(p->name, sizeof(p->name), "%s", name ? name : "");
  static const char *common[] = {"name",
                                 "type",
                                 "transform",
                                 "bsdf",
                                 "emission",
                                 "bump_strength",
                                 "file",
                                 "smooth",
                                 "backface_culling",
                                 "recompute_normals",
                                 "sample",
                                 "cone_angle",
                                 NULL};
  if (strcmp(type, "quad") == 0)
    p->type = KPCN_PRIM_QUAD;
  else if (strcmp(type, "cube") == 0)
    p->type = KPCN_PRIM_CUBE;
  else if (strcmp(type, "sphere") == 0)
    p->type = KPCN_PRIM_SPHERE;
  else if (strcmp(type, "disk") == 0)
    p->type = KPCN_PRIM_DISK;
  else if (strcmp(type, "mesh") == 0)
    p->type = KPCN_PRIM_MESH;
  else if (strcmp(type, "infinite_sphere") == 0)
    p->type = KPCN_PRIM_INFINITE_SPHERE;
  else
    return kpcn_fail(KPCN_ERR_UNSUPPORTED,
                     "%s.type: unsupported primitive type '%s' (quad, cube, sphere, disk, mesh, "
                     "infinite_sphere)",
                     path, type);
  /* fields after the type: a Tungsten skydome or point light is named as the unsupported type
   * it is, not by its first field ("temperature", "power") */
  KPCN_TRY(check_fields(pj, path, common));
  /* type-specific fields present on the wrong type are errors too */
  const char *mesh_only[] = {"file", "smooth", "backface_culling", "recompute_normals"};
  for (int i = 0; i < 4; i++)
    if (p->type != KPCN_PRIM_MESH && cJSON_GetObjectItemCaseSensitive(pj, mesh_only[i]))
      return kpcn_fail(KPCN_ERR_UNSUPPORTED, "%s.%s: unsupported field for type '%s'", path,
                       mesh_only[i], type);
  if (p->type != KPCN_PRIM_INFINITE_SPHERE && cJSON_GetObjectItemCaseSensitive(pj, "sample"))
    return kpcn_fail(KPCN_ERR_UNSUPPORTED, "%s.sample: unsupported field for type '%s'", path,
                     type);
  if (cJSON_GetObjectItemCaseSensitive(pj, "cone_angle")) {
    double ca = 90.0;
    snprintf(sub, sizeof(sub), "%s", path);
    KPCN_TRY(get_number(pj, "cone_angle", sub, &ca, NULL));
    if (p->type != KPCN_PRIM_DISK || ca != 90.0)
      return kpcn_fail(KPCN_ERR_UNSUPPORTED, "%s.cone_angle: only 90 on disks is supported", path);
  }
  double bump = 1.0;
  KPCN_TRY(get_number(pj, "bump_strength", path, &bump, NULL));

  kpcn_xform x;
  snprintf(sub, sizeof(sub), "%s.transform", path);
  KPCN_TRY(kpcn_xform_parse(cJSON_GetObjectItemCaseSensitive(pj, "transform"), sub, &x));

  if (p->type == KPCN_PRIM_MESH) {
    const char *file = get_string(pj, "file");
    if (!file) return kpcn_fail(KPCN_ERR_FORMAT, "%s.file: missing or not a string", path);
    char full[8192];
    if (!kpcn_path_join(full, sizeof(full), s->base_dir, file))
      return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s.file: the path is longer than %zu bytes",
                       path, sizeof(full) - 1);
    snprintf(sub, sizeof(sub), "%s.file", path);
    KPCN_TRY(kpcn_mesh_load(full, sub, &p->mesh));
    p->mesh.smooth =
        0; /* Tungsten's default: flat unless "smooth": true (was 1 until session 58) */
    KPCN_TRY(get_bool(pj, "smooth", path, &p->mesh.smooth));
    KPCN_TRY(require_bool(pj, "backface_culling", path, 0));
    int recompute = 0;
    KPCN_TRY(get_bool(pj, "recompute_normals", path, &recompute));
    if (p->mesh.smooth && (recompute || !p->mesh.nrm)) KPCN_TRY(kpcn_mesh_smooth_normals(&p->mesh));
    s->ntriangles += p->mesh.ntris;
  }
  KPCN_TRY(setup_shape(p, &x, path));

  if (p->type == KPCN_PRIM_INFINITE_SPHERE) {
    if (s->env_prim >= 0)
      return kpcn_fail(KPCN_ERR_UNSUPPORTED, "%s: only one infinite_sphere is supported", path);
    int sample = 1;
    KPCN_TRY(get_bool(pj, "sample", path, &sample));
    /* Tungsten's scenes give it a bsdf (materialtest: null) that does nothing; a broken one is
     * still a broken scene file */
    const cJSON *bj = cJSON_GetObjectItemCaseSensitive(pj, "bsdf");
    if (bj) {
      const kpcn_bsdf *unused;
      snprintf(sub, sizeof(sub), "%s.bsdf", path);
      KPCN_TRY(kpcn_bsdf_parse(s->mats, bj, sub, &unused));
    }
    const cJSON *e = cJSON_GetObjectItemCaseSensitive(pj, "emission");
    if (!e)
      return kpcn_fail(KPCN_ERR_FORMAT, "%s.emission: infinite_sphere needs an emission", path);
    snprintf(sub, sizeof(sub), "%s.emission", path);
    KPCN_TRY(parse_emission(s, p, e, sub));
    if (!p->emission_tex) {
      KPCN_TRY(kpcn_texture_constant(kpcn_material_lib_textures(s->mats), p->emission,
                                     &p->emission_tex));
    }
    float rot[9];
    for (int r = 0; r < 3; r++)
      for (int c = 0; c < 3; c++)
        rot[3 * r + c] = x.m[r][c];
    KPCN_TRY(kpcn_envmap_create(p->emission_tex, rot, sample, &s->env));
    s->env_prim = s->nprims;
    s->nprims++;
    return KPCN_OK;
  }

  const cJSON *bj = cJSON_GetObjectItemCaseSensitive(pj, "bsdf");
  if (!bj) return kpcn_fail(KPCN_ERR_FORMAT, "%s.bsdf: missing", path);
  snprintf(sub, sizeof(sub), "%s.bsdf", path);
  KPCN_TRY(kpcn_bsdf_parse(s->mats, bj, sub, &p->bsdf));
  const cJSON *e = cJSON_GetObjectItemCaseSensitive(pj, "emission");
  if (e) {
    snprintf(sub, sizeof(sub), "%s.emission", path);
    KPCN_TRY(parse_emission(s, p, e, sub));
    if (p->emissive && !(p->area > 0.0f))
      return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s.emission: emitter has zero area", path);
  }
  s->nprims++;
  return KPCN_OK;
}

/* Parses primitive `index` into the next slot (s->prims[s->nprims]); the slot only counts
 * (and is freed with the scene) once it is complete, so a failure part-way frees what the
 * slot already holds (a loaded mesh) here. */
static kpcn_status parse_primitive(kpcn_scene *s, const cJSON *pj, int index) {
  kpcn_status st = parse_primitive_into_slot(s, pj, index);
  if (st != KPCN_OK) {
    kpcn_mesh_free(&s->prims[s->nprims].mesh);
    memset(&s->prims[s->nprims], 0, sizeof(kpcn_prim));
  }
  return st;
}

/* ---- camera, integrator, renderer ---- */

static kpcn_status parse_camera(kpcn_scene *s, const cJSON *cj) {
  const char *path = "camera";
  kpcn_camera *c = &s->cam;
  c->width = 1000, c->height = 563; /* Tungsten's defaults */
  c->fov_deg = 60.0f;
  c->filter = KPCN_FILTER_TENT;
  c->focus_dist = 1.0f;
  c->aperture = 0.001f;
  /* view direction kept as a direction: (pos + dir) - pos in float loses it far from the
   * origin (ulp(1e7) = 1) */
  kpcn_vec3 pos = kv3(0, 0, 2), dir = kv3(0, 0, -3), up = kv3(0, 1, 0);
  int from_transform = 0; /* the view came from camera.transform (for the error below) */
  if (!cj) goto finish;
  if (!cJSON_IsObject(cj)) return kpcn_fail(KPCN_ERR_FORMAT, "camera: expected an object");
  static const char *known[] = {"type",
                                "resolution",
                                "fov",
                                "transform",
                                "reconstruction_filter",
                                "tonemap",
                                "file",
                                "focus_distance",
                                "aperture_size",
                                "cateye",
                                "position",
                                "lookAt",
                                "up",
                                "spp",
                                NULL};
  KPCN_TRY(check_fields(cj, path, known));
  static const kpcn_typed_field typed[] = {{"tonemap", JT_STR, "a tonemapper name"},
                                           {"file", JT_STR, "a file name"},
                                           {"spp", JT_NUM, "a number"},
                                           {NULL, 0, NULL}};
  KPCN_TRY(check_types(cj, path, typed));
  const char *type = get_string(cj, "type");
  if (!type) return kpcn_fail(KPCN_ERR_FORMAT, "camera.type: missing or not a string");
  if (strcmp(type, "thinlens") == 0)
    c->thinlens = 1;
  else if (strcmp(type, "pinhole") != 0)
    return kpcn_fail(KPCN_ERR_UNSUPPORTED,
                     "camera.type: unsupported camera '%s' (pinhole, thinlens)", type);
  if (!c->thinlens && (cJSON_GetObjectItemCaseSensitive(cj, "focus_distance") ||
                       cJSON_GetObjectItemCaseSensitive(cj, "aperture_size")))
    return kpcn_fail(KPCN_ERR_UNSUPPORTED,
                     "camera: focus_distance/aperture_size need type thinlens");
  const cJSON *res = cJSON_GetObjectItemCaseSensitive(cj, "resolution");
  if (res) {
    double w, h;
    if (cJSON_IsNumber(res)) {
      w = h = res->valuedouble;
    } else if (cJSON_IsArray(res) && cJSON_GetArraySize(res) == 2 &&
               cJSON_IsNumber(cJSON_GetArrayItem(res, 0)) &&
               cJSON_IsNumber(cJSON_GetArrayItem(res, 1))) {
      w = cJSON_GetArrayItem(res, 0)->valuedouble;
      h = cJSON_GetArrayItem(res, 1)->valuedouble;
    } else {
      return kpcn_fail(KPCN_ERR_FORMAT, "camera.resolution: expected a number or [width, height]");
    }
    if (!(w >= 1 && h >= 1 && w <= KPCN_MAX_DIM && h <= KPCN_MAX_DIM) || w != floor(w) ||
        h != floor(h))
      return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                       "camera.resolution: invalid size %gx%g (integers in [1, %d])", w, h,
                       KPCN_MAX_DIM);
    c->width = (int)w, c->height = (int)h;
  }
  double fov = c->fov_deg;
  KPCN_TRY(get_number(cj, "fov", path, &fov, NULL));
  /* checked as it is used: a float, through tanf. 1e-38 passed a check on the double, became
   * 0 or a denormal as a float and 1/tan(fov/2) Inf (Embree aborted on the camera rays);
   * 179.99999999 rounds to 180.0f, and just below it float pi/2 makes tanf negative. */
  const float fovf = (float)fov, tan_half = tanf(fovf * (KPCN_PI / 180.0f) * 0.5f);
  if (!(fov >= KPCN_MIN_FOV && fovf < 180.0f && tan_half > 0.0f && isfinite(tan_half))) {
    char as_float[48] = "";
    if ((double)fovf != fov) snprintf(as_float, sizeof(as_float), " (%.9g as a float)", fovf);
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "camera.fov: %.12g%s is outside [%g, 180) degrees",
                     fov, as_float, KPCN_MIN_FOV);
  }
  c->fov_deg = fovf;
  const char *filt = get_string(cj, "reconstruction_filter");
  if (cJSON_GetObjectItemCaseSensitive(cj, "reconstruction_filter") && !filt)
    return kpcn_fail(KPCN_ERR_FORMAT, "camera.reconstruction_filter: expected a string");
  if (filt) {
    if (strcmp(filt, "box") == 0)
      c->filter = KPCN_FILTER_BOX;
    else if (strcmp(filt, "tent") == 0)
      c->filter = KPCN_FILTER_TENT;
    else if (strcmp(filt, "gaussian") == 0)
      c->filter = KPCN_FILTER_GAUSSIAN;
    else
      return kpcn_fail(
          KPCN_ERR_UNSUPPORTED,
          "camera.reconstruction_filter: unsupported filter '%s' (box, tent, gaussian)", filt);
  }
  double fd = c->focus_dist, ap = c->aperture, ce = 0.0;
  KPCN_TRY(get_number(cj, "focus_distance", path, &fd, NULL));
  KPCN_TRY(get_number(cj, "aperture_size", path, &ap, NULL));
  KPCN_TRY(get_number(cj, "cateye", path, &ce, NULL));
  if (ce != 0.0) return kpcn_fail(KPCN_ERR_UNSUPPORTED, "camera.cateye: only 0 is supported");
  c->focus_dist = (float)fd, c->aperture = (float)ap;
  /* as floats (1e39 became Inf, the camera rays NaN, and Embree aborted), within the scene's
   * coordinate range like the camera position, and not so small that the focus point
   * underflows onto the lens; kpcn_render_ctx_init checks the focus plane's size */
  if (!(c->focus_dist >= KPCN_MIN_FOCUS_DISTANCE && c->focus_dist <= KPCN_SCENE_MAX_EXTENT))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "camera.focus_distance: %g is outside [%g, %g]", fd,
                     (double)KPCN_MIN_FOCUS_DISTANCE, (double)KPCN_SCENE_MAX_EXTENT);
  if (!(ap >= 0.0))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "camera.aperture_size: %g is negative", ap);
  const cJSON *tj = cJSON_GetObjectItemCaseSensitive(cj, "transform");
  from_transform = tj != NULL;
  /* Tungsten's older camera fields, the view when there is no transform */
  static const char *const old_keys[3] = {"position", "lookAt", "up"};
  if (tj) {
    for (int k = 0; k < 3; k++)
      if (cJSON_GetObjectItemCaseSensitive(cj, old_keys[k]))
        return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                         "camera.%s: given beside camera.transform, which sets the view (give "
                         "one of the two)",
                         old_keys[k]);
    kpcn_xform x;
    KPCN_TRY(kpcn_xform_parse(tj, "camera.transform", &x));
    pos = kpcn_xform_point(&x, kv3s(0));
    dir = kpcn_xform_column(&x, 2);
    up = kpcn_xform_column(&x, 1);
    /* the camera takes a position and an orientation: a scale would stretch the view in
     * Tungsten, and was dropped here without a word */
    for (int k = 0; k < 3; k++) {
      const float len = kv3_length(kpcn_xform_column(&x, k));
      if (!(fabsf(len - 1.0f) <= 1e-3f))
        return kpcn_fail(KPCN_ERR_UNSUPPORTED,
                         "camera.transform: a scale is not supported (its %c axis has length %g; "
                         "the camera takes position and orientation only)",
                         "xyz"[k], (double)len);
    }
    /* a mirror (scale -1, or a left-handed matrix) would flip the image in Tungsten */
    if (kv3_dot(kv3_cross(kpcn_xform_column(&x, 0), up), dir) < 0.0f)
      return kpcn_fail(KPCN_ERR_UNSUPPORTED,
                       "camera.transform: a mirroring transform (left-handed axes) is not "
                       "supported");
  } else { /* Tungsten's older camera fields */
    kpcn_vec3 look = kv3_add(pos, dir);
    kpcn_vec3 *dst[3] = {&pos, &look, &up};
    for (int k = 0; k < 3; k++) {
      const cJSON *a = cJSON_GetObjectItemCaseSensitive(cj, old_keys[k]);
      if (!a) continue;
      if (!cJSON_IsArray(a) || cJSON_GetArraySize(a) != 3)
        return kpcn_fail(KPCN_ERR_FORMAT, "camera.%s: expected 3 numbers", old_keys[k]);
      float v[3];
      for (int i = 0; i < 3; i++) {
        const cJSON *e = cJSON_GetArrayItem(a, i);
        if (!cJSON_IsNumber(e) || !isfinite((float)e->valuedouble))
          return kpcn_fail(KPCN_ERR_FORMAT, "camera.%s[%d]: expected a finite number", old_keys[k],
                           i);
        v[i] = (float)e->valuedouble;
      }
      *dst[k] = kv3(v[0], v[1], v[2]);
    }
    dir = kv3_sub(look, pos);
  }
finish:
  c->pos = pos;
  c->fwd = kv3_normalize(dir);
  c->right = kv3_normalize(kv3_cross(c->fwd, up));
  if (!(kv3_length2(c->fwd) > 0.5f) || !(kv3_length2(c->right) > 0.5f))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     from_transform
                         ? "camera.transform: degenerate view (its look_at equals its position, or "
                           "its up is parallel to the view direction)"
                         : "camera.lookAt / camera.up: degenerate view (lookAt equals position, or "
                           "up is parallel to the view direction)");
  c->up = kv3_normalize(kv3_cross(c->right, c->fwd));
  c->plane_dist = 1.0f / tanf(c->fov_deg * (KPCN_PI / 180.0f) * 0.5f);
  return KPCN_OK;
}

static kpcn_status parse_integrator(kpcn_scene *s, const cJSON *ij) {
  s->min_bounces = 0, s->max_bounces = 64, s->light_sampling = 1;
  if (!ij) return KPCN_OK;
  if (!cJSON_IsObject(ij)) return kpcn_fail(KPCN_ERR_FORMAT, "integrator: expected an object");
  static const char *known[] = {"type",
                                "min_bounces",
                                "max_bounces",
                                "enable_light_sampling",
                                "enable_volume_light_sampling",
                                "enable_consistency_checks",
                                "enable_two_sided_shading",
                                NULL};
  KPCN_TRY(check_fields(ij, "integrator", known));
  const char *type = get_string(ij, "type");
  if (!type || strcmp(type, "path_tracer") != 0)
    return kpcn_fail(KPCN_ERR_UNSUPPORTED,
                     "integrator.type: unsupported integrator '%s' (path_tracer)",
                     type ? type : "(missing)");
  KPCN_TRY(get_int(ij, "min_bounces", "integrator", &s->min_bounces, 0, 100000));
  KPCN_TRY(get_int(ij, "max_bounces", "integrator", &s->max_bounces, 0, 100000));
  KPCN_TRY(get_bool(ij, "enable_light_sampling", "integrator", &s->light_sampling));
  KPCN_TRY(require_bool(ij, "enable_two_sided_shading", "integrator", 1));
  int dummy = 1;
  KPCN_TRY(get_bool(ij, "enable_volume_light_sampling", "integrator", &dummy));
  KPCN_TRY(get_bool(ij, "enable_consistency_checks", "integrator", &dummy));
  return KPCN_OK;
}

static kpcn_status parse_renderer(kpcn_scene *s, const cJSON *rj) {
  s->spp = 32; /* Tungsten's RendererSettings default (it was 64) */
  if (!rj) return KPCN_OK;
  if (!cJSON_IsObject(rj)) return kpcn_fail(KPCN_ERR_FORMAT, "renderer: expected an object");
  /* Everything but spp concerns Tungsten's own output/scheduling; accepted, without effect. */
  static const char *known[] = {"spp",
                                "output_file",
                                "hdr_output_file",
                                "resume_render_file",
                                "overwrite_output_files",
                                "adaptive_sampling",
                                "enable_resume_render",
                                "stratified_sampler",
                                "scene_bvh",
                                "spp_step",
                                "checkpoint_interval",
                                "timeout",
                                "output_buffers",
                                NULL};
  KPCN_TRY(check_fields(rj, "renderer", known));
  /* checkpoint_interval was an integer in older Tungsten versions, a duration string later */
  static const kpcn_typed_field typed[] = {
      {"output_file", JT_STR, "a file name"},
      {"hdr_output_file", JT_STR, "a file name"},
      {"resume_render_file", JT_STR, "a file name"},
      {"overwrite_output_files", JT_BOOL, "true or false"},
      {"adaptive_sampling", JT_BOOL, "true or false"},
      {"enable_resume_render", JT_BOOL, "true or false"},
      {"stratified_sampler", JT_BOOL, "true or false"},
      {"scene_bvh", JT_BOOL, "true or false"},
      {"spp_step", JT_NUM, "a number"},
      {"checkpoint_interval", JT_STR | JT_NUM, "a duration string or a number"},
      {"timeout", JT_STR | JT_NUM, "a duration string or a number"},
      {"output_buffers", JT_ARR, "an array"},
      {NULL, 0, NULL}};
  KPCN_TRY(check_types(rj, "renderer", typed));
  return get_int(rj, "spp", "renderer", &s->spp, 1, 1 << 24);
}

static kpcn_status parse_document(kpcn_scene *s, const cJSON *root) {
  if (!cJSON_IsObject(root)) return kpcn_fail(KPCN_ERR_FORMAT, "(root): expected a JSON object");
  KPCN_TRY(kpcn_json_check_duplicates(root));
  static const char *known[] = {"media",      "bsdfs",    "primitives", "camera",
                                "integrator", "renderer", NULL};
  KPCN_TRY(check_fields(root, "(root)", known));
  const cJSON *media = cJSON_GetObjectItemCaseSensitive(root, "media");
  if (media && !cJSON_IsArray(media))
    return kpcn_fail(KPCN_ERR_FORMAT, "media: expected an array (of media)");
  if (media && cJSON_GetArraySize(media) != 0)
    return kpcn_fail(KPCN_ERR_UNSUPPORTED, "media: participating media are not supported");
  KPCN_TRY(kpcn_material_lib_create(s->base_dir, &s->mats));
  const cJSON *bsdfs = cJSON_GetObjectItemCaseSensitive(root, "bsdfs");
  if (bsdfs && !cJSON_IsArray(bsdfs)) return kpcn_fail(KPCN_ERR_FORMAT, "bsdfs: expected an array");
  KPCN_TRY(kpcn_material_lib_parse_bsdfs(s->mats, bsdfs, "bsdfs"));
  const cJSON *prims = cJSON_GetObjectItemCaseSensitive(root, "primitives");
  if (!cJSON_IsArray(prims))
    return kpcn_fail(KPCN_ERR_FORMAT, "primitives: missing or not an array");
  int n = cJSON_GetArraySize(prims);
  s->prims = kpcn_calloc((size_t)n + 1, sizeof(kpcn_prim), "primitives");
  if (!s->prims) return KPCN_ERR_OUT_OF_MEMORY;
  int i = 0;
  for (const cJSON *pj = prims->child; pj; pj = pj->next, i++)
    KPCN_TRY(parse_primitive(s, pj, i));
  KPCN_TRY(parse_camera(s, cJSON_GetObjectItemCaseSensitive(root, "camera")));
  KPCN_TRY(parse_integrator(s, cJSON_GetObjectItemCaseSensitive(root, "integrator")));
  KPCN_TRY(parse_renderer(s, cJSON_GetObjectItemCaseSensitive(root, "renderer")));
  if (s->nprims - (s->env_prim >= 0) == 0 && s->env_prim < 0)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "primitives: the scene is empty");
  KPCN_TRY(kpcn_scene_build_embree(s));
  KPCN_TRY(kpcn_scene_build_lights(s));
  return KPCN_OK;
}

void kpcn_scene_destroy(kpcn_scene *s) {
  if (!s) return;
  kpcn_scene_release_embree(s);
  for (int i = 0; i < s->nprims; i++)
    kpcn_mesh_free(&s->prims[i].mesh);
  free(s->prims);
  free(s->geom_to_prim);
  free(s->lights);
  kpcn_distrib1d_free(&s->light_cdf);
  if (s->env) kpcn_envmap_destroy(s->env);
  if (s->mats) kpcn_material_lib_destroy(s->mats);
  free(s);
}

kpcn_status kpcn_scene_load_json(const char *text, const char *base_dir, const char *name,
                                 kpcn_scene **out) {
  if (!out) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_scene_load_json: out is NULL");
  *out = NULL;
  if (!text) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_scene_load_json: json_text is NULL");
  if (!name) name = "<memory>";
  /* require_null_terminated: text after the document ("{...} garbage") is an error, not
   * ignored */
  /* the error position comes from this call's own return_parse_end: cJSON_GetErrorPtr() is
   * one process-wide variable, which another thread's parse resets or overwrites (a pointer
   * into that thread's text: the line count below then read far past this one) */
  const char *err = NULL;
  cJSON *root = cJSON_ParseWithOpts(text, &err, 1);
  if (!root) {
    long off = err ? (long)(err - text) : -1;
    int line = 1;
    for (long k = 0; k < off; k++)
      line += text[k] == '\n';
    /* say so when the document itself was complete (error path only: parsed once more) */
    cJSON *prefix = cJSON_ParseWithOpts(text, NULL, 0);
    cJSON_Delete(prefix);
    /* or when cJSON stopped at its nesting limit, which its error pointer does not tell */
    int depth = 0, in_string = 0;
    for (long k = 0; k < off; k++) {
      const char ch = text[k];
      if (in_string)
        in_string = ch == '\\' ? (k++, 1) : ch != '"';
      else if (ch == '"')
        in_string = 1;
      else
        depth += (ch == '[' || ch == '{') - (ch == ']' || ch == '}');
    }
    char why[96] = "";
    if (prefix)
      snprintf(why, sizeof why, ": text after the end of the document");
    else if (depth >= CJSON_NESTING_LIMIT)
      snprintf(why, sizeof why, ": arrays and objects nested deeper than %d levels",
               CJSON_NESTING_LIMIT);
    return kpcn_fail(KPCN_ERR_FORMAT, "scene '%s': invalid JSON near line %d (byte %ld)%s", name,
                     line, off, why);
  }
  const size_t max_dir = sizeof(((kpcn_scene *)0)->base_dir) - 1;
  if (base_dir && strlen(base_dir) > max_dir) {
    cJSON_Delete(root);
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "scene '%s': its folder's path is %zu bytes, longer than %zu (a shortened "
                     "one would read other files)",
                     name, strlen(base_dir), max_dir);
  }
  kpcn_scene *s = kpcn_calloc(1, sizeof(*s), "scene");
  if (!s) {
    cJSON_Delete(root);
    return KPCN_ERR_OUT_OF_MEMORY;
  }
  s->env_prim = -1;
  s->env_light = -1;
  snprintf(s->name, sizeof(s->name), "%s", name);
  snprintf(s->base_dir, sizeof(s->base_dir), "%s", base_dir ? base_dir : "");
  kpcn_status st = parse_document(s, root);
  cJSON_Delete(root);
  if (st != KPCN_OK) {
    kpcn_fail_context("scene '%s'", name);
    kpcn_scene_destroy(s);
    return st;
  }
  *out = s;
  return KPCN_OK;
}

kpcn_status kpcn_scene_load(const char *path, kpcn_scene **out) {
  if (!out || !path) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_scene_load: NULL argument");
  *out = NULL;
  const char *why;
  FILE *f = kpcn_fopen_input(path, &why);
  if (!f) return kpcn_fail(KPCN_ERR_IO, "cannot open scene '%s': %s", path, why);
  fseek(f, 0, SEEK_END);
  long n = ftell(f);
  fseek(f, 0, SEEK_SET);
  if (n < 0 || n > (1L << 30)) {
    fclose(f);
    return kpcn_fail(KPCN_ERR_IO, "cannot read scene '%s'", path);
  }
  char *text = kpcn_alloc((size_t)n + 1, "scene text");
  if (!text) {
    fclose(f);
    return KPCN_ERR_OUT_OF_MEMORY;
  }
  size_t got = fread(text, 1, (size_t)n, f);
  fclose(f);
  text[got] = 0;
  /* the parser stops at a NUL byte: what follows it would be ignored unseen */
  const char *nul = memchr(text, 0, got);
  if (nul) {
    long off = (long)(nul - text);
    free(text);
    return kpcn_fail(KPCN_ERR_FORMAT, "scene '%s': NUL byte at byte %ld (not a JSON text)", path,
                     off);
  }
  char dir[4096];
  if (strlen(path) >= sizeof(dir)) {
    free(text);
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "scene path of %zu bytes is longer than %zu",
                     strlen(path), sizeof(dir) - 1);
  }
  snprintf(dir, sizeof(dir), "%s", path);
  char *slash = strrchr(dir, '/');
  if (slash)
    slash[slash == dir] = 0; /* "/scene.json" is in "/", not in the working directory */
  else
    dir[0] = 0;
  kpcn_status st = kpcn_scene_load_json(text, dir, path, out);
  free(text);
  return st;
}

kpcn_status kpcn_scene_get_info(const kpcn_scene *s, kpcn_scene_info *info) {
  if (!s || !info)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_scene_get_info: NULL argument");
  memset(info, 0, sizeof(*info));
  info->width = s->cam.width;
  info->height = s->cam.height;
  info->spp = s->spp;
  info->min_bounces = s->min_bounces;
  info->max_bounces = s->max_bounces;
  info->light_sampling = s->light_sampling;
  info->nprimitives = s->nprims;
  info->nlights = s->nlights;
  info->ntriangles = s->ntriangles;
  info->fov_deg = s->cam.fov_deg;
  snprintf(info->camera, sizeof(info->camera), "%s", s->cam.thinlens ? "thinlens" : "pinhole");
  static const char *fn[] = {"box", "tent", "gaussian"};
  snprintf(info->filter, sizeof(info->filter), "%s", fn[s->cam.filter]);
  snprintf(info->name, sizeof(info->name), "%s", s->name);
  return KPCN_OK;
}
