/* Planar float images with named channels, and AOV sets (kpcn/image.h). */
#include "kpcn/image.h"

#include "core/internal.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- kpcn_image ---- */

static char *dup_str(const char *s) {
  size_t n = strlen(s) + 1;
  char *p = kpcn_alloc(n, "channel name");
  if (p) memcpy(p, s, n);
  return p;
}

kpcn_status kpcn_image_create(kpcn_image **out, int width, int height, int nchannels,
                              const char *const *names) {
  if (!out) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_image_create: out is NULL");
  *out = NULL;
  KPCN_TRY(kpcn_check_size(width, height, "kpcn_image_create"));
  if (nchannels <= 0 || nchannels > 4096)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_image_create: bad channel count %d",
                     nchannels);
  size_t plane = (size_t)width * (size_t)height;
  /* Guard the product before it reaches the allocator: 2^28 pixels x 4096 channels x 4 bytes
   * would be 4 TiB, which calloc would only refuse after trying. */
  if ((double)plane * nchannels * sizeof(float) > 64.0 * 1024 * 1024 * 1024)
    return kpcn_fail(KPCN_ERR_OUT_OF_MEMORY, "kpcn_image_create: absurd size %dx%dx%d", width,
                     height, nchannels);
  kpcn_image *img = kpcn_calloc(1, sizeof *img, "kpcn_image");
  if (!img) return KPCN_ERR_OUT_OF_MEMORY;
  img->width = width;
  img->height = height;
  img->nchannels = nchannels;
  img->names = kpcn_calloc((size_t)nchannels, sizeof(char *), "channel names");
  img->data = kpcn_calloc(plane * (size_t)nchannels, sizeof(float), "image pixels");
  if (!img->names || !img->data) {
    kpcn_image_destroy(img);
    return KPCN_ERR_OUT_OF_MEMORY;
  }
  for (int c = 0; c < nchannels; c++) {
    char tmp[16];
    const char *nm = names && names[c] ? names[c] : (snprintf(tmp, sizeof tmp, "%d", c), tmp);
    img->names[c] = dup_str(nm);
    if (!img->names[c]) {
      kpcn_image_destroy(img);
      return KPCN_ERR_OUT_OF_MEMORY;
    }
  }
  *out = img;
  return KPCN_OK;
}

void kpcn_image_destroy(kpcn_image *img) {
  if (!img) return;
  if (img->names)
    for (int c = 0; c < img->nchannels; c++)
      free(img->names[c]);
  free(img->names);
  free(img->data);
  free(img);
}

kpcn_status kpcn_image_clone(kpcn_image **out, const kpcn_image *src) {
  if (!out || !src) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_image_clone: NULL argument");
  KPCN_TRY(kpcn_image_create(out, src->width, src->height, src->nchannels,
                             (const char *const *)src->names));
  memcpy((*out)->data, src->data,
         (size_t)src->width * src->height * (size_t)src->nchannels * sizeof(float));
  return KPCN_OK;
}

int kpcn_image_find_channel(const kpcn_image *img, const char *name) {
  if (!img || !name) return -1;
  for (int c = 0; c < img->nchannels; c++)
    if (img->names[c] && strcmp(img->names[c], name) == 0) return c;
  return -1;
}

/* ---- buffers ---- */

static const char *const g_buf_names[KPCN_BUF_COUNT] = {"color",  "diffuse", "specular",  "albedo",
                                                        "normal", "depth",   "visibility"};
static const char *const g_chan_names[KPCN_BUF_COUNT][3] = {
    {"R", "G", "B"},
    {"diffuse.R", "diffuse.G", "diffuse.B"},
    {"specular.R", "specular.G", "specular.B"},
    {"albedo.R", "albedo.G", "albedo.B"},
    {"N.X", "N.Y", "N.Z"},
    {"Z", NULL, NULL},
    {"visibility.V", NULL, NULL}};
static const char *const g_var_names[KPCN_BUF_COUNT] = {
    "color.var", "diffuse.var", "specular.var", "albedo.var", "N.var", "Z.var", "visibility.var"};

static int valid_buffer(kpcn_buffer b) { return (int)b >= 0 && b < KPCN_BUF_COUNT; }

int kpcn_buffer_channels(kpcn_buffer b) {
  if (!valid_buffer(b)) return 0;
  return (b == KPCN_BUF_DEPTH || b == KPCN_BUF_VISIBILITY) ? 1 : 3;
}

const char *kpcn_buffer_name(kpcn_buffer b) { return valid_buffer(b) ? g_buf_names[b] : "?"; }

const char *kpcn_buffer_channel_name(kpcn_buffer b, int c) {
  if (!valid_buffer(b) || c < 0 || c >= kpcn_buffer_channels(b)) return NULL;
  return g_chan_names[b][c];
}

const char *kpcn_buffer_variance_name(kpcn_buffer b) {
  return valid_buffer(b) ? g_var_names[b] : NULL;
}

int kpcn_buffer_from_name(const char *name) {
  if (!name) return -1;
  for (int b = 0; b < KPCN_BUF_COUNT; b++)
    if (strcmp(name, g_buf_names[b]) == 0) return b;
  return -1;
}

int kpcn_buffer_is_color(kpcn_buffer b) { return b <= KPCN_BUF_ALBEDO && (int)b >= 0; }

/* ---- AOV sets ---- */

kpcn_status kpcn_aov_create(kpcn_aov_set **out, int width, int height) {
  if (!out) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_aov_create: out is NULL");
  *out = NULL;
  KPCN_TRY(kpcn_check_size(width, height, "kpcn_aov_create"));
  kpcn_aov_set *s = kpcn_calloc(1, sizeof *s, "kpcn_aov_set");
  if (!s) return KPCN_ERR_OUT_OF_MEMORY;
  s->width = width;
  s->height = height;
  s->spp = -1;
  s->seed = -1;
  *out = s;
  return KPCN_OK;
}

void kpcn_aov_destroy(kpcn_aov_set *set) {
  if (!set) return;
  for (int b = 0; b < KPCN_BUF_COUNT; b++) {
    free(set->buf[b]);
    free(set->var[b]);
  }
  free(set);
}

kpcn_status kpcn_aov_add(kpcn_aov_set *set, kpcn_buffer b, int with_variance) {
  if (!set || !valid_buffer(b))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_aov_add: bad set or buffer %d", (int)b);
  size_t n = kpcn_aov_plane_size(set);
  if (!set->buf[b]) {
    set->buf[b] =
        kpcn_calloc(n * (size_t)kpcn_buffer_channels(b), sizeof(float), kpcn_buffer_name(b));
    if (!set->buf[b]) return KPCN_ERR_OUT_OF_MEMORY;
  }
  if (with_variance && !set->var[b]) {
    set->var[b] = kpcn_calloc(n, sizeof(float), kpcn_buffer_variance_name(b));
    if (!set->var[b]) return KPCN_ERR_OUT_OF_MEMORY;
  }
  return KPCN_OK;
}

kpcn_status kpcn_aov_clone(kpcn_aov_set **out, const kpcn_aov_set *src) {
  if (!out || !src) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_aov_clone: NULL argument");
  KPCN_TRY(kpcn_aov_create(out, src->width, src->height));
  kpcn_aov_set *d = *out;
  d->spp = src->spp;
  d->albedo_spp = src->albedo_spp;
  d->albedo_footprint = src->albedo_footprint;
  d->seed = src->seed;
  memcpy(d->scene, src->scene, sizeof d->scene);
  memcpy(d->version, src->version, sizeof d->version);
  size_t n = kpcn_aov_plane_size(src);
  for (int b = 0; b < KPCN_BUF_COUNT; b++) {
    if (!src->buf[b] && !src->var[b]) continue;
    kpcn_status s = kpcn_aov_add(d, (kpcn_buffer)b, src->var[b] != NULL);
    if (s != KPCN_OK) {
      kpcn_aov_destroy(d);
      *out = NULL;
      return s;
    }
    if (src->buf[b])
      memcpy(d->buf[b], src->buf[b], n * (size_t)kpcn_buffer_channels(b) * sizeof(float));
    else { /* a variance without its buffer: keep the shape of the source */
      free(d->buf[b]);
      d->buf[b] = NULL;
    }
    if (src->var[b]) memcpy(d->var[b], src->var[b], n * sizeof(float));
  }
  return KPCN_OK;
}

kpcn_status kpcn_aov_require_list(const kpcn_aov_set *set, const kpcn_buffer *b, int n,
                                  int need_variance, const char *what) {
  if (!set || n < 0 || (n > 0 && !b))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_aov_require: NULL set or buffer list");
  for (int i = 0; i < n; i++)
    if (!valid_buffer(b[i]))
      return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_aov_require: bad buffer %d", (int)b[i]);
  /* every absent buffer and variance in one message, so a render missing several is fixed
   * in one go rather than one rerun per channel */
  char msg[1024] = "";
  size_t len = 0;
  for (int i = 0; i < n; i++) {
    const kpcn_buffer x = b[i];
    const int novar = need_variance && !set->var[x];
    const char *sep = len ? ", " : "";
    int k = 0;
    if (!set->buf[x] && kpcn_buffer_channels(x) == 1)
      k = snprintf(msg + len, sizeof msg - len, "%sbuffer '%s' (channel %s%s%s)", sep,
                   g_buf_names[x], g_chan_names[x][0], novar ? ", and its variance " : "",
                   novar ? g_var_names[x] : "");
    else if (!set->buf[x])
      k = snprintf(msg + len, sizeof msg - len, "%sbuffer '%s' (channels %s %s %s%s%s)", sep,
                   g_buf_names[x], g_chan_names[x][0], g_chan_names[x][1], g_chan_names[x][2],
                   novar ? ", and its variance " : "", novar ? g_var_names[x] : "");
    else if (novar)
      k = snprintf(msg + len, sizeof msg - len, "%svariance of '%s' (channel %s)", sep,
                   g_buf_names[x], g_var_names[x]);
    if (k > 0) len = len + (size_t)k < sizeof msg ? len + (size_t)k : sizeof msg - 1;
  }
  if (!len) return KPCN_OK;
  return kpcn_fail(KPCN_ERR_MISSING_CHANNEL, "%s: missing %s", what ? what : "AOV set", msg);
}

kpcn_status kpcn_aov_require(const kpcn_aov_set *set, kpcn_buffer b, int need_variance,
                             const char *what) {
  return kpcn_aov_require_list(set, &b, 1, need_variance, what);
}

kpcn_status kpcn_aov_to_image(kpcn_image **out, const kpcn_aov_set *set) {
  if (!out || !set) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_aov_to_image: NULL argument");
  *out = NULL;
  const char *names[KPCN_BUF_COUNT * 4];
  const float *src[KPCN_BUF_COUNT * 4];
  int n = 0;
  size_t plane = kpcn_aov_plane_size(set);
  for (int b = 0; b < KPCN_BUF_COUNT; b++) {
    if (set->buf[b])
      for (int c = 0; c < kpcn_buffer_channels((kpcn_buffer)b); c++) {
        names[n] = g_chan_names[b][c];
        src[n++] = set->buf[b] + (size_t)c * plane;
      }
    if (set->var[b]) {
      names[n] = g_var_names[b];
      src[n++] = set->var[b];
    }
  }
  if (n == 0) return kpcn_fail(KPCN_ERR_MISSING_CHANNEL, "kpcn_aov_to_image: the AOV set is empty");
  KPCN_TRY(kpcn_image_create(out, set->width, set->height, n, names));
  for (int i = 0; i < n; i++)
    memcpy(kpcn_image_plane(*out, i), src[i], plane * sizeof(float));
  return KPCN_OK;
}

kpcn_status kpcn_aov_create_for_channels(kpcn_aov_set **out, int width, int height, int nch,
                                         const char *const *names, float **dst, const char *what) {
  if (!out || (nch > 0 && (!names || !dst)))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_aov_create_for_channels: NULL argument");
  *out = NULL;
  for (int c = 0; c < nch; c++) /* defined on every failure below */
    dst[c] = NULL;
  int chan[KPCN_BUF_COUNT][3], var[KPCN_BUF_COUNT];
  KPCN_TRY(kpcn_aov_map_channels(names, nch, chan, var, what ? what : "image"));
  kpcn_aov_set *s;
  KPCN_TRY(kpcn_aov_create(&s, width, height));
  const size_t plane = kpcn_aov_plane_size(s);
  for (int c = 0; c < nch; c++)
    dst[c] = NULL;
  for (int b = 0; b < KPCN_BUF_COUNT; b++) {
    kpcn_status st = KPCN_OK;
    if (chan[b][0] >= 0) {
      st = kpcn_aov_add(s, (kpcn_buffer)b, var[b] >= 0);
      for (int c = 0; st == KPCN_OK && c < kpcn_buffer_channels((kpcn_buffer)b); c++)
        dst[chan[b][c]] = s->buf[b] + (size_t)c * plane;
    } else if (var[b] >= 0) { /* a variance without its buffer: kept all the same */
      s->var[b] = kpcn_alloc(plane * sizeof(float), g_var_names[b]);
      if (!s->var[b]) st = KPCN_ERR_OUT_OF_MEMORY;
    }
    if (st != KPCN_OK) {
      kpcn_aov_destroy(s);
      for (int c = 0; c < nch; c++) /* they pointed into the destroyed set */
        dst[c] = NULL;
      return st;
    }
    if (var[b] >= 0) dst[var[b]] = s->var[b];
  }
  *out = s;
  return KPCN_OK;
}

kpcn_status kpcn_aov_from_image(kpcn_aov_set **out, const kpcn_image *img) {
  if (!out || !img)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_aov_from_image: NULL argument");
  *out = NULL;
  float **dst = kpcn_calloc((size_t)img->nchannels + 1, sizeof(float *), "channel planes");
  if (!dst) return KPCN_ERR_OUT_OF_MEMORY;
  kpcn_status s = kpcn_aov_create_for_channels(out, img->width, img->height, img->nchannels,
                                               (const char *const *)img->names, dst, "image");
  const size_t plane = (size_t)img->width * (size_t)img->height;
  for (int c = 0; s == KPCN_OK && c < img->nchannels; c++)
    if (dst[c]) memcpy(dst[c], kpcn_image_plane(img, c), plane * sizeof(float));
  free(dst);
  return s;
}

size_t kpcn_aov_count_nonfinite(const kpcn_aov_set *set, const char **first_name) {
  if (first_name) *first_name = NULL;
  if (!set) return 0;
  size_t plane = kpcn_aov_plane_size(set), count = 0;
  for (int b = 0; b < KPCN_BUF_COUNT; b++) {
    for (int c = 0; set->buf[b] && c < kpcn_buffer_channels((kpcn_buffer)b); c++) {
      const float *p = set->buf[b] + (size_t)c * plane;
      for (size_t i = 0; i < plane; i++)
        if (!isfinite(p[i])) {
          if (first_name && !*first_name) *first_name = g_chan_names[b][c];
          count++;
        }
    }
    if (set->var[b])
      for (size_t i = 0; i < plane; i++)
        if (!isfinite(set->var[b][i])) {
          if (first_name && !*first_name) *first_name = g_var_names[b];
          count++;
        }
  }
  return count;
}
