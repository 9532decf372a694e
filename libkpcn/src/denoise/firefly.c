/* Bounding isolated diffuse fireflies before the KPCN sees them (kpcn/denoise.h,
 * kpcn_aov_bound_fireflies; docs/denoiser.md "Fireflies at partly covered pixels").
 *
 * Why: the diffuse branch filters irradiance, diffuse / (albedo + eps). At a pixel that the
 * diffuse surface only partly covers (an object's silhouette against a mirror or the sky),
 * the pixel's albedo is the covered fraction times the surface's, so one bright sample there
 * becomes an irradiance several times its colour. A neighbour's kernel that borrows part of
 * it remodulates it with that neighbour's full albedo: the firefly comes out brighter and
 * wider than it went in (glossy-mirror v001, 16 spp: 1.93 in, 3.56 out next to it, reference
 * 0.047). A pixel whose irradiance stands far above all eight neighbours and whose value
 * rests on a few samples is therefore scaled down to a bound before denoising.
 *
 * Deterministic and independent of threads: every decision reads the irradiance computed
 * before any pixel changes. */
#include "core/internal.h"
#include "denoise_internal.h"

#include <math.h>

/* The variance of the mean of N samples of which one carries all the light is ~mean^2, of
 * which k carry it ~mean^2 / k: above this relative variance the pixel's value rests on at
 * most ~4 samples. Smooth bright detail (an emitter's edge, a sharp caustic seen at many
 * samples) has a far lower one and is left alone. */
#define FIREFLY_MIN_RELVAR 0.25f
/* Bound floor, as a fraction of the image's exposure (kpcn_aov_exposure): a pixel amid black
 * neighbours is bounded to this, not to zero, and the rule is exposure-invariant. */
#define FIREFLY_FLOOR 0.01

kpcn_status kpcn_aov_bound_fireflies(kpcn_aov_set *aov, float ratio, float eps, double exposure,
                                     int *count) {
  if (count) *count = 0;
  if (!aov) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "bound_fireflies: aov is NULL");
  if (!(ratio >= 1.0f) || !isfinite(ratio))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "bound_fireflies: ratio %g must be >= 1",
                     (double)ratio);
  if (!(eps > 0.0f) || !isfinite(eps))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "bound_fireflies: eps %g must be > 0", (double)eps);
  KPCN_TRY(kpcn_aov_require(aov, KPCN_BUF_DIFFUSE, 1, "bound_fireflies"));
  KPCN_TRY(kpcn_aov_require(aov, KPCN_BUF_ALBEDO, 0, "bound_fireflies"));
  KPCN_TRY(kpcn_aov_require(aov, KPCN_BUF_SPECULAR, 0, "bound_fireflies"));
  if (!(exposure > 0.0)) KPCN_TRY(kpcn_aov_exposure(aov, &exposure));
  const int W = aov->width;
  int H = aov->height;
  const size_t P = kpcn_aov_plane_size(aov);
  float *irr = kpcn_aligned_alloc(sizeof(float) * P, "firefly irradiance");
  if (!irr) return KPCN_ERR_OUT_OF_MEMORY;
  float *dif = aov->buf[KPCN_BUF_DIFFUSE], *var = aov->var[KPCN_BUF_DIFFUSE];
  const float *alb = aov->buf[KPCN_BUF_ALBEDO];
  float *col = aov->buf[KPCN_BUF_COLOR]; /* kept = diffuse + specular where present */
  for (size_t i = 0; i < P; i++) {
    float e = 0.0f;
    for (int c = 0; c < 3; c++)
      e += dif[c * P + i] / (alb[c * P + i] + eps);
    irr[i] = e * (1.0f / 3.0f);
  }
  const float bound_floor = (float)(FIREFLY_FLOOR * exposure);
  int n = 0;
  /* a 1x1 image has no neighbour to compare with: nothing says its pixel is a firefly (the
   * bound fell to the floor and darkened it 700-fold) */
  if (P == 1) H = 0;
  for (int y = 0; y < H; y++)
    for (int x = 0; x < W; x++) {
      const size_t i = (size_t)y * W + x;
      float nb = 0.0f; /* the brightest of the (up to) eight neighbours inside the image */
      for (int dy = -1; dy <= 1; dy++)
        for (int dx = -1; dx <= 1; dx++) {
          const int yy = y + dy, xx = x + dx;
          if ((dx || dy) && yy >= 0 && yy < H && xx >= 0 && xx < W) {
            const float v = irr[(size_t)yy * W + xx];
            if (v > nb) nb = v;
          }
        }
      const float bound = ratio * nb + bound_floor;
      if (!(irr[i] > bound)) continue;
      const float m = (dif[i] + dif[P + i] + dif[2 * P + i]) * (1.0f / 3.0f);
      if (!(var[i] > FIREFLY_MIN_RELVAR * m * m)) continue;
      const float s = bound / irr[i];
      for (int c = 0; c < 3; c++) {
        const float d = dif[c * P + i];
        dif[c * P + i] = d * s;
        if (col) col[c * P + i] -= d - d * s;
      }
      var[i] *= s * s;
      n++;
    }
  kpcn_aligned_free(irr);
  if (count) *count = n;
  return KPCN_OK;
}
