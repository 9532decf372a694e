/* The oidn.h-style denoiser object: options, named strided input buffers, execute. */
#include "core/internal.h"
#include "denoise_internal.h"

#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

typedef struct slot {
  const float *ptr;
  int width, height;
  size_t pixel_stride, row_stride; /* bytes */
} slot;

struct kpcn_denoiser {
  kpcn_denoiser_options opt;
  char *model_path;
  kpcn_model *model;
  slot buf[KPCN_BUF_COUNT][3];
  slot var[KPCN_BUF_COUNT];
  kpcn_progress prog;
  kpcn_denoise_stats stats;
  kpcn_pipeline_cache cache;
  const kpcn_kernel_sink *sink; /* set only during kpcn_denoiser_kernels_aov */
};

void kpcn_denoiser_options_defaults(kpcn_denoiser_options *o) {
  if (!o) return;
  memset(o, 0, sizeof *o);
  o->method = KPCN_DENOISE_KPCN;
  /* Defaults chosen on the Tungsten Cornell 16 spp pair (docs/denoiser.md, tests). */
  o->bilateral.radius = 7;
  o->bilateral.sigma_spatial = 4.0f;
  o->bilateral.k_color = 2.0f;
  o->bilateral.sigma_normal = 0.1f;
  o->bilateral.sigma_albedo = 0.05f;
  o->bilateral.sigma_depth = 0.02f;
  o->bilateral.patch_radius = 0;
  o->nlmeans.radius = 7;
  o->nlmeans.sigma_spatial = 0.0f;
  o->nlmeans.k_color = 0.7f;
  o->nlmeans.sigma_normal = 0.1f;
  o->nlmeans.sigma_albedo = 0.05f;
  o->nlmeans.sigma_depth = 0.02f;
  o->nlmeans.patch_radius = 3;
  o->firefly = KPCN_DENOISE_DEFAULT_FIREFLY;
}

static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* Checks what both create calls accept alike. */
static kpcn_status check_options(const kpcn_denoiser_options *o) {
  /* switches are 0 or 1: any other value acted as 1 without a word */
  if (o->bf16 != 0 && o->bf16 != 1)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "denoiser_create: bf16 %d must be 0 or 1", o->bf16);
  if (o->direct_conv != 0 && o->direct_conv != 1)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "denoiser_create: direct_conv %d must be 0 or 1",
                     o->direct_conv);
  if (o->tile < 0)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "denoiser_create: tile %d must be >= 0", o->tile);
  /* libgomp aborts the process when it cannot start the threads asked for */
  if (o->nthreads < 0 || o->nthreads > KPCN_DENOISE_MAX_THREADS)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "denoiser_create: nthreads %d must be 0 (all cores) .. %d", o->nthreads,
                     KPCN_DENOISE_MAX_THREADS);
  if (!(o->exposure >= 0.0f || o->exposure == KPCN_EXPOSURE_AS_RENDERED) || !isfinite(o->exposure))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "denoiser_create: exposure %g must be > 0, 0 (the model's) or "
                     "KPCN_EXPOSURE_AS_RENDERED",
                     (double)o->exposure);
  if (!(o->firefly == 0.0f || o->firefly >= 1.0f) || !isfinite(o->firefly))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "denoiser_create: firefly %g must be 0 (off) or a ratio >= 1",
                     (double)o->firefly);
  if (o->ensemble < 0 || o->ensemble > KPCN_DENOISE_MAX_ENSEMBLE ||
      (o->ensemble > 1 && (o->ensemble & (o->ensemble - 1)) != 0))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "denoiser_create: ensemble %d must be 0, 1, 2, 4 or 8", o->ensemble);
  /* a baseline's parameters at create, not at the first execute */
  if (o->method == KPCN_DENOISE_BILATERAL) return kpcn_baseline_params_check(&o->bilateral, 0);
  if (o->method == KPCN_DENOISE_NLMEANS) return kpcn_baseline_params_check(&o->nlmeans, 1);
  return KPCN_OK;
}

kpcn_status kpcn_denoiser_create(kpcn_denoiser **out, const kpcn_denoiser_options *opts) {
  if (!out) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "denoiser_create: out is NULL");
  *out = NULL;
  kpcn_denoiser_options o;
  if (opts)
    o = *opts;
  else
    kpcn_denoiser_options_defaults(&o);
  if (o.method < KPCN_DENOISE_KPCN || o.method > KPCN_DENOISE_NLMEANS)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "denoiser_create: unknown method %d", o.method);
  KPCN_TRY(check_options(&o));
  if (o.method == KPCN_DENOISE_KPCN && (!o.model_path || !*o.model_path))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "denoiser_create: method kpcn needs model_path");
  kpcn_denoiser *d = kpcn_calloc(1, sizeof *d, "denoiser");
  if (!d) return KPCN_ERR_OUT_OF_MEMORY;
  d->opt = o;
  if (o.method == KPCN_DENOISE_KPCN) {
    d->model_path = strdup(o.model_path);
    kpcn_status s = d->model_path ? kpcn_model_load(o.model_path, &d->model)
                                  : kpcn_fail(KPCN_ERR_OUT_OF_MEMORY,
                                              "out of memory for the denoiser model path");
    if (s == KPCN_OK) s = kpcn_features_check_arch(kpcn_model_arch(d->model));
    if (s != KPCN_OK) {
      kpcn_fail_context("denoiser model '%s'", o.model_path);
      kpcn_denoiser_destroy(d);
      return s;
    }
    d->opt.model_path = d->model_path;
  } else {
    d->opt.model_path = NULL;
  }
  *out = d;
  return KPCN_OK;
}

kpcn_status kpcn_denoiser_create_with_model(kpcn_denoiser **out, kpcn_model *model,
                                            const kpcn_denoiser_options *opts) {
  if (out) *out = NULL; /* on every failure, as kpcn_denoiser_create */
  if (!out || !model)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "denoiser_create_with_model: %s is NULL",
                     !out ? "out" : "model");
  KPCN_TRY(kpcn_features_check_arch(kpcn_model_arch(model)));
  kpcn_denoiser_options o;
  if (opts)
    o = *opts;
  else
    kpcn_denoiser_options_defaults(&o);
  o.method = KPCN_DENOISE_KPCN; /* documented as ignored, so the baselines' options are too */
  KPCN_TRY(check_options(&o));
  kpcn_denoiser *d = kpcn_calloc(1, sizeof *d, "denoiser");
  if (!d) return KPCN_ERR_OUT_OF_MEMORY;
  d->opt = o;
  d->opt.model_path = NULL;
  d->model = model; /* borrowed: model_path is NULL so destroy leaves it alone */
  *out = d;
  return KPCN_OK;
}

void kpcn_denoiser_destroy(kpcn_denoiser *d) {
  if (!d) return;
  kpcn_pipeline_cache_release(&d->cache);
  if (d->model_path) kpcn_model_destroy(d->model);
  free(d->model_path);
  free(d);
}

void kpcn_denoiser_set_progress(kpcn_denoiser *d, kpcn_progress_fn fn, void *user) {
  if (!d) return;
  d->prog.fn = fn;
  d->prog.user = user;
  d->prog.cancelled = 0;
}

void kpcn_denoiser_get_stats(const kpcn_denoiser *d, kpcn_denoise_stats *s) {
  if (!s) return;
  if (d)
    *s = d->stats;
  else
    memset(s, 0, sizeof *s);
}

/* "diffuse" -> (buffer, 0); "diffuse.var" -> (buffer, 1). */
static kpcn_status parse_name(const char *name, int *b, int *is_var) {
  if (!name) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "denoiser_set_buffer: name is NULL");
  char tmp[64];
  size_t n = strlen(name);
  *is_var = 0;
  if (n > 4 && n < sizeof tmp && strcmp(name + n - 4, ".var") == 0) {
    memcpy(tmp, name, n - 4);
    tmp[n - 4] = 0;
    *is_var = 1;
    *b = kpcn_buffer_from_name(tmp);
  } else {
    *b = kpcn_buffer_from_name(name);
  }
  if (*b < 0)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "denoiser_set_buffer: unknown buffer '%s' (color, diffuse, specular, albedo, "
                     "normal, depth, visibility, or <name>.var)",
                     name);
  return KPCN_OK;
}

static kpcn_status check_geom(const char *name, int width, int height) {
  return kpcn_check_size(width, height, name);
}

/* Strides in bytes, whole floats, a pixel holding its `pixel_bytes` (all its channels) and a
 * row its width of pixels: smaller ones made pixels overlap, read or written without a word. */
static kpcn_status check_strides(const char *name, int width, size_t pixel_stride,
                                 size_t row_stride, size_t pixel_bytes) {
  if (pixel_stride % sizeof(float) || row_stride % sizeof(float))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "'%s': strides must be whole floats (pixel %zu, row %zu bytes)", name,
                     pixel_stride, row_stride);
  if (pixel_stride < pixel_bytes)
    return kpcn_fail(
        KPCN_ERR_INVALID_ARGUMENT,
        "'%s': pixel stride %zu bytes is less than a pixel's %zu: pixels would overlap", name,
        pixel_stride, pixel_bytes);
  if (row_stride < (size_t)(width - 1) * pixel_stride + pixel_bytes)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "'%s': row stride %zu bytes is less than a row's %zu: rows would overlap",
                     name, row_stride, (size_t)(width - 1) * pixel_stride + pixel_bytes);
  return KPCN_OK;
}

kpcn_status kpcn_denoiser_set_buffer_channel(kpcn_denoiser *d, const char *name, int channel,
                                             const float *ptr, int width, int height,
                                             size_t pixel_stride, size_t row_stride) {
  if (!d) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "denoiser_set_buffer: denoiser is NULL");
  int b = -1, is_var = 0;
  KPCN_TRY(parse_name(name, &b, &is_var));
  int nch = is_var ? 1 : kpcn_buffer_channels((kpcn_buffer)b);
  if (channel < 0 || channel >= nch)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "denoiser_set_buffer: '%s' has no channel %d", name,
                     channel);
  slot *sl = is_var ? &d->var[b] : &d->buf[b][channel];
  if (!ptr) {
    memset(sl, 0, sizeof *sl);
    return KPCN_OK;
  }
  KPCN_TRY(check_geom(name, width, height));
  if (pixel_stride == 0) pixel_stride = sizeof(float);
  if (row_stride == 0) row_stride = (size_t)width * pixel_stride;
  KPCN_TRY(check_strides(name, width, pixel_stride, row_stride, sizeof(float)));
  sl->ptr = ptr;
  sl->width = width;
  sl->height = height;
  sl->pixel_stride = pixel_stride;
  sl->row_stride = row_stride;
  return KPCN_OK;
}

kpcn_status kpcn_denoiser_set_buffer(kpcn_denoiser *d, const char *name, const float *ptr,
                                     int width, int height, size_t pixel_stride,
                                     size_t row_stride) {
  if (!d) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "denoiser_set_buffer: denoiser is NULL");
  int b = -1, is_var = 0;
  KPCN_TRY(parse_name(name, &b, &is_var));
  int nch = is_var ? 1 : kpcn_buffer_channels((kpcn_buffer)b);
  if (pixel_stride == 0) pixel_stride = (size_t)nch * sizeof(float);
  if (row_stride == 0 && width > 0) row_stride = (size_t)width * pixel_stride;
  if (ptr) {
    KPCN_TRY(check_geom(name, width, height));
    KPCN_TRY(check_strides(name, width, pixel_stride, row_stride, (size_t)nch * sizeof(float)));
  }
  for (int c = 0; c < nch; c++)
    KPCN_TRY(kpcn_denoiser_set_buffer_channel(d, name, c, ptr ? ptr + c : NULL, width, height,
                                              pixel_stride, row_stride));
  return KPCN_OK;
}

static void copy_in(const slot *sl, float *dst, int W, int H) {
  for (int y = 0; y < H; y++) {
    const char *row = (const char *)sl->ptr + (size_t)y * sl->row_stride;
    for (int x = 0; x < W; x++)
      dst[(size_t)y * W + x] = *(const float *)(row + x * sl->pixel_stride);
  }
}

/* Gathers the set buffers into a planar AOV set; partially set buffers and size
 * mismatches are named. */
static kpcn_status assemble(const kpcn_denoiser *d, int W, int H, kpcn_aov_set **out) {
  KPCN_TRY(kpcn_aov_create(out, W, H));
  kpcn_aov_set *a = *out;
  const size_t P = kpcn_aov_plane_size(a);
  for (int b = 0; b < KPCN_BUF_COUNT; b++) {
    int nch = kpcn_buffer_channels((kpcn_buffer)b), nset = 0;
    for (int c = 0; c < nch; c++)
      nset += d->buf[b][c].ptr != NULL;
    if (nset == 0) continue;
    const char *bn = kpcn_buffer_name((kpcn_buffer)b);
    if (nset != nch)
      return kpcn_fail(KPCN_ERR_MISSING_CHANNEL, "denoiser input '%s': only %d of %d channels set",
                       bn, nset, nch);
    const int hv = d->var[b].ptr != NULL;
    for (int c = 0; c < nch + hv; c++) {
      const slot *sl = c < nch ? &d->buf[b][c] : &d->var[b];
      if (sl->width != W || sl->height != H)
        return kpcn_fail(KPCN_ERR_SIZE_MISMATCH, "denoiser input '%s%s' is %dx%d, output is %dx%d",
                         bn, c < nch ? "" : ".var", sl->width, sl->height, W, H);
    }
    KPCN_TRY(kpcn_aov_add(a, (kpcn_buffer)b, hv));
    for (int c = 0; c < nch; c++)
      copy_in(&d->buf[b][c], a->buf[b] + c * P, W, H);
    if (hv) copy_in(&d->var[b], a->var[b], W, H);
  }
  return KPCN_OK;
}

/* Runs the configured method on a planar AOV set into planar RGB out (the KPCN at colour
 * scale `scale`; the baselines are exposure-invariant as they are). */
static kpcn_status run_method(kpcn_denoiser *d, const kpcn_aov_set *aov, float scale, float *out) {
  d->prog.cancelled = 0;
  unsigned csr = kpcn_fast_fp_begin(d->opt.nthreads);
  kpcn_status s;
  switch (d->opt.method) {
  case KPCN_DENOISE_BILATERAL:
    s = kpcn_baseline_bilateral(aov, &d->opt.bilateral, out, d->opt.nthreads, &d->prog);
    break;
  case KPCN_DENOISE_NLMEANS:
    s = kpcn_baseline_nlmeans(aov, &d->opt.nlmeans, out, d->opt.nthreads, &d->prog);
    break;
  default:
    s = kpcn_pipeline_run(d->model, aov, &d->opt, scale, &d->prog, out, &d->stats, &d->cache,
                          d->sink);
  }
  kpcn_fast_fp_end(csr, d->opt.nthreads);
  return s;
}

kpcn_status kpcn_denoise_ensemble_xform(int i, kpcn_augment_xform *x) {
  if (!x) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "denoise_ensemble_xform: x is NULL");
  if (i < 0 || i >= KPCN_DENOISE_MAX_ENSEMBLE)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "denoise_ensemble_xform: index %d not in 0..7", i);
  kpcn_augment_identity(x);
  static const int rot[4] = {0, 2, 1, 3}; /* pairs of i: rot180 before the quarter turns, so
                                             the first 4 are a group (Klein four) */
  x->mirror_h = i & 1;
  x->rot90 = rot[i >> 1];
  return KPCN_OK;
}

/* Scales the progress of ensemble member `k` of `n` into the caller's [0,1]. */
typedef struct ensemble_progress {
  kpcn_progress *outer;
  int k, n;
} ensemble_progress;

static int ensemble_progress_fn(void *user, double f) {
  ensemble_progress *e = user;
  return kpcn_progress_report(e->outer, (e->k + f) / e->n);
}

/* The colour scale that shows the KPCN the input at its exposure target (1 as rendered, for
 * the baselines, for a model that records no exposure and for a black image). */
static kpcn_status exposure_scale(kpcn_denoiser *d, const kpcn_aov_set *aov, float *scale) {
  *scale = 1.0f;
  if (d->opt.method != KPCN_DENOISE_KPCN) return KPCN_OK;
  const double t = d->opt.exposure > 0.0f    ? d->opt.exposure
                   : d->opt.exposure == 0.0f ? kpcn_model_arch(d->model)->exposure
                                             : 0.0;
  if (!(t > 0.0)) return KPCN_OK;
  double e;
  KPCN_TRY(kpcn_aov_exposure(aov, &e));
  d->stats.exposure = e;
  const double s = e > 0.0 ? t / e : 1.0;
  /* Beyond these the features cannot be formed in float: a scale below FLT_MIN is flushed to
   * 0 (an input near 5e37 then failed inside with "color scale 0"), and above 1e15 the
   * colour variance's cs^2 overflows (an input whose exposure is below ~1e-16 of the
   * model's reached the network as Inf/NaN variances and changed the result silently). */
  if (!(s >= FLT_MIN))
    return kpcn_fail(KPCN_ERR_NONFINITE,
                     "input: values near the float limit in the input (exposure %g; the model's "
                     "is %g)",
                     e, t);
  if (s > 1e15)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "input: exposure %g is too dim to be scaled to the model's %g (a scale of "
                     "%g; at most 1e15): scale the render up first",
                     e, t, s);
  *scale = (float)s;
  return KPCN_OK;
}

/* run_method on each transform of the ensemble, mapped back and averaged into out. The
 * members are summed in a fixed order, so the result does not depend on threads. Every
 * member sees the same colour scale `sc` (run_denoise measures it once). */
static kpcn_status run_ensemble(kpcn_denoiser *d, const kpcn_aov_set *aov, float sc, float *out) {
  const int n = d->opt.ensemble > 1 ? d->opt.ensemble : 1;
  if (n == 1) return run_method(d, aov, sc, out);
  const int W = aov->width, H = aov->height, nt = d->opt.nthreads;
  const size_t N = 3 * kpcn_aov_plane_size(aov);
  float *member = kpcn_aligned_alloc(sizeof(float) * N, "ensemble member output");
  float *back = kpcn_aligned_alloc(sizeof(float) * N, "ensemble member output");
  if (!member || !back) {
    kpcn_aligned_free(member);
    kpcn_aligned_free(back);
    return KPCN_ERR_OUT_OF_MEMORY;
  }
  kpcn_progress outer = d->prog;
  outer.cancelled = 0; /* the last execute's cancel is written back below: not this one's */
  ensemble_progress ep = {&outer, 0, n};
  d->prog.fn = outer.fn ? ensemble_progress_fn : NULL;
  d->prog.user = &ep;
  memset(out, 0, sizeof(float) * N);
  kpcn_status s = KPCN_OK;
  for (int k = 0; k < n && s == KPCN_OK; k++) {
    kpcn_augment_xform x, inv;
    kpcn_denoise_ensemble_xform(k, &x);
    int tw, th;
    kpcn_augment_output_size(&x, W, H, &tw, &th);
    ep.k = k;
    if (k == 0) {
      s = run_method(d, aov, sc, back);
    } else {
      kpcn_aov_set *t = NULL;
      s = kpcn_augment_aov(&t, aov, &x, nt);
      if (s == KPCN_OK) s = run_method(d, t, sc, member);
      kpcn_aov_destroy(t);
      kpcn_augment_inverse(&inv, &x, W, H);
      if (s == KPCN_OK) s = kpcn_augment_planes(back, member, 3, NULL, tw, th, &inv, nt);
    }
    for (size_t i = 0; s == KPCN_OK && i < N; i++)
      out[i] += back[i];
  }
  const float scale = 1.0f / (float)n; /* a power of two: exact */
  for (size_t i = 0; s == KPCN_OK && i < N; i++)
    out[i] *= scale;
  d->prog = outer; /* outer.cancelled was set by ensemble_progress_fn on a cancel */
  kpcn_aligned_free(member);
  kpcn_aligned_free(back);
  return s;
}

/* A malloc'd copy of n floats (NULL for a NULL src, or on failure with *s set). */
static float *dup_floats(const float *src, size_t n, kpcn_status *s) {
  if (!src || *s != KPCN_OK) return NULL;
  float *p = kpcn_alloc(sizeof(float) * n, "firefly-bounded input plane");
  if (!p) {
    *s = KPCN_ERR_OUT_OF_MEMORY;
    return NULL;
  }
  memcpy(p, src, sizeof(float) * n);
  return p;
}

/* A finite input can still come back non-finite when a model's weights are finite but absurd
 * (a damaged file, a diverged run): logits overflow to Inf and the softmax gives NaN. Refuse
 * such a result rather than return it as a success. */
static kpcn_status check_result(kpcn_status s, const float *out, size_t n) {
  if (s != KPCN_OK) return s;
  size_t bad = 0;
  for (size_t i = 0; i < n; i++)
    bad += !isfinite(out[i]);
  if (bad)
    return kpcn_fail(KPCN_ERR_NONFINITE,
                     "denoise: the result holds %zu non-finite value(s) (NaN/Inf) from a finite "
                     "input: values near the float limit in the input, or a model whose weights "
                     "overflow (a damaged or diverged model?)",
                     bad);
  return KPCN_OK;
}

/* The KPCN divides the diffuse by albedo + eps: a negative albedo (a pixel filter with negative
 * lobes, such as Lanczos or Mitchell) near -eps blows that up, and at -eps it is NaN, which
 * check_result then blamed on the model. Refused, naming the least value and where it is. */
static kpcn_status check_albedo(const kpcn_denoiser *d, const kpcn_aov_set *aov) {
  const float *a = aov->buf[KPCN_BUF_ALBEDO];
  if (!a) return KPCN_OK; /* kpcn_pipeline_require names it */
  const size_t P = kpcn_aov_plane_size(aov);
  size_t nneg = 0, at = 0;
  for (size_t i = 0; i < 3 * P; i++)
    if (a[i] < 0.0f) {
      if (!nneg || a[i] < a[at]) at = i;
      nneg++;
    }
  if (!nneg) return KPCN_OK;
  const size_t px = at % P;
  return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                   "denoise: the albedo holds %zu negative value(s), the least %g in albedo.%c at "
                   "pixel (%zu, %zu): the KPCN divides the diffuse by albedo + %g, so clamp the "
                   "albedo at 0 first (a pixel filter with negative lobes makes these)",
                   nneg, (double)a[at], "RGB"[at / P], px % (size_t)aov->width,
                   px / (size_t)aov->width, (double)kpcn_model_arch(d->model)->eps);
}

/* The exposure scale (measured on the input as given), the KPCN's firefly bound, then
 * run_ensemble, then the result check. The bound runs once, before the ensemble's mirrors and
 * rotations (it commutes with them), on a shallow copy of the input whose only own planes are the
 * three it changes: diffuse, its variance and colour (the other buffers stay the caller's, read
 * only). */
static kpcn_status run_denoise(kpcn_denoiser *d, const kpcn_aov_set *aov, float *out) {
  /* A NaN or Inf reaches every softmax window (and baseline weight) that sees it and comes back
   * as a patch of NaN while the call succeeds: refuse it, naming the buffer. */
  const char *bad = NULL;
  const size_t nbad = kpcn_aov_count_nonfinite(aov, &bad);
  if (nbad)
    return kpcn_fail(KPCN_ERR_NONFINITE,
                     "denoise: the input holds %zu non-finite value(s) (NaN/Inf), the first in "
                     "'%s'",
                     nbad, bad ? bad : "?");
  if (d->opt.method == KPCN_DENOISE_KPCN) {
    KPCN_TRY(kpcn_pipeline_require(aov)); /* before the exposure, whose message would be odd */
    KPCN_TRY(check_albedo(d, aov));
  }
  float sc;
  KPCN_TRY(exposure_scale(d, aov, &sc));
  d->stats.exposure_scale = sc;
  const size_t P = kpcn_aov_plane_size(aov);
  if (d->opt.method != KPCN_DENOISE_KPCN || d->opt.firefly == 0.0f)
    return check_result(run_ensemble(d, aov, sc, out), out, 3 * P);
  kpcn_status s = KPCN_OK;
  kpcn_aov_set b = *aov;
  b.buf[KPCN_BUF_DIFFUSE] = dup_floats(aov->buf[KPCN_BUF_DIFFUSE], 3 * P, &s);
  b.var[KPCN_BUF_DIFFUSE] = dup_floats(aov->var[KPCN_BUF_DIFFUSE], P, &s);
  b.buf[KPCN_BUF_COLOR] = dup_floats(aov->buf[KPCN_BUF_COLOR], 3 * P, &s);
  if (s == KPCN_OK)
    s = kpcn_aov_bound_fireflies(&b, d->opt.firefly, kpcn_model_arch(d->model)->eps,
                                 d->stats.exposure, /* measured once by exposure_scale; 0 =
                                                       not measured there: the bound measures */
                                 &d->stats.fireflies);
  if (s == KPCN_OK) s = run_ensemble(d, &b, sc, out);
  free(b.buf[KPCN_BUF_DIFFUSE]);
  free(b.var[KPCN_BUF_DIFFUSE]);
  free(b.buf[KPCN_BUF_COLOR]);
  return check_result(s, out, 3 * P);
}

/* Every buffer the KPCN reads, named as kpcn_denoiser_set_buffer spells them, in one message:
 * one missing at a time took an embedder seven calls to learn the list. */
static kpcn_status check_all_set(const kpcn_denoiser *d) {
  if (d->opt.method != KPCN_DENOISE_KPCN) return KPCN_OK; /* the baselines name theirs */
  static const kpcn_buffer need[] = {KPCN_BUF_DIFFUSE, KPCN_BUF_SPECULAR, KPCN_BUF_ALBEDO,
                                     KPCN_BUF_NORMAL,  KPCN_BUF_DEPTH,    KPCN_BUF_VISIBILITY};
  char list[256] = "";
  int n = 0;
  for (size_t i = 0; i < sizeof need / sizeof need[0]; i++)
    for (int v = 0; v < 2; v++) {
      const kpcn_buffer b = need[i];
      if (v ? d->var[b].ptr != NULL : d->buf[b][0].ptr != NULL) continue;
      snprintf(list + strlen(list), sizeof list - strlen(list), "%s%s%s", n++ ? ", " : "",
               kpcn_buffer_name(b), v ? ".var" : "");
    }
  if (!n) return KPCN_OK;
  return kpcn_fail(KPCN_ERR_MISSING_CHANNEL,
                   "denoiser_execute: the KPCN needs %d more buffer(s): %s (set with "
                   "kpcn_denoiser_set_buffer; docs/denoiser.md, \"Feeding it from a renderer\")",
                   n, list);
}

kpcn_status kpcn_denoiser_execute(kpcn_denoiser *d, float *out, int width, int height,
                                  size_t pixel_stride, size_t row_stride) {
  if (!d || !out)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "denoiser_execute: %s is NULL", !d ? "d" : "out");
  KPCN_TRY(kpcn_check_size(width, height, "denoiser output"));
  double t0 = now_s();
  memset(&d->stats, 0, sizeof d->stats);
  if (pixel_stride == 0) pixel_stride = 3 * sizeof(float);
  if (row_stride == 0) row_stride = (size_t)width * pixel_stride;
  KPCN_TRY(check_strides("denoiser output", width, pixel_stride, row_stride, 3 * sizeof(float)));
  KPCN_TRY(check_all_set(d));
  kpcn_aov_set *aov = NULL;
  float *rgb = NULL;
  kpcn_status s = assemble(d, width, height, &aov);
  if (s == KPCN_OK) {
    rgb = kpcn_aligned_alloc(sizeof(float) * 3 * kpcn_aov_plane_size(aov), "denoiser output");
    s = rgb ? run_denoise(d, aov, rgb) : KPCN_ERR_OUT_OF_MEMORY;
  }
  if (s == KPCN_OK) {
    const size_t P = kpcn_aov_plane_size(aov);
    for (int y = 0; y < height; y++) {
      char *row = (char *)out + (size_t)y * row_stride;
      for (int x = 0; x < width; x++) {
        float *px = (float *)(row + (size_t)x * pixel_stride);
        for (int c = 0; c < 3; c++)
          px[c] = rgb[c * P + (size_t)y * width + x];
      }
    }
  }
  kpcn_aligned_free(rgb);
  kpcn_aov_destroy(aov);
  d->stats.total_s = now_s() - t0;
  return s;
}

kpcn_status kpcn_denoiser_execute_aov(kpcn_denoiser *d, const kpcn_aov_set *aov,
                                      float *out_planar) {
  if (!d || !aov || !out_planar)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "denoiser_execute_aov: %s is NULL",
                     !d     ? "d"
                     : !aov ? "aov"
                            : "out_planar");
  KPCN_TRY(kpcn_check_size(aov->width, aov->height, "denoiser_execute_aov"));
  double t0 = now_s();
  memset(&d->stats, 0, sizeof d->stats);
  kpcn_status s = run_denoise(d, aov, out_planar);
  d->stats.total_s = now_s() - t0;
  return s;
}

/* Fails unless d is a KPCN denoiser; `what` names the caller. */
static kpcn_status require_kpcn(const kpcn_denoiser *d, const char *what) {
  if (d->opt.method == KPCN_DENOISE_KPCN) return KPCN_OK;
  return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                   "%s: only the KPCN predicts kernels, not the %s baseline", what,
                   d->opt.method == KPCN_DENOISE_BILATERAL ? "bilateral" : "nlmeans");
}

kpcn_status kpcn_denoiser_kernel_info(const kpcn_denoiser *d, int *kernel_size, int *passes,
                                      float *eps) {
  if (!d || !kernel_size)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "denoiser_kernel_info: %s is NULL",
                     !d ? "d" : "kernel_size");
  KPCN_TRY(require_kpcn(d, "denoiser_kernel_info"));
  const kpcn_arch *a = kpcn_model_arch(d->model);
  *kernel_size = a->kernel_size;
  if (passes) *passes = kpcn_arch_kpa_passes(a);
  if (eps) *eps = a->eps;
  return KPCN_OK;
}

kpcn_status kpcn_denoiser_kernels_aov(kpcn_denoiser *d, const kpcn_aov_set *aov, int branch,
                                      float *weights, float *noisy_pre) {
  if (!d || !aov || !weights)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "denoiser_kernels: %s is NULL",
                     !d     ? "d"
                     : !aov ? "aov"
                            : "weights");
  KPCN_TRY(require_kpcn(d, "denoiser_kernels"));
  if (branch != KPCN_BRANCH_DIFFUSE && branch != KPCN_BRANCH_SPECULAR)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "denoiser_kernels: branch %d is neither diffuse (0) nor specular (1)", branch);
  if (d->opt.ensemble > 1)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "denoiser_kernels: a self-ensemble (ensemble = %d) averages %d results, "
                     "each with its own kernels; export them with ensemble = 1",
                     d->opt.ensemble, d->opt.ensemble);
  if (kpcn_model_arch(d->model)->source_weight)
    return kpcn_fail(KPCN_ERR_UNSUPPORTED,
                     "denoiser_kernels: the model weights its sources (source_weight), so its "
                     "first kernel pass is not the plain weighted sum the export describes");
  KPCN_TRY(kpcn_check_size(aov->width, aov->height, "denoiser_kernels"));
  double t0 = now_s();
  memset(&d->stats, 0, sizeof d->stats);
  /* the run's image: only the branch's part is computed, onto zeros */
  float *out = kpcn_calloc(3 * kpcn_aov_plane_size(aov), sizeof(float), "denoiser output");
  if (!out) return KPCN_ERR_OUT_OF_MEMORY;
  const kpcn_kernel_sink sink = {branch, weights, noisy_pre};
  d->sink = &sink;
  kpcn_status s = run_denoise(d, aov, out);
  d->sink = NULL;
  free(out);
  d->stats.total_s = now_s() - t0;
  return s;
}

kpcn_status kpcn_denoise_aov_stats(const kpcn_aov_set *aov, const kpcn_denoiser_options *opts,
                                   kpcn_image **out_rgb, kpcn_denoise_stats *stats) {
  if (!aov || !out_rgb)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "denoise_aov: %s is NULL",
                     !aov ? "aov" : "out_rgb");
  *out_rgb = NULL;
  kpcn_denoiser *d = NULL;
  KPCN_TRY(kpcn_denoiser_create(&d, opts));
  static const char *const names[3] = {"R", "G", "B"};
  kpcn_image *img = NULL;
  kpcn_status s = kpcn_image_create(&img, aov->width, aov->height, 3, names);
  if (s == KPCN_OK) s = kpcn_denoiser_execute_aov(d, aov, img->data);
  if (s == KPCN_OK && stats) kpcn_denoiser_get_stats(d, stats);
  kpcn_denoiser_destroy(d);
  if (s != KPCN_OK) {
    kpcn_image_destroy(img);
    return s;
  }
  *out_rgb = img;
  return KPCN_OK;
}

kpcn_status kpcn_denoise_aov(const kpcn_aov_set *aov, const kpcn_denoiser_options *opts,
                             kpcn_image **out_rgb) {
  return kpcn_denoise_aov_stats(aov, opts, out_rgb, NULL);
}
