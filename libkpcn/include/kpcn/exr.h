/* kpcn/exr.h — multi-channel EXR read/write (OpenEXR Core C API) for kpcn images and
 * AOV sets (DESIGN.md §4, docs/aov-exr.md).
 *
 * Reading:
 *  - scanline and tiled single-part files (part 0 of multi-part files), any compression
 *    OpenEXR supports (DWAA/DWAB only with OpenEXR >= 3.2: KPCN_ERR_UNSUPPORTED before);
 *    half/float/uint channels are all converted to float32;
 *  - channel names are kept exactly as stored (OpenEXR stores them sorted by name);
 *  - the data window may start anywhere (it is read as is; the image is the data window);
 *  - values are NOT filtered: NaN/Inf are kept (see kpcn_aov_count_nonfinite);
 *  - subsampled channels (x/y sampling != 1) and deep files give KPCN_ERR_UNSUPPORTED;
 *  - a missing file gives KPCN_ERR_IO, a truncated or malformed one KPCN_ERR_FORMAT,
 *    a header with zero/absurd dimensions KPCN_ERR_FORMAT / KPCN_ERR_OUT_OF_MEMORY;
 *    every message names the file.
 * Writing:
 *  - one scanline part, channels sorted by name (OpenEXR's order), pixel type per file;
 *  - atomic: the data goes to a temporary file next to `path` that is renamed over
 *    `path` only once complete; on any failure the temporary file is removed and `path`
 *    is untouched.
 * Ownership: *out results are allocated by the call and freed by the caller with
 * kpcn_image_destroy / kpcn_aov_destroy. All functions are thread-safe (no globals).
 */
#ifndef KPCN_EXR_H
#define KPCN_EXR_H

#include "kpcn/common.h"
#include "kpcn/image.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef enum kpcn_exr_compression {
  KPCN_EXR_ZIP = 0, /* default: lossless, 16 scanlines per chunk */
  KPCN_EXR_NONE,
  KPCN_EXR_ZIPS, /* ZIP, 1 scanline per chunk */
  KPCN_EXR_PIZ,
  KPCN_EXR_RLE
} kpcn_exr_compression;

typedef enum kpcn_exr_pixel_type {
  KPCN_EXR_FLOAT = 0, /* default: 32-bit float */
  KPCN_EXR_HALF       /* 16-bit half (references, previews) */
} kpcn_exr_pixel_type;

#define KPCN_EXR_MAX_ATTRS 16

/* One extra header attribute. Type string when `is_int` is 0, int otherwise. */
typedef struct kpcn_exr_attr {
  char name[64];
  int is_int;
  int ivalue;
  char svalue[256];
} kpcn_exr_attr;

typedef struct kpcn_exr_write_options {
  kpcn_exr_compression compression;
  kpcn_exr_pixel_type pixel_type;
  /* Threads compressing chunks (0 = all cores); the file is byte-identical for any count. */
  int nthreads;
  /* Extra attributes written to the header (kpcn:spp, kpcn:seed, ... for plain images;
   * kpcn_exr_write_aov writes the set's metadata itself). */
  int nattrs;
  kpcn_exr_attr attrs[KPCN_EXR_MAX_ATTRS];
} kpcn_exr_write_options;

/* ZIP, float, no extra attributes. */
kpcn_exr_write_options kpcn_exr_write_options_defaults(void);
/* "zip", "zips", "piz", "rle" or "none" (the names kpcn_exr_info reports) into *out;
 * KPCN_ERR_INVALID_ARGUMENT naming the text otherwise. */
kpcn_status kpcn_exr_compression_parse(const char *name, kpcn_exr_compression *out);
/* Appends a string/int attribute to opt, or replaces one of the same name
 * (KPCN_ERR_INVALID_ARGUMENT when full, or the name or a string value is too long). */
kpcn_status kpcn_exr_options_add_string(kpcn_exr_write_options *opt, const char *name,
                                        const char *value);
kpcn_status kpcn_exr_options_add_int(kpcn_exr_write_options *opt, const char *name, int value);

/* Reads every channel of part 0 as float32; names as stored in the file. Chunks are decoded
 * by kpcn_resolve_threads(nthreads) threads (the _mt forms; the plain forms use 0 = all);
 * the result does not depend on the thread count. */
kpcn_status kpcn_exr_read_image(const char *path, kpcn_image **out);
kpcn_status kpcn_exr_read_image_mt(const char *path, int nthreads, kpcn_image **out);
/* Writes every channel of img. opt may be NULL (defaults). Channel names must be unique and
 * non-empty. */
kpcn_status kpcn_exr_write_image(const char *path, const kpcn_image *img,
                                 const kpcn_exr_write_options *opt);

/* Reads an AOV EXR into a set: canonical names and aliases (see docs/aov-exr.md) are
 * mapped to buffers, unknown channels are ignored, header attributes kpcn:spp,
 * kpcn:seed, kpcn:scene, kpcn:version fill set->spp/seed/scene/version (spp/seed -1,
 * strings "" when absent). A buffer is present only if all its channels are found; a
 * partially present buffer (e.g. N.X and N.Y without N.Z) is KPCN_ERR_MISSING_CHANNEL
 * naming the channel and file. Use kpcn_aov_require to demand buffers. */
kpcn_status kpcn_exr_read_aov(const char *path, kpcn_aov_set **out);
kpcn_status kpcn_exr_read_aov_mt(const char *path, int nthreads, kpcn_aov_set **out);
/* Writes the present buffers with canonical names plus kpcn:spp/seed/scene/version
 * (spp/seed only when >= 0, scene only when non-empty; version always, this library's when
 * empty) and kpcn:albedoSpp / kpcn:albedoFootprint (when > 0 / > 1). opt may be NULL. */
kpcn_status kpcn_exr_write_aov(const char *path, const kpcn_aov_set *set,
                               const kpcn_exr_write_options *opt);

/* Header summary for `kpcntool --info`; reads the header only. */
#define KPCN_EXR_MAX_INFO_CHANNELS 256
typedef struct kpcn_exr_info_t {
  int width, height;  /* data window size */
  int data_x, data_y; /* data window origin */
  int tiled;          /* 1 for tiled files */
  int nparts;         /* number of parts in the file (only part 0 is read) */
  int nchannels;      /* channels in part 0 (may exceed the list below) */
  char channels[KPCN_EXR_MAX_INFO_CHANNELS][64];   /* names (truncated to 63 chars) */
  int channel_is_half[KPCN_EXR_MAX_INFO_CHANNELS]; /* 1 half, 0 float, 2 uint */
  char compression[16];                            /* "zip", "none", "piz", ... */
  int spp;                                         /* kpcn:spp, -1 if absent */
  int64_t seed;                                    /* kpcn:seed, -1 if absent */
  char scene[256];                                 /* kpcn:scene, "" if absent */
  char version[32];                                /* kpcn:version, "" if absent */
  /* AOV buffers recognised (canonical or alias): 1 if all channels present. */
  int has_buffer[KPCN_BUF_COUNT];
  int has_variance[KPCN_BUF_COUNT];
} kpcn_exr_info_t;

kpcn_status kpcn_exr_info(const char *path, kpcn_exr_info_t *out);

#ifdef __cplusplus
}
#endif
#endif
