/* Environment map (Tungsten infinite_sphere): direction <-> (u,v) mapping and importance
 * sampling of a bitmap over the sphere. */
#include "render/envmap.h"

#include "core/internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

struct kpcn_envmap {
  const kpcn_texture *tex;
  float rot[9];        /* world-from-local, orthonormal columns, row-major */
  int importance;      /* distribution built (bitmap + sample) */
  kpcn_distrib2d dist; /* over (u, t = 1 - v) = image (column, row) / size */
};

kpcn_status kpcn_envmap_create(const kpcn_texture *emission, const float rot[9], int importance,
                               kpcn_envmap **out) {
  if (!emission || !out)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_envmap_create: NULL argument");
  *out = NULL;
  kpcn_envmap *e = kpcn_calloc(1, sizeof(kpcn_envmap), "environment map");
  if (!e) return KPCN_ERR_OUT_OF_MEMORY;
  e->tex = emission;
  static const float ident[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  memcpy(e->rot, rot ? rot : ident, sizeof(e->rot));
  for (int c = 0; c < 3; ++c) { /* drop any scale: normalise the columns */
    float l = sqrtf(e->rot[c] * e->rot[c] + e->rot[3 + c] * e->rot[3 + c] +
                    e->rot[6 + c] * e->rot[6 + c]);
    if (!(l > 0.0f) || !isfinite(l)) {
      free(e);
      return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                       "infinite_sphere: degenerate or non-finite rotation");
    }
    for (int r = 0; r < 3; ++r)
      e->rot[3 * r + c] /= l;
  }
  if (importance && emission->type == KPCN_TEX_BITMAP) {
    int w = emission->width, h = emission->height;
    float *lum = kpcn_alloc(sizeof(float) * (size_t)w * h, "environment weights");
    float *wgt = kpcn_alloc(sizeof(float) * (size_t)w * h, "environment weights");
    if (!lum || !wgt) {
      free(lum);
      free(wgt);
      free(e);
      return KPCN_ERR_OUT_OF_MEMORY;
    }
    for (size_t i = 0; i < (size_t)w * h; ++i) {
      const float *p = emission->texels + 3 * i;
      float m = fmaxf(p[0], fmaxf(p[1], p[2]));
      lum[i] = (m > 0.0f && isfinite(m)) ? m : 0.0f;
    }
    /* Bilinear lookups blend a texel with its 8 neighbours, so each cell's weight is the max
     * over its 3x3 neighbourhood: no direction with radiance gets pdf 0. u wraps; v wraps as
     * the lookup does unless the texture clamps (the top row's lookups blend the bottom row's
     * texels, which a clamped neighbourhood left out: radiance with pdf 0 there). */
    for (int y = 0; y < h; ++y) {
      float st = sinf(KPCN_PI * ((float)y + 0.5f) / (float)h);
      for (int x = 0; x < w; ++x) {
        float m = 0.0f;
        for (int dy = -1; dy <= 1; ++dy) {
          int yy = y + dy;
          if (!emission->clamp) yy = (yy % h + h) % h;
          if (yy < 0 || yy >= h) continue;
          for (int dx = -1; dx <= 1; ++dx) {
            int xx = ((x + dx) % w + w) % w;
            m = fmaxf(m, lum[(size_t)yy * w + xx]);
          }
        }
        wgt[(size_t)y * w + x] = m * st;
      }
    }
    free(lum);
    kpcn_status s = kpcn_distrib2d_init(&e->dist, wgt, w, h);
    free(wgt);
    if (s != KPCN_OK) {
      free(e);
      return s;
    }
    e->importance = 1;
  }
  *out = e;
  return KPCN_OK;
}

void kpcn_envmap_destroy(kpcn_envmap *e) {
  if (!e) return;
  if (e->importance) kpcn_distrib2d_free(&e->dist);
  free(e);
}

static inline kpcn_vec3 to_local(const kpcn_envmap *e, kpcn_vec3 d) {
  const float *m = e->rot; /* transpose */
  return kv3(m[0] * d.x + m[3] * d.y + m[6] * d.z, m[1] * d.x + m[4] * d.y + m[7] * d.z,
             m[2] * d.x + m[5] * d.y + m[8] * d.z);
}
static inline kpcn_vec3 to_world(const kpcn_envmap *e, kpcn_vec3 d) {
  const float *m = e->rot;
  return kv3(m[0] * d.x + m[1] * d.y + m[2] * d.z, m[3] * d.x + m[4] * d.y + m[5] * d.z,
             m[6] * d.x + m[7] * d.y + m[8] * d.z);
}

void kpcn_envmap_dir_to_uv(const kpcn_envmap *e, kpcn_vec3 dir, float *u, float *v) {
  kpcn_vec3 l = to_local(e, dir);
  float y = fminf(fmaxf(-l.y, -1.0f), 1.0f);
  *u = atan2f(l.z, l.x) * KPCN_INV_2PI + 0.5f;
  *v = acosf(y) * KPCN_INV_PI;
}

kpcn_vec3 kpcn_envmap_uv_to_dir(const kpcn_envmap *e, float u, float v) {
  float phi = (u - 0.5f) * 2.0f * KPCN_PI;
  float theta = v * KPCN_PI;
  float st = sinf(theta);
  return to_world(e, kv3(cosf(phi) * st, -cosf(theta), sinf(phi) * st));
}

kpcn_vec3 kpcn_envmap_eval(const kpcn_envmap *e, kpcn_vec3 dir) {
  if (e->tex->type == KPCN_TEX_CONSTANT) return e->tex->value;
  float u, v;
  kpcn_envmap_dir_to_uv(e, dir, &u, &v);
  return kpcn_texture_eval(e->tex, u, v);
}

float kpcn_envmap_pdf(const kpcn_envmap *e, kpcn_vec3 dir) {
  if (!e->importance) return KPCN_INV_4PI;
  kpcn_vec3 l = to_local(e, dir);
  float st = sqrtf(fmaxf(1.0f - l.y * l.y, 0.0f));
  if (!(st > 0.0f)) return 0.0f;
  float u, v;
  kpcn_envmap_dir_to_uv(e, dir, &u, &v);
  float t = 1.0f - v;
  if (u >= 1.0f) u = 0x1.fffffep-1f;
  if (t >= 1.0f) t = 0x1.fffffep-1f;
  return kpcn_distrib2d_pdf(&e->dist, u, t) / (2.0f * KPCN_PI * KPCN_PI * st);
}

int kpcn_envmap_sample(const kpcn_envmap *e, float u1, float u2, kpcn_vec3 *dir,
                       kpcn_vec3 *radiance, float *pdf) {
  if (!e->importance) {
    float z = 1.0f - 2.0f * u1;
    float r = sqrtf(fmaxf(0.0f, 1.0f - z * z));
    float phi = 2.0f * KPCN_PI * u2;
    *dir = kv3(r * cosf(phi), r * sinf(phi), z);
    *pdf = KPCN_INV_4PI;
    *radiance = kpcn_envmap_eval(e, *dir);
    return 1;
  }
  float u, t, puv;
  kpcn_distrib2d_sample(&e->dist, u1, u2, &u, &t, &puv);
  float v = 1.0f - t;
  float st = sinf(v * KPCN_PI);
  if (!(puv > 0.0f) || !(st > 0.0f)) return 0;
  *dir = kpcn_envmap_uv_to_dir(e, u, v);
  *pdf = puv / (2.0f * KPCN_PI * KPCN_PI * st);
  *radiance = kpcn_texture_eval(e->tex, u, v);
  return 1;
}
