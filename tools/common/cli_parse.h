/* Strict parsing of the command-line tools' numeric option values (kpcn-render, kpcn-dataset,
 * kpcn-train, kpcntool's modifiers): integers are digits, with a '-' only where the range
 * allows negatives, and are range-checked as 64-bit values; numbers are plain decimals. No
 * blanks, no '+' on integers, no hexadecimal, inf or nan, nothing after the value. sscanf's %d
 * wraps what does not fit an int without a word (4294967312x4294967304 was read as 16x8), and
 * strtol/strtod alone skip leading blanks. */
#ifndef KPCN_TOOLS_CLI_PARSE_H
#define KPCN_TOOLS_CLI_PARSE_H

#ifdef __cplusplus
extern "C" {
#endif

/* One integer in [lo, hi]: 1 and *out set, or 0 (out untouched). */
int cli_parse_int(const char *s, long lo, long hi, int *out);
int cli_parse_ll(const char *s, long long lo, long long hi, long long *out);

/* A finite decimal number, [+-]digits[.digits][e[+-]digits]: 1 and *out set, or 0. strtod
 * alone also takes leading blanks, hexadecimal ("0x8p-4"), "inf" and "nan". */
int cli_parse_double(const char *s, double *out);

/* n integers separated by the single character sep ("16x16", "0,0,8,8", "1/4"), integer i in
 * [lo[i], hi[i]]: 1 and out[0..n-1] set, or 0. */
int cli_parse_int_list(const char *s, char sep, int n, const long *lo, const long *hi, int *out);

#ifdef __cplusplus
}
#endif

#endif
