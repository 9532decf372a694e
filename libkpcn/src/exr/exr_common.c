/* Opening EXR files, error mapping, header metadata (kpcn:spp ...). */
#include "exr/exr_internal.h"

#include "core/internal.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

/* OpenEXR delivers error messages on the thread that caused them, so a thread-local buffer
 * is enough to carry the detail into our own message without any printing. */
static _Thread_local char g_exr_msg[512];

static void capture_error(exr_const_context_t ctxt, exr_result_t code, const char *msg) {
  (void)ctxt;
  snprintf(g_exr_msg, sizeof g_exr_msg, "%s (%s)", msg ? msg : "",
           exr_get_error_code_as_string(code));
}

exr_context_initializer_t kpcn_exr_initializer(void) {
  exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
  init.error_handler_fn = capture_error;
  init.max_image_width = KPCN_MAX_DIM;
  init.max_image_height = KPCN_MAX_DIM;
  init.max_tile_width = KPCN_MAX_DIM;
  init.max_tile_height = KPCN_MAX_DIM;
  init.flags = EXR_CONTEXT_FLAG_DISABLE_CHUNK_RECONSTRUCTION;
  return init;
}

kpcn_status kpcn_exr_fail(exr_result_t rv, kpcn_status st, const char *what, const char *path) {
  const char *detail = g_exr_msg[0] ? g_exr_msg : exr_get_default_error_message(rv);
  kpcn_status s = kpcn_fail(st, "%s '%s': %s", what, path, detail);
  g_exr_msg[0] = 0;
  return s;
}

void kpcn_exr_record_error(kpcn_exr_chunk_error *e, kpcn_status st, int chunk) {
#pragma omp critical(kpcn_exr_chunk_error)
  if (e->st == KPCN_OK || chunk < e->chunk) {
    e->st = st;
    e->chunk = chunk;
    snprintf(e->msg, sizeof e->msg, "%s", kpcn_last_error());
  }
}

/* Compressions the OpenEXR Core library cannot decode, refused at open rather than read:
 * Debian 12's 3.1.5 has no DWAA/DWAB decoder (the pixel read failed as "corrupt"). (B44/B44A
 * files with two or more float channels were refused here until session 61: their chunks are
 * stored raw, which exr_read.c now reads as such.) */
static kpcn_status check_codec(exr_context_t ctx, const char *path) {
  exr_compression_t comp = EXR_COMPRESSION_NONE;
  if (exr_get_compression(ctx, 0, &comp) != EXR_ERR_SUCCESS) return KPCN_OK;
  int maj = 0, min = 0, patch = 0;
  exr_get_library_version(&maj, &min, &patch, NULL);
  if ((comp == EXR_COMPRESSION_DWAA || comp == EXR_COMPRESSION_DWAB) && maj * 100 + min < 302)
    return kpcn_fail(KPCN_ERR_UNSUPPORTED,
                     "'%s': %s compression cannot be decoded by this OpenEXR library (%d.%d.%d); "
                     "save it with another (oiiotool IN --compression zip -o OUT)",
                     path, comp == EXR_COMPRESSION_DWAA ? "DWAA" : "DWAB", maj, min, patch);
  return KPCN_OK;
}

kpcn_status kpcn_exr_open_read(const char *path, exr_context_t *ctx) {
  *ctx = NULL;
  if (!path || !*path) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "EXR read: empty file name");
  /* Check existence/readability ourselves so a missing file is an I/O error with errno text,
   * not a header-format error. */
  const char *why;
  FILE *f = kpcn_fopen_input(path, &why);
  if (!f) return kpcn_fail(KPCN_ERR_IO, "cannot open '%s': %s", path, why);
  struct stat st;
  const int statted = fstat(fileno(f), &st) == 0;
  fclose(f);
  if (!statted) return kpcn_fail(KPCN_ERR_IO, "cannot open '%s': %s", path, strerror(errno));
  if (st.st_size < 8)
    return kpcn_fail(KPCN_ERR_FORMAT, "'%s' is not an EXR file (%lld bytes)", path,
                     (long long)st.st_size);

  g_exr_msg[0] = 0;
  exr_context_initializer_t init = kpcn_exr_initializer();
  exr_result_t rv = exr_start_read(ctx, path, &init);
  if (rv != EXR_ERR_SUCCESS) {
    exr_finish(ctx);
    *ctx = NULL;
    if (rv == EXR_ERR_FILE_ACCESS) return kpcn_exr_fail(rv, KPCN_ERR_IO, "cannot open", path);
    if (rv == EXR_ERR_OUT_OF_MEMORY)
      return kpcn_exr_fail(rv, KPCN_ERR_OUT_OF_MEMORY, "cannot read", path);
    return kpcn_exr_fail(rv, KPCN_ERR_FORMAT, "not a valid EXR file", path);
  }
  exr_storage_t storage;
  exr_attr_box2i_t dw;
  const exr_attr_chlist_t *chl = NULL;
  kpcn_status s = KPCN_OK;
  if (exr_get_storage(*ctx, 0, &storage) != EXR_ERR_SUCCESS ||
      exr_get_data_window(*ctx, 0, &dw) != EXR_ERR_SUCCESS ||
      exr_get_channels(*ctx, 0, &chl) != EXR_ERR_SUCCESS || !chl)
    s = kpcn_fail(KPCN_ERR_FORMAT, "'%s': malformed EXR header (storage, data window or channels)",
                  path);
  else if (storage == EXR_STORAGE_DEEP_SCANLINE || storage == EXR_STORAGE_DEEP_TILED)
    s = kpcn_fail(KPCN_ERR_UNSUPPORTED, "'%s': deep EXR files are not supported", path);
  else if (chl->num_channels <= 0)
    s = kpcn_fail(KPCN_ERR_FORMAT, "'%s': EXR file has no channels", path);
  else {
    int64_t w = (int64_t)dw.max.x - dw.min.x + 1, h = (int64_t)dw.max.y - dw.min.y + 1;
    if (w <= 0 || h <= 0)
      s = kpcn_fail(KPCN_ERR_FORMAT, "'%s': empty data window (%lld x %lld)", path, (long long)w,
                    (long long)h);
    else if (kpcn_check_size((int)(w > KPCN_MAX_DIM ? KPCN_MAX_DIM + 1 : w),
                             (int)(h > KPCN_MAX_DIM ? KPCN_MAX_DIM + 1 : h), path) != KPCN_OK)
      s = kpcn_last_status();
    for (int c = 0; s == KPCN_OK && c < chl->num_channels; c++)
      if (chl->entries[c].x_sampling != 1 || chl->entries[c].y_sampling != 1)
        s = kpcn_fail(KPCN_ERR_UNSUPPORTED, "'%s': channel '%s' is subsampled (%dx%d)", path,
                      chl->entries[c].name.str, chl->entries[c].x_sampling,
                      chl->entries[c].y_sampling);
    if (s == KPCN_OK) s = check_codec(*ctx, path);
  }
  if (s != KPCN_OK) {
    exr_finish(ctx);
    *ctx = NULL;
  }
  return s;
}

static int attr_number(exr_context_t ctx, const char *name, double *out) {
  const exr_attribute_t *a = NULL;
  if (exr_get_attribute_by_name(ctx, 0, name, &a) != EXR_ERR_SUCCESS || !a) return 0;
  switch (a->type) {
  case EXR_ATTR_INT: *out = a->i; return 1;
  case EXR_ATTR_FLOAT: *out = a->f; return 1;
  case EXR_ATTR_DOUBLE: *out = a->d; return 1;
  case EXR_ATTR_STRING: {
    if (!a->string || !a->string->str || a->string->length <= 0) return 0;
    char buf[64], *end;
    int n = a->string->length < 63 ? a->string->length : 63;
    memcpy(buf, a->string->str, (size_t)n);
    buf[n] = 0;
    double v = strtod(buf, &end);
    if (end == buf) return 0;
    *out = v;
    return 1;
  }
  default: return 0;
  }
}

static void attr_string(exr_context_t ctx, const char *name, char *out, size_t outsz) {
  const exr_attribute_t *a = NULL;
  out[0] = 0;
  if (exr_get_attribute_by_name(ctx, 0, name, &a) != EXR_ERR_SUCCESS || !a) return;
  if (a->type == EXR_ATTR_STRING && a->string && a->string->str && a->string->length > 0) {
    size_t n = (size_t)a->string->length < outsz - 1 ? (size_t)a->string->length : outsz - 1;
    memcpy(out, a->string->str, n);
    out[n] = 0;
  } else if (a->type == EXR_ATTR_INT) {
    snprintf(out, outsz, "%d", a->i);
  }
}

int kpcn_exr_read_positive_int(exr_context_t ctx, const char *name) {
  double v;
  return attr_number(ctx, name, &v) && v > 0 && v < 2147483647.0 ? (int)v : 0;
}

void kpcn_exr_read_meta(exr_context_t ctx, int *spp, int64_t *seed, char *scene, size_t scenesz,
                        char *version, size_t versionsz) {
  double v;
  *spp = attr_number(ctx, "kpcn:spp", &v) && v >= 0 && v < 2147483647.0 ? (int)v : -1;
  /* seed: an int attribute when it fits in 32 bits, a decimal string otherwise (EXR has
   * no 64-bit integer attribute type). Parse strings exactly, not through double. */
  *seed = -1;
  char sbuf[64];
  attr_string(ctx, "kpcn:seed", sbuf, sizeof sbuf);
  if (sbuf[0]) { /* digits only, in range: "12abc" or "-5" is no seed (-1), not 12 or -5 */
    char *end;
    errno = 0;
    long long s = sbuf[0] >= '0' && sbuf[0] <= '9' ? strtoll(sbuf, &end, 10) : -1;
    if (s >= 0 && !*end && errno != ERANGE) *seed = s;
  } else if (attr_number(ctx, "kpcn:seed", &v) && v >= 0.0 && v < 9.2e18) {
    *seed = (int64_t)v; /* the cast of NaN or of a value past int64 is undefined */
  }
  attr_string(ctx, "kpcn:scene", scene, scenesz);
  attr_string(ctx, "kpcn:version", version, versionsz);
}
