/* Minimal test harness shared by all C unit tests: CHECK macros that count
 * failures and a summary line ctest can read. Deliberately tiny. */
#ifndef KPCN_TESTUTIL_H
#define KPCN_TESTUTIL_H
#include <math.h>
#include <stdint.h>
#include <stdio.h>

extern int kt_failures;
extern int kt_checks;

#define CHECK(cond)                                                                                \
  do {                                                                                             \
    kt_checks++;                                                                                   \
    if (!(cond)) {                                                                                 \
      kt_failures++;                                                                               \
      fprintf(stderr, "%s:%d: CHECK failed: %s\n", __FILE__, __LINE__, #cond);                     \
    }                                                                                              \
  } while (0)

#define CHECK_NEAR(a, b, tol)                                                                      \
  do {                                                                                             \
    double _a = (double)(a), _b = (double)(b), _t = (double)(tol);                                 \
    kt_checks++;                                                                                   \
    if (!(fabs(_a - _b) <= _t)) {                                                                  \
      kt_failures++;                                                                               \
      fprintf(stderr, "%s:%d: CHECK_NEAR failed: %s=%.9g vs %s=%.9g (tol %.3g)\n", __FILE__,       \
              __LINE__, #a, _a, #b, _b, _t);                                                       \
    }                                                                                              \
  } while (0)

/* Relative+absolute closeness: |a-b| <= atol + rtol*|b|. */
#define CHECK_CLOSE(a, b, rtol, atol) CHECK_NEAR(a, b, (atol) + (rtol)*fabs((double)(b)))

/* Prints "N passed, N failed" and returns the process exit code. */
/* The larger of a running worst error w and a new error e, keeping NaN: fmax(w, NaN) is w,
 * and `err > worst` is false for NaN, so a NaN result (an unwritten gradient, a NaN kernel)
 * would pass a `worst < tol` check. Use as w = kt_worst(w, e); then CHECK(w < tol). */
static inline double kt_worst(double w, double e) {
  if (isnan(w)) return w;
  return e <= w ? w : e;
}
int kt_summary(const char *suite);
/* Whether bf16 nets can run here: oneDNN 2.6 has bf16 convolutions on AVX-512 CPUs only (and
 * not under ONEDNN_MAX_CPU_ISA=AVX2, which the *_avx2 tests set); elsewhere nets refuse bf16
 * with a message (test_denoise_kpcn checks it). Prints "<what>: bf16 skipped" when not. */
int kt_have_bf16(const char *what);

/* Path helpers: a fresh temp dir for this test process, and a file path inside it. */
const char *kt_tmpdir(void);
const char *kt_tmpfile(const char *name);

/* Reads a whole file into a malloc'd, NUL-terminated buffer (NULL on failure); its length
 * goes to *len when len is non-NULL. The caller frees it. */
char *kt_slurp(const char *path, long *len);

/* Deterministic PRNG for test data (xorshift). */
float kt_randf(unsigned *state);

/* The bfloat16 nearest to a finite float (ties to even), as its 16 bits: what oneDNN writes
 * for a bf16 destination. */
uint16_t kt_bf16_round(float f);
#endif
