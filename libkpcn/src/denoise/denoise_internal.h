/* Private interfaces between the denoise module's files. */
#ifndef KPCN_DENOISE_INTERNAL_H
#define KPCN_DENOISE_INTERNAL_H

#include "kpcn/denoise.h"

/* Progress reporting shared by long loops: returns non-zero when the callback asked to
 * cancel. Safe to call from one thread at a time. */
typedef struct kpcn_progress {
  kpcn_progress_fn fn;
  void *user;
  int cancelled;
} kpcn_progress;

static inline int kpcn_progress_report(kpcn_progress *p, double f) {
  if (p && p->fn && !p->cancelled && p->fn(p->user, f)) p->cancelled = 1;
  return p ? p->cancelled : 0;
}

/* The baseline parameters' ranges (the bilateral filter's, or non-local means' with nlmeans),
 * checked at kpcn_denoiser_create and again by each baseline. */
kpcn_status kpcn_baseline_params_check(const kpcn_baseline_params *p, int nlmeans);
/* Classical baselines on the color buffer of `aov` guided by its features. out: planar RGB
 * [3][H][W]. Need color + color.var, and normal/albedo/depth for each feature whose sigma
 * is > 0 (missing ones are named in the error). */
kpcn_status kpcn_baseline_bilateral(const kpcn_aov_set *aov, const kpcn_baseline_params *p,
                                    float *out, int nthreads, kpcn_progress *prog);
kpcn_status kpcn_baseline_nlmeans(const kpcn_aov_set *aov, const kpcn_baseline_params *p,
                                  float *out, int nthreads, kpcn_progress *prog);

/* Memory for one padded tile's buffers when no tile size is given (tile_grid in
 * kpcn_pipeline.c chooses the grid with the least overlap that fits it): an eighth of the
 * machine's physical memory, clamped to [MIN, MAX] (kpcn_tile_budget_bytes). */
#define KPCN_TILE_BUDGET_MIN ((size_t)1 << 30)
#define KPCN_TILE_BUDGET_MAX ((size_t)3 << 30)
size_t kpcn_tile_budget_bytes(void);

/* Whether kpcn_features_build_region_pixels has its vector path here for this element type
 * (AVX-512 with BW, VL and, for bf16, BF16). Elsewhere it runs scalar, slower than a net's
 * own input reorder, so the pipeline builds planar features there. */
int kpcn_features_pixels_fast(int bf16);

/* What the KPCN pipeline keeps from one execute to the next (the denoiser owns one, as an
 * OIDN filter keeps its buffers): one network, rebound to either branch, and the tile
 * buffers. A warm execute of the same size then creates no oneDNN primitive and touches no
 * fresh page (net creation and page zeroing were ~7 % of a 1 Mpx execute). */
typedef struct kpcn_pipeline_cache {
  kpcn_net *net;
  int net_w, net_h, bf16, direct_conv, nthreads; /* what `net` was created for */
  double conv_base;                              /* net's convolution seconds already counted */
  float *feat, *noisy, *filt;
  size_t capacity; /* padded-tile pixels the buffers hold */
} kpcn_pipeline_cache;

/* Frees what the cache holds and zeroes it (safe on a zeroed cache). */
void kpcn_pipeline_cache_release(kpcn_pipeline_cache *c);

/* Fails naming the first buffer or variance the KPCN needs that `aov` lacks. */
kpcn_status kpcn_pipeline_require(const kpcn_aov_set *aov);

/* Where kpcn_pipeline_run also writes one branch's predicted kernels (kpcn_denoiser_kernels_aov):
 * weights [K²][H][W], the softmax weights of every pixel, and noisy_pre [3][H][W] (may be
 * NULL), the preprocessed colour they filter. The other branch is then not run at all. */
typedef struct kpcn_kernel_sink {
  int branch;
  float *weights;
  float *noisy_pre;
} kpcn_kernel_sink;

/* Runs the two-branch KPCN on `aov` into out (planar RGB [3][H][W]) with o's tile, bf16,
 * nthreads and direct_conv; the network sees the colour buffers times color_scale (> 0,
 * kpcn_features_norm) and the result is divided by it. Accumulates timings into *st.
 * cache: kept between calls, or NULL for a run that frees everything it allocates.
 * sink: NULL, or where one branch's kernels go (out then holds that branch's part only). */
kpcn_status kpcn_pipeline_run(kpcn_model *model, const kpcn_aov_set *aov,
                              const kpcn_denoiser_options *o, float color_scale,
                              kpcn_progress *prog, float *out, kpcn_denoise_stats *st,
                              kpcn_pipeline_cache *cache, const kpcn_kernel_sink *sink);

#endif
