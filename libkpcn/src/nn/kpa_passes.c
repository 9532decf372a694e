/* The kernel layer's chain as the architecture asks for it.
 *  - Source weights (arch.source_weight): the first pass weights each neighbour q by
 *    w(q) = e + (1-e)·sigmoid(s(q)), s being one more output channel of the network, and
 *    renormalises. It is the plain layer (kpa.c) run on nc + 1 channels, w·c and w, followed by
 *    a division, so the tested forward and backward carry it; only the premultiply and the
 *    quotient's chain rule are new here.
 *  - Several passes (arch.kpa_passes): pass p filters pass p-1's result with the same kernels,
 *    so an output pixel averages a (passes·(K-1)+1)² footprint while the network still predicts
 *    K² logits. The backward runs the passes from the last, adding each pass's dlogits share. */
#include "core/internal.h"
#include "kpcn/nn.h"
#include "nn/kpa_internal.h"

#include <math.h>
#include <stdint.h>

/* Offset of the source score (channel K²) of pixel q of image b in a logits layout. */
static size_t score_at(const kpcn_logits_layout *l, int K2, int b, size_t q) {
  return (size_t)b * l->image_stride + (size_t)(K2 / l->block) * l->block_stride +
         q * (size_t)l->pixel_stride + (size_t)(K2 % l->block);
}

/* Element i of logits stored as the layout says (f32 or bf16). */
static float logit_at(const void *logits, const kpcn_logits_layout *l, size_t i) {
  return l->bf16 ? kpcn_bf16_to_float(((const uint16_t *)logits)[i]) : ((const float *)logits)[i];
}

static inline float source_weight(float s) {
  return KPCN_KPA_SOURCE_EPS + (1.0f - KPCN_KPA_SOURCE_EPS) / (1.0f + expf(-s));
}

kpcn_status kpcn_kpa_forward_weighted(int K, int n, int nc, int h, int w, const void *logits,
                                      const kpcn_logits_layout *layout, const float *noisy,
                                      float *src1, float *acc1, float *out, float *weights,
                                      int nthreads) {
  static const char fn[] = "kpcn_kpa_forward_weighted";
  if (!logits || !noisy || !src1 || !acc1 || !out)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s: NULL buffer", fn);
  /* before score_at indexes the logits through the layout; nc + 1 channels are filtered */
  KPCN_TRY(kpcn_kpa_check_call(fn, K, n, nc + 1, h, w, layout, K * K + 1));
  if (n > 1 && ((const float *)src1 == noisy || out == acc1))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "%s: with n > 1 the source buffer may not be the input, nor the output the "
                     "accumulator",
                     fn);
  const int K2 = K * K, nt = kpcn_resolve_threads(nthreads);
  const size_t pl = (size_t)h * w;
  for (int b = 0; b < n; b++) {
    const float *nz = noisy + (size_t)b * nc * pl;
    float *s1 = src1 + (size_t)b * (nc + 1) * pl;
#pragma omp parallel for num_threads(nt) schedule(static)
    for (size_t q = 0; q < pl; q++) {
      const float wq = source_weight(logit_at(logits, layout, score_at(layout, K2, b, q)));
      for (int c = 0; c < nc; c++)
        s1[c * pl + q] = wq * nz[c * pl + q];
      s1[nc * pl + q] = wq;
    }
  }
  KPCN_TRY(
      kpcn_kpa_forward_layout(K, n, nc + 1, h, w, logits, layout, src1, acc1, weights, nthreads));
  for (int b = 0; b < n; b++) {
    const float *a1 = acc1 + (size_t)b * (nc + 1) * pl;
    float *o = out + (size_t)b * nc * pl;
#pragma omp parallel for num_threads(nt) schedule(static)
    for (size_t q = 0; q < pl; q++) {
      const float inv = 1.0f / a1[nc * pl + q]; /* >= KPCN_KPA_SOURCE_EPS: weights sum to 1 */
      for (int c = 0; c < nc; c++)
        o[c * pl + q] = a1[c * pl + q] * inv;
    }
  }
  return KPCN_OK;
}

/* Backward of kpcn_kpa_forward_weighted from dL/dout: dlogits (softmax part, via the plain
 * backward on nc + 1 channels) and the source score's gradient written into channel K².
 * scratch: 2·n·(nc+1)·h·w floats. */
static kpcn_status backward_weighted(int K, int n, int nc, int h, int w, const float *weights,
                                     const float *noisy, const float *src1, const float *acc1,
                                     const float *dout, float *dlogits,
                                     const kpcn_logits_layout *layout, float *scratch,
                                     int nthreads) {
  const int K2 = K * K, nt = kpcn_resolve_threads(nthreads);
  const size_t pl = (size_t)h * w, img1 = (size_t)n * (nc + 1) * pl;
  float *dacc = scratch, *dsrc = scratch + img1;
  /* out_c = acc_c / D: dacc_c = dout_c / D, dD = -sum_c dout_c out_c / D */
  for (int b = 0; b < n; b++) {
    const float *a1 = acc1 + (size_t)b * (nc + 1) * pl, *dy = dout + (size_t)b * nc * pl;
    float *da = dacc + (size_t)b * (nc + 1) * pl;
#pragma omp parallel for num_threads(nt) schedule(static)
    for (size_t q = 0; q < pl; q++) {
      const float inv = 1.0f / a1[nc * pl + q];
      float dd = 0;
      for (int c = 0; c < nc; c++) {
        da[c * pl + q] = dy[c * pl + q] * inv;
        dd -= dy[c * pl + q] * a1[c * pl + q] * inv;
      }
      da[nc * pl + q] = dd * inv;
    }
  }
  KPCN_TRY(kpcn_kpa_backward_layout(K, n, nc + 1, h, w, weights, src1, dacc, dlogits, layout, dsrc,
                                    nthreads));
  /* src_c = w·noisy_c, src_nc = w: dw = sum_c dsrc_c noisy_c + dsrc_nc; dw/ds = (1-e)σ(1-σ)
   * with σ recovered from the stored w */
  const float e = KPCN_KPA_SOURCE_EPS;
  for (int b = 0; b < n; b++) {
    const float *s1 = src1 + (size_t)b * (nc + 1) * pl, *nz = noisy + (size_t)b * nc * pl;
    const float *ds = dsrc + (size_t)b * (nc + 1) * pl;
#pragma omp parallel for num_threads(nt) schedule(static)
    for (size_t q = 0; q < pl; q++) {
      float dw = ds[nc * pl + q];
      for (int c = 0; c < nc; c++)
        dw += ds[c * pl + q] * nz[c * pl + q];
      const float sg = (s1[nc * pl + q] - e) / (1.0f - e);
      dlogits[score_at(layout, K2, b, q)] = dw * (1.0f - e) * sg * (1.0f - sg);
    }
  }
  return KPCN_OK;
}

size_t kpcn_kpa_passes_mid_floats(int passes, int source_weight, int n, int nc, int h, int w) {
  const size_t pl = (size_t)n * h * w;
  return (size_t)(passes > 1 ? passes - 1 : 0) * nc * pl +
         (source_weight ? 2 * (size_t)(nc + 1) * pl : 0);
}

size_t kpcn_kpa_passes_scratch_floats(int passes, int source_weight, int n, int nc, int h, int w,
                                      const kpcn_logits_layout *layout) {
  if (!layout) return 0; /* documented: the layout is needed (its image stride) */
  const size_t pl = (size_t)n * h * w;
  return (passes > 1 ? 2 * (size_t)nc * pl + (size_t)n * layout->image_stride : 0) +
         (source_weight ? 2 * (size_t)(nc + 1) * pl : 0);
}

static kpcn_status check_chain(const char *fn, int passes, int source_weight, const float *mid) {
  if (passes < 1 || passes > KPCN_NN_MAX_KPA_PASSES || (source_weight != 0 && source_weight != 1))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "%s: passes = %d not in [1, %d] or source_weight = %d not 0/1", fn, passes,
                     KPCN_NN_MAX_KPA_PASSES, source_weight);
  if ((passes > 1 || source_weight) && !mid)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s: no mid buffer", fn);
  return KPCN_OK;
}

kpcn_status kpcn_kpa_forward_passes(int K, int passes, int source_weight, int n, int nc, int h,
                                    int w, const void *logits, const kpcn_logits_layout *layout,
                                    const float *noisy, float *mid, float *out, float *weights,
                                    int nthreads) {
  KPCN_TRY(check_chain("kpcn_kpa_forward_passes", passes, source_weight, mid));
  KPCN_TRY(kpcn_kpa_check_call("kpcn_kpa_forward_passes", K, n, nc, h, w, layout,
                               K * K + source_weight));
  const size_t img = (size_t)n * nc * h * w, img1 = (size_t)n * (nc + 1) * h * w;
  float *src1 = mid ? mid + (size_t)(passes - 1) * img : NULL, *acc1 = src1 ? src1 + img1 : NULL;
  const float *src = noisy;
  for (int p = 0; p < passes; p++) {
    float *dst = p == passes - 1 ? out : mid + (size_t)p * img;
    float *wt = p == 0 ? weights : NULL;
    if (p == 0 && source_weight)
      KPCN_TRY(kpcn_kpa_forward_weighted(K, n, nc, h, w, logits, layout, src, src1, acc1, dst, wt,
                                         nthreads));
    else
      KPCN_TRY(kpcn_kpa_forward_layout(K, n, nc, h, w, logits, layout, src, dst, wt, nthreads));
    src = dst;
  }
  return KPCN_OK;
}

/* a += b over n floats */
static void add_inplace(float *restrict a, const float *restrict b, size_t n, int nthreads) {
  const int nt = kpcn_resolve_threads(nthreads);
#pragma omp parallel for num_threads(nt) schedule(static)
  for (size_t i = 0; i < n; i++)
    a[i] += b[i];
}

kpcn_status kpcn_kpa_backward_passes(int K, int passes, int source_weight, int n, int nc, int h,
                                     int w, const float *weights, const float *noisy,
                                     const float *mid, const float *dout, float *dlogits,
                                     const kpcn_logits_layout *layout, float *scratch,
                                     int nthreads) {
  KPCN_TRY(check_chain("kpcn_kpa_backward_passes", passes, source_weight, mid));
  KPCN_TRY(kpcn_kpa_check_call("kpcn_kpa_backward_passes", K, n, nc, h, w, layout,
                               K * K + source_weight));
  if ((passes > 1 || source_weight) && !scratch)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_kpa_backward_passes: no scratch buffer");
  const size_t img = (size_t)n * nc * h * w, img1 = (size_t)n * (nc + 1) * h * w;
  /* scratch: dL/d(pass input) ping-pong [2][img] and one pass's dlogits share (passes > 1),
   * then the source-weighted pass's own [2][img1] */
  float *dmid[2] = {scratch, scratch ? scratch + img : NULL};
  float *dshare = scratch ? scratch + 2 * img : NULL;
  float *wscr =
      scratch ? scratch + (passes > 1 ? 2 * img + (size_t)n * layout->image_stride : 0) : NULL;
  const float *src1 = mid ? mid + (size_t)(passes - 1) * img : NULL;
  for (int p = passes - 1; p >= 0; p--) {
    const float *src = p == 0 ? noisy : mid + (size_t)(p - 1) * img;
    float *dl = p == passes - 1 ? dlogits : dshare;
    float *din = p > 0 ? dmid[p & 1] : NULL;
    if (p == 0 && source_weight)
      KPCN_TRY(backward_weighted(K, n, nc, h, w, weights, noisy, src1, src1 + img1, dout, dl,
                                 layout, wscr, nthreads));
    else
      KPCN_TRY(
          kpcn_kpa_backward_layout(K, n, nc, h, w, weights, src, dout, dl, layout, din, nthreads));
    if (dl != dlogits) {
      /* the score channel is the first pass's alone: keep it out of the sum */
      if (source_weight)
        for (int b = 0; b < n; b++)
          for (size_t q = 0; q < (size_t)h * w; q++) {
            const size_t i = score_at(layout, K * K, b, q);
            dlogits[i] = dl[i], dl[i] = 0;
          }
      add_inplace(dlogits, dl, (size_t)n * layout->image_stride, nthreads);
    }
    dout = din;
  }
  return KPCN_OK;
}
