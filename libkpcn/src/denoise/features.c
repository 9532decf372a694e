/* Network input preprocessing shared by inference and training (kpcn/denoise.h §1).
 * The single place that defines what the network sees. */
#include "core/internal.h"
#include "kpcn/denoise.h"

#include <math.h>
#include <omp.h>
#include <stdint.h>
#include <stdlib.h>
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
  norm->color_scale = 1.0f;
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

/* Preprocessed color of one channel (col already exposure-scaled): diffuse / (albedo + eps),
 * or log(1 + specular). */
static inline float pre_color(int branch, float col, float alb, float eps) {
  if (branch == KPCN_BRANCH_DIFFUSE) return col / (alb + eps);
  return log1pf(col > 0.0f ? col : 0.0f);
}

/* Central differences of one source row over the region's columns, edges clamped:
 * dx = ((r[x+1] - off) * sc - (r[x-1] - off) * sc) / 2, dy likewise from rows d and u.
 * The rows are indexed from column `org` (r[x - org] is column x). */
static void grad_row(const float *restrict r, const float *restrict u, const float *restrict d,
                     int org, int x0, int w, int W, float off, float sc, float *restrict dx,
                     float *restrict dy) {
  for (int xx = 0; xx < w; xx++) {
    const int x = x0 + xx, xm = x > 0 ? x - 1 : 0, xp = x < W - 1 ? x + 1 : W - 1;
    dx[xx] = 0.5f * ((r[xp - org] - off) * sc - (r[xm - org] - off) * sc);
    dy[xx] = 0.5f * ((d[x - org] - off) * sc - (u[x - org] - off) * sc);
  }
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
  const kpcn_buffer cb = branch == KPCN_BRANCH_DIFFUSE ? KPCN_BUF_DIFFUSE : KPCN_BUF_SPECULAR;
  const float *col = aov->buf[cb], *alb = aov->buf[KPCN_BUF_ALBEDO],
              *nrm = aov->buf[KPCN_BUF_NORMAL], *z = aov->buf[KPCN_BUF_DEPTH];
  const float *cvar = aov->var[cb], *nvar = aov->var[KPCN_BUF_NORMAL],
              *avar = aov->var[KPCN_BUF_ALBEDO], *zvar = aov->var[KPCN_BUF_DEPTH],
              *vis = aov->buf[KPCN_BUF_VISIBILITY], *visvar = aov->var[KPCN_BUF_VISIBILITY];
  const float zoff = nm.depth_offset, zs = nm.depth_scale, cs = nm.color_scale;
  if (!(cs > 0.0f) || !isfinite(cs))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "features_build: color scale %g must be > 0",
                     (double)cs);
  const size_t Q = (size_t)w * h;
  if (out_stride && out_stride < Q)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "features_build: plane stride %zu is smaller than the %dx%d region",
                     out_stride, w, h);
  const size_t S = out_stride ? out_stride : Q; /* feature plane stride */
  const int nt = kpcn_resolve_threads(nthreads);
  /* The preprocessed color (a log1p per value for specular) is needed at each pixel and its
   * four neighbours. Each thread takes a contiguous band of rows and keeps the preprocessed
   * rows y-1, y, y+1 of columns [xa, xb] in a three-row ring, so every value is computed
   * once; everything else is row loops the compiler vectorizes. */
  const int xa = x0 > 0 ? x0 - 1 : 0, xb = x0 + w < W ? x0 + w : W - 1, rw = xb - xa + 1;
  float *ring = kpcn_alloc(sizeof(float) * 9 * (size_t)rw * (size_t)nt, "feature rows");
  if (!ring) return KPCN_ERR_OUT_OF_MEMORY;

#pragma omp parallel num_threads(nt)
  {
    const int t = omp_get_thread_num(), T = omp_get_num_threads();
    const int ya = (int)((int64_t)h * t / T), yb = (int)((int64_t)h * (t + 1) / T);
    float *rows = ring + (size_t)9 * rw * t; /* [slot 3][channel 3][rw] */
    int held[3] = {-1, -1, -1};
    for (int yy = ya; yy < yb; yy++) {
      const int y = y0 + yy, ym = y > 0 ? y - 1 : 0, yp = y < H - 1 ? y + 1 : H - 1;
      const int need[3] = {ym, y, yp};
      for (int k = 0; k < 3; k++) {
        const int r = need[k], slot = r % 3;
        if (held[slot] == r) continue;
        for (int c = 0; c < 3; c++) {
          const size_t base = (size_t)c * P + (size_t)r * W + xa;
          float *dst = rows + (size_t)(slot * 3 + c) * rw;
          for (int x = 0; x < rw; x++)
            dst[x] = pre_color(branch, cs * col[base + x], alb[base + x], eps);
        }
        held[slot] = r;
      }
      const size_t o = (size_t)yy * w, i = (size_t)y * W + x0;
      for (int c = 0; c < 3; c++) {
        const float *cur = rows + (size_t)((y % 3) * 3 + c) * rw;
        const float *up = rows + (size_t)((ym % 3) * 3 + c) * rw;
        const float *dn = rows + (size_t)((yp % 3) * 3 + c) * rw;
        if (noisy_pre) memcpy(noisy_pre + c * Q + o, cur + (x0 - xa), sizeof(float) * w);
        if (!out) continue;
        memcpy(out + (F_COLOR + c) * S + o, cur + (x0 - xa), sizeof(float) * w);
        memcpy(out + (F_N + c) * S + o, nrm + c * P + i, sizeof(float) * w);
        memcpy(out + (F_ALB + c) * S + o, alb + c * P + i, sizeof(float) * w);
        grad_row(cur, up, dn, xa, x0, w, W, 0.0f, 1.0f, out + (F_DX + c) * S + o,
                 out + (F_DY + c) * S + o);
        const size_t rc = c * P + (size_t)y * W, ru = c * P + (size_t)ym * W,
                     rd = c * P + (size_t)yp * W;
        grad_row(nrm + rc, nrm + ru, nrm + rd, 0, x0, w, W, 0.0f, 1.0f,
                 out + (F_DX + 3 + c) * S + o, out + (F_DY + 3 + c) * S + o);
        grad_row(alb + rc, alb + ru, alb + rd, 0, x0, w, W, 0.0f, 1.0f,
                 out + (F_DX + 6 + c) * S + o, out + (F_DY + 6 + c) * S + o);
      }
      if (!out) continue;
      /* color variance in the preprocessed space: var / d² averaged over the channels, with
       * d the derivative's inverse (albedo + eps, or 1 + specular) */
      float *cv = out + F_COLOR_VAR * S + o;
      for (int xx = 0; xx < w; xx++) {
        float vscale = 0.0f;
        for (int c = 0; c < 3; c++) {
          const size_t k = c * P + i + xx;
          const float v = cs * col[k];
          const float d =
              branch == KPCN_BRANCH_DIFFUSE ? alb[k] + eps : 1.0f + (v > 0.0f ? v : 0.0f);
          vscale += 1.0f / (d * d);
        }
        cv[xx] = cs * cs * cvar[i + xx] * (vscale / 3.0f);
      }
      float *fz = out + F_Z * S + o, *fzv = out + F_Z_VAR * S + o;
      for (int xx = 0; xx < w; xx++) {
        fz[xx] = (z[i + xx] - zoff) * zs;
        fzv[xx] = zvar[i + xx] * zs * zs;
      }
      memcpy(out + F_N_VAR * S + o, nvar + i, sizeof(float) * w);
      memcpy(out + F_ALB_VAR * S + o, avar + i, sizeof(float) * w);
      memcpy(out + F_VIS * S + o, vis + i, sizeof(float) * w);
      memcpy(out + F_VIS_VAR * S + o, visvar + i, sizeof(float) * w);
      grad_row(z + (size_t)y * W, z + (size_t)ym * W, z + (size_t)yp * W, 0, x0, w, W, zoff, zs,
               out + (F_DX + 9) * S + o, out + (F_DY + 9) * S + o);
    }
  }
  free(ring);
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
