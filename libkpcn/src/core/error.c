/* Thread-local error state, logging, checked allocation. */
#define _GNU_SOURCE
#include "core/internal.h"

#include <omp.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <unistd.h>

/* Thread-local rather than global so concurrent callers never see each other's errors. */
static _Thread_local char g_msg[2048];
static _Thread_local kpcn_status g_status = KPCN_OK;

const char *kpcn_status_string(kpcn_status s) {
  switch (s) {
  case KPCN_OK: return "ok";
  case KPCN_ERR_INVALID_ARGUMENT: return "invalid argument";
  case KPCN_ERR_IO: return "i/o error";
  case KPCN_ERR_FORMAT: return "malformed input";
  case KPCN_ERR_MISSING_CHANNEL: return "missing channel";
  case KPCN_ERR_SIZE_MISMATCH: return "size mismatch";
  case KPCN_ERR_NONFINITE: return "non-finite value";
  case KPCN_ERR_OUT_OF_MEMORY: return "out of memory";
  case KPCN_ERR_UNSUPPORTED: return "unsupported";
  case KPCN_ERR_CANCELLED: return "cancelled";
  case KPCN_ERR_INTERNAL: return "internal error";
  }
  return "unknown status";
}

const char *kpcn_last_error(void) { return g_msg; }
kpcn_status kpcn_last_status(void) { return g_status; }
void kpcn_clear_error(void) {
  g_msg[0] = 0;
  g_status = KPCN_OK;
}

kpcn_status kpcn_fail(kpcn_status s, const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(g_msg, sizeof g_msg, fmt, ap);
  va_end(ap);
  g_status = s;
  return s;
}

kpcn_status kpcn_fail_context(const char *fmt, ...) {
  char prefix[1024], old[sizeof g_msg];
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(prefix, sizeof prefix, fmt, ap);
  va_end(ap);
  memcpy(old, g_msg, sizeof old);
  /* Bounded precisions keep the result inside g_msg (and -Wformat-truncation quiet). */
  snprintf(g_msg, sizeof g_msg, "%.1000s: %.1000s", prefix, old);
  return g_status == KPCN_OK ? KPCN_ERR_INTERNAL : g_status;
}

void kpcn_log(kpcn_log_fn fn, void *user, kpcn_log_level level, const char *fmt, ...) {
  if (!fn) return;
  char buf[2048];
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(buf, sizeof buf, fmt, ap);
  va_end(ap);
  fn(user, level, buf);
}

int kpcn_resolve_threads(int n) {
  if (n > KPCN_MAX_THREADS) return KPCN_MAX_THREADS;
  if (n > 0) return n;
  int p = omp_get_num_procs();
  return p > 0 ? p : 1;
}

/* Large blocks (image planes, training tensors) take kpcn_aligned_alloc's huge-page path
 * too (kpcn_calloc's clear them): with THP in "madvise" mode a fresh 4 MiB plane otherwise costs
 * 1024 page faults
 * (~0.25 s for one 1-Mpixel AOV file's planes in this VM). free() releases either kind. */
void *kpcn_alloc(size_t bytes, const char *what) {
  if (bytes >= (4u << 20)) return kpcn_aligned_alloc(bytes, what);
  void *p = malloc(bytes ? bytes : 1);
  if (!p) kpcn_fail(KPCN_ERR_OUT_OF_MEMORY, "cannot allocate %zu bytes for %s", bytes, what);
  return p;
}

void *kpcn_calloc(size_t count, size_t size, const char *what) {
  if (size && count <= SIZE_MAX / size && count * size >= (4u << 20)) { /* see kpcn_alloc */
    void *p = kpcn_aligned_alloc(count * size, what);
    if (p) memset(p, 0, count * size);
    return p;
  }
  void *p = calloc(count ? count : 1, size ? size : 1);
  if (!p)
    kpcn_fail(KPCN_ERR_OUT_OF_MEMORY, "cannot allocate %zu x %zu bytes for %s", count, size, what);
  return p;
}

/* Buffers of a few MiB and more (activations, logits, render accumulators) are placed on
 * 2 MiB boundaries and marked for transparent huge pages: Debian's default THP mode is
 * "madvise", so without the hint every 4 KiB page of a fresh buffer costs a fault on first
 * touch and a TLB entry afterwards (measured in bench_denoise, see docs/denoiser.md). */
enum { HUGE_PAGE = 2u << 20, HUGE_MIN = 4u << 20 };

uint64_t kpcn_physical_memory(void) {
  static uint64_t mem; /* a benign race: every thread computes the same value */
  if (!mem) {
    const long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGESIZE);
    if (pages > 0 && page > 0) mem = (uint64_t)pages * (uint64_t)page;
  }
  return mem;
}

uint64_t kpcn_available_memory(void) {
  const uint64_t phys = kpcn_physical_memory();
  FILE *f = fopen("/proc/meminfo", "r");
  if (!f) return phys;
  unsigned long long kb, avail = 0, swap = 0;
  int found = 0;
  char line[256];
  while (fgets(line, sizeof line, f)) {
    if (sscanf(line, "MemAvailable: %llu kB", &kb) == 1) avail = kb, found = 1;
    if (sscanf(line, "SwapFree: %llu kB", &kb) == 1) swap = kb;
  }
  fclose(f);
  if (!found) return phys;
  const uint64_t a = (uint64_t)(avail + swap) * 1024u;
  return phys && a > phys ? phys : a;
}

void *kpcn_aligned_alloc(size_t bytes, const char *what) {
  /* A block larger than the machine (an absurd header, a huge render) is an error to name,
   * not an allocation that overcommits and ends in the OOM killer once its pages are touched. */
  const uint64_t mem = kpcn_physical_memory();
  if (mem && bytes > mem) {
    kpcn_fail(KPCN_ERR_OUT_OF_MEMORY,
              "cannot allocate %.1f GB for %s: more than this machine's %.1f GB of memory",
              (double)bytes * 1e-9, what, (double)mem * 1e-9);
    return NULL;
  }
  void *p = NULL;
  const int huge = bytes >= HUGE_MIN;
  const size_t n = huge ? (bytes + HUGE_PAGE - 1) / HUGE_PAGE * HUGE_PAGE : bytes ? bytes : 64;
  if (posix_memalign(&p, huge ? HUGE_PAGE : 64, n) != 0) {
    kpcn_fail(KPCN_ERR_OUT_OF_MEMORY, "cannot allocate %zu bytes for %s", bytes, what);
    return NULL;
  }
#ifdef MADV_HUGEPAGE
  if (huge) (void)madvise(p, n, MADV_HUGEPAGE); /* a hint: failure changes nothing */
#endif
  return p;
}

void kpcn_aligned_free(void *p) { free(p); }

kpcn_status kpcn_check_size(int width, int height, const char *what) {
  if (width <= 0 || height <= 0)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s: zero or negative size %dx%d", what, width,
                     height);
  if (width > KPCN_MAX_DIM || height > KPCN_MAX_DIM ||
      (int64_t)width * (int64_t)height > KPCN_MAX_PIXELS)
    return kpcn_fail(KPCN_ERR_OUT_OF_MEMORY,
                     "%s: absurd size %dx%d (limit %d per side, %lld pixels)", what, width, height,
                     KPCN_MAX_DIM, (long long)KPCN_MAX_PIXELS);
  return KPCN_OK;
}
