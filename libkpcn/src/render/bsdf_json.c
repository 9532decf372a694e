/* Tungsten-format JSON for bsdfs and textures (see bsdf.h, texture.h, docs/materials.md).
 * Every field a type does not know is an error naming its JSON path: a scene must never render
 * with a silently ignored parameter. */
#define _POSIX_C_SOURCE 200809L
#include "render/bsdf.h"

#include "core/internal.h"
#include "render/fresnel.h"
#include "render/microfacet.h"

#include <cjson/cJSON.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct named_bsdf {
  char *name;
  const cJSON *node;
  char path[64];
  int state; /* 0 pending, 1 being parsed (cycle guard), 2 done */
  const kpcn_bsdf *bsdf;
} named_bsdf;

struct kpcn_material_lib {
  char *scene_dir;
  kpcn_texture_cache *tex;
  named_bsdf *named;
  int nnamed;
  kpcn_bsdf **owned;
  int nowned, capowned;
};

kpcn_status kpcn_material_lib_create(const char *scene_dir, kpcn_material_lib **out) {
  if (!out) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_material_lib_create: out is NULL");
  *out = NULL;
  kpcn_material_lib *lib = kpcn_calloc(1, sizeof(*lib), "material library");
  if (!lib) return KPCN_ERR_OUT_OF_MEMORY;
  lib->scene_dir = strdup(scene_dir ? scene_dir : "");
  kpcn_status s = lib->scene_dir
                      ? kpcn_texture_cache_create(&lib->tex)
                      : kpcn_fail(KPCN_ERR_OUT_OF_MEMORY, "material library: out of memory");
  if (s != KPCN_OK) {
    kpcn_material_lib_destroy(lib);
    return s;
  }
  *out = lib;
  return KPCN_OK;
}

void kpcn_material_lib_destroy(kpcn_material_lib *lib) {
  if (!lib) return;
  for (int i = 0; i < lib->nowned; ++i)
    kpcn_bsdf_destroy(lib->owned[i]);
  free(lib->owned);
  for (int i = 0; i < lib->nnamed; ++i)
    free(lib->named[i].name);
  free(lib->named);
  kpcn_texture_cache_destroy(lib->tex);
  free(lib->scene_dir);
  free(lib);
}

kpcn_texture_cache *kpcn_material_lib_textures(kpcn_material_lib *lib) { return lib->tex; }

kpcn_status kpcn_material_lib_adopt(kpcn_material_lib *lib, kpcn_bsdf *b) {
  if (lib->nowned == lib->capowned) {
    int cap = lib->capowned ? 2 * lib->capowned : 16;
    kpcn_bsdf **p = realloc(lib->owned, sizeof(*p) * (size_t)cap);
    if (!p) {
      kpcn_bsdf_destroy(b);
      return kpcn_fail(KPCN_ERR_OUT_OF_MEMORY, "material library: out of memory");
    }
    lib->owned = p;
    lib->capowned = cap;
  }
  lib->owned[lib->nowned++] = b;
  return KPCN_OK;
}

const kpcn_bsdf *kpcn_material_lib_find(const kpcn_material_lib *lib, const char *name) {
  for (int i = 0; i < lib->nnamed; ++i)
    if (lib->named[i].state == 2 && strcmp(lib->named[i].name, name) == 0)
      return lib->named[i].bsdf;
  return NULL;
}

/* ---- small JSON helpers ---- */

/* Numbers are checked as the floats they become: a finite double such as 1e39 is Inf as a
 * float (an albedo or checker colour of 1e39 reached the integrator as Inf). */
static kpcn_status json_float(const cJSON *v, const char *path, const char *key, float *out) {
  if (!cJSON_IsNumber(v)) return kpcn_fail(KPCN_ERR_FORMAT, "%s.%s: expected a number", path, key);
  double d = v->valuedouble;
  if (!isfinite((float)d))
    return kpcn_fail(KPCN_ERR_NONFINITE, "%s.%s: non-finite number (as a float)", path, key);
  *out = (float)d;
  return KPCN_OK;
}

/* A number (broadcast) or [x, y, z], as Tungsten's Vec3 fields accept. */
static kpcn_status json_vec3(const cJSON *v, const char *path, const char *key, kpcn_vec3 *out) {
  if (cJSON_IsNumber(v)) {
    float f = 0.0f;
    KPCN_TRY(json_float(v, path, key, &f));
    *out = kv3s(f);
    return KPCN_OK;
  }
  if (cJSON_IsArray(v) && (cJSON_GetArraySize(v) == 3 || cJSON_GetArraySize(v) == 1)) {
    int n = cJSON_GetArraySize(v);
    float c[3];
    for (int i = 0; i < n; ++i) {
      const cJSON *e = cJSON_GetArrayItem(v, i);
      if (!cJSON_IsNumber(e) || !isfinite((float)e->valuedouble))
        return kpcn_fail(KPCN_ERR_FORMAT, "%s.%s[%d]: expected a finite number", path, key, i);
      c[i] = (float)e->valuedouble;
    }
    *out = n == 3 ? kv3(c[0], c[1], c[2]) : kv3s(c[0]);
    return KPCN_OK;
  }
  return kpcn_fail(KPCN_ERR_FORMAT, "%s.%s: expected a number or an array of 3 numbers", path, key);
}

/* A JSON bool only: a number (7) used to read as true, so a typo changed the material. */
static kpcn_status json_bool(const cJSON *v, const char *path, const char *key, int *out) {
  if (!cJSON_IsBool(v))
    return kpcn_fail(KPCN_ERR_FORMAT, "%s.%s: expected true or false", path, key);
  *out = cJSON_IsTrue(v) ? 1 : 0;
  return KPCN_OK;
}

static kpcn_status json_int(const cJSON *v, const char *path, const char *key, int *out) {
  if (!cJSON_IsNumber(v) || v->valuedouble != floor(v->valuedouble) || fabs(v->valuedouble) > 1e9)
    return kpcn_fail(KPCN_ERR_FORMAT, "%s.%s: expected an integer", path, key);
  *out = (int)v->valuedouble;
  return KPCN_OK;
}

static int key_in(const char *k, const char *const *allowed) {
  for (; *allowed; ++allowed)
    if (strcmp(k, *allowed) == 0) return 1;
  return 0;
}

static kpcn_status check_keys(const cJSON *obj, const char *path, const char *what,
                              const char *const *allowed) {
  for (const cJSON *c = obj->child; c; c = c->next) {
    if (!c->string) continue;
    if (!key_in(c->string, allowed))
      return kpcn_fail(KPCN_ERR_UNSUPPORTED, "%s.%s: unsupported field for %s", path, c->string,
                       what);
  }
  return KPCN_OK;
}

/* ---- textures ---- */

kpcn_status kpcn_texture_parse(kpcn_material_lib *lib, const cJSON *node, const char *path,
                               int scalar, const kpcn_texture **out) {
  if (!lib || !node || !out) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s: NULL texture", path);
  if (cJSON_IsNumber(node) || cJSON_IsArray(node)) {
    kpcn_vec3 v;
    /* json_vec3 names path.key: the last component of path is the key (bsdf.albedo[1], not
     * bsdf.albedo.value[1], a key the file does not have) */
    const char *dot = strrchr(path, '.');
    char parent[256];
    snprintf(parent, sizeof parent, "%.*s", dot ? (int)(dot - path) : 0, path);
    KPCN_TRY(json_vec3(node, dot ? parent : "", dot ? dot + 1 : path, &v));
    return kpcn_texture_constant(lib->tex, v, out);
  }
  kpcn_bitmap_options opt;
  kpcn_bitmap_options_defaults(&opt);
  opt.scalar = scalar;
  const char *file = NULL;
  if (cJSON_IsString(node)) {
    file = node->valuestring;
  } else if (cJSON_IsObject(node)) {
    const cJSON *t = cJSON_GetObjectItemCaseSensitive(node, "type");
    if (!cJSON_IsString(t))
      return kpcn_fail(KPCN_ERR_FORMAT, "%s.type: missing or not a string", path);
    const char *type = t->valuestring;
    if (strcmp(type, "constant") == 0) {
      static const char *const keys[] = {"type", "value", NULL};
      KPCN_TRY(check_keys(node, path, "constant texture", keys));
      kpcn_vec3 v = kv3s(0.0f); /* Tungsten's ConstantTexture() (it was 1) */
      const cJSON *val = cJSON_GetObjectItemCaseSensitive(node, "value");
      if (val) KPCN_TRY(json_vec3(val, path, "value", &v));
      return kpcn_texture_constant(lib->tex, v, out);
    }
    if (strcmp(type, "checker") == 0) {
      static const char *const keys[] = {"type", "on_color", "off_color", "res_u", "res_v", NULL};
      KPCN_TRY(check_keys(node, path, "checker texture", keys));
      kpcn_vec3 on = kv3s(0.8f), off = kv3s(0.2f); /* Tungsten's defaults */
      int ru = 20, rv = 20;
      const cJSON *f;
      if ((f = cJSON_GetObjectItemCaseSensitive(node, "on_color")))
        KPCN_TRY(json_vec3(f, path, "on_color", &on));
      if ((f = cJSON_GetObjectItemCaseSensitive(node, "off_color")))
        KPCN_TRY(json_vec3(f, path, "off_color", &off));
      if ((f = cJSON_GetObjectItemCaseSensitive(node, "res_u")))
        KPCN_TRY(json_int(f, path, "res_u", &ru));
      if ((f = cJSON_GetObjectItemCaseSensitive(node, "res_v")))
        KPCN_TRY(json_int(f, path, "res_v", &rv));
      if (ru < 1 || rv < 1)
        return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s: res_u/res_v must be >= 1 (got %d, %d)",
                         path, ru, rv);
      return kpcn_texture_checker(lib->tex, on, off, ru, rv, out);
    }
    if (strcmp(type, "bitmap") == 0) {
      static const char *const keys[] = {"type",  "file", "gamma_correct", "interpolate", "clamp",
                                         "scale", NULL};
      KPCN_TRY(check_keys(node, path, "bitmap texture", keys));
      const cJSON *f = cJSON_GetObjectItemCaseSensitive(node, "file");
      if (!cJSON_IsString(f))
        return kpcn_fail(KPCN_ERR_FORMAT, "%s.file: missing or not a string", path);
      file = f->valuestring;
      if ((f = cJSON_GetObjectItemCaseSensitive(node, "gamma_correct")))
        KPCN_TRY(json_bool(f, path, "gamma_correct", &opt.gamma_correct));
      if ((f = cJSON_GetObjectItemCaseSensitive(node, "interpolate")))
        KPCN_TRY(json_bool(f, path, "interpolate", &opt.interpolate));
      if ((f = cJSON_GetObjectItemCaseSensitive(node, "clamp")))
        KPCN_TRY(json_bool(f, path, "clamp", &opt.clamp));
      if ((f = cJSON_GetObjectItemCaseSensitive(node, "scale"))) {
        KPCN_TRY(json_float(f, path, "scale", &opt.scale));
        if (opt.scale < 0.0f) /* would make every texel negative */
          return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s.scale: %g is negative", path,
                           (double)opt.scale);
      }
    } else {
      return kpcn_fail(KPCN_ERR_UNSUPPORTED, "%s.type: unsupported texture type '%s'", path, type);
    }
  } else {
    return kpcn_fail(KPCN_ERR_FORMAT,
                     "%s: expected a number, [r,g,b], a file name or a texture object", path);
  }
  if (!file[0]) return kpcn_fail(KPCN_ERR_FORMAT, "%s: empty texture file name", path);
  char full[8192];
  if (!kpcn_path_join(full, sizeof(full), lib->scene_dir, file))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s: the texture path is longer than %zu bytes",
                     path, sizeof(full) - 1);
  kpcn_status s = kpcn_texture_bitmap(lib->tex, full, &opt, out);
  if (s != KPCN_OK) return kpcn_fail_context("%s", path);
  return KPCN_OK;
}

/* ---- bsdfs ---- */

static kpcn_status parse_named(kpcn_material_lib *lib, named_bsdf *nb);

static kpcn_status lookup_name(kpcn_material_lib *lib, const char *name, const char *path,
                               const kpcn_bsdf **out) {
  for (int i = 0; i < lib->nnamed; ++i) {
    named_bsdf *nb = &lib->named[i];
    if (strcmp(nb->name, name) != 0) continue;
    if (nb->state == 1)
      return kpcn_fail(KPCN_ERR_FORMAT, "%s: bsdf '%s' refers to itself (cycle)", path, name);
    if (nb->state == 0) KPCN_TRY(parse_named(lib, nb));
    *out = nb->bsdf;
    return KPCN_OK;
  }
  return kpcn_fail(KPCN_ERR_FORMAT, "%s: no bsdf named '%s' in \"bsdfs\"", path, name);
}

static kpcn_status parse_object(kpcn_material_lib *lib, const cJSON *node, const char *path,
                                const kpcn_bsdf **out) {
  const cJSON *t = cJSON_GetObjectItemCaseSensitive(node, "type");
  if (!cJSON_IsString(t))
    return kpcn_fail(KPCN_ERR_FORMAT, "%s.type: missing or not a string", path);
  kpcn_bsdf_type type = KPCN_BSDF_TYPE_COUNT;
  for (int i = 0; i < KPCN_BSDF_TYPE_COUNT; ++i)
    if (strcmp(t->valuestring, kpcn_bsdf_type_name((kpcn_bsdf_type)i)) == 0)
      type = (kpcn_bsdf_type)i;
  if (type == KPCN_BSDF_TYPE_COUNT)
    return kpcn_fail(KPCN_ERR_UNSUPPORTED, "%s.type: unsupported bsdf type '%s'", path,
                     t->valuestring);
  /* checked here too, for inline bsdfs (the "bsdfs" list checks its own names) */
  const cJSON *nm = cJSON_GetObjectItemCaseSensitive(node, "name");
  if (nm && !cJSON_IsString(nm)) return kpcn_fail(KPCN_ERR_FORMAT, "%s.name: not a string", path);

  /* fields per type; "name", "type", "albedo" are common (Tungsten's Bsdf base) */
  static const char *const k_plain[] = {"name", "type", "albedo", NULL};
  static const char *const k_cond[] = {"name", "type", "albedo", "material", "eta", "k", NULL};
  static const char *const k_rcond[] = {"name", "type",         "albedo",    "material", "eta",
                                        "k",    "distribution", "roughness", NULL};
  static const char *const k_diel[] = {"name", "type", "albedo", "ior", "enable_refraction", NULL};
  static const char *const k_rdiel[] = {
      "name", "type", "albedo", "ior", "enable_refraction", "distribution", "roughness", NULL};
  static const char *const k_plas[] = {"name",      "type",    "albedo", "ior",
                                       "thickness", "sigma_a", NULL};
  static const char *const k_rplas[] = {"name",    "type",         "albedo",    "ior", "thickness",
                                        "sigma_a", "distribution", "roughness", NULL};
  static const char *const k_coat[] = {"name",      "type",    "albedo",    "ior",
                                       "thickness", "sigma_a", "substrate", NULL};
  const char *const *keys = k_plain;
  switch (type) {
  case KPCN_BSDF_CONDUCTOR: keys = k_cond; break;
  case KPCN_BSDF_ROUGH_CONDUCTOR: keys = k_rcond; break;
  case KPCN_BSDF_DIELECTRIC: keys = k_diel; break;
  case KPCN_BSDF_ROUGH_DIELECTRIC: keys = k_rdiel; break;
  case KPCN_BSDF_PLASTIC: keys = k_plas; break;
  case KPCN_BSDF_ROUGH_PLASTIC: keys = k_rplas; break;
  case KPCN_BSDF_SMOOTH_COAT: keys = k_coat; break;
  default: break;
  }
  KPCN_TRY(check_keys(node, path, t->valuestring, keys));

  kpcn_bsdf_params p;
  kpcn_bsdf_params_defaults(&p, type);
  char sub[512];
  const cJSON *f;
  if ((f = cJSON_GetObjectItemCaseSensitive(node, "albedo"))) {
    snprintf(sub, sizeof(sub), "%s.albedo", path);
    KPCN_TRY(kpcn_texture_parse(lib, f, sub, 0, &p.albedo));
    /* a reflectance below 0 is meaningless; the same rule as for emission, for constants,
     * checker colours and bitmaps alike */
    float lo, hi;
    kpcn_texture_range(p.albedo, &lo, &hi);
    if (!(lo >= 0.0f))
      return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s: negative albedo %g (must be >= 0)", sub,
                       (double)lo);
  }
  if ((f = cJSON_GetObjectItemCaseSensitive(node, "roughness"))) {
    snprintf(sub, sizeof(sub), "%s.roughness", path);
    if (cJSON_IsNumber(f))
      KPCN_TRY(json_float(f, path, "roughness", &p.roughness_value));
    else
      KPCN_TRY(kpcn_texture_parse(lib, f, sub, 1, &p.roughness));
    float lo = p.roughness_value, hi = p.roughness_value;
    if (p.roughness) kpcn_texture_range(p.roughness, &lo, &hi);
    if (lo < 0.0f)
      return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s.roughness: %g must be >= 0", path,
                       (double)lo);
    /* alpha^2 and the distributions' powers of it must stay finite (1e20 rendered NaN) */
    if (hi > 1e4f)
      return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s.roughness: %g is above 1e4", path,
                       (double)hi);
    /* one value per lookup: an RGB roughness was read as its red alone */
    const kpcn_texture *r = p.roughness;
    const kpcn_vec3 c0 = r && r->type == KPCN_TEX_CHECKER ? r->on_color
                         : r                              ? r->value
                                                          : kv3s(0),
                    c1 = r && r->type == KPCN_TEX_CHECKER ? r->off_color : c0;
    if (r && r->type != KPCN_TEX_BITMAP &&
        !(c0.x == c0.y && c0.y == c0.z && c1.x == c1.y && c1.y == c1.z))
      return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                       "%s.roughness: a colour (%g, %g, %g) is not one roughness: give a number",
                       path, (double)c0.x, (double)c0.y, (double)c0.z);
  }
  if ((f = cJSON_GetObjectItemCaseSensitive(node, "distribution"))) {
    if (!cJSON_IsString(f) || !kpcn_mf_from_name(f->valuestring, &p.distribution))
      return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                       "%s.distribution: unknown value '%s' (expected beckmann, ggx or phong)",
                       path, cJSON_IsString(f) ? f->valuestring : "<not a string>");
  }
  const cJSON *eta = cJSON_GetObjectItemCaseSensitive(node, "eta");
  const cJSON *k = cJSON_GetObjectItemCaseSensitive(node, "k");
  if ((eta != NULL) != (k != NULL))
    return kpcn_fail(KPCN_ERR_FORMAT, "%s.%s: \"eta\" and \"k\" must be given together", path,
                     eta ? "eta" : "k");
  if (eta) {
    KPCN_TRY(json_vec3(eta, path, "eta", &p.eta));
    KPCN_TRY(json_vec3(k, path, "k", &p.k));
  }
  if ((f = cJSON_GetObjectItemCaseSensitive(node, "material"))) {
    if (eta) /* Tungsten lets the name win without a word; here that would ignore a field */
      return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                       "%s.material: give a conductor name or \"eta\" and \"k\", not both", path);
    if (!cJSON_IsString(f) || !kpcn_conductor_lookup(f->valuestring, &p.eta, &p.k))
      return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s.material: unknown conductor '%s'", path,
                       cJSON_IsString(f) ? f->valuestring : "<not a string>");
  }
  if ((f = cJSON_GetObjectItemCaseSensitive(node, "ior"))) {
    KPCN_TRY(json_float(f, path, "ior", &p.ior));
    /* 1/ior must be a normal float (1e-40 flushed to Inf, and rendered NaN) */
    if (!(p.ior >= 1e-4f && p.ior <= 1e4f))
      return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s.ior: %g is outside [1e-4, 1e4]", path,
                       (double)p.ior);
  }
  if ((f = cJSON_GetObjectItemCaseSensitive(node, "enable_refraction")))
    KPCN_TRY(json_bool(f, path, "enable_refraction", &p.enable_refraction));
  if ((f = cJSON_GetObjectItemCaseSensitive(node, "thickness"))) {
    KPCN_TRY(json_float(f, path, "thickness", &p.thickness));
    if (p.thickness < 0.0f)
      return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s.thickness: %g must be >= 0", path,
                       (double)p.thickness);
  }
  if ((f = cJSON_GetObjectItemCaseSensitive(node, "sigma_a"))) {
    KPCN_TRY(json_vec3(f, path, "sigma_a", &p.sigma_a));
    if (kv3_min_comp(p.sigma_a) < 0.0f)
      return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s.sigma_a: %g must be >= 0", path,
                       (double)kv3_min_comp(p.sigma_a));
  }
  if (type == KPCN_BSDF_SMOOTH_COAT) {
    /* Tungsten's smooth_coat never applies its own albedo; accept only the neutral value
     * rather than silently ignoring a colour */
    if (p.albedo && !(p.albedo->type == KPCN_TEX_CONSTANT && p.albedo->value.x == 1.0f &&
                      p.albedo->value.y == 1.0f && p.albedo->value.z == 1.0f))
      return kpcn_fail(KPCN_ERR_UNSUPPORTED,
                       "%s.albedo: smooth_coat ignores albedo (as Tungsten); only 1 is accepted, "
                       "colour the substrate instead",
                       path);
    if ((f = cJSON_GetObjectItemCaseSensitive(node, "substrate"))) {
      snprintf(sub, sizeof(sub), "%s.substrate", path);
      KPCN_TRY(kpcn_bsdf_parse(lib, f, sub, &p.substrate));
    } else {
      /* Tungsten's default substrate: a default rough_conductor (Cu, ggx, 0.1) */
      kpcn_bsdf_params dp;
      kpcn_bsdf_params_defaults(&dp, KPCN_BSDF_ROUGH_CONDUCTOR);
      kpcn_bsdf *d;
      KPCN_TRY(kpcn_bsdf_create(&dp, &d));
      KPCN_TRY(kpcn_material_lib_adopt(lib, d));
      p.substrate = d;
    }
  }
  if ((type == KPCN_BSDF_PLASTIC || type == KPCN_BSDF_ROUGH_PLASTIC) && p.albedo) {
    /* the diffuse base a / (1 - a F_dr) has a pole at 1 / F_dr (about 1.68 at ior 1.5):
     * there and beyond it rendered Inf or negative radiance */
    float lo, hi;
    kpcn_texture_range(p.albedo, &lo, &hi);
    const float fdr = kpcn_fresnel_diffuse_reflectance(p.ior);
    if (hi * fdr >= 1.0f)
      return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                       "%s.albedo: %g reaches the plastic's limit 1/F_dr = %g (ior %g), where "
                       "its diffuse term a / (1 - a F_dr) is infinite",
                       path, (double)hi, 1.0 / fdr, (double)p.ior);
  }
  kpcn_bsdf *b;
  if (kpcn_bsdf_create(&p, &b) != KPCN_OK) return kpcn_fail_context("%s", path);
  KPCN_TRY(kpcn_material_lib_adopt(lib, b));
  *out = b;
  return KPCN_OK;
}

static kpcn_status parse_named(kpcn_material_lib *lib, named_bsdf *nb) {
  nb->state = 1;
  kpcn_status s = parse_object(lib, nb->node, nb->path, &nb->bsdf);
  nb->state = s == KPCN_OK ? 2 : 0;
  return s;
}

kpcn_status kpcn_bsdf_parse(kpcn_material_lib *lib, const cJSON *node, const char *path,
                            const kpcn_bsdf **out) {
  if (!lib || !out || !path)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_bsdf_parse: NULL argument");
  if (!node) return kpcn_fail(KPCN_ERR_FORMAT, "%s: missing bsdf", path);
  if (cJSON_IsString(node)) return lookup_name(lib, node->valuestring, path, out);
  if (cJSON_IsObject(node)) return parse_object(lib, node, path, out);
  if (cJSON_IsArray(node)) /* Tungsten's per-material-group meshes */
    return kpcn_fail(KPCN_ERR_UNSUPPORTED,
                     "%s: a list of bsdfs (one per mesh material group) is not supported: give "
                     "one bsdf name or object",
                     path);
  return kpcn_fail(KPCN_ERR_FORMAT, "%s: expected a bsdf name or a bsdf object", path);
}

static kpcn_status parse_bsdfs_impl(kpcn_material_lib *lib, const cJSON *array, const char *jp,
                                    int first);

kpcn_status kpcn_material_lib_parse_bsdfs(kpcn_material_lib *lib, const cJSON *array,
                                          const char *json_path) {
  if (!lib) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_material_lib_parse_bsdfs: NULL lib");
  if (!array) return KPCN_OK;
  int first = lib->nnamed;
  kpcn_status s = parse_bsdfs_impl(lib, array, json_path ? json_path : "bsdfs", first);
  if (s != KPCN_OK) { /* forget this array's names so the lib stays usable (bsdfs stay owned) */
    for (int i = first; i < lib->nnamed; ++i)
      free(lib->named[i].name);
    lib->nnamed = first;
  }
  return s;
}

static kpcn_status parse_bsdfs_impl(kpcn_material_lib *lib, const cJSON *array, const char *jp,
                                    int first) {
  if (!cJSON_IsArray(array)) return kpcn_fail(KPCN_ERR_FORMAT, "%s: expected an array", jp);
  int n = cJSON_GetArraySize(array);
  named_bsdf *nb = realloc(lib->named, sizeof(named_bsdf) * (size_t)(lib->nnamed + n + 1));
  if (!nb) return kpcn_fail(KPCN_ERR_OUT_OF_MEMORY, "%s: out of memory", jp);
  lib->named = nb;
  for (int i = 0; i < n; ++i) {
    const cJSON *e = cJSON_GetArrayItem(array, i);
    char path[64];
    snprintf(path, sizeof(path), "%s[%d]", jp, i);
    if (!cJSON_IsObject(e)) return kpcn_fail(KPCN_ERR_FORMAT, "%s: expected a bsdf object", path);
    const cJSON *name = cJSON_GetObjectItemCaseSensitive(e, "name");
    if (!cJSON_IsString(name) || !name->valuestring[0])
      return kpcn_fail(KPCN_ERR_FORMAT, "%s.name: missing (entries of \"%s\" need a name)", path,
                       jp);
    for (int j = 0; j < lib->nnamed; ++j)
      if (strcmp(lib->named[j].name, name->valuestring) == 0)
        return kpcn_fail(KPCN_ERR_FORMAT, "%s.name: duplicate bsdf name '%s' (also %s)", path,
                         name->valuestring, lib->named[j].path);
    named_bsdf *d = &lib->named[lib->nnamed];
    memset(d, 0, sizeof(*d));
    d->name = strdup(name->valuestring);
    if (!d->name) return kpcn_fail(KPCN_ERR_OUT_OF_MEMORY, "%s: out of memory", path);
    d->node = e;
    snprintf(d->path, sizeof(d->path), "%s", path);
    lib->nnamed++;
  }
  for (int i = first; i < lib->nnamed; ++i)
    if (lib->named[i].state == 0) KPCN_TRY(parse_named(lib, &lib->named[i]));
  return KPCN_OK;
}
