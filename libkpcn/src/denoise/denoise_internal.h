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

/* Classical baselines on the color buffer of `aov` guided by its features. out: planar RGB
 * [3][H][W]. Need color + color.var, and normal/albedo/depth for each feature whose sigma
 * is > 0 (missing ones are named in the error). */
kpcn_status kpcn_baseline_bilateral(const kpcn_aov_set *aov, const kpcn_baseline_params *p,
                                    float *out, int nthreads, kpcn_progress *prog);
kpcn_status kpcn_baseline_nlmeans(const kpcn_aov_set *aov, const kpcn_baseline_params *p,
                                  float *out, int nthreads, kpcn_progress *prog);

/* Memory for one padded tile's buffers when no tile size is given (tile_grid in
 * kpcn_pipeline.c chooses the grid with the least overlap that fits it). */
#define KPCN_TILE_BUDGET_BYTES ((size_t)1 << 30)

/* Runs the two-branch KPCN on `aov` into out (planar RGB [3][H][W]) with o's tile, bf16,
 * nthreads and direct_conv; accumulates timings into *st. */
kpcn_status kpcn_pipeline_run(kpcn_model *model, const kpcn_aov_set *aov,
                              const kpcn_denoiser_options *o, kpcn_progress *prog, float *out,
                              kpcn_denoise_stats *st);

#endif
