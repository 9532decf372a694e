/* Low-discrepancy sampler: shuffled, Owen-scrambled Sobol points (Burley 2020, "Practical
 * Hash-based Owen Scrambling"). Every 2D dimension pair of a path uses the first two Sobol
 * dimensions (a (0,2)-sequence) with its own index shuffle and its own nested uniform
 * scramble, both keyed on a hash of (seed, pixel, pair), so pixels are decorrelated and each
 * pixel's sequence depends only on (seed, pixel, sample index): results do not depend on
 * which thread renders the pixel. Power-of-two sample counts are stratified per pair. */
#ifndef KPCN_RENDER_SAMPLER_H
#define KPCN_RENDER_SAMPLER_H

#include <stdint.h>

typedef struct kpcn_sampler {
  uint32_t pixel_seed; /* hash of seed and pixel */
  uint32_t index;      /* sample index within the pixel */
  uint32_t pair;       /* next dimension pair */
} kpcn_sampler;

static inline uint32_t kpcn_hash32(uint32_t x) {
  /* lowbias32 (Wellons) */
  x ^= x >> 16;
  x *= 0x7feb352dU;
  x ^= x >> 15;
  x *= 0x846ca68bU;
  x ^= x >> 16;
  return x;
}

static inline uint32_t kpcn_hash_combine(uint32_t seed, uint32_t v) {
  return seed ^ (kpcn_hash32(v) + 0x9e3779b9U + (seed << 6) + (seed >> 2));
}

static inline uint32_t kpcn_reverse_bits(uint32_t x) {
  x = ((x >> 1) & 0x55555555U) | ((x & 0x55555555U) << 1);
  x = ((x >> 2) & 0x33333333U) | ((x & 0x33333333U) << 2);
  x = ((x >> 4) & 0x0F0F0F0FU) | ((x & 0x0F0F0F0FU) << 4);
  x = ((x >> 8) & 0x00FF00FFU) | ((x & 0x00FF00FFU) << 8);
  return (x >> 16) | (x << 16);
}

/* Laine-Karras style hash permutation, improved constants from Burley 2020. */
static inline uint32_t kpcn_lk_permute(uint32_t x, uint32_t seed) {
  x ^= x * 0x3d20adeaU;
  x += seed;
  x *= (seed >> 16) | 1U;
  x ^= x * 0x05526c56U;
  x ^= x * 0x53a22864U;
  return x;
}

static inline uint32_t kpcn_nested_scramble(uint32_t x, uint32_t seed) {
  return kpcn_reverse_bits(kpcn_lk_permute(kpcn_reverse_bits(x), seed));
}

/* Sobol dimension 1 (primitive polynomial x + 1): direction v_0 = 2^31, v_k = v_{k-1} ^ v_{k-1}>>1. */
static inline uint32_t kpcn_sobol1(uint32_t index) {
  uint32_t r = 0, v = 0x80000000U;
  while (index) {
    if (index & 1U) r ^= v;
    index >>= 1;
    v ^= v >> 1;
  }
  return r;
}

static inline void kpcn_sampler_start(kpcn_sampler *s, uint64_t seed, uint32_t px, uint32_t py,
                                      uint32_t index) {
  uint32_t h = kpcn_hash32((uint32_t)seed ^ 0xa511e9b3U);
  h = kpcn_hash_combine(h, (uint32_t)(seed >> 32));
  h = kpcn_hash_combine(h, px);
  h = kpcn_hash_combine(h, py);
  s->pixel_seed = h;
  s->index = index;
  s->pair = 0;
}

static inline float kpcn_u32_to_unit(uint32_t x) { return (float)(x >> 8) * (1.0f / 16777216.0f); }

static inline void kpcn_sampler_2d(kpcn_sampler *s, float *u, float *v) {
  uint32_t seed = kpcn_hash_combine(s->pixel_seed, s->pair++);
  uint32_t i = kpcn_nested_scramble(s->index, seed);
  uint32_t x = kpcn_reverse_bits(i), y = kpcn_sobol1(i);
  x = kpcn_nested_scramble(x, kpcn_hash32(seed ^ 0x68bc21ebU));
  y = kpcn_nested_scramble(y, kpcn_hash32(seed ^ 0x02e5be93U));
  *u = kpcn_u32_to_unit(x);
  *v = kpcn_u32_to_unit(y);
}

/* Jumps to the dimension pair `pair` (keeps per-bounce dimensions fixed whatever the
 * previous bounce consumed). */
static inline void kpcn_sampler_set_pair(kpcn_sampler *s, uint32_t pair) { s->pair = pair; }

#endif
