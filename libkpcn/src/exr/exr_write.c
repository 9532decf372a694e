/* EXR writing through the OpenEXR Core C API: one scanline part, atomic (temp + rename). */
#include "exr/exr_internal.h"

#include "core/internal.h"

#include <limits.h>
#include <stdint.h>
#include <stdlib.h>
#include <stdio.h>
#include <string.h>

kpcn_exr_write_options kpcn_exr_write_options_defaults(void) {
  kpcn_exr_write_options o;
  memset(&o, 0, sizeof o);
  o.compression = KPCN_EXR_ZIP;
  o.pixel_type = KPCN_EXR_FLOAT;
  return o;
}

static kpcn_status add_attr(kpcn_exr_write_options *opt, const char *name, kpcn_exr_attr **a) {
  if (!opt || !name || !*name)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "EXR attribute: NULL options or empty name");
  if (opt->nattrs < 0 || opt->nattrs > KPCN_EXR_MAX_ATTRS) /* an index below: never trusted */
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "EXR options: nattrs %d is outside [0, %d]",
                     opt->nattrs, KPCN_EXR_MAX_ATTRS);
  if (strlen(name) >= sizeof opt->attrs[0].name)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "EXR attribute name '%s' is too long", name);
  for (int i = 0; i < opt->nattrs; i++) /* replace an attribute of the same name */
    if (strcmp(opt->attrs[i].name, name) == 0) {
      *a = &opt->attrs[i];
      return KPCN_OK;
    }
  if (opt->nattrs >= KPCN_EXR_MAX_ATTRS)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "EXR attribute '%s': more than %d attributes", name,
                     KPCN_EXR_MAX_ATTRS);
  *a = &opt->attrs[opt->nattrs++];
  memset(*a, 0, sizeof **a);
  strcpy((*a)->name, name);
  return KPCN_OK;
}

kpcn_status kpcn_exr_options_add_string(kpcn_exr_write_options *opt, const char *name,
                                        const char *value) {
  kpcn_exr_attr *a;
  if (!name) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "EXR attribute: NULL name");
  if (!value) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "EXR attribute '%s': NULL value", name);
  if (strlen(value) >= sizeof a->svalue)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "EXR attribute '%s': value longer than %zu bytes",
                     name, sizeof a->svalue - 1);
  KPCN_TRY(add_attr(opt, name, &a));
  a->is_int = 0;
  strcpy(a->svalue, value);
  return KPCN_OK;
}

kpcn_status kpcn_exr_options_add_int(kpcn_exr_write_options *opt, const char *name, int value) {
  kpcn_exr_attr *a;
  KPCN_TRY(add_attr(opt, name, &a));
  a->is_int = 1;
  a->ivalue = value;
  return KPCN_OK;
}

static exr_compression_t to_exr_compression(kpcn_exr_compression c) {
  switch (c) {
  case KPCN_EXR_NONE: return EXR_COMPRESSION_NONE;
  case KPCN_EXR_ZIPS: return EXR_COMPRESSION_ZIPS;
  case KPCN_EXR_PIZ: return EXR_COMPRESSION_PIZ;
  case KPCN_EXR_RLE: return EXR_COMPRESSION_RLE;
  case KPCN_EXR_ZIP:
  default: return EXR_COMPRESSION_ZIP;
  }
}

kpcn_status kpcn_exr_compression_parse(const char *name, kpcn_exr_compression *out) {
  static const struct {
    const char *name;
    kpcn_exr_compression c;
  } tab[] = {{"zip", KPCN_EXR_ZIP},
             {"zips", KPCN_EXR_ZIPS},
             {"piz", KPCN_EXR_PIZ},
             {"rle", KPCN_EXR_RLE},
             {"none", KPCN_EXR_NONE}};
  for (size_t k = 0; name && out && k < sizeof tab / sizeof tab[0]; k++)
    if (strcmp(name, tab[k].name) == 0) {
      *out = tab[k].c;
      return KPCN_OK;
    }
  return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "compression '%s' is not zip, zips, piz, rle or none",
                   name ? name : "(null)");
}

/* Packs and compresses the chunk starting at scanline y into enc (not written yet). */
static kpcn_status encode_chunk(exr_context_t ctx, int part, int y, int w, int n,
                                const char *const *names, const float *const *planes,
                                exr_encode_pipeline_t *enc, int *first, const char *path) {
  exr_chunk_info_t ci;
  exr_result_t rv = exr_write_scanline_chunk_info(ctx, part, y, &ci);
  if (rv == EXR_ERR_SUCCESS)
    rv = *first ? exr_encoding_initialize(ctx, part, &ci, enc)
                : exr_encoding_update(ctx, part, &ci, enc);
  if (rv != EXR_ERR_SUCCESS) return kpcn_exr_fail(rv, KPCN_ERR_INTERNAL, "cannot encode", path);
  /* The encoder lists channels in OpenEXR's sorted order: match by name. */
  for (int i = 0; i < enc->channel_count; i++) {
    exr_coding_channel_info_t *ch = &enc->channels[i];
    int c = -1;
    for (int k = 0; k < n && c < 0; k++)
      if (strcmp(names[k], ch->channel_name) == 0) c = k;
    if (c < 0)
      return kpcn_fail(KPCN_ERR_INTERNAL, "'%s': encoder channel '%s' unknown", path,
                       ch->channel_name);
    ch->encode_from_ptr = (const uint8_t *)(planes[c] + (size_t)ci.start_y * (size_t)w);
    ch->user_pixel_stride = (int32_t)sizeof(float);
    ch->user_line_stride = (int32_t)(sizeof(float) * (size_t)w);
    ch->user_data_type = EXR_PIXEL_FLOAT; /* the library converts to half if asked */
    ch->user_bytes_per_element = (int16_t)sizeof(float);
  }
  if (*first) {
    rv = exr_encoding_choose_default_routines(ctx, part, enc);
    if (rv != EXR_ERR_SUCCESS) return kpcn_exr_fail(rv, KPCN_ERR_INTERNAL, "cannot encode", path);
    /* we write ourselves, in order (see write_body) */
    enc->yield_until_ready_fn = NULL;
    enc->write_fn = NULL;
    *first = 0;
  }
  rv = exr_encoding_run(ctx, part, enc);
  if (rv != EXR_ERR_SUCCESS) return kpcn_exr_fail(rv, KPCN_ERR_INTERNAL, "cannot compress", path);
  return KPCN_OK;
}

/* A compressed chunk waiting for its turn to be written. */
typedef struct chunk_slot {
  void *bytes;
  uint64_t size, cap;
  int start_y;
  kpcn_status st;
} chunk_slot;

/* Copies the pipeline's chunk into slot (the pipeline reuses its buffers). A reader takes a
 * chunk as large as its raw data for uncompressed, but OpenEXR Core 3.1 falls back to the raw
 * bytes only when compressing made a chunk larger: on a tie it keeps the compressed bytes, and
 * the chunk read back as garbage (ZIP, half, 7x32; session 59). So a chunk that compression
 * did not shrink is written raw. */
static kpcn_status keep_chunk(chunk_slot *slot, const exr_encode_pipeline_t *enc) {
  const int raw = enc->compressed_bytes >= enc->packed_bytes;
  const void *src = raw ? enc->packed_buffer : enc->compressed_buffer;
  const uint64_t n = raw ? enc->packed_bytes : (uint64_t)enc->compressed_bytes;
  if (n > slot->cap) {
    void *b = realloc(slot->bytes, (size_t)n);
    if (!b)
      return kpcn_fail(KPCN_ERR_OUT_OF_MEMORY, "EXR chunk of %llu bytes", (unsigned long long)n);
    slot->bytes = b;
    slot->cap = n;
  }
  memcpy(slot->bytes, src, (size_t)n);
  slot->size = n;
  slot->start_y = enc->chunk.start_y;
  return KPCN_OK;
}

/* Writes the header and all chunks into an open write context. */
static kpcn_status write_body(exr_context_t ctx, int w, int h, int n, const char *const *names,
                              const float *const *planes, const kpcn_exr_write_options *opt,
                              const char *path) {
  int part = 0;
  exr_result_t rv = exr_add_part(ctx, "", EXR_STORAGE_SCANLINE, &part);
  if (rv == EXR_ERR_SUCCESS)
    rv = exr_initialize_required_attr_simple(ctx, part, w, h, to_exr_compression(opt->compression));
  if (rv != EXR_ERR_SUCCESS) return kpcn_exr_fail(rv, KPCN_ERR_INTERNAL, "cannot set up", path);
  exr_pixel_type_t pt = opt->pixel_type == KPCN_EXR_HALF ? EXR_PIXEL_HALF : EXR_PIXEL_FLOAT;
  for (int c = 0; c < n; c++) {
    rv = exr_add_channel(ctx, part, names[c], pt, EXR_PERCEPTUALLY_LOGARITHMIC, 1, 1);
    if (rv != EXR_ERR_SUCCESS)
      return kpcn_exr_fail(rv, KPCN_ERR_INVALID_ARGUMENT, "cannot add a channel to", path);
  }
  for (int i = 0; i < opt->nattrs; i++) {
    const kpcn_exr_attr *a = &opt->attrs[i];
    rv = a->is_int ? exr_attr_set_int(ctx, part, a->name, a->ivalue)
                   : exr_attr_set_string(ctx, part, a->name, a->svalue);
    if (rv != EXR_ERR_SUCCESS)
      return kpcn_exr_fail(rv, KPCN_ERR_INVALID_ARGUMENT, "cannot set an attribute of", path);
  }
  rv = exr_write_header(ctx);
  if (rv != EXR_ERR_SUCCESS) return kpcn_exr_fail(rv, KPCN_ERR_IO, "cannot write header of", path);

  int32_t spc = 1;
  exr_get_scanlines_per_chunk(ctx, part, &spc);
  if (spc <= 0) spc = 1;
  int nchunks = (h + spc - 1) / spc;
  int nt = kpcn_resolve_threads(opt->nthreads);
  if (nt > nchunks) nt = nchunks;
  /* Without real compression a chunk is a memcpy: the ordered hand-off between threads
   * would cost more than it saves (badly so on an oversubscribed machine). */
  if (opt->compression == KPCN_EXR_NONE || opt->compression == KPCN_EXR_RLE) nt = 1;
  kpcn_exr_chunk_error err = {KPCN_OK, 0, ""};
  int failed = 0;
  /* Chunks are packed and compressed in parallel, a round of per_round chunks at a time
   * (exr_encoding_run releases the context lock after packing; the pipeline's own write step
   * is disabled), each copied into its slot; then one thread writes the round in increasing
   * order, as OpenEXR requires for INCREASING_Y files. A round hands over once: an ordered
   * loop handed over at every chunk, and with the waiting thread spinning on a shared CPU a
   * tall frame (16x16000) wrote 8-20x slower (session 59). The bytes written do not depend on
   * the thread count. */
  const int per_round = 4 * nt;
  chunk_slot *slot = kpcn_calloc((size_t)per_round, sizeof *slot, "EXR chunk slots");
  if (!slot) return kpcn_last_status();
#pragma omp parallel num_threads(nt)
  {
    exr_encode_pipeline_t enc = EXR_ENCODE_PIPELINE_INITIALIZER;
    int first = 1;
    for (int r0 = 0; r0 < nchunks; r0 += per_round) { /* every thread runs every round */
      const int r1 = r0 + per_round < nchunks ? r0 + per_round : nchunks;
#pragma omp for schedule(static, 1)
      for (int k = r0; k < r1; k++) {
        int stop;
#pragma omp atomic read
        stop = failed;
        kpcn_status s =
            stop ? KPCN_ERR_CANCELLED
                 : encode_chunk(ctx, part, k * spc, w, n, names, planes, &enc, &first, path);
        if (s == KPCN_OK) s = keep_chunk(&slot[k - r0], &enc);
        slot[k - r0].st = s;
        if (s != KPCN_OK && s != KPCN_ERR_CANCELLED) kpcn_exr_record_error(&err, s, k);
      }
#pragma omp single
      for (int k = r0; k < r1 && !failed; k++) {
        chunk_slot *c = &slot[k - r0];
        exr_result_t wr = c->st == KPCN_OK
                              ? exr_write_scanline_chunk(ctx, part, c->start_y, c->bytes, c->size)
                              : EXR_ERR_SUCCESS;
        if (wr != EXR_ERR_SUCCESS)
          kpcn_exr_record_error(&err,
                                kpcn_exr_fail(wr, KPCN_ERR_IO, "cannot write pixels of", path), k);
        if (c->st != KPCN_OK || wr != EXR_ERR_SUCCESS) failed = 1;
      }
    }
    exr_encoding_destroy(ctx, &enc);
  }
  for (int i = 0; i < per_round; i++)
    free(slot[i].bytes);
  free(slot);
  if (err.st != KPCN_OK) return kpcn_fail(err.st, "%s", err.msg);
  return KPCN_OK;
}

kpcn_status kpcn_exr_write_planes(const char *path, int w, int h, int n, const char *const *names,
                                  const float *const *planes, const kpcn_exr_write_options *opt) {
  kpcn_exr_write_options def = kpcn_exr_write_options_defaults();
  if (!opt) opt = &def;
  if (!path || !*path) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "EXR write: empty file name");
  KPCN_TRY(kpcn_check_size(w, h, path));
  if (n <= 0) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "EXR write '%s': no channels", path);
  if ((unsigned)opt->compression > KPCN_EXR_RLE || (unsigned)opt->pixel_type > KPCN_EXR_HALF ||
      opt->nattrs < 0 || opt->nattrs > KPCN_EXR_MAX_ATTRS)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "EXR write '%s': invalid write options", path);
  for (int c = 0; c < n; c++) {
    if (!names[c] || !*names[c] || strlen(names[c]) > 255)
      return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                       "EXR write '%s': channel %d has an empty or overlong name", path, c);
    if (!planes[c])
      return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "EXR write '%s': channel '%s' has no data", path,
                       names[c]);
    for (int k = 0; k < c; k++)
      if (strcmp(names[k], names[c]) == 0)
        return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "EXR write '%s': duplicate channel '%s'", path,
                         names[c]);
  }
  char tmp[4096];
  if (strlen(path) + 32 > sizeof tmp)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "EXR write: path too long: '%.64s...'", path);
  KPCN_TRY(kpcn_temp_path(tmp, sizeof tmp, path));

  exr_context_initializer_t init = kpcn_exr_initializer();
  exr_context_t ctx = NULL;
  exr_result_t rv = exr_start_write(&ctx, tmp, EXR_WRITE_FILE_DIRECTLY, &init);
  if (rv != EXR_ERR_SUCCESS) {
    exr_finish(&ctx);
    kpcn_abort_file(tmp);
    return kpcn_exr_fail(rv, KPCN_ERR_IO, "cannot create", path);
  }
  kpcn_status s = write_body(ctx, w, h, n, names, planes, opt, path);
  rv = exr_finish(&ctx); /* writes the chunk offset table */
  if (s == KPCN_OK && rv != EXR_ERR_SUCCESS)
    s = kpcn_exr_fail(rv, KPCN_ERR_IO, "cannot finish", path);
  if (s != KPCN_OK) {
    kpcn_abort_file(tmp);
    return s;
  }
  return kpcn_commit_file(tmp, path);
}

kpcn_status kpcn_exr_write_image(const char *path, const kpcn_image *img,
                                 const kpcn_exr_write_options *opt) {
  if (!img || !img->data || !img->names)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "EXR write '%s': NULL image", path ? path : "");
  if (img->nchannels <= 0 || img->nchannels > 4096)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "EXR write '%s': bad channel count %d",
                     path ? path : "", img->nchannels);
  const float *planes[4096];
  for (int c = 0; c < img->nchannels; c++)
    planes[c] = kpcn_image_plane(img, c);
  return kpcn_exr_write_planes(path, img->width, img->height, img->nchannels,
                               (const char *const *)img->names, planes, opt);
}
