/* Shared helpers of the exr module (not installed). */
#ifndef KPCN_EXR_INTERNAL_H
#define KPCN_EXR_INTERNAL_H

#include "kpcn/exr.h"

#include <openexr.h>

/* Opens `path` for reading with an error handler that captures OpenEXR's message (the
 * library never prints) and chunk reconstruction disabled (a truncated file is an error,
 * not silently patched). Validates part 0: not deep, no subsampling, sane size.
 * On failure returns a kpcn status with a message naming the file; *ctx is NULL. */
kpcn_status kpcn_exr_open_read(const char *path, exr_context_t *ctx);

/* Maps an OpenEXR result to a kpcn status and records "<what> '<path>': <msg>". */
kpcn_status kpcn_exr_fail(exr_result_t rv, kpcn_status st, const char *what, const char *path);

/* Context initializer: error capture, KPCN_MAX_DIM limits, no chunk reconstruction. */
exr_context_initializer_t kpcn_exr_initializer(void);

/* Reads kpcn:spp/seed/scene/version from part 0 (tolerates int, float, double, string). */
void kpcn_exr_read_meta(exr_context_t ctx, int *spp, int64_t *seed, char *scene, size_t scenesz,
                        char *version, size_t versionsz);
/* A positive int attribute such as kpcn:albedoSpp (the albedo pass's samples) or
 * kpcn:albedoFootprint; 0 if absent or not a positive int. */
int kpcn_exr_read_positive_int(exr_context_t ctx, const char *name);

/* First error of a parallel chunk loop (reader and writer), kept by lowest chunk index so the
 * message does not depend on thread timing. Messages live in thread-local storage, so
 * workers copy theirs here and the calling thread re-raises it with kpcn_fail. */
typedef struct {
  kpcn_status st;
  int chunk;
  char msg[1024];
} kpcn_exr_chunk_error;

/* Records st (and the calling thread's kpcn_last_error()) for chunk if it is the first. */
void kpcn_exr_record_error(kpcn_exr_chunk_error *e, kpcn_status st, int chunk);

/* Reads all channels of part 0 of an open context into a new image (names as stored). */
kpcn_status kpcn_exr_read_context(exr_context_t ctx, const char *path, int nthreads,
                                  kpcn_image **out);

/* Writes n planes of w*h floats atomically (shared by the image and AOV writers). */
kpcn_status kpcn_exr_write_planes(const char *path, int w, int h, int n, const char *const *names,
                                  const float *const *planes, const kpcn_exr_write_options *opt);

#endif
