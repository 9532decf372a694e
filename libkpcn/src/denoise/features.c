/* Network input preprocessing shared by inference and training (kpcn/denoise.h §1).
 * The single place that defines what the network sees. */
#include "core/internal.h"
#include "core/transpose16.h"
#include "denoise/denoise_internal.h"
#include "kpcn/denoise.h"

#include <math.h>
#include <omp.h>
#include <stdint.h>
#include <stdlib.h>
#include <stdio.h>
#include <string.h>

/* As in nn/kpa.c: GCC will not if-convert the float compares of log1p_nonneg's loops (so not
 * vectorize them) while FP exceptions are assumed observable; this file never inspects them.
 * No FMA contraction either: a vectorized loop and its scalar remainder contracted
 * log1p_nonneg's products differently, so a pixel's feature depended on where its tile began
 * (untiled vs tile=16 differed in the last bits); without contraction every path rounds each
 * operation alike. */
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC optimize("no-trapping-math", "fp-contract=off")
#endif

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

/* Required inputs of a branch, checked up front so the error names every absent one. */
static kpcn_status require_inputs(const kpcn_aov_set *aov, int branch) {
  kpcn_buffer cb = branch == KPCN_BRANCH_DIFFUSE ? KPCN_BUF_DIFFUSE : KPCN_BUF_SPECULAR;
  const kpcn_buffer need[] = {cb, KPCN_BUF_ALBEDO, KPCN_BUF_NORMAL, KPCN_BUF_DEPTH,
                              KPCN_BUF_VISIBILITY};
  return kpcn_aov_require_list(aov, need, (int)(sizeof need / sizeof need[0]), 1, "KPCN features");
}

/* log(1 + x) for x >= 0 (finite), in plain arithmetic the compiler vectorizes: glibc's
 * log1pf is a scalar call, and it was a third of the specular branch's feature building.
 * The classic float method (as in fdlibm). u = 1 + x is rounded; c = (1 + x - u) / u is the
 * first-order correction for that rounding. Then u = 2^k m with m in [sqrt(2)/2, sqrt(2)),
 * f = m - 1, s = f / (2 + f), and log m = f - f²/2 + s (f²/2 + R(s²)) with R's degree-4
 * minimax coefficients. Small x is exact to the last bit (u = 1: the result is x).
 * test_denoise_features compares it with double log1p over [0, 3.4e38]. */
static inline float log1p_nonneg(float x) {
  const float u = 1.0f + x;
  uint32_t iu;
  memcpy(&iu, &u, 4);
  iu += 0x3f800000u - 0x3f3504f3u; /* k counts from sqrt(2)/2 */
  const int k = (int)(iu >> 23) - 0x7f;
  iu = (iu & 0x007fffffu) + 0x3f3504f3u;
  float m;
  memcpy(&m, &iu, 4);
  /* u - 1 (k < 2) and u - x (k >= 2) are exact: Sterbenz. Both are computed and one is
   * selected (a branch here kept the loops from vectorizing). */
  const float c_hi = 1.0f - (u - x), c_lo = x - (u - 1.0f);
  const float c = (k >= 2 ? c_hi : c_lo) / u;
  const float f = m - 1.0f, s = f / (2.0f + f), z = s * s, w = z * z;
  const float R =
      z * (0.66666662693f + w * 0.28498786688f) + w * (0.40000972152f + w * 0.24279078841f);
  const float hfsq = 0.5f * f * f, dk = (float)k;
  return s * (hfsq + R) + (dk * 9.0580006145e-06f + c) - hfsq + f + dk * 6.9313812256e-01f;
}

/* Preprocessed color of one channel (col already exposure-scaled): diffuse / (albedo + eps),
 * or log(1 + specular). */
static inline float pre_color(int branch, float col, float alb, float eps) {
  if (branch == KPCN_BRANCH_DIFFUSE) return col / (alb + eps);
  return log1p_nonneg(col > 0.0f ? col : 0.0f);
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

/* The bfloat16 nearest to f (ties to even), as vcvtneps2bf16 rounds: denormals flush to
 * (signed) zero, NaN stays a quiet NaN. */
static uint16_t bf16_rne(float f) {
  uint32_t u;
  memcpy(&u, &f, 4);
  if ((u & 0x7f800000u) == 0x7f800000u && (u & 0x007fffffu)) return (uint16_t)((u >> 16) | 0x40u);
  if ((u & 0x7f800000u) == 0) return (uint16_t)((u >> 16) & 0x8000u);
  u += 0x7fffu + ((u >> 16) & 1u);
  return (uint16_t)(u >> 16);
}

/* dst[x * ps + c] = rows[c * rs + x] for c < nc, x < w: one row of planar features to the
 * pixel-major layout of a net's input, as floats or bf16. */
static void emit_pixels(const float *rows, size_t rs, int nc, int w, void *dst, int ps, int bf16) {
  for (int x = 0; x < w; x++)
    for (int c = 0; c < nc; c++) {
      const float v = rows[(size_t)c * rs + x];
      if (bf16)
        ((uint16_t *)dst)[(size_t)x * ps + c] = bf16_rne(v);
      else
        ((float *)dst)[(size_t)x * ps + c] = v;
    }
}

#ifdef KPCN_HAVE_T16
/* The same with 16 x 16 register transposes (16 pixels x up to 16 channels a block, masked
 * at the row's and the channels' ends) and vcvtneps2bf16 for bf16: the conversion oneDNN's
 * reorder uses, so a net fed this way sees the bits its own input reorder would give it. */
__attribute__((target("avx512f,avx512bw,avx512vl,avx512bf16"))) static void
emit_pixels16(const float *rows, size_t rs, int nc, int w, void *dst, int ps, int bf16) {
  for (int x0 = 0; x0 < w; x0 += 16) {
    const int np = w - x0 < 16 ? w - x0 : 16;
    const __mmask16 pm = (__mmask16)((1u << np) - 1u);
    for (int c0 = 0; c0 < nc; c0 += 16) {
      const int nb = nc - c0 < 16 ? nc - c0 : 16;
      const __mmask16 cm = (__mmask16)((1u << nb) - 1u);
      __m512 r[16], row[16];
      for (int i = 0; i < 16; i++)
        r[i] = i < nb ? _mm512_maskz_loadu_ps(pm, rows + (size_t)(c0 + i) * rs + x0)
                      : _mm512_setzero_ps();
      transpose16_regs(r, row);
      for (int j = 0; j < np; j++) {
        const size_t at = (size_t)(x0 + j) * ps + c0;
        if (bf16)
          _mm256_mask_storeu_epi16((uint16_t *)dst + at, cm, (__m256i)_mm512_cvtneps_pbh(row[j]));
        else
          _mm512_mask_storeu_ps((float *)dst + at, cm, row[j]);
      }
    }
  }
}
#endif

int kpcn_features_pixels_fast(int bf16) {
#ifdef KPCN_HAVE_T16
  return kpcn_cpu_allows_avx512() && __builtin_cpu_supports("avx512bw") &&
         __builtin_cpu_supports("avx512vl") && (!bf16 || __builtin_cpu_supports("avx512bf16"));
#else
  (void)bf16;
  return 0;
#endif
}

/* Builds the features into planar planes S floats apart (out, may be NULL) or, when px is
 * non-NULL, pixel-major into px (pixel stride ps, floats or bf16) through a per-thread row
 * buffer. */
static kpcn_status build_region(const kpcn_aov_set *aov, int branch, float eps,
                                const kpcn_features_norm *norm, int x0, int y0, int w, int h,
                                float *out, size_t out_stride, void *px, int ps, int bf16,
                                float *noisy_pre, int nthreads) {
  if (!aov) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "features_build: aov is NULL");
  if (!kpcn_branch_name(branch))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "features_build: bad branch %d", branch);
  if (!(eps > 0.0f) || !isfinite(eps))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "features_build: eps must be > 0 (got %g)",
                     (double)eps);
  if (w <= 0 || h <= 0 || x0 < 0 || y0 < 0 || w > aov->width - x0 || h > aov->height - y0)
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
  /* per thread: the colour ring, and for pixel-major output one row of every feature */
  const size_t per = 9 * (size_t)rw + (px ? (size_t)KPCN_FEATURES_COUNT * w : 0);
  float *ring = kpcn_alloc(sizeof(float) * per * (size_t)nt, "feature rows");
  if (!ring) return KPCN_ERR_OUT_OF_MEMORY;
  const int e16 = px ? kpcn_features_pixels_fast(bf16) : 0;
  const size_t es = bf16 ? 2 : 4;

#pragma omp parallel num_threads(nt)
  {
    const int t = omp_get_thread_num(), T = omp_get_num_threads();
    const int ya = (int)((int64_t)h * t / T), yb = (int)((int64_t)h * (t + 1) / T);
    float *rows = ring + per * t;                    /* [slot 3][channel 3][rw] */
    float *prow = px ? rows + (size_t)9 * rw : NULL; /* [feature][w] */
    /* where this row's features go: planes S apart at offset o, or prow's rows */
    float *const ob = px ? prow : out;
    const size_t Sb = px ? (size_t)w : S;
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
          if (branch == KPCN_BRANCH_DIFFUSE) /* two loops: each vectorizes */
            for (int x = 0; x < rw; x++)
              dst[x] = pre_color(KPCN_BRANCH_DIFFUSE, cs * col[base + x], alb[base + x], eps);
          else
            for (int x = 0; x < rw; x++)
              dst[x] = pre_color(KPCN_BRANCH_SPECULAR, cs * col[base + x], alb[base + x], eps);
        }
        held[slot] = r;
      }
      const size_t o = (size_t)yy * w, i = (size_t)y * W + x0, oo = px ? 0 : o;
      for (int c = 0; c < 3; c++) {
        const float *cur = rows + (size_t)((y % 3) * 3 + c) * rw;
        const float *up = rows + (size_t)((ym % 3) * 3 + c) * rw;
        const float *dn = rows + (size_t)((yp % 3) * 3 + c) * rw;
        if (noisy_pre) memcpy(noisy_pre + c * Q + o, cur + (x0 - xa), sizeof(float) * w);
        if (!ob) continue;
        memcpy(ob + (F_COLOR + c) * Sb + oo, cur + (x0 - xa), sizeof(float) * w);
        memcpy(ob + (F_N + c) * Sb + oo, nrm + c * P + i, sizeof(float) * w);
        memcpy(ob + (F_ALB + c) * Sb + oo, alb + c * P + i, sizeof(float) * w);
        grad_row(cur, up, dn, xa, x0, w, W, 0.0f, 1.0f, ob + (F_DX + c) * Sb + oo,
                 ob + (F_DY + c) * Sb + oo);
        const size_t rc = c * P + (size_t)y * W, ru = c * P + (size_t)ym * W,
                     rd = c * P + (size_t)yp * W;
        grad_row(nrm + rc, nrm + ru, nrm + rd, 0, x0, w, W, 0.0f, 1.0f,
                 ob + (F_DX + 3 + c) * Sb + oo, ob + (F_DY + 3 + c) * Sb + oo);
        grad_row(alb + rc, alb + ru, alb + rd, 0, x0, w, W, 0.0f, 1.0f,
                 ob + (F_DX + 6 + c) * Sb + oo, ob + (F_DY + 6 + c) * Sb + oo);
      }
      if (!ob) continue;
      /* color variance in the preprocessed space: var / d² averaged over the channels, with
       * d the derivative's inverse (albedo + eps, or 1 + specular) */
      float *cv = ob + F_COLOR_VAR * Sb + oo;
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
      float *fz = ob + F_Z * Sb + oo, *fzv = ob + F_Z_VAR * Sb + oo;
      for (int xx = 0; xx < w; xx++) {
        fz[xx] = (z[i + xx] - zoff) * zs;
        fzv[xx] = zvar[i + xx] * zs * zs;
      }
      memcpy(ob + F_N_VAR * Sb + oo, nvar + i, sizeof(float) * w);
      memcpy(ob + F_ALB_VAR * Sb + oo, avar + i, sizeof(float) * w);
      memcpy(ob + F_VIS * Sb + oo, vis + i, sizeof(float) * w);
      memcpy(ob + F_VIS_VAR * Sb + oo, visvar + i, sizeof(float) * w);
      grad_row(z + (size_t)y * W, z + (size_t)ym * W, z + (size_t)yp * W, 0, x0, w, W, zoff, zs,
               ob + (F_DX + 9) * Sb + oo, ob + (F_DY + 9) * Sb + oo);
      if (px) {
        void *dst = (char *)px + es * (size_t)yy * w * ps;
#ifdef KPCN_HAVE_T16
        if (e16)
          emit_pixels16(prow, Sb, KPCN_FEATURES_COUNT, w, dst, ps, bf16);
        else
#endif
          emit_pixels(prow, Sb, KPCN_FEATURES_COUNT, w, dst, ps, bf16);
      }
    }
  }
  free(ring);
  return KPCN_OK;
}

kpcn_status kpcn_features_build_region(const kpcn_aov_set *aov, int branch, float eps,
                                       const kpcn_features_norm *norm, int x0, int y0, int w, int h,
                                       float *out, size_t out_stride, float *noisy_pre,
                                       int nthreads) {
  return build_region(aov, branch, eps, norm, x0, y0, w, h, out, out_stride, NULL, 0, 0, noisy_pre,
                      nthreads);
}

kpcn_status kpcn_features_build_region_pixels(const kpcn_aov_set *aov, int branch, float eps,
                                              const kpcn_features_norm *norm, int x0, int y0, int w,
                                              int h, void *out, int pixel_stride, int bf16,
                                              float *noisy_pre, int nthreads) {
  if (!out) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "features_build: pixel output is NULL");
  if (pixel_stride < KPCN_FEATURES_COUNT || (bf16 != 0 && bf16 != 1))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "features_build: pixel stride %d < %d features or bf16 = %d not 0/1",
                     pixel_stride, KPCN_FEATURES_COUNT, bf16);
  return build_region(aov, branch, eps, norm, x0, y0, w, h, NULL, 0, out, pixel_stride, bf16,
                      noisy_pre, nthreads);
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
    out[i] = log1p_nonneg(specular[i] > 0.0f ? specular[i] : 0.0f);
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
