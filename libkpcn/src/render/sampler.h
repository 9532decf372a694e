/* Low-discrepancy sampler: shuffled, Owen-scrambled Sobol points (Burley 2020, "Practical
 * Hash-based Owen Scrambling"). Every 2D dimension pair of a path uses the first two Sobol
 * dimensions (a (0,2)-sequence) with its own index shuffle and its own nested uniform
 * scramble, both keyed on a hash of (seed, pixel, pair), so pixels are decorrelated and each
 * pixel's sequence depends only on (seed, pixel, sample index): results do not depend on
 * which thread renders the pixel. Power-of-two sample counts are stratified per pair.
 *
 * Pairs from KPCN_SAMPLER_LD_PAIRS on (the camera and the first two bounces are below it) are
 * plain hashed uniforms: stratification of the third and later bounces no longer lowers the
 * pixel error measurably (the integrand there is already a sum over many paths), while the
 * Owen-Sobol construction cost 15% of the render time at deep bounces. */
#ifndef KPCN_RENDER_SAMPLER_H
#define KPCN_RENDER_SAMPLER_H

#include <stdint.h>
#ifdef __GFNI__
#include <immintrin.h>
#endif

/* Per-pixel cache of the Owen-Sobol pair seeds (they depend on seed, pixel and pair, not on
 * the sample index), filled lazily. */
#define KPCN_SAMPLER_LD_PAIRS 8
#define KPCN_SAMPLER_CACHE KPCN_SAMPLER_LD_PAIRS
typedef struct kpcn_sampler_cache {
  uint32_t pixel_seed;
  uint32_t filled; /* pairs [0, filled) are valid */
  uint32_t seed[KPCN_SAMPLER_CACHE][3];
} kpcn_sampler_cache;

typedef struct kpcn_sampler {
  uint32_t pixel_seed;       /* hash of seed and pixel */
  uint32_t index;            /* sample index within the pixel */
  uint32_t rev_index;        /* bit-reversed index */
  uint32_t pair;             /* next dimension pair */
  kpcn_sampler_cache *cache; /* may be NULL */
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

#ifdef __GFNI__
/* One affine GF(2) byte transform reverses the bits of every byte, a byte swap does the rest:
 * a quarter of the instructions of the shift-and-mask version below, on the sampler's
 * dependency chain (the integrator is compiled a second time with GFNI enabled, see
 * integrator_gfni.c; both give the same bits). */
static inline uint32_t kpcn_reverse_bits(uint32_t x) {
  __m128i v = _mm_cvtsi32_si128((int)x);
  v = _mm_gf2p8affine_epi64_epi8(v, _mm_set1_epi64x(0x8040201008040201LL), 0);
  return __builtin_bswap32((uint32_t)_mm_cvtsi128_si32(v));
}
#else
/* byte swap, then swap nibbles, bit pairs and bits: register-only, no table loads on the
 * sampler's dependency chain */
static inline uint32_t kpcn_reverse_bits(uint32_t x) {
  x = __builtin_bswap32(x);
  x = ((x >> 4) & 0x0f0f0f0fU) | ((x & 0x0f0f0f0fU) << 4);
  x = ((x >> 2) & 0x33333333U) | ((x & 0x33333333U) << 2);
  return ((x >> 1) & 0x55555555U) | ((x & 0x55555555U) << 1);
}
#endif

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

/* Sobol dimension 1 (primitive polynomial x + 1): direction v_0 = 2^31, v_k = v_{k-1} ^ v_{k-1}>>1.
 * The shuffled indices are full 32-bit numbers, so the generator matrix is applied a byte at a
 * time through tables holding the BIT-REVERSED direction numbers (what the Owen scramble works
 * on); filled once by kpcn_sampler_init. */
extern uint32_t kpcn_sobol1_rev_table[4][256];
void kpcn_sampler_init(void);

static inline uint32_t kpcn_sobol1_reversed(uint32_t index) {
  return kpcn_sobol1_rev_table[0][index & 255U] ^ kpcn_sobol1_rev_table[1][(index >> 8) & 255U] ^
         kpcn_sobol1_rev_table[2][(index >> 16) & 255U] ^ kpcn_sobol1_rev_table[3][index >> 24];
}

/* Cheap independent uniform for decisions that need no stratification (Russian roulette). */
static inline float kpcn_sampler_random(const kpcn_sampler *s, uint32_t salt) {
  return (float)(kpcn_hash32(kpcn_hash_combine(s->pixel_seed ^ 0x5bd1e995U,
                                               s->index * 0x9e3779b9U + salt)) >>
                 8) *
         (1.0f / 16777216.0f);
}

static inline uint32_t kpcn_pixel_seed(uint64_t seed, uint32_t px, uint32_t py) {
  uint32_t h = kpcn_hash32((uint32_t)seed ^ 0xa511e9b3U);
  h = kpcn_hash_combine(h, (uint32_t)(seed >> 32));
  h = kpcn_hash_combine(h, px);
  return kpcn_hash_combine(h, py);
}

/* Starts sample `index` of pixel (px, py). cache (optional) must belong to this pixel: call
 * kpcn_sampler_cache_reset(cache, kpcn_pixel_seed(...)) when moving to a new pixel. */
static inline void kpcn_sampler_start(kpcn_sampler *s, uint64_t seed, uint32_t px, uint32_t py,
                                      uint32_t index, kpcn_sampler_cache *cache) {
  s->pixel_seed = cache ? cache->pixel_seed : kpcn_pixel_seed(seed, px, py);
  s->index = index;
  s->rev_index = 0;
  s->pair = 0;
  s->cache = cache;
}

static inline void kpcn_sampler_cache_reset(kpcn_sampler_cache *c, uint32_t pixel_seed) {
  c->pixel_seed = pixel_seed;
  c->filled = 0;
}

static inline void kpcn_pair_seeds(uint32_t pixel_seed, uint32_t pair, uint32_t out[3]) {
  uint32_t seed = kpcn_hash_combine(pixel_seed, pair);
  out[0] = seed;
  out[1] = kpcn_hash32(seed ^ 0x68bc21ebU);
  out[2] = kpcn_hash32(seed ^ 0x02e5be93U);
}

static inline float kpcn_u32_to_unit(uint32_t x) { return (float)(x >> 8) * (1.0f / 16777216.0f); }

/* Nested uniform scrambling is rev(LK(rev(x))); working in the reversed domain saves the
 * inner reversals: dimension 0 of Sobol is rev(i), dimension 1 comes reversed from the table. */
__attribute__((always_inline)) static inline void kpcn_sampler_2d(kpcn_sampler *s, float *u,
                                                                  float *v) {
  uint32_t tmp[3];
  const uint32_t *sd;
  uint32_t pair = s->pair++;
  if (pair >= KPCN_SAMPLER_LD_PAIRS) {
    uint32_t h = kpcn_hash32(kpcn_hash_combine(s->pixel_seed ^ 0x2c1b3c6dU,
                                               s->index * 0x9e3779b9U + pair * 0x85ebca6bU));
    *u = kpcn_u32_to_unit(h);
    *v = kpcn_u32_to_unit(kpcn_hash32(h ^ 0x297a2d39U));
    return;
  }
  kpcn_sampler_cache *c = s->cache;
  if (c && pair < KPCN_SAMPLER_CACHE) {
    while (c->filled <= pair) {
      kpcn_pair_seeds(c->pixel_seed, c->filled, c->seed[c->filled]);
      c->filled++;
    }
    sd = c->seed[pair];
  } else {
    kpcn_pair_seeds(s->pixel_seed, pair, tmp);
    sd = tmp;
  }
  if (!s->rev_index && s->index) s->rev_index = kpcn_reverse_bits(s->index);
  uint32_t ir = kpcn_lk_permute(s->rev_index, sd[0]); /* reversed shuffled index */
  uint32_t i = kpcn_reverse_bits(ir);
  uint32_t x = kpcn_reverse_bits(kpcn_lk_permute(i, sd[1]));
  uint32_t y = kpcn_reverse_bits(kpcn_lk_permute(kpcn_sobol1_reversed(i), sd[2]));
  *u = kpcn_u32_to_unit(x);
  *v = kpcn_u32_to_unit(y);
}

/* Jumps to the dimension pair `pair` (keeps per-bounce dimensions fixed whatever the
 * previous bounce consumed). */
static inline void kpcn_sampler_set_pair(kpcn_sampler *s, uint32_t pair) { s->pair = pair; }

#endif
