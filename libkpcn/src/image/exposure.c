/* The exposure of an AOV set (kpcn/image.h, kpcn_aov_exposure): a statistic of its
 * brightness that scales with the image and ignores its orientation and sample count. The
 * KPCN denoiser normalises its input to it (kpcn_denoiser_options.exposure). */
#include "core/internal.h"
#include "kpcn/image.h"

#include <math.h>
#include <stdlib.h>

/* Block index along an axis of n pixels: blocks of 8 laid out from the image centre
 * outwards (the central block of an odd axis has 7 pixels), so mirroring the axis maps
 * blocks onto blocks and the exposure is the same for every mirrored / rotated copy. */
static int axis_block(int x, int n) {
  const int u = 2 * x + 1 - n; /* twice the offset of the pixel centre from the image centre */
  if (n % 2) {
    const int k = (abs(u) + 8) / 16;
    return u < 0 ? -k : k;
  }
  return u > 0 ? (u - 1) / 16 : -1 - (-u - 1) / 16;
}

kpcn_status kpcn_aov_exposure(const kpcn_aov_set *aov, double *out) {
  if (!aov || !out) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "aov_exposure: NULL argument");
  *out = 0.0;
  KPCN_TRY(kpcn_aov_require(aov, KPCN_BUF_DIFFUSE, 0, "exposure"));
  KPCN_TRY(kpcn_aov_require(aov, KPCN_BUF_SPECULAR, 0, "exposure"));
  const int W = aov->width, H = aov->height;
  const int x0 = axis_block(0, W), y0 = axis_block(0, H);
  const int bx = axis_block(W - 1, W) - x0 + 1, by = axis_block(H - 1, H) - y0 + 1;
  const size_t P = kpcn_aov_plane_size(aov), nb = (size_t)bx * by;
  double *sum = kpcn_calloc(nb, sizeof(double), "exposure blocks");
  int *cnt = kpcn_calloc(nb, sizeof(int), "exposure blocks");
  int *col = kpcn_alloc(sizeof(int) * (size_t)W, "exposure blocks");
  if (!sum || !cnt || !col) {
    free(sum), free(cnt), free(col);
    return KPCN_ERR_OUT_OF_MEMORY;
  }
  for (int x = 0; x < W; x++)
    col[x] = axis_block(x, W) - x0;
  static const double wl[3] = {0.2126, 0.7152, 0.0722}; /* Rec. 709 luminance */
  const float *d = aov->buf[KPCN_BUF_DIFFUSE], *sp = aov->buf[KPCN_BUF_SPECULAR];
  for (int y = 0; y < H; y++) {
    const size_t row = (size_t)(axis_block(y, H) - y0) * bx;
    for (int x = 0; x < W; x++) {
      const size_t k = (size_t)y * W + x;
      double l = 0.0;
      for (int c = 0; c < 3; c++)
        l += wl[c] * ((double)d[c * P + k] + (double)sp[c * P + k]);
      if (isfinite(l)) sum[row + col[x]] += l, cnt[row + col[x]]++;
    }
  }
  size_t n = 0; /* lit blocks' means, packed to the front of sum */
  for (size_t b = 0; b < nb; b++)
    if (cnt[b] > 0 && sum[b] > 0.0 && isfinite(sum[b])) sum[n++] = sum[b] / cnt[b];
  *out = kpcn_median_inplace(sum, n);
  free(sum), free(cnt), free(col);
  return KPCN_OK;
}
