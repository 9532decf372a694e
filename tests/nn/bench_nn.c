/* bench_nn: throughput of the nn module (not a test; prints figures).
 *   inference: presets paper and cpu, fp32 and bf16, a W x H frame (default 1024 x 1024)
 *              processed in T x T tiles (default 512), both branches, kernel-prediction
 *              applied; ms per megapixel, conv GFLOP/s over the whole time, share of time
 *              outside convolutions, peak RSS.
 *   training:  batch 16 of 64 x 64, fp32 forward + backward of one branch, plus kpa
 *              forward/backward; iterations/s and GFLOP/s (fwd + bwd-data + bwd-weights).
 * usage: bench_nn [--size WxH] [--tile T] [--threads N] [--presets paper,cpu] [--iters N]
 *                 [--layout auto|nchw16c|nhwc] [--no-bf16] [--no-train] [--no-infer] */
#include "kpcn/nn.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <time.h>

#define N_INPUTS 36 /* the denoise module's feature count (KPCN_FEATURES_COUNT) */

static double now_s(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

static double peak_rss_mib(void) {
  struct rusage ru;
  getrusage(RUSAGE_SELF, &ru);
  return (double)ru.ru_maxrss / 1024.0;
}

static kpcn_model *make_model(const char *preset) {
  kpcn_arch a;
  if (kpcn_arch_preset(preset, &a) != KPCN_OK) return NULL;
  char nm[N_INPUTS][16];
  const char *names[N_INPUTS];
  for (int i = 0; i < N_INPUTS; i++)
    snprintf(nm[i], 16, "f%d", i), names[i] = nm[i];
  kpcn_arch_set_inputs(&a, N_INPUTS, names);
  kpcn_model *m = NULL;
  if (kpcn_model_create(&a, 1, &m) != KPCN_OK) fprintf(stderr, "%s\n", kpcn_last_error());
  return m;
}

static void fill(float *p, size_t n, unsigned s) {
  for (size_t i = 0; i < n; i++) {
    s = s * 1664525u + 1013904223u;
    p[i] = (float)(s >> 8) * (1.0f / 16777216.0f);
  }
}

static kpcn_layout g_layout = KPCN_LAYOUT_AUTO;

static int infer(const char *preset, kpcn_precision prec, int W, int H, int T, int nt) {
  kpcn_model *m = make_model(preset);
  if (!m) return 1;
  const kpcn_arch *a = kpcn_model_arch(m);
  const int K = a->kernel_size, K2 = K * K;
  int tw = T < W ? T : W, th = T < H ? T : H;
  size_t tp = (size_t)tw * th;
  float *in = malloc(tp * N_INPUTS * 4), *lg = malloc(tp * K2 * 4), *nz = malloc(tp * 3 * 4),
        *out = malloc(tp * 3 * 4);
  fill(in, tp * N_INPUTS, 1);
  fill(nz, tp * 3, 2);
  kpcn_net_options o;
  kpcn_net_options_defaults(&o);
  o.height = th, o.width = tw, o.precision = prec, o.nthreads = nt, o.layout = g_layout;
  kpcn_net *net[2] = {NULL, NULL};
  for (int b = 0; b < 2; b++) {
    kpcn_status st = kpcn_net_create(m, (kpcn_branch)b, &o, &net[b]);
    if (st == KPCN_ERR_UNSUPPORTED && prec == KPCN_PREC_BF16) { /* no AVX-512: not a failure */
      printf("infer %-5s bf16 skipped: %s\n", preset, kpcn_last_error());
      kpcn_net_destroy(net[0]);
      kpcn_model_destroy(m);
      free(in), free(lg), free(nz), free(out);
      return 0;
    }
    if (st != KPCN_OK) {
      fprintf(stderr, "net: %s\n", kpcn_last_error());
      return 1;
    }
  }
  /* warm-up tile (first-touch, JIT) of both nets and the kernel layer, not timed (net[1]'s
   * and the kernel layer's first calls were timed) */
  for (int b = 0; b < 2; b++)
    kpcn_net_forward(net[b], in, lg);
  kpcn_kpa_forward(K, 1, 3, th, tw, lg, nz, out, NULL, nt);
  kpcn_net_stats s0[2];
  kpcn_net_get_stats(net[0], &s0[0]);
  kpcn_net_get_stats(net[1], &s0[1]);
  int tiles = ((W + tw - 1) / tw) * ((H + th - 1) / th);
  double kpa_s = 0, t0 = now_s();
  for (int t = 0; t < tiles; t++)
    for (int b = 0; b < 2; b++) {
      kpcn_net_forward(net[b], in, lg);
      double k0 = now_s();
      kpcn_kpa_forward(K, 1, 3, th, tw, lg, nz, out, NULL, nt);
      kpa_s += now_s() - k0;
    }
  double total = now_s() - t0, conv = 0, fwd = 0;
  for (int b = 0; b < 2; b++) {
    kpcn_net_stats s;
    kpcn_net_get_stats(net[b], &s);
    conv += s.fwd_conv_s - s0[b].fwd_conv_s;
    fwd += s.fwd_s - s0[b].fwd_s;
  }
  double px = (double)tiles * tp, mp = px / 1e6;
  double flops = 2.0 * kpcn_arch_flops_per_pixel(a) * px;
  kpcn_net_stats s;
  kpcn_net_get_stats(net[0], &s);
  /* a Winograd logits layer does fewer multiplies than the direct-convolution FLOPs counted
   * here, so these GFLOP/s can pass the machine's peak: say so on the line */
  const char *last = kpcn_net_impl_name(net[0], kpcn_arch_n_layers(a) - 1);
  const int wino = strstr(last, "wino") != NULL;
  printf("infer %-5s %-4s %dx%d in %d tiles of %dx%d, 2 branches: %8.0f ms/MP | %6.1f GFLOP/s "
         "end-to-end, %6.1f in convs%s | outside convs %4.1f%% (reorders %4.1f%%, kpa %4.1f%%) | "
         "net %.0f MiB, peak RSS %.0f MiB | %s, %d slow prims, %d space-to-batch\n",
         preset, prec == KPCN_PREC_BF16 ? "bf16" : "fp32", W, H, tiles, tw, th, 1e3 * total / mp,
         flops / total / 1e9, flops / conv / 1e9,
         wino ? " (direct-convolution FLOPs; the logits layer is Winograd)" : "",
         100 * (total - conv) / total, 100 * (fwd - conv) / total, 100 * kpa_s / total,
         (double)s.bytes / 1048576.0, peak_rss_mib(), kpcn_net_impl_name(net[0], 1), s.n_slow,
         s.n_space_to_batch);
  fflush(stdout);
  kpcn_net_destroy(net[0]);
  kpcn_net_destroy(net[1]);
  kpcn_model_destroy(m);
  free(in), free(lg), free(nz), free(out);
  return 0;
}

static int train(const char *preset, int iters, int nt) {
  kpcn_model *m = make_model(preset);
  if (!m) return 1;
  const kpcn_arch *a = kpcn_model_arch(m);
  const int N = 16, S = 64, K = a->kernel_size, K2 = K * K;
  size_t px = (size_t)N * S * S;
  float *in = malloc(px * N_INPUTS * 4), *lg = malloc(px * K2 * 4), *nz = malloc(px * 3 * 4),
        *out = malloc(px * 3 * 4), *dout = malloc(px * 3 * 4);
  fill(in, px * N_INPUTS, 3);
  fill(nz, px * 3, 4);
  fill(dout, px * 3, 5);
  kpcn_net_options o;
  kpcn_net_options_defaults(&o);
  o.batch = N, o.height = S, o.width = S, o.training = 1, o.nthreads = nt, o.layout = g_layout;
  kpcn_net *net = NULL;
  if (kpcn_net_create(m, KPCN_BRANCH_DIFFUSE, &o, &net) != KPCN_OK) {
    fprintf(stderr, "net: %s\n", kpcn_last_error());
    return 1;
  }
  /* conv FLOPs: forward + backward-weights for every layer, backward-data except layer 0 */
  double f_fwd = kpcn_arch_flops_per_pixel(a), f0 = 2.0 * kpcn_arch_layer_in(a, 0) *
                                                    kpcn_arch_layer_out(a, 0) * a->conv_size[0] *
                                                    a->conv_size[0];
  double flops_it = (3 * f_fwd - f0) * (double)px;
  double t0 = 0, kpa = 0;
  kpcn_net_stats s0;
  for (int it = -1; it < iters; it++) { /* iteration -1 is a warm-up */
    if (it == 0) {
      t0 = now_s();
      kpcn_net_get_stats(net, &s0);
    }
    kpcn_net_forward(net, in, lg);
    double k0 = now_s();
    kpcn_kpa_forward(K, N, 3, S, S, lg, nz, out, lg, nt);
    kpcn_kpa_backward(K, N, 3, S, S, lg, nz, dout, lg, NULL, nt);
    if (it >= 0) kpa += now_s() - k0;
    kpcn_net_backward(net, lg, NULL);
  }
  double total = now_s() - t0;
  kpcn_net_stats s;
  kpcn_net_get_stats(net, &s);
  double conv = (s.fwd_conv_s - s0.fwd_conv_s) + (s.bwd_conv_s - s0.bwd_conv_s);
  printf("train %-5s fp32 batch %dx%dx%d, 1 branch: %6.2f it/s, %7.1f patches/s | %6.1f GFLOP/s "
         "end-to-end, %6.1f in convs (fwd %.0f%%, bwd %.0f%% of conv time) | kpa %4.1f%% | "
         "net %.0f MiB, peak RSS %.0f MiB, %d slow prims, %d layout switches, %d backward-data "
         "as forward, %d space-to-batch\n",
         preset, N, S, S, iters / total, N * iters / total, flops_it * iters / total / 1e9,
         flops_it * iters / conv / 1e9, 100 * (s.fwd_conv_s - s0.fwd_conv_s) / conv,
         100 * (s.bwd_conv_s - s0.bwd_conv_s) / conv, 100 * kpa / total,
         (double)s.bytes / 1048576.0, peak_rss_mib(), s.n_slow, s.n_relayout, s.n_bwdd_fwd,
         s.n_space_to_batch);
  fflush(stdout);
  kpcn_net_destroy(net);
  kpcn_model_destroy(m);
  free(in), free(lg), free(nz), free(out), free(dout);
  return 0;
}

int main(int argc, char **argv) {
  int W = 1024, H = 1024, T = 512, nt = 0, iters = 3, bf16 = 1, do_train = 1, do_infer = 1;
  char presets[128] = "cpu,paper";
  for (int i = 1; i < argc; i++) {
    if (!strcmp(argv[i], "--size") && i + 1 < argc)
      sscanf(argv[++i], "%dx%d", &W, &H);
    else if (!strcmp(argv[i], "--tile") && i + 1 < argc)
      T = atoi(argv[++i]);
    else if (!strcmp(argv[i], "--threads") && i + 1 < argc)
      nt = atoi(argv[++i]);
    else if (!strcmp(argv[i], "--iters") && i + 1 < argc)
      iters = atoi(argv[++i]);
    else if (!strcmp(argv[i], "--presets") && i + 1 < argc)
      snprintf(presets, sizeof presets, "%s", argv[++i]);
    else if (!strcmp(argv[i], "--no-bf16"))
      bf16 = 0;
    else if (!strcmp(argv[i], "--layout") && i + 1 < argc)
      g_layout = !strcmp(argv[++i], "nhwc")    ? KPCN_LAYOUT_NHWC
                 : !strcmp(argv[i], "nchw16c") ? KPCN_LAYOUT_NCHW16C
                                               : KPCN_LAYOUT_AUTO;
    else if (!strcmp(argv[i], "--no-train"))
      do_train = 0;
    else if (!strcmp(argv[i], "--no-infer"))
      do_infer = 0;
    else {
      fprintf(stderr,
              "usage: %s [--size WxH] [--tile T] [--threads N] [--presets paper,cpu] "
              "[--iters N] [--layout auto|nchw16c|nhwc] [--no-bf16] [--no-train] [--no-infer]\n",
              argv[0]);
      return 2;
    }
  }
  if (W < 1 || H < 1 || T < 1 || iters < 1) return 2;
  printf("bench_nn: %d threads (0 = all), %d inputs; timings on a shared machine vary\n", nt,
         N_INPUTS);
  int rc = 0;
  for (char *p = strtok(presets, ","); p; p = strtok(NULL, ",")) {
    kpcn_arch a;
    if (kpcn_arch_preset(p, &a) != KPCN_OK) {
      fprintf(stderr, "%s\n", kpcn_last_error());
      return 2;
    }
    a.n_inputs = N_INPUTS;
    printf("preset %s: %.3f MFLOP/pixel/branch, %zu params/branch, conv radius %d, K %d\n", p,
           kpcn_arch_flops_per_pixel(&a) / 1e6, kpcn_arch_param_count(&a),
           kpcn_arch_conv_radius(&a), a.kernel_size);
    if (do_infer) {
      rc |= infer(p, KPCN_PREC_F32, W, H, T, nt);
      if (bf16) rc |= infer(p, KPCN_PREC_BF16, W, H, T, nt);
    }
    if (do_train) rc |= train(p, iters, nt);
  }
  return rc;
}
