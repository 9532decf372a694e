/* Shared by the KPCN denoiser tests: a tiny random model whose every term matters, and running
 * one denoiser on an AOV set. */
#ifndef KPCN_TEST_DENOISE_MODEL_FIXTURE_H
#define KPCN_TEST_DENOISE_MODEL_FIXTURE_H
#include <math.h>
#include <stdio.h>

#include "core/internal.h"
#include "kpcn/denoise.h"
#include "testutil.h"

/* Tiny arch with a wider receptive field than the preset so tiles really overlap; its
 * kernels applied `passes` times, the first with source weights when sw. The pipeline rounds
 * the overlap up to a multiple of 8 plus one (tile_pad); with sw the conv radius is 7, so the
 * one-pass overlap 7 + K/2 = 9 needs a pad of 16 where one without the sources' K/2 gets 8. */
static inline kpcn_model *make_model_chain(uint64_t seed, int passes, int sw) {
  kpcn_arch arch;
  if (kpcn_arch_preset("tiny", &arch) != KPCN_OK) return NULL;
  arch.dilation[1] = 2; /* conv radius 1 + 2 + 1 = 4, K = 5 */
  arch.kpa_passes = passes;
  arch.source_weight = sw;
  if (sw) arch.dilation[1] = 5;
  /* more passes: K = 7, so the tile pad the one-pass overlap max(4, 3) would give (6) is
   * short of the two-pass one, max(4 + 3, 3 + 3) = 7, and the tiling test would see it */
  if (passes > 1) arch.kernel_size = 7;
  /* a recorded exposure above the synthetic images' (~0.33): every denoise below runs with
   * the input scaled to it */
  arch.exposure = 0.75f;
  if (kpcn_features_set_arch(&arch) != KPCN_OK) return NULL;
  kpcn_model *m = NULL;
  if (kpcn_model_create(&arch, seed, &m) != KPCN_OK) return NULL;
  /* Sharpen the last layer and give biases values so the softmax is far from uniform
   * and every term of the forward pass matters. */
  for (int b = 0; b < 2; b++)
    for (int l = 0; l < kpcn_arch_n_layers(&arch); l++) {
      kpcn_layer_view v;
      kpcn_model_layer(m, (kpcn_branch)b, l, &v);
      size_t nw = (size_t)v.out_ch * v.in_ch * v.size * v.size;
      if (l == arch.n_hidden)
        for (size_t i = 0; i < nw; i++)
          v.weight[i] *= 4.0f;
      for (int o = 0; o < v.out_ch; o++)
        v.bias[o] = 0.05f * (float)((o * 7 + l + b) % 5 - 2);
    }
  return m;
}
static inline kpcn_model *make_model(uint64_t seed) { return make_model_chain(seed, 1, 0); }

/* One denoiser with options o (and progress callback fn, may be NULL) on a: out [3][H][W]. */
static inline kpcn_status run_opts(kpcn_model *m, const kpcn_aov_set *a,
                                   const kpcn_denoiser_options *o, kpcn_progress_fn fn,
                                   float *out) {
  kpcn_denoiser *d = NULL;
  kpcn_status s = kpcn_denoiser_create_with_model(&d, m, o);
  if (s == KPCN_OK && fn) kpcn_denoiser_set_progress(d, fn, NULL);
  if (s == KPCN_OK) s = kpcn_denoiser_execute_aov(d, a, out);
  kpcn_denoiser_destroy(d);
  return s;
}

static inline kpcn_status run(kpcn_model *m, const kpcn_aov_set *a, int tile, int bf16,
                              float *out) {
  kpcn_denoiser_options o;
  kpcn_denoiser_options_defaults(&o);
  o.tile = tile;
  o.bf16 = bf16;
  o.nthreads = 2;
  kpcn_status s = run_opts(m, a, &o, NULL, out);
  if (s != KPCN_OK) fprintf(stderr, "denoise: %s\n", kpcn_last_error());
  return s;
}

static inline double max_rel(const float *x, const float *y, size_t n) {
  double w = 0;
  for (size_t i = 0; i < n; i++)
    w = kt_worst(w, fabs((double)x[i] - y[i]) / (1e-3 + fabs((double)y[i])));
  return w;
}

#endif
