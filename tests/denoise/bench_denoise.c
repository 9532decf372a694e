/* bench_denoise — speed and memory of the denoisers (not a test; prints figures).
 *
 *   bench_denoise                 baselines + cpu + paper presets (fp32, bf16) at 1024x1024
 *   bench_denoise --size WxH      another frame size
 *   bench_denoise --4k            paper preset, tiled, on a 3840x2160 frame: time + peak RSS
 *                                 (run alone so the process's peak RSS is this frame's)
 *   bench_denoise --bf16-quality  PSNR of bf16 vs fp32 inference with the shipped model on a
 *                                 fresh 16-spp render of the held-out main-job scene against
 *                                 its bundled reference (also part of the default run)
 *   --threads N  --tile N  --preset NAME (only that preset)  --no-baselines
 *   --direct-conv                 fp32 without Winograd convolutions (the pre-Winograd path)
 *   --kpa-passes N                the presets' kernels applied N times (arch.kpa_passes):
 *                                 what a multi-pass model costs (the kernel layer runs N times)
 *   --source-weight               the presets with a source score (arch.source_weight): what
 *                                 a source-weighted first pass costs
 *   --ensemble N                  self-ensemble of N (2, 4, 8) members: ms/Mpx of the whole
 *                                 ensemble; GFLOP/s count the members' FLOPs
 *   --warm N                      N warm runs (default 3), each printed, then their median
 *                                 (the VM's speed drifts a few % from run to run)
 *   --max-tiles N                 stop (through the progress callback) after N tiles of the
 *                                 diffuse pass: peak memory is reached by the first full tile
 *                                 (buffers are sized once), so --4k --max-tiles 2 measures the
 *                                 4K peak RSS in a fraction of the full run's time
 *
 * Models are randomly initialised (timing does not depend on the weights). Inputs are a
 * synthetic AOV set with every buffer. ms/Mpx counts everything after the AOV set exists:
 * feature building, both networks, kernel apply, recombination. GFLOP/s: "conv" = conv
 * FLOPs executed / time inside oneDNN convolutions; "e2e" = FLOPs of the untiled frame
 * (2 branches x flops/pixel x pixels) / total time, so tile overlap counts as overhead. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>

#include "kpcn/denoise.h"
#include "kpcn/exr.h"
#include "kpcn/metrics.h"
#ifdef KPCN_HAVE_EMBREE
#include "kpcn/render.h"
#include "kpcn/scene.h"
#endif
#include "synth.h"
#include "machine_peak.h"
#include "testutil.h"

static double peak_rss_mib(void) {
  struct rusage ru;
  getrusage(RUSAGE_SELF, &ru);
  return (double)ru.ru_maxrss / 1024.0;
}

static int g_max_tiles = 0, g_calls = 0, g_direct = 0;
static int g_ensemble = 0; /* --ensemble N: kpcn_denoiser_options.ensemble */
static int g_warm = 3;     /* --warm N: warm runs after the cold one */
static int g_passes = 1;   /* --kpa-passes N: arch.kpa_passes of the presets */
static int g_sw;           /* --source-weight: arch.source_weight of the presets */
static int stop_after(void *user, double f) {
  (void)user;
  (void)f;
  return g_max_tiles > 0 && g_calls++ >= g_max_tiles;
}

static kpcn_aov_set *bench_aov(int W, int H) { return synth_aov(W, H, 12345); }

static void bench_baseline(kpcn_aov_set *a, int method, int nthreads) {
  kpcn_denoiser_options o;
  kpcn_denoiser_options_defaults(&o);
  o.method = method;
  o.nthreads = nthreads;
  kpcn_denoiser *d = NULL;
  float *out = malloc(sizeof(float) * 3 * kpcn_aov_plane_size(a));
  if (kpcn_denoiser_create(&d, &o) != KPCN_OK || kpcn_denoiser_execute_aov(d, a, out) != KPCN_OK) {
    printf("%s failed: %s\n", method == 1 ? "bilateral" : "nlmeans", kpcn_last_error());
    return;
  }
  kpcn_denoise_stats st;
  kpcn_denoiser_get_stats(d, &st);
  double mpx = (double)kpcn_aov_plane_size(a) * 1e-6;
  printf("%-22s %9.1f ms/Mpx   (%.2f s for %.2f Mpx)\n",
         method == 1 ? "bilateral r=7" : "nlmeans r=7 f=3", st.total_s * 1e3 / mpx, st.total_s,
         mpx);
  kpcn_denoiser_destroy(d);
  free(out);
}

static void bench_kpcn(kpcn_aov_set *a, const char *preset, int bf16, int tile, int nthreads) {
  kpcn_arch arch;
  kpcn_model *m = NULL;
  if (kpcn_arch_preset(preset, &arch) != KPCN_OK || kpcn_features_set_arch(&arch) != KPCN_OK ||
      (arch.kpa_passes = g_passes, arch.source_weight = g_sw, kpcn_model_create(&arch, 1, &m)) !=
          KPCN_OK) {
    printf("preset %s: %s\n", preset, kpcn_last_error());
    return;
  }
  kpcn_denoiser_options o;
  kpcn_denoiser_options_defaults(&o);
  o.bf16 = bf16;
  o.tile = tile;
  o.nthreads = nthreads;
  o.direct_conv = g_direct;
  /* fp32 inference runs a 3x3 undilated logits layer as Winograd where oneDNN has the kernel
   * (nn.md), which does fewer multiplies than the direct-convolution FLOPs counted here: the
   * share of the peak can then pass 100 %, and the printed lines say so */
  const int last = kpcn_arch_n_layers(&arch) - 1;
  const int wino = !bf16 && !g_direct && arch.conv_size[last] == 3 && arch.dilation[last] == 1;
  o.ensemble = g_ensemble;
  kpcn_denoiser *d = NULL;
  float *out = malloc(sizeof(float) * 3 * kpcn_aov_plane_size(a));
  kpcn_status es = kpcn_denoiser_create_with_model(&d, m, &o);
  if (es == KPCN_OK) {
    g_calls = 0;
    kpcn_denoiser_set_progress(d, stop_after, NULL);
    es = kpcn_denoiser_execute_aov(d, a, out);
  }
  if (es == KPCN_ERR_CANCELLED) {
    kpcn_denoise_stats st;
    kpcn_denoiser_get_stats(d, &st);
    const int nt = st.tiles_total;
    double per = st.tiles ? st.total_s / st.tiles : 0.0;
    printf("kpcn %-6s %-4s tiles %dx%d: stopped after %d of %d tiles (diffuse pass) in %.1f s, "
           "%.1f s/tile -> full frame ~%.0f s (2 branches); peak RSS %.0f MiB\n",
           preset, bf16 ? "bf16" : "fp32", st.tile_w, st.tile_h, st.tiles, nt, st.total_s, per,
           per * 2 * nt, peak_rss_mib());
  } else if (es == KPCN_ERR_UNSUPPORTED && bf16) { /* a CPU without AVX-512: not a failure */
    printf("kpcn %-6s bf16 skipped: %s\n", preset, kpcn_last_error());
  } else if (es != KPCN_OK) {
    printf("kpcn %s failed: %s\n", preset, kpcn_last_error());
  }
  if (es != KPCN_OK) {
    kpcn_denoiser_destroy(d);
    kpcn_model_destroy(m);
    free(out);
    return;
  }
  /* cold: the process's first denoise (oneDNN JITs its kernels, ~0.1 s); warm: the same
   * denoiser again (what every later frame of a sequence costs) */
  kt_machine_peak peak = {0};
  double e2e[64], share[64], msmpx[64];
  int nw = 0;
  for (int run = 0; run <= g_warm && es == KPCN_OK; run++) {
    if (run) {
      peak = kt_measure_peak(kpcn_resolve_threads(nthreads)); /* just before: the VM drifts */
      es = kpcn_denoiser_execute_aov(d, a, out);
    }
    if (es != KPCN_OK) {
      printf("kpcn %s failed: %s\n", preset, kpcn_last_error());
      break;
    }
    kpcn_denoise_stats st;
    kpcn_denoiser_get_stats(d, &st);
    double px = (double)kpcn_aov_plane_size(a), mpx = px * 1e-6;
    double useful = 2.0 * kpcn_arch_flops_per_pixel(&arch) * px * (g_ensemble > 1 ? g_ensemble : 1);
    char grid[32];
    snprintf(grid, sizeof grid, "%dx%d", st.tile_w, st.tile_h);
    printf("kpcn %-6s %-4s %-4s tile %-9s %9.1f ms/Mpx  conv %6.1f GFLOP/s  e2e %6.1f GFLOP/s  "
           "outside convs %4.1f%% (features %.1f%%, kpa %.1f%%, net non-conv %.1f%%, other "
           "%.1f%%)  tiles %d  nets built %d  peak RSS %.0f MiB\n",
           preset, bf16 ? "bf16" : "fp32", run ? "warm" : "cold", grid, st.total_s * 1e3 / mpx,
           st.conv_s > 0 ? st.conv_flops / st.conv_s * 1e-9 : 0.0, useful / st.total_s * 1e-9,
           100.0 * (1.0 - st.conv_s / st.total_s), 100.0 * st.features_s / st.total_s,
           100.0 * st.kpa_s / st.total_s, 100.0 * (st.net_s - st.conv_s) / st.total_s,
           100.0 * st.other_s / st.total_s, st.tiles, st.nets_created, peak_rss_mib());
    if (run) {
      const double g = useful / st.total_s * 1e-9, pk = bf16 ? peak.bf16 : peak.fp32;
      kt_print_vs_peak(&peak, bf16,
                       wino ? "end to end (FLOPs of direct convolution; a Winograd logits layer "
                              "does fewer)"
                            : "end to end",
                       g, bf16 ? 400.0 : 200.0);
      if (nw < 64)
        e2e[nw] = g, share[nw] = pk > 0.0 ? g / pk : 0.0, msmpx[nw++] = st.total_s * 1e3 / mpx;
    }
    fflush(stdout);
  }
  if (nw > 1) { /* the median warm run (by end-to-end speed), and the median share of the peak */
    int idx[64];
    for (int i = 0; i < nw; i++)
      idx[i] = i;
    for (int i = 1; i < nw; i++) /* insertion sort by e2e */
      for (int j = i; j > 0 && e2e[idx[j]] < e2e[idx[j - 1]]; j--) {
        const int t = idx[j];
        idx[j] = idx[j - 1], idx[j - 1] = t;
      }
    double sh[64];
    for (int i = 0; i < nw; i++)
      sh[i] = share[i];
    for (int i = 1; i < nw; i++)
      for (int j = i; j > 0 && sh[j] < sh[j - 1]; j--) {
        const double t = sh[j];
        sh[j] = sh[j - 1], sh[j - 1] = t;
      }
    const int mid = idx[nw / 2];
    const double ref = bf16 ? KT_REF_PEAK_BF16 : KT_REF_PEAK_FP32, target = bf16 ? 400.0 : 200.0;
    printf("kpcn %-6s %-4s median of %d warm runs: %.1f ms/Mpx, e2e %.1f GFLOP/s (runs %.1f .. "
           "%.1f)%s; median share of the peak %.1f%% -> %.0f on the targets' machine: target "
           "%.0f %s\n",
           preset, bf16 ? "bf16" : "fp32", nw, msmpx[mid], e2e[mid], e2e[idx[0]], e2e[idx[nw - 1]],
           wino ? " (direct-convolution FLOPs, Winograd logits)" : "", 100.0 * sh[nw / 2],
           sh[nw / 2] * ref, target, sh[nw / 2] * ref >= target ? "met" : "NOT met");
  }
  kpcn_denoiser_destroy(d);
  kpcn_model_destroy(m);
  free(out);
}

/* bf16 changes the denoised image by rounding weights and activations to 8 mantissa bits,
 * Winograd (the fp32 default) by computing 3x3 convolutions in a transformed basis; what
 * matters is the change in quality on a real render with real (trained) weights, measured
 * against fp32 direct convolution. */
static void bench_bf16_quality(int nthreads) {
#ifdef KPCN_HAVE_EMBREE
  const char *scene_path = KPCN_TESTDATA "/scenes/diffuse-interreflection/scene.json";
  const char *ref_path = KPCN_TESTDATA "/references/diffuse-interreflection_256.exr";
  const char *model_path = KPCN_TESTDATA "/models/kpcn-cpu.safetensors";
  kpcn_scene *sc = NULL;
  kpcn_aov_set *noisy = NULL, *ref = NULL;
  kpcn_model *m = NULL;
  if (kpcn_scene_load(scene_path, &sc) != KPCN_OK || kpcn_exr_read_aov(ref_path, &ref) != KPCN_OK ||
      kpcn_model_load(model_path, &m) != KPCN_OK) {
    printf("bf16 quality: skipped (%s)\n", kpcn_last_error());
    goto done;
  }
  kpcn_render_settings rs = kpcn_render_settings_defaults();
  rs.spp = 16, rs.seed = 1, rs.width = ref->width, rs.height = ref->height;
  rs.nthreads = nthreads;
  if (kpcn_render(sc, &rs, &noisy) != KPCN_OK) {
    printf("bf16 quality: render failed: %s\n", kpcn_last_error());
    goto done;
  }
  double psnr[3] = {0, 0, 0}, ms[3] = {0, 0, 0};
  size_t P = kpcn_aov_plane_size(noisy);
  float *out = malloc(sizeof(float) * 3 * P);
  for (int b = 0; b < 3 && out; b++) { /* fp32 direct, fp32 (Winograd where possible), bf16 */
    kpcn_denoiser_options o;
    kpcn_denoiser_options_defaults(&o);
    o.direct_conv = b == 0;
    o.bf16 = b == 2;
    o.nthreads = nthreads;
    kpcn_denoiser *d = NULL;
    kpcn_metric_options mo;
    kpcn_metric_options_defaults(&mo);
    kpcn_metric_result r;
    kpcn_status es = kpcn_denoiser_create_with_model(&d, m, &o);
    if (es == KPCN_OK) es = kpcn_denoiser_execute_aov(d, noisy, out);
    if (es == KPCN_OK)
      es = kpcn_metric_planar(KPCN_METRIC_PSNR, out, ref->buf[KPCN_BUF_COLOR], noisy->width,
                              noisy->height, 3, &mo, &r, NULL);
    if (es != KPCN_OK) { /* bf16 on a CPU without AVX-512 is skipped, not failed */
      printf("bf16 quality: %s%s\n", es == KPCN_ERR_UNSUPPORTED && b == 2 ? "skipped: " : "",
             kpcn_last_error());
      kpcn_denoiser_destroy(d);
      free(out);
      goto done;
    }
    kpcn_denoise_stats st;
    kpcn_denoiser_get_stats(d, &st);
    psnr[b] = r.value, ms[b] = st.total_s * 1e3;
    kpcn_denoiser_destroy(d);
  }
  free(out);
  printf("quality (shipped kpcn-cpu model, diffuse-interreflection %dx%d at 16 spp vs the "
         "bundled reference): PSNR fp32 direct %.4f dB; fp32 default (Winograd) %.4f dB, change "
         "%+.4f dB; bf16 %.4f dB, change %+.4f dB (target |change| <= 0.1); %.0f / %.0f / %.0f "
         "ms\n",
         noisy->width, noisy->height, psnr[0], psnr[1], psnr[1] - psnr[0], psnr[2],
         psnr[2] - psnr[0], ms[0], ms[1], ms[2]);
done:
  kpcn_aov_destroy(noisy);
  kpcn_aov_destroy(ref);
  kpcn_model_destroy(m);
  kpcn_scene_destroy(sc);
#else
  (void)nthreads;
  printf("bf16 quality: skipped (built without the renderer)\n");
#endif
}

int main(int argc, char **argv) {
  int W = 1024, H = 1024, nthreads = 0, tile = 0, k4 = 0, baselines = 1, quality_only = 0;
  const char *only = NULL;
  for (int i = 1; i < argc; i++) {
    if (!strcmp(argv[i], "--size") && i + 1 < argc) {
      if (sscanf(argv[++i], "%dx%d", &W, &H) != 2) return fprintf(stderr, "bad --size\n"), 2;
    } else if (!strcmp(argv[i], "--threads") && i + 1 < argc) {
      nthreads = atoi(argv[++i]);
    } else if (!strcmp(argv[i], "--tile") && i + 1 < argc) {
      tile = atoi(argv[++i]);
    } else if (!strcmp(argv[i], "--preset") && i + 1 < argc) {
      only = argv[++i];
    } else if (!strcmp(argv[i], "--max-tiles") && i + 1 < argc) {
      g_max_tiles = atoi(argv[++i]);
    } else if (!strcmp(argv[i], "--no-baselines")) {
      baselines = 0;
    } else if (!strcmp(argv[i], "--4k")) {
      k4 = 1;
    } else if (!strcmp(argv[i], "--bf16-quality")) {
      quality_only = 1;
    } else if (!strcmp(argv[i], "--direct-conv")) {
      g_direct = 1;
    } else if (!strcmp(argv[i], "--kpa-passes") && i + 1 < argc) {
      g_passes = atoi(argv[++i]);
    } else if (!strcmp(argv[i], "--source-weight")) {
      g_sw = 1;
    } else if (!strcmp(argv[i], "--ensemble") && i + 1 < argc) {
      g_ensemble = atoi(argv[++i]);
    } else if (!strcmp(argv[i], "--warm") && i + 1 < argc) {
      g_warm = atoi(argv[++i]);
      if (g_warm < 1 || g_warm > 64) return fprintf(stderr, "--warm: 1 .. 64 runs\n"), 2;
    } else {
      fprintf(stderr, "usage: bench_denoise [--size WxH] [--4k] [--threads N] [--tile N] "
                      "[--preset NAME] [--no-baselines] [--max-tiles N] [--bf16-quality] "
                      "[--direct-conv] [--ensemble N] [--kpa-passes N] [--source-weight] "
                      "[--warm N]\n");
      return 2;
    }
  }
  if (quality_only) {
    bench_bf16_quality(nthreads);
    return 0;
  }
  if (k4) {
    W = 3840;
    H = 2160;
  }
  kpcn_aov_set *a = bench_aov(W, H);
  if (!a) return fprintf(stderr, "cannot build the synthetic AOV set: %s\n", kpcn_last_error()), 1;
  printf("bench_denoise: %dx%d, %d threads, AOV set built (peak RSS so far %.0f MiB)\n", W, H,
         kpcn_resolve_threads(nthreads), peak_rss_mib());
  if (k4) {
    bench_kpcn(a, only ? only : "paper", 0, tile, nthreads);
    printf("4K frame peak RSS: %.0f MiB (target <= 4096)\n", peak_rss_mib());
    kpcn_aov_destroy(a);
    return 0;
  }
  if (baselines && !only) {
    bench_baseline(a, KPCN_DENOISE_BILATERAL, nthreads);
    bench_baseline(a, KPCN_DENOISE_NLMEANS, nthreads);
  }
  if (!only) bench_bf16_quality(nthreads);
  const char *presets[] = {"cpu", "paper"};
  for (int p = 0; p < 2; p++) {
    if (only && strcmp(only, presets[p])) continue;
    for (int b = 0; b < 2; b++)
      bench_kpcn(a, presets[p], b, tile, nthreads);
  }
  kpcn_aov_destroy(a);
  return 0;
}
