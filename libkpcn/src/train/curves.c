/* Training-curve plot from the trainer's CSV log: training loss, validation relMSE and
 * validation 1-SSIM against the iteration, on a log y axis (they span decades). Reading the
 * CSV back (rather than keeping the points in memory) makes resumed runs plot their whole
 * history. */
#include "core/internal.h"
#include "kpcn/train.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Splits a CSV line in place into at most max fields; returns the count. */
static int split(char *line, char **f, int max) {
  int n = 0;
  char *p = line;
  while (n < max) {
    f[n++] = p;
    char *c = strchr(p, ',');
    if (!c) break;
    *c = 0;
    p = c + 1;
  }
  char *nl = strpbrk(f[n - 1], "\r\n");
  if (nl) *nl = 0;
  return n;
}

static double field(char **f, int n, int col) {
  if (col < 0 || col >= n || !*f[col]) return NAN;
  char *end;
  double v = strtod(f[col], &end);
  return end == f[col] ? NAN : v;
}

kpcn_status kpcn_train_plot_csv(const char *csv_path, const char *png_path, const char *title) {
  if (!csv_path || !png_path)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_train_plot_csv: NULL path");
  FILE *in = fopen(csv_path, "r");
  if (!in) return kpcn_fail(KPCN_ERR_IO, "cannot open CSV '%s': %s", csv_path, strerror(errno));
  char line[2048], *f[32];
  if (!fgets(line, sizeof line, in)) {
    fclose(in);
    return kpcn_fail(KPCN_ERR_FORMAT, "CSV '%s' is empty", csv_path);
  }
  int nf = split(line, f, 32), ci = -1, cl = -1, cr = -1, cs = -1;
  for (int i = 0; i < nf; i++) {
    if (!strcmp(f[i], "iter")) ci = i;
    if (!strcmp(f[i], "loss")) cl = i;
    if (!strcmp(f[i], "val_relmse")) cr = i;
    if (!strcmp(f[i], "val_ssim")) cs = i;
  }
  if (ci < 0) {
    fclose(in);
    return kpcn_fail(KPCN_ERR_FORMAT, "CSV '%s' has no 'iter' column", csv_path);
  }
  size_t cap = 1024, n = 0;
  double *buf = kpcn_alloc(cap * 4 * sizeof(double), "plot data");
  kpcn_status st = buf ? KPCN_OK : kpcn_last_status();
  while (st == KPCN_OK && fgets(line, sizeof line, in)) {
    int k = split(line, f, 32);
    if (n == cap) {
      double *nb = realloc(buf, cap * 8 * sizeof(double));
      if (!nb) {
        st = kpcn_fail(KPCN_ERR_OUT_OF_MEMORY, "plot data");
        break;
      }
      /* re-layout: 4 arrays of cap -> 4 arrays of 2cap */
      for (int a = 3; a >= 1; a--) memmove(nb + a * 2 * cap, nb + a * cap, cap * sizeof(double));
      buf = nb, cap *= 2;
    }
    buf[n] = field(f, k, ci);
    buf[cap + n] = field(f, k, cl);
    buf[2 * cap + n] = field(f, k, cr);
    double s = field(f, k, cs);
    buf[3 * cap + n] = 1.0 - s;
    n++;
  }
  fclose(in);
  if (st == KPCN_OK) {
    kpcn_plot_series ser[3] = {{"train loss", buf, buf + cap, (int)n},
                               {"val relmse", buf, buf + 2 * cap, (int)n},
                               {"val 1-ssim", buf, buf + 3 * cap, (int)n}};
    kpcn_plot_settings ps;
    kpcn_plot_settings_defaults(&ps);
    ps.log_y = 1;
    ps.title = title;
    ps.xlabel = "iteration";
    ps.ylabel = "loss / error";
    st = kpcn_plot_png(png_path, &ps, ser, 3);
  }
  free(buf);
  return st;
}
