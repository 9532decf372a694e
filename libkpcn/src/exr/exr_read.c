/* EXR reading through the OpenEXR Core C API: every channel of part 0 to planar float32. */
#include "exr/exr_internal.h"

#include "core/internal.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Points the decoder's channels at the image planes for a chunk whose top-left pixel is
 * (x0, y0) relative to the data window. Channels are matched by name: OpenEXR sorts them,
 * and the decoder's order is the file's, which is also the image's (built from the header). */
static kpcn_status bind_channels(exr_decode_pipeline_t *dec, kpcn_image *img, int x0, int y0,
                                 const char *path) {
  for (int i = 0; i < dec->channel_count; i++) {
    exr_coding_channel_info_t *ch = &dec->channels[i];
    int c = kpcn_image_find_channel(img, ch->channel_name);
    if (c < 0)
      return kpcn_fail(KPCN_ERR_FORMAT, "'%s': chunk has unknown channel '%s'", path,
                       ch->channel_name);
    float *dst = kpcn_image_plane(img, c) + (size_t)y0 * img->width + x0;
    ch->decode_to_ptr = (uint8_t *)dst;
    ch->user_pixel_stride = (int32_t)sizeof(float);
    ch->user_line_stride = (int32_t)(sizeof(float) * (size_t)img->width);
    ch->user_data_type = EXR_PIXEL_FLOAT; /* half and uint converted by the library */
    ch->user_bytes_per_element = (int16_t)sizeof(float);
  }
  return KPCN_OK;
}

/* One thread's decoder: `first` selects initialize vs update (OpenEXR call order). */
typedef struct chunk_decoder {
  exr_decode_pipeline_t dec;
  int first;
  int b44;                                             /* the part is B44/B44A compressed */
  exr_result_t (*decompress)(exr_decode_pipeline_t *); /* the library's default routine */
} chunk_decoder;

/* Decodes one chunk into img. */
static kpcn_status decode_chunk(exr_context_t ctx, const exr_chunk_info_t *ci, chunk_decoder *cd,
                                kpcn_image *img, int x0, int y0, const char *path) {
  exr_decode_pipeline_t *dec = &cd->dec;
  int *first = &cd->first;
  exr_result_t rv;
  if (x0 < 0 || y0 < 0 || x0 + ci->width > img->width || y0 + ci->height > img->height)
    return kpcn_fail(KPCN_ERR_FORMAT, "'%s': chunk %d lies outside the data window", path, ci->idx);
  if (*first) {
    rv = exr_decoding_initialize(ctx, 0, ci, dec);
    if (rv != EXR_ERR_SUCCESS) return kpcn_exr_fail(rv, KPCN_ERR_FORMAT, "corrupt chunk in", path);
  } else {
    rv = exr_decoding_update(ctx, 0, ci, dec);
    if (rv != EXR_ERR_SUCCESS) return kpcn_exr_fail(rv, KPCN_ERR_FORMAT, "corrupt chunk in", path);
  }
  KPCN_TRY(bind_channels(dec, img, x0, y0, path));
  if (*first) {
    rv = exr_decoding_choose_default_routines(ctx, 0, dec);
    if (rv != EXR_ERR_SUCCESS)
      return kpcn_exr_fail(rv, KPCN_ERR_UNSUPPORTED, "cannot decode", path);
    cd->decompress = dec->decompress_fn;
    *first = 0;
  }
  /* A writer stores a chunk raw when compressing would not make it smaller (packed size ==
   * unpacked size), as the C++ library reads it. OpenEXR Core 3.1 takes that shortcut for
   * every codec but B44/B44A, whose decoder it runs on the raw bytes: rows and channels came
   * out scrambled (≥ 2 float channels: every chunk is raw) or wrong (a last chunk of one half
   * row), or the chunk was called corrupt. The raw bytes are the pixels: no decompression. */
  if (cd->b44) dec->decompress_fn = ci->packed_size == ci->unpacked_size ? NULL : cd->decompress;
  rv = exr_decoding_run(ctx, 0, dec);
  if (rv != EXR_ERR_SUCCESS)
    return kpcn_exr_fail(rv, KPCN_ERR_FORMAT, "truncated or corrupt pixel data in", path);
  return KPCN_OK;
}

/* Reads chunk k: scanline block k, or tile (k % ntx, k / ntx) of level 0. */
static kpcn_status read_one_chunk(exr_context_t ctx, int k, int tiled, int spc, int tw, int th,
                                  int ntx, const exr_attr_box2i_t *dw, chunk_decoder *cd,
                                  kpcn_image *img, const char *path) {
  exr_chunk_info_t ci;
  exr_result_t rv;
  if (tiled) {
    int tx = k % ntx, ty = k / ntx;
    rv = exr_read_tile_chunk_info(ctx, 0, tx, ty, 0, 0, &ci);
    if (rv != EXR_ERR_SUCCESS)
      return kpcn_exr_fail(rv, KPCN_ERR_FORMAT, "truncated or corrupt file (tile table)", path);
    return decode_chunk(ctx, &ci, cd, img, tx * tw, ty * th, path);
  }
  rv = exr_read_scanline_chunk_info(ctx, 0, dw->min.y + k * spc, &ci);
  if (rv != EXR_ERR_SUCCESS)
    return kpcn_exr_fail(rv, KPCN_ERR_FORMAT, "truncated or corrupt file", path);
  return decode_chunk(ctx, &ci, cd, img, 0, ci.start_y - dw->min.y, path);
}

/* Decodes all chunks; chunks are independent, so threads split them (read contexts are
 * thread-safe in OpenEXR Core) and the result does not depend on the thread count. */
static kpcn_status read_pixels(exr_context_t ctx, kpcn_image *img, const exr_attr_box2i_t *dw,
                               int tiled, int nthreads, const char *path) {
  int32_t spc = 1;
  uint32_t tw = 0, th = 0;
  int ntx = 1, nchunks;
  if (tiled) {
    exr_tile_level_mode_t lm;
    exr_tile_round_mode_t rm;
    exr_result_t rv = exr_get_tile_descriptor(ctx, 0, &tw, &th, &lm, &rm);
    if (rv != EXR_ERR_SUCCESS || tw == 0 || th == 0)
      return kpcn_exr_fail(rv, KPCN_ERR_FORMAT, "bad tile description in", path);
    /* Only the full-resolution level (0,0) is read; mip/rip levels are ignored. */
    ntx = (int)((img->width + (int64_t)tw - 1) / tw);
    nchunks = ntx * (int)((img->height + (int64_t)th - 1) / th);
  } else {
    exr_result_t rv = exr_get_scanlines_per_chunk(ctx, 0, &spc);
    if (rv != EXR_ERR_SUCCESS || spc <= 0)
      return kpcn_exr_fail(rv, KPCN_ERR_FORMAT, "bad scanline chunking in", path);
    nchunks = (int)((img->height + (int64_t)spc - 1) / spc);
  }
  exr_compression_t comp = EXR_COMPRESSION_NONE;
  exr_get_compression(ctx, 0, &comp);
  const int b44 = comp == EXR_COMPRESSION_B44 || comp == EXR_COMPRESSION_B44A;
  int nt = kpcn_resolve_threads(nthreads);
  if (nt > nchunks) nt = nchunks;
  kpcn_exr_chunk_error err = {KPCN_OK, 0, ""};
  int failed = 0;
#pragma omp parallel num_threads(nt)
  {
    chunk_decoder cd = {EXR_DECODE_PIPELINE_INITIALIZER, 1, b44, NULL};
#pragma omp for schedule(dynamic, 1)
    for (int k = 0; k < nchunks; k++) {
      int stop;
#pragma omp atomic read
      stop = failed;
      if (stop) continue;
      kpcn_status s = read_one_chunk(ctx, k, tiled, spc, (int)tw, (int)th, ntx, dw, &cd, img, path);
      if (s != KPCN_OK) {
        kpcn_exr_record_error(&err, s, k);
#pragma omp atomic write
        failed = 1;
      }
    }
    exr_decoding_destroy(ctx, &cd.dec);
  }
  if (err.st != KPCN_OK) return kpcn_fail(err.st, "%s", err.msg);
  return KPCN_OK;
}

kpcn_status kpcn_exr_read_context(exr_context_t ctx, const char *path, int nthreads,
                                  kpcn_image **out) {
  exr_attr_box2i_t dw;
  const exr_attr_chlist_t *chl = NULL;
  exr_storage_t storage;
  exr_get_data_window(ctx, 0, &dw);
  exr_get_channels(ctx, 0, &chl);
  exr_get_storage(ctx, 0, &storage);
  int w = dw.max.x - dw.min.x + 1, h = dw.max.y - dw.min.y + 1; /* validated on open */
  const char **names = kpcn_calloc((size_t)chl->num_channels, sizeof(char *), "channel names");
  if (!names) return KPCN_ERR_OUT_OF_MEMORY;
  for (int c = 0; c < chl->num_channels; c++)
    names[c] = chl->entries[c].name.str;
  kpcn_status s = kpcn_image_create(out, w, h, chl->num_channels, names);
  free((void *)names);
  if (s != KPCN_OK) return kpcn_fail_context("reading '%s'", path);
  s = read_pixels(ctx, *out, &dw, storage == EXR_STORAGE_TILED, nthreads, path);
  if (s != KPCN_OK) {
    kpcn_image_destroy(*out);
    *out = NULL;
  }
  return s;
}

kpcn_status kpcn_exr_read_image(const char *path, kpcn_image **out) {
  return kpcn_exr_read_image_mt(path, 0, out);
}

kpcn_status kpcn_exr_read_image_mt(const char *path, int nthreads, kpcn_image **out) {
  if (!out) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_exr_read_image: out is NULL");
  *out = NULL;
  exr_context_t ctx;
  KPCN_TRY(kpcn_exr_open_read(path, &ctx));
  kpcn_status s = kpcn_exr_read_context(ctx, path, nthreads, out);
  exr_finish(&ctx);
  return s;
}
