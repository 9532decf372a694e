/* Kernel-prediction layer (Bako 2017 / seed eq. 4.x): per pixel a softmax over K² logits
 * gives a normalized K x K filter that is applied to the noisy neighbourhood, the same
 * filter for every colour channel. Plain C: rows are independent, so we parallelize over
 * (image, row) and keep the inner loops over x contiguous for the vectorizer.
 * Border: reads outside the image are clamped to the nearest edge pixel (replicate). */
#include "core/internal.h"
#include "kpcn/nn.h"
#include "nn/kpa_internal.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#ifdef _OPENMP
#include <omp.h>
#endif
#ifdef __AVX2__
#include <immintrin.h>
#endif

/* The per-row loops below are auto-vectorized, and they bound the kernel layer by loads: a
 * second copy built for AVX-512 (x86-64-v4), chosen at load time where the CPU has it, does
 * each load and FMA on 16 pixels instead of 8. The arithmetic per pixel is the same. */
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__AVX2__) &&        \
    !defined(KPCN_NO_CLONES)
#define KPCN_AVX512_CLONES __attribute__((target_clones("arch=x86-64-v4", "default")))
#else
#define KPCN_AVX512_CLONES
#endif

/* GCC will not if-convert the float compares of the softmax loops (so not vectorize them)
 * while FP exceptions are assumed observable; this file never inspects them. */
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC optimize("no-trapping-math")
#endif

static kpcn_status check_args(const char *fn, int K, int n, int nc, int h, int w) {
  if (K < 1 || K % 2 == 0 || K > KPCN_NN_MAX_KERNEL)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s: K = %d must be odd in [1, %d]", fn, K,
                     KPCN_NN_MAX_KERNEL);
  if (n < 1 || nc < 1 || nc > 64)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s: n = %d, nc = %d invalid", fn, n, nc);
  return kpcn_check_size(w, h, fn);
}

static kpcn_status check_layout(const char *fn, const kpcn_logits_layout *l, int K2) {
  if (l->bf16 != 0 && l->bf16 != 1)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s: logits layout bf16 = %d is not 0 or 1", fn,
                     l->bf16);
  if (l->block < 1 || l->pixel_stride < 1 || (l->block < K2 && l->pixel_stride < l->block) ||
      (l->block >= K2 && l->pixel_stride < K2))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "%s: logits layout (block %d, pixel stride %d) overlaps itself", fn, l->block,
                     l->pixel_stride);
  return KPCN_OK;
}

kpcn_status kpcn_kpa_check_call(const char *fn, int K, int n, int nc, int h, int w,
                                const kpcn_logits_layout *layout, int nlogits) {
  KPCN_TRY(check_args(fn, K, n, nc, h, w));
  if (!layout) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s: NULL logits layout", fn);
  return check_layout(fn, layout, nlogits);
}

/* row[x + r] = src[clamp(x)] for x in [-r, w + r) */
static void padded_row(float *restrict row, const float *restrict src, int w, int r) {
  for (int x = 0; x < r; x++)
    row[x] = src[0];
  memcpy(row + r, src, (size_t)w * sizeof(float));
  for (int x = 0; x < r; x++)
    row[r + w + x] = src[w - 1];
}

/* dst[j * ds + x] = value of src[x * ps + j] for x < w, j < nb: the bf16 logits' gather into
 * tap-major rows where the vector path (softmax16) does not run; scalar, as it only takes the
 * last < 16 pixels of a chunk (or every pixel on CPUs without AVX-512, where bf16 nets do not
 * run). */
static void gather_bf16(const uint16_t *restrict src, int ps, int w, int nb, float *restrict dst,
                        size_t ds) {
  for (int j = 0; j < nb; j++)
    for (int x = 0; x < w; x++)
      dst[(size_t)j * ds + x] = kpcn_bf16_to_float(src[(size_t)x * ps + j]);
}

#define XB 32 /* pixels per register-blocked chunk */

/* This thread's slice of a per-thread scratch buffer of `per` floats each. */
static inline float *thread_scratch(float *buf, size_t per) {
#ifdef _OPENMP
  return buf + (size_t)omp_get_thread_num() * per;
#else
  return buf;
#endif
}

static inline int clampi(int v, int lo, int hi) { return v < lo ? lo : v > hi ? hi : v; }

/* exp(x) for x <= 0 (softmax after max subtraction), written with plain arithmetic so the
 * compiler vectorizes it (glibc's expf is a scalar call and costed ~25 % of inference on the
 * cpu preset). Range reduction x = n ln2 + r, |r| <= ln2/2, degree-6 Taylor/Horner for e^r
 * (truncation < 2e-8 relative), 2^n through the exponent bits. x < -87 is clamped to
 * -87 (e^-87 ≈ 1.6e-38, not 0). */
static inline float exp_nonpos(float x) {
  x = x < -87.f ? -87.f : x; /* a NaN stays NaN (and comes out NaN: see below) */
  float t = x * 1.44269504088896341f;
  const float big = t + 12582912.f; /* 1.5 * 2^23: its low mantissa bits hold round(t) */
  float nf = big - 12582912.f;      /* round to nearest (|t| < 2^22) */
  float r = x - nf * 0.693145751953125f - nf * 1.428606765330187e-06f;
  float p = 1.f / 720.f;
  p = p * r + 1.f / 120.f;
  p = p * r + 1.f / 24.f;
  p = p * r + 1.f / 6.f;
  p = p * r + 0.5f;
  p = p * r + 1.f;
  p = p * r + 1.f;
  /* 2^n from the integer in big's bits, not (int)nf: converting a NaN to int is undefined
   * behaviour, and a NaN logit (an overflowing model) must come out as NaN for the denoiser's
   * result check to see it. Unsigned arithmetic: for finite x, n + 127 is in [1, 127]. */
  union {
    float f;
    uint32_t u;
  } b = {.f = big}, u;
  u.u = (b.u - 0x4B400000u + 127u) << 23;
  return p * u.f;
}

/* For channels c < nch: o[c * os + i] = sc[i] * sum over the K² taps t of
 * wt[t][i] * pr[c][slot[dy]][dx + i] for i < n (sc NULL: 1); wt rows ws floats apart,
 * padded source rows pw apart, K of them per channel, source row dy in slot[dy]. Inlined with
 * constant n = XB the accumulators are registers (a variable n only serves the row's last chunk);
 * with nch = 3 each weight is loaded once for all three colour channels instead of three times
 * (loads, not FMAs, bound this loop).
 * fused (inference): wt holds the logits and sc their per-pixel max; the softmax numerators
 * e^(wt - sc) are made here, summed in tap order as the separate pass does, and the result
 * divided by their sum (the same operations, so the same bits). The exponentials' arithmetic
 * then runs beside this loop's loads instead of in a pass of its own that stored every
 * numerator and this loop reloaded (the cpu preset's kernel layer on 1024², bf16 logits,
 * 2 threads: 37.8 -> 36.7-37.2 ms). */
static inline __attribute__((always_inline)) void
apply_chunk(const int n, const int nch, const int fused, int K, const float *restrict wt, size_t ws,
            const float *restrict pr, int pw, const int *slot, const float *restrict sc,
            float *restrict o, size_t os) {
  float acc[3][XB], sum[XB];
  for (int i = 0; i < XB; i++) {
    sum[i] = 0.f;
    for (int c = 0; c < nch; c++)
      acc[c][i] = 0.f;
  }
  const size_t pc = (size_t)K * pw;
  for (int dy = 0; dy < K; dy++)
    for (int dx = 0; dx < K; dx++) {
      const float *restrict wr = wt + (size_t)(dy * K + dx) * ws;
      const float *restrict src = pr + (size_t)slot[dy] * pw + dx;
      for (int i = 0; i < n; i++) {
        const float wi = fused ? exp_nonpos(wr[i] - sc[i]) : wr[i];
        if (fused) sum[i] += wi;
        for (int c = 0; c < nch; c++)
          acc[c][i] += wi * src[c * pc + i];
      }
    }
  for (int c = 0; c < nch; c++)
    for (int i = 0; i < n; i++)
      o[c * os + i] = fused ? acc[c][i] * (1.f / sum[i]) : sc ? acc[c][i] * sc[i] : acc[c][i];
}

#ifdef __AVX2__
/* dst[j * ds + i] = src[i * ss + j] for an 8 x 8 block (unpack / shuffle / lane swap). */
static inline void transpose8x8(const float *src, size_t ss, float *dst, size_t ds) {
  __m256 r[8], t[8];
  for (int i = 0; i < 8; i++)
    r[i] = _mm256_loadu_ps(src + (size_t)i * ss);
  for (int i = 0; i < 8; i += 2) {
    t[i] = _mm256_unpacklo_ps(r[i], r[i + 1]);
    t[i + 1] = _mm256_unpackhi_ps(r[i], r[i + 1]);
  }
  for (int i = 0; i < 8; i += 4) {
    r[i] = _mm256_shuffle_ps(t[i], t[i + 2], 0x44);
    r[i + 1] = _mm256_shuffle_ps(t[i], t[i + 2], 0xEE);
    r[i + 2] = _mm256_shuffle_ps(t[i + 1], t[i + 3], 0x44);
    r[i + 3] = _mm256_shuffle_ps(t[i + 1], t[i + 3], 0xEE);
  }
  for (int i = 0; i < 4; i++) {
    _mm256_storeu_ps(dst + (size_t)i * ds, _mm256_permute2f128_ps(r[i], r[i + 4], 0x20));
    _mm256_storeu_ps(dst + (size_t)(i + 4) * ds, _mm256_permute2f128_ps(r[i], r[i + 4], 0x31));
  }
}
#endif

#include "core/transpose16.h"

#ifdef KPCN_HAVE_T16
/* dst[j * ds + i] = src[i * ss + j] for i < 16, j < nb <= 16 (for nChw16c logits: 16 pixels'
 * whole cache lines of one block to nb tap rows). Reads all 16 floats of every source row (a
 * block's padding too, so the caller keeps them inside the row stride), stores only nb rows. */
__attribute__((target("avx512f"))) static void transpose16x16(const float *src, size_t ss,
                                                              float *dst, size_t ds, int nb) {
  __m512 r[16], row[16];
  for (int i = 0; i < 16; i++)
    r[i] = _mm512_loadu_ps(src + (size_t)i * ss);
  transpose16_regs(r, row);
  for (int j = 0; j < nb; j++)
    _mm512_storeu_ps(dst + (size_t)j * ds, row[j]);
}

/* exp_nonpos on 16 lanes, the same arithmetic (FMAs where the scalar form multiplies then
 * adds, so the last bit may differ from the default build's). */
__attribute__((target("avx512f"), always_inline)) static inline __m512 exp_nonpos16(__m512 x) {
  const __m512 magic = _mm512_set1_ps(12582912.f);
  x = _mm512_max_ps(_mm512_set1_ps(-87.f), x); /* NaN in x is returned, so it propagates */
  const __m512 nf =
      _mm512_sub_ps(_mm512_fmadd_ps(x, _mm512_set1_ps(1.44269504088896341f), magic), magic);
  __m512 r = _mm512_fnmadd_ps(nf, _mm512_set1_ps(0.693145751953125f), x);
  r = _mm512_fnmadd_ps(nf, _mm512_set1_ps(1.428606765330187e-06f), r);
  __m512 p = _mm512_set1_ps(1.f / 720.f);
  p = _mm512_fmadd_ps(p, r, _mm512_set1_ps(1.f / 120.f));
  p = _mm512_fmadd_ps(p, r, _mm512_set1_ps(1.f / 24.f));
  p = _mm512_fmadd_ps(p, r, _mm512_set1_ps(1.f / 6.f));
  p = _mm512_fmadd_ps(p, r, _mm512_set1_ps(0.5f));
  p = _mm512_fmadd_ps(p, r, _mm512_set1_ps(1.f));
  p = _mm512_fmadd_ps(p, r, _mm512_set1_ps(1.f));
  /* p * 2^nf in one instruction instead of building 2^nf's exponent bits and multiplying
   * (4): the same product, exact for the integral nf >= -126 here (the softmax's exp loop is
   * bound by its arithmetic, 16 -> 13 instructions a tap). */
  return _mm512_scalef_ps(p, nf);
}

/* The softmax numerators of pixels [0, 16 ng) of a chunk whose taps come in runs of 16
 * consecutive floats (nChw16c blocks, or pixel-major rows; L0: the chunk's first pixel,
 * block 0). Per group of 16 pixels each run is loaded masked to its valid taps (nothing past
 * a pixel's row or the buffer is read), transposed in registers into tap rows wt[t][16g ..]
 * and folded into the running max on the way, so the max costs no pass of its own; then
 * e^(l - max) replaces each row, summed in a register (tap order, as the generic loop).
 * The logits come from DRAM (the net just wrote them), in up to K²/16 streams a block plane
 * apart; the hardware prefetcher lost them at every 4 KiB page, so each load also prefetches
 * its line of the next 16 pixels (1024-px rows, 121 taps, 2 threads: 29 -> 22 ms a tile).
 * Leaves the exponentials in wt and their sums in sum[0, 16 ng). */
__attribute__((target("avx512f,avx512bw,avx512vl"))) static void
softmax16(const void *L0, const kpcn_logits_layout *lay, int K2, int ng, float *wt, size_t ws,
          float *sum, float *mx) {
  const int bl = lay->block, ps = lay->pixel_stride, bf = lay->bf16;
  const size_t es = bf ? 2 : 4; /* bytes per logit */
  for (int g = 0; g < ng; g++) {
    __m512 m = _mm512_set1_ps(-INFINITY);
    for (int t0 = 0; t0 < K2; t0 += 16) {
      const int nb = K2 - t0 < 16 ? K2 - t0 : 16;
      const char *src = (const char *)L0 + es * ((size_t)(t0 / bl) * lay->block_stride +
                                                 (size_t)(t0 % bl) + (size_t)16 * g * ps);
      const __mmask16 k = (__mmask16)((1u << nb) - 1u);
      __m512 r[16], row[16];
      for (int i = 0; i < 16; i++) {
        _mm_prefetch(src + es * (size_t)(i + 16) * ps, _MM_HINT_T0);
        const char *p = src + es * (size_t)i * ps;
        /* bf16: the upper halves of floats, widened by a shift */
        r[i] = bf ? _mm512_castsi512_ps(_mm512_slli_epi32(
                        _mm512_cvtepu16_epi32(_mm256_maskz_loadu_epi16(k, p)), 16))
                  : _mm512_maskz_loadu_ps(k, (const float *)p);
      }
      transpose16_regs(r, row);
      for (int j = 0; j < nb; j++) {
        _mm512_storeu_ps(wt + (size_t)(t0 + j) * ws + 16 * g, row[j]);
        m = _mm512_max_ps(m, row[j]);
      }
    }
    if (mx) { /* fused: the apply loop exponentiates */
      _mm512_storeu_ps(mx + 16 * g, m);
      continue;
    }
    __m512 acc = _mm512_setzero_ps();
    for (int t = 0; t < K2; t++) {
      float *wr = wt + (size_t)t * ws + 16 * g;
      const __m512 e = exp_nonpos16(_mm512_sub_ps(_mm512_loadu_ps(wr), m));
      _mm512_storeu_ps(wr, e);
      acc = _mm512_add_ps(acc, e);
    }
    _mm512_storeu_ps(sum + 16 * g, acc);
  }
}
#endif

/* 1: libkpcn's AVX-512 kernels may run (f32 logits); 2: also those reading bf16 (BW, VL). */
static int have_avx512(void) {
#ifdef KPCN_HAVE_T16
  if (!kpcn_cpu_allows_avx512()) return 0;
  return __builtin_cpu_supports("avx512bw") && __builtin_cpu_supports("avx512vl") ? 2 : 1;
#else
  return 0;
#endif
}

/* dst[j * ds + x] = src[x * ps + j] for x in [xa, xb), j in [ja, jb): 8 x 8 AVX2 register
 * transposes, scalar edges. */
static void transpose_8(const float *restrict src, int ps, int xa, int xb, int ja, int jb,
                        float *restrict dst, size_t ds) {
  int x0 = xa;
#ifdef __AVX2__
  for (; x0 + 8 <= xb; x0 += 8) {
    int j = ja;
    for (; j + 8 <= jb; j += 8)
      transpose8x8(src + (size_t)x0 * ps + j, (size_t)ps, dst + (size_t)j * ds + x0, ds);
    for (; j < jb; j++)
      for (int x = x0; x < x0 + 8; x++)
        dst[(size_t)j * ds + x] = src[(size_t)x * ps + j];
  }
#endif
  for (int x = x0; x < xb; x++)
    for (int j = ja; j < jb; j++)
      dst[(size_t)j * ds + x] = src[(size_t)x * ps + j];
}

/* dst[j * ds + x] = src[x * ps + j] for x < w, j < nb: pixel-major logits to the tap-major
 * rows the softmax and apply loops read, and (backward) tap-major rows back to pixel-major.
 * Element by element this was ~40 % of the layer (scattered single-float stores); register
 * transposes leave only the edges scalar. Where the CPU has AVX-512 (t16), 16 x 16 blocks
 * cover every column block that lies within the row stride ps (so a nChw16c block's last,
 * partly padded 16 columns too: only its nb rows are stored), 8 x 8 AVX2 ones the rest. */
static void transpose(const float *restrict src, int ps, int w, int nb, float *restrict dst,
                      size_t ds, int t16) {
  int x16 = 0, j16 = 0; /* the 16 x 16 blocks cover x < x16, j < j16 */
#ifdef KPCN_HAVE_T16
  if (t16) {
    while (j16 < nb && j16 + 16 <= ps)
      j16 += 16;
    if (j16 > 0) x16 = w & ~15;
    for (int x0 = 0; x0 < x16; x0 += 16)
      for (int j0 = 0; j0 < j16; j0 += 16)
        transpose16x16(src + (size_t)x0 * ps + j0, (size_t)ps, dst + (size_t)j0 * ds + x0, ds,
                       nb - j0 < 16 ? nb - j0 : 16);
    if (j16 > nb) j16 = nb;
  }
#else
  (void)t16;
#endif
  transpose_8(src, ps, 0, x16, j16, nb, dst, ds);
  transpose_8(src, ps, x16, w, 0, nb, dst, ds);
}

/* The K clamped source rows around output row y of image b (noisy: the image's first plane),
 * every channel, padded by K/2 (padded_row), in a ring of K slots per channel indexed by the
 * unclamped source row; slot[dy] = the slot of row y + dy - K/2. A thread's rows are
 * consecutive (static schedule), so after its first row it pads one new source row per
 * output row instead of K (re-padding all of them was ~15 % of the forward). last[] = the
 * image and row this thread did before (-1: none). */
static void source_rows(int K, int nc, int h, int w, int b, int y, const float *noisy, float *pr,
                        int *last, int *slot) {
  const int r = K / 2, pw = w + 2 * r;
  const size_t plane = (size_t)h * w;
  const int first = last[0] == b && last[1] == y - 1 ? K - 1 : 0;
  for (int dy = 0; dy < K; dy++) {
    const int sy = y + dy - r;
    slot[dy] = ((sy % K) + K) % K;
    if (dy >= first)
      for (int c = 0; c < nc; c++)
        padded_row(pr + (size_t)(c * K + slot[dy]) * pw,
                   noisy + (size_t)c * plane + (size_t)clampi(sy, 0, h - 1) * w, w, r);
  }
  last[0] = b, last[1] = y;
}

/* What each of nt threads works in: `per` floats of scratch and the state of source_rows
 * (64 bytes apart). Both or neither are allocated. */
typedef struct kpa_workspace {
  float *buf;
  int *last;
} kpa_workspace;

static kpcn_status workspace_alloc(kpa_workspace *ws, int nt, size_t per) {
  ws->buf = kpcn_aligned_alloc((size_t)nt * per * sizeof(float), "kpa scratch");
  ws->last = kpcn_aligned_alloc((size_t)nt * 16 * sizeof(int), "kpa row state");
  if (!ws->buf || !ws->last) {
    kpcn_aligned_free(ws->buf);
    kpcn_aligned_free(ws->last);
    return KPCN_ERR_OUT_OF_MEMORY;
  }
  for (int i = 0; i < nt; i++)
    ws->last[16 * i] = -1;
  return KPCN_OK;
}

static void workspace_free(kpa_workspace *ws) {
  kpcn_aligned_free(ws->buf);
  kpcn_aligned_free(ws->last);
}

static inline int *thread_state(int *last) {
#ifdef _OPENMP
  return last + 16 * omp_get_thread_num();
#else
  return last;
#endif
}

#define XC 64 /* pixels per column chunk of gathered logits: its K² weight rows stay in L1/L2 */

/* One output row y of one image. A separate function (all sizes by value) so the compiler
 * sees loop bounds and pointers that the stores cannot alias; inside the OpenMP region it
 * reloaded them from the shared-variable block and did not vectorize. logits points at the
 * image's first logit; planar logits are read in place, any other layout is first gathered
 * into the chunk's softmax buffer wt ([K2][ws]), where the exponentials then overwrite it.
 * Gathered layouts are processed in chunks of xc_n = XC pixels (gather, max, exp, apply):
 * with the whole row's K² x w weights (~0.5 MB at w = 1024, K = 11) every pass streamed
 * them through L2. Planar logits are read in place and run whole rows (xc_n = w): 64-float
 * pieces of K² rows a plane apart defeated the prefetcher (1.4x slower). */
KPCN_AVX512_CLONES static void fwd_row(int K, int nc, int h, int w, int xc_n, size_t ws, int b,
                                       int y, const void *logits, const kpcn_logits_layout *lay,
                                       const float *noisy, float *out, float *weights,
                                       float *restrict wt, int *last, int t16) {
  const int r = K / 2, K2 = K * K, pw = w + 2 * r;
  const size_t plane = (size_t)h * w;
  float *restrict mx = wt + (size_t)K2 * ws, *restrict sum = mx + xc_n, *restrict pr = sum + xc_n;
  int slot[KPCN_NN_MAX_KERNEL];
  source_rows(K, nc, h, w, b, y, noisy, pr, last, slot);
  const int planar = lay->block == 1 && lay->pixel_stride == 1 && !lay->bf16;
  const size_t es = lay->bf16 ? 2 : 4; /* bytes per logit */
  /* Normalized weights are only materialized when the caller keeps them (training); for
   * inference the apply loop makes the numerators itself and divides by their sum once per
   * output pixel (apply_chunk, fused). */
  const int fused = weights == NULL;
  for (int xc = 0; xc < w; xc += xc_n) {
    const int n = w - xc < xc_n ? w - xc : xc_n;
    const float *L; /* logit 0 of pixel xc; logit t's row starts at L + t * lstride */
    size_t lstride;
    int x1 = 0; /* pixels [0, x1) already hold their exponentials and sums (fused: maxima) */
    if (planar) {
      L = (const float *)logits + (size_t)y * w + xc, lstride = lay->block_stride;
    } else {
      const int ps = lay->pixel_stride, bl = lay->block;
      const char *L0 = (const char *)logits + es * ((size_t)y * w + xc) * ps;
#ifdef KPCN_HAVE_T16
      if ((lay->bf16 ? t16 == 2 : t16 > 0) && (bl % 16 == 0 || bl >= K2)) {
        x1 = n & ~15;
        softmax16(L0, lay, K2, x1 / 16, wt, ws, sum, fused ? mx : NULL);
      }
#endif
      if (x1 < n)
        for (int t0 = 0; t0 < K2; t0 += bl) {
          const char *src = L0 + es * ((size_t)(t0 / bl) * lay->block_stride + (size_t)x1 * ps);
          const int nb = K2 - t0 < bl ? K2 - t0 : bl;
          if (lay->bf16)
            gather_bf16((const uint16_t *)src, ps, n - x1, nb, wt + (size_t)t0 * ws + x1, ws);
          else
            transpose((const float *)src, ps, n - x1, nb, wt + (size_t)t0 * ws + x1, ws, t16);
        }
      L = wt, lstride = ws;
    }
    for (int x = x1; x < n; x++)
      mx[x] = L[x];
    for (int t = 1; t < K2; t++) {
      const float *restrict Lt = L + (size_t)t * lstride;
      for (int x = x1; x < n; x++)
        mx[x] = Lt[x] > mx[x] ? Lt[x] : mx[x]; /* fmaxf won't vectorize */
    }
    if (!fused) {
      for (int x = x1; x < n; x++)
        sum[x] = 0.f;
      for (int t = 0; t < K2; t++) {
        float *wr = wt + (size_t)t * ws; /* may be Lt itself (gathered layouts): same element */
        const float *Lt = L + (size_t)t * lstride;
#pragma omp simd
        for (int x = x1; x < n; x++) {
          float e = exp_nonpos(Lt[x] - mx[x]);
          wr[x] = e;
          sum[x] += e;
        }
      }
      for (int x = 0; x < n; x++)
        sum[x] = 1.f / sum[x];
      for (int t = 0; t < K2; t++) {
        float *restrict wr = wt + (size_t)t * ws;
        for (int x = 0; x < n; x++)
          wr[x] *= sum[x];
      }
    }
    /* the weight rows the apply loop reads: the logits where they are (fused), else wt */
    const float *A = fused ? L : wt;
    const size_t as = fused ? lstride : ws;
    /* Apply: each block of XB pixels accumulates its K² taps in registers (one store per
     * pixel instead of K²), three channels at a time (RGB: the usual case) or one. */
    for (int c0 = 0; c0 < nc;) {
      const int nch = nc - c0 >= 3 ? 3 : 1;
      const float *prc = pr + (size_t)c0 * K * pw + xc;
      float *o = out + (size_t)c0 * plane + (size_t)y * w + xc;
      for (int x0 = 0; x0 < n; x0 += XB) {
        /* constant width, channel count and mode: the accumulators stay in registers */
        const float *a = A + x0, *p = prc + x0;
        float *ox = o + x0;
        if (fused && n - x0 >= XB && nch == 3)
          apply_chunk(XB, 3, 1, K, a, as, p, pw, slot, mx + x0, ox, plane);
        else if (fused && n - x0 >= XB)
          apply_chunk(XB, 1, 1, K, a, as, p, pw, slot, mx + x0, ox, plane);
        else if (fused)
          apply_chunk(n - x0, nch, 1, K, a, as, p, pw, slot, mx + x0, ox, plane);
        else if (n - x0 >= XB && nch == 3)
          apply_chunk(XB, 3, 0, K, a, as, p, pw, slot, NULL, ox, plane);
        else if (n - x0 >= XB)
          apply_chunk(XB, 1, 0, K, a, as, p, pw, slot, NULL, ox, plane);
        else
          apply_chunk(n - x0, nch, 0, K, a, as, p, pw, slot, NULL, ox, plane);
      }
      c0 += nch;
    }
    if (weights) { /* written last so weights may alias logits */
      float *W = weights + (size_t)y * w + xc;
      for (int t = 0; t < K2; t++)
        memcpy(W + t * plane, wt + (size_t)t * ws, (size_t)n * 4);
    }
  }
}

kpcn_logits_layout kpcn_logits_layout_planar(int K2, int h, int w) {
  kpcn_logits_layout l;
  l.block_stride = (size_t)h * w;
  l.image_stride = (size_t)K2 * l.block_stride;
  l.block = 1;
  l.pixel_stride = 1;
  l.bf16 = 0;
  return l;
}

kpcn_status kpcn_kpa_forward_layout(int K, int n, int nc, int h, int w, const void *logits,
                                    const kpcn_logits_layout *layout, const float *noisy,
                                    float *out, float *weights, int nthreads) {
  KPCN_TRY(check_args("kpcn_kpa_forward", K, n, nc, h, w));
  if (!logits || !noisy || !out || !layout)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_kpa_forward: NULL buffer");
  const int r = K / 2, K2 = K * K, nt = kpcn_resolve_threads(nthreads);
  const kpcn_logits_layout lay = *layout;
  KPCN_TRY(check_layout("kpcn_kpa_forward", &lay, K2));
  const size_t plane = (size_t)h * w;
  /* per thread: softmax rows [K2][ws] of one chunk, its max and sum, nc x K padded rows. The
   * row stride ws is padded (kpcn_plane_stride) so the K2 rows the apply loop reads together
   * do not all fall on one cache set. */
  const int planar = lay.block == 1 && lay.pixel_stride == 1 && !lay.bf16;
  const int xc_n = planar || w < XC ? w : XC;
  const size_t ws = kpcn_plane_stride((size_t)xc_n);
  const size_t scratch = (size_t)K2 * ws + 2 * (size_t)xc_n + (size_t)nc * K * (w + 2 * r) + 64;
  kpa_workspace wsp;
  KPCN_TRY(workspace_alloc(&wsp, nt, scratch));
  const int t16 = have_avx512();
#pragma omp parallel for num_threads(nt) schedule(static)
  for (long row = 0; row < (long)n * h; row++) {
    const int b = (int)(row / h), y = (int)(row % h);
    fwd_row(K, nc, h, w, xc_n, ws, b, y,
            (const char *)logits + (size_t)b * lay.image_stride * (lay.bf16 ? 2 : 4), &lay,
            noisy + (size_t)b * nc * plane, out + (size_t)b * nc * plane,
            weights ? weights + (size_t)b * K2 * plane : NULL, thread_scratch(wsp.buf, scratch),
            thread_state(wsp.last), t16);
  }
  workspace_free(&wsp);
  return KPCN_OK;
}

kpcn_status kpcn_kpa_forward(int K, int n, int nc, int h, int w, const float *logits,
                             const float *noisy, float *out, float *weights, int nthreads) {
  KPCN_TRY(check_args("kpcn_kpa_forward", K, n, nc, h, w));
  kpcn_logits_layout lay = kpcn_logits_layout_planar(K * K, h, w);
  return kpcn_kpa_forward_layout(K, n, nc, h, w, logits, &lay, noisy, out, weights, nthreads);
}

/* Backward, dnoisy: one (image, channel, source row qy) of the gather over output rows.
 * Separate functions for the same reasons as fwd_row (and the AVX-512 copy). */
KPCN_AVX512_CLONES static void bwd_dnoisy_row(int K, int nc, int h, int w, long row,
                                              const float *weights, const float *dout,
                                              float *dnoisy, float *scratch) {
  const int r = K / 2, K2 = K * K;
  const size_t plane = (size_t)h * w;
  float *acc = scratch;
  const int qy = (int)(row % h), c = (int)((row / h) % nc), b = (int)(row / ((long)h * nc));
  for (int x = 0; x < w + 2 * r; x++)
    acc[x] = 0.f;
  const float *dO = dout + ((size_t)b * nc + c) * plane;
  for (int dy = 0; dy < K; dy++) {
    /* source rows py with clamp(py + dy - r) == qy */
    int lo = qy - (dy - r), hi = lo;
    if (qy == 0) lo = 0;
    if (qy == h - 1) hi = h - 1;
    if (lo < 0) lo = 0;
    if (hi > h - 1) hi = h - 1;
    for (int py = lo; py <= hi; py++) {
      if (clampi(py + dy - r, 0, h - 1) != qy) continue;
      const float *dor = dO + (size_t)py * w;
      for (int dx = 0; dx < K; dx++) {
        const float *wr =
            weights + (size_t)b * K2 * plane + (size_t)(dy * K + dx) * plane + (size_t)py * w;
        float *a = acc + dx;
        for (int x = 0; x < w; x++)
          a[x] += wr[x] * dor[x];
      }
    }
  }
  float *dn = dnoisy + ((size_t)b * nc + c) * plane + (size_t)qy * w;
  memcpy(dn, acc + r, (size_t)w * 4);
  for (int x = 0; x < r; x++) {
    dn[0] += acc[x];
    dn[w - 1] += acc[r + w + x];
  }
}

/* Row y of one image's dlogits (img) in layout lay, from tap-major rows D[t][w]: the transpose
 * the forward does on the way in, reversed (pixel-major rows of the tap-major ones), with the
 * layout's padding slots zeroed (oneDNN requires zero padding in blocked layouts). */
static void store_dlogits_row(const float *D, int K2, int w, int y, const kpcn_logits_layout *lay,
                              float *img, int t16) {
  const int bl = lay->block, ps = lay->pixel_stride, slots = bl < K2 ? bl : ps;
  for (int t0 = 0; t0 < K2; t0 += bl) {
    const int nb = K2 - t0 < bl ? K2 - t0 : bl;
    float *dst = img + (size_t)(t0 / bl) * lay->block_stride + (size_t)y * w * ps;
    transpose(D + (size_t)t0 * w, w, nb, w, dst, (size_t)ps, t16);
    if (nb < slots)
      for (int x = 0; x < w; x++)
        memset(dst + (size_t)x * ps + nb, 0, (size_t)(slots - nb) * sizeof(float));
  }
}

/* dL/dw for the taps of XB (or n) pixels: g[t][i] = sum over channels c of dout[c][i] *
 * pr[c][slot[dy]][dx + i], and dot[i] = sum_t W[t][i] g[t][i]; each tap's sum is kept in
 * registers over the channels (the K² rows of g are written once, not once per channel). The
 * sums run in the same order as a per-channel pass over g would (c, then t for dot). */
static inline __attribute__((always_inline)) void
grad_chunk(const int n, int nc, int K, const float *restrict W, size_t plane,
           const float *restrict dor, size_t dstride, const float *restrict pr, int pw,
           const int *slot, float *restrict g, size_t gs, float *restrict dot) {
  float dacc[XB];
  for (int i = 0; i < XB; i++)
    dacc[i] = 0.f;
  const size_t pc = (size_t)K * pw;
  for (int dy = 0; dy < K; dy++)
    for (int dx = 0; dx < K; dx++) {
      const int t = dy * K + dx;
      const float *restrict src = pr + (size_t)slot[dy] * pw + dx;
      float acc[XB];
      for (int i = 0; i < XB; i++)
        acc[i] = 0.f;
      for (int c = 0; c < nc; c++)
        for (int i = 0; i < n; i++)
          acc[i] += dor[c * dstride + i] * src[c * pc + i];
      const float *restrict Wt = W + (size_t)t * plane;
      float *restrict gt = g + (size_t)t * gs;
      for (int i = 0; i < n; i++) {
        gt[i] = acc[i];
        dacc[i] += Wt[i] * acc[i];
      }
    }
  for (int i = 0; i < n; i++)
    dot[i] = dacc[i];
}

/* Backward, dlogits: one (image, row) through the softmax Jacobian,
 * dlogit_t = w_t (g_t - sum_s w_s g_s). Planar dlogits are written in place of the row's
 * result; other layouts (lay non-NULL) go through store_dlogits_row. */
KPCN_AVX512_CLONES static void bwd_dlogits_row(int K, int nc, int h, int w, int b, int y,
                                               const float *weights, const float *noisy,
                                               const float *dout, float *dlogits,
                                               const kpcn_logits_layout *lay, float *scratch,
                                               int *last, int t16) {
  const int r = K / 2, K2 = K * K, pw = w + 2 * r;
  const size_t plane = (size_t)h * w;
  float *g = scratch; /* [K2][w]: dL/dw_t */
  float *dot = g + (size_t)K2 * w, *pr = dot + (size_t)w;
  int slot[KPCN_NN_MAX_KERNEL];
  source_rows(K, nc, h, w, b, y, noisy + (size_t)b * nc * plane, pr, last, slot);
  const float *W = weights + (size_t)b * K2 * plane + (size_t)y * w;
  const float *dor = dout + (size_t)b * nc * plane + (size_t)y * w;
  for (int x0 = 0; x0 < w; x0 += XB) {
    if (w - x0 >= XB)
      grad_chunk(XB, nc, K, W + x0, plane, dor + x0, plane, pr + x0, pw, slot, g + x0, w, dot + x0);
    else
      grad_chunk(w - x0, nc, K, W + x0, plane, dor + x0, plane, pr + x0, pw, slot, g + x0, w,
                 dot + x0);
  }
  if (lay) {
    for (int t = 0; t < K2; t++)
      for (int x = 0; x < w; x++)
        g[(size_t)t * w + x] = W[t * plane + x] * (g[(size_t)t * w + x] - dot[x]);
    store_dlogits_row(g, K2, w, y, lay, dlogits + (size_t)b * lay->image_stride, t16);
    return;
  }
  float *D = dlogits + (size_t)b * K2 * plane + (size_t)y * w;
  for (int t = 0; t < K2; t++)
    for (int x = 0; x < w; x++)
      D[t * plane + x] = W[t * plane + x] * (g[(size_t)t * w + x] - dot[x]);
}

/* lay NULL: planar dlogits (which may alias weights) */
static kpcn_status kpa_backward(const char *fn, int K, int n, int nc, int h, int w,
                                const float *weights, const float *noisy, const float *dout,
                                float *dlogits, const kpcn_logits_layout *lay, float *dnoisy,
                                int nthreads) {
  KPCN_TRY(check_args(fn, K, n, nc, h, w));
  if (!weights || !noisy || !dout || !dlogits)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s: NULL buffer", fn);
  const int r = K / 2, K2 = K * K, nt = kpcn_resolve_threads(nthreads);
  if (lay) KPCN_TRY(check_layout(fn, lay, K2));
  const int t16 = have_avx512();
  /* per thread: g [K2][w], dot [w], the ring of nc x K padded source rows (dnoisy: one
   * padded accumulator row) */
  const size_t scratch = (size_t)K2 * w + (size_t)w + (size_t)nc * K * (w + 2 * r) + 64;
  kpa_workspace wsp;
  KPCN_TRY(workspace_alloc(&wsp, nt, scratch));
  /* dnoisy first: it reads weights, which dlogits may alias. Gather over output rows qy
   * (each thread owns its rows, so the sum order is fixed and thread-count independent);
   * within a row the x-scatter goes to a padded accumulator folded at the edges. */
  if (dnoisy) {
#pragma omp parallel for num_threads(nt) schedule(static)
    for (long row = 0; row < (long)n * nc * h; row++)
      bwd_dnoisy_row(K, nc, h, w, row, weights, dout, dnoisy, thread_scratch(wsp.buf, scratch));
  }
#pragma omp parallel for num_threads(nt) schedule(static)
  for (long row = 0; row < (long)n * h; row++)
    bwd_dlogits_row(K, nc, h, w, (int)(row / h), (int)(row % h), weights, noisy, dout, dlogits, lay,
                    thread_scratch(wsp.buf, scratch), thread_state(wsp.last), t16);
  workspace_free(&wsp);
  return KPCN_OK;
}

kpcn_status kpcn_kpa_backward(int K, int n, int nc, int h, int w, const float *weights,
                              const float *noisy, const float *dout, float *dlogits, float *dnoisy,
                              int nthreads) {
  return kpa_backward("kpcn_kpa_backward", K, n, nc, h, w, weights, noisy, dout, dlogits, NULL,
                      dnoisy, nthreads);
}

kpcn_status kpcn_kpa_backward_layout(int K, int n, int nc, int h, int w, const float *weights,
                                     const float *noisy, const float *dout, float *dlogits,
                                     const kpcn_logits_layout *layout, float *dnoisy,
                                     int nthreads) {
  if (!layout) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_kpa_backward_layout: NULL layout");
  if (layout->bf16)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "kpcn_kpa_backward_layout: dlogits are written as f32 (layout bf16 = 1)");
  if (dlogits == weights)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "kpcn_kpa_backward_layout: dlogits may not alias weights");
  const size_t plane = (size_t)h * w;
  const int planar = layout->block == 1 && layout->pixel_stride == 1 &&
                     layout->block_stride == plane && layout->image_stride == plane * K * K;
  return kpa_backward("kpcn_kpa_backward_layout", K, n, nc, h, w, weights, noisy, dout, dlogits,
                      planar ? NULL : layout, dnoisy, nthreads); /* planar: rows in place */
}
