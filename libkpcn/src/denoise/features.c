/* Network input preprocessing shared by inference and training (kpcn/denoise.h §1).
 * The single place that defines what the network sees. */
#include "core/internal.h"
#include "kpcn/denoise.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

static const char *const k_names[KPCN_FEATURES_COUNT] = {
    "color.R",     "color.G", "color.B",      "color.var",      "N.X",         "N.Y",
    "N.Z",         "N.var",   "albedo.R",     "albedo.G",       "albedo.B",    "albedo.var",
    "Z",           "Z.var",   "visibility.V", "visibility.var", "dx.color.R",  "dx.color.G",
    "dx.color.B",  "dx.N.X",  "dx.N.Y",       "dx.N.Z",         "dx.albedo.R", "dx.albedo.G",
    "dx.albedo.B", "dx.Z",    "dy.color.R",   "dy.color.G",     "dy.color.B",  "dy.N.X",
    "dy.N.Y",      "dy.N.Z",  "dy.albedo.R",  "dy.albedo.G",    "dy.albedo.B", "dy.Z"};

/* Feature channel layout (indices into the list above). */
enum {
  F_COLOR = 0,
  F_COLOR_VAR = 3,
  F_N = 4,
  F_N_VAR = 7,
  F_ALB = 8,
  F_ALB_VAR = 11,
  F_Z = 12,
  F_Z_VAR = 13,
  F_VIS = 14,
  F_VIS_VAR = 15,
  F_DX = 16,
  F_DY = 26,
  N_GRAD = 10 /* color(3) normal(3) albedo(3) depth(1) */
};

const char *kpcn_branch_name(int branch) {
  return branch == KPCN_BRANCH_DIFFUSE    ? "diffuse"
         : branch == KPCN_BRANCH_SPECULAR ? "specular"
                                          : NULL;
}

int kpcn_features_count(int branch) { return kpcn_branch_name(branch) ? KPCN_FEATURES_COUNT : -1; }

int kpcn_features_channel_names(int branch, const char **names, int max) {
  if (!kpcn_branch_name(branch)) return -1;
  for (int i = 0; names && i < KPCN_FEATURES_COUNT && i < max; i++)
    names[i] = k_names[i];
  return KPCN_FEATURES_COUNT;
}

kpcn_status kpcn_features_norm_compute(const kpcn_aov_set *aov, kpcn_features_norm *norm) {
  if (!aov || !norm)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "features_norm_compute: NULL argument");
  KPCN_TRY(kpcn_aov_require(aov, KPCN_BUF_DEPTH, 0, "depth normalisation"));
  const float *z = aov->buf[KPCN_BUF_DEPTH];
  size_t n = kpcn_aov_plane_size(aov);
  float lo = INFINITY, hi = -INFINITY;
  for (size_t i = 0; i < n; i++) {
    if (!isfinite(z[i])) continue;
    lo = z[i] < lo ? z[i] : lo;
    hi = z[i] > hi ? z[i] : hi;
  }
  if (!(lo <= hi)) lo = hi = 0.0f; /* no finite depth at all */
  norm->depth_offset = lo;
  norm->depth_scale = (double)hi - (double)lo > 1e-12 ? (float)(1.0 / ((double)hi - lo)) : 1.0f;
  return KPCN_OK;
}

/* Required inputs of a branch, checked up front so the error names the first absent one. */
static kpcn_status require_inputs(const kpcn_aov_set *aov, int branch) {
  kpcn_buffer cb = branch == KPCN_BRANCH_DIFFUSE ? KPCN_BUF_DIFFUSE : KPCN_BUF_SPECULAR;
  const kpcn_buffer need[] = {cb, KPCN_BUF_ALBEDO, KPCN_BUF_NORMAL, KPCN_BUF_DEPTH,
                              KPCN_BUF_VISIBILITY};
  for (size_t i = 0; i < sizeof need / sizeof need[0]; i++)
    KPCN_TRY(kpcn_aov_require(aov, need[i], 1, "KPCN features"));
  return KPCN_OK;
}

/* Value of gradient source channel g (0..9) at full-image pixel index i. Sources are the
 * preprocessed color (computed on the fly, so neighbours outside a region are exact),
 * normal, albedo, normalised depth. */
typedef struct src_ctx {
  const float *col[3], *alb[3], *nrm[3], *z;
  int branch;
  float eps, zoff, zscale;
} src_ctx;

static inline float pre_color(const src_ctx *s, int c, size_t i) {
  if (s->branch == KPCN_BRANCH_DIFFUSE) return s->col[c][i] / (s->alb[c][i] + s->eps);
  float v = s->col[c][i];
  return log1pf(v > 0.0f ? v : 0.0f);
}

static inline float grad_src(const src_ctx *s, int g, size_t i) {
  if (g < 3) return pre_color(s, g, i);
  if (g < 6) return s->nrm[g - 3][i];
  if (g < 9) return s->alb[g - 6][i];
  return (s->z[i] - s->zoff) * s->zscale;
}

kpcn_status kpcn_features_build_region(const kpcn_aov_set *aov, int branch, float eps,
                                       const kpcn_features_norm *norm, int x0, int y0, int w, int h,
                                       float *out, size_t out_stride, float *noisy_pre,
                                       int nthreads) {
  if (!aov) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "features_build: aov is NULL");
  if (!kpcn_branch_name(branch))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "features_build: bad branch %d", branch);
  if (!(eps > 0.0f) || !isfinite(eps))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "features_build: eps must be > 0 (got %g)",
                     (double)eps);
  if (w <= 0 || h <= 0 || x0 < 0 || y0 < 0 || x0 + w > aov->width || y0 + h > aov->height)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "features_build: region %dx%d+%d+%d outside the %dx%d image", w, h, x0, y0,
                     aov->width, aov->height);
  KPCN_TRY(require_inputs(aov, branch));
  kpcn_features_norm nm;
  if (norm)
    nm = *norm;
  else
    KPCN_TRY(kpcn_features_norm_compute(aov, &nm));

  const size_t P = kpcn_aov_plane_size(aov);
  const int W = aov->width, H = aov->height;
  src_ctx s;
  kpcn_buffer cb = branch == KPCN_BRANCH_DIFFUSE ? KPCN_BUF_DIFFUSE : KPCN_BUF_SPECULAR;
  for (int c = 0; c < 3; c++) {
    s.col[c] = aov->buf[cb] + c * P;
    s.alb[c] = aov->buf[KPCN_BUF_ALBEDO] + c * P;
    s.nrm[c] = aov->buf[KPCN_BUF_NORMAL] + c * P;
  }
  s.z = aov->buf[KPCN_BUF_DEPTH];
  s.branch = branch;
  s.eps = eps;
  s.zoff = nm.depth_offset;
  s.zscale = nm.depth_scale;
  const float *cvar = aov->var[cb], *nvar = aov->var[KPCN_BUF_NORMAL],
              *avar = aov->var[KPCN_BUF_ALBEDO], *zvar = aov->var[KPCN_BUF_DEPTH],
              *vis = aov->buf[KPCN_BUF_VISIBILITY], *visvar = aov->var[KPCN_BUF_VISIBILITY];
  const size_t Q = (size_t)w * h;
  if (out_stride && out_stride < Q)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "features_build: plane stride %zu is smaller than the %dx%d region",
                     out_stride, w, h);
  const size_t S = out_stride ? out_stride : Q; /* feature plane stride */
  const int nt = kpcn_resolve_threads(nthreads);

#pragma omp parallel for num_threads(nt) schedule(static)
  for (int yy = 0; yy < h; yy++) {
    const int y = y0 + yy;
    const int ym = y > 0 ? y - 1 : 0, yp = y < H - 1 ? y + 1 : H - 1;
    for (int xx = 0; xx < w; xx++) {
      const int x = x0 + xx;
      const int xm = x > 0 ? x - 1 : 0, xp = x < W - 1 ? x + 1 : W - 1;
      const size_t i = (size_t)y * W + x, o = (size_t)yy * w + xx;
      float pc[3], vscale = 0.0f;
      for (int c = 0; c < 3; c++) {
        pc[c] = pre_color(&s, c, i);
        float d;
        if (branch == KPCN_BRANCH_DIFFUSE)
          d = s.alb[c][i] + eps;
        else
          d = 1.0f + (s.col[c][i] > 0.0f ? s.col[c][i] : 0.0f);
        vscale += 1.0f / (d * d);
      }
      if (noisy_pre)
        for (int c = 0; c < 3; c++)
          noisy_pre[c * Q + o] = pc[c];
      if (!out) continue;
      for (int c = 0; c < 3; c++) {
        out[(F_COLOR + c) * S + o] = pc[c];
        out[(F_N + c) * S + o] = s.nrm[c][i];
        out[(F_ALB + c) * S + o] = s.alb[c][i];
      }
      out[F_COLOR_VAR * S + o] = cvar[i] * (vscale / 3.0f);
      out[F_N_VAR * S + o] = nvar[i];
      out[F_ALB_VAR * S + o] = avar[i];
      out[F_Z * S + o] = (s.z[i] - s.zoff) * s.zscale;
      out[F_Z_VAR * S + o] = zvar[i] * s.zscale * s.zscale;
      out[F_VIS * S + o] = vis[i];
      out[F_VIS_VAR * S + o] = visvar[i];
      const size_t il = (size_t)y * W + xm, ir = (size_t)y * W + xp;
      const size_t iu = (size_t)ym * W + x, id = (size_t)yp * W + x;
      for (int g = 0; g < N_GRAD; g++) {
        out[(F_DX + g) * S + o] = 0.5f * (grad_src(&s, g, ir) - grad_src(&s, g, il));
        out[(F_DY + g) * S + o] = 0.5f * (grad_src(&s, g, id) - grad_src(&s, g, iu));
      }
    }
  }
  return KPCN_OK;
}

kpcn_status kpcn_features_build(const kpcn_aov_set *aov, int branch, float eps,
                                const kpcn_features_norm *norm, float *out_planar, float *noisy_pre,
                                int nthreads) {
  if (!aov) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "features_build: aov is NULL");
  return kpcn_features_build_region(aov, branch, eps, norm, 0, 0, aov->width, aov->height,
                                    out_planar, 0, noisy_pre, nthreads);
}

/* ---- element-wise transforms ---- */
void kpcn_demodulate_diffuse(const float *diffuse, const float *albedo, float eps, size_t n,
                             float *out) {
  for (size_t i = 0; i < n; i++)
    out[i] = diffuse[i] / (albedo[i] + eps);
}

void kpcn_log_specular(const float *specular, size_t n, float *out) {
  for (size_t i = 0; i < n; i++)
    out[i] = log1pf(specular[i] > 0.0f ? specular[i] : 0.0f);
}

void kpcn_remodulate_diffuse(const float *diffuse_out, const float *albedo, float eps, size_t n,
                             float *out) {
  for (size_t i = 0; i < n; i++)
    out[i] = diffuse_out[i] * (albedo[i] + eps);
}

void kpcn_exp_specular(const float *spec_out, size_t n, float *out) {
  for (size_t i = 0; i < n; i++)
    out[i] = expm1f(spec_out[i]);
}

void kpcn_recombine(const float *diffuse_out, const float *spec_out, const float *albedo, float eps,
                    size_t n, float *out) {
  for (size_t i = 0; i < n; i++) {
    float v = 0.0f;
    if (diffuse_out) v += diffuse_out[i] * (albedo[i] + eps);
    if (spec_out) v += expm1f(spec_out[i]);
    out[i] = v;
  }
}

void kpcn_recombine_backward(const float *grad_out, const float *spec_out, const float *albedo,
                             float eps, size_t n, float *grad_diffuse, float *grad_spec) {
  for (size_t i = 0; i < n; i++) {
    if (grad_diffuse) grad_diffuse[i] = grad_out[i] * (albedo[i] + eps);
    if (grad_spec) grad_spec[i] = grad_out[i] * expf(spec_out[i]);
  }
}

kpcn_status kpcn_features_set_arch(kpcn_arch *arch) {
  if (!arch) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "features_set_arch: arch is NULL");
  KPCN_TRY(kpcn_arch_set_inputs(arch, KPCN_FEATURES_COUNT, k_names));
  snprintf(arch->preprocess, sizeof arch->preprocess, "%s", KPCN_FEATURES_PREPROCESS);
  return KPCN_OK;
}

kpcn_status kpcn_features_check_arch(const kpcn_arch *arch) {
  if (!arch) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "features_check_arch: arch is NULL");
  if (strcmp(arch->preprocess, KPCN_FEATURES_PREPROCESS) != 0)
    return kpcn_fail(KPCN_ERR_UNSUPPORTED,
                     "model preprocessing '%s' differs from this denoiser's '%s'", arch->preprocess,
                     KPCN_FEATURES_PREPROCESS);
  if (arch->n_inputs != KPCN_FEATURES_COUNT)
    return kpcn_fail(KPCN_ERR_UNSUPPORTED,
                     "model expects %d input channels, the denoiser builds %d", arch->n_inputs,
                     KPCN_FEATURES_COUNT);
  for (int i = 0; i < KPCN_FEATURES_COUNT; i++)
    if (strcmp(arch->inputs[i], k_names[i]) != 0)
      return kpcn_fail(KPCN_ERR_UNSUPPORTED, "model input %d is '%s', the denoiser builds '%s'", i,
                       arch->inputs[i], k_names[i]);
  if (!(arch->eps > 0.0f) || !isfinite(arch->eps))
    return kpcn_fail(KPCN_ERR_FORMAT, "model eps %g must be > 0", (double)arch->eps);
  return KPCN_OK;
}
