/* Training losses on planar fp32 images, each returning the value and the
 * gradient with respect to the prediction (seed chapter 5, DESIGN.md §7).
 *
 * Layout: n images of c planes of h*w floats, image-major ([n][c][h][w]).
 * Value = mean over every element (pixel-wise losses) or over every valid SSIM
 * window position (SSIM); the gradient is d value / d pred, same layout.
 *
 * Determinism: partial sums are taken per (image, plane, row) in double into a
 * fixed array and added in index order afterwards, so the value is bitwise the
 * same for any thread count. The gradients are element-wise (no reductions) or,
 * for SSIM, fixed-order separable filters, so they are thread-independent too. */
#include "core/internal.h"
#include "kpcn/train.h"

#include <math.h>
#include <omp.h>
#include <stdlib.h>
#include <string.h>

const char *kpcn_loss_name(kpcn_loss_kind k) {
  switch (k) {
  case KPCN_LOSS_L1: return "l1";
  case KPCN_LOSS_L2: return "l2";
  case KPCN_LOSS_RELMSE: return "relmse";
  case KPCN_LOSS_RELL1: return "rell1";
  case KPCN_LOSS_SSIM: return "ssim";
  case KPCN_LOSS_RELMSE_SG: return "relmse-sg";
  case KPCN_LOSS_RELL1_SG: return "rell1-sg";
  }
  return "?";
}

kpcn_status kpcn_loss_parse(const char *name, kpcn_loss_kind *out) {
  static const struct {
    const char *n;
    kpcn_loss_kind k;
  } tab[] = {{"l1", KPCN_LOSS_L1},
             {"l2", KPCN_LOSS_L2},
             {"mse", KPCN_LOSS_L2},
             {"relmse", KPCN_LOSS_RELMSE},
             {"rell1", KPCN_LOSS_RELL1},
             {"ssim", KPCN_LOSS_SSIM},
             {"relmse-sg", KPCN_LOSS_RELMSE_SG},
             {"rell1-sg", KPCN_LOSS_RELL1_SG}};
  if (!name || !out) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_loss_parse: NULL argument");
  for (size_t i = 0; i < sizeof tab / sizeof tab[0]; i++)
    if (strcmp(tab[i].n, name) == 0) {
      *out = tab[i].k;
      return KPCN_OK;
    }
  return kpcn_fail(
      KPCN_ERR_INVALID_ARGUMENT,
      "unknown loss '%s' (expected l1, l2, relmse, rell1, ssim, relmse-sg or rell1-sg)", name);
}

void kpcn_loss_settings_defaults(kpcn_loss_settings *s) {
  s->rel_eps = 0.01;
  s->ssim_window = 11;
  s->ssim_sigma = 1.5f;
  s->ssim_k1 = 0.01f;
  s->ssim_k2 = 0.03f;
  s->ssim_range = 1.0f;
}

/* Sum of row partials in a fixed order. */
static double ordered_sum(const double *p, size_t n) {
  double s = 0.0;
  for (size_t i = 0; i < n; i++)
    s += p[i];
  return s;
}

/* Pixel-wise losses. relMSE = (x-y)^2/(y^2+eps) and relL1 = |x-y|/(|y|+eps): the
 * denominator depends on the reference only, so it is a constant w.r.t. x (as in
 * Rousselle 2011 / Bako 2017, who normalise by the reference or a stop-gradient
 * copy of it). relmse-sg and rell1-sg divide by the prediction's own x^2 + eps or |x| + eps, held
 * constant (stop-gradient), so its gradient is not the derivative of its value: it is the
 * derivative with the denominator frozen. At x == y the L1 subgradient is taken as 0. */
static kpcn_status pixel_loss(kpcn_loss_kind kind, const kpcn_loss_settings *s, const float *x,
                              const float *y, size_t rows, size_t w, float *grad, double *value,
                              int nthreads) {
  double *part = kpcn_alloc(rows * sizeof(double), "loss row partials");
  if (!part) return kpcn_last_status();
  const double inv_n = 1.0 / ((double)rows * (double)w);
  const double eps = s->rel_eps;
  long long nrows = (long long)rows;
#pragma omp parallel for num_threads(nthreads) schedule(static)
  for (long long r = 0; r < nrows; r++) {
    const float *xr = x + (size_t)r * w, *yr = y + (size_t)r * w;
    float *gr = grad ? grad + (size_t)r * w : NULL;
    double acc = 0.0;
    for (size_t i = 0; i < w; i++) {
      double d = (double)xr[i] - (double)yr[i], v, g;
      switch (kind) {
      case KPCN_LOSS_L1:
        v = fabs(d);
        g = d > 0 ? 1.0 : (d < 0 ? -1.0 : 0.0);
        break;
      case KPCN_LOSS_L2:
        v = d * d;
        g = 2.0 * d;
        break;
      case KPCN_LOSS_RELMSE:
      case KPCN_LOSS_RELMSE_SG: { /* reference's or (stop-gradient) prediction's square */
        double r = kind == KPCN_LOSS_RELMSE ? (double)yr[i] : (double)xr[i];
        double den = r * r + eps;
        v = d * d / den;
        g = 2.0 * d / den;
        break;
      }
      default: { /* RELL1, RELL1_SG: the reference's or (stop-gradient) prediction's magnitude */
        double den = fabs(kind == KPCN_LOSS_RELL1 ? (double)yr[i] : (double)xr[i]) + eps;
        v = fabs(d) / den;
        g = (d > 0 ? 1.0 : (d < 0 ? -1.0 : 0.0)) / den;
        break;
      }
      }
      acc += v;
      if (gr) gr[i] = (float)(g * inv_n);
    }
    part[r] = acc;
  }
  *value = ordered_sum(part, rows) * inv_n;
  free(part);
  return KPCN_OK;
}

/* ---- SSIM (Wang 2004) with a separable Gaussian window, "valid" positions only
 * (the window never leaves the image, like Wang's MATLAB reference with 'valid'
 * filtering), so patch borders do not bias the loss. ---- */

static void gauss_weights(int win, double sigma, double *g) {
  double sum = 0.0;
  int r = win / 2;
  for (int i = 0; i < win; i++) {
    g[i] = exp(-(double)((i - r) * (i - r)) / (2.0 * sigma * sigma));
    sum += g[i];
  }
  for (int i = 0; i < win; i++)
    g[i] /= sum;
}

/* Valid correlation: out[(h-win+1) x (w-win+1)] = sum_ij g_i g_j in[y+i][x+j].
 * tmp holds h x (w-win+1) doubles. */
static void filt_valid(const double *in, int h, int w, const double *g, int win, double *tmp,
                       double *out) {
  int ow = w - win + 1, oh = h - win + 1;
  for (int yy = 0; yy < h; yy++)
    for (int xx = 0; xx < ow; xx++) {
      double a = 0.0;
      for (int j = 0; j < win; j++)
        a += g[j] * in[(size_t)yy * w + xx + j];
      tmp[(size_t)yy * ow + xx] = a;
    }
  for (int yy = 0; yy < oh; yy++)
    for (int xx = 0; xx < ow; xx++) {
      double a = 0.0;
      for (int i = 0; i < win; i++)
        a += g[i] * tmp[(size_t)(yy + i) * ow + xx];
      out[(size_t)yy * ow + xx] = a;
    }
}

/* Adjoint of filt_valid: out[h x w] = sum over window positions p covering q of
 * g(q-p) in[p]. tmp holds (h-win+1) x w doubles. */
static void filt_adjoint(const double *in, int h, int w, const double *g, int win, double *tmp,
                         double *out) {
  int ow = w - win + 1, oh = h - win + 1;
  for (int yy = 0; yy < oh; yy++)
    for (int xx = 0; xx < w; xx++) {
      double a = 0.0;
      int j0 = xx - (ow - 1) > 0 ? xx - (ow - 1) : 0, j1 = xx < win - 1 ? xx : win - 1;
      for (int j = j0; j <= j1; j++)
        a += g[j] * in[(size_t)yy * ow + (xx - j)];
      tmp[(size_t)yy * w + xx] = a;
    }
  for (int yy = 0; yy < h; yy++) {
    int i0 = yy - (oh - 1) > 0 ? yy - (oh - 1) : 0, i1 = yy < win - 1 ? yy : win - 1;
    for (int xx = 0; xx < w; xx++) {
      double a = 0.0;
      for (int i = i0; i <= i1; i++)
        a += g[i] * tmp[(size_t)(yy - i) * w + xx];
      out[(size_t)yy * w + xx] = a;
    }
  }
}

/* One plane: returns the sum of SSIM over its valid positions; if grad is set,
 * writes d(sum SSIM)/dx scaled by `gscale`. Uses SSIM_SCRATCH planes of h*w doubles:
 * 5 product planes, 5 window-statistic maps, 1 filter temp, 1 adjoint output. */
#define SSIM_SCRATCH 12
static double ssim_plane(const float *x, const float *y, int h, int w, const double *g, int win,
                         double c1, double c2, float *grad, double gscale, double *scr) {
  size_t n = (size_t)h * w;
  int ow = w - win + 1, oh = h - win + 1;
  size_t m = (size_t)oh * ow;
  double *px = scr, *py = scr + n, *pxx = scr + 2 * n, *pyy = scr + 3 * n, *pxy = scr + 4 * n;
  double *mx = scr + 5 * n, *my = scr + 6 * n, *sxx = scr + 7 * n, *syy = scr + 8 * n,
         *sxy = scr + 9 * n;
  double *tmp = scr + 10 * n;
  for (size_t i = 0; i < n; i++) {
    px[i] = x[i];
    py[i] = y[i];
    pxx[i] = px[i] * px[i];
    pyy[i] = py[i] * py[i];
    pxy[i] = px[i] * py[i];
  }
  filt_valid(px, h, w, g, win, tmp, mx);
  filt_valid(py, h, w, g, win, tmp, my);
  filt_valid(pxx, h, w, g, win, tmp, sxx);
  filt_valid(pyy, h, w, g, win, tmp, syy);
  filt_valid(pxy, h, w, g, win, tmp, sxy);
  double total = 0.0;
  /* Re-use px/py/pxx planes as the coefficient maps alpha, beta, gamma of
   * dS_p/dx_q = g(q-p) * (alpha_p + beta_p x_q + gamma_p y_q). */
  double *al = px, *be = py, *ga = pxx;
  for (size_t p = 0; p < m; p++) {
    double ux = mx[p], uy = my[p];
    double vx = sxx[p] - ux * ux, vy = syy[p] - uy * uy, cxy = sxy[p] - ux * uy;
    double A1 = 2 * ux * uy + c1, A2 = 2 * cxy + c2, B1 = ux * ux + uy * uy + c1, B2 = vx + vy + c2;
    double S = (A1 * A2) / (B1 * B2);
    total += S;
    if (grad) {
      double dmu = S * (2 * uy / A1 - 2 * ux / B1); /* dS/dmu_x */
      double dvx = -S / B2;                         /* dS/dsigma_x^2 */
      double dcv = 2 * S / A2;                      /* dS/dsigma_xy */
      al[p] = dmu - 2 * ux * dvx - uy * dcv;
      be[p] = 2 * dvx;
      ga[p] = dcv;
    }
  }
  if (grad) {
    double *fa = pyy, *fb = pxy, *fc = scr + 11 * n; /* pyy/pxy are free by now */
    filt_adjoint(al, h, w, g, win, tmp, fa);
    filt_adjoint(be, h, w, g, win, tmp, fb);
    filt_adjoint(ga, h, w, g, win, tmp, fc);
    for (size_t q = 0; q < n; q++)
      grad[q] = (float)(gscale * (fa[q] + fb[q] * (double)x[q] + fc[q] * (double)y[q]));
  }
  return total;
}

static kpcn_status ssim_loss(const kpcn_loss_settings *s, const float *x, const float *y,
                             int planes, int w, int h, float *grad, double *value, int nthreads) {
  int win = s->ssim_window;
  if (win < 1 || win % 2 == 0 || win > w || win > h)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "SSIM loss: window %d must be odd and no larger than the %dx%d image", win, w,
                     h);
  if (!(s->ssim_sigma > 0))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "SSIM loss: sigma must be > 0");
  double g[257];
  if (win > 257) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "SSIM loss: window %d > 257", win);
  gauss_weights(win, s->ssim_sigma, g);
  double c1 = (s->ssim_k1 * (double)s->ssim_range) * (s->ssim_k1 * (double)s->ssim_range);
  double c2 = (s->ssim_k2 * (double)s->ssim_range) * (s->ssim_k2 * (double)s->ssim_range);
  size_t n = (size_t)w * h;
  size_t m = (size_t)(w - win + 1) * (h - win + 1);
  double *part = kpcn_alloc((size_t)planes * sizeof(double), "SSIM partials");
  if (!part) return kpcn_last_status();
  int nt = kpcn_resolve_threads(nthreads);
  if (nt > planes) nt = planes;
  double *scr = kpcn_alloc((size_t)nt * SSIM_SCRATCH * n * sizeof(double), "SSIM scratch");
  if (!scr) {
    free(part);
    return kpcn_last_status();
  }
  double gscale = -1.0 / ((double)m * planes); /* loss = 1 - mean SSIM */
#pragma omp parallel for num_threads(nt) schedule(static)
  for (int p = 0; p < planes; p++) {
    int t = omp_get_thread_num();
    part[p] =
        ssim_plane(x + (size_t)p * n, y + (size_t)p * n, h, w, g, win, c1, c2,
                   grad ? grad + (size_t)p * n : NULL, gscale, scr + (size_t)t * SSIM_SCRATCH * n);
  }
  *value = 1.0 - ordered_sum(part, (size_t)planes) / ((double)m * planes);
  free(scr);
  free(part);
  return KPCN_OK;
}

kpcn_status kpcn_loss_compute(kpcn_loss_kind kind, const kpcn_loss_settings *settings,
                              const float *pred, const float *ref, int n, int c, int w, int h,
                              float *grad, double *value, int nthreads) {
  if (!pred || !ref || !value)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_loss_compute: NULL pred/ref/value");
  if (n <= 0 || c <= 0 || w <= 0 || h <= 0)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_loss_compute: bad shape %dx%dx%dx%d", n, c, h,
                     w);
  kpcn_loss_settings def;
  if (!settings) {
    kpcn_loss_settings_defaults(&def);
    settings = &def;
  }
  int nt = kpcn_resolve_threads(nthreads);
  size_t planes = (size_t)n * c;
  switch (kind) {
  case KPCN_LOSS_L1:
  case KPCN_LOSS_L2:
  case KPCN_LOSS_RELMSE:
  case KPCN_LOSS_RELMSE_SG:
  case KPCN_LOSS_RELL1:
  case KPCN_LOSS_RELL1_SG:
    return pixel_loss(kind, settings, pred, ref, planes * (size_t)h, (size_t)w, grad, value, nt);
  case KPCN_LOSS_SSIM: return ssim_loss(settings, pred, ref, (int)planes, w, h, grad, value, nt);
  }
  return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_loss_compute: unknown loss kind %d", (int)kind);
}
