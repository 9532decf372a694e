#define _GNU_SOURCE
#include "core/internal.h"
#include "testutil.h"
#include <stdlib.h>
#include <string.h>

int kt_failures = 0;
int kt_checks = 0;

int kt_summary(const char *suite) {
  printf("%s: %d checks, %d passed, %d failed\n", suite, kt_checks, kt_checks - kt_failures,
         kt_failures);
  return kt_failures ? 1 : 0;
}

const char *kt_tmpdir(void) {
  static char dir[256];
  if (!dir[0]) {
    snprintf(dir, sizeof dir, "/tmp/kpcn_test_XXXXXX");
    if (!mkdtemp(dir)) {
      perror("mkdtemp");
      abort();
    }
  }
  return dir;
}

const char *kt_tmpfile(const char *name) {
  static char path[8][512];
  static int slot = 0;
  slot = (slot + 1) % 8;
  snprintf(path[slot], sizeof path[slot], "%s/%s", kt_tmpdir(), name);
  return path[slot];
}

float kt_randf(unsigned *state) {
  unsigned x = *state ? *state : 2463534242u;
  x ^= x << 13;
  x ^= x >> 17;
  x ^= x << 5;
  *state = x;
  return (x >> 8) * (1.0f / 16777216.0f);
}

char *kt_slurp(const char *path, long *len) {
  FILE *f = fopen(path, "rb");
  if (!f) return NULL;
  fseek(f, 0, SEEK_END);
  long n = ftell(f);
  fseek(f, 0, SEEK_SET);
  char *b = n >= 0 ? malloc((size_t)n + 1) : NULL;
  if (b && fread(b, 1, (size_t)n, f) != (size_t)n) {
    free(b);
    b = NULL;
  }
  fclose(f);
  if (!b) return NULL;
  b[n] = 0;
  if (len) *len = n;
  return b;
}

uint16_t kt_bf16_round(float f) {
  uint32_t u;
  memcpy(&u, &f, 4);
  u += 0x7fffu + ((u >> 16) & 1u);
  return (uint16_t)(u >> 16);
}
