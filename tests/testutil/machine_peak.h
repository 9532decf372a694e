/* The machine's arithmetic peak, measured now, for benchmarks to report their GFLOP/s as a
 * share of it. The targets in the issues were set on one machine (2-core Zen 4: ~235 GFLOP/s
 * fp32, ~470 bf16; STACK_NOTES.md); hosts differ (a Zen 5 has twice the fp32 units) and a
 * shared VM's speed drifts by ±10-20 % within minutes. A share of a peak measured moments
 * before is comparable across both. */
#ifndef KPCN_MACHINE_PEAK_H
#define KPCN_MACHINE_PEAK_H

typedef struct kt_machine_peak {
  double fp32;     /* GFLOP/s of independent fused multiply-adds (2 FLOP each), all threads */
  double bf16;     /* GFLOP/s of bf16 dot-product accumulates (vdpbf16ps), 0 if none */
  const char *isa; /* "avx512" or "avx2" (the fp32 probe's width) */
  int amx;         /* oneDNN may run bf16 on AMX tiles, which the bf16 probe does not bound */
} kt_machine_peak;

/* Runs each probe with nthreads threads, ~0.1 s per try, best of three (after one untimed
 * try per process: a VM's first AVX-512 work ran at three quarters of the later rate). */
kt_machine_peak kt_measure_peak(int nthreads);

/* The targets' machine (STACK_NOTES.md "Measured limits"): fp32 and bf16 FMA peaks. */
#define KT_REF_PEAK_FP32 235.0
#define KT_REF_PEAK_BF16 470.0

/* Prints one line: `what` (GFLOP/s measured in the same minute as p) as a share of this
 * machine's peak for its precision, that share applied to the targets' machine, and whether
 * the target (GFLOP/s on the targets' machine) is reached at that share. bf16 on an AMX CPU
 * has no probed peak (p->amx): the line then compares the absolute figure with the target. */
void kt_print_vs_peak(const kt_machine_peak *p, int bf16, const char *what, double gflops,
                      double target);
#endif
