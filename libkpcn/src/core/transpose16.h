/* A 16 x 16 float transpose in AVX-512 registers, shared by the kernel-prediction layer
 * (nn/kpa.c: pixel-major logits to tap rows) and the feature builder (denoise/features.c:
 * feature rows to a net's pixel-major input). KPCN_HAVE_T16 is defined where it exists;
 * callers still check the CPU at run time (kpcn_cpu_allows_avx512). */
#ifndef KPCN_CORE_TRANSPOSE16_H
#define KPCN_CORE_TRANSPOSE16_H
#if defined(__GNUC__) && defined(__x86_64__) && defined(__AVX2__)
#include <immintrin.h>
#define KPCN_HAVE_T16 1
/* row[j] (lane i) = src[i * ss + j] for i, j < 16: four shuffle stages, 32-bit and 64-bit
 * interleaves leaving a 4 x 4 transposed block in each 128-bit lane, then two lane shuffles
 * gathering the four lanes of each output row. r holds the 16 source rows (lanes j). */
__attribute__((target("avx512f"), always_inline)) static inline void
transpose16_regs(__m512 r[16], __m512 row[16]) {
  __m512 t[16], u[16];
  for (int i = 0; i < 16; i += 2) {
    t[i] = _mm512_unpacklo_ps(r[i], r[i + 1]);
    t[i + 1] = _mm512_unpackhi_ps(r[i], r[i + 1]);
  }
  /* u[4g + c], lane k: column 4k + c of rows 4g .. 4g + 3 */
  for (int g = 0; g < 16; g += 4) {
    const __m512d a = _mm512_castps_pd(t[g]), b = _mm512_castps_pd(t[g + 1]),
                  c = _mm512_castps_pd(t[g + 2]), d = _mm512_castps_pd(t[g + 3]);
    u[g] = _mm512_castpd_ps(_mm512_unpacklo_pd(a, c));
    u[g + 1] = _mm512_castpd_ps(_mm512_unpackhi_pd(a, c));
    u[g + 2] = _mm512_castpd_ps(_mm512_unpacklo_pd(b, d));
    u[g + 3] = _mm512_castpd_ps(_mm512_unpackhi_pd(b, d));
  }
  for (int c = 0; c < 4; c++) {
    const __m512 lo01 = _mm512_shuffle_f32x4(u[c], u[4 + c], _MM_SHUFFLE(1, 0, 1, 0)),
                 hi01 = _mm512_shuffle_f32x4(u[c], u[4 + c], _MM_SHUFFLE(3, 2, 3, 2)),
                 lo23 = _mm512_shuffle_f32x4(u[8 + c], u[12 + c], _MM_SHUFFLE(1, 0, 1, 0)),
                 hi23 = _mm512_shuffle_f32x4(u[8 + c], u[12 + c], _MM_SHUFFLE(3, 2, 3, 2));
    row[c] = _mm512_shuffle_f32x4(lo01, lo23, _MM_SHUFFLE(2, 0, 2, 0));
    row[4 + c] = _mm512_shuffle_f32x4(lo01, lo23, _MM_SHUFFLE(3, 1, 3, 1));
    row[8 + c] = _mm512_shuffle_f32x4(hi01, hi23, _MM_SHUFFLE(2, 0, 2, 0));
    row[12 + c] = _mm512_shuffle_f32x4(hi01, hi23, _MM_SHUFFLE(3, 1, 3, 1));
  }
}
#endif
#endif
