/* Textures with Tungsten's semantics: constant, checker, bitmap (PNG/JPEG/HDR via stb_image,
 * EXR via kpcn_exr_read_image when available).
 *
 * CONVENTIONS
 *  - Lookups take surface (u, v). Bitmaps follow Tungsten's BitmapTexture: u goes right,
 *    v goes UP (row 0 of the file is v = 1), wrap-around (repeat) addressing, bilinear
 *    interpolation between texel centres.
 *  - 8-bit files (PNG/JPEG) are decoded with gamma 2.2 when gamma_correct (Tungsten's
 *    "gamma_correct", default true); HDR/EXR are linear. "scale" multiplies every texel.
 *  - Checker: on_color where (int(u*res_u) XOR int(v*res_v)) is odd, else off_color (Tungsten
 *    CheckerTexture; int() truncates toward zero).
 *  - 8-bit gamma correction replicates Tungsten's table: linear byte = floor(255*(c/255)^2.2),
 *    so 8-bit textures are quantised exactly as Tungsten quantises them.
 *  - Scalar textures (roughness) return the first channel of the RGB lookup; a bitmap requested
 *    as scalar is averaged over RGB when loaded, before any gamma correction, as Tungsten's
 *    TexelConversion::REQUEST_AVERAGE does.
 *  - Textures are immutable after creation and thread-safe to read.
 *  - Ownership: a kpcn_texture_cache owns every texture created through it; textures are
 *    freed with the cache (kpcn_texture_cache_destroy).
 */
#ifndef KPCN_RENDER_TEXTURE_H
#define KPCN_RENDER_TEXTURE_H

#include "kpcn/common.h"
#include "render/vec3.h"

typedef enum kpcn_texture_type {
  KPCN_TEX_CONSTANT,
  KPCN_TEX_CHECKER,
  KPCN_TEX_BITMAP
} kpcn_texture_type;

typedef struct kpcn_texture {
  kpcn_texture_type type;
  kpcn_vec3 value;               /* constant */
  kpcn_vec3 on_color, off_color; /* checker */
  int res_u, res_v;              /* checker cell counts */
  /* bitmap: linear RGB, row-major, row 0 = top of the file (v = 1) */
  int width, height;
  float *texels;     /* 3 floats per texel */
  int interpolate;   /* bilinear (1) or nearest (0) */
  int clamp;         /* clamp instead of repeat */
  float scale;       /* multiplies texels (Tungsten "scale") */
  kpcn_vec3 average; /* mean texel value (or the constant / checker mean) */
  char *path;        /* resolved file path (bitmap) for messages */
} kpcn_texture;

typedef struct kpcn_texture_cache kpcn_texture_cache;

kpcn_status kpcn_texture_cache_create(kpcn_texture_cache **out);
void kpcn_texture_cache_destroy(kpcn_texture_cache *c);

/* Constant and checker textures (owned by the cache). */
kpcn_status kpcn_texture_constant(kpcn_texture_cache *c, kpcn_vec3 value, const kpcn_texture **out);
kpcn_status kpcn_texture_checker(kpcn_texture_cache *c, kpcn_vec3 on_color, kpcn_vec3 off_color,
                                 int res_u, int res_v, const kpcn_texture **out);
typedef struct kpcn_bitmap_options {
  int gamma_correct; /* default 1 */
  int interpolate;   /* default 1 */
  int clamp;         /* default 0 */
  float scale;       /* default 1 */
  int scalar;        /* 1 = average RGB at load (roughness maps); default 0 */
} kpcn_bitmap_options;
void kpcn_bitmap_options_defaults(kpcn_bitmap_options *o);
/* Loads a bitmap (PNG/JPEG/HDR/TGA/BMP via stb_image, .exr via kpcn_exr_read_image). The same
 * path with the same options is loaded once. opt NULL = defaults. Errors name the path. */
kpcn_status kpcn_texture_bitmap(kpcn_texture_cache *c, const char *path,
                                const kpcn_bitmap_options *opt, const kpcn_texture **out);
/* Wraps caller-supplied linear RGB texels (copied; row 0 = top). For tests and generated maps. */
kpcn_status kpcn_texture_from_pixels(kpcn_texture_cache *c, int width, int height, const float *rgb,
                                     const kpcn_texture **out);

/* Smallest and largest value any channel of a lookup can return (constant, both checker
 * colours, every bitmap texel times its scale): callers bound albedo and emission with it. */
void kpcn_texture_range(const kpcn_texture *t, float *lo, float *hi);

/* Lookup at (u, v). */
kpcn_vec3 kpcn_texture_eval(const kpcn_texture *t, float u, float v);
static inline float kpcn_texture_eval_scalar(const kpcn_texture *t, float u, float v) {
  return kpcn_texture_eval(t, u, v).x;
}
/* True when the texture is a constant (fast path: t->value). */
static inline int kpcn_texture_is_constant(const kpcn_texture *t) {
  return t->type == KPCN_TEX_CONSTANT;
}

/* Tungsten's 8-bit gamma table: floor(255 * (c/255)^2.2) for c in 0..255. */
int kpcn_gamma_byte(int c);

#endif
