/* Tables for the Sobol sampler (see sampler.h). */
#include "render/sampler.h"

#include <pthread.h>

uint32_t kpcn_sobol1_rev_table[4][256];
static pthread_once_t once = PTHREAD_ONCE_INIT;

static void build(void) {
  uint32_t v[32];
  v[0] = 0x80000000U;
  for (int k = 1; k < 32; k++)
    v[k] = v[k - 1] ^ (v[k - 1] >> 1);
  for (int b = 0; b < 4; b++)
    for (int x = 0; x < 256; x++) {
      uint32_t r = 0;
      for (int bit = 0; bit < 8; bit++)
        if (x & (1 << bit)) r ^= v[8 * b + bit];
      /* bit-reverse r (32 bits) */
      uint32_t rr = 0;
      for (int bit = 0; bit < 32; bit++)
        if (r & (1U << bit)) rr |= 1U << (31 - bit);
      kpcn_sobol1_rev_table[b][x] = rr;
    }
}

void kpcn_sampler_init(void) { pthread_once(&once, build); }
