/* Small helpers for kpcn-dataset: messages, directories, atomic files, parsing. */
#define _GNU_SOURCE
#include "ds.h"

#include "kpcn/common.h"
#include "kpcn/exr.h"

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

const char *ds_prog = "kpcn-dataset";

void ds_err(const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  fprintf(stderr, "%s: ", ds_prog);
  vfprintf(stderr, fmt, ap);
  fputc('\n', stderr);
  va_end(ap);
}

int ds_mkdir_p(const char *path) {
  char tmp[DS_PATH];
  snprintf(tmp, sizeof tmp, "%s", path);
  for (char *p = tmp + 1; *p; p++) {
    if (*p != '/') continue;
    *p = 0;
    if (mkdir(tmp, 0777) != 0 && errno != EEXIST) return -1;
    *p = '/';
  }
  if (mkdir(tmp, 0777) != 0 && errno != EEXIST) return -1;
  return 0;
}

int ds_exists(const char *path) {
  struct stat sb;
  return stat(path, &sb) == 0 && S_ISREG(sb.st_mode) && sb.st_size > 0;
}

void ds_join(char *out, size_t n, const char *a, const char *b) {
  const size_t la = strlen(a);
  if (b[0] == '/' || !la)
    snprintf(out, n, "%s", b);
  else /* "ds/" + "x": one slash, not "ds//x" in messages */
    snprintf(out, n, "%s%s%s", a, a[la - 1] == '/' ? "" : "/", b);
}

char *ds_slurp(const char *path, size_t *len, const char **why) {
  FILE *f = kpcn_fopen_input(path, why);
  if (!f) return NULL;
  size_t cap = 1 << 16, n = 0;
  char *b = malloc(cap);
  if (why) *why = "out of memory";
  if (!b) {
    fclose(f);
    return NULL;
  }
  for (;;) {
    if (n + 4096 > cap) {
      cap *= 2;
      char *nb = realloc(b, cap);
      if (!nb) {
        free(b);
        fclose(f);
        return NULL;
      }
      b = nb;
    }
    size_t got = fread(b + n, 1, cap - n - 1, f);
    n += got;
    if (got == 0) break;
  }
  fclose(f);
  b[n] = 0;
  if (len) *len = n;
  return b;
}

int ds_write_atomic(const char *path, const char *data, size_t len) {
  char tmp[DS_PATH + 32];
  snprintf(tmp, sizeof tmp, "%s.tmp.%ld", path, (long)getpid());
  FILE *f = fopen(tmp, "wb");
  if (!f) {
    ds_err("cannot write '%s': %s", tmp, strerror(errno));
    return -1;
  }
  int ok = fwrite(data, 1, len, f) == len;
  ok &= fclose(f) == 0;
  if (!ok || rename(tmp, path) != 0) {
    ds_err("cannot write '%s': %s", path, strerror(errno));
    unlink(tmp);
    return -1;
  }
  return 0;
}

int ds_parse_int_list(const char *s, long hi, int *out, int cap) {
  int n = 0;
  if (!s || !*s) return -1;
  for (const char *p = s;; p++) {
    const char *comma = strchr(p, ',');
    const size_t len = comma ? (size_t)(comma - p) : strlen(p);
    char item[32];
    if (len == 0 || len >= sizeof item || n == cap) return -1; /* "4,,8", "4,", ",4" */
    memcpy(item, p, len);
    item[len] = 0;
    if (!cli_parse_int(item, 1, hi, &out[n])) return -1;
    for (int k = 0; k < n; k++)
      if (out[k] == out[n]) return -1; /* twice: the same job planned (or a pair cut) twice */
    n++;
    if (!comma) return n;
    p = comma;
  }
}

/* Decimal digits only: strtoull would take "-1" as 2^64-1, skip leading blanks and
 * saturate past 2^64 with nothing but errno to tell. */
int ds_parse_u64(const char *s, uint64_t hi, uint64_t *out) {
  if (!s || !*s) return 0;
  uint64_t v = 0;
  for (const char *p = s; *p; p++) {
    if (*p < '0' || *p > '9') return 0;
    unsigned d = (unsigned)(*p - '0');
    if (d > hi || v > (hi - d) / 10) return 0;
    v = v * 10 + d;
  }
  *out = v;
  return 1;
}

uint64_t ds_hash(const char *s, uint64_t seed) {
  uint64_t h = 1469598103934665603ull ^ (seed * 0x9e3779b97f4a7c15ull);
  for (; *s; s++)
    h = (h ^ (unsigned char)*s) * 1099511628211ull;
  h ^= h >> 29;
  h *= 0xbf58476d1ce4e5b9ull;
  return h ^ (h >> 32);
}

double ds_now(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

int ds_isatty(void) { return isatty(2); }

void ds_progress(double *last, double every, int final, int done, int total, double elapsed,
                 double eta, const char *detail) {
  const int tty = ds_isatty();
  const double now = ds_now();
  if (!tty && !final && now - *last < every) return;
  *last = now;
  fprintf(stderr, "%s[%d/%d] %s, %.0fs elapsed, ~%.0fs left%s", tty ? "\r" : "", done, total,
          detail, elapsed, eta, tty ? "   " : "\n");
  fflush(stderr);
}

/* A render on disk is the one its job describes: size, spp and seed from its header. A render
 * left by an earlier plan (plan --force into the same folder) or a hand-edited manifest was
 * used as if it were the job's. A header without kpcn:spp or kpcn:seed (a --renderer that does
 * not write them) is checked for its size only. Returns 0 when it matches, -1 (message given)
 * when not. */
int ds_check_render(const char *path, const ds_job *j) {
  kpcn_exr_info_t *info = malloc(sizeof *info);
  if (!info) {
    ds_err("out of memory checking '%s'", path);
    return -1;
  }
  int rc = 0;
  if (kpcn_exr_info(path, info) != KPCN_OK) {
    ds_err("%s: %s", path, kpcn_last_error());
    rc = -1;
  } else if (info->width != j->width || info->height != j->height ||
             (info->spp >= 0 && info->spp != j->spp) ||
             (info->seed >= 0 && (uint64_t)info->seed != j->seed)) { /* -1: not in the header */
    ds_err("%s is not the render of job %s (the file: %dx%d, %d spp, seed %lld; the job: %dx%d, "
           "%d spp, seed %llu): it was left by an earlier plan (plan --force) or the manifest was "
           "edited; remove the renders/ folder to render again, or plan into a new folder",
           path, j->id, info->width, info->height, info->spp, (long long)info->seed, j->width,
           j->height, j->spp, (unsigned long long)j->seed);
    rc = -1;
  }
  free(info);
  return rc;
}
