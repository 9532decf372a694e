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

/* Reads columns xcol and ycols[0..ny-1] of a trainer CSV into *out (layout: x then each y,
 * *n values each, malloc'ed). Missing cells are NaN; a missing column is an error. */
static kpcn_status read_columns(const char *path, const char *xcol, const char *const *ycols,
                                int ny, double **out, size_t *n_out) {
  const char *why;
  FILE *in = kpcn_fopen_input(path, &why);
  if (!in) return kpcn_fail(KPCN_ERR_IO, "cannot open CSV '%s': %s", path, why);
  char line[2048], *f[32];
  if (!fgets(line, sizeof line, in)) {
    fclose(in);
    return kpcn_fail(KPCN_ERR_FORMAT, "CSV '%s' is empty", path);
  }
  int nf = split(line, f, 32), col[9];
  for (int k = 0; k <= ny; k++) {
    const char *want = k == 0 ? xcol : ycols[k - 1];
    col[k] = -1;
    for (int i = 0; i < nf; i++)
      if (!strcmp(f[i], want)) col[k] = i;
    if (col[k] < 0) {
      fclose(in);
      return kpcn_fail(KPCN_ERR_FORMAT, "CSV '%s' has no column '%s'", path, want);
    }
  }
  size_t cap = 256, n = 0, stride = (size_t)ny + 1;
  double *rows = kpcn_alloc(cap * stride * sizeof(double), "plot data");
  if (!rows) {
    fclose(in);
    return kpcn_last_status();
  }
  while (fgets(line, sizeof line, in)) {
    int k = split(line, f, 32);
    if (n == cap) {
      double *nr = realloc(rows, 2 * cap * stride * sizeof(double));
      if (!nr) {
        free(rows);
        fclose(in);
        return kpcn_fail(KPCN_ERR_OUT_OF_MEMORY, "out of memory for the plot data of '%s'", path);
      }
      rows = nr, cap *= 2;
    }
    for (size_t c = 0; c < stride; c++)
      rows[n * stride + c] = field(f, k, col[c]);
    n++;
  }
  fclose(in);
  /* transpose to column blocks */
  double *o = kpcn_alloc((n ? n : 1) * stride * sizeof(double), "plot data");
  if (!o) {
    free(rows);
    return kpcn_last_status();
  }
  for (size_t r = 0; r < n; r++)
    for (size_t c = 0; c < stride; c++)
      o[c * n + r] = rows[r * stride + c];
  free(rows);
  *out = o;
  *n_out = n;
  return KPCN_OK;
}

kpcn_status kpcn_train_plot_csv(const char *csv_path, const char *png_path, const char *title) {
  if (!csv_path || !png_path)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_train_plot_csv: NULL path");
  static const char *cols[3] = {"loss", "val_relmse", "val_ssim"};
  double *d;
  size_t n;
  KPCN_TRY(read_columns(csv_path, "iter", cols, 3, &d, &n));
  for (size_t i = 0; i < n; i++)
    d[3 * n + i] = 1.0 - d[3 * n + i]; /* 1 - SSIM */
  kpcn_plot_series ser[3] = {{"train loss", d, d + n, (int)n},
                             {"val relmse", d, d + 2 * n, (int)n},
                             {"val 1-ssim", d, d + 3 * n, (int)n}};
  kpcn_plot_settings ps;
  kpcn_plot_settings_defaults(&ps);
  ps.log_y = 1;
  ps.title = title;
  ps.xlabel = "iteration";
  ps.ylabel = "loss / error";
  kpcn_status st = kpcn_plot_png(png_path, &ps, ser, 3);
  free(d);
  return st;
}

kpcn_status kpcn_train_plot_compare(const char *png_path, const char *title, const char *xcol,
                                    const char *ycol, int log_y, int nruns,
                                    const char *const *labels, const char *const *csv_paths) {
  if (!png_path || !xcol || !ycol || nruns < 1 || nruns > KPCN_PLOT_MAX_SERIES || !labels ||
      !csv_paths)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "kpcn_train_plot_compare: bad arguments (%d runs, at most %d)", nruns,
                     KPCN_PLOT_MAX_SERIES);
  double *d[KPCN_PLOT_MAX_SERIES] = {0};
  kpcn_plot_series ser[KPCN_PLOT_MAX_SERIES];
  kpcn_status st = KPCN_OK;
  for (int r = 0; r < nruns && st == KPCN_OK; r++) {
    size_t n = 0;
    st = read_columns(csv_paths[r], xcol, &ycol, 1, &d[r], &n);
    /* a run with nothing to draw (no --val for a val_ column), or values a log axis cannot
     * show, would be a legend entry without a line: refused, naming the run */
    size_t finite = 0, nonpos = 0;
    for (size_t i = 0; st == KPCN_OK && i < n; i++)
      if (isfinite(d[r][i]) && isfinite(d[r][n + i])) {
        finite++;
        nonpos += !strcmp(ycol, "val_ssim") ? 1.0 - d[r][n + i] <= 0 : d[r][n + i] <= 0;
      }
    if (st == KPCN_OK && !finite)
      st = kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "run '%s' (%s) has no value in column '%s'%s",
                     labels[r], csv_paths[r], ycol,
                     !strncmp(ycol, "val_", 4) ? " (was it trained without --val?)" : "");
    else if (st == KPCN_OK && log_y && nonpos)
      st = kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "run '%s' (%s): %zu value(s) of '%s' are <= 0, which a log axis cannot show "
                     "(plot with --linear)",
                     labels[r], csv_paths[r], nonpos, ycol);
    if (st == KPCN_OK) {
      if (!strcmp(ycol, "val_ssim"))
        for (size_t i = 0; i < n; i++)
          d[r][n + i] = 1.0 - d[r][n + i];
      ser[r].label = labels[r];
      ser[r].x = d[r];
      ser[r].y = d[r] + n;
      ser[r].n = (int)n;
    }
  }
  if (st == KPCN_OK) {
    kpcn_plot_settings ps;
    kpcn_plot_settings_defaults(&ps);
    ps.log_y = log_y;
    ps.title = title;
    ps.xlabel = !strcmp(xcol, "elapsed_s") ? "seconds" : xcol;
    ps.ylabel = !strcmp(ycol, "val_ssim") ? "1 - val ssim" : ycol;
    st = kpcn_plot_png(png_path, &ps, ser, nruns);
  }
  for (int r = 0; r < nruns; r++)
    free(d[r]);
  return st;
}
