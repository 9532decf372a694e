/* Internal helpers shared by libkpcn modules (not installed). */
#ifndef KPCN_CORE_INTERNAL_H
#define KPCN_CORE_INTERNAL_H

#include "kpcn/common.h"
#include <stdarg.h>
#include <stdint.h>
#include <string.h>

/* Records an error for the calling thread and returns s, so call sites read
 *   return kpcn_fail(KPCN_ERR_IO, "cannot open '%s': %s", path, strerror(errno)); */
kpcn_status kpcn_fail(kpcn_status s, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
/* Prepends context to the current error message ("reading 'x.exr': ...") and returns the
 * current status. */
kpcn_status kpcn_fail_context(const char *fmt, ...) __attribute__((format(printf, 1, 2)));

/* Logs through an optional callback (no-op when fn is NULL). */
void kpcn_log(kpcn_log_fn fn, void *user, kpcn_log_level level, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));

/* Checked allocation: returns NULL and sets KPCN_ERR_OUT_OF_MEMORY naming `what`. */
void *kpcn_alloc(size_t bytes, const char *what);
void *kpcn_calloc(size_t count, size_t size, const char *what);
/* 64-byte aligned allocation (free with kpcn_aligned_free). */
void *kpcn_aligned_alloc(size_t bytes, const char *what);
void kpcn_aligned_free(void *p);

/* Validates an image size: positive, <= KPCN_MAX_DIM each, <= KPCN_MAX_PIXELS total. */
kpcn_status kpcn_check_size(int width, int height, const char *what);

/* Writes `path` atomically (core/files.c): callers write to the temp name from kpcn_temp_path
 * (unique per call; an error if it does not fit outsz, or if path is a directory or another
 * non-regular file), then kpcn_commit_file renames it over path, or over a symbolic link's
 * target (kpcn_abort_file removes it). */
kpcn_status kpcn_temp_path(char *out, size_t outsz, const char *path);
kpcn_status kpcn_commit_file(const char *tmp, const char *path);
/* file resolved against dir (absolute files and an empty dir as they are) into out; 0 when
 * it does not fit, since a truncated path could name another file */
int kpcn_path_join(char *out, size_t n, const char *dir, const char *file);
void kpcn_abort_file(const char *tmp);
/* The reason a write failed, for its message: the text of `err` (the errno the caller saved
 * right after the failing call, before kpcn_abort_file or fclose can change it), or "short
 * write" where the C library set none. Not a guess such as "disk full?": a file-size limit
 * or a removed folder fail the same calls. */
const char *kpcn_write_reason(int err);

/* Denormal floats take a slow microcode path in the SIMD units (many times the cost of a
 * normal FMA); trained weights and their gradients drift into that range, which made
 * training 2.5x slower before this existed. kpcn_fast_fp_begin sets flush-to-zero and
 * denormals-are-zero on the calling thread and on an OpenMP team of nthreads (0 = all; the
 * pool that oneDNN and libkpcn's loops then reuse) and returns the caller's MXCSR;
 * kpcn_fast_fp_end restores the previous modes everywhere. Calls may nest. */
unsigned kpcn_fast_fp_begin(int nthreads);
void kpcn_fast_fp_end(unsigned saved, int nthreads);

/* Whether libkpcn's own AVX-512 kernels may run: the CPU has AVX-512F and the oneDNN ISA cap
 * ($ONEDNN_MAX_CPU_ISA, or the older $DNNL_MAX_CPU_ISA) does not name a level below it
 * (SSE41, AVX, AVX2, AVX2_VNNI...). One variable then makes both oneDNN and kpcn run as on
 * an AVX2 machine, which is how the tests cover the fallback paths on an AVX-512 host. */
int kpcn_cpu_allows_avx512(void);

/* Whether oneDNN may run bf16 convolutions on AMX tiles (Sapphire Rapids and later): the CPU
 * has AMX-TILE and AMX-BF16, AVX-512 is allowed, and the cap is absent, ALL or names an AMX
 * level. Benchmarks use it: the vdpbf16ps probe does not bound AMX throughput. */
int kpcn_cpu_allows_amx(void);

/* Median of v[0..n) (sorts v; the mean of the two middle values for even n; 0 for n = 0). */
double kpcn_median_inplace(double *v, size_t n);

/* The float a bfloat16 stands for (its 16 bits are the float's upper half). */
static inline float kpcn_bf16_to_float(uint16_t v) {
  const uint32_t u = (uint32_t)v << 16;
  float f;
  memcpy(&f, &u, sizeof f);
  return f;
}

#define KPCN_TRY(expr)                                                                             \
  do {                                                                                             \
    kpcn_status _s = (expr);                                                                       \
    if (_s != KPCN_OK) return _s;                                                                  \
  } while (0)

#endif
