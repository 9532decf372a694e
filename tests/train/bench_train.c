/* bench_train: training speed for the cpu and paper presets at batch 16 of 64x64 patches
 * (synthetic 65x65 store): iterations/s, patches/s and achieved GFLOP/s counting the conv
 * FLOPs of forward + backward (both branches; see kpcn_trainer_flops_per_iter).
 * usage: bench_train [--threads N] [PRESET[:STAGE]:ITERS[:bf16] ...]
 *   (default cpu:1:6 cpu:2:6 cpu:2:6:bf16 paper:1:2)
 * STAGE 1 = both branches on their own targets, 2 = fine-tuning through the recombination;
 * bf16 = mixed-precision training (kpcn_train_settings.bf16), compared with the bf16 peak. */
#include "kpcn/train.h"
#include "machine_peak.h"
#include "testutil.h"
#include "train_fixture.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <time.h>
#include <unistd.h>

static double now(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* CPU seconds used by this process (all threads): with other jobs on the machine, wall-clock
 * rates understate the code's speed; FLOPs per CPU-second x threads is the idle-machine
 * estimate (it still counts spin-waiting as work, so it errs low). */
static double cpu_s(void) {
  struct rusage r;
  getrusage(RUSAGE_SELF, &r);
  return (double)r.ru_utime.tv_sec + 1e-6 * (double)r.ru_utime.tv_usec + (double)r.ru_stime.tv_sec +
         1e-6 * (double)r.ru_stime.tv_usec;
}

static void bench(const char *store, const char *preset, int iters, int threads, int stage,
                  int bf16) {
  kpcn_train_settings s;
  kpcn_train_settings_defaults(&s);
  if (kpcn_arch_preset(preset, &s.arch) != KPCN_OK) return;
  s.store_path = store;
  s.out_path = kt_tmpfile("bench.safetensors");
  s.batch = 16;
  s.patch = 64;
  s.iters = 1000000;
  s.stage1_iters = stage == 1 ? 1000000 : 0;
  s.nthreads = threads;
  s.bf16 = bf16;
  kpcn_trainer *t = NULL;
  double loss, t0 = now();
  kpcn_status st = kpcn_trainer_create(&t, &s);
  if (st == KPCN_OK) st = kpcn_trainer_step(t, &loss); /* warm-up: primitives, first touch */
  if (st != KPCN_OK) {
    if (st == KPCN_ERR_UNSUPPORTED && bf16) /* a CPU without AVX-512: not a failure */
      printf("%-6s stage %d bf16: skipped: %s\n", preset, stage, kpcn_last_error());
    else
      fprintf(stderr, "bench_train: %s\n", kpcn_last_error());
    kpcn_trainer_destroy(t);
    return;
  }
  double warm = now() - t0;
  kpcn_train_timing tw; /* the warm-up step's first touches are no part of the shares */
  kpcn_trainer_get_timing(t, &tw);
  kt_machine_peak peak = kt_measure_peak(kpcn_resolve_threads(threads)); /* the VM drifts */
  t0 = now();
  double c0 = cpu_s();
  for (int i = 0; i < iters; i++)
    if (kpcn_trainer_step(t, &loss) != KPCN_OK) {
      fprintf(stderr, "bench_train: %s\n", kpcn_last_error());
      break;
    }
  double dt = now() - t0, f = kpcn_trainer_flops_per_iter(t), dc = cpu_s() - c0;
  kpcn_train_timing tm;
  kpcn_trainer_get_timing(t, &tm);
  tm.batch_s -= tw.batch_s, tm.net_s -= tw.net_s, tm.conv_s -= tw.conv_s, tm.kpa_s -= tw.kpa_s;
  tm.loss_s -= tw.loss_s, tm.adam_s -= tw.adam_s, tm.total_s -= tw.total_s, tm.steps -= tw.steps;
  printf("%-6s stage %d %s batch 16x64x64  threads %d: %.3f it/s  %.1f patches/s  %.1f GFLOP/s "
         "(%.1f GFLOP/it; warm-up %.2f s, %d timed iterations)\n",
         preset, stage, bf16 ? "bf16" : "f32 ", kpcn_resolve_threads(threads), iters / dt,
         16 * iters / dt, f * iters / dt * 1e-9, f * 1e-9, warm, iters);
  int nt = kpcn_resolve_threads(threads);
  printf("       CPU obtained %.2f of %d cores; per CPU-second %.1f GFLOP -> %.1f GFLOP/s if the "
         "%d cores were ours\n",
         dc / dt, nt, f * iters / dc * 1e-9, f * iters / dc * nt * 1e-9, nt);
  printf("       time shares over %lld steps: convs %.0f%% (%.1f GFLOP/s inside convs), rest of "
         "net %.0f%%, batch %.0f%%, kernel layer %.0f%%, loss %.0f%%, Adam %.0f%%\n",
         (long long)tm.steps, 100 * tm.conv_s / tm.total_s, f * tm.steps / tm.conv_s * 1e-9,
         100 * (tm.net_s - tm.conv_s) / tm.total_s, 100 * tm.batch_s / tm.total_s,
         100 * tm.kpa_s / tm.total_s, 100 * tm.loss_s / tm.total_s, 100 * tm.adam_s / tm.total_s);
  kt_print_vs_peak(&peak, bf16, "training", f * iters / dt * 1e-9, 180.0);
  fflush(stdout);
  kpcn_trainer_destroy(t);
}

int main(int argc, char **argv) {
  int th = 0, first = 1;
  if (argc > 2 && !strcmp(argv[1], "--threads")) th = atoi(argv[2]), first = 3;
  static const char *defaults[] = {"cpu:1:6", "cpu:2:6", "cpu:2:6:bf16", "paper:1:2"};
  const char *const *jobs = first < argc ? (const char *const *)argv + first : defaults;
  int njobs = first < argc ? argc - first : 4;
  const char *store = kt_tmpfile("bench.kps");
  if (tf_make_store(store, 65, 160, 160, 64, 1, 0, NULL, 0) != 0) return 1;
  printf("bench_train: conv FLOPs = forward + backward-weights + backward-data (no input "
         "gradient for layer 0), both branches; other processes share this CPU.\n");
  for (int j = 0; j < njobs; j++) {
    char preset[32];
    int stage = 1, iters = 2;
    const char *c1 = strchr(jobs[j], ':');
    size_t pl = c1 ? (size_t)(c1 - jobs[j]) : strlen(jobs[j]);
    snprintf(preset, sizeof preset, "%.*s", (int)(pl < 31 ? pl : 31), jobs[j]);
    if (c1 && sscanf(c1 + 1, "%d:%d", &stage, &iters) < 2) sscanf(c1 + 1, "%d", &iters), stage = 1;
    bench(store, preset, iters, th, stage, strstr(jobs[j], ":bf16") != NULL);
  }
  unlink(store);
  return 0;
}
