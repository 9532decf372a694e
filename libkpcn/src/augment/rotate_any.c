/* Rotation by an arbitrary angle with bilinear resampling. Unlike the quarter turns this
 * is NOT exact: interpolation averages neighbouring noisy samples, which lowers the
 * per-pixel variance and correlates the noise spatially (documented in augment.h). The
 * ".var" planes are propagated as sum(w_i^2 var_i), the variance of the interpolated mean
 * under independent pixels, so mean and variance stay mutually consistent. */
#include "augment/roles.h"
#include "core/internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

typedef struct tap {
  uint32_t idx[4];
  float w[4];
} tap;

static int is_var(const char *name) {
  if (!name) return 0;
  size_t n = strlen(name);
  return n >= 4 && strcmp(name + n - 4, ".var") == 0;
}

static kpcn_status rotate_ptrs(float *const *dst, const float *const *src, int nch,
                               const char *const *names, int W, int H, double degrees,
                               int nthreads) {
  if (!dst || !src || nch <= 0 || !isfinite(degrees))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "rotate: NULL buffer, no channels or bad angle");
  KPCN_TRY(kpcn_check_size(W, H, "rotate input"));
  kpcn_channel_roles roles;
  KPCN_TRY(kpcn_channel_roles_init(&roles, names, nch, NULL));
  size_t n = (size_t)W * (size_t)H;
  tap *taps = kpcn_alloc(n * sizeof *taps, "rotation taps");
  if (!taps) {
    kpcn_channel_roles_free(&roles);
    return KPCN_ERR_OUT_OF_MEMORY;
  }
  double th = degrees * 3.14159265358979323846 / 180.0, cs = cos(th), sn = sin(th);
  double cx = 0.5 * (W - 1), cy = 0.5 * (H - 1);
  int nt = kpcn_resolve_threads(nthreads);
#pragma omp parallel for num_threads(nt) schedule(static)
  for (int yo = 0; yo < H; yo++) {
    for (int xo = 0; xo < W; xo++) {
      /* Screen coordinates with y up; the inverse rotation finds the source point. */
      double u = xo - cx, v = -(yo - cy);
      double us = cs * u + sn * v, vs = -sn * u + cs * v;
      double xs = cx + us, ys = cy - vs;
      tap *t = &taps[(size_t)yo * (size_t)W + (size_t)xo];
      memset(t, 0, sizeof *t);
      int x0 = (int)floor(xs), y0 = (int)floor(ys);
      double fx = xs - x0, fy = ys - y0;
      for (int j = 0; j < 4; j++) {
        int px = x0 + (j & 1), py = y0 + (j >> 1);
        double w = ((j & 1) ? fx : 1 - fx) * ((j >> 1) ? fy : 1 - fy);
        if (px < 0 || py < 0 || px >= W || py >= H || w <= 0) continue;
        t->idx[j] = (uint32_t)((size_t)py * (size_t)W + (size_t)px);
        t->w[j] = (float)w;
      }
    }
  }
  kpcn_status st = KPCN_OK;
  for (int c = 0; c < nch; c++) {
    const float *s = src[c];
    float *d = dst[c];
    int sq = is_var(names ? names[c] : NULL);
#pragma omp parallel for num_threads(nt) schedule(static)
    for (size_t i = 0; i < n; i++) {
      const tap *t = &taps[i];
      double acc = 0;
      for (int j = 0; j < 4; j++)
        acc += (sq ? (double)t->w[j] * t->w[j] : t->w[j]) * s[t->idx[j]];
      d[i] = (float)acc;
    }
  }
  /* Rotate normal x/y by the angle, then renormalise (interpolation shortens them). */
  for (int c = 0; c < nch && st == KPCN_OK; c++) {
    /* a lone N.Y is refused as a lone N.X is (it was resampled but left unrotated) */
    if (roles.normal_role[c] == 1 && roles.normal_pair[c][0] < 0) {
      st = kpcn_fail(KPCN_ERR_MISSING_CHANNEL, "rotate: normal channel '%s' needs its N.X",
                     names[c]);
      break;
    }
    if (roles.normal_role[c] != 0) continue;
    int ix = roles.normal_pair[c][0], iy = roles.normal_pair[c][1], iz = roles.normal_pair[c][2];
    if (iy < 0) {
      st = kpcn_fail(KPCN_ERR_MISSING_CHANNEL, "rotate: normal channel '%s' needs its N.Y",
                     names[c]);
      break;
    }
    float *nx = dst[ix], *ny = dst[iy], *nz = iz >= 0 ? dst[iz] : NULL;
#pragma omp parallel for num_threads(nt) schedule(static)
    for (size_t i = 0; i < n; i++) {
      double a = nx[i], b = ny[i], z = nz ? nz[i] : 0.0;
      double ra = cs * a - sn * b, rb = sn * a + cs * b;
      double len = sqrt(ra * ra + rb * rb + z * z);
      if (len > 1e-12) {
        nx[i] = (float)(ra / len);
        ny[i] = (float)(rb / len);
        if (nz) nz[i] = (float)(z / len);
      } else {
        nx[i] = (float)ra;
        ny[i] = (float)rb;
      }
    }
  }
  free(taps);
  kpcn_channel_roles_free(&roles);
  return st;
}

static kpcn_status rotate_ptrs_fn(float *const *dst, const float *const *src, int nch,
                                  const char *const *names, int W, int H, const void *arg,
                                  int nthreads) {
  return rotate_ptrs(dst, src, nch, names, W, H, *(const double *)arg, nthreads);
}

kpcn_status kpcn_augment_rotate_any_planes(float *dst, const float *src, int nch,
                                           const char *const *names, int width, int height,
                                           double degrees, int nthreads) {
  if (!dst || !src || nch <= 0 || nch > 4096)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_augment_rotate_any_planes: bad arguments");
  KPCN_TRY(kpcn_check_size(width, height, "kpcn_augment_rotate_any_planes"));
  return kpcn_augment_contiguous(dst, src, nch, names, width, height, rotate_ptrs_fn, &degrees,
                                 nthreads);
}

kpcn_status kpcn_augment_rotate_any_aov(kpcn_aov_set **out, const kpcn_aov_set *in, double degrees,
                                        int nthreads) {
  if (!out || !in) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_augment_rotate_any_aov: NULL");
  *out = NULL;
  kpcn_aov_set *o = NULL;
  KPCN_TRY(kpcn_aov_like(&o, in, in->width, in->height));
  float *sp[KPCN_AOV_MAX_PLANES], *dp[KPCN_AOV_MAX_PLANES];
  const char *names[KPCN_AOV_MAX_PLANES];
  int n = kpcn_aov_collect_planes(in, sp, names);
  kpcn_aov_collect_planes(o, dp, names);
  kpcn_status st = n ? rotate_ptrs(dp, (const float *const *)sp, n, names, in->width, in->height,
                                   degrees, nthreads)
                     : kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "rotate: the AOV set has no buffers");
  if (st != KPCN_OK) {
    kpcn_aov_destroy(o);
    return st;
  }
  *out = o;
  return KPCN_OK;
}
