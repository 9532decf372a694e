/* The KPCN pipeline (DESIGN.md §5): per tile and branch, build the features of the tile
 * plus its overlap from the full image, run the branch's network, softmax + kernel apply
 * on the preprocessed noisy color, invert the preprocessing and add the branches.
 *
 * Tiling: output tiles of T x T pixels, each computed on the tile grown by
 * kpcn_denoise_tile_overlap() pixels per side (clipped at the image border). Inside that
 * padded tile every core pixel sees exactly the inputs the untiled net would see (the conv
 * stack reads within its radius, the kernel within K/2, and features come from the full
 * image), so tiled == untiled up to floating-point summation order inside oneDNN.
 * Memory is bounded by the padded tile, not the image (see tile_grid for the default). */
#include "core/internal.h"
#include "denoise_internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

int kpcn_denoise_tile_overlap(const kpcn_arch *arch) {
  return arch ? kpcn_arch_receptive_radius(arch) : 0;
}

typedef struct tile_t {
  int x0, y0, x1, y1;   /* core (output) region */
  int px0, py0, pw, ph; /* padded region */
} tile_t;

/* Tiles sorted so equal padded sizes are adjacent (nets are bound to a size and only one
 * is alive at a time), largest first so the memory peak is reached at the first tile. */
static int tile_cmp(const void *a, const void *b) {
  const tile_t *s = a, *t = b;
  if (s->pw != t->pw) return s->pw > t->pw ? -1 : 1;
  if (s->ph != t->ph) return s->ph > t->ph ? -1 : 1;
  if (s->y0 != t->y0) return s->y0 < t->y0 ? -1 : 1;
  return s->x0 < t->x0 ? -1 : s->x0 > t->x0;
}

/* Bytes a padded tile pixel costs while its net runs: features, noisy and filtered colour
 * (four planes each, for source weights) in float; two hidden activations (ping-pong) and
 * the logits (their channels padded to 16: net.c's padded logits layer, or the blocked
 * Winograd output), in float, or in bf16 for a bf16 net, which also holds a bf16 copy of its
 * input. Matches peak RSS within ~10 %. */
static size_t bytes_per_pixel(const kpcn_arch *a, int bf16) {
  const size_t es = bf16 ? 2 : 4;
  const size_t act = 2 * (size_t)a->channels * es;
  const size_t logits = (((size_t)kpcn_arch_logit_channels(a) + 15) & ~(size_t)15) * es;
  const size_t in_copy = bf16 ? 2 * (size_t)KPCN_FEATURES_COUNT : 0;
  return 4 * (KPCN_FEATURES_COUNT + 8) + act + logits + in_copy;
}

/* Why an eighth of the memory, up to 3 GiB: overlap is recomputed work, so the fewer tiles
 * the faster (a 1024² frame on the Zen 4: the paper preset 190 -> 206 GFLOP/s in fp32 and
 * 395 -> 415 in bf16 as one tile; the cpu preset's fp32 230 -> 229-247), and the paper preset
 * needs 2.9 GB of buffers for that; at 3 GiB its 4K frame still peaks below the 4 GiB the
 * denoiser promises (the AOV set and output come on top). Smaller machines keep 1 GiB tiles
 * (a 4K paper frame: ~1.7 GiB). */
size_t kpcn_tile_budget_bytes(void) {
  const long pages = sysconf(_SC_PHYS_PAGES), psz = sysconf(_SC_PAGESIZE);
  size_t b = pages > 0 && psz > 0 ? (size_t)pages * (size_t)psz / 8 : 0;
  if (b < KPCN_TILE_BUDGET_MIN) b = KPCN_TILE_BUDGET_MIN;
  if (b > KPCN_TILE_BUDGET_MAX) b = KPCN_TILE_BUDGET_MAX;
  return b;
}

/* Pixels a tile is grown by on each side: at least one more than the overlap, and the padded
 * origin is then rounded down to even (so up to pad + 1 on the left/top). The Winograd logits
 * layer (net.c) computes 2x2 output blocks anchored at the tile's origin and its rounding
 * depends on each block's whole 4x4 input window; aligned blocks with correct inputs keep
 * the result independent of the tile size bit for bit. The pad is rounded up to a multiple of
 * 8: with even core edges the padded origins then need no rounding, so the first and last tile
 * of a row or column (each padded on one side only) get the same size and one network serves
 * both (the cpu preset's 1024² frame then runs two 1024x536 tiles, not a 535-row and a 536-row
 * one needing a second network); and a padded edge of core + pad stays a multiple of 8 where
 * the core is one, for which oneDNN 2.6's Winograd kernel keeps its per-tile schedule: with a
 * two-kernel-pass model the pad rounded to even gave 1024x540 tiles, and for those it switched
 * to transforming the whole tile into an 885 MB scratchpad (peak RSS 1.0 -> 1.9 GB on a 1024²
 * frame; net.c now also refuses such a Winograd primitive). */
static int tile_pad(const kpcn_arch *a) { return (kpcn_denoise_tile_overlap(a) + 8) & ~7; }

/* Padded extent [*p0, *p1) of the core [c0, c1) in an image of size n. */
static void pad_range(int c0, int c1, int n, int pad, int *p0, int *p1) {
  *p0 = c0 - pad > 0 ? (c0 - pad) & ~1 : 0;
  *p1 = c1 + pad < n ? c1 + pad : n;
}

/* The summed padded extent of the tiles of size `tile` along an axis of n pixels. */
static double padded_span(int n, int tile, int pad) {
  double sum = 0.0;
  for (int c0 = 0; c0 < n; c0 += tile) {
    int p0, p1;
    pad_range(c0, c0 + tile < n ? c0 + tile : n, n, pad, &p0, &p1);
    sum += p1 - p0;
  }
  return sum;
}

/* Automatic core sizes are even (see tile_pad). */
static int even_up(int n) { return (n + 1) & ~1; }

/* Tile grid. An explicit tile size gives square tiles of that size. Otherwise (tile = 0)
 * the grid is the one with the least padded area (overlap is recomputed work) whose
 * largest padded tile fits kpcn_tile_budget_bytes(): with a 3 GiB budget a 1024x1024 frame
 * runs as one tile with either preset and precision; with 1 GiB the cpu preset's runs as two
 * 1024x512 tiles in fp32 (4.3 % overlap) instead of four 512x512 ones (8.8 %) and as one in
 * bf16. Ties go to fewer tiles. */
static void tile_grid(const kpcn_arch *a, int bf16, int W, int H, int pad, int tile, int *tw,
                      int *th) {
  if (tile > 0) { /* a tile beyond the image is one piece (and keeps W + tile - 1 in int) */
    *tw = tile < W ? tile : W;
    *th = tile < H ? tile : H;
    return;
  }
  const double budget = (double)kpcn_tile_budget_bytes() / (double)bytes_per_pixel(a, bf16);
  double best = -1.0;
  int best_n = 0;
  *tw = *th = 64;
  for (int nx = 1; nx <= (W + 63) / 64; nx++) {
    const int Tx = even_up((W + nx - 1) / nx), pw = Tx + 2 * pad + 1 < W ? Tx + 2 * pad + 1 : W;
    for (int ny = 1; ny <= (H + 63) / 64; ny++) {
      const int Ty = even_up((H + ny - 1) / ny), ph = Ty + 2 * pad + 1 < H ? Ty + 2 * pad + 1 : H;
      const int fits = (double)pw * ph <= budget;
      if (!fits && !(Tx <= 64 && Ty <= 64)) continue;
      const double area = (double)(W + 2 * pad * (nx - 1)) * (double)(H + 2 * pad * (ny - 1));
      if (best < 0.0 || area < best || (area == best && nx * ny < best_n)) {
        best = area;
        best_n = nx * ny;
        *tw = Tx;
        *th = Ty;
      }
      if (fits) break; /* more rows only add overlap */
    }
  }
}

kpcn_status kpcn_pipeline_require(const kpcn_aov_set *aov) {
  const kpcn_buffer need[] = {KPCN_BUF_DIFFUSE, KPCN_BUF_SPECULAR, KPCN_BUF_ALBEDO,
                              KPCN_BUF_NORMAL,  KPCN_BUF_DEPTH,    KPCN_BUF_VISIBILITY};
  return kpcn_aov_require_list(aov, need, (int)(sizeof need / sizeof need[0]), 1,
                               "KPCN denoiser input");
}

static double net_conv_s(const kpcn_net *net) {
  kpcn_net_stats ns;
  kpcn_net_get_stats(net, &ns);
  return ns.fwd_conv_s;
}

/* Counts the cached net's convolution time since it was last counted. */
static void take_conv_time(kpcn_pipeline_cache *c, kpcn_denoise_stats *st) {
  if (!c->net) return;
  const double t = net_conv_s(c->net);
  st->conv_s += t - c->conv_base;
  c->conv_base = t;
}

void kpcn_pipeline_cache_release(kpcn_pipeline_cache *c) {
  if (!c) return;
  kpcn_net_destroy(c->net);
  kpcn_aligned_free(c->feat);
  kpcn_aligned_free(c->noisy);
  kpcn_aligned_free(c->filt);
  memset(c, 0, sizeof *c);
}

/* Tile buffers for padded tiles of up to mp pixels, kept if big enough. */
static kpcn_status cache_buffers(kpcn_pipeline_cache *c, size_t mp) {
  if (c->feat && c->capacity >= mp) return KPCN_OK;
  kpcn_aligned_free(c->feat);
  kpcn_aligned_free(c->noisy);
  kpcn_aligned_free(c->filt);
  c->capacity = 0;
  /* feature planes at a padded stride: 36 planes of exactly 2^k floats (a 1024x1024 tile)
   * would all map to the same cache sets, which made feature building 3x and the net's input
   * reorder 2x slower (bench_denoise --size 1024x1024 --tile 1024) */
  c->feat = kpcn_aligned_alloc(sizeof(float) * kpcn_plane_stride(mp) * KPCN_FEATURES_COUNT,
                               "denoiser features");
  /* 4 planes: a source-weighted first pass filters w·RGB and w (kpcn_kpa_forward_weighted) */
  c->noisy = kpcn_aligned_alloc(sizeof(float) * mp * 4, "denoiser noisy tile");
  c->filt = kpcn_aligned_alloc(sizeof(float) * mp * 4, "denoiser filtered tile");
  if (!c->feat || !c->noisy || !c->filt) return KPCN_ERR_OUT_OF_MEMORY;
  c->capacity = mp;
  return KPCN_OK;
}

/* The cached net, bound to branch b and a pw x ph tile: rebound when only the branch
 * differs, recreated when the size or the options do. */
static kpcn_status cache_net(kpcn_pipeline_cache *c, kpcn_model *model, kpcn_branch b, int pw,
                             int ph, const kpcn_denoiser_options *o, kpcn_denoise_stats *st) {
  if (c->net && c->net_w == pw && c->net_h == ph && c->bf16 == o->bf16 &&
      c->direct_conv == o->direct_conv && c->nthreads == o->nthreads)
    return kpcn_net_set_branch(c->net, b);
  take_conv_time(c, st);
  kpcn_net_destroy(c->net);
  c->net = NULL;
  kpcn_net_options no;
  kpcn_net_options_defaults(&no);
  no.batch = 1;
  no.width = pw;
  no.height = ph;
  no.precision = o->bf16 ? KPCN_PREC_BF16 : KPCN_PREC_F32;
  no.nthreads = o->nthreads;
  no.direct_conv = o->direct_conv;
  no.input_plane_stride = kpcn_plane_stride((size_t)pw * ph);
  kpcn_status s = kpcn_net_create(model, b, &no, &c->net);
  if (s != KPCN_OK)
    return kpcn_fail_context("KPCN denoiser: creating the %dx%d %s network", pw, ph,
                             kpcn_branch_name(b));
  c->net_w = pw;
  c->net_h = ph;
  c->bf16 = o->bf16;
  c->direct_conv = o->direct_conv;
  c->nthreads = o->nthreads;
  c->conv_base = net_conv_s(c->net);
  st->nets_created++;
  return KPCN_OK;
}

/* Copies a tile's core from its padded planes (weights [K²][ph][pw], the preprocessed colour
 * [3][ph][pw]) into the sink's full-image planes. */
static void sink_tile(const kpcn_kernel_sink *sink, int K, int W, int H, const tile_t *t,
                      const float *weights, const float *noisy) {
  const size_t P = (size_t)W * H, Q = (size_t)t->pw * t->ph;
  const int cw = t->x1 - t->x0;
  for (int y = t->y0; y < t->y1; y++) {
    const size_t src = (size_t)(y - t->py0) * t->pw + (size_t)(t->x0 - t->px0);
    const size_t dst = (size_t)y * W + (size_t)t->x0;
    for (int k = 0; k < K * K; k++)
      memcpy(sink->weights + (size_t)k * P + dst, weights + (size_t)k * Q + src,
             sizeof(float) * (size_t)cw);
    if (sink->noisy_pre)
      for (int c = 0; c < 3; c++)
        memcpy(sink->noisy_pre + (size_t)c * P + dst, noisy + (size_t)c * Q + src,
               sizeof(float) * (size_t)cw);
  }
}

kpcn_status kpcn_pipeline_run(kpcn_model *model, const kpcn_aov_set *aov,
                              const kpcn_denoiser_options *o, float color_scale,
                              kpcn_progress *prog, float *out, kpcn_denoise_stats *st,
                              kpcn_pipeline_cache *cache, const kpcn_kernel_sink *sink) {
  const int tile = o->tile, nthreads = o->nthreads;
  const kpcn_arch *arch = kpcn_model_arch(model);
  KPCN_TRY(kpcn_features_check_arch(arch));
  KPCN_TRY(kpcn_pipeline_require(aov));
  const int W = aov->width, H = aov->height, K = arch->kernel_size;
  const int passes = kpcn_arch_kpa_passes(arch);
  const int pad = tile_pad(arch);
  const float eps = arch->eps;
  const size_t P = kpcn_aov_plane_size(aov);
  /* Each tile is padded by `pad` on every side (as far as the image reaches), so a tile far
   * below it multiplies the work (tile 1 of the shipped model: hundreds of times, which looks
   * like a hang). Refused when the padded tiles would hold more than 25 times the image. */
  if (tile > 0) {
    const double cost = padded_span(W, tile, pad) * padded_span(H, tile, pad) / ((double)W * H);
    if (cost > 25.0)
      return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                       "denoise: tile %d would split this %dx%d image into tiles whose padded "
                       "areas (the model needs %d pixels of context per side) add up to %.0f "
                       "times the image, more than 25 times the untiled work: use 0 "
                       "(automatic), a larger tile, or one of at least the image's size",
                       tile, W, H, pad, cost);
  }
  int TW, TH;
  tile_grid(arch, o->bf16, W, H, pad, tile, &TW, &TH);
  kpcn_features_norm norm;
  KPCN_TRY(kpcn_features_norm_compute(aov, &norm));
  norm.color_scale = color_scale;
  const float inv_scale = 1.0f / color_scale; /* 1 exactly when the exposure is untouched */

  const int nx = (W + TW - 1) / TW, ny = (H + TH - 1) / TH, nt = nx * ny;
  st->tiles_total += nt; /* summed over an ensemble's members, as tiles is */
  st->tile_w = TW;
  st->tile_h = TH;
  tile_t *tiles = kpcn_alloc(sizeof(tile_t) * (size_t)nt, "denoiser tile list");
  if (!tiles) return KPCN_ERR_OUT_OF_MEMORY;
  int maxp = 0;
  for (int j = 0; j < ny; j++)
    for (int i = 0; i < nx; i++) {
      tile_t *t = &tiles[j * nx + i];
      t->x0 = i * TW;
      t->y0 = j * TH;
      t->x1 = t->x0 + TW < W ? t->x0 + TW : W;
      t->y1 = t->y0 + TH < H ? t->y0 + TH : H;
      int px1, py1;
      pad_range(t->x0, t->x1, W, pad, &t->px0, &px1);
      pad_range(t->y0, t->y1, H, pad, &t->py0, &py1);
      t->pw = px1 - t->px0;
      t->ph = py1 - t->py0;
      if (t->pw * t->ph > maxp) maxp = t->pw * t->ph;
    }
  qsort(tiles, (size_t)nt, sizeof(tile_t), tile_cmp);

  kpcn_pipeline_cache local = {0};
  kpcn_pipeline_cache *pc = cache ? cache : &local;
  float *tile_weights = NULL; /* a sink's: one tile's K² weight planes */
  kpcn_status s = cache_buffers(pc, (size_t)maxp);
  if (s != KPCN_OK) goto done;
  float *feat = pc->feat, *noisy = pc->noisy, *filt = pc->filt;
  if (sink) {
    tile_weights = kpcn_alloc(sizeof(float) * (size_t)K * K * (size_t)maxp, "kernel weights");
    if (!tile_weights) {
      s = KPCN_ERR_OUT_OF_MEMORY;
      goto done;
    }
  }
  const int nthr = kpcn_resolve_threads(nthreads);
  const float *alb = aov->buf[KPCN_BUF_ALBEDO];
  /* Branch-major order: only one network (activations of one padded tile) is alive at a
   * time, rebound from branch to branch; the diffuse pass stores its remodulated result in
   * `out`, the specular pass adds exp(s) - 1. This keeps a 4K frame with the paper preset
   * under 4 GiB. */
  for (int b = 0; b < 2; b++) {
    if (sink && b != sink->branch) continue;
    for (int i = 0; i < nt; i++) {
      /* the specular pass walks the tiles backwards, so it starts with the size the diffuse
       * pass ended with and ends with the size the next execute starts with: with the cache,
       * one net serves every tile of one size in both passes */
      const int ti = b == 0 ? i : nt - 1 - i;
      const tile_t *t = &tiles[ti];
      if (kpcn_progress_report(prog, (double)(b * nt + i) / (2.0 * nt))) {
        s = kpcn_fail(KPCN_ERR_CANCELLED, "KPCN denoiser: cancelled by the progress callback");
        goto done;
      }
      double tn = now_s();
      s = cache_net(pc, model, (kpcn_branch)b, t->pw, t->ph, o, st);
      if (s != KPCN_OK) goto done;
      kpcn_net *net = pc->net;
      st->other_s += now_s() - tn;
      const size_t Q = (size_t)t->pw * t->ph;
      double ta = now_s();
      /* Where the net reads pixel-major input, the features are built straight into its
       * input buffer (no planar f32 planes written and then reordered by the net: the cpu
       * preset's 1024² bf16 frame ~3 % faster); elsewhere planar. Same bits either way. */
      int ips = 0, ibf = 0;
      void *xin = kpcn_net_input_buffer(net, &ips, &ibf);
      if (xin && !kpcn_features_pixels_fast(ibf)) xin = NULL;
      if (xin)
        s = kpcn_features_build_region_pixels(aov, b, eps, &norm, t->px0, t->py0, t->pw, t->ph, xin,
                                              ips, ibf, noisy, nthreads);
      else
        s = kpcn_features_build_region(aov, b, eps, &norm, t->px0, t->py0, t->pw, t->ph, feat,
                                       kpcn_plane_stride(Q), noisy, nthreads);
      if (s != KPCN_OK) goto done;
      double tb = now_s();
      /* the kpa layer reads the logits where and as the net left them (no reorder) */
      const void *logits;
      kpcn_logits_layout lay;
      s = kpcn_net_forward_logits(net, xin ? NULL : feat, &logits, &lay);
      if (s != KPCN_OK) goto done;
      double tc = now_s();
      /* every pass filters the previous one's result with the same kernels; the noisy
       * colour is not needed after the first, so the passes ping-pong between the two */
      if (sink) { /* the weights materialized once more (the passes below fuse them away) */
        s = kpcn_kpa_forward_layout(K, 1, 3, t->ph, t->pw, logits, &lay, noisy, filt, tile_weights,
                                    nthreads);
        if (s != KPCN_OK) goto done;
        sink_tile(sink, K, W, H, t, tile_weights, noisy);
      }
      float *src = noisy, *res = filt;
      for (int pass = 0; pass < passes; pass++) {
        if (pass == 0 && arch->source_weight) /* in place: w·noisy over noisy, the quotient
                                                 over the filtered sums */
          s = kpcn_kpa_forward_weighted(K, 1, 3, t->ph, t->pw, logits, &lay, src, src, res, res,
                                        NULL, nthreads);
        else
          s = kpcn_kpa_forward_layout(K, 1, 3, t->ph, t->pw, logits, &lay, src, res, NULL,
                                      nthreads);
        if (s != KPCN_OK) goto done;
        float *tmp = src;
        src = res, res = tmp;
      }
      res = src;
      double td = now_s();
      st->features_s += tb - ta;
      st->net_s += tc - tb;
      st->kpa_s += td - tc;
      st->conv_flops += kpcn_arch_flops_per_pixel(arch) * (double)Q;
      /* Invert the preprocessing on the core: c = (d * (albedo + eps) + exp(s) - 1) / scale. */
#pragma omp parallel for num_threads(nthr) schedule(static)
      for (int y = t->y0; y < t->y1; y++) {
        for (int c = 0; c < 3; c++) {
          const float *f = res + c * Q + (size_t)(y - t->py0) * t->pw - t->px0;
          const size_t go = (size_t)c * P + (size_t)y * W;
          if (b == KPCN_BRANCH_DIFFUSE)
            for (int x = t->x0; x < t->x1; x++)
              out[go + x] = f[x] * (alb[go + x] + eps) * inv_scale;
          else
            for (int x = t->x0; x < t->x1; x++)
              out[go + x] += expm1f(f[x]) * inv_scale;
        }
      }
      st->other_s += now_s() - td;
      /* the branch that runs (a kernel export of the specular one counted none) */
      if (b == (sink ? sink->branch : 0)) st->tiles++;
    }
  }
  /* the final call may cancel too (its answer was dropped: the result came back) */
  if (kpcn_progress_report(prog, 1.0))
    s = kpcn_fail(KPCN_ERR_CANCELLED, "KPCN denoiser: cancelled by the progress callback");
done:
  free(tile_weights);
  take_conv_time(pc, st);
  if (!cache || s != KPCN_OK) kpcn_pipeline_cache_release(pc); /* no half-built state kept */
  free(tiles);
  return s;
}
