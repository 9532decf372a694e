/* Pre-render augmentation (seed §3.3): random but deterministic perturbations of a
 * Tungsten scene.json — camera orbit/dolly/look-at jitter, field of view, material
 * albedo/hue, roughness, IOR, BSDF type swaps, light size/intensity/position and
 * environment rotation. Only scene parameters change; geometry files are untouched.
 * Ranges are documented in docs/dataset.md; every strength scales its ranges. */
#include "core/internal.h"
#include "kpcn/dataset.h"

#include <cjson/cJSON.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define PI 3.14159265358979323846

void kpcn_perturb_settings_defaults(kpcn_perturb_settings *s) {
  s->camera = 1.0;
  s->fov = 1.0;
  s->material = 1.0;
  s->bsdf_swap = 0.15;
  s->light = 1.0;
  s->env = 1.0;
}

typedef struct rng {
  uint64_t s;
} rng;
static double urand(rng *r) {
  uint64_t z = (r->s += 0x9e3779b97f4a7c15ull);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  z ^= z >> 31;
  return (double)(z >> 11) * (1.0 / 9007199254740992.0);
}
static double uni(rng *r, double a, double b) { return a + (b - a) * urand(r); }
static double clampd(double v, double a, double b) { return v < a ? a : v > b ? b : v; }

typedef struct summary {
  char *buf;
  size_t size;
} summary;
static void note(summary *s, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void note(summary *s, const char *fmt, ...) {
  if (!s->buf || s->size == 0) return;
  size_t n = strlen(s->buf);
  if (n + 2 >= s->size) return;
  if (n) s->buf[n++] = ' ', s->buf[n] = 0;
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(s->buf + n, s->size - n, fmt, ap);
  va_end(ap);
}

static int get_vec3(const cJSON *a, double v[3]) {
  if (!cJSON_IsArray(a) || cJSON_GetArraySize(a) != 3) return 0;
  for (int i = 0; i < 3; i++) {
    const cJSON *e = cJSON_GetArrayItem(a, i);
    if (!cJSON_IsNumber(e)) return 0;
    v[i] = e->valuedouble;
  }
  return 1;
}
static void set_vec3(cJSON *obj, const char *key, const double v[3]) {
  cJSON *a = cJSON_CreateDoubleArray(v, 3);
  if (cJSON_GetObjectItemCaseSensitive(obj, key))
    cJSON_ReplaceItemInObjectCaseSensitive(obj, key, a);
  else
    cJSON_AddItemToObject(obj, key, a);
}
static void set_num(cJSON *obj, const char *key, double v) {
  cJSON *n = cJSON_CreateNumber(v);
  if (cJSON_GetObjectItemCaseSensitive(obj, key))
    cJSON_ReplaceItemInObjectCaseSensitive(obj, key, n);
  else
    cJSON_AddItemToObject(obj, key, n);
}
static void sub(double o[3], const double a[3], const double b[3]) {
  for (int i = 0; i < 3; i++)
    o[i] = a[i] - b[i];
}
static double dot(const double a[3], const double b[3]) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}
static void cross(double o[3], const double a[3], const double b[3]) {
  o[0] = a[1] * b[2] - a[2] * b[1];
  o[1] = a[2] * b[0] - a[0] * b[2];
  o[2] = a[0] * b[1] - a[1] * b[0];
}
static void normalize(double v[3]) {
  double l = sqrt(dot(v, v));
  if (l > 0)
    for (int i = 0; i < 3; i++)
      v[i] /= l;
}
/* Rodrigues rotation of v about unit axis k by angle a. */
static void rotate(double v[3], const double k[3], double a) {
  double c = cos(a), s = sin(a), kxv[3], kv = dot(k, v);
  cross(kxv, k, v);
  for (int i = 0; i < 3; i++)
    v[i] = v[i] * c + kxv[i] * s + k[i] * kv * (1 - c);
}

static void perturb_camera(cJSON *cam, rng *r, const kpcn_perturb_settings *s, summary *sm) {
  cJSON *t = cJSON_GetObjectItemCaseSensitive(cam, "transform");
  double pos[3], at[3], up[3] = {0, 1, 0};
  if (s->camera > 0 && cJSON_IsObject(t) &&
      get_vec3(cJSON_GetObjectItemCaseSensitive(t, "position"), pos) &&
      get_vec3(cJSON_GetObjectItemCaseSensitive(t, "look_at"), at)) {
    get_vec3(cJSON_GetObjectItemCaseSensitive(t, "up"), up);
    normalize(up);
    double d[3];
    sub(d, pos, at);
    double dist = sqrt(dot(d, d));
    /* Orbit: azimuth about `up` through look_at, elevation about the camera's right axis. */
    double az = uni(r, -25, 25) * s->camera * PI / 180, el = uni(r, -10, 10) * s->camera * PI / 180;
    rotate(d, up, az);
    double right[3];
    cross(right, up, d);
    normalize(right);
    double nd[3] = {d[0], d[1], d[2]};
    rotate(nd, right, el);
    /* Keep away from the pole so `up` stays a valid up vector. */
    double dn[3] = {nd[0], nd[1], nd[2]};
    normalize(dn);
    if (fabs(dot(dn, up)) < 0.97) memcpy(d, nd, sizeof d);
    double dolly = exp(uni(r, -0.2, 0.2) * s->camera);
    double jit = 0.04 * dist * s->camera;
    for (int i = 0; i < 3; i++) {
      at[i] += uni(r, -jit, jit);
      pos[i] = at[i] + d[i] * dolly;
    }
    set_vec3(t, "position", pos);
    set_vec3(t, "look_at", at);
    note(sm, "camera(az=%.1f,el=%.1f,dolly=%.3f)", az * 180 / PI, el * 180 / PI, dolly);
  }
  cJSON *fov = cJSON_GetObjectItemCaseSensitive(cam, "fov");
  if (s->fov > 0 && cJSON_IsNumber(fov)) {
    double f = clampd(fov->valuedouble * exp(uni(r, -0.25, 0.25) * s->fov), 5, 120);
    set_num(cam, "fov", f);
    note(sm, "fov=%.2f", f);
  }
}

/* Hue rotation about the grey axis (Rodrigues in RGB), then saturation/brightness jitter;
 * results stay in [0, 0.95] so materials remain energy conserving. */
static void perturb_rgb(double c[3], double hue, double sat, double gain) {
  double k[3] = {1 / sqrt(3.0), 1 / sqrt(3.0), 1 / sqrt(3.0)};
  rotate(c, k, hue);
  double m = (c[0] + c[1] + c[2]) / 3;
  for (int i = 0; i < 3; i++)
    c[i] = clampd((m + (c[i] - m) * sat) * gain, 0.0, 0.95);
}

static void perturb_albedo(cJSON *owner, const char *key, rng *r, double st) {
  cJSON *a = cJSON_GetObjectItemCaseSensitive(owner, key);
  double hue = uni(r, -PI, PI) * st, sat = exp(uni(r, -0.4, 0.4) * st),
         gain = exp(uni(r, -0.3, 0.3) * st);
  double c[3];
  if (cJSON_IsNumber(a)) {
    double v[3] = {a->valuedouble, a->valuedouble, a->valuedouble};
    /* A grey albedo gets a random tint so hue jitter has something to rotate. */
    for (int i = 0; i < 3; i++)
      v[i] *= 1 + uni(r, -0.3, 0.3) * st;
    perturb_rgb(v, hue, sat, gain);
    set_vec3(owner, key, v);
  } else if (get_vec3(a, c)) {
    perturb_rgb(c, hue, sat, gain);
    set_vec3(owner, key, c);
  } else if (cJSON_IsObject(a)) { /* procedural texture: perturb its colours */
    static const char *const keys[] = {"on_color", "off_color", "color", "albedo"};
    for (size_t i = 0; i < sizeof keys / sizeof *keys; i++)
      if (get_vec3(cJSON_GetObjectItemCaseSensitive(a, keys[i]), c)) {
        perturb_rgb(c, hue, sat, gain);
        set_vec3(a, keys[i], c);
      }
  } /* image textures (strings) are left alone */
}

static const char *const g_swap_types[] = {"lambert", "plastic", "rough_plastic", "rough_conductor",
                                           "conductor"};
static const char *const g_metals[] = {"Cu", "Au", "Ag", "Al", "Cr"};

static void perturb_bsdf(cJSON *b, rng *r, const kpcn_perturb_settings *s, summary *sm,
                         int *nswaps) {
  if (!cJSON_IsObject(b)) return;
  cJSON *type = cJSON_GetObjectItemCaseSensitive(b, "type");
  if (!cJSON_IsString(type) || !strcmp(type->valuestring, "null")) return; /* lights, portals */
  /* Draw everything up front so the number of draws per BSDF is fixed. */
  double u_swap = urand(r), u_type = urand(r), u_metal = urand(r), u_rough = urand(r);
  double st = s->material;
  int opaque = !strcmp(type->valuestring, "lambert") || !strcmp(type->valuestring, "plastic") ||
               !strcmp(type->valuestring, "rough_plastic") ||
               !strcmp(type->valuestring, "rough_conductor") ||
               !strcmp(type->valuestring, "conductor");
  /* Only opaque single-layer BSDFs swap (a glass or coated object keeps its type). */
  if (opaque && u_swap < s->bsdf_swap) {
    const char *nt = g_swap_types[(int)(u_type * 5) % 5];
    /* The renderer rejects fields a type does not know (e.g. "ior" on a conductor), so a
     * swapped BSDF keeps only its name and albedo and gets the new type's own fields. */
    for (cJSON *it = b->child; it;) {
      cJSON *next = it->next;
      if (strcmp(it->string, "name") && strcmp(it->string, "albedo"))
        cJSON_Delete(cJSON_DetachItemViaPointer(b, it));
      it = next;
    }
    cJSON_AddStringToObject(b, "type", nt);
    type = cJSON_GetObjectItemCaseSensitive(b, "type");
    if (strstr(nt, "conductor")) {
      cJSON_DeleteItemFromObjectCaseSensitive(b, "material");
      cJSON_AddStringToObject(b, "material", g_metals[(int)(u_metal * 5) % 5]);
    }
    if (!strncmp(nt, "rough", 5)) set_num(b, "roughness", 0.05 + 0.4 * u_rough);
    if (strstr(nt, "plastic") && !cJSON_GetObjectItemCaseSensitive(b, "ior"))
      set_num(b, "ior", 1.5);
    (*nswaps)++;
  }
  if (st > 0) {
    /* smooth_coat ignores its own albedo (as Tungsten): only its substrate is coloured. */
    if (strcmp(type->valuestring, "smooth_coat")) perturb_albedo(b, "albedo", r, st);
    cJSON *ro = cJSON_GetObjectItemCaseSensitive(b, "roughness");
    double f = exp(uni(r, -0.7, 0.7) * st);
    if (cJSON_IsNumber(ro)) set_num(b, "roughness", clampd(ro->valuedouble * f, 0.01, 1.0));
    cJSON *ior = cJSON_GetObjectItemCaseSensitive(b, "ior");
    double di = uni(r, -0.2, 0.2) * st;
    if (cJSON_IsNumber(ior)) set_num(b, "ior", clampd(ior->valuedouble + di, 1.05, 2.5));
    cJSON *subs = cJSON_GetObjectItemCaseSensitive(b, "substrate");
    if (cJSON_IsObject(subs)) perturb_bsdf(subs, r, s, sm, nswaps);
  }
}

static int is_emitter(const cJSON *p) {
  const cJSON *e = cJSON_GetObjectItemCaseSensitive(p, "emission");
  const cJSON *pw = cJSON_GetObjectItemCaseSensitive(p, "power");
  return e != NULL || pw != NULL;
}

static void scale_emission(cJSON *p, const char *key, double k) {
  cJSON *e = cJSON_GetObjectItemCaseSensitive(p, key);
  double c[3];
  if (cJSON_IsNumber(e))
    set_num(p, key, e->valuedouble * k);
  else if (get_vec3(e, c)) {
    for (int i = 0; i < 3; i++)
      c[i] *= k;
    set_vec3(p, key, c);
  }
}

static void perturb_light(cJSON *p, rng *r, const kpcn_perturb_settings *s, summary *sm) {
  cJSON *type = cJSON_GetObjectItemCaseSensitive(p, "type");
  int env = cJSON_IsString(type) && (!strcmp(type->valuestring, "infinite_sphere") ||
                                     !strcmp(type->valuestring, "skydome"));
  double u[6];
  for (int i = 0; i < 6; i++)
    u[i] = urand(r);
  cJSON *t = cJSON_GetObjectItemCaseSensitive(p, "transform");
  if (env) {
    if (s->env <= 0) return;
    if (!cJSON_IsObject(t)) {
      t = cJSON_CreateObject();
      cJSON_AddItemToObject(p, "transform", t);
    }
    double rot[3] = {0, 0, 0};
    get_vec3(cJSON_GetObjectItemCaseSensitive(t, "rotation"), rot);
    rot[1] = fmod(rot[1] + 360 * u[0] * s->env, 360);
    set_vec3(t, "rotation", rot);
    note(sm, "env_rot=%.1f", rot[1]);
    return;
  }
  if (s->light <= 0) return;
  double k = exp((u[1] * 1.0 - 0.5) * s->light);
  scale_emission(p, "emission", k);
  scale_emission(p, "power", k);
  if (cJSON_IsObject(t)) {
    double sz = exp((u[2] * 0.6 - 0.3) * s->light), sc[3], pos[3];
    cJSON *scale = cJSON_GetObjectItemCaseSensitive(t, "scale");
    double mag = 1;
    if (cJSON_IsNumber(scale)) {
      mag = scale->valuedouble;
      set_num(t, "scale", mag * sz);
    } else if (get_vec3(scale, sc)) {
      mag = sqrt(dot(sc, sc) / 3);
      for (int i = 0; i < 3; i++)
        sc[i] *= sz;
      set_vec3(t, "scale", sc);
    }
    /* Move in the horizontal plane by up to 10% of the light's size: keeps ceiling
     * lights on their ceiling. */
    if (get_vec3(cJSON_GetObjectItemCaseSensitive(t, "position"), pos)) {
      pos[0] += (u[3] * 2 - 1) * 0.1 * fabs(mag) * s->light;
      pos[2] += (u[4] * 2 - 1) * 0.1 * fabs(mag) * s->light;
      set_vec3(t, "position", pos);
    }
    note(sm, "light(x%.2f,size x%.2f)", k, sz);
  } else {
    note(sm, "light(x%.2f)", k);
  }
}

kpcn_status kpcn_perturb_scene(char **out_json, const char *scene_json, uint64_t seed, int variant,
                               const kpcn_perturb_settings *s, char *summary_buf,
                               size_t summary_size) {
  if (!out_json || !scene_json)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_perturb_scene: NULL argument");
  *out_json = NULL;
  if (variant < 0) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "perturb: variant %d < 0", variant);
  kpcn_perturb_settings def;
  kpcn_perturb_settings_defaults(&def);
  if (!s) s = &def;
  summary sm = {summary_buf, summary_size};
  if (summary_buf && summary_size) summary_buf[0] = 0;
  cJSON *root = cJSON_Parse(scene_json);
  if (!root || !cJSON_IsObject(root)) {
    const char *e = cJSON_GetErrorPtr();
    cJSON_Delete(root);
    return kpcn_fail(KPCN_ERR_FORMAT, "scene JSON does not parse%s%.40s", e ? " near: " : "",
                     e ? e : "");
  }
  if (variant > 0) {
    rng r = {seed * 0x9e3779b97f4a7c15ull ^ ((uint64_t)variant * 0xd1b54a32d192ed03ull)};
    urand(&r);
    cJSON *cam = cJSON_GetObjectItemCaseSensitive(root, "camera");
    if (cJSON_IsObject(cam)) perturb_camera(cam, &r, s, &sm);
    int nswaps = 0;
    cJSON *b;
    cJSON_ArrayForEach(b, cJSON_GetObjectItemCaseSensitive(root, "bsdfs")) {
      perturb_bsdf(b, &r, s, &sm, &nswaps);
    }
    cJSON *p;
    cJSON_ArrayForEach(p, cJSON_GetObjectItemCaseSensitive(root, "primitives")) {
      cJSON *ib = cJSON_GetObjectItemCaseSensitive(p, "bsdf");
      if (cJSON_IsObject(ib)) perturb_bsdf(ib, &r, s, &sm, &nswaps);
      if (is_emitter(p)) perturb_light(p, &r, s, &sm);
    }
    if (s->material > 0) note(&sm, "materials(swaps=%d)", nswaps);
  } else {
    note(&sm, "unperturbed");
  }
  char *txt = cJSON_Print(root);
  cJSON_Delete(root);
  if (!txt) return kpcn_fail(KPCN_ERR_OUT_OF_MEMORY, "perturb: printing JSON");
  *out_json = txt;
  return KPCN_OK;
}
