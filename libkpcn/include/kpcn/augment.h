/* kpcn/augment.h — post-render augmentation (seed §3.4, DESIGN.md §6) and patch
 * extraction with flat-patch culling (seed §4.4).
 *
 * Every operation acts on a whole AOV set (or on any planar multi-channel buffer whose
 * channels are named) with ONE transform, so a (noisy, reference) pair stays aligned:
 * draw one kpcn_augment_xform, apply it to both.
 *
 * Channel roles are derived from canonical channel names (kpcn/image.h), so the same
 * code serves kpcn_aov_set, kpcn_image, patch-store patches and ImageBufs:
 *  - colour triple: three channels "<p>R" "<p>G" "<p>B" with the same prefix <p>, where <p>
 *    is empty or ends with '.' ("R G B", "diffuse.R ...", "ref.specular.R ..."). The colour
 *    permutation acts inside each triple. Variance channels ("color.var", ...) are averaged
 *    over RGB (seed §3.5) and therefore unchanged by a permutation.
 *  - normal: X, Y, Z of a normal buffer under any name the AOV readers accept (kpcn/image.h:
 *    "<p>N.X", "normal.X", "Denoising Normal.X", "normal.R" ...; camera space: x right, y up,
 *    z toward the camera). Mirrors negate them, rotations rotate them, colour swaps leave
 *    them alone; N.Z is untouched.
 *  - everything else (depth, visibility, variances, unknown channels) moves geometrically.
 *
 * Transform semantics (applied in this order):
 *   1. colour permutation perm: output channel c of each triple = input channel perm[c]
 *      (perm = {2,0,1} is "BRG": new R = old B, new G = old R, new B = old G);
 *   2. mirror_h: left-right flip, x' = W-1-x, N.X -> -N.X;
 *   3. mirror_v: top-bottom flip, y' = H-1-y, N.Y -> -N.Y;
 *   4. rot90: k quarter turns COUNTER-CLOCKWISE as seen on screen (image y points down):
 *      one turn maps pixel (x, y) of a W x H image to (y, W-1-x) of the H x W result and
 *      the normal (N.X, N.Y) to (-N.Y, N.X) (a vector pointing right now points up);
 *   5. shift (dx, dy): x' = x + dx, y' = y + dy with WRAP-AROUND (torus) so the size is kept
 *      and the op is exactly invertible. Use kpcn_augment_crop_aov for a seam-free shift.
 * All of 1-5 are exact (pure copies and sign flips, bit-exact inverses).
 *
 * Arbitrary angles (kpcn_augment_rotate_any) resample bilinearly. That ALTERS THE NOISE
 * STATISTICS (interpolation averages neighbouring noisy samples: lower variance, spatially
 * correlated noise), so it is not used by default; variance planes are propagated as
 * sum(w_i^2 var_i) to stay consistent with the resampled mean.
 *
 * Thread count: nthreads 0 = all cores; results never depend on it.
 */
#ifndef KPCN_AUGMENT_H
#define KPCN_AUGMENT_H

#include "kpcn/image.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct kpcn_augment_xform {
  int perm[3];  /* colour permutation, identity {0,1,2} */
  int mirror_h; /* 0/1 */
  int mirror_v; /* 0/1 */
  int rot90;    /* quarter turns counter-clockwise, 0..3 */
  int dx, dy;   /* wrap-around shift in pixels (any sign; reduced modulo the size) */
} kpcn_augment_xform;

/* Identity transform. */
void kpcn_augment_identity(kpcn_augment_xform *x);
/* Parses "RGB", "BRG", "GBR", ... (case-insensitive) into perm; error names the string. */
kpcn_status kpcn_augment_parse_perm(const char *s, int perm[3]);
/* Inverse transform: applying x then inv gives back the input bit-exactly. width x height is
 * the size of the image x applies to (the shift, any int, is reduced modulo x's output size). */
void kpcn_augment_inverse(kpcn_augment_xform *inv, const kpcn_augment_xform *x, int width,
                          int height);
/* Output size of x applied to a width x height input (rot90 odd swaps them). */
void kpcn_augment_output_size(const kpcn_augment_xform *x, int width, int height, int *out_w,
                              int *out_h);

/* Random draw settings. */
typedef enum kpcn_augment_mode {
  KPCN_AUGMENT_ALL = 0, /* each enabled op drawn independently (default) */
  KPCN_AUGMENT_ONE_OF   /* exactly one enabled op per draw, as in seed Fig. 3.3 */
} kpcn_augment_mode;

typedef struct kpcn_augment_draw_settings {
  int colorswap; /* 1: uniform over the 6 permutations */
  int mirror;    /* 1: mirror_h with probability 1/2 */
  int mirror_v;  /* 1: mirror_v with probability 1/2 (default 0; rot180 covers it) */
  int rotate;    /* 1: rot90 uniform in 0..3 */
  int max_shift; /* shift uniform in [-max_shift, max_shift] each axis; 0 = no shift */
  kpcn_augment_mode mode;
} kpcn_augment_draw_settings;

/* colorswap=1, mirror=1, mirror_v=0, rotate=1, max_shift=0, mode ALL. */
void kpcn_augment_draw_defaults(kpcn_augment_draw_settings *s);
/* Deterministic counter-based draw: the result depends only on (seed, index), never on
 * call order or threads, so patch i of epoch e can use index = e * count + i. */
void kpcn_augment_draw(kpcn_augment_xform *x, const kpcn_augment_draw_settings *s, uint64_t seed,
                       uint64_t index);

/* Applies x to nch planar channels of width x height (src: nch planes, channel c at
 * src + c*width*height). dst must hold nch planes of the output size and must not alias
 * src. names[c] gives each channel's role (see above); names may be NULL (all channels
 * geometric, no colour/normal handling). */
kpcn_status kpcn_augment_planes(float *dst, const float *src, int nch, const char *const *names,
                                int width, int height, const kpcn_augment_xform *x, int nthreads);

/* Applies x to every present buffer of an AOV set; *out is a new set (caller destroys). */
kpcn_status kpcn_augment_aov(kpcn_aov_set **out, const kpcn_aov_set *in,
                             const kpcn_augment_xform *x, int nthreads);
/* Same for an image with named channels. */
kpcn_status kpcn_augment_image(kpcn_image **out, const kpcn_image *in, const kpcn_augment_xform *x,
                               int nthreads);

/* Seam-free shift/crop: *out is the w x h window with top-left corner (x0, y0) of in. */
kpcn_status kpcn_augment_crop_aov(kpcn_aov_set **out, const kpcn_aov_set *in, int x0, int y0, int w,
                                  int h);

/* Rotation by an arbitrary angle (degrees, counter-clockwise on screen) about the image
 * centre, bilinear, same size as the input; pixels mapping outside are 0. Normals are
 * rotated and renormalised; channels whose name ends in ".var" are propagated as
 * sum(w^2 var). Alters noise statistics. */
kpcn_status kpcn_augment_rotate_any_planes(float *dst, const float *src, int nch,
                                           const char *const *names, int width, int height,
                                           double degrees, int nthreads);
kpcn_status kpcn_augment_rotate_any_aov(kpcn_aov_set **out, const kpcn_aov_set *in, double degrees,
                                        int nthreads);

/* ---- patch extraction (seed §4.4) ----
 *
 * Flat-patch culling criterion (tunable): let m be the per-channel median over the patch
 * of the colour used for culling (the reference colour when a reference is given, else
 * the noisy colour), and L(m) = (m_R + m_G + m_B) / 3. A pixel p is "near" when
 *     max_c |p_c - m_c| <= cull_tol * (L(m) + cull_abs).
 * The patch is flat, and culled, when the fraction of near pixels is >= cull.
 * Defaults cull = 0.9, cull_tol = 0.05, cull_abs = 0.01; cull > 1 disables culling.
 */
typedef struct kpcn_patch_settings {
  int size;           /* patch side, default 65 */
  int count;          /* random patches per image (default 400); 0 = regular grid */
  int stride;         /* grid stride when count == 0 (default = size) */
  uint64_t seed;      /* default 1 */
  double cull;        /* default 0.9 */
  double cull_tol;    /* default 0.05 */
  double cull_abs;    /* default 0.01 */
  int importance;     /* 1: draw candidates with probability proportional to the mean
                         noisy color.var inside the patch (plus a floor of 10% of the mean,
                         so no region is impossible); default 0 = uniform */
  int max_candidates; /* random mode: stop after this many candidates (default 8*count) */
  int nthreads;
} kpcn_patch_settings;

void kpcn_patch_settings_defaults(kpcn_patch_settings *s);

typedef struct kpcn_patch_origin {
  int x, y;        /* top-left corner in the source image */
  float flat_frac; /* fraction of near pixels (culling statistic) */
  float weight;    /* selection probability relative to uniform (1 when uniform) */
} kpcn_patch_origin;

typedef struct kpcn_patch_stats {
  int64_t candidates; /* patches examined */
  int64_t kept;
  int64_t culled; /* flat patches removed */
} kpcn_patch_stats;

/* Fraction of near pixels of the size x size window at (x0, y0) of a 3-plane colour
 * (planes r, g, b, each of row length stride); see the criterion above. */
double kpcn_patch_flat_fraction(const float *r, const float *g, const float *b, int stride, int x0,
                                int y0, int size, double cull_tol, double cull_abs);

/* Chooses patch origins in noisy (and its reference; may be NULL, must match in size):
 * *out is an allocated array of *nout origins (free with free()). Deterministic for
 * (settings, image). Requires the color buffer (and color.var if importance). */
kpcn_status kpcn_patches_select(kpcn_patch_origin **out, int *nout, kpcn_patch_stats *stats,
                                const kpcn_aov_set *noisy, const kpcn_aov_set *ref,
                                const kpcn_patch_settings *s);

#ifdef __cplusplus
}
#endif
#endif
