/* The KPCN pipeline with randomly initialised models: against a naive reference
 * (direct conv loops, softmax, kernel apply, recombination), tiled == untiled, bf16 vs
 * fp32 bounded, the C API (model file, named strided buffers, missing buffer named,
 * cancellation), models with a foreign input list rejected, the self-ensemble. What a model
 * records (exposure, eps, grafted branches) is tested in test_denoise_model_ops.c. */
#include <limits.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "core/internal.h"
#include "denoise/denoise_internal.h" /* kpcn_tile_budget_bytes */
#include "kpcn/augment.h"
#include "kpcn/denoise.h"
#include "model_fixture.h"
#include "synth.h"
#include "testutil.h"

/* Naive reference: out[3][H][W] (double). */
static void reference(kpcn_model *m, const kpcn_aov_set *a, double *out) {
  const kpcn_arch *arch = kpcn_model_arch(m);
  int W = a->width, H = a->height, K = arch->kernel_size, R = K / 2;
  size_t P = (size_t)W * H;
  kpcn_features_norm n;
  kpcn_features_norm_compute(a, &n);
  /* the network sees the colour at the model's exposure */
  double e = 0.0;
  kpcn_aov_exposure(a, &e);
  n.color_scale = e > 0.0 && arch->exposure > 0.0f ? (float)(arch->exposure / e) : 1.0f;
  float *feat = malloc(sizeof(float) * P * KPCN_FEATURES_COUNT);
  double *act = malloc(sizeof(double) * P * 64), *nxt = malloc(sizeof(double) * P * 64);
  double *filt[2] = {malloc(sizeof(double) * 3 * P), malloc(sizeof(double) * 3 * P)};
  double *src = malloc(sizeof(double) * 3 * P);
  for (int b = 0; b < 2; b++) {
    kpcn_features_build(a, b, arch->eps, &n, feat, NULL, 1);
    for (size_t i = 0; i < P * KPCN_FEATURES_COUNT; i++)
      act[i] = feat[i];
    for (int l = 0; l < kpcn_arch_n_layers(arch); l++) {
      kpcn_layer_view v;
      kpcn_model_layer(m, (kpcn_branch)b, l, &v);
      int ks = v.size, d = v.dilation, pad = d * (ks - 1) / 2;
      for (int o = 0; o < v.out_ch; o++)
        for (int y = 0; y < H; y++)
          for (int x = 0; x < W; x++) {
            double s = v.bias[o];
            for (int c = 0; c < v.in_ch; c++)
              for (int ky = 0; ky < ks; ky++)
                for (int kx = 0; kx < ks; kx++) {
                  int yy = y + ky * d - pad, xx = x + kx * d - pad;
                  if (yy < 0 || xx < 0 || yy >= H || xx >= W) continue;
                  s += (double)v.weight[(((size_t)o * v.in_ch + c) * ks + ky) * ks + kx] *
                       act[(size_t)c * P + (size_t)yy * W + xx];
                }
            nxt[(size_t)o * P + (size_t)y * W + x] = v.relu && s < 0 ? 0 : s;
          }
      double *t = act;
      act = nxt;
      nxt = t;
    }
    /* act = logits [K²][H][W]; softmax + kernel apply with clamped reads, each pass on the
     * previous pass's result */
    for (size_t i = 0; i < 3 * P; i++)
      src[i] = feat[i];
    for (int pass = 0; pass < kpcn_arch_kpa_passes(arch); pass++) {
      if (pass > 0) memcpy(src, filt[b], sizeof(double) * 3 * P);
      const int weighted = pass == 0 && arch->source_weight;
      for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
          size_t i = (size_t)y * W + x;
          double mx = -1e300, z = 0, acc[3] = {0, 0, 0};
          for (int t = 0; t < K * K; t++)
            mx = kt_worst(mx, act[(size_t)t * P + i]);
          for (int t = 0; t < K * K; t++) {
            double w = exp(act[(size_t)t * P + i] - mx);
            int yy = y + t / K - R, xx = x + t % K - R;
            yy = yy < 0 ? 0 : yy >= H ? H - 1 : yy;
            xx = xx < 0 ? 0 : xx >= W ? W - 1 : xx;
            /* source weight of the neighbour: logit channel K² there */
            if (weighted)
              w *= 1e-3 + (1 - 1e-3) / (1 + exp(-act[(size_t)K * K * P + (size_t)yy * W + xx]));
            for (int c = 0; c < 3; c++)
              acc[c] += w * src[(size_t)c * P + (size_t)yy * W + xx];
            z += w;
          }
          for (int c = 0; c < 3; c++)
            filt[b][c * P + i] = acc[c] / z;
        }
    }
  }
  for (size_t i = 0; i < 3 * P; i++)
    out[i] = (filt[0][i] * ((double)a->buf[KPCN_BUF_ALBEDO][i] + arch->eps) + expm1(filt[1][i])) /
             n.color_scale;
  free(feat);
  free(act);
  free(nxt);
  free(filt[0]);
  free(filt[1]);
  free(src);
}

static void test_reference_and_tiling(int passes, int sw) {
  kpcn_model *m = make_model_chain(42, passes, sw);
  CHECK(m != NULL);
  if (!m) return;
  kpcn_aov_set *a = synth_aov(29, 23, 3);
  size_t P = kpcn_aov_plane_size(a);
  float *out = malloc(sizeof(float) * 3 * P), *til = malloc(sizeof(float) * 3 * P);
  double *ref = malloc(sizeof(double) * 3 * P);
  CHECK(run(m, a, 4096, 0, out) == KPCN_OK);
  reference(m, a, ref);
  double worst = 0;
  for (size_t i = 0; i < 3 * P; i++)
    worst = kt_worst(worst, fabs(out[i] - ref[i]) / (1e-3 + fabs(ref[i])));
  printf("pipeline (%d kernel passes%s) vs naive reference: max rel err %.3g\n", passes,
         sw ? ", source weights" : "", worst);
  CHECK(worst < 1e-4);
  if (!sw) {
    /* the same model with a zero source score channel added computes the same function */
    kpcn_model *m2 = NULL;
    CHECK(kpcn_model_add_source_weight(m, &m2) == KPCN_OK);
    CHECK(m2 && kpcn_model_arch(m2)->source_weight == 1);
    if (m2) {
      CHECK(run(m2, a, 4096, 0, til) == KPCN_OK);
      double e = max_rel(til, out, 3 * P);
      printf("with a zero source score added: max rel diff %.3g\n", e);
      CHECK(e < 1e-5);
      kpcn_model_destroy(m2);
    }
  }
  /* tiles of 8 (overlap 4, or 7 with two passes, < tile) and 13 (uneven edge tiles) equal the
   * untiled result */
  const int tiles[] = {8, 13};
  for (int k = 0; k < 2; k++) {
    CHECK(run(m, a, tiles[k], 0, til) == KPCN_OK);
    double e = max_rel(til, out, 3 * P);
    printf("tile %d vs untiled: max rel diff %.3g\n", tiles[k], e);
    CHECK(e < 2e-6);
  }
  free(out);
  free(til);
  free(ref);
  kpcn_aov_destroy(a);
  kpcn_model_destroy(m);
}

static void test_bf16_and_larger_tiling(void) {
  kpcn_model *m = make_model(7);
  if (!m) return;
  kpcn_aov_set *a = synth_aov(150, 110, 9);
  size_t P = kpcn_aov_plane_size(a);
  float *f32 = malloc(sizeof(float) * 3 * P), *b16 = malloc(sizeof(float) * 3 * P),
        *til = malloc(sizeof(float) * 3 * P);
  CHECK(run(m, a, 4096, 0, f32) == KPCN_OK);
  CHECK(run(m, a, 64, 0, til) == KPCN_OK);
  double e = max_rel(til, f32, 3 * P);
  printf("150x110, tile 64 vs untiled: max rel diff %.3g\n", e);
  CHECK(e < 2e-6);
  kpcn_status bs = run(m, a, 4096, 1, b16);
  if (bs == KPCN_ERR_UNSUPPORTED && !kpcn_cpu_allows_avx512()) {
    /* an AVX2 CPU (or ONEDNN_MAX_CPU_ISA=AVX2): bf16 must be refused with a clear reason */
    printf("bf16 refused on this CPU: %s\n", kpcn_last_error());
    CHECK(strstr(kpcn_last_error(), "bf16 is not available on this CPU") != NULL);
  } else {
    CHECK(bs == KPCN_OK);
    double se = 0, sr = 0, mx = max_rel(b16, f32, 3 * P);
    for (size_t i = 0; i < 3 * P; i++) {
      se += pow((double)b16[i] - f32[i], 2);
      sr += (double)f32[i] * f32[i];
    }
    double rel_rms = sqrt(se / sr);
    printf("bf16 vs fp32: rms rel %.3g, max rel %.3g\n", rel_rms, mx);
    /* bf16 has an 8-bit mantissa (rel. rounding 2^-9 = 2e-3) on weights and activations;
     * through the net and softmax the output moves by a few 1e-4 rms. The bounds are ~8x
     * the measurement; an rms relative change of 3e-3 is ~0.03 dB of PSNR. */
    CHECK(rel_rms < 3e-3); /* measured 3.6e-4 */
    CHECK(mx < 2e-2);      /* measured 2.5e-3 */
  }
  free(f32);
  free(b16);
  free(til);
  kpcn_aov_destroy(a);
  kpcn_model_destroy(m);
}

static int g_calls, g_cancel_at = 3;
static int cancel_third(void *u, double f) {
  (void)u;
  (void)f;
  return ++g_calls >= g_cancel_at;
}

static void test_api(void) {
  kpcn_model *m = make_model(5);
  if (!m) return;
  const char *path = kt_tmpfile("kpcn_test.safetensors");
  CHECK(kpcn_model_save(m, path) == KPCN_OK);
  kpcn_aov_set *a = synth_aov(40, 30, 1);
  const int W = a->width, H = a->height;
  size_t P = kpcn_aov_plane_size(a);
  float *ref = malloc(sizeof(float) * 3 * P), *out = malloc(sizeof(float) * 4 * P),
        *inter = malloc(sizeof(float) * 4 * P);
  CHECK(run(m, a, 16, 0, ref) == KPCN_OK);

  kpcn_denoiser_options o;
  kpcn_denoiser_options_defaults(&o);
  o.model_path = path;
  o.tile = 16;
  kpcn_denoiser *d = NULL;
  CHECK(kpcn_denoiser_create(&d, &o) == KPCN_OK);
  if (!d) return;
  /* diffuse interleaved with its variance (4 floats per pixel), everything else planar
   * channel by channel */
  for (size_t i = 0; i < P; i++) {
    for (int c = 0; c < 3; c++)
      inter[4 * i + c] = a->buf[KPCN_BUF_DIFFUSE][c * P + i];
    inter[4 * i + 3] = a->var[KPCN_BUF_DIFFUSE][i];
  }
  for (int b = 0; b < KPCN_BUF_COUNT; b++) {
    if (b == KPCN_BUF_DIFFUSE || b == KPCN_BUF_COLOR) continue;
    const char *bn = kpcn_buffer_name((kpcn_buffer)b);
    char vn[64];
    snprintf(vn, sizeof vn, "%s.var", bn);
    for (int c = 0; c < kpcn_buffer_channels((kpcn_buffer)b); c++)
      CHECK(kpcn_denoiser_set_buffer_channel(d, bn, c, a->buf[b] + c * P, W, H, 0, 0) == KPCN_OK);
    CHECK(kpcn_denoiser_set_buffer(d, vn, a->var[b], W, H, 0, 0) == KPCN_OK);
  }
  CHECK(kpcn_denoiser_execute(d, out, W, H, 0, 0) == KPCN_ERR_MISSING_CHANNEL);
  CHECK(strstr(kpcn_last_error(), "diffuse") != NULL);
  CHECK(kpcn_denoiser_set_buffer(d, "diffuse", inter, W, H, 4 * sizeof(float), 0) == KPCN_OK);
  CHECK(kpcn_denoiser_set_buffer(d, "diffuse.var", inter + 3, W, H, 4 * sizeof(float), 0) ==
        KPCN_OK);
  /* output with a 4-float pixel stride (RGBA-like) */
  for (size_t i = 0; i < 4 * P; i++)
    out[i] = -7.0f;
  CHECK(kpcn_denoiser_execute(d, out, W, H, 4 * sizeof(float), 0) == KPCN_OK);
  int diff = 0;
  for (size_t i = 0; i < P; i++) {
    for (int c = 0; c < 3; c++)
      diff += out[4 * i + c] != ref[c * P + i];
    diff += out[4 * i + 3] != -7.0f;
  }
  CHECK(diff == 0);
  kpcn_denoise_stats st;
  kpcn_denoiser_get_stats(d, &st);
  CHECK(st.tiles == 6); /* ceil(40/16) * ceil(30/16) */
  CHECK(st.tiles_total == 6 && st.tile_w == 16 && st.tile_h == 16);
  CHECK(st.conv_flops > 0 && st.total_s > 0);
  /* cancellation: 6 tiles, the third progress call cancels */
  g_calls = 0;
  kpcn_denoiser_set_progress(d, cancel_third, NULL);
  CHECK(kpcn_denoiser_execute(d, out, W, H, 0, 0) == KPCN_ERR_CANCELLED);
  CHECK(g_calls == 3);
  /* session 62: the final call (2 x 6 + 1 = the 13th, at 1.0) cancels too, leaving the output
   * as it was (its answer was dropped and the result returned); then the same denoiser runs
   * afresh, bit for bit */
  for (size_t i = 0; i < 3 * P; i++)
    out[i] = -3.0f;
  g_calls = 0, g_cancel_at = 13;
  CHECK(kpcn_denoiser_execute(d, out, W, H, 0, 0) == KPCN_ERR_CANCELLED && g_calls == 13);
  int kept = 1;
  for (size_t i = 0; i < 3 * P; i++)
    kept &= out[i] == -3.0f;
  CHECK(kept);
  g_calls = 0, g_cancel_at = 1000;
  CHECK(kpcn_denoiser_execute(d, out, W, H, 0, 0) == KPCN_OK && g_calls == 13);
  int same = 1; /* out interleaved RGB, ref planar */
  for (size_t i = 0; i < P; i++)
    for (int c = 0; c < 3; c++)
      same &= out[3 * i + c] == ref[c * P + i];
  CHECK(same);
  g_cancel_at = 3;
  kpcn_denoiser_destroy(d);
  /* an ensemble denoiser cancelled once runs its next execute (it stayed cancelled, its
   * callback never called again) */
  o.ensemble = 2;
  CHECK(kpcn_denoiser_create(&d, &o) == KPCN_OK);
  if (d) {
    kpcn_denoiser_set_progress(d, cancel_third, NULL);
    CHECK(kpcn_denoiser_execute_aov(d, a, out) == KPCN_ERR_CANCELLED);
    g_calls = 0, g_cancel_at = 1000;
    CHECK(kpcn_denoiser_execute_aov(d, a, out) == KPCN_OK && g_calls > 0);
    kpcn_denoise_stats es;
    kpcn_denoiser_get_stats(d, &es);
    CHECK(es.tiles == 12 && es.tiles_total == 12); /* summed over the 2 members */
    g_cancel_at = 3;
    kpcn_denoiser_destroy(d);
  }
  o.ensemble = 0;
  kpcn_denoise_stats none;
  memset(&none, 0x5A, sizeof none);
  kpcn_denoiser_get_stats(NULL, &none);
  CHECK(none.tiles == 0 && none.total_s == 0.0);

  /* tile 0: the automatic grid (a small frame fits the memory budget in one tile), and a tile
   * far beyond the image ("never tile", where W + tile must not overflow): one piece each,
   * equal to the explicitly tiled result */
  const int one_piece[2] = {0, INT_MAX};
  for (int k = 0; k < 2; k++) {
    o.tile = one_piece[k];
    CHECK(kpcn_denoiser_create(&d, &o) == KPCN_OK);
    if (!d) continue;
    kpcn_denoiser_set_progress(d, NULL, NULL);
    CHECK(kpcn_denoiser_execute_aov(d, a, out) == KPCN_OK);
    kpcn_denoiser_get_stats(d, &st);
    CHECK(st.tiles_total == 1 && st.tile_w == W && st.tile_h == H);
    CHECK(max_rel(out, ref, 3 * P) < 2e-6);
    kpcn_denoiser_destroy(d);
  }
  o.tile = 16;

  /* missing specular through the convenience call */
  free(a->buf[KPCN_BUF_SPECULAR]);
  a->buf[KPCN_BUF_SPECULAR] = NULL;
  kpcn_image *img = NULL;
  CHECK(kpcn_denoise_aov(a, &o, &img) == KPCN_ERR_MISSING_CHANNEL);
  CHECK(strstr(kpcn_last_error(), "specular") != NULL && img == NULL);

  /* a model whose arch has no feature list is rejected, naming the file */
  kpcn_arch bare;
  kpcn_arch_preset("tiny", &bare);
  const char *names[3] = {"R", "G", "B"};
  kpcn_arch_set_inputs(&bare, 3, names);
  kpcn_model *bm = NULL;
  CHECK(kpcn_model_create(&bare, 1, &bm) == KPCN_OK);
  const char *bpath = kt_tmpfile("bare.safetensors");
  CHECK(kpcn_model_save(bm, bpath) == KPCN_OK);
  o.model_path = bpath;
  CHECK(kpcn_denoiser_create(&d, &o) == KPCN_ERR_UNSUPPORTED);
  CHECK(strstr(kpcn_last_error(), "bare.safetensors") != NULL);
  o.model_path = kt_tmpfile("does-not-exist.safetensors");
  CHECK(kpcn_denoiser_create(&d, &o) == KPCN_ERR_IO);
  kpcn_model_destroy(bm);
  free(ref);
  free(out);
  free(inter);
  kpcn_aov_destroy(a);
  kpcn_model_destroy(m);
}

/* A denoiser keeps its network and tile buffers between executes: a warm execute, one
 * after another frame size, and one after the weights changed must all equal a fresh
 * denoiser's result, and a warm execute of an unchanged size builds no network. */
static void test_reuse_between_executes(void) {
  kpcn_model *m = make_model(11);
  if (!m) return;
  kpcn_aov_set *a = synth_aov(150, 110, 9), *b = synth_aov(37, 51, 4);
  const size_t Pa = kpcn_aov_plane_size(a), Pb = kpcn_aov_plane_size(b);
  float *fresh = malloc(sizeof(float) * 3 * Pa), *warm = malloc(sizeof(float) * 3 * Pa),
        *fb = malloc(sizeof(float) * 3 * Pb), *wb = malloc(sizeof(float) * 3 * Pb);
  kpcn_denoiser_options o;
  kpcn_denoiser_options_defaults(&o);
  o.tile = 64; /* 3x2 grid, padded tiles of several sizes */
  o.nthreads = 2;
  kpcn_denoiser *d = NULL;
  CHECK(kpcn_denoiser_create_with_model(&d, m, &o) == KPCN_OK);
  kpcn_denoise_stats cold, st;
  CHECK(kpcn_denoiser_execute_aov(d, a, warm) == KPCN_OK);
  kpcn_denoiser_get_stats(d, &cold);
  CHECK(run(m, a, 64, 0, fresh) == KPCN_OK);
  CHECK(max_rel(warm, fresh, 3 * Pa) == 0.0);
  CHECK(kpcn_denoiser_execute_aov(d, a, warm) == KPCN_OK);
  kpcn_denoiser_get_stats(d, &st);
  printf("150x110 tile 64: nets built cold %d, warm %d; warm == fresh: %s\n", cold.nets_created,
         st.nets_created, max_rel(warm, fresh, 3 * Pa) == 0.0 ? "yes" : "no");
  CHECK(max_rel(warm, fresh, 3 * Pa) == 0.0);
  CHECK(st.nets_created < cold.nets_created);
  CHECK(st.conv_s > 0.0 && st.conv_s <= st.net_s);
  /* another frame size in between (one tile), then the first again */
  CHECK(kpcn_denoiser_execute_aov(d, b, wb) == KPCN_OK);
  CHECK(run(m, b, 64, 0, fb) == KPCN_OK);
  CHECK(max_rel(wb, fb, 3 * Pb) == 0.0);
  CHECK(kpcn_denoiser_execute_aov(d, b, wb) == KPCN_OK);
  kpcn_denoiser_get_stats(d, &st);
  CHECK(st.nets_created == 0); /* one tile size: both branches share the cached net */
  CHECK(max_rel(wb, fb, 3 * Pb) == 0.0);
  CHECK(kpcn_denoiser_execute_aov(d, a, warm) == KPCN_OK);
  CHECK(max_rel(warm, fresh, 3 * Pa) == 0.0);
  /* weights edited in place (as a trainer does) are what the next execute uses */
  kpcn_layer_view v;
  kpcn_model_layer(m, KPCN_BRANCH_SPECULAR, 0, &v);
  v.bias[0] += 0.5f;
  CHECK(kpcn_denoiser_execute_aov(d, a, warm) == KPCN_OK);
  CHECK(run(m, a, 64, 0, fresh) == KPCN_OK);
  CHECK(max_rel(warm, fresh, 3 * Pa) == 0.0);
  kpcn_denoiser_destroy(d);
  /* 100x100 in 50x50 tiles: the even pad gives all four padded tiles one size, so a single
   * network serves both branches and every tile, and nothing is rebuilt when warm */
  kpcn_aov_set *c = synth_aov(100, 100, 6);
  const size_t Pc = kpcn_aov_plane_size(c);
  float *tc = malloc(sizeof(float) * 3 * Pc), *uc = malloc(sizeof(float) * 3 * Pc);
  o.tile = 50;
  CHECK(kpcn_denoiser_create_with_model(&d, m, &o) == KPCN_OK);
  CHECK(kpcn_denoiser_execute_aov(d, c, tc) == KPCN_OK);
  kpcn_denoiser_get_stats(d, &cold);
  CHECK(kpcn_denoiser_execute_aov(d, c, tc) == KPCN_OK);
  kpcn_denoiser_get_stats(d, &st);
  printf("100x100 tile 50: %d tiles, nets built cold %d, warm %d\n", st.tiles, cold.nets_created,
         st.nets_created);
  CHECK(st.tiles == 4 && cold.nets_created == 1 && st.nets_created == 0);
  CHECK(run(m, c, 4096, 0, uc) == KPCN_OK);
  CHECK(max_rel(tc, uc, 3 * Pc) < 2e-6);
  kpcn_denoiser_destroy(d);
  kpcn_aov_destroy(c);
  free(tc);
  free(uc);
  free(fresh);
  free(warm);
  free(fb);
  free(wb);
  kpcn_aov_destroy(a);
  kpcn_aov_destroy(b);
  kpcn_model_destroy(m);
}

/* ensemble = n (tile, progress callback fn may be NULL): out is [3][H][W]. */
static kpcn_status run_ensemble(kpcn_model *m, const kpcn_aov_set *a, int n, int tile,
                                kpcn_progress_fn fn, float *out) {
  kpcn_denoiser_options o;
  kpcn_denoiser_options_defaults(&o);
  o.tile = tile;
  o.nthreads = 2;
  o.ensemble = n;
  return run_opts(m, a, &o, fn, out);
}

/* Applies transform i of the ensemble to the RGB planes of a W x H image (out: its size). */
static void xform_rgb(const float *in, int W, int H, int i, int inverse, float *out) {
  kpcn_augment_xform x, inv;
  kpcn_denoise_ensemble_xform(i, &x);
  int tw, th;
  kpcn_augment_output_size(&x, W, H, &tw, &th);
  kpcn_augment_inverse(&inv, &x, tw, th);
  kpcn_augment_planes(out, in, 3, NULL, W, H, inverse ? &inv : &x, 1);
}

static double g_last_progress;
static int g_progress_ok;
static int watch_progress(void *u, double f) {
  (void)u;
  if (f < g_last_progress - 1e-12 || f > 1.0 + 1e-12) g_progress_ok = 0;
  g_last_progress = f;
  return 0;
}

/* Self-ensemble: the average of the members computed by hand (bit-exact), equivariance of
 * the 8-member result under the transforms (an independent property: the plain network has
 * none), progress and cancellation across members, bad sizes rejected. */
static void test_ensemble(void) {
  kpcn_model *m = make_model(23);
  if (!m) return;
  const int W = 45, H = 37; /* not square: rotated members have another shape */
  kpcn_aov_set *a = synth_aov(W, H, 3);
  const size_t N = 3 * kpcn_aov_plane_size(a);
  float *plain = malloc(sizeof(float) * N), *member = malloc(sizeof(float) * N),
        *back = malloc(sizeof(float) * N), *ens = malloc(sizeof(float) * N),
        *want = malloc(sizeof(float) * N), *ens_t = malloc(sizeof(float) * N);
  /* the transforms: 0 is the identity, 2/4/8 members form groups, each has an inverse */
  kpcn_augment_xform x;
  CHECK(kpcn_denoise_ensemble_xform(0, &x) == KPCN_OK && !x.mirror_h && !x.rot90);
  CHECK(kpcn_denoise_ensemble_xform(8, &x) != KPCN_OK);
  /* closure: x_j after x_i is some x_k with k < n, for n = 2, 4, 8 (on a 5 x 5 ramp) */
  {
    float img[25], t1[25], t2[25], tk[25];
    for (int i = 0; i < 25; i++)
      img[i] = (float)i;
    int closed = 1;
    for (int n = 2; n <= 8; n *= 2)
      for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) {
          kpcn_augment_xform xi, xj, xk;
          kpcn_denoise_ensemble_xform(i, &xi);
          kpcn_denoise_ensemble_xform(j, &xj);
          kpcn_augment_planes(t1, img, 1, NULL, 5, 5, &xi, 1);
          kpcn_augment_planes(t2, t1, 1, NULL, 5, 5, &xj, 1);
          int found = 0;
          for (int k = 0; k < n && !found; k++) {
            kpcn_denoise_ensemble_xform(k, &xk);
            kpcn_augment_planes(tk, img, 1, NULL, 5, 5, &xk, 1);
            found = memcmp(tk, t2, sizeof tk) == 0;
          }
          closed &= found;
        }
    CHECK(closed);
  }
  /* by hand: mean over members of inverse(denoise(transform(a))), in member order */
  for (int n = 2; n <= 8; n *= 2) {
    memset(want, 0, sizeof(float) * N);
    for (int i = 0; i < n; i++) {
      kpcn_augment_xform xi;
      kpcn_denoise_ensemble_xform(i, &xi);
      kpcn_aov_set *t = NULL;
      CHECK(kpcn_augment_aov(&t, a, &xi, 1) == KPCN_OK);
      CHECK(run(m, t, 0, 0, member) == KPCN_OK);
      xform_rgb(member, t->width, t->height, i, 1, back);
      for (size_t k = 0; k < N; k++)
        want[k] += back[k];
      kpcn_aov_destroy(t);
    }
    for (size_t k = 0; k < N; k++)
      want[k] *= 1.0f / (float)n;
    CHECK(run_ensemble(m, a, n, 0, NULL, ens) == KPCN_OK);
    printf("ensemble %d: max rel. difference to the members averaged by hand %.3g\n", n,
           max_rel(ens, want, N));
    CHECK(max_rel(ens, want, N) == 0.0);
  }
  /* ens ends as the 8-member result; plain output differs from it (members disagree) */
  CHECK(run(m, a, 0, 0, plain) == KPCN_OK);
  CHECK(max_rel(plain, ens, N) > 1e-4);
  /* equivariance: E(T a) = T E(a) for every transform T of the group; tiled too */
  double worst = 0;
  for (int i = 1; i < 8; i++) {
    kpcn_augment_xform xi;
    kpcn_denoise_ensemble_xform(i, &xi);
    kpcn_aov_set *t = NULL;
    CHECK(kpcn_augment_aov(&t, a, &xi, 1) == KPCN_OK);
    CHECK(run_ensemble(m, t, 8, i == 5 ? 16 : 0, NULL, ens_t) == KPCN_OK);
    xform_rgb(ens, W, H, i, 0, want);
    worst = kt_worst(worst, max_rel(ens_t, want, N));
    kpcn_aov_destroy(t);
  }
  printf("ensemble 8 equivariance: max rel. difference %.3g\n", worst);
  CHECK(worst < 1e-5);
  /* progress runs once from 0 to 1 over all members; a cancel stops the execute */
  g_last_progress = 0;
  g_progress_ok = 1;
  CHECK(run_ensemble(m, a, 4, 16, watch_progress, ens) == KPCN_OK);
  CHECK(g_progress_ok && g_last_progress > 0.99);
  g_calls = 0;
  CHECK(run_ensemble(m, a, 8, 16, cancel_third, ens) == KPCN_ERR_CANCELLED);
  /* sizes other than 0, 1, 2, 4, 8 are rejected, naming the option */
  const int bad[] = {3, 6, -1, 16};
  for (int i = 0; i < 4; i++) {
    CHECK(run_ensemble(m, a, bad[i], 0, NULL, ens) == KPCN_ERR_INVALID_ARGUMENT);
    CHECK(strstr(kpcn_last_error(), "ensemble") != NULL);
  }
  CHECK(run_ensemble(m, a, 1, 0, NULL, ens) == KPCN_OK && max_rel(ens, plain, N) == 0.0);
  free(plain);
  free(member);
  free(back);
  free(ens);
  free(want);
  free(ens_t);
  kpcn_aov_destroy(a);
  kpcn_model_destroy(m);
}

/* The automatic tile grid and its memory budget (docs/denoiser.md, "tile"; denoise.h's
 * kpcn_denoiser_options.tile): the budget is an eighth of the machine's physical memory kept
 * within [1, 3] GiB, and tile = 0 picks the grid with the least padded area whose largest
 * padded tile's buffers fit it. Truth, rebuilt here from the documentation: padded tiles are
 * the (even) core grown by the pad (the overlap plus at least one pixel, rounded up to a
 * multiple of 8) on each side, as far as the image reaches; a padded pixel costs the features
 * and colour (noisy and filtered, four planes each) in float, two hidden activations and the
 * logits (channels rounded up to 16) in float, or in bf16 for a bf16 net, which also holds a
 * bf16 copy of its input (kpcn_pipeline.c's estimate). The grid is read from the stats of an
 * execute on a 3840x2160 frame cancelled at its first progress call (before any network is
 * built: the stats already hold the grid).
 * "Fits" is taken as the grid search takes it: every tile bounded by its core plus a pad on
 * both sides and one pixel for the even origin (clipped to the image). A grid whose largest
 * padded tile fits only because its edge tiles are padded on one side (or by that pixel) is
 * passed over, so on some memory sizes the literal "least padded area whose largest padded
 * tile fits" would be up to ~2 % less padding (printed below when it is, not checked). */
static int g_progress_calls;
static int cancel_first(void *u, double f) {
  (void)u;
  (void)f;
  g_progress_calls++;
  return 1;
}

/* Sum of padded extents and the largest padded extent of cores of size t along n pixels. */
static void padded_axis(int n, int t, int pad, double *sum, int *maxext) {
  *sum = 0;
  *maxext = 0;
  for (int c0 = 0; c0 < n; c0 += t) {
    const int c1 = c0 + t < n ? c0 + t : n;
    const int p0 = c0 - pad > 0 ? (c0 - pad) & ~1 : 0, p1 = c1 + pad < n ? c1 + pad : n;
    *sum += p1 - p0;
    if (p1 - p0 > *maxext) *maxext = p1 - p0;
  }
}

static void test_tile_budget(void) {
  /* the budget: exactly clamp(pages * page size / 8, 1 GiB, 3 GiB) (the implementation's
   * sysconf), and /proc/meminfo's MemTotal agrees to within a page */
  const long pages = sysconf(_SC_PHYS_PAGES), psz = sysconf(_SC_PAGESIZE);
  CHECK(pages > 0 && psz > 0);
  const uint64_t gib = 1073741824ull, mem = (uint64_t)pages * (uint64_t)psz;
  uint64_t want = mem / 8;
  want = want < gib ? gib : want > 3 * gib ? 3 * gib : want;
  const size_t budget = kpcn_tile_budget_bytes();
  CHECK((uint64_t)budget == want);
  FILE *mi = fopen("/proc/meminfo", "r");
  if (mi) {
    unsigned long long kb = 0;
    char line[256];
    while (fgets(line, sizeof line, mi))
      if (sscanf(line, "MemTotal: %llu kB", &kb) == 1) break;
    fclose(mi);
    uint64_t m2 = (uint64_t)kb * 1024 / 8;
    m2 = m2 < gib ? gib : m2 > 3 * gib ? 3 * gib : m2;
    CHECK(kb > 0 && (m2 > budget ? m2 - budget : budget - m2) <= (uint64_t)psz);
  }
  printf("tile budget: %.3f GiB (physical memory %.2f GiB)\n", (double)budget / (double)gib,
         (double)mem / (double)gib);

  const int W = 3840, H = 2160;
  kpcn_aov_set *a = synth_aov(W, H, 3);
  float *out = malloc(sizeof(float) * 3 * (size_t)W * H);
  CHECK(a && out);
  const char *presets[2] = {"paper", "cpu"};
  for (int p = 0; a && out && p < 2; p++)
    for (int bf16 = 0; bf16 < 2; bf16++) {
      kpcn_arch arch;
      kpcn_model *m = NULL;
      CHECK(kpcn_arch_preset(presets[p], &arch) == KPCN_OK);
      CHECK(kpcn_features_set_arch(&arch) == KPCN_OK);
      CHECK(kpcn_model_create(&arch, 7, &m) == KPCN_OK);
      if (!m) continue;
      const int overlap = kpcn_denoise_tile_overlap(&arch);
      const int pad = (overlap + 1 + 7) / 8 * 8; /* >= overlap + 1, a multiple of 8 */
      const size_t es = bf16 ? 2 : 4;
      const size_t bpp = 4 * (KPCN_FEATURES_COUNT + 4 + 4) + 2 * (size_t)arch.channels * es +
                         (((size_t)kpcn_arch_logit_channels(&arch) + 15) / 16 * 16) * es +
                         (bf16 ? 2 * KPCN_FEATURES_COUNT : 0);
      kpcn_denoiser_options o;
      kpcn_denoiser_options_defaults(&o);
      o.tile = 0;
      o.bf16 = bf16;
      o.firefly = 0.0f; /* no copy of the frame's buffers: the grid does not depend on it */
      o.nthreads = 2;
      kpcn_denoiser *d = NULL;
      CHECK(kpcn_denoiser_create_with_model(&d, m, &o) == KPCN_OK);
      if (!d) {
        kpcn_model_destroy(m);
        continue;
      }
      kpcn_denoiser_set_progress(d, cancel_first, NULL);
      g_progress_calls = 0;
      CHECK(kpcn_denoiser_execute_aov(d, a, out) == KPCN_ERR_CANCELLED);
      kpcn_denoise_stats st;
      kpcn_denoiser_get_stats(d, &st);
      CHECK(g_progress_calls == 1 && st.tiles == 0 && st.nets_created == 0);
      const int tw = st.tile_w, th = st.tile_h;
      CHECK(tw > 0 && th > 0 && tw % 2 == 0 && th % 2 == 0);
      if (!(tw > 0 && th > 0)) {
        kpcn_denoiser_destroy(d);
        kpcn_model_destroy(m);
        continue;
      }
      double sx, sy;
      int mx, my;
      padded_axis(W, tw, pad, &sx, &mx);
      padded_axis(H, th, pad, &sy, &my);
      CHECK(st.tiles_total == ((W + tw - 1) / tw) * ((H + th - 1) / th));
      const double chosen = sx * sy, chosen_bytes = (double)mx * my * (double)bpp;
      /* within the budget, and not one piece (which the frame cannot be: the test is void
       * otherwise) */
      CHECK(chosen_bytes <= (double)budget);
      CHECK((double)W * H * (double)bpp > (double)budget && st.tiles_total > 1);
      /* no grid of even cores with less padded area fits the budget (bounding each tile by
       * core + 2 pad + 1, above); `literal` bounds it by its true largest padded tile */
      double best = -1, literal = -1;
      int bx = 0, by = 0;
      double *ax = malloc(sizeof(double) * (W / 2 + 1));
      int *axm = malloc(sizeof(int) * (W / 2 + 1));
      for (int t = 2; t <= W; t += 2)
        padded_axis(W, t, pad, &ax[t / 2], &axm[t / 2]);
      for (int ty = 2; ty <= H; ty += 2) {
        double syy;
        int myy;
        padded_axis(H, ty, pad, &syy, &myy);
        const double bound_y = ty + 2 * pad + 1 < H ? ty + 2 * pad + 1 : H;
        for (int t = 2; t <= W; t += 2) {
          const double area = ax[t / 2] * syy, bound_x = t + 2 * pad + 1 < W ? t + 2 * pad + 1 : W;
          if ((double)axm[t / 2] * myy * (double)bpp <= (double)budget &&
              (literal < 0 || area < literal))
            literal = area;
          if (bound_x * bound_y * (double)bpp > (double)budget) continue;
          if (best < 0 || area < best) best = area, bx = t, by = ty;
        }
      }
      free(ax);
      free(axm);
      CHECK(best > 0 && chosen <= best);
      if (literal > 0 && literal < chosen)
        printf("  (%s %s: a grid whose true largest padded tile fits has %.2f %% less padded "
               "area)\n",
               presets[p], bf16 ? "bf16" : "fp32", 100.0 * (1.0 - literal / chosen));
      if (!(chosen <= best) || !(chosen_bytes <= (double)budget))
        fprintf(stderr,
                "  %s %s: grid %dx%d tiles of %dx%d (padded area %.0f, largest padded tile %d x %d "
                "= %.0f bytes); least padded area that fits: %dx%d tiles (%.0f)\n",
                presets[p], bf16 ? "bf16" : "fp32", (W + tw - 1) / tw, (H + th - 1) / th, tw, th,
                chosen, mx, my, chosen_bytes, bx, by, best);
      printf("%s %s 3840x2160: %d tiles of %dx%d, largest padded tile %.0f MiB of %.0f, %.1f %% "
             "padding\n",
             presets[p], bf16 ? "bf16" : "fp32", st.tiles_total, tw, th, chosen_bytes / 1048576.0,
             (double)budget / 1048576.0, 100.0 * (chosen / ((double)W * H) - 1.0));
      kpcn_denoiser_destroy(d);
      kpcn_model_destroy(m);
    }
  free(out);
  kpcn_aov_destroy(a);
}

int main(void) {
  test_reference_and_tiling(1, 0);
  test_reference_and_tiling(2, 0);
  test_reference_and_tiling(1, 1);
  test_reference_and_tiling(2, 1);
  test_bf16_and_larger_tiling();
  test_reuse_between_executes();
  test_api();
  test_ensemble();
  test_tile_budget();
  return kt_summary("test_denoise_kpcn");
}
