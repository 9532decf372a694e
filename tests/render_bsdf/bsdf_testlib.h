/* Shared helpers for the bsdf tests: a deterministic RNG and bsdf construction shortcuts. */
#ifndef KPCN_TEST_BSDF_LIB_H
#define KPCN_TEST_BSDF_LIB_H

#include "render/bsdf.h"
#include "render/sampling.h"

#include <math.h>
#include <stdint.h>

typedef struct {
  uint64_t s;
} kt_rng;

static inline float kt_next(kt_rng *r) {
  /* splitmix64 -> 24-bit float in [0,1) */
  uint64_t z = (r->s += 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  z ^= z >> 31;
  return (float)(z >> 40) * (1.0f / 16777216.0f);
}

static inline kpcn_vec3 kt_dir(float theta_deg, float phi_deg) {
  float t = theta_deg * KPCN_PI / 180.0f, p = phi_deg * KPCN_PI / 180.0f;
  return kv3(sinf(t) * cosf(p), sinf(t) * sinf(p), cosf(t));
}

#endif
