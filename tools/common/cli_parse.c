/* Strict option-value parsing shared by the C tools: cli_parse.h. */
#include "cli_parse.h"

#include <errno.h>
#include <math.h>
#include <stdlib.h>

/* One integer at s in [lo, hi], *end left after it; 0 unless it is digits (a leading '-' only
 * where lo < 0: "-0" is no value of a non-negative option). */
static int read_ll(const char *s, long long lo, long long hi, long long *v, const char **end) {
  if (!s) return 0;
  const char *d = *s == '-' && lo < 0 ? s + 1 : s;
  if (*d < '0' || *d > '9') return 0;
  char *e;
  errno = 0;
  long long x = strtoll(s, &e, 10);
  if (errno == ERANGE || x < lo || x > hi) return 0;
  *v = x;
  *end = e;
  return 1;
}

int cli_parse_ll(const char *s, long long lo, long long hi, long long *out) {
  long long v;
  const char *end;
  if (!read_ll(s, lo, hi, &v, &end) || *end) return 0;
  *out = v;
  return 1;
}

int cli_parse_int(const char *s, long lo, long hi, int *out) {
  long long v;
  if (!cli_parse_ll(s, lo, hi, &v)) return 0;
  *out = (int)v;
  return 1;
}

int cli_parse_int_list(const char *s, char sep, int n, const long *lo, const long *hi, int *out) {
  for (int i = 0; i < n; i++) {
    long long v;
    const char *end;
    if (!read_ll(s, lo[i], hi[i], &v, &end)) return 0;
    if (i + 1 < n ? *end != sep : *end != 0) return 0;
    out[i] = (int)v;
    s = end + 1;
  }
  return 1;
}

int cli_parse_double(const char *s, double *out) {
  if (!s) return 0;
  /* [+-] digits [. digits] [eE [+-] digits], at least one digit before the exponent */
  const char *p = s;
  int digits = 0;
  if (*p == '+' || *p == '-') p++;
  for (; *p >= '0' && *p <= '9'; p++)
    digits++;
  if (*p == '.')
    for (p++; *p >= '0' && *p <= '9'; p++)
      digits++;
  if (!digits) return 0;
  if (*p == 'e' || *p == 'E') {
    p++;
    if (*p == '+' || *p == '-') p++;
    if (*p < '0' || *p > '9') return 0;
    while (*p >= '0' && *p <= '9')
      p++;
  }
  if (*p) return 0;
  const double v = strtod(s, NULL);
  if (!isfinite(v)) return 0; /* 1e999 */
  *out = v;
  return 1;
}
