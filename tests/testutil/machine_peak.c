/* FMA-peak probes (machine_peak.h). Each thread runs 12 independent accumulator chains, more
 * than FMA latency x issue width on current x86 (4 cycles x 2 units), so the loop is bound
 * by throughput alone; the result is summed and returned so nothing is optimised away. */
#include "machine_peak.h"
#include "core/internal.h"

#include <immintrin.h>
#include <omp.h>
#include <stdio.h>
#include <time.h>

enum { CHAINS = 12 };

static double now_s(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

/* One probe kernel per instruction: CHAINS accumulators a[i] = OP(a[i], b, c) for `iters`
 * rounds, then their sum (so the loop is not optimised away). */
#define PROBE_KERNEL(NAME, TARGET, VEC, ARG, SET_ACC, SET_B, SET_C, OP, ADD, SUM)                  \
  __attribute__((target(TARGET))) static float NAME(long iters) {                                  \
    VEC a[CHAINS];                                                                                 \
    ARG b = SET_B, c = SET_C;                                                                      \
    for (int i = 0; i < CHAINS; i++)                                                               \
      a[i] = SET_ACC((float)i);                                                                    \
    for (long k = 0; k < iters; k++) {                                                             \
      _Pragma("GCC unroll 12") for (int i = 0; i < CHAINS; i++) a[i] = OP(a[i], b, c);             \
    }                                                                                              \
    VEC s = a[0];                                                                                  \
    for (int i = 1; i < CHAINS; i++)                                                               \
      s = ADD(s, a[i]);                                                                            \
    return SUM(s);                                                                                 \
  }

__attribute__((target("avx2"))) static float sum256(__m256 s) {
  float v[8];
  _mm256_storeu_ps(v, s);
  return v[0] + v[1] + v[2] + v[3] + v[4] + v[5] + v[6] + v[7];
}

PROBE_KERNEL(fma512, "avx512f", __m512, __m512, _mm512_set1_ps, _mm512_set1_ps(0.999f),
             _mm512_set1_ps(1e-6f), _mm512_fmadd_ps, _mm512_add_ps, _mm512_reduce_add_ps)
PROBE_KERNEL(fma256, "avx2,fma", __m256, __m256, _mm256_set1_ps, _mm256_set1_ps(0.999f),
             _mm256_set1_ps(1e-6f), _mm256_fmadd_ps, _mm256_add_ps, sum256)
/* vdpbf16ps: 32 bf16 products summed pairwise into 16 fp32 lanes, i.e. 64 FLOP */
PROBE_KERNEL(dpbf16, "avx512f,avx512bf16", __m512, __m512bh, _mm512_set1_ps,
             (__m512bh)_mm512_set1_epi16(0x3f80), (__m512bh)_mm512_set1_epi16(0x3a80),
             _mm512_dpbf16_ps, _mm512_add_ps, _mm512_reduce_add_ps)

/* kind 0: fp32 512-bit, 1: fp32 256-bit, 2: bf16. Returns GFLOP/s, best of three tries. */
static double probe(int kind, int nthreads) {
  const double flop_per_iter = CHAINS * (kind == 0 ? 32.0 : kind == 1 ? 16.0 : 64.0);
  /* CHAINS independent FMAs per iteration at 2 per cycle: 6 cycles, so ~0.1 s per try at
   * ~3.5 GHz (3e6 was ~5 ms, too short for the untimed first try to lift a core out of a
   * slow start) */
  const long iters = 60000000;
  static int warmed[3];       /* kind's untimed first try done (probes run on one thread) */
  double best = 0.0;
  volatile float sink = 0.0f;
  for (int r = warmed[kind] ? 0 : -1; r < 3; r++) {
    float acc = 0.0f;
    double t0 = now_s();
#pragma omp parallel num_threads(nthreads) reduction(+ : acc)
    acc += kind == 0 ? fma512(iters) : kind == 1 ? fma256(iters) : dpbf16(iters);
    double dt = now_s() - t0;
    sink += acc;
    double g = (double)nthreads * (double)iters * flop_per_iter / dt * 1e-9;
    if (r >= 0 && g > best) best = g;
  }
  warmed[kind] = 1;
  (void)sink;
  return best;
}

kt_machine_peak kt_measure_peak(int nthreads) {
  kt_machine_peak p = {0.0, 0.0, "avx2", kpcn_cpu_allows_amx()};
  if (nthreads < 1) nthreads = omp_get_max_threads();
  __builtin_cpu_init();
  /* under ONEDNN_MAX_CPU_ISA=AVX2 (kpcn_cpu_allows_avx512) the code runs as on an AVX2 CPU,
   * so its share is of the AVX2 peak */
  const int avx512 = __builtin_cpu_supports("avx512f") && kpcn_cpu_allows_avx512();
  if (avx512) {
    p.isa = "avx512";
    p.fp32 = probe(0, nthreads);
  } else {
    p.fp32 = probe(1, nthreads);
  }
  if (avx512 && __builtin_cpu_supports("avx512bf16")) p.bf16 = probe(2, nthreads);
  return p;
}

void kt_print_vs_peak(const kt_machine_peak *p, int bf16, const char *what, double gflops,
                      double target) {
  double peak = bf16 ? p->bf16 : p->fp32, ref = bf16 ? KT_REF_PEAK_BF16 : KT_REF_PEAK_FP32;
  if (bf16 && p->amx) { /* a share of the vdpbf16ps peak would read 300 % and more there */
    printf("  %s %.1f GFLOP/s: bf16 on AMX tiles, whose peak is not probed (vdpbf16ps: %.0f "
           "GFLOP/s), so no share; target %.0f GFLOP/s on the targets' machine (no AMX), "
           "compared as is: %s\n",
           what, gflops, p->bf16, target, gflops >= target ? "met" : "NOT met");
    return;
  }
  if (!(peak > 0.0)) {
    printf("  %s vs peak: this CPU has no %s FMA probe\n", what, bf16 ? "bf16" : "fp32");
    return;
  }
  double share = gflops / peak;
  printf("  %s %.1f GFLOP/s = %.1f%% of this machine's %s peak (%.0f GFLOP/s, %s, measured just "
         "before) -> %.0f on the targets' machine (peak %.0f); target %.0f = %.1f%% of it: %s\n",
         what, gflops, 100.0 * share, bf16 ? "bf16" : "fp32 FMA", peak, p->isa, share * ref, ref,
         target, 100.0 * target / ref, share * ref >= target ? "met at this share" : "NOT met");
}

/* Here, not in testutil.c: it reads libkpcn's internal CPU switch, so only tests linking
 * kpcn_internal may pull it (testutil.c serves the PUBLIC_API tests too). */
int kt_have_bf16(const char *what) {
  if (kpcn_cpu_allows_avx512()) return 1;
  printf("%s: bf16 skipped (no AVX-512 here)\n", what);
  return 0;
}
