/* kpcn/dataset.h — the patch store the trainer streams from, the dataset manifest,
 * and pre-render scene perturbation (seed §3.3). docs/dataset.md describes the formats.
 *
 * ---- Patch store (.kps), format version 1 ----
 * One file, little-endian, memory-mappable:
 *   offset 0     fixed header (64 bytes, rest of the first 4096 bytes is zero):
 *                  char     magic[8]     = "KPCNPS\0\1"
 *                  uint32   version      = 1
 *                  uint32   dtype        = 1 float32 | 2 float16 (IEEE half)
 *                  uint32   patch_size   S
 *                  uint32   nchannels    C
 *                  uint64   count        N
 *                  uint64   patch_bytes  = C*S*S*sizeof(dtype)
 *                  uint64   index_offset = 4096 + N*patch_bytes
 *                  uint64   meta_offset  = index_offset + N*32
 *                  uint64   meta_length  (bytes of JSON; the file ends right after it)
 *   offset 4096  N patches, each planar: channel c, row y, column x at
 *                  ((c*S + y)*S + x) elements from the patch start
 *   index_offset N records of 32 bytes (kpcn_patch_record below, same layout)
 *   meta_offset  UTF-8 JSON: {"format":"kpcn-patchstore","version":1,"dtype":"float32",
 *                  "patch_size":S,"channels":[...C names...],"count":N,
 *                  "sources":[{"scene","variant","split","spp","ref_spp","width","height",
 *                  "depth_min","depth_max","depth_mean","depth_std","noisy","reference"},...],
 *                  "stats":{"candidates","kept","culled"}, "settings":{...free-form...}}
 * Opening validates magic, version, dtype, sizes, offsets against the file size
 * (truncation), the JSON, source ids of the index, and optionally the channel list.
 *
 * Default channel list (KPCN_PATCHSTORE_DEFAULT_CHANNELS, 33 channels): the 24 noisy
 * channels in canonical names (kpcn/image.h), then the 9 reference channels prefixed
 * "ref.":
 *   R G B diffuse.R diffuse.G diffuse.B specular.R specular.G specular.B
 *   albedo.R albedo.G albedo.B N.X N.Y N.Z Z visibility.V
 *   color.var diffuse.var specular.var albedo.var N.var Z.var visibility.var
 *   ref.R ref.G ref.B ref.diffuse.R ref.diffuse.G ref.diffuse.B
 *   ref.specular.R ref.specular.G ref.specular.B
 * These names are what kpcn_augment_planes understands, so a trainer applies one
 * augmentation draw to a whole patch (noisy and reference together) in one call.
 * Depth is stored raw; each source carries full-image depth statistics so per-image
 * depth normalisation of a patch equals that of the full image.
 */
#ifndef KPCN_DATASET_H
#define KPCN_DATASET_H

#include "kpcn/image.h"

#ifdef __cplusplus
extern "C" {
#endif

#define KPCN_PATCHSTORE_VERSION 1
#define KPCN_PATCHSTORE_DATA_OFFSET 4096

typedef enum kpcn_dtype { KPCN_DTYPE_F32 = 1, KPCN_DTYPE_F16 = 2 } kpcn_dtype;

/* The default channel list (NULL-terminated array of KPCN_PATCHSTORE_NUM_DEFAULT names). */
#define KPCN_PATCHSTORE_NUM_DEFAULT 33
#define KPCN_PATCHSTORE_NUM_NOISY 24
extern const char *const kpcn_patchstore_default_channels[KPCN_PATCHSTORE_NUM_DEFAULT + 1];

/* One source image pair (one render of one scene variant at one spp). */
typedef struct kpcn_patch_source {
  char scene[128]; /* base scene name (the split unit) */
  int variant;     /* perturbation index, 0 = unperturbed */
  char split[16];  /* "train", "val", "test" */
  int spp;         /* noisy spp */
  int ref_spp;
  int width, height;          /* full image size */
  float depth_min, depth_max; /* over the whole noisy image, all pixels (misses are 0) */
  float depth_mean, depth_std;
  double exposure; /* kpcn_aov_exposure of the whole noisy image; 0 = not recorded */
  char noisy[256]; /* file names, informative */
  char reference[256];
} kpcn_patch_source;

/* Index record, 32 bytes on disk. */
typedef struct kpcn_patch_record {
  uint32_t source; /* index into sources */
  int32_t x, y;    /* top-left corner in the source image */
  uint32_t flags;  /* reserved, 0 */
  float flat_frac; /* culling statistic of this patch */
  float weight;    /* selection probability relative to uniform */
  uint64_t reserved;
} kpcn_patch_record;

/* Computes the whole-image statistics of a noisy AOV set into src: size, depth statistics
 * (needs the depth buffer) and, where diffuse and specular are present, the exposure
 * (kpcn_aov_exposure; 0 otherwise). */
kpcn_status kpcn_patch_source_image_stats(kpcn_patch_source *src, const kpcn_aov_set *noisy);

/* ---- writing ---- */
typedef struct kpcn_patchstore_writer kpcn_patchstore_writer;

typedef struct kpcn_patchstore_settings {
  int patch_size;              /* default 65 */
  kpcn_dtype dtype;            /* default KPCN_DTYPE_F32 */
  int nchannels;               /* 0 = default list */
  const char *const *channels; /* NULL = default list */
  const char *settings_json;   /* optional JSON object text stored under "settings" */
} kpcn_patchstore_settings;

void kpcn_patchstore_settings_defaults(kpcn_patchstore_settings *s);

/* Starts writing `path` (data goes to a temp file next to it; nothing appears at path
 * until kpcn_patchstore_finish succeeds). */
kpcn_status kpcn_patchstore_create(kpcn_patchstore_writer **w, const char *path,
                                   const kpcn_patchstore_settings *s);
/* Registers a source; *id receives its index. */
kpcn_status kpcn_patchstore_add_source(kpcn_patchstore_writer *w, const kpcn_patch_source *src,
                                       uint32_t *id);
/* Appends one patch given as C planar float planes of S x S (converted to dtype). */
kpcn_status kpcn_patchstore_append(kpcn_patchstore_writer *w, const kpcn_patch_record *rec,
                                   const float *planes);
/* Appends the S x S window at (rec->x, rec->y) of (noisy, ref) using the writer's channel
 * names: noisy buffers by canonical name, "ref."-prefixed names from ref. A missing
 * buffer is an error naming the channel. */
kpcn_status kpcn_patchstore_append_aov(kpcn_patchstore_writer *w, const kpcn_patch_record *rec,
                                       const kpcn_aov_set *noisy, const kpcn_aov_set *ref);
/* Adds culling statistics to the metadata "stats". */
void kpcn_patchstore_add_stats(kpcn_patchstore_writer *w, int64_t candidates, int64_t kept,
                               int64_t culled);
/* Writes index + metadata, then renames the temp file onto path. Frees w in all cases. */
kpcn_status kpcn_patchstore_finish(kpcn_patchstore_writer *w);
/* Discards everything (removes the temp file) and frees w. NULL is a no-op. */
void kpcn_patchstore_abort(kpcn_patchstore_writer *w);

/* ---- reading ---- */
typedef struct kpcn_patchstore kpcn_patchstore;

/* Opens and validates (memory-maps) a store. expected/nexpected: if non-NULL, the
 * channel list must equal it exactly (else KPCN_ERR_FORMAT naming the first difference). */
kpcn_status kpcn_patchstore_open(kpcn_patchstore **ps, const char *path,
                                 const char *const *expected, int nexpected);
void kpcn_patchstore_close(kpcn_patchstore *ps);

uint64_t kpcn_patchstore_count(const kpcn_patchstore *ps);
int kpcn_patchstore_patch_size(const kpcn_patchstore *ps);
int kpcn_patchstore_nchannels(const kpcn_patchstore *ps);
kpcn_dtype kpcn_patchstore_dtype(const kpcn_patchstore *ps);
/* Channel names (owned by ps). */
const char *const *kpcn_patchstore_channels(const kpcn_patchstore *ps);
/* Index of a channel name, or -1. */
int kpcn_patchstore_find_channel(const kpcn_patchstore *ps, const char *name);
int kpcn_patchstore_nsources(const kpcn_patchstore *ps);
const kpcn_patch_source *kpcn_patchstore_source(const kpcn_patchstore *ps, int i);
/* The median exposure (kpcn_patch_source.exposure) of the store's training sources (split
 * "train", or all when none is marked), skipping sources without one; 0 when none has one
 * (a store written before sources carried their exposure). */
kpcn_status kpcn_patchstore_exposure(const kpcn_patchstore *ps, double *median);

/* Copies patch i as C planar float32 planes into dst (C*S*S floats); rec optional.
 * Thread-safe (read-only mapping). */
kpcn_status kpcn_patchstore_get(const kpcn_patchstore *ps, uint64_t i, float *dst,
                                kpcn_patch_record *rec);
/* The record of patch i (its source, position, flat fraction and weight) without reading
 * its pixels: the index sits apart from the pixel data, so a pass over every record of a
 * store larger than memory reads kilobytes, not the store. Thread-safe. */
kpcn_status kpcn_patchstore_record(const kpcn_patchstore *ps, uint64_t i, kpcn_patch_record *rec);
/* Raw mapped pointer to patch i (dtype elements), valid until close. */
const void *kpcn_patchstore_raw(const kpcn_patchstore *ps, uint64_t i);

/* half <-> float (IEEE 754 binary16, round-to-nearest-even). */
uint16_t kpcn_float_to_half(float f);
float kpcn_half_to_float(uint16_t h);

/* ---- pre-render scene perturbation (seed §3.3) ----
 * Works on Tungsten scene.json text. Each enabled perturbation is drawn from
 * (seed, variant); variant 0 returns the scene unchanged. Strengths are relative and
 * documented in docs/dataset.md. */
typedef struct kpcn_perturb_settings {
  double camera;    /* orbit angle / dolly / look-at jitter strength, default 1 (0 = off) */
  double fov;       /* field-of-view jitter strength, default 1 */
  double material;  /* albedo/hue, roughness, IOR jitter, default 1 */
  double bsdf_swap; /* probability that a BSDF changes type, default 0.15 */
  double light;     /* light size/intensity/position jitter, default 1 */
  double env;       /* environment rotation, default 1 */
  /* Probability that an eligible albedo texture is swapped, default 0.2: an image texture
   * for another image, a constant for a checker of two colours, a checker for a constant. */
  double texture_swap;
  /* Image pool for those swaps: a directory (its .png/.jpg/.jpeg/.tga/.bmp/.hdr/.exr files,
   * made absolute) or NULL = the albedo images the scene itself uses. Default NULL. */
  const char *texture_dir;
  /* Probability that a swapped constant albedo becomes an image of that pool instead of a
   * two-colour checker, default 0 (a pool of many bitmaps then reaches every surface, not
   * only those that had an image; without images in the pool it stays a checker). */
  double texture_bitmap;
} kpcn_perturb_settings;

void kpcn_perturb_settings_defaults(kpcn_perturb_settings *s);
/* *out_json: malloc'ed JSON text of the perturbed scene (free with free()).
 * summary (optional, size summary_size) receives a one-line description of what changed. */
kpcn_status kpcn_perturb_scene(char **out_json, const char *scene_json, uint64_t seed, int variant,
                               const kpcn_perturb_settings *s, char *summary, size_t summary_size);

#ifdef __cplusplus
}
#endif
#endif
