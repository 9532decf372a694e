/* Flush-to-zero / denormals-are-zero for the duration of a compute call. */
#include "core/internal.h"

#include <omp.h>
#include <xmmintrin.h>

/* MXCSR bits: FTZ (15) flushes denormal results to zero, DAZ (6) reads denormal inputs as
 * zero. */
#define FAST_FP_BITS 0x8040u

unsigned kpcn_fast_fp_begin(int nthreads) {
  unsigned saved = _mm_getcsr();
  int n = kpcn_resolve_threads(nthreads);
  /* every member of the team sets its own register: MXCSR is per thread, and libgomp
   * reuses these threads for the later parallel regions of the call (ours and oneDNN's) */
#pragma omp parallel num_threads(n)
  _mm_setcsr(_mm_getcsr() | FAST_FP_BITS);
  _mm_setcsr(saved | FAST_FP_BITS);
  return saved;
}

void kpcn_fast_fp_end(unsigned saved, int nthreads) {
  int n = kpcn_resolve_threads(nthreads);
  unsigned bits = saved & FAST_FP_BITS;
#pragma omp parallel num_threads(n)
  _mm_setcsr((_mm_getcsr() & ~FAST_FP_BITS) | bits);
  _mm_setcsr(saved);
}
