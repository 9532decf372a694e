/* Training-curve plots as PNG: axes, ticks, labels in a built-in 5x7 bitmap font,
 * anti-alias-free poly-lines, legend. The only file defining
 * STB_IMAGE_WRITE_IMPLEMENTATION in the train module (static, so it cannot clash with
 * another module that embeds stb_image_write as well). */
#include "core/internal.h"
#include "kpcn/train.h"

#include <ctype.h>
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define STB_IMAGE_WRITE_IMPLEMENTATION
#define STB_IMAGE_WRITE_STATIC
#if defined(__GNUC__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wunused-function"
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"
#pragma GCC diagnostic ignored "-Wsign-compare"
#endif
#include <stb/stb_image_write.h>

#if defined(__GNUC__)
#pragma GCC diagnostic pop
#endif

/* stb's PNG bytes to a file, remembering a short write (stbi_write_png does not) */
typedef struct png_sink {
  FILE *f;
  int ok;
} png_sink;

static void png_write(void *user, void *data, int size) {
  png_sink *s = user;
  if (s->ok && fwrite(data, 1, (size_t)size, s->f) != (size_t)size) s->ok = 0;
}

/* 5x7 glyphs, one byte per row, bit 4 = leftmost column. Lowercase letters are drawn
 * as uppercase (except those listed). */
static const struct {
  char c;
  unsigned char rows[7];
} k_font[] = {
    {'0', {0x0e, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0e}},
    {'1', {0x04, 0x0c, 0x04, 0x04, 0x04, 0x04, 0x0e}},
    {'2', {0x0e, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1f}},
    {'3', {0x1f, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0e}},
    {'4', {0x02, 0x06, 0x0a, 0x12, 0x1f, 0x02, 0x02}},
    {'5', {0x1f, 0x10, 0x1e, 0x01, 0x01, 0x11, 0x0e}},
    {'6', {0x06, 0x08, 0x10, 0x1e, 0x11, 0x11, 0x0e}},
    {'7', {0x1f, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08}},
    {'8', {0x0e, 0x11, 0x11, 0x0e, 0x11, 0x11, 0x0e}},
    {'9', {0x0e, 0x11, 0x11, 0x0f, 0x01, 0x02, 0x0c}},
    {'A', {0x0e, 0x11, 0x11, 0x1f, 0x11, 0x11, 0x11}},
    {'B', {0x1e, 0x11, 0x11, 0x1e, 0x11, 0x11, 0x1e}},
    {'C', {0x0e, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0e}},
    {'D', {0x1c, 0x12, 0x11, 0x11, 0x11, 0x12, 0x1c}},
    {'E', {0x1f, 0x10, 0x10, 0x1e, 0x10, 0x10, 0x1f}},
    {'F', {0x1f, 0x10, 0x10, 0x1e, 0x10, 0x10, 0x10}},
    {'G', {0x0e, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0f}},
    {'H', {0x11, 0x11, 0x11, 0x1f, 0x11, 0x11, 0x11}},
    {'I', {0x0e, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0e}},
    {'J', {0x07, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0c}},
    {'K', {0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11}},
    {'L', {0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1f}},
    {'M', {0x11, 0x1b, 0x15, 0x15, 0x11, 0x11, 0x11}},
    {'N', {0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11}},
    {'O', {0x0e, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0e}},
    {'P', {0x1e, 0x11, 0x11, 0x1e, 0x10, 0x10, 0x10}},
    {'Q', {0x0e, 0x11, 0x11, 0x11, 0x15, 0x12, 0x0d}},
    {'R', {0x1e, 0x11, 0x11, 0x1e, 0x14, 0x12, 0x11}},
    {'S', {0x0f, 0x10, 0x10, 0x0e, 0x01, 0x01, 0x1e}},
    {'T', {0x1f, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04}},
    {'U', {0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0e}},
    {'V', {0x11, 0x11, 0x11, 0x11, 0x11, 0x0a, 0x04}},
    {'W', {0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0a}},
    {'X', {0x11, 0x11, 0x0a, 0x04, 0x0a, 0x11, 0x11}},
    {'Y', {0x11, 0x11, 0x0a, 0x04, 0x04, 0x04, 0x04}},
    {'Z', {0x1f, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1f}},
    {'.', {0x00, 0x00, 0x00, 0x00, 0x00, 0x0c, 0x0c}},
    {'-', {0x00, 0x00, 0x00, 0x1f, 0x00, 0x00, 0x00}},
    {'+', {0x00, 0x04, 0x04, 0x1f, 0x04, 0x04, 0x00}},
    {':', {0x00, 0x0c, 0x0c, 0x00, 0x0c, 0x0c, 0x00}},
    {'/', {0x00, 0x01, 0x02, 0x04, 0x08, 0x10, 0x00}},
    {'(', {0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02}},
    {')', {0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08}},
    {'_', {0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x1f}},
    {'=', {0x00, 0x00, 0x1f, 0x00, 0x1f, 0x00, 0x00}},
    {',', {0x00, 0x00, 0x00, 0x00, 0x0c, 0x04, 0x08}},
    {'%', {0x18, 0x19, 0x02, 0x04, 0x08, 0x13, 0x03}},
    {'x', {0x00, 0x00, 0x11, 0x0a, 0x04, 0x0a, 0x11}},
};

static const unsigned char *glyph(char c) {
  for (size_t i = 0; i < sizeof k_font / sizeof k_font[0]; i++)
    if (k_font[i].c == c) return k_font[i].rows;
  c = (char)toupper((unsigned char)c);
  for (size_t i = 0; i < sizeof k_font / sizeof k_font[0]; i++)
    if (k_font[i].c == c) return k_font[i].rows;
  return NULL; /* space and unknown characters are blank */
}

typedef struct canvas {
  unsigned char *px;
  int w, h;
} canvas;

static void put(canvas *cv, int x, int y, const unsigned char rgb[3]) {
  if (x < 0 || y < 0 || x >= cv->w || y >= cv->h) return;
  memcpy(cv->px + 3 * ((size_t)y * cv->w + x), rgb, 3);
}

static void text(canvas *cv, int x, int y, const char *s, const unsigned char rgb[3], int vert) {
  /* vert: drawn bottom-to-top (rotated 90 degrees), for the y-axis label */
  for (int k = 0; s[k]; k++) {
    const unsigned char *g = glyph(s[k]);
    if (g)
      for (int r = 0; r < 7; r++)
        for (int c = 0; c < 5; c++)
          if (g[r] & (0x10 >> c)) {
            if (vert)
              put(cv, x + r, y - 6 * k - c, rgb);
            else
              put(cv, x + 6 * k + c, y + r, rgb);
          }
  }
}

static void line(canvas *cv, int x0, int y0, int x1, int y1, const unsigned char rgb[3],
                 int thick) {
  int dx = abs(x1 - x0), sx = x0 < x1 ? 1 : -1, dy = -abs(y1 - y0), sy = y0 < y1 ? 1 : -1;
  int err = dx + dy;
  for (int guard = 0; guard < 100000; guard++) {
    for (int t = 0; t < thick; t++) {
      put(cv, x0, y0 + t, rgb);
      put(cv, x0 + t, y0, rgb);
    }
    if (x0 == x1 && y0 == y1) break;
    int e2 = 2 * err;
    if (e2 >= dy) {
      err += dy;
      x0 += sx;
    }
    if (e2 <= dx) {
      err += dx;
      y0 += sy;
    }
  }
}

static const unsigned char k_colors[KPCN_PLOT_MAX_SERIES][3] = {
    {31, 119, 180},  {214, 39, 40}, {44, 160, 44},   {255, 127, 14},
    {148, 103, 189}, {140, 86, 75}, {227, 119, 194}, {23, 190, 207}};

void kpcn_plot_settings_defaults(kpcn_plot_settings *s) {
  memset(s, 0, sizeof *s);
  s->width = 800;
  s->height = 500;
}

/* A "nice" tick step (1, 2 or 5 x 10^k) giving about n ticks over span. */
static double nice_step(double span, int n) {
  double raw = span / n, p = pow(10.0, floor(log10(raw))), f = raw / p;
  return (f < 1.5 ? 1 : f < 3.5 ? 2 : f < 7.5 ? 5 : 10) * p;
}

/* A tick label with `digits` significant digits (callers raise it until neighbouring ticks
 * read differently; at least 3). */
static void fmt_num(char *buf, size_t n, double v, int digits) {
  if (v != 0 && (fabs(v) >= 1e5 || fabs(v) < 1e-3))
    snprintf(buf, n, "%.*g", digits, v);
  else
    snprintf(buf, n, "%.*g", digits < 6 ? 6 : digits, v);
}

/* Significant digits that tell ticks `step` apart near magnitude `mag` (3 at least). */
static int tick_digits(double mag, double step) {
  if (!(step > 0) || !(mag > 0)) return 3;
  int d = (int)ceil(log10(mag / step)) + 1;
  return d < 3 ? 3 : d > 12 ? 12 : d;
}

/* Linear ticks over [v0, v1] (value space) at a nice step: their count, values in t[]. A tick
 * within rounding of zero is exactly 0 (it printed as "-0"). */
static int linear_ticks(double v0, double v1, int want, double *t, int max, double *step) {
  double sv = nice_step(v1 - v0, want);
  int n = 0;
  for (double v = ceil(v0 / sv) * sv; v <= v1 + 1e-9 * sv && n < max; v += sv)
    t[n++] = fabs(v) < 1e-9 * sv ? 0.0 : v;
  *step = sv;
  return n;
}

kpcn_status kpcn_plot_png(const char *path, const kpcn_plot_settings *st,
                          const kpcn_plot_series *series, int nseries) {
  kpcn_plot_settings def;
  if (!st) {
    kpcn_plot_settings_defaults(&def);
    st = &def;
  }
  if (!path || nseries < 0 || nseries > KPCN_PLOT_MAX_SERIES || (nseries && !series))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_plot_png: bad arguments (%d series)",
                     nseries);
  if (st->width < 200 || st->height < 150 || st->width > 8192 || st->height > 8192)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_plot_png: size %dx%d out of range", st->width,
                     st->height);
  /* data range */
  double x0 = INFINITY, x1 = -INFINITY, y0 = INFINITY, y1 = -INFINITY;
  for (int s = 0; s < nseries; s++)
    for (int i = 0; i < series[s].n; i++) {
      double x = series[s].x[i], y = series[s].y[i];
      if (!isfinite(x) || !isfinite(y) || (st->log_y && y <= 0)) continue;
      if (st->log_y) y = log10(y);
      x0 = fmin(x0, x), x1 = fmax(x1, x), y0 = fmin(y0, y), y1 = fmax(y1, y);
    }
  if (!(x0 <= x1)) x0 = 0, x1 = 1, y0 = 0, y1 = 1; /* no data: empty axes */
  if (x1 - x0 < 1e-12) x1 = x0 + 1;
  if (y1 - y0 < 1e-12 * fmax(1.0, fabs(y0))) y0 -= 0.5, y1 += 0.5;
  double pad = 0.04 * (y1 - y0);
  y0 -= pad, y1 += pad;

  canvas cv = {kpcn_alloc((size_t)st->width * st->height * 3, "plot canvas"), st->width,
               st->height};
  if (!cv.px) return kpcn_last_status();
  memset(cv.px, 255, (size_t)st->width * st->height * 3);
  const unsigned char black[3] = {0, 0, 0}, grey[3] = {225, 225, 225};
  int L = 70, R = st->width - 20, T = 30, B = st->height - 45;
#define PX(x) (L + (int)lround(((x)-x0) / (x1 - x0) * (R - L)))
#define PY(y) (B - (int)lround(((y)-y0) / (y1 - y0) * (B - T)))
  char buf[64];
  /* x ticks + grid */
  double tick[64], step;
  int nt = linear_ticks(x0, x1, 6, tick, 64, &step);
  for (int i = 0; i < nt; i++) {
    int px = PX(tick[i]);
    line(&cv, px, T, px, B, grey, 1);
    line(&cv, px, B, px, B + 4, black, 1);
    fmt_num(buf, sizeof buf, tick[i], tick_digits(fmax(fabs(x0), fabs(x1)), step));
    text(&cv, px - 3 * (int)strlen(buf), B + 8, buf, black, 0);
  }
  /* y ticks + grid (in the axis's space: log10 of the value on a log axis). A log axis gets
   * ticks at 1, 2, 5 x 10^k (only 10^k over > 4 decades); where fewer than two of those fall
   * inside (a curve within one factor of 2 or so), linear ticks in value space instead: the
   * axis had no label at all. */
  double yt[64];
  int ny = 0, digits = 3;
  if (st->log_y) {
    static const double mant[3] = {1, 2, 5};
    int nm = y1 - y0 > 4 ? 1 : 3;
    for (int k = (int)floor(y0); k <= (int)ceil(y1) && ny < 64; k++)
      for (int j = 0; j < nm && ny < 64; j++) {
        double v = k + log10(mant[j]);
        if (v >= y0 && v <= y1) yt[ny++] = v;
      }
    if (ny < 2) {
      double v[64];
      ny = linear_ticks(pow(10.0, y0), pow(10.0, y1), 5, v, 64, &step);
      digits = tick_digits(pow(10.0, y1), step);
      for (int i = 0; i < ny; i++)
        yt[i] = log10(v[i]);
    }
  } else {
    ny = linear_ticks(y0, y1, 6, yt, 64, &step);
    digits = tick_digits(fmax(fabs(y0), fabs(y1)), step);
  }
  for (int i = 0; i < ny; i++) {
    int py = PY(yt[i]);
    line(&cv, L, py, R, py, grey, 1);
    line(&cv, L - 4, py, L, py, black, 1);
    fmt_num(buf, sizeof buf, st->log_y ? pow(10.0, yt[i]) : yt[i], digits);
    text(&cv, L - 7 - 6 * (int)strlen(buf), py - 3, buf, black, 0);
  }
  line(&cv, L, T, L, B, black, 1);
  line(&cv, L, B, R, B, black, 1);
  line(&cv, R, T, R, B, black, 1);
  line(&cv, L, T, R, T, black, 1);
  if (st->title) text(&cv, (L + R) / 2 - 3 * (int)strlen(st->title), 10, st->title, black, 0);
  if (st->xlabel)
    text(&cv, (L + R) / 2 - 3 * (int)strlen(st->xlabel), B + 24, st->xlabel, black, 0);
  if (st->ylabel) text(&cv, 6, (T + B) / 2 + 3 * (int)strlen(st->ylabel), st->ylabel, black, 1);
  /* series */
  for (int s = 0; s < nseries; s++) {
    const unsigned char *c = k_colors[s];
    int have = 0, lx = 0, ly = 0;
    for (int i = 0; i < series[s].n; i++) {
      double x = series[s].x[i], y = series[s].y[i];
      if (!isfinite(x) || !isfinite(y) || (st->log_y && y <= 0)) continue;
      int px = PX(x), py = PY(st->log_y ? log10(y) : y);
      if (have)
        line(&cv, lx, ly, px, py, c, 2);
      else if (series[s].n == 1 || i == series[s].n - 1)
        line(&cv, px - 2, py, px + 2, py, c, 2);
      lx = px, ly = py, have = 1;
    }
    if (series[s].label) { /* legend, top right */
      int ly2 = T + 8 + 12 * s, lx2 = R - 10 - 6 * (int)strlen(series[s].label) - 22;
      line(&cv, lx2, ly2 + 3, lx2 + 16, ly2 + 3, c, 2);
      text(&cv, lx2 + 22, ly2, series[s].label, black, 0);
    }
  }
#undef PX
#undef PY
  char tmp[4096];
  if (kpcn_temp_path(tmp, sizeof tmp, path) != KPCN_OK) {
    free(cv.px);
    return kpcn_last_status();
  }
  /* through a callback, not stbi_write_png: that one ignores fwrite's and fclose's errors and
   * left an empty PNG behind on a full disk */
  FILE *f = fopen(tmp, "wb");
  int ok = f != NULL;
  if (ok) {
    png_sink sink = {f, 1};
    ok = stbi_write_png_to_func(png_write, &sink, cv.w, cv.h, 3, cv.px, cv.w * 3) && sink.ok;
    ok &= fflush(f) == 0 && !ferror(f);
    ok &= fclose(f) == 0;
  }
  const int e = errno;
  free(cv.px);
  if (!ok) {
    kpcn_abort_file(tmp);
    return kpcn_fail(KPCN_ERR_IO, "cannot write plot PNG '%s': %s", path, strerror(e));
  }
  return kpcn_commit_file(tmp, path);
}
