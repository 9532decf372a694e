/* Synthetic AOV sets for the denoise tests: every buffer and variance present, smooth
 * structure (edges between regions) plus deterministic noise. */
#ifndef KPCN_TEST_DENOISE_SYNTH_H
#define KPCN_TEST_DENOISE_SYNTH_H
#include <math.h>
#include <string.h>

#include "kpcn/image.h"
#include "testutil.h"

static kpcn_aov_set *synth_aov(int W, int H, unsigned seed) {
  kpcn_aov_set *a = NULL;
  if (kpcn_aov_create(&a, W, H) != KPCN_OK) return NULL;
  for (int b = 0; b < KPCN_BUF_COUNT; b++)
    if (kpcn_aov_add(a, (kpcn_buffer)b, 1) != KPCN_OK) return NULL;
  const size_t P = kpcn_aov_plane_size(a);
  unsigned st = seed;
  for (int y = 0; y < H; y++)
    for (int x = 0; x < W; x++) {
      const size_t i = (size_t)y * W + x;
      const int region = (x * 3 / W) + 3 * (y * 2 / H);
      float z = 1.0f + 0.5f * region + 0.01f * x;
      for (int c = 0; c < 3; c++) {
        float alb = 0.1f + 0.15f * (float)((region + c) % 5);
        float dif = alb * (0.5f + 0.3f * sinf(0.1f * x + c)) * (0.6f + 0.8f * kt_randf(&st));
        float spc = (region == 4 ? 2.0f : 0.05f) * (0.2f + 1.6f * kt_randf(&st));
        a->buf[KPCN_BUF_ALBEDO][c * P + i] = alb;
        a->buf[KPCN_BUF_DIFFUSE][c * P + i] = dif;
        a->buf[KPCN_BUF_SPECULAR][c * P + i] = spc;
        a->buf[KPCN_BUF_COLOR][c * P + i] = dif + spc;
      }
      float nx = 0.3f * (float)(region % 3) - 0.3f, ny = 0.2f * (float)(region / 3);
      float nz = sqrtf(fmaxf(0.0f, 1.0f - nx * nx - ny * ny));
      a->buf[KPCN_BUF_NORMAL][0 * P + i] = nx;
      a->buf[KPCN_BUF_NORMAL][1 * P + i] = ny;
      a->buf[KPCN_BUF_NORMAL][2 * P + i] = nz;
      a->buf[KPCN_BUF_DEPTH][i] = z;
      a->buf[KPCN_BUF_VISIBILITY][i] = kt_randf(&st) < 0.7f ? 1.0f : 0.25f;
      for (int b = 0; b < KPCN_BUF_COUNT; b++)
        a->var[b][i] = 0.01f * kt_randf(&st) * (b + 1);
    }
  return a;
}
#endif
