/* Constant, checker and bitmap textures with Tungsten's lookup rules (see texture.h). */
#define _POSIX_C_SOURCE 200809L
#include "render/texture.h"

#include "core/internal.h"
#include "kpcn/exr.h"
#include "kpcn/image.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include <stb/stb_image.h>

typedef struct tex_node {
  kpcn_texture tex;
  kpcn_bitmap_options opt; /* bitmap cache key together with tex.path */
  struct tex_node *next;
} tex_node;

struct kpcn_texture_cache {
  tex_node *head;
};

kpcn_status kpcn_texture_cache_create(kpcn_texture_cache **out) {
  if (!out) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_texture_cache_create: out is NULL");
  *out = kpcn_calloc(1, sizeof(kpcn_texture_cache), "texture cache");
  return *out ? KPCN_OK : KPCN_ERR_OUT_OF_MEMORY;
}

void kpcn_texture_cache_destroy(kpcn_texture_cache *c) {
  if (!c) return;
  tex_node *n = c->head;
  while (n) {
    tex_node *next = n->next;
    free(n->tex.texels);
    free(n->tex.path);
    free(n);
    n = next;
  }
  free(c);
}

static tex_node *new_node(kpcn_texture_cache *c) {
  tex_node *n = kpcn_calloc(1, sizeof(tex_node), "texture");
  if (!n) return NULL;
  n->tex.scale = 1.0f;
  n->tex.interpolate = 1;
  n->next = c->head;
  c->head = n;
  return n;
}

kpcn_status kpcn_texture_constant(kpcn_texture_cache *c, kpcn_vec3 value,
                                  const kpcn_texture **out) {
  if (!c || !out)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_texture_constant: NULL argument");
  if (!kv3_is_finite(value))
    return kpcn_fail(KPCN_ERR_NONFINITE, "constant texture: non-finite value");
  tex_node *n = new_node(c);
  if (!n) return KPCN_ERR_OUT_OF_MEMORY;
  n->tex.type = KPCN_TEX_CONSTANT;
  n->tex.value = value;
  n->tex.average = value;
  *out = &n->tex;
  return KPCN_OK;
}

kpcn_status kpcn_texture_checker(kpcn_texture_cache *c, kpcn_vec3 on_color, kpcn_vec3 off_color,
                                 int res_u, int res_v, const kpcn_texture **out) {
  if (!c || !out)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_texture_checker: NULL argument");
  if (res_u < 1 || res_v < 1)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "checker texture: res_u=%d res_v=%d (need >= 1)",
                     res_u, res_v);
  if (!kv3_is_finite(on_color) || !kv3_is_finite(off_color))
    return kpcn_fail(KPCN_ERR_NONFINITE, "checker texture: non-finite colour");
  tex_node *n = new_node(c);
  if (!n) return KPCN_ERR_OUT_OF_MEMORY;
  n->tex.type = KPCN_TEX_CHECKER;
  n->tex.on_color = on_color;
  n->tex.off_color = off_color;
  n->tex.res_u = res_u;
  n->tex.res_v = res_v;
  n->tex.average = kv3_scale(kv3_add(on_color, off_color), 0.5f);
  *out = &n->tex;
  return KPCN_OK;
}

void kpcn_texture_range(const kpcn_texture *t, float *lo, float *hi) {
  kpcn_vec3 a = t->value, b = t->value;
  if (t->type == KPCN_TEX_CHECKER) a = t->on_color, b = t->off_color;
  float l = fminf(kv3_min_comp(a), kv3_min_comp(b)), h = fmaxf(kv3_max_comp(a), kv3_max_comp(b));
  if (t->type == KPCN_TEX_BITMAP) {
    float tl = INFINITY, th = -INFINITY;
    for (size_t i = 0; i < 3 * (size_t)t->width * (size_t)t->height; ++i)
      tl = fminf(tl, t->texels[i]), th = fmaxf(th, t->texels[i]);
    /* lookups interpolate texels, then scale (either sign) */
    l = fminf(tl * t->scale, th * t->scale), h = fmaxf(tl * t->scale, th * t->scale);
  }
  *lo = l, *hi = h;
}

int kpcn_gamma_byte(int c) {
  if (c <= 0) return 0;
  if (c >= 255) return 255;
  /* double precision so values exactly at an integer boundary round as Tungsten's table */
  return (int)(255.0 * pow(c / 255.0, 2.2) + 1e-9);
}

void kpcn_bitmap_options_defaults(kpcn_bitmap_options *o) {
  o->gamma_correct = 1;
  o->interpolate = 1;
  o->clamp = 0;
  o->scale = 1.0f;
  o->scalar = 0;
}

static void finish_bitmap(kpcn_texture *t) {
  double acc[3] = {0, 0, 0};
  size_t np = (size_t)t->width * t->height;
  for (size_t i = 0; i < np; ++i)
    for (int ch = 0; ch < 3; ++ch)
      acc[ch] += t->texels[3 * i + ch];
  t->average =
      kv3_scale(kv3((float)(acc[0] / np), (float)(acc[1] / np), (float)(acc[2] / np)), t->scale);
}

/* EXR through the io module: channels R, G, B (or a single Y / luminance channel), linear. */
static kpcn_status load_exr(const char *path, const kpcn_bitmap_options *opt, kpcn_texture *t) {
  kpcn_image *img = NULL;
  kpcn_status s = kpcn_exr_read_image(path, &img);
  if (s != KPCN_OK) return kpcn_fail_context("texture '%s'", path);
  int ch[3] = {kpcn_image_find_channel(img, "R"), kpcn_image_find_channel(img, "G"),
               kpcn_image_find_channel(img, "B")};
  if (ch[0] < 0 || ch[1] < 0 || ch[2] < 0) {
    int y = kpcn_image_find_channel(img, "Y");
    if (y < 0) {
      kpcn_image_destroy(img);
      return kpcn_fail(KPCN_ERR_MISSING_CHANNEL, "texture '%s': no R, G, B (or Y) channels", path);
    }
    ch[0] = ch[1] = ch[2] = y;
  }
  size_t np = (size_t)img->width * img->height;
  t->texels = kpcn_alloc(np * 3 * sizeof(float), "texture texels");
  if (!t->texels) {
    kpcn_image_destroy(img);
    return KPCN_ERR_OUT_OF_MEMORY;
  }
  t->width = img->width;
  t->height = img->height;
  for (size_t i = 0; i < np; ++i) {
    float rgb[3];
    for (int c = 0; c < 3; ++c) {
      rgb[c] = kpcn_image_plane(img, ch[c])[i];
      /* a NaN or Inf texel would put NaN into every path that reads it: named, not zeroed */
      if (!isfinite(rgb[c])) {
        const int w = img->width;
        kpcn_image_destroy(img);
        free(t->texels);
        t->texels = NULL;
        return kpcn_fail(KPCN_ERR_NONFINITE, "texture '%s': non-finite value at texel (%zu, %zu)",
                         path, i % (size_t)w, i / (size_t)w);
      }
    }
    if (opt->scalar) rgb[0] = rgb[1] = rgb[2] = (rgb[0] + rgb[1] + rgb[2]) / 3.0f;
    for (int c = 0; c < 3; ++c)
      t->texels[3 * i + c] = rgb[c];
  }
  kpcn_image_destroy(img);
  return KPCN_OK;
}

static kpcn_status load_pixels(const char *path, const kpcn_bitmap_options *opt, kpcn_texture *t) {
  if (kpcn_has_extension(path, ".exr")) return load_exr(path, opt, t);
  const char *why;
  FILE *f = kpcn_fopen_input(path, &why);
  if (!f) return kpcn_fail(KPCN_ERR_IO, "texture '%s': cannot open file: %s", path, why);
  int w = 0, h = 0, ch = 0;
  int hdr = stbi_is_hdr_from_file(f);
  fseek(f, 0, SEEK_SET);
  float *px = NULL;
  unsigned char *px8 = NULL;
  if (hdr)
    px = stbi_loadf_from_file(f, &w, &h, &ch, 3);
  else
    px8 = stbi_load_from_file(f, &w, &h, &ch, 4);
  fclose(f);
  if (!px && !px8)
    return kpcn_fail(KPCN_ERR_FORMAT, "texture '%s': cannot decode image: %s", path,
                     stbi_failure_reason() ? stbi_failure_reason() : "unknown error");
  kpcn_status s = kpcn_check_size(w, h, path);
  if (s != KPCN_OK) {
    stbi_image_free(px ? (void *)px : (void *)px8);
    return s;
  }
  size_t np = (size_t)w * h;
  t->texels = kpcn_alloc(np * 3 * sizeof(float), "texture texels");
  if (!t->texels) {
    stbi_image_free(px ? (void *)px : (void *)px8);
    return KPCN_ERR_OUT_OF_MEMORY;
  }
  t->width = w;
  t->height = h;
  for (size_t i = 0; i < np; ++i) {
    float rgb[3];
    if (px) {
      for (int c = 0; c < 3; ++c)
        rgb[c] = px[3 * i + c];
      if (opt->scalar) rgb[0] = rgb[1] = rgb[2] = (rgb[0] + rgb[1] + rgb[2]) / 3.0f;
    } else if (opt->scalar) {
      /* Tungsten averages the raw bytes (integer division), without gamma correction */
      int avg = ((int)px8[4 * i] + px8[4 * i + 1] + px8[4 * i + 2]) / 3;
      rgb[0] = rgb[1] = rgb[2] = (float)avg * (1.0f / 255.0f);
    } else {
      for (int c = 0; c < 3; ++c) {
        int b = px8[4 * i + c];
        if (opt->gamma_correct) b = kpcn_gamma_byte(b);
        rgb[c] = (float)b * (1.0f / 255.0f);
      }
    }
    for (int c = 0; c < 3; ++c)
      t->texels[3 * i + c] = rgb[c];
  }
  stbi_image_free(px ? (void *)px : (void *)px8);
  return KPCN_OK;
}

kpcn_status kpcn_texture_bitmap(kpcn_texture_cache *c, const char *path,
                                const kpcn_bitmap_options *opt_in, const kpcn_texture **out) {
  if (!c || !path || !out)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_texture_bitmap: NULL argument");
  kpcn_bitmap_options opt;
  if (opt_in)
    opt = *opt_in;
  else
    kpcn_bitmap_options_defaults(&opt);
  if (!isfinite(opt.scale))
    return kpcn_fail(KPCN_ERR_NONFINITE, "texture '%s': non-finite scale", path);
  for (tex_node *n = c->head; n; n = n->next) {
    if (n->tex.type == KPCN_TEX_BITMAP && n->tex.path && strcmp(n->tex.path, path) == 0 &&
        n->opt.gamma_correct == opt.gamma_correct && n->opt.interpolate == opt.interpolate &&
        n->opt.clamp == opt.clamp && n->opt.scale == opt.scale && n->opt.scalar == opt.scalar) {
      *out = &n->tex;
      return KPCN_OK;
    }
  }
  kpcn_texture t;
  memset(&t, 0, sizeof(t));
  t.type = KPCN_TEX_BITMAP;
  t.interpolate = opt.interpolate;
  t.clamp = opt.clamp;
  t.scale = opt.scale;
  KPCN_TRY(load_pixels(path, &opt, &t));
  t.path = strdup(path);
  tex_node *n = t.path ? new_node(c) : NULL;
  if (!n) {
    free(t.texels);
    free(t.path);
    return kpcn_fail(KPCN_ERR_OUT_OF_MEMORY, "texture '%s': out of memory", path);
  }
  finish_bitmap(&t);
  n->tex = t;
  n->opt = opt;
  *out = &n->tex;
  return KPCN_OK;
}

kpcn_status kpcn_texture_from_pixels(kpcn_texture_cache *c, int width, int height, const float *rgb,
                                     const kpcn_texture **out) {
  if (!c || !rgb || !out)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_texture_from_pixels: NULL argument");
  KPCN_TRY(kpcn_check_size(width, height, "texture from pixels"));
  size_t np = (size_t)width * height;
  float *tx = kpcn_alloc(np * 3 * sizeof(float), "texture texels");
  if (!tx) return KPCN_ERR_OUT_OF_MEMORY;
  memcpy(tx, rgb, np * 3 * sizeof(float));
  tex_node *n = new_node(c);
  if (!n) {
    free(tx);
    return KPCN_ERR_OUT_OF_MEMORY;
  }
  n->tex.type = KPCN_TEX_BITMAP;
  n->tex.width = width;
  n->tex.height = height;
  n->tex.texels = tx;
  kpcn_bitmap_options_defaults(&n->opt);
  finish_bitmap(&n->tex);
  *out = &n->tex;
  return KPCN_OK;
}

static inline kpcn_vec3 texel(const kpcn_texture *t, int x, int y) {
  const float *p = t->texels + 3 * ((size_t)y * t->width + x);
  return kv3(p[0], p[1], p[2]);
}

static inline int wrap_index(int i, int n, int clamp) {
  if ((unsigned)i < (unsigned)n) return i; /* inside: no division (most lookups) */
  if (clamp) return i < 0 ? 0 : n - 1;
  i %= n;
  return i < 0 ? i + n : i;
}

/* floor for the range textures see; avoids the (int) truncation bug for negative u */
static inline int ifloor(float x) {
  int i = (int)x;
  return (x < 0.0f && (float)i != x) ? i - 1 : i;
}

kpcn_vec3 kpcn_texture_eval(const kpcn_texture *t, float u, float v) {
  switch (t->type) {
  case KPCN_TEX_CONSTANT: return t->value;
  case KPCN_TEX_CHECKER: {
    int iu = (int)(u * (float)t->res_u), iv = (int)(v * (float)t->res_v);
    return ((iu ^ iv) & 1) ? t->on_color : t->off_color;
  }
  case KPCN_TEX_BITMAP: {
    if (!(isfinite(u) && isfinite(v))) return kv3s(0.0f);
    float x = u * (float)t->width, y = (1.0f - v) * (float)t->height;
    if (t->interpolate) {
      x -= 0.5f;
      y -= 0.5f;
    }
    int x0 = ifloor(x), y0 = ifloor(y);
    float fx = x - (float)x0, fy = y - (float)y0;
    int x1 = wrap_index(x0 + 1, t->width, t->clamp), y1 = wrap_index(y0 + 1, t->height, t->clamp);
    x0 = wrap_index(x0, t->width, t->clamp);
    y0 = wrap_index(y0, t->height, t->clamp);
    if (!t->interpolate) return kv3_scale(texel(t, x0, y0), t->scale);
    kpcn_vec3 a = kv3_add(kv3_scale(texel(t, x0, y0), 1.0f - fx), kv3_scale(texel(t, x1, y0), fx));
    kpcn_vec3 b = kv3_add(kv3_scale(texel(t, x0, y1), 1.0f - fx), kv3_scale(texel(t, x1, y1), fx));
    return kv3_scale(kv3_add(kv3_scale(a, 1.0f - fy), kv3_scale(b, fy)), t->scale);
  }
  }
  return kv3s(0.0f);
}
