/* Pre-render augmentation (seed §3.3): random but deterministic perturbations of a
 * Tungsten scene.json — camera orbit/dolly/look-at jitter, field of view, material
 * albedo/hue, roughness, IOR, BSDF type swaps, light size/intensity/position and
 * environment rotation, albedo texture swaps. Only scene parameters change; geometry files
 * are untouched.
 * Ranges are documented in docs/dataset.md; every strength scales its ranges. */
#define _GNU_SOURCE /* realpath, strcasecmp */
#include "core/internal.h"
#include "kpcn/dataset.h"

#include <cjson/cJSON.h>
#include <dirent.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <errno.h>
#include <strings.h>
#include <sys/stat.h>

#define PI 3.14159265358979323846

void kpcn_perturb_settings_defaults(kpcn_perturb_settings *s) {
  s->camera = 1.0;
  s->fov = 1.0;
  s->material = 1.0;
  s->bsdf_swap = 0.15;
  s->light = 1.0;
  s->env = 1.0;
  s->texture_swap = 0.2;
  s->texture_dir = NULL;
  s->texture_bitmap = 0;
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
    static const char *const keys[] = {"on_color", "off_color", "color", "albedo", "value"};
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

/* Scales a number or [r,g,b] emission (or power); returns 0 for a textured one (a bitmap,
 * checker or constant object), which is left as it is: recorded datasets were made so, and
 * their recipes must plan the same scenes. The summary says so instead of claiming a factor. */
static int scale_emission(cJSON *p, const char *key, double k) {
  cJSON *e = cJSON_GetObjectItemCaseSensitive(p, key);
  double c[3];
  if (cJSON_IsNumber(e))
    set_num(p, key, e->valuedouble * k);
  else if (get_vec3(e, c)) {
    for (int i = 0; i < 3; i++)
      c[i] *= k;
    set_vec3(p, key, c);
  } else if (e) {
    return 0;
  }
  return 1;
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
  const int scaled = scale_emission(p, "emission", k) & scale_emission(p, "power", k);
  char kk[32];
  if (scaled)
    snprintf(kk, sizeof kk, "x%.2f", k);
  else
    snprintf(kk, sizeof kk, "textured, not scaled");
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
    note(sm, "light(%s,size x%.2f)", kk, sz);
  } else {
    note(sm, "light(%s)", kk);
  }
}

/* ---- texture swaps ----
 * Drawn from their own sub-stream of the (seed, variant) generator, after every other
 * perturbation: with texture_swap = 0 a variant is byte-identical to what it was before
 * texture swaps existed, and at any probability camera/material/light draws are unchanged. */

typedef struct tex_pool {
  char **files;
  int n, cap;
} tex_pool;

static int pool_add(tex_pool *p, const char *f) {
  for (int i = 0; i < p->n; i++)
    if (!strcmp(p->files[i], f)) return 1;
  if (p->n == p->cap) {
    int cap = p->cap ? 2 * p->cap : 16;
    char **nf = realloc(p->files, sizeof *nf * (size_t)cap);
    if (!nf) return 0;
    p->files = nf, p->cap = cap;
  }
  size_t l = strlen(f) + 1;
  char *c = malloc(l);
  if (!c) return 0;
  memcpy(c, f, l);
  p->files[p->n++] = c;
  return 1;
}
static void pool_free(tex_pool *p) {
  for (int i = 0; i < p->n; i++)
    free(p->files[i]);
  free(p->files);
}
static int cmp_str(const void *a, const void *b) {
  return strcmp(*(char *const *)a, *(char *const *)b);
}

/* BSDFs whose albedo is their visible surface colour; glass, coats and null keep theirs
 * (smooth_coat only accepts albedo 1 in the renderer). */
static int tex_eligible(const cJSON *b) {
  static const char *const types[] = {"lambert", "mirror",          "conductor",
                                      "plastic", "rough_conductor", "rough_plastic"};
  const cJSON *t = cJSON_GetObjectItemCaseSensitive(b, "type");
  if (!cJSON_IsString(t)) return 0;
  for (size_t i = 0; i < sizeof types / sizeof *types; i++)
    if (!strcmp(t->valuestring, types[i])) return 1;
  return 0;
}

/* The image file of an albedo: a bare file name or a {"type":"bitmap","file":...} object. */
static const char *albedo_file(const cJSON *a) {
  if (cJSON_IsString(a)) return a->valuestring[0] ? a->valuestring : NULL;
  const cJSON *t = cJSON_GetObjectItemCaseSensitive(a, "type");
  const cJSON *f = cJSON_GetObjectItemCaseSensitive(a, "file");
  if (cJSON_IsString(t) && !strcmp(t->valuestring, "bitmap") && cJSON_IsString(f) &&
      f->valuestring[0])
    return f->valuestring;
  return NULL;
}

static int gather_bitmaps(const cJSON *b, tex_pool *p) {
  if (!cJSON_IsObject(b)) return 1;
  const char *f =
      tex_eligible(b) ? albedo_file(cJSON_GetObjectItemCaseSensitive(b, "albedo")) : NULL;
  if (f && !pool_add(p, f)) return 0;
  return gather_bitmaps(cJSON_GetObjectItemCaseSensitive(b, "substrate"), p);
}

static int is_image_name(const char *n) {
  static const char *const ext[] = {".png", ".jpg", ".jpeg", ".tga", ".bmp", ".hdr", ".exr"};
  size_t l = strlen(n);
  for (size_t i = 0; i < sizeof ext / sizeof *ext; i++) {
    size_t e = strlen(ext[i]);
    if (l > e && !strcasecmp(n + l - e, ext[i])) return 1;
  }
  return 0;
}

/* Image files of a directory, absolute and sorted (readdir order is not deterministic). */
static kpcn_status load_dir_pool(const char *dir, tex_pool *p) {
  DIR *d = opendir(dir);
  if (!d)
    return kpcn_fail(KPCN_ERR_IO, "perturb: texture_dir '%s' cannot be opened: %s", dir,
                     strerror(errno));
  char *rd = realpath(dir, NULL);
  struct dirent *e;
  int ok = rd != NULL;
  while (ok && (e = readdir(d))) {
    if (e->d_name[0] == '.' || !is_image_name(e->d_name)) continue;
    size_t l = strlen(rd) + strlen(e->d_name) + 2;
    char *f = malloc(l);
    if (!f) {
      ok = 0;
      break;
    }
    snprintf(f, l, "%s/%s", rd, e->d_name);
    struct stat st;
    if (stat(f, &st) == 0 && S_ISREG(st.st_mode)) ok = pool_add(p, f);
    free(f);
  }
  closedir(d);
  free(rd);
  if (!ok)
    return kpcn_fail(KPCN_ERR_OUT_OF_MEMORY, "perturb: out of memory listing texture_dir '%s'",
                     dir);
  if (p->n == 0)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "perturb: texture_dir '%s' holds no image file (.png .jpg .jpeg .tga .bmp "
                     ".hdr .exr)",
                     dir);
  qsort(p->files, (size_t)p->n, sizeof *p->files, cmp_str);
  return KPCN_OK;
}

typedef struct tex_log {
  int nswaps, full;
  char list[200]; /* what changed, for the variant summary */
} tex_log;

/* Appends an entry; base names only, with characters that would break the JSON line the
 * summary is written into replaced. */
static void tex_log_add(tex_log *lg, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void tex_log_add(tex_log *lg, const char *fmt, ...) {
  lg->nswaps++;
  char e[128];
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(e, sizeof e, fmt, ap);
  va_end(ap);
  for (char *c = e; *c; c++)
    if (*c == '"' || *c == '\\' || (unsigned char)*c < 32 || *c == ' ') *c = '_';
  if (lg->full) return;
  size_t n = strlen(lg->list);
  if (n + strlen(e) + 6 >= sizeof lg->list) { /* keep room for ",..." */
    strcat(lg->list, n ? ",..." : "...");
    lg->full = 1;
    return;
  }
  if (n) strcat(lg->list, ",");
  strcat(lg->list, e);
}
static const char *base_name(const char *f) {
  const char *s = strrchr(f, '/');
  return s ? s + 1 : f;
}

/* A constant albedo: a number, [r,g,b] or {"type":"constant","value":...} (value 1 when
 * absent, as the renderer). */
static int albedo_constant(const cJSON *a, double c[3]) {
  if (cJSON_IsNumber(a)) {
    c[0] = c[1] = c[2] = a->valuedouble;
    return 1;
  }
  if (get_vec3(a, c)) return 1;
  const cJSON *t = cJSON_GetObjectItemCaseSensitive(a, "type");
  if (!cJSON_IsObject(a) || !cJSON_IsString(t) || strcmp(t->valuestring, "constant")) return 0;
  const cJSON *v = cJSON_GetObjectItemCaseSensitive(a, "value");
  if (!v) {
    c[0] = c[1] = c[2] = 1;
    return 1;
  }
  return albedo_constant(v, c);
}

static void swap_texture(cJSON *b, rng *r, const kpcn_perturb_settings *s, const tex_pool *pool,
                         tex_log *lg) {
  if (!cJSON_IsObject(b)) return;
  /* A fixed number of draws per BSDF, whatever happens to it. */
  double u[8];
  for (int i = 0; i < 8; i++)
    u[i] = urand(r);
  cJSON *a = cJSON_GetObjectItemCaseSensitive(b, "albedo");
  if (a && tex_eligible(b) && u[0] < s->texture_swap) {
    const char *file = albedo_file(a);
    const cJSON *ty = cJSON_GetObjectItemCaseSensitive(a, "type");
    double c[3];
    if (file) {
      /* Another image of the pool; none when the pool holds only this one. */
      int alt = 0;
      for (int i = 0; i < pool->n; i++)
        alt += strcmp(pool->files[i], file) != 0;
      if (alt > 0) {
        int k = (int)(u[1] * alt) % alt;
        const char *nf = NULL;
        for (int i = 0; i < pool->n && !nf; i++)
          if (strcmp(pool->files[i], file) && k-- == 0) nf = pool->files[i];
        tex_log_add(lg, "%s>%s", base_name(file), base_name(nf));
        if (cJSON_IsString(a))
          cJSON_ReplaceItemInObjectCaseSensitive(b, "albedo", cJSON_CreateString(nf));
        else
          cJSON_ReplaceItemInObjectCaseSensitive(a, "file", cJSON_CreateString(nf));
      }
    } else if (albedo_constant(a, c) && pool->n > 0 && u[1] < s->texture_bitmap) {
      /* An image of the pool instead (u[1] is the draw a constant leaves unused, so at
       * texture_bitmap 0 every variant is what it was before this option existed). */
      const char *nf = pool->files[(int)(u[2] * pool->n) % pool->n];
      tex_log_add(lg, "const>%s", base_name(nf));
      cJSON_ReplaceItemInObjectCaseSensitive(b, "albedo", cJSON_CreateString(nf));
    } else if (albedo_constant(a, c)) {
      /* Two colours around the constant: a brighter and a darker hue-shifted one. */
      double on[3] = {c[0], c[1], c[2]}, off[3] = {c[0], c[1], c[2]};
      perturb_rgb(on, (u[2] * 2 - 1) * PI / 3, 1, exp(u[3] * 0.6 - 0.2));
      perturb_rgb(off, (u[4] * 2 - 1) * PI, exp(u[5] * 0.8 - 0.4), exp(-0.4 - 1.2 * u[6]));
      int res = 2 + (int)(u[7] * 23); /* 2..24 checks per unit of uv */
      cJSON *ck = cJSON_CreateObject();
      cJSON_AddStringToObject(ck, "type", "checker");
      cJSON_AddItemToObject(ck, "on_color", cJSON_CreateDoubleArray(on, 3));
      cJSON_AddItemToObject(ck, "off_color", cJSON_CreateDoubleArray(off, 3));
      cJSON_AddNumberToObject(ck, "res_u", res);
      cJSON_AddNumberToObject(ck, "res_v", res);
      cJSON_ReplaceItemInObjectCaseSensitive(b, "albedo", ck);
      tex_log_add(lg, "const>checker%d", res);
    } else if (cJSON_IsString(ty) && !strcmp(ty->valuestring, "checker")) {
      /* The checker's mean colour (Tungsten's defaults 0.8/0.2 where absent), jittered. */
      double on[3] = {0.8, 0.8, 0.8}, off[3] = {0.2, 0.2, 0.2};
      get_vec3(cJSON_GetObjectItemCaseSensitive(a, "on_color"), on);
      get_vec3(cJSON_GetObjectItemCaseSensitive(a, "off_color"), off);
      double m[3];
      for (int i = 0; i < 3; i++)
        m[i] = (on[i] + off[i]) / 2;
      perturb_rgb(m, 0, 1, exp(u[2] * 0.4 - 0.2));
      set_vec3(b, "albedo", m);
      tex_log_add(lg, "checker>const");
    }
  }
  swap_texture(cJSON_GetObjectItemCaseSensitive(b, "substrate"), r, s, pool, lg);
}

static kpcn_status perturb_textures(cJSON *root, rng *r, const kpcn_perturb_settings *s,
                                    summary *sm) {
  tex_pool pool = {0};
  cJSON *b, *p, *bsdfs = cJSON_GetObjectItemCaseSensitive(root, "bsdfs"),
                *prims = cJSON_GetObjectItemCaseSensitive(root, "primitives");
  if (s->texture_dir) {
    kpcn_status st = load_dir_pool(s->texture_dir, &pool);
    if (st != KPCN_OK) {
      pool_free(&pool);
      return st;
    }
  } else {
    int ok = 1;
    cJSON_ArrayForEach(b, bsdfs) ok &= gather_bitmaps(b, &pool);
    cJSON_ArrayForEach(p, prims) ok &=
        gather_bitmaps(cJSON_GetObjectItemCaseSensitive(p, "bsdf"), &pool);
    if (!ok) {
      pool_free(&pool);
      return kpcn_fail(KPCN_ERR_OUT_OF_MEMORY, "perturb: out of memory for the texture pool");
    }
  }
  tex_log lg = {0, 0, ""};
  cJSON_ArrayForEach(b, bsdfs) swap_texture(b, r, s, &pool, &lg);
  cJSON_ArrayForEach(p, prims) {
    cJSON *ib = cJSON_GetObjectItemCaseSensitive(p, "bsdf");
    if (cJSON_IsObject(ib)) swap_texture(ib, r, s, &pool, &lg);
  }
  pool_free(&pool);
  note(sm, "textures(swaps=%d%s%s)", lg.nswaps, lg.nswaps ? ":" : "", lg.list);
  return KPCN_OK;
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
  /* the error position from this call's own end pointer (cJSON_GetErrorPtr() is one
   * process-wide variable other threads' parses change) */
  const char *e = NULL;
  cJSON *root = cJSON_ParseWithOpts(scene_json, &e, 0);
  if (!root)
    return kpcn_fail(KPCN_ERR_FORMAT, "scene JSON does not parse%s%.40s", e ? " near: " : "",
                     e ? e : "");
  if (!cJSON_IsObject(root)) {
    cJSON_Delete(root);
    return kpcn_fail(KPCN_ERR_FORMAT, "scene JSON is not an object (a scene is {...})");
  }
  if (variant > 0) {
    rng r = {seed * 0x9e3779b97f4a7c15ull ^ ((uint64_t)variant * 0xd1b54a32d192ed03ull)};
    urand(&r);
    const rng r0 = r;
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
    if (s->texture_swap > 0) {
      /* Sub-stream of the same (seed, variant) generator; see perturb_textures. */
      rng tr = {r0.s ^ 0x6a09e667f3bcc909ull};
      kpcn_status st = perturb_textures(root, &tr, s, &sm);
      if (st != KPCN_OK) {
        cJSON_Delete(root);
        if (summary_buf && summary_size) summary_buf[0] = 0;
        return st;
      }
    }
  } else {
    note(&sm, "unperturbed");
  }
  char *txt = cJSON_Print(root);
  cJSON_Delete(root);
  if (!txt) return kpcn_fail(KPCN_ERR_OUT_OF_MEMORY, "perturb: out of memory printing the JSON");
  *out_json = txt;
  return KPCN_OK;
}
