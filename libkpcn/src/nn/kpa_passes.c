/* Several passes of the kernel-prediction layer with one set of kernels (arch.kpa_passes):
 * pass p filters pass p-1's result, so an output pixel averages a (passes·(K-1)+1)² footprint
 * while the network still predicts K² logits. Built on the one-pass forward and backward
 * (kpa.c); the backward runs the passes from the last, adding each pass's dlogits share. */
#include "core/internal.h"
#include "kpcn/nn.h"

size_t kpcn_kpa_passes_scratch_floats(int passes, int n, int nc, int h, int w,
                                      const kpcn_logits_layout *layout) {
  if (passes <= 1) return 0;
  return 2 * (size_t)n * nc * h * w + (size_t)n * layout->image_stride;
}

kpcn_status kpcn_kpa_forward_passes(int K, int passes, int n, int nc, int h, int w,
                                    const float *logits, const kpcn_logits_layout *layout,
                                    const float *noisy, float *mid, float *out, float *weights,
                                    int nthreads) {
  if (passes < 1 || passes > KPCN_NN_MAX_KPA_PASSES || (passes > 1 && !mid))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "kpcn_kpa_forward_passes: passes = %d not in [1, %d] or no mid buffer", passes,
                     KPCN_NN_MAX_KPA_PASSES);
  const size_t img = (size_t)n * nc * h * w;
  const float *src = noisy;
  for (int p = 0; p < passes; p++) {
    float *dst = p == passes - 1 ? out : mid + (size_t)p * img;
    KPCN_TRY(kpcn_kpa_forward_layout(K, n, nc, h, w, logits, layout, src, dst,
                                     p == 0 ? weights : NULL, nthreads));
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

kpcn_status kpcn_kpa_backward_passes(int K, int passes, int n, int nc, int h, int w,
                                     const float *weights, const float *noisy, const float *mid,
                                     const float *dout, float *dlogits,
                                     const kpcn_logits_layout *layout, float *scratch,
                                     int nthreads) {
  if (passes < 1 || passes > KPCN_NN_MAX_KPA_PASSES || (passes > 1 && (!mid || !scratch)))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "kpcn_kpa_backward_passes: passes = %d not in [1, %d] or no mid/scratch "
                     "buffer",
                     passes, KPCN_NN_MAX_KPA_PASSES);
  const size_t img = (size_t)n * nc * h * w;
  /* scratch: dL/d(pass input) ping-pong [2][img], then one pass's dlogits share */
  float *dmid[2] = {scratch, scratch ? scratch + img : NULL};
  float *dshare = scratch ? scratch + 2 * img : NULL;
  for (int p = passes - 1; p >= 0; p--) {
    const float *src = p == 0 ? noisy : mid + (size_t)(p - 1) * img;
    float *dl = p == passes - 1 ? dlogits : dshare;
    float *din = p > 0 ? dmid[p & 1] : NULL;
    KPCN_TRY(
        kpcn_kpa_backward_layout(K, n, nc, h, w, weights, src, dout, dl, layout, din, nthreads));
    if (dl != dlogits) add_inplace(dlogits, dl, (size_t)n * layout->image_stride, nthreads);
    dout = din;
  }
  return KPCN_OK;
}
