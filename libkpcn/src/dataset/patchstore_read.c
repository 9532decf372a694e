/* Patch store reader: memory-maps the file and validates every offset and the JSON
 * metadata before handing out a single patch, so a truncated or foreign file is a clear
 * error rather than a crash in the trainer. */
#define _GNU_SOURCE
#include "core/internal.h"
#include "dataset/ps_internal.h"

#include <cjson/cJSON.h>
#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <math.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

struct kpcn_patchstore {
  char path[1024];
  const unsigned char *map;
  size_t size;
  kps_header h;
  char **channels;
  kpcn_patch_source *src;
  int nsrc;
};

void kpcn_patchstore_close(kpcn_patchstore *ps) {
  if (!ps) return;
  if (ps->map) munmap((void *)ps->map, ps->size);
  if (ps->channels)
    for (uint32_t c = 0; c < ps->h.nchannels; c++)
      free(ps->channels[c]);
  free(ps->channels);
  free(ps->src);
  free(ps);
}

static kpcn_status bad(kpcn_patchstore *ps, const char *path, const char *what) {
  kpcn_status s = kpcn_fail(KPCN_ERR_FORMAT, "patch store '%s': %s", path, what);
  kpcn_patchstore_close(ps);
  return s;
}

static void copy_str(char *dst, size_t n, const cJSON *o, const char *key) {
  const cJSON *v = cJSON_GetObjectItemCaseSensitive(o, key);
  snprintf(dst, n, "%s", cJSON_IsString(v) ? v->valuestring : "");
}
static double num(const cJSON *o, const char *key, double def) {
  const cJSON *v = cJSON_GetObjectItemCaseSensitive(o, key);
  return cJSON_IsNumber(v) ? v->valuedouble : def;
}

static kpcn_status parse_meta(kpcn_patchstore *ps, const char *path) {
  char *text = kpcn_alloc(ps->h.meta_length + 1, "patch store metadata");
  if (!text) return KPCN_ERR_OUT_OF_MEMORY;
  memcpy(text, ps->map + ps->h.meta_offset, ps->h.meta_length);
  text[ps->h.meta_length] = 0;
  cJSON *j = cJSON_Parse(text);
  free(text);
  kpcn_status st = KPCN_OK;
  const cJSON *fmt = j ? cJSON_GetObjectItemCaseSensitive(j, "format") : NULL;
  const cJSON *ch = j ? cJSON_GetObjectItemCaseSensitive(j, "channels") : NULL;
  const cJSON *srcs = j ? cJSON_GetObjectItemCaseSensitive(j, "sources") : NULL;
  if (!j) {
    st = kpcn_fail(KPCN_ERR_FORMAT, "patch store '%s': metadata is not valid JSON", path);
  } else if (!cJSON_IsString(fmt) || strcmp(fmt->valuestring, "kpcn-patchstore") != 0) {
    st = kpcn_fail(KPCN_ERR_FORMAT, "patch store '%s': metadata \"format\" is not kpcn-patchstore",
                   path);
  } else if (!cJSON_IsArray(ch) || cJSON_GetArraySize(ch) != (int)ps->h.nchannels) {
    st = kpcn_fail(KPCN_ERR_FORMAT,
                   "patch store '%s': metadata \"channels\" has %d names, header says %u", path,
                   cJSON_IsArray(ch) ? cJSON_GetArraySize(ch) : -1, ps->h.nchannels);
  } else if (!cJSON_IsArray(srcs)) {
    st = kpcn_fail(KPCN_ERR_FORMAT, "patch store '%s': metadata \"sources\" missing", path);
  } else if (num(j, "count", -1) != (double)ps->h.count ||
             num(j, "patch_size", -1) != ps->h.patch_size) {
    st = kpcn_fail(KPCN_ERR_FORMAT,
                   "patch store '%s': metadata count/patch_size disagree with the header", path);
  }
  if (st == KPCN_OK) {
    ps->channels = kpcn_calloc(ps->h.nchannels, sizeof(char *), "channel names");
    ps->nsrc = cJSON_GetArraySize(srcs);
    ps->src = kpcn_calloc((size_t)(ps->nsrc ? ps->nsrc : 1), sizeof *ps->src, "patch sources");
    if (!ps->channels || !ps->src) st = KPCN_ERR_OUT_OF_MEMORY;
  }
  for (uint32_t c = 0; st == KPCN_OK && c < ps->h.nchannels; c++) {
    const cJSON *v = cJSON_GetArrayItem(ch, (int)c);
    if (!cJSON_IsString(v) || !v->valuestring[0])
      st = kpcn_fail(KPCN_ERR_FORMAT, "patch store '%s': channels[%u] is not a name", path, c);
    else if (!(ps->channels[c] = strdup(v->valuestring)))
      st = kpcn_fail(KPCN_ERR_OUT_OF_MEMORY, "out of memory for the channel names");
  }
  for (int i = 0; st == KPCN_OK && i < ps->nsrc; i++) {
    const cJSON *o = cJSON_GetArrayItem(srcs, i);
    kpcn_patch_source *s = &ps->src[i];
    if (!cJSON_IsObject(o)) {
      st = kpcn_fail(KPCN_ERR_FORMAT, "patch store '%s': sources[%d] is not an object", path, i);
      break;
    }
    copy_str(s->scene, sizeof s->scene, o, "scene");
    copy_str(s->split, sizeof s->split, o, "split");
    copy_str(s->noisy, sizeof s->noisy, o, "noisy");
    copy_str(s->reference, sizeof s->reference, o, "reference");
    s->variant = (int)num(o, "variant", 0);
    s->spp = (int)num(o, "spp", -1);
    s->ref_spp = (int)num(o, "ref_spp", -1);
    s->width = (int)num(o, "width", 0);
    s->height = (int)num(o, "height", 0);
    s->depth_min = (float)num(o, "depth_min", 0);
    s->depth_max = (float)num(o, "depth_max", 0);
    s->depth_mean = (float)num(o, "depth_mean", 0);
    s->depth_std = (float)num(o, "depth_std", 0);
    s->exposure = num(o, "exposure", 0); /* absent in stores written before it existed */
    if (!(s->exposure >= 0.0) || !isfinite(s->exposure)) {
      st = kpcn_fail(KPCN_ERR_FORMAT, "patch store '%s': sources[%d].exposure %g is not >= 0", path,
                     i, s->exposure);
      break;
    }
  }
  cJSON_Delete(j);
  return st;
}

kpcn_status kpcn_patchstore_open(kpcn_patchstore **out, const char *path,
                                 const char *const *expected, int nexpected) {
  if (!out || !path) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_patchstore_open: NULL");
  *out = NULL;
  kpcn_patchstore *ps = kpcn_calloc(1, sizeof *ps, "patch store");
  if (!ps) return KPCN_ERR_OUT_OF_MEMORY;
  snprintf(ps->path, sizeof ps->path, "%s", path);
  int fd = open(path, O_RDONLY | O_NONBLOCK | O_CLOEXEC); /* a FIFO: refused below, not waited on */
  if (fd < 0) {
    int e = errno;
    kpcn_patchstore_close(ps);
    return kpcn_fail(KPCN_ERR_IO, "cannot open patch store '%s': %s", path, strerror(e));
  }
  struct stat sb;
  if (fstat(fd, &sb) != 0 || !S_ISREG(sb.st_mode)) {
    close(fd);
    kpcn_patchstore_close(ps);
    return kpcn_fail(KPCN_ERR_IO, "patch store '%s' is not a regular file", path);
  }
  ps->size = (size_t)sb.st_size;
  if (ps->size < KPS_HEADER_BYTES) {
    close(fd);
    return bad(ps, path, "file too short for the header (truncated or not a patch store)");
  }
  void *m = mmap(NULL, ps->size, PROT_READ, MAP_SHARED, fd, 0);
  int e = errno;
  close(fd);
  if (m == MAP_FAILED) {
    kpcn_patchstore_close(ps);
    return kpcn_fail(KPCN_ERR_IO, "cannot map patch store '%s': %s", path, strerror(e));
  }
  ps->map = m;
  kps_get_header(&ps->h, ps->map);
  kps_header *h = &ps->h;
  if (memcmp(h->magic, KPS_MAGIC, 8) != 0)
    return bad(ps, path, "wrong magic (not a kpcn patch store)");
  if (h->version != KPCN_PATCHSTORE_VERSION) {
    kpcn_status s =
        kpcn_fail(KPCN_ERR_UNSUPPORTED, "patch store '%s': format version %u, this build reads %d",
                  path, h->version, KPCN_PATCHSTORE_VERSION);
    kpcn_patchstore_close(ps);
    return s;
  }
  size_t ds = kps_dtype_size(h->dtype);
  if (!ds) return bad(ps, path, "unknown dtype code");
  if (h->patch_size == 0 || h->patch_size > 4096 || h->nchannels == 0 || h->nchannels > 1024)
    return bad(ps, path, "patch size or channel count out of range");
  uint64_t pb = (uint64_t)h->nchannels * h->patch_size * h->patch_size * ds;
  if (h->patch_bytes != pb)
    return bad(ps, path, "patch_bytes disagrees with channels x size^2 x dtype");
  if (h->count > (UINT64_MAX - KPCN_PATCHSTORE_DATA_OFFSET) / (pb + KPS_RECORD_BYTES))
    return bad(ps, path, "patch count absurd");
  if (h->index_offset != KPCN_PATCHSTORE_DATA_OFFSET + h->count * pb ||
      h->meta_offset != h->index_offset + h->count * KPS_RECORD_BYTES)
    return bad(ps, path, "index/metadata offsets disagree with the patch count");
  /* each piece against the file size: their sum may wrap past 2^64 in a crafted header */
  if (h->meta_length > ((uint64_t)1 << 31) || h->meta_offset > ps->size ||
      h->meta_length > ps->size - h->meta_offset) {
    kpcn_status s = kpcn_fail(
        KPCN_ERR_FORMAT,
        "patch store '%s': truncated (file has %zu bytes, header needs metadata of %llu bytes at "
        "offset %llu)",
        path, ps->size, (unsigned long long)h->meta_length, (unsigned long long)h->meta_offset);
    kpcn_patchstore_close(ps);
    return s;
  }
  if (h->meta_offset != ps->size - h->meta_length)
    return bad(ps, path, "trailing bytes after the metadata");
  kpcn_status st = parse_meta(ps, path);
  if (st != KPCN_OK) {
    kpcn_patchstore_close(ps);
    return st;
  }
  for (uint64_t i = 0; i < h->count; i++) {
    kpcn_patch_record r;
    kps_get_record(&r, ps->map + h->index_offset + i * KPS_RECORD_BYTES);
    if (r.source >= (uint32_t)ps->nsrc)
      st = kpcn_fail(KPCN_ERR_FORMAT, "patch store '%s': patch %llu names source %u of %d", path,
                     (unsigned long long)i, r.source, ps->nsrc);
    else if (!(r.flat_frac >= 0.0f && r.flat_frac <= 1.0f) || !(r.weight > 0.0f) ||
             !isfinite(r.weight) || r.flags != 0)
      st = kpcn_fail(KPCN_ERR_FORMAT,
                     "patch store '%s': patch %llu has an invalid record (flat fraction %g, "
                     "weight %g, flags %u)",
                     path, (unsigned long long)i, (double)r.flat_frac, (double)r.weight, r.flags);
    if (st != KPCN_OK) {
      kpcn_patchstore_close(ps);
      return st;
    }
  }
  if (expected) {
    int n = nexpected;
    for (int c = 0; c < n || c < (int)h->nchannels; c++) {
      const char *a = c < (int)h->nchannels ? ps->channels[c] : "(none)";
      const char *b = c < n ? expected[c] : "(none)";
      if (strcmp(a, b) != 0) {
        st = kpcn_fail(
            KPCN_ERR_FORMAT,
            "patch store '%s': channel list mismatch at %d: store has '%s', expected '%s' "
            "(store %u channels, expected %d)",
            path, c, a, b, h->nchannels, n);
        kpcn_patchstore_close(ps);
        return st;
      }
    }
  }
  *out = ps;
  return KPCN_OK;
}

uint64_t kpcn_patchstore_count(const kpcn_patchstore *ps) { return ps ? ps->h.count : 0; }
int kpcn_patchstore_patch_size(const kpcn_patchstore *ps) { return ps ? (int)ps->h.patch_size : 0; }
int kpcn_patchstore_nchannels(const kpcn_patchstore *ps) { return ps ? (int)ps->h.nchannels : 0; }
kpcn_dtype kpcn_patchstore_dtype(const kpcn_patchstore *ps) { return (kpcn_dtype)ps->h.dtype; }
const char *const *kpcn_patchstore_channels(const kpcn_patchstore *ps) {
  return (const char *const *)ps->channels;
}
int kpcn_patchstore_find_channel(const kpcn_patchstore *ps, const char *name) {
  for (uint32_t c = 0; ps && name && c < ps->h.nchannels; c++)
    if (strcmp(ps->channels[c], name) == 0) return (int)c;
  return -1;
}
int kpcn_patchstore_nsources(const kpcn_patchstore *ps) { return ps ? ps->nsrc : 0; }
const kpcn_patch_source *kpcn_patchstore_source(const kpcn_patchstore *ps, int i) {
  return ps && i >= 0 && i < ps->nsrc ? &ps->src[i] : NULL;
}

kpcn_status kpcn_patchstore_exposure(const kpcn_patchstore *ps, double *median) {
  if (!ps || !median) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "patchstore_exposure: NULL");
  *median = 0.0;
  double *v = kpcn_alloc(sizeof(double) * (size_t)(ps->nsrc ? ps->nsrc : 1), "exposures");
  if (!v) return KPCN_ERR_OUT_OF_MEMORY;
  int any_train = 0;
  size_t n = 0;
  for (int i = 0; i < ps->nsrc; i++)
    any_train |= strcmp(ps->src[i].split, "train") == 0;
  for (int i = 0; i < ps->nsrc; i++)
    if ((!any_train || strcmp(ps->src[i].split, "train") == 0) && ps->src[i].exposure > 0.0)
      v[n++] = ps->src[i].exposure;
  *median = kpcn_median_inplace(v, n);
  free(v);
  return KPCN_OK;
}

const void *kpcn_patchstore_raw(const kpcn_patchstore *ps, uint64_t i) {
  if (!ps || i >= ps->h.count) return NULL;
  return ps->map + KPCN_PATCHSTORE_DATA_OFFSET + i * ps->h.patch_bytes;
}

kpcn_status kpcn_patchstore_record(const kpcn_patchstore *ps, uint64_t i, kpcn_patch_record *rec) {
  if (!ps || !rec) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_patchstore_record: NULL");
  if (i >= ps->h.count)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "patch store '%s': patch %llu of %llu", ps->path,
                     (unsigned long long)i, (unsigned long long)ps->h.count);
  kps_get_record(rec, ps->map + ps->h.index_offset + i * KPS_RECORD_BYTES);
  return KPCN_OK;
}

kpcn_status kpcn_patchstore_get(const kpcn_patchstore *ps, uint64_t i, float *dst,
                                kpcn_patch_record *rec) {
  if (!ps || !dst) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_patchstore_get: NULL");
  if (i >= ps->h.count)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "patch store '%s': patch %llu of %llu", ps->path,
                     (unsigned long long)i, (unsigned long long)ps->h.count);
  const unsigned char *p = kpcn_patchstore_raw(ps, i);
  size_t n = (size_t)ps->h.nchannels * ps->h.patch_size * ps->h.patch_size;
  if (ps->h.dtype == KPCN_DTYPE_F32) {
    for (size_t k = 0; k < n; k++) {
      uint32_t u = (uint32_t)p[4 * k] | (uint32_t)p[4 * k + 1] << 8 | (uint32_t)p[4 * k + 2] << 16 |
                   (uint32_t)p[4 * k + 3] << 24;
      memcpy(&dst[k], &u, 4);
    }
  } else {
    for (size_t k = 0; k < n; k++)
      dst[k] = kpcn_half_to_float((uint16_t)(p[2 * k] | p[2 * k + 1] << 8));
  }
  return rec ? kpcn_patchstore_record(ps, i, rec) : KPCN_OK;
}
