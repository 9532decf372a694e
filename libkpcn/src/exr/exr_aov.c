/* AOV EXR files: canonical names + aliases on read, canonical names + kpcn:* metadata on
 * write, header summary for `kpcntool --info`. */
#include "exr/exr_internal.h"

#include "core/internal.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

kpcn_status kpcn_exr_read_aov(const char *path, kpcn_aov_set **out) {
  return kpcn_exr_read_aov_mt(path, 0, out);
}

kpcn_status kpcn_exr_read_aov_mt(const char *path, int nthreads, kpcn_aov_set **out) {
  if (!out) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_exr_read_aov: out is NULL");
  *out = NULL;
  exr_context_t ctx;
  KPCN_TRY(kpcn_exr_open_read(path, &ctx));
  kpcn_image *img = NULL;
  kpcn_status s = kpcn_exr_read_context(ctx, path, nthreads, &img);
  int spp = -1, albedo_spp = 0, albedo_footprint = 0;
  int64_t seed = -1;
  char scene[256], version[32];
  if (s == KPCN_OK) {
    kpcn_exr_read_meta(ctx, &spp, &seed, scene, sizeof scene, version, sizeof version);
    albedo_spp = kpcn_exr_read_positive_int(ctx, "kpcn:albedoSpp");
    albedo_footprint = kpcn_exr_read_positive_int(ctx, "kpcn:albedoFootprint");
  }
  exr_finish(&ctx);
  if (s != KPCN_OK) return s;
  /* Map names first so a partial buffer is reported with the file name. */
  int chan[KPCN_BUF_COUNT][3], var[KPCN_BUF_COUNT];
  s = kpcn_aov_map_channels((const char *const *)img->names, img->nchannels, chan, var, path);
  if (s == KPCN_OK) s = kpcn_aov_from_image(out, img);
  kpcn_image_destroy(img);
  if (s != KPCN_OK) return s;
  (*out)->spp = spp;
  (*out)->albedo_spp = albedo_spp;
  (*out)->albedo_footprint = albedo_footprint;
  (*out)->seed = seed;
  snprintf((*out)->scene, sizeof(*out)->scene, "%s", scene);
  snprintf((*out)->version, sizeof(*out)->version, "%s", version);
  return KPCN_OK;
}

kpcn_status kpcn_exr_write_aov(const char *path, const kpcn_aov_set *set,
                               const kpcn_exr_write_options *opt) {
  if (!set)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "EXR write '%s': NULL AOV set", path ? path : "");
  const char *names[KPCN_BUF_COUNT * 4];
  const float *planes[KPCN_BUF_COUNT * 4];
  int n = 0;
  size_t plane = kpcn_aov_plane_size(set);
  for (int b = 0; b < KPCN_BUF_COUNT; b++) {
    for (int c = 0; set->buf[b] && c < kpcn_buffer_channels((kpcn_buffer)b); c++) {
      names[n] = kpcn_buffer_channel_name((kpcn_buffer)b, c);
      planes[n++] = set->buf[b] + (size_t)c * plane;
    }
    if (set->var[b]) {
      names[n] = kpcn_buffer_variance_name((kpcn_buffer)b);
      planes[n++] = set->var[b];
    }
  }
  if (n == 0)
    return kpcn_fail(KPCN_ERR_MISSING_CHANNEL, "EXR write '%s': the AOV set has no buffers",
                     path ? path : "");
  kpcn_exr_write_options o = opt ? *opt : kpcn_exr_write_options_defaults();
  if (set->spp >= 0) KPCN_TRY(kpcn_exr_options_add_int(&o, "kpcn:spp", set->spp));
  if (set->albedo_spp > 0)
    KPCN_TRY(kpcn_exr_options_add_int(&o, "kpcn:albedoSpp", set->albedo_spp));
  if (set->albedo_footprint > 1)
    KPCN_TRY(kpcn_exr_options_add_int(&o, "kpcn:albedoFootprint", set->albedo_footprint));
  if (set->seed >= 0) {
    /* EXR has no 64-bit int attribute: int when it fits, decimal string otherwise. */
    if (set->seed <= INT32_MAX) {
      KPCN_TRY(kpcn_exr_options_add_int(&o, "kpcn:seed", (int)set->seed));
    } else {
      char buf[32];
      snprintf(buf, sizeof buf, "%lld", (long long)set->seed);
      KPCN_TRY(kpcn_exr_options_add_string(&o, "kpcn:seed", buf));
    }
  }
  char tmp[sizeof set->scene + 1];
  snprintf(tmp, sizeof tmp, "%.*s", (int)sizeof set->scene - 1, set->scene);
  if (tmp[0]) KPCN_TRY(kpcn_exr_options_add_string(&o, "kpcn:scene", tmp));
  snprintf(tmp, sizeof tmp, "%.*s", (int)sizeof set->version - 1, set->version);
  KPCN_TRY(kpcn_exr_options_add_string(&o, "kpcn:version", tmp[0] ? tmp : KPCN_VERSION_STRING));
  return kpcn_exr_write_planes(path, set->width, set->height, n, names, planes, &o);
}

static const char *compression_name(exr_compression_t c) {
  static const char *const n[] = {"none",  "rle", "zips", "zip",  "piz",
                                  "pxr24", "b44", "b44a", "dwaa", "dwab"};
  return (unsigned)c < sizeof n / sizeof n[0] ? n[c] : "unknown";
}

kpcn_status kpcn_exr_info(const char *path, kpcn_exr_info_t *out) {
  if (!out) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_exr_info: out is NULL");
  memset(out, 0, sizeof *out);
  exr_context_t ctx;
  KPCN_TRY(kpcn_exr_open_read(path, &ctx));
  exr_attr_box2i_t dw;
  const exr_attr_chlist_t *chl = NULL;
  exr_storage_t storage;
  exr_compression_t comp = EXR_COMPRESSION_NONE;
  exr_get_data_window(ctx, 0, &dw);
  exr_get_channels(ctx, 0, &chl);
  exr_get_storage(ctx, 0, &storage);
  exr_get_compression(ctx, 0, &comp);
  exr_get_count(ctx, &out->nparts);
  out->width = dw.max.x - dw.min.x + 1;
  out->height = dw.max.y - dw.min.y + 1;
  out->data_x = dw.min.x;
  out->data_y = dw.min.y;
  out->tiled = storage == EXR_STORAGE_TILED;
  out->nchannels = chl->num_channels;
  snprintf(out->compression, sizeof out->compression, "%s", compression_name(comp));
  /* the first KPCN_EXR_MAX_INFO_CHANNELS are listed; the buffers are found among all of
   * them (a buffer whose channels sort past the 256th was reported absent) */
  const int n = chl->num_channels;
  const char **names = kpcn_calloc((size_t)n, sizeof *names, "EXR channel names");
  if (!names) {
    exr_finish(&ctx);
    return kpcn_last_status();
  }
  for (int c = 0; c < n; c++) {
    names[c] = chl->entries[c].name.str;
    if (c >= KPCN_EXR_MAX_INFO_CHANNELS) continue;
    snprintf(out->channels[c], sizeof out->channels[c], "%s", chl->entries[c].name.str);
    exr_pixel_type_t t = chl->entries[c].pixel_type;
    out->channel_is_half[c] = t == EXR_PIXEL_HALF ? 1 : t == EXR_PIXEL_UINT ? 2 : 0;
  }
  kpcn_exr_read_meta(ctx, &out->spp, &out->seed, out->scene, sizeof out->scene, out->version,
                     sizeof out->version);
  int chan[KPCN_BUF_COUNT][3], var[KPCN_BUF_COUNT];
  /* A partial buffer is not an error for --info: it is simply reported as absent. */
  if (kpcn_aov_map_channels(names, n, chan, var, path) != KPCN_OK) kpcn_clear_error();
  free(names);
  for (int b = 0; b < KPCN_BUF_COUNT; b++) {
    out->has_buffer[b] = chan[b][0] >= 0;
    out->has_variance[b] = var[b] >= 0;
  }
  exr_finish(&ctx);
  return KPCN_OK;
}
