/* CPU feature gates for libkpcn's own SIMD kernels (see internal.h). */
#include "core/internal.h"

#include <pthread.h>
#include <stdlib.h>
#include <strings.h>

static int allows_avx512, allows_amx;
static pthread_once_t once = PTHREAD_ONCE_INIT;

/* A cap names a level below AVX-512 when it is an SSE or AVX level other than AVX512_*. */
static int cap_below_avx512(const char *cap) {
  if (!cap || !*cap) return 0;
  if (strncasecmp(cap, "avx512", 6) == 0 || strcasecmp(cap, "all") == 0) return 0;
  return strncasecmp(cap, "sse", 3) == 0 || strncasecmp(cap, "avx", 3) == 0;
}

static void detect(void) {
  const char *cap = getenv("ONEDNN_MAX_CPU_ISA");
  if (!cap || !*cap) cap = getenv("DNNL_MAX_CPU_ISA");
#if defined(__x86_64__) || defined(__i386__)
  allows_avx512 = __builtin_cpu_supports("avx512f") && !cap_below_avx512(cap);
  /* oneDNN runs bf16 convolutions on AMX tiles up to the cap AVX512_CORE_AMX (or none) */
  allows_amx = allows_avx512 && __builtin_cpu_supports("amx-tile") &&
               __builtin_cpu_supports("amx-bf16") &&
               (!cap || !*cap || strcasecmp(cap, "all") == 0 ||
                strncasecmp(cap, "avx512_core_amx", 15) == 0);
#else
  allows_avx512 = allows_amx = 0;
#endif
}

int kpcn_cpu_allows_avx512(void) {
  pthread_once(&once, detect);
  return allows_avx512;
}

int kpcn_cpu_allows_amx(void) {
  pthread_once(&once, detect);
  return allows_amx;
}
