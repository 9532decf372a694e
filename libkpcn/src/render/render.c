/* The render loop: rows of the (cropped) image are distributed over OpenMP threads; each
 * pixel traces all of its samples in order with its own sample sequence and keeps per
 * channel Welford accumulators (mean, M2) in double. Nothing is shared between pixels, so
 * the result is bit-identical whatever the thread count or schedule, and a render resumed from
 * a checkpoint (render_ckpt.c: the finished rows) equals an uninterrupted one.
 *
 * Filtering is done by importance sampling the reconstruction filter (Tungsten's approach):
 * every sample has weight 1 and lands in its own pixel, so the variance of the mean is the
 * plain sample variance / n. */
#include "core/internal.h"
#include "render/render_internal.h"

#include <cjson/cJSON.h>
#include <float.h>
#include <math.h>
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

kpcn_render_settings kpcn_render_settings_defaults(void) {
  kpcn_render_settings s;
  memset(&s, 0, sizeof(s));
  s.spp = 0;
  s.seed = 1;
  s.nthreads = 0;
  s.max_bounces = -1;
  s.lights = KPCN_LIGHTS_SCENE;
  s.checkpoint_every_s = 60.0;
  return s;
}

enum { NCH = 17 }; /* color 3, diffuse 3, specular 3, albedo 3, normal 3, depth, visibility */
static const int buf_first[KPCN_BUF_COUNT] = {0, 3, 6, 9, 12, 15, 16};

static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static void sample_to_channels(const kpcn_sample_out *so, float *v) {
  kpcn_vec3 c = kv3_add(so->diffuse, so->specular);
  const kpcn_vec3 vs[5] = {c, so->diffuse, so->specular, so->albedo, so->normal};
  for (int b = 0; b < 5; b++) {
    v[3 * b] = vs[b].x;
    v[3 * b + 1] = vs[b].y;
    v[3 * b + 2] = vs[b].z;
  }
  v[15] = so->depth;
  v[16] = so->visibility;
}

/* Per-channel Welford accumulators of one pixel (zeroed by the caller). cnt is the number of
 * samples a channel has seen: every sample for all but visibility, which is the fraction of the
 * shadow rays traced from the feature surface that reach their light (DESIGN §4, and what
 * Tungsten writes): a sample that traces none there (the sampled light faces away, the BSDF is
 * zero, an environment sample below the horizon, a miss) does not count. */
typedef struct pixel_acc {
  double mean[NCH], m2[NCH];
  int64_t cnt[NCH];
} pixel_acc;

/* Traces samples [0, n) of pixel (px, py)'s sequence with c — the colour pass, or the albedo
 * pass (c->features_only: the same sequence, so its first spp samples are the colour pass's
 * camera rays) — into acc, in sample order. A sample with a NaN/Inf channel (should not
 * happen) counts as black. */
static void pixel_samples(const kpcn_render_ctx *c, int px, int py, int n,
                          kpcn_sampler_cache *cache, pixel_acc *acc, uint64_t *rays,
                          uint64_t *nonfinite) {
  kpcn_sampler_cache_reset(cache, kpcn_pixel_seed(c->seed, (uint32_t)px, (uint32_t)py));
  for (int i0 = 0; i0 < n; i0 += 16) {
    int m = n - i0 < 16 ? n - i0 : 16;
    kpcn_sampler smp[16];
    kpcn_sample_out so[16];
    for (int k = 0; k < m; k++)
      kpcn_sampler_start(&smp[k], c->seed, (uint32_t)px, (uint32_t)py, (uint32_t)(i0 + k), cache);
    c->trace(c, px, py, smp, m, so);
    for (int k = 0; k < m; k++) { /* accumulated in sample order */
      *rays += so[k].rays;
      float v[NCH];
      sample_to_channels(&so[k], v);
      int ok = 1;
      for (int ch = 0; ch < NCH; ch++)
        ok &= isfinite(v[ch]) != 0;
      if (!ok) {
        (*nonfinite)++;
        memset(v, 0, sizeof(v));
      }
      int nch = so[k].vis_traced ? NCH : NCH - 1; /* visibility is the last channel */
      for (int ch = 0; ch < nch; ch++) {
        double delta = (double)v[ch] - acc->mean[ch];
        acc->mean[ch] += delta * (1.0 / (double)++acc->cnt[ch]); /* 1/n, then a product */
        acc->m2[ch] += delta * ((double)v[ch] - acc->mean[ch]);
      }
    }
  }
}

/* Buffer b of pixel pi from the accumulators: the means, and the variance of the mean
 * averaged over the buffer's channels (0 for one sample or none; a mean of none is 0). The means
 * are means of floats, so they fit a float; the variance of samples near the emission limit (1e15,
 * its square 1e30) fits too, but a brighter path (an albedo above 1 multiplies) can overflow it: it
 * is stored saturated at FLT_MAX, never as Inf, which the output must not contain. */
static void store_buffer(kpcn_aov_set *set, int b, const pixel_acc *acc, size_t pi) {
  const size_t plane = (size_t)set->width * (size_t)set->height;
  const int nc = kpcn_buffer_channels((kpcn_buffer)b);
  double var = 0.0;
  for (int c = 0; c < nc; c++) {
    int ch = buf_first[b] + c;
    double n = (double)acc->cnt[ch];
    set->buf[b][(size_t)c * plane + pi] = (float)acc->mean[ch];
    if (n > 1) var += acc->m2[ch] / ((n - 1.0) * n);
  }
  var /= nc;
  if (set->var[b]) set->var[b][pi] = var < (double)FLT_MAX ? (float)var : FLT_MAX;
}

kpcn_status kpcn_render_check_memory(int width, int height, int planes, uint64_t avail_bytes) {
  /* available, not physical: a render between the two was accepted, to be killed by the OOM
   * killer part-way (16000x16000: 24.6 GB against 25.3 physical, 23.6 available then) */
  if (avail_bytes == 0) avail_bytes = kpcn_available_memory();
  if (avail_bytes == 0) return KPCN_OK; /* unknown: let the allocation decide */
  const uint64_t need = (uint64_t)width * (uint64_t)height * (uint64_t)planes * sizeof(float);
  if (need > avail_bytes)
    return kpcn_fail(KPCN_ERR_OUT_OF_MEMORY,
                     "render %dx%d: the output buffers need %.2f GB (%d float planes), more than "
                     "the %.2f GB of memory this machine has available (of %.2f GB physical)",
                     width, height, (double)need * 1e-9, planes, (double)avail_bytes * 1e-9,
                     (double)kpcn_physical_memory() * 1e-9);
  return KPCN_OK;
}

kpcn_status kpcn_render_ctx_init(kpcn_render_ctx *ctx, const kpcn_scene *scene,
                                 const kpcn_render_settings *settings) {
  const kpcn_render_settings *st = settings;
  memset(ctx, 0, sizeof(*ctx));
  ctx->scene = scene;
  ctx->width = st->width > 0 ? st->width : scene->cam.width;
  ctx->height = st->height > 0 ? st->height : scene->cam.height;
  if ((st->width > 0) != (st->height > 0) || st->width < 0 || st->height < 0)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "resolution override: give both width and height (> 0)");
  KPCN_TRY(kpcn_check_size(ctx->width, ctx->height, "render resolution"));
  ctx->ratio = (float)ctx->height / (float)ctx->width;
  /* A thin lens scales the image-plane point by focus_distance * tan(fov/2) (camera_ray); at a
   * tall aspect ratio a far focus plane with a wide fov squares past float range there and
   * the ray's direction becomes zero or NaN, which Embree does not survive. The loader bounds
   * each factor (docs/renderer.md); their product depends on the resolution, known only here. */
  const kpcn_camera *cam = &scene->cam;
  if (cam->thinlens && cam->aperture > 0.0f) {
    double reach = (double)cam->focus_dist / (double)cam->plane_dist * (1.0 + ctx->ratio);
    if (!(reach <= 1e18))
      return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                       "camera: the thin lens's focus plane reaches %g at %dx%d (focus_distance "
                       "%g, fov %g); supported <= 1e18",
                       reach, ctx->width, ctx->height, (double)cam->focus_dist,
                       (double)cam->fov_deg);
  }
  ctx->max_bounces = st->max_bounces >= 0 ? st->max_bounces : scene->max_bounces;
  ctx->min_bounces = scene->min_bounces;
  if (st->lights < KPCN_LIGHTS_SCENE || st->lights > KPCN_LIGHTS_NEE_ONLY)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "render settings: lights = %d is not a kpcn_light_strategy (0 scene, 1 MIS, "
                     "2 BSDF only, 3 NEE only)",
                     (int)st->lights);
  kpcn_light_strategy ls = st->lights;
  if (ls == KPCN_LIGHTS_SCENE) ls = scene->light_sampling ? KPCN_LIGHTS_MIS : KPCN_LIGHTS_BSDF_ONLY;
  ctx->nee = ls == KPCN_LIGHTS_MIS || ls == KPCN_LIGHTS_NEE_ONLY;
  ctx->bsdf_emission = ls == KPCN_LIGHTS_MIS || ls == KPCN_LIGHTS_BSDF_ONLY;
  ctx->mis = ls == KPCN_LIGHTS_MIS;
  ctx->color_only = st->color_only;
  ctx->seed = (uint64_t)st->seed;
  kpcn_filter_table_init(&ctx->filter, scene->cam.filter);
  kpcn_sampler_init();
  ctx->trace = kpcn_trace_pixel;
#ifdef KPCN_HAVE_GFNI_VARIANT
  __builtin_cpu_init();
  if (__builtin_cpu_supports("gfni")) ctx->trace = kpcn_trace_pixel_gfni;
#endif
  return KPCN_OK;
}

/* What identifies a render's pixels, for its checkpoint: the scene, every resolved setting
 * that changes a pixel, the window and the library version (its sampling may change). */
static cJSON *render_identity(const kpcn_render_ctx *c, const kpcn_render_settings *st,
                              const kpcn_scene *scene, int spp, int aspp, const int crop[4]) {
  char key[32], seed[32];
  snprintf(key, sizeof key, "%016llx", (unsigned long long)st->scene_key);
  snprintf(seed, sizeof seed, "%lld", (long long)st->seed);
  const int dims[2] = {c->width, c->height};
  cJSON *o = cJSON_CreateObject();
  if (!o) return NULL;
  int ok = cJSON_AddStringToObject(o, "kpcn_version", KPCN_VERSION_STRING) &&
           /* the caller's key names the scene's content; without one, its name (a path) */
           (st->scene_key ? cJSON_AddStringToObject(o, "scene_key", key) != NULL
                          : cJSON_AddStringToObject(o, "scene", scene->name) != NULL) &&
           cJSON_AddItemToObject(o, "resolution", cJSON_CreateIntArray(dims, 2)) &&
           cJSON_AddItemToObject(o, "crop", cJSON_CreateIntArray(crop, 4)) &&
           cJSON_AddNumberToObject(o, "spp", spp) && cJSON_AddStringToObject(o, "seed", seed) &&
           cJSON_AddNumberToObject(o, "albedo_spp", aspp) &&
           cJSON_AddNumberToObject(o, "albedo_footprint", c->albedo_footprint) &&
           cJSON_AddNumberToObject(o, "color_only", c->color_only) &&
           cJSON_AddNumberToObject(o, "max_bounces", c->max_bounces) &&
           cJSON_AddNumberToObject(o, "lights",
                                   c->mis   ? 1
                                   : c->nee ? 3
                                            : 2);
  if (!ok) {
    cJSON_Delete(o);
    return NULL;
  }
  return o;
}

kpcn_status kpcn_render_ex(const kpcn_scene *scene, const kpcn_render_settings *settings,
                           kpcn_aov_set **out, kpcn_render_stats *stats) {
  /* defined on every return: a caller reads rows_resumed after a cancel too */
  if (stats) memset(stats, 0, sizeof *stats);
  if (!scene || !out) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_render: NULL scene or out");
  *out = NULL;
  kpcn_render_settings st = settings ? *settings : kpcn_render_settings_defaults();
  kpcn_render_ctx ctx;
  KPCN_TRY(kpcn_render_ctx_init(&ctx, scene, &st));
  /* 0 .. 2^63-1: the EXR header records the seed (kpcn:seed) only when it is >= 0 */
  if (st.seed < 0)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "seed: %lld is negative (seeds are 0 .. 2^63-1)",
                     (long long)st.seed);
  int spp = st.spp > 0 ? st.spp : scene->spp;
  if (st.spp < 0 || spp > (1 << 24))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "spp: %d is out of range [1, 2^24]", st.spp);
  /* -1 is the scene's; any other negative was taken as -1 without a word */
  if (st.max_bounces < -1)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "max_bounces: %d must be >= 0 (-1: the scene's integrator.max_bounces)",
                     st.max_bounces);
  if (st.albedo_spp < 0 || st.albedo_spp > (1 << 24))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "albedo_spp (--albedo-spp): %d is out of range (0 = off, or 1 .. 2^24)",
                     st.albedo_spp);
  /* the render's spp may be the scene's, which the caller never typed: say where it is from */
  if (st.albedo_spp > 0 && st.albedo_spp < spp)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "albedo_spp (--albedo-spp): %d is below the render's %d samples per pixel "
                     "(%s); the albedo pass takes at least as many",
                     st.albedo_spp, spp, st.spp > 0 ? "as asked" : "the scene's");
  if (st.albedo_spp > 0 && st.color_only)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "albedo_spp: a colour-only render has no albedo buffer");
  if (st.albedo_footprint < 0 || st.albedo_footprint > 16)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "albedo_footprint: %d is out of range (0 or 1 = off, 2 .. 16)",
                     st.albedo_footprint);
  if (st.albedo_footprint > 1 && st.color_only)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "albedo_footprint: a colour-only render has no albedo buffer");
  ctx.albedo_footprint = st.albedo_footprint > 1 ? st.albedo_footprint : 0;
  const int aspp = st.albedo_spp > spp ? st.albedo_spp : 0; /* 0: no albedo pass */
  kpcn_render_ctx fctx = ctx;                               /* the albedo pass: features only */
  fctx.features_only = 1;
  int cx = 0, cy = 0, cw = ctx.width, chh = ctx.height;
  /* all four 0 = no crop; anything else is a crop (a negative size at offset 0 was ignored) */
  if (st.crop_w || st.crop_h || st.crop_x || st.crop_y) {
    cx = st.crop_x, cy = st.crop_y, cw = st.crop_w, chh = st.crop_h;
    /* in 64 bits: cx + cw overflows an int for a crop near INT_MAX */
    if (cx < 0 || cy < 0 || cw <= 0 || chh <= 0 || (int64_t)cx + cw > ctx.width ||
        (int64_t)cy + chh > ctx.height)
      return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                       cw <= 0 || chh <= 0
                           ? "crop %d,%d,%d,%d is empty (its size must be positive; the "
                             "image is %dx%d)"
                           : "crop %d,%d,%d,%d lies outside the %dx%d image",
                       cx, cy, cw, chh, ctx.width, ctx.height);
  }

  /* calloc only reserves address space: a render larger than the machine would start, then be
   * killed by the kernel part-way (16384x16384 needs 25.8 GB). Refuse it up front instead. */
  int planes = 0;
  for (int b = 0; b < KPCN_BUF_COUNT; b++)
    if (!st.color_only || b == KPCN_BUF_COLOR) planes += kpcn_buffer_channels((kpcn_buffer)b) + 1;
  KPCN_TRY(kpcn_render_check_memory(cw, chh, planes, 0));
  kpcn_aov_set *set = NULL;
  KPCN_TRY(kpcn_aov_create(&set, cw, chh));
  for (int b = 0; b < KPCN_BUF_COUNT; b++) {
    if (st.color_only && b != KPCN_BUF_COLOR) continue;
    kpcn_status s2 = kpcn_aov_add(set, (kpcn_buffer)b, 1);
    if (s2 != KPCN_OK) {
      kpcn_aov_destroy(set);
      return s2;
    }
  }
  set->spp = spp;
  set->albedo_spp = aspp;
  set->albedo_footprint = ctx.albedo_footprint;
  set->seed = st.seed;
  snprintf(set->scene, sizeof(set->scene), "%s", scene->name);
  snprintf(set->version, sizeof(set->version), "%s", KPCN_VERSION_STRING);

  if (st.checkpoint && !(st.checkpoint_every_s >= 0)) {
    kpcn_aov_destroy(set);
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "checkpoint_every_s: %g must be >= 0",
                     st.checkpoint_every_s);
  }
  const int crop[4] = {cx, cy, cw, chh};
  cJSON *what = st.checkpoint ? render_identity(&ctx, &st, scene, spp, aspp, crop) : NULL;
  kpcn_render_ckpt *ck = NULL;
  kpcn_status cs = st.checkpoint && !what
                       ? kpcn_fail(KPCN_ERR_OUT_OF_MEMORY, "render checkpoint: out of memory")
                       : kpcn_render_ckpt_create(&ck, st.checkpoint, what, set);
  cJSON_Delete(what);
  int resumed = 0;
  if (cs == KPCN_OK) cs = kpcn_render_ckpt_load(ck, &resumed);
  /* a path that cannot be written fails now, not after the first interval's work */
  if (cs == KPCN_OK) cs = kpcn_render_ckpt_probe(ck);
  if (cs != KPCN_OK) {
    kpcn_render_ckpt_destroy(ck);
    kpcn_aov_destroy(set);
    return cs;
  }

  int nthreads = kpcn_resolve_threads(st.nthreads);
  volatile int cancel = 0;
  int reported_all = 0; /* the calling thread's callback has seen 1.0 */
  int rows_done = resumed;
  uint64_t total_rays = 0; /* traced by this call */
  int save_errors = 0;
  unsigned saved_csr = kpcn_fast_fp_begin(nthreads); /* radiance never needs denormals */
  double t0 = now_s(), last_save = t0;
#pragma omp parallel num_threads(nthreads) reduction(+ : total_rays)
  {
#pragma omp for schedule(dynamic, 1)
    for (int row = 0; row < chh; row++) {
      if (cancel || kpcn_render_ckpt_is_done(ck, row)) continue;
      int py = cy + row;
      uint64_t rays = 0, nonfinite = 0;
      for (int col = 0; col < cw; col++) {
        int px = cx + col;
        pixel_acc acc;
        memset(&acc, 0, sizeof(acc));
        kpcn_sampler_cache cache;
        pixel_samples(&ctx, px, py, spp, &cache, &acc, &rays, &nonfinite);
        size_t pi = (size_t)row * (size_t)cw + (size_t)col;
        for (int b = 0; b < KPCN_BUF_COUNT; b++)
          if (set->buf[b]) store_buffer(set, b, &acc, pi);
        if (aspp) { /* the albedo pass replaces the albedo buffer */
          memset(&acc, 0, sizeof(acc));
          pixel_samples(&fctx, px, py, aspp, &cache, &acc, &rays, &nonfinite);
          store_buffer(set, KPCN_BUF_ALBEDO, &acc, pi);
        }
      }
      total_rays += rays;
      kpcn_render_ckpt_row_done(ck, row, rays, nonfinite);
#pragma omp atomic
      rows_done++;
      /* the calling thread (errors are thread-local: kpcn_last_error is the caller's) */
      if (omp_get_thread_num() == 0) {
        if (st.progress) {
          int done;
#pragma omp atomic read
          done = rows_done;
          if (st.progress(st.progress_user, (double)done / chh)) cancel = 1;
          if (done == chh) reported_all = 1;
        }
        if (st.checkpoint && st.checkpoint_every_s > 0 &&
            now_s() - last_save >= st.checkpoint_every_s) {
          /* hours of rendering are worth more than one save: go on, try again later */
          if (kpcn_render_ckpt_save(ck) != KPCN_OK) save_errors++;
          last_save = now_s();
        }
      }
    }
  }
  kpcn_fast_fp_end(saved_csr, nthreads);
  double secs = now_s() - t0;
  /* Only the calling thread calls back (inside the loop, after its rows): when the other
   * threads finished the last rows, 1.0 is reported here, and its answer counts too (a
   * few-row render on several threads could not be cancelled: the only call was this one,
   * whose return value was dropped). Reported once. */
  if (!cancel && st.progress && !reported_all && st.progress(st.progress_user, 1.0)) cancel = 1;
  if (cancel) {
    if (stats) { /* what a log should say of a resumed render stopped again */
      stats->seconds = secs;
      stats->rows_resumed = resumed;
      stats->checkpoint_errors = save_errors;
    }
    kpcn_status r = kpcn_render_ckpt_save(ck);
    if (r == KPCN_OK)
      r = kpcn_fail(KPCN_ERR_CANCELLED, "render of '%s' cancelled%s", scene->name,
                    st.checkpoint ? " (its finished rows are in the checkpoint)" : "");
    kpcn_render_ckpt_destroy(ck);
    kpcn_aov_destroy(set);
    return r;
  }
  /* every row, in case writing the result fails (a full disk, a missing folder): then the
   * same call again returns at once */
  if (st.checkpoint && resumed < chh && kpcn_render_ckpt_save(ck) != KPCN_OK) save_errors++;
  if (stats) {
    uint64_t all_rays, nonfinite;
    kpcn_render_ckpt_totals(ck, &all_rays, &nonfinite);
    stats->seconds = secs;
    /* the albedo pass's camera samples too (aspp per pixel, 0 without one) */
    stats->samples = (uint64_t)(chh - resumed) * (uint64_t)cw * (uint64_t)(spp + aspp);
    stats->rays = total_rays;
    stats->rows_resumed = resumed;
    stats->checkpoint_errors = save_errors;
    stats->nonfinite_samples = nonfinite;
  }
  kpcn_render_ckpt_destroy(ck);
  *out = set;
  return KPCN_OK;
}

kpcn_status kpcn_render(const kpcn_scene *scene, const kpcn_render_settings *settings,
                        kpcn_aov_set **out) {
  return kpcn_render_ex(scene, settings, out, NULL);
}
