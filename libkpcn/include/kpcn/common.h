/* kpcn/common.h — status codes, error messages, logging and progress callbacks
 * shared by every libkpcn module.
 *
 * Conventions (DESIGN.md §3):
 *  - every fallible call returns kpcn_status; KPCN_OK (0) is success;
 *  - the message of the last error on the calling thread is kpcn_last_error();
 *    it names the file / channel / JSON path / argument that was wrong;
 *  - the library never prints and never calls exit(): diagnostics go through a
 *    caller-supplied kpcn_log_fn, long jobs report through kpcn_progress_fn;
 *  - thread counts are explicit: 0 means "all cores" (kpcn_resolve_threads below).
 */
#ifndef KPCN_COMMON_H
#define KPCN_COMMON_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#ifdef __cplusplus
extern "C" {
#endif

#define KPCN_VERSION_STRING "0.2.0"

typedef enum kpcn_status {
  KPCN_OK = 0,
  KPCN_ERR_INVALID_ARGUMENT = 1, /* bad parameter value (NULL, negative size, unknown name) */
  KPCN_ERR_IO = 2,               /* file cannot be opened/read/written */
  KPCN_ERR_FORMAT = 3,           /* file exists but is malformed / truncated */
  KPCN_ERR_MISSING_CHANNEL = 4,  /* a required channel / buffer is absent (message names it) */
  KPCN_ERR_SIZE_MISMATCH = 5,    /* images or tensors of incompatible sizes */
  KPCN_ERR_NONFINITE = 6,        /* NaN/Inf where finite values are required */
  KPCN_ERR_OUT_OF_MEMORY = 7,    /* allocation failed or requested size is absurd */
  KPCN_ERR_UNSUPPORTED = 8,      /* valid but unsupported feature (message names it) */
  KPCN_ERR_CANCELLED = 9,        /* a progress callback asked to stop */
  KPCN_ERR_INTERNAL = 10         /* a third-party library failed unexpectedly */
} kpcn_status;

/* Short constant name of a status code ("invalid argument", ...). */
const char *kpcn_status_string(kpcn_status s);

/* Message of the last error raised on the calling thread ("" if none). The
 * storage is thread-local and valid until the next failing call on this thread. */
const char *kpcn_last_error(void);
/* Status of the last error raised on the calling thread. */
kpcn_status kpcn_last_status(void);
/* Clears the calling thread's error. */
void kpcn_clear_error(void);

/* Log levels for kpcn_log_fn. */
typedef enum kpcn_log_level { KPCN_LOG_DEBUG, KPCN_LOG_INFO, KPCN_LOG_WARNING } kpcn_log_level;
typedef void (*kpcn_log_fn)(void *user, kpcn_log_level level, const char *message);

/* Progress callback for long jobs: fraction in [0,1]; return non-zero to cancel
 * (the job then stops at the next safe point and returns KPCN_ERR_CANCELLED). */
typedef int (*kpcn_progress_fn)(void *user, double fraction);

/* The instruction set libkpcn's kernels, oneDNN and Embree run on this CPU: "avx512", or
 * "avx2" on a CPU without AVX-512F or when $ONEDNN_MAX_CPU_ISA (or $DNNL_MAX_CPU_ISA) names a
 * level below it. Renders and networks are bit-identical for a seed and thread count only on
 * one of the two: their kernels round differently (docs/renderer.md, "Determinism"). */
const char *kpcn_cpu_isa(void);
/* One line for --version: "libkpcn 0.2.0; instruction set avx512; oneDNN 2.6.3, Embree
 * 3.13.5, OpenEXR 3.1.5" (oneDNN's and OpenEXR's as loaded, Embree's as built against). */
const char *kpcn_build_info(void);

/* Upper bound of every thread count: OpenMP cannot start many more threads than this (the
 * metrics and the feature builder crashed asked for 100000, before session 58). */
#define KPCN_MAX_THREADS 1024

/* Number of threads a call will use for the request n: n itself for 1 .. KPCN_MAX_THREADS, all
 * cores for 0 (or a negative n), and KPCN_MAX_THREADS for a larger n. Every nthreads argument
 * and option field of libkpcn goes through it; the denoiser object (kpcn_denoiser_create) and
 * the tools' --threads refuse counts outside [0, KPCN_MAX_THREADS] instead. */
int kpcn_resolve_threads(int n);

/* Files a tool reads and writes. Every writer in libkpcn (and kpcntool) writes a temporary
 * file next to its output and renames it into place, so an output that is not a regular file
 * would be replaced, not written into: a device (/dev/full), a FIFO or a socket is refused,
 * and a symbolic link is followed (its target is replaced, the link kept).
 *
 * kpcn_check_output_path refuses, before any work, an output path that cannot be written that
 * way: empty, a directory, an existing non-regular file, a dangling link, or one whose folder
 * does not exist or is not writable. `what` names it in the message ("model", "-o"). */
kpcn_status kpcn_check_output_path(const char *path, const char *what);
/* 1 if path ends in ext (".exr"; the path in any letter case). */
int kpcn_has_extension(const char *path, const char *ext);
/* KPCN_ERR_INVALID_ARGUMENT unless path ends in ext, e.g. "-o 'x.png' must end in .exr (it is
 * written as OpenEXR)": a writer of one format does not follow the name. */
kpcn_status kpcn_check_extension(const char *path, const char *ext, const char *what,
                                 const char *format);
/* 1 if a and b name the same file: by device and inode when both exist (other spellings, links
 * and hard links count), else by their folders' real paths and their names ("./x" and "x"
 * before either is written; the text as given when the folder does not exist). */
int kpcn_same_file(const char *a, const char *b);
/* KPCN_ERR_INVALID_ARGUMENT if output and input are the same file (kpcn_same_file), naming
 * both roles: writing one would destroy the other. */
kpcn_status kpcn_check_not_input(const char *output, const char *out_what, const char *input,
                                 const char *in_what);
/* fopen(path, "rb") for an input that must be a regular file: a FIFO is opened without
 * blocking and refused, as are directories and devices (which would block or read forever).
 * On failure returns NULL, keeps errno (ENOENT for a missing file) and points *why at the
 * reason ("No such file or directory", "is a directory", "is not a regular file (a FIFO,
 * device or socket)"). */
FILE *kpcn_fopen_input(const char *path, const char **why);
/* This machine's physical memory in bytes (0 if unknown). */
uint64_t kpcn_physical_memory(void);
/* Memory available to a new allocation now (Linux's MemAvailable: free memory plus what the
 * kernel can reclaim, plus free swap), at most the physical memory; the physical memory where
 * /proc/meminfo cannot be read; 0 if neither is known. Cgroup limits are not seen. Tools use
 * it to refuse a buffer that cannot fit before allocating it. */
uint64_t kpcn_available_memory(void);

/* Upper bound for any image dimension and pixel count accepted by the library;
 * larger requests are rejected as "absurd" rather than attempted. */
#define KPCN_MAX_DIM 65536
#define KPCN_MAX_PIXELS ((int64_t)1 << 28)

#ifdef __cplusplus
}
#endif
#endif
