/* kpcn/image.h — planar float images with named channels, and AOV sets.
 *
 * kpcn_image is a plain, transparent struct: data is planar float32,
 *   pixel (x, y) of channel c is data[(size_t)c * width * height + (size_t)y * width + x].
 * Create with kpcn_image_create (owns data and names), free with kpcn_image_destroy.
 *
 * kpcn_aov_set holds the buffers of DESIGN.md §4. Canonical EXR channel names:
 *
 *   buffer      channels                         variance channel (variance of the mean,
 *                                                averaged over the buffer's channels)
 *   color       R G B                            color.var
 *   diffuse     diffuse.R diffuse.G diffuse.B    diffuse.var
 *   specular    specular.R specular.G specular.B specular.var
 *   albedo      albedo.R albedo.G albedo.B       albedo.var
 *   normal      N.X N.Y N.Z                      N.var       camera space: x right, y up,
 *                                                            z toward the camera
 *   depth       Z                                Z.var       path length camera -> first
 *                                                            non-delta hit (mirrors and glass
 *                                                            followed); 0 where the ray missed
 *   visibility  visibility.V                     visibility.var
 *
 * Aliases accepted on read (see exr.h): Blender/Cycles pass names
 * (ViewLayer.Combined.*, Denoising Albedo.*, Denoising Normal.*, Denoising Depth.Z,
 * DiffCol/GlossCol ...), normal.X/Y/Z, depth.Z / depth.V.
 */
#ifndef KPCN_IMAGE_H
#define KPCN_IMAGE_H

#include "kpcn/common.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct kpcn_image {
  int width;
  int height;
  int nchannels;
  char **names; /* nchannels NUL-terminated names, owned */
  float *data;  /* planar, nchannels * width * height floats, owned */
} kpcn_image;

/* Allocates a zero-filled image. names may be NULL (channels named "0", "1", ...).
 * Rejects zero/negative or absurd sizes (KPCN_MAX_DIM, KPCN_MAX_PIXELS) and channel counts
 * outside 1 .. 4096. */
kpcn_status kpcn_image_create(kpcn_image **out, int width, int height, int nchannels,
                              const char *const *names);
void kpcn_image_destroy(kpcn_image *img);
/* Deep copy. */
kpcn_status kpcn_image_clone(kpcn_image **out, const kpcn_image *src);
/* Index of the channel named `name`, or -1. */
int kpcn_image_find_channel(const kpcn_image *img, const char *name);
/* Pointer to the plane of channel c. */
static inline float *kpcn_image_plane(const kpcn_image *img, int c) {
  return img->data + (size_t)c * (size_t)img->width * (size_t)img->height;
}

/* ---- AOV sets ---- */
typedef enum kpcn_buffer {
  KPCN_BUF_COLOR = 0,
  KPCN_BUF_DIFFUSE,
  KPCN_BUF_SPECULAR,
  KPCN_BUF_ALBEDO,
  KPCN_BUF_NORMAL,
  KPCN_BUF_DEPTH,
  KPCN_BUF_VISIBILITY,
  KPCN_BUF_COUNT
} kpcn_buffer;

/* Number of channels of a buffer (3 for color-like and normal, 1 for depth/visibility). */
int kpcn_buffer_channels(kpcn_buffer b);
/* Short name: "color", "diffuse", "specular", "albedo", "normal", "depth", "visibility". */
const char *kpcn_buffer_name(kpcn_buffer b);
/* Canonical EXR channel name of channel c of buffer b ("R", "diffuse.G", "N.Z", "Z", ...). */
const char *kpcn_buffer_channel_name(kpcn_buffer b, int c);
/* Canonical EXR name of the variance channel of buffer b ("color.var", "N.var", ...). */
const char *kpcn_buffer_variance_name(kpcn_buffer b);
/* Buffer whose short name is `name`, or -1. */
int kpcn_buffer_from_name(const char *name);
/* True for buffers whose channels are RGB colours (color, diffuse, specular, albedo). */
int kpcn_buffer_is_color(kpcn_buffer b);

typedef struct kpcn_aov_set {
  int width;
  int height;
  /* Planar buffers, kpcn_buffer_channels(b) planes each; NULL when absent. Owned. */
  float *buf[KPCN_BUF_COUNT];
  /* One plane each (variance of the mean); NULL when absent. Owned. */
  float *var[KPCN_BUF_COUNT];
  /* Header metadata (kpcn:spp, kpcn:seed, kpcn:scene, kpcn:version); spp/seed -1 if unknown. */
  int spp;
  int albedo_spp; /* kpcn:albedoSpp: samples of the albedo buffer when not spp; 0 = spp */
  /* kpcn:albedoFootprint: k when each sample's textured albedo is its pixel footprint's mean
   * over k x k points (kpcn_render_settings.albedo_footprint); 0 = point samples */
  int albedo_footprint;
  int64_t seed;
  char scene[256];
  char version[32];
} kpcn_aov_set;

/* Allocates an empty set (no buffers) of the given size; validates the size. */
kpcn_status kpcn_aov_create(kpcn_aov_set **out, int width, int height);
void kpcn_aov_destroy(kpcn_aov_set *set);
kpcn_status kpcn_aov_clone(kpcn_aov_set **out, const kpcn_aov_set *src);
/* Allocates (zero-filled) buffer b and, if with_variance, its variance plane.
 * Existing planes are kept. */
kpcn_status kpcn_aov_add(kpcn_aov_set *set, kpcn_buffer b, int with_variance);
/* Fails with KPCN_ERR_MISSING_CHANNEL naming the buffer (and `what`, e.g. a file
 * name, in the message) if buffer b -- and its variance if need_variance -- is absent. */
kpcn_status kpcn_aov_require(const kpcn_aov_set *set, kpcn_buffer b, int need_variance,
                             const char *what);
/* The same for the n buffers b[0..n-1], with one message naming every absent buffer and
 * variance ("what: missing buffer 'normal' (channels N.X N.Y N.Z, and its variance N.var),
 * variance of 'diffuse' (channel diffuse.var)"). */
kpcn_status kpcn_aov_require_list(const kpcn_aov_set *set, const kpcn_buffer *b, int n,
                                  int need_variance, const char *what);
/* Number of floats in one plane. */
static inline size_t kpcn_aov_plane_size(const kpcn_aov_set *s) {
  return (size_t)s->width * (size_t)s->height;
}

/* Converts between an AOV set and a flat image with canonical channel names
 * (only the buffers present). */
kpcn_status kpcn_aov_to_image(kpcn_image **out, const kpcn_aov_set *set);
/* Recognises canonical names and aliases; channels it does not know are ignored. */
kpcn_status kpcn_aov_from_image(kpcn_aov_set **out, const kpcn_image *img);
/* The AOV set kpcn_aov_from_image would make of an image whose `nch` channels carry these
 * names, with its planes allocated but not filled: dst[c] (nch entries) receives the plane
 * channel c belongs in, NULL where the set does not use channel c. For readers that fill the
 * planes straight from a file or another library's buffer. `what` names the source in errors
 * (a missing channel of a partly present buffer). */
kpcn_status kpcn_aov_create_for_channels(kpcn_aov_set **out, int width, int height, int nch,
                                         const char *const *names, float **dst, const char *what);

/* Maps one channel name (canonical or alias, see docs/aov-exr.md) to a buffer and a
 * channel index; *channel is -1 for the buffer's variance plane. *rank (may be NULL) is
 * 0 for canonical names and grows for less preferred aliases. Returns 1 if recognised. */
int kpcn_aov_channel_lookup(const char *name, kpcn_buffer *buffer, int *channel, int *rank);

/* Which of `n` channel names feed which AOV plane: on return chan[b][c] is the index (into
 * names) of channel c of buffer b and var[b] that of its variance, or -1 when absent.
 * A buffer is mapped only when all its channels come from one group (same name prefix);
 * among complete groups the canonical/most preferred wins. A buffer found only partially
 * (e.g. N.X, N.Y but no N.Z) fails with KPCN_ERR_MISSING_CHANNEL naming the missing
 * channel and `what` (a file name, for the message); the other buffers are still mapped. */
kpcn_status kpcn_aov_map_channels(const char *const *names, int n, int chan[KPCN_BUF_COUNT][3],
                                  int var[KPCN_BUF_COUNT], const char *what);

/* Exposure of an image: the median, over 8x8 pixel blocks, of the block's mean luminance
 * (Rec. 709 weights) of diffuse + specular, counting only blocks whose mean is finite and
 * > 0 (black background is not "dark exposure"; non-finite pixels are skipped). Block means
 * average 64 pixels, so the figure barely depends on the sample count; it scales with the
 * image (exposure(s * img) = s * exposure(img), exactly for powers of two), and the blocks
 * are laid out from the image centre outwards, so a mirrored or rotated copy of the image
 * has the same exposure. *out = 0 when no block qualifies. Needs diffuse and specular. */
kpcn_status kpcn_aov_exposure(const kpcn_aov_set *aov, double *out);

/* Counts non-finite values in every present plane; returns the count and, if
 * first_name is non-NULL, the channel name of the first offender. */
size_t kpcn_aov_count_nonfinite(const kpcn_aov_set *set, const char **first_name);

#ifdef __cplusplus
}
#endif
#endif
