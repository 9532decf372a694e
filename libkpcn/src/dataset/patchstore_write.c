/* Patch store writer: patches stream to a temp file after a 4096-byte header gap; the
 * index and JSON metadata are appended by finish, the header is written last and the
 * file renamed into place, so a crash never leaves a store that looks complete. */
#define _GNU_SOURCE
#include "core/internal.h"
#include "dataset/ps_internal.h"

#include <cjson/cJSON.h>
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

const char *const kpcn_patchstore_default_channels[KPCN_PATCHSTORE_NUM_DEFAULT + 1] = {
    "R",
    "G",
    "B",
    "diffuse.R",
    "diffuse.G",
    "diffuse.B",
    "specular.R",
    "specular.G",
    "specular.B",
    "albedo.R",
    "albedo.G",
    "albedo.B",
    "N.X",
    "N.Y",
    "N.Z",
    "Z",
    "visibility.V",
    "color.var",
    "diffuse.var",
    "specular.var",
    "albedo.var",
    "N.var",
    "Z.var",
    "visibility.var",
    "ref.R",
    "ref.G",
    "ref.B",
    "ref.diffuse.R",
    "ref.diffuse.G",
    "ref.diffuse.B",
    "ref.specular.R",
    "ref.specular.G",
    "ref.specular.B",
    NULL};

/* ---- little-endian helpers ---- */
static void put_le(unsigned char *p, uint64_t v, int nbytes) {
  for (int i = 0; i < nbytes; i++)
    p[i] = (unsigned char)(v >> (8 * i));
}
static uint64_t get_le(const unsigned char *p, int nbytes) {
  uint64_t v = 0;
  for (int i = 0; i < nbytes; i++)
    v |= (uint64_t)p[i] << (8 * i);
  return v;
}
static void put32(unsigned char *p, uint32_t v) { put_le(p, v, 4); }
static void put64(unsigned char *p, uint64_t v) { put_le(p, v, 8); }
static uint32_t get32(const unsigned char *p) { return (uint32_t)get_le(p, 4); }
static uint64_t get64(const unsigned char *p) { return get_le(p, 8); }
static uint32_t fbits(float f) {
  uint32_t u;
  memcpy(&u, &f, 4);
  return u;
}
static float bitsf(uint32_t u) {
  float f;
  memcpy(&f, &u, 4);
  return f;
}

void kps_put_header(unsigned char o[KPS_HEADER_BYTES], const kps_header *h) {
  memset(o, 0, KPS_HEADER_BYTES);
  memcpy(o, h->magic, 8);
  put32(o + 8, h->version);
  put32(o + 12, h->dtype);
  put32(o + 16, h->patch_size);
  put32(o + 20, h->nchannels);
  put64(o + 24, h->count);
  put64(o + 32, h->patch_bytes);
  put64(o + 40, h->index_offset);
  put64(o + 48, h->meta_offset);
  put64(o + 56, h->meta_length);
}
void kps_get_header(kps_header *h, const unsigned char in[KPS_HEADER_BYTES]) {
  memcpy(h->magic, in, 8);
  h->version = get32(in + 8);
  h->dtype = get32(in + 12);
  h->patch_size = get32(in + 16);
  h->nchannels = get32(in + 20);
  h->count = get64(in + 24);
  h->patch_bytes = get64(in + 32);
  h->index_offset = get64(in + 40);
  h->meta_offset = get64(in + 48);
  h->meta_length = get64(in + 56);
}
void kps_put_record(unsigned char o[KPS_RECORD_BYTES], const kpcn_patch_record *r) {
  put32(o, r->source);
  put32(o + 4, (uint32_t)r->x);
  put32(o + 8, (uint32_t)r->y);
  put32(o + 12, r->flags);
  put32(o + 16, fbits(r->flat_frac));
  put32(o + 20, fbits(r->weight));
  put64(o + 24, r->reserved);
}
void kps_get_record(kpcn_patch_record *r, const unsigned char in[KPS_RECORD_BYTES]) {
  r->source = get32(in);
  r->x = (int32_t)get32(in + 4);
  r->y = (int32_t)get32(in + 8);
  r->flags = get32(in + 12);
  r->flat_frac = bitsf(get32(in + 16));
  r->weight = bitsf(get32(in + 20));
  r->reserved = get64(in + 24);
}
size_t kps_dtype_size(uint32_t dtype) {
  return dtype == KPCN_DTYPE_F32 ? 4 : dtype == KPCN_DTYPE_F16 ? 2 : 0;
}

/* ---- IEEE half ---- */
uint16_t kpcn_float_to_half(float f) {
  uint32_t x = fbits(f);
  uint32_t sign = (x >> 16) & 0x8000u;
  uint32_t absx = x & 0x7fffffffu;
  if (absx >= 0x7f800000u) /* Inf or NaN (keep a quiet NaN) */
    return (uint16_t)(sign | 0x7c00u | (absx > 0x7f800000u ? 0x200u : 0));
  if (absx >= 0x477ff000u) return (uint16_t)(sign | 0x7c00u); /* overflow -> Inf */
  if (absx < 0x38800000u) {                                   /* subnormal or zero */
    if (absx < 0x33000000u) return (uint16_t)sign;
    uint32_t mant = (absx & 0x7fffffu) | 0x800000u;
    int shift = 126 - (int)(absx >> 23); /* value = h * 2^-24 */
    uint32_t h = mant >> shift;
    uint32_t rem = mant & ((1u << shift) - 1), half = 1u << (shift - 1);
    if (rem > half || (rem == half && (h & 1))) h++;
    return (uint16_t)(sign | h);
  }
  uint32_t h = ((absx - 0x38000000u) >> 13);
  uint32_t rem = absx & 0x1fffu;
  if (rem > 0x1000u || (rem == 0x1000u && (h & 1))) h++;
  return (uint16_t)(sign | h);
}

float kpcn_half_to_float(uint16_t h) {
  uint32_t sign = (uint32_t)(h & 0x8000u) << 16;
  uint32_t e = (h >> 10) & 0x1fu, m = h & 0x3ffu;
  if (e == 0) {
    float v = (float)m * (1.0f / 16777216.0f); /* m * 2^-24 */
    return sign ? -v : v;
  }
  if (e == 31) return bitsf(sign | 0x7f800000u | (m << 13));
  return bitsf(sign | ((e + 112u) << 23) | (m << 13));
}

/* ---- writer ---- */
struct kpcn_patchstore_writer {
  char path[4096];
  char tmp[4200];
  FILE *f;
  int S, C;
  kpcn_dtype dtype;
  char **channels;
  char *settings_json;
  kpcn_patch_source *src;
  uint32_t nsrc, capsrc;
  kpcn_patch_record *rec;
  uint64_t nrec, caprec;
  void *conv; /* one patch converted to dtype */
  float *tmpf;
  int64_t cand, kept, culled;
};

void kpcn_patchstore_settings_defaults(kpcn_patchstore_settings *s) {
  memset(s, 0, sizeof *s);
  s->patch_size = 65;
  s->dtype = KPCN_DTYPE_F32;
}

static void free_writer(kpcn_patchstore_writer *w) {
  if (!w) return;
  if (w->f) fclose(w->f);
  if (w->channels)
    for (int c = 0; c < w->C; c++)
      free(w->channels[c]);
  free(w->channels);
  free(w->settings_json);
  free(w->src);
  free(w->rec);
  free(w->conv);
  free(w->tmpf);
  free(w);
}

kpcn_status kpcn_patchstore_create(kpcn_patchstore_writer **out, const char *path,
                                   const kpcn_patchstore_settings *s) {
  if (!out || !path || !s)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_patchstore_create: NULL argument");
  *out = NULL;
  if (s->patch_size <= 0 || s->patch_size > 4096)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "patch store '%s': patch size %d not in [1, 4096]",
                     path, s->patch_size);
  if (!kps_dtype_size((uint32_t)s->dtype))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "patch store '%s': unknown dtype %d", path,
                     (int)s->dtype);
  const char *const *names = s->channels ? s->channels : kpcn_patchstore_default_channels;
  int C = s->channels ? s->nchannels : KPCN_PATCHSTORE_NUM_DEFAULT;
  if (C <= 0 || C > 1024)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "patch store '%s': %d channels (1 to 1024)", path,
                     C);
  if (strlen(path) >= 4000)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "patch store path too long (%zu bytes, at most 3999)", strlen(path));
  char tmp[sizeof((kpcn_patchstore_writer *)0)->tmp];
  KPCN_TRY(kpcn_temp_path(tmp, sizeof tmp, path));
  kpcn_patchstore_writer *w = kpcn_calloc(1, sizeof *w, "patch store writer");
  if (!w) return KPCN_ERR_OUT_OF_MEMORY;
  snprintf(w->path, sizeof w->path, "%s", path);
  memcpy(w->tmp, tmp, sizeof tmp);
  w->S = s->patch_size;
  w->C = C;
  w->dtype = s->dtype;
  w->channels = kpcn_calloc((size_t)C, sizeof(char *), "channel names");
  size_t pe = (size_t)C * (size_t)w->S * (size_t)w->S;
  w->conv = kpcn_alloc(pe * kps_dtype_size((uint32_t)w->dtype), "patch buffer");
  w->tmpf = kpcn_alloc(pe * sizeof(float), "patch buffer");
  if (!w->channels || !w->conv || !w->tmpf) {
    free_writer(w);
    return KPCN_ERR_OUT_OF_MEMORY;
  }
  for (int c = 0; c < C; c++) {
    if (!names[c] || !names[c][0] || strlen(names[c]) > 63) {
      free_writer(w);
      return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "patch store '%s': channel %d has no valid name",
                       path, c);
    }
    w->channels[c] = strdup(names[c]);
  }
  if (s->settings_json) {
    cJSON *j = cJSON_Parse(s->settings_json);
    int ok = j && cJSON_IsObject(j);
    cJSON_Delete(j);
    if (!ok) {
      free_writer(w);
      return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                       "patch store '%s': settings_json is not a JSON object", path);
    }
    w->settings_json = strdup(s->settings_json);
  }
  w->f = fopen(w->tmp, "wb");
  if (!w->f) {
    int e = errno;
    free_writer(w);
    return kpcn_fail(KPCN_ERR_IO, "cannot create '%s': %s", w->tmp, strerror(e));
  }
  static const unsigned char zero[KPCN_PATCHSTORE_DATA_OFFSET];
  if (fwrite(zero, 1, sizeof zero, w->f) != sizeof zero) {
    kpcn_patchstore_abort(w);
    return kpcn_fail(KPCN_ERR_IO, "cannot write '%s'", path);
  }
  *out = w;
  return KPCN_OK;
}

kpcn_status kpcn_patchstore_add_source(kpcn_patchstore_writer *w, const kpcn_patch_source *src,
                                       uint32_t *id) {
  if (!w || !src) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_patchstore_add_source: NULL");
  if (w->nsrc == w->capsrc) {
    uint32_t cap = w->capsrc ? 2 * w->capsrc : 16;
    kpcn_patch_source *n = realloc(w->src, sizeof *n * cap);
    if (!n) return kpcn_fail(KPCN_ERR_OUT_OF_MEMORY, "out of memory for the patch store sources");
    w->src = n;
    w->capsrc = cap;
  }
  w->src[w->nsrc] = *src;
  kpcn_patch_source *d = &w->src[w->nsrc];
  d->scene[sizeof d->scene - 1] = d->split[sizeof d->split - 1] = 0;
  d->noisy[sizeof d->noisy - 1] = d->reference[sizeof d->reference - 1] = 0;
  if (id) *id = w->nsrc;
  w->nsrc++;
  return KPCN_OK;
}

kpcn_status kpcn_patchstore_append(kpcn_patchstore_writer *w, const kpcn_patch_record *rec,
                                   const float *planes) {
  if (!w || !rec || !planes)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_patchstore_append: NULL argument");
  if (rec->source >= w->nsrc)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "patch store '%s': source id %u not registered (%u sources)", w->path,
                     rec->source, w->nsrc);
  size_t pe = (size_t)w->C * (size_t)w->S * (size_t)w->S;
  for (size_t i = 0; i < pe; i++)
    if (!isfinite(planes[i]))
      return kpcn_fail(KPCN_ERR_NONFINITE,
                       "patch store '%s': non-finite value in channel '%s' of patch %llu", w->path,
                       w->channels[i / ((size_t)w->S * w->S)], (unsigned long long)w->nrec);
    else if (w->dtype == KPCN_DTYPE_F16 && fabsf(planes[i]) > 65504.0f)
      /* would be stored as Inf, which training then refuses */
      return kpcn_fail(KPCN_ERR_NONFINITE,
                       "patch store '%s': value %g in channel '%s' of patch %llu overflows "
                       "float16 (max 65504); write the store as f32",
                       w->path, (double)planes[i], w->channels[i / ((size_t)w->S * w->S)],
                       (unsigned long long)w->nrec);
  if (w->dtype == KPCN_DTYPE_F32) {
    unsigned char *o = w->conv;
    for (size_t i = 0; i < pe; i++)
      put32(o + 4 * i, fbits(planes[i]));
  } else {
    unsigned char *o = w->conv;
    for (size_t i = 0; i < pe; i++) {
      uint16_t h = kpcn_float_to_half(planes[i]);
      o[2 * i] = (unsigned char)h;
      o[2 * i + 1] = (unsigned char)(h >> 8);
    }
  }
  size_t bytes = pe * kps_dtype_size((uint32_t)w->dtype);
  if (fwrite(w->conv, 1, bytes, w->f) != bytes)
    return kpcn_fail(KPCN_ERR_IO, "patch store '%s': write failed: %s", w->path,
                     kpcn_write_reason(errno));
  if (w->nrec == w->caprec) {
    uint64_t cap = w->caprec ? 2 * w->caprec : 1024;
    kpcn_patch_record *n = realloc(w->rec, sizeof *n * cap);
    if (!n) return kpcn_fail(KPCN_ERR_OUT_OF_MEMORY, "out of memory for the patch store index");
    w->rec = n;
    w->caprec = cap;
  }
  w->rec[w->nrec++] = *rec;
  return KPCN_OK;
}

/* Finds the plane of a canonical channel name in an AOV set. */
static const float *aov_plane(const kpcn_aov_set *s, const char *name) {
  size_t np = kpcn_aov_plane_size(s);
  for (int b = 0; b < KPCN_BUF_COUNT; b++) {
    for (int c = 0; c < kpcn_buffer_channels((kpcn_buffer)b); c++)
      if (s->buf[b] && strcmp(kpcn_buffer_channel_name((kpcn_buffer)b, c), name) == 0)
        return s->buf[b] + (size_t)c * np;
    if (s->var[b] && strcmp(kpcn_buffer_variance_name((kpcn_buffer)b), name) == 0) return s->var[b];
  }
  return NULL;
}

kpcn_status kpcn_patchstore_append_aov(kpcn_patchstore_writer *w, const kpcn_patch_record *rec,
                                       const kpcn_aov_set *noisy, const kpcn_aov_set *ref) {
  if (!w || !rec || !noisy)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_patchstore_append_aov: NULL argument");
  int S = w->S;
  if (rec->x < 0 || rec->y < 0 || rec->x > noisy->width - S || rec->y > noisy->height - S)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "patch %dx%d at (%d,%d) outside the %dx%d image", S,
                     S, rec->x, rec->y, noisy->width, noisy->height);
  if (ref && (ref->width != noisy->width || ref->height != noisy->height))
    return kpcn_fail(KPCN_ERR_SIZE_MISMATCH, "reference %dx%d vs noisy %dx%d", ref->width,
                     ref->height, noisy->width, noisy->height);
  for (int c = 0; c < w->C; c++) {
    const char *nm = w->channels[c];
    int is_ref = strncmp(nm, "ref.", 4) == 0;
    const kpcn_aov_set *s = is_ref ? ref : noisy;
    const float *p = s ? aov_plane(s, is_ref ? nm + 4 : nm) : NULL;
    if (!p)
      return kpcn_fail(KPCN_ERR_MISSING_CHANNEL,
                       "patch store: channel '%s' missing in the %s image%s%s%s", nm,
                       is_ref ? "reference" : "noisy", s && s->scene[0] ? " (rendered from " : "",
                       s && s->scene[0] ? s->scene : "", s && s->scene[0] ? ")" : "");
    for (int y = 0; y < S; y++)
      memcpy(w->tmpf + ((size_t)c * S + y) * S,
             p + (size_t)(rec->y + y) * (size_t)noisy->width + (size_t)rec->x, sizeof(float) * S);
  }
  return kpcn_patchstore_append(w, rec, w->tmpf);
}

void kpcn_patchstore_add_stats(kpcn_patchstore_writer *w, int64_t candidates, int64_t kept,
                               int64_t culled) {
  if (!w) return;
  w->cand += candidates;
  w->kept += kept;
  w->culled += culled;
}

static cJSON *meta_json(const kpcn_patchstore_writer *w) {
  cJSON *j = cJSON_CreateObject();
  cJSON_AddStringToObject(j, "format", "kpcn-patchstore");
  cJSON_AddNumberToObject(j, "version", KPCN_PATCHSTORE_VERSION);
  cJSON_AddStringToObject(j, "dtype", w->dtype == KPCN_DTYPE_F32 ? "float32" : "float16");
  cJSON_AddNumberToObject(j, "patch_size", w->S);
  cJSON_AddItemToObject(j, "channels",
                        cJSON_CreateStringArray((const char *const *)w->channels, w->C));
  cJSON_AddNumberToObject(j, "count", (double)w->nrec);
  cJSON *srcs = cJSON_AddArrayToObject(j, "sources");
  for (uint32_t i = 0; i < w->nsrc; i++) {
    const kpcn_patch_source *s = &w->src[i];
    cJSON *o = cJSON_CreateObject();
    cJSON_AddStringToObject(o, "scene", s->scene);
    cJSON_AddNumberToObject(o, "variant", s->variant);
    cJSON_AddStringToObject(o, "split", s->split);
    cJSON_AddNumberToObject(o, "spp", s->spp);
    cJSON_AddNumberToObject(o, "ref_spp", s->ref_spp);
    cJSON_AddNumberToObject(o, "width", s->width);
    cJSON_AddNumberToObject(o, "height", s->height);
    cJSON_AddNumberToObject(o, "depth_min", s->depth_min);
    cJSON_AddNumberToObject(o, "depth_max", s->depth_max);
    cJSON_AddNumberToObject(o, "depth_mean", s->depth_mean);
    cJSON_AddNumberToObject(o, "depth_std", s->depth_std);
    if (s->exposure > 0.0) cJSON_AddNumberToObject(o, "exposure", s->exposure);
    cJSON_AddStringToObject(o, "noisy", s->noisy);
    cJSON_AddStringToObject(o, "reference", s->reference);
    cJSON_AddItemToArray(srcs, o);
  }
  cJSON *st = cJSON_AddObjectToObject(j, "stats");
  cJSON_AddNumberToObject(st, "candidates", (double)w->cand);
  cJSON_AddNumberToObject(st, "kept", (double)w->kept);
  cJSON_AddNumberToObject(st, "culled", (double)w->culled);
  cJSON_AddItemToObject(j, "settings",
                        w->settings_json ? cJSON_Parse(w->settings_json) : cJSON_CreateObject());
  return j;
}

kpcn_status kpcn_patchstore_finish(kpcn_patchstore_writer *w) {
  if (!w) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_patchstore_finish: NULL writer");
  kps_header h;
  memcpy(h.magic, KPS_MAGIC, 8);
  h.version = KPCN_PATCHSTORE_VERSION;
  h.dtype = (uint32_t)w->dtype;
  h.patch_size = (uint32_t)w->S;
  h.nchannels = (uint32_t)w->C;
  h.count = w->nrec;
  h.patch_bytes = (uint64_t)w->C * w->S * w->S * kps_dtype_size(h.dtype);
  h.index_offset = KPCN_PATCHSTORE_DATA_OFFSET + h.count * h.patch_bytes;
  h.meta_offset = h.index_offset + h.count * KPS_RECORD_BYTES;
  cJSON *j = meta_json(w);
  char *text = j ? cJSON_PrintUnformatted(j) : NULL;
  cJSON_Delete(j);
  kpcn_status st = KPCN_OK;
  if (!text) {
    st = kpcn_fail(KPCN_ERR_OUT_OF_MEMORY, "patch store '%s': out of memory for the metadata",
                   w->path);
    goto fail;
  }
  h.meta_length = strlen(text);
  for (uint64_t i = 0; i < w->nrec; i++) {
    unsigned char r[KPS_RECORD_BYTES];
    kps_put_record(r, &w->rec[i]);
    if (fwrite(r, 1, sizeof r, w->f) != sizeof r) goto io;
  }
  if (fwrite(text, 1, h.meta_length, w->f) != h.meta_length) goto io;
  unsigned char hb[KPS_HEADER_BYTES];
  kps_put_header(hb, &h);
  if (fseek(w->f, 0, SEEK_SET) != 0 || fwrite(hb, 1, sizeof hb, w->f) != sizeof hb) goto io;
  if (fflush(w->f) != 0 || ferror(w->f)) goto io;
  int rc = fclose(w->f);
  w->f = NULL;
  if (rc != 0) goto io;
  free(text);
  text = NULL;
  st = kpcn_commit_file(w->tmp, w->path);
  free_writer(w);
  return st;
io: /* straight after the failing call, so errno is its reason */
  st = kpcn_fail(KPCN_ERR_IO, "patch store '%s': write failed: %s", w->path,
                 kpcn_write_reason(errno));
fail:
  free(text);
  kpcn_patchstore_abort(w);
  return st;
}

void kpcn_patchstore_abort(kpcn_patchstore_writer *w) {
  if (!w) return;
  if (w->f) {
    fclose(w->f);
    w->f = NULL;
  }
  kpcn_abort_file(w->tmp);
  free_writer(w);
}

kpcn_status kpcn_patch_source_image_stats(kpcn_patch_source *src, const kpcn_aov_set *noisy) {
  if (!src || !noisy) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "depth stats: NULL");
  KPCN_TRY(
      kpcn_aov_require(noisy, KPCN_BUF_DEPTH, 0, noisy->scene[0] ? noisy->scene : "noisy image"));
  size_t n = kpcn_aov_plane_size(noisy);
  const float *z = noisy->buf[KPCN_BUF_DEPTH];
  double mn = INFINITY, mx = -INFINITY, s = 0, s2 = 0;
  for (size_t i = 0; i < n; i++) {
    double v = z[i];
    if (!isfinite(v))
      return kpcn_fail(KPCN_ERR_NONFINITE, "depth stats: non-finite Z at pixel %zu", i);
    mn = v < mn ? v : mn;
    mx = v > mx ? v : mx;
    s += v;
    s2 += v * v;
  }
  double mean = s / (double)n, var = s2 / (double)n - mean * mean;
  src->depth_min = (float)mn;
  src->depth_max = (float)mx;
  src->depth_mean = (float)mean;
  src->depth_std = (float)sqrt(var > 0 ? var : 0);
  src->width = noisy->width;
  src->height = noisy->height;
  src->exposure = 0.0;
  if (noisy->buf[KPCN_BUF_DIFFUSE] && noisy->buf[KPCN_BUF_SPECULAR])
    KPCN_TRY(kpcn_aov_exposure(noisy, &src->exposure));
  return KPCN_OK;
}
