/* Losses: values against naive independent formulas (written here from the
 * definitions, SSIM with a direct 2-D window sum in double), gradients against
 * double-precision central finite differences, determinism across thread counts. */
#include "kpcn/metrics.h"
#include "kpcn/train.h"
#include "testutil.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Independent double-precision loss in plain loops (no separable filters). */
/* xden: the prediction relmse-sg divides by (its stop-gradient copy; NULL = x itself) */
static double naive_loss(kpcn_loss_kind k, const double *x, const float *y, int planes, int w,
                         int h, int win, const double *xden) {
  size_t n = (size_t)w * h;
  if (k != KPCN_LOSS_SSIM) {
    double s = 0;
    for (size_t i = 0; i < n * planes; i++) {
      double d = x[i] - y[i];
      switch (k) {
      case KPCN_LOSS_L1: s += fabs(d); break;
      case KPCN_LOSS_L2: s += d * d; break;
      case KPCN_LOSS_RELMSE: s += d * d / ((double)y[i] * y[i] + 0.01); break;
      case KPCN_LOSS_RELMSE_SG: {
        double xs = xden ? xden[i] : x[i];
        s += d * d / (xs * xs + 0.01);
        break;
      }
      case KPCN_LOSS_RELL1_SG: s += fabs(d) / (fabs(xden ? xden[i] : x[i]) + 0.01); break;
      default: s += fabs(d) / (fabs((double)y[i]) + 0.01); break;
      }
    }
    return s / (double)(n * planes);
  }
  double g[64], gs = 0, sigma = 1.5;
  for (int i = 0; i < win; i++) {
    double d = i - win / 2;
    g[i] = exp(-d * d / (2 * sigma * sigma));
    gs += g[i];
  }
  double c1 = 1e-4, c2 = 9e-4, tot = 0;
  int cnt = 0;
  for (int p = 0; p < planes; p++) {
    const double *xp = x + p * n;
    const float *yp = y + p * n;
    for (int oy = 0; oy + win <= h; oy++)
      for (int ox = 0; ox + win <= w; ox++) {
        double mx = 0, my = 0, xx = 0, yy = 0, xy = 0;
        for (int i = 0; i < win; i++)
          for (int j = 0; j < win; j++) {
            double wt = g[i] * g[j] / (gs * gs);
            double a = xp[(oy + i) * w + ox + j], b = yp[(oy + i) * w + ox + j];
            mx += wt * a, my += wt * b;
          }
        for (int i = 0; i < win; i++)
          for (int j = 0; j < win; j++) {
            double wt = g[i] * g[j] / (gs * gs);
            double a = xp[(oy + i) * w + ox + j] - mx, b = yp[(oy + i) * w + ox + j] - my;
            xx += wt * a * a, yy += wt * b * b, xy += wt * a * b;
          }
        tot += (2 * mx * my + c1) * (2 * xy + c2) / ((mx * mx + my * my + c1) * (xx + yy + c2));
        cnt++;
      }
  }
  return 1.0 - tot / cnt;
}

static void check_loss(kpcn_loss_kind k, int planes, int w, int h, int win, unsigned seed) {
  size_t n = (size_t)planes * w * h;
  float *x = malloc(n * sizeof(float)), *y = malloc(n * sizeof(float));
  float *g = malloc(n * sizeof(float)), *g1 = malloc(n * sizeof(float));
  double *xd = malloc(n * sizeof(double));
  unsigned st = seed;
  for (size_t i = 0; i < n; i++) {
    y[i] = kt_randf(&st) * 1.5f - 0.2f;
    /* keep |x - y| away from 0 so L1's kink is not crossed by the FD step */
    float d = 0.05f + 0.3f * kt_randf(&st);
    x[i] = y[i] + (kt_randf(&st) < 0.5f ? -d : d);
    xd[i] = x[i];
  }
  kpcn_loss_settings ls;
  kpcn_loss_settings_defaults(&ls);
  ls.ssim_window = win;
  double v = 0, v1 = 0;
  CHECK(kpcn_loss_compute(k, &ls, x, y, 1, planes, w, h, g, &v, 2) == KPCN_OK);
  double ref = naive_loss(k, xd, y, planes, w, h, win, NULL);
  double *x0 = malloc(n * sizeof(double)); /* relmse-sg: denominator frozen at the start */
  memcpy(x0, xd, n * sizeof(double));
  CHECK_CLOSE(v, ref, 1e-9, 1e-12);
  /* thread-count independence, bit for bit */
  CHECK(kpcn_loss_compute(k, &ls, x, y, 1, planes, w, h, g1, &v1, 1) == KPCN_OK);
  CHECK(v == v1);
  CHECK(memcmp(g, g1, n * sizeof(float)) == 0);
  /* central differences on the double-precision naive formula at sampled elements */
  double maxrel = 0;
  for (int t = 0; t < 40; t++) {
    size_t i = (size_t)(kt_randf(&st) * (float)n) % n;
    double hstep = 1e-5, keep = xd[i];
    xd[i] = keep + hstep;
    double fp = naive_loss(k, xd, y, planes, w, h, win, x0);
    xd[i] = keep - hstep;
    double fm = naive_loss(k, xd, y, planes, w, h, win, x0);
    xd[i] = keep;
    double fd = (fp - fm) / (2 * hstep);
    double err = fabs(fd - g[i]) / (fabs(fd) + 1e-3 * (1.0 / (double)n) + 1e-12);
    maxrel = kt_worst(maxrel, err);
  }
  if (maxrel > 2e-3) fprintf(stderr, "loss %s: max rel grad err %g\n", kpcn_loss_name(k), maxrel);
  CHECK(maxrel <= 2e-3);
  free(x), free(y), free(g), free(g1), free(xd), free(x0);
}

int main(void) {
  for (int k = KPCN_LOSS_L1; k <= KPCN_LOSS_RELL1; k++)
    check_loss((kpcn_loss_kind)k, 3, 13, 9, 11, 7u + k);
  check_loss(KPCN_LOSS_RELMSE_SG, 3, 13, 9, 11, 17u);
  check_loss(KPCN_LOSS_RELL1_SG, 3, 13, 9, 11, 19u);

  /* Bias: one prediction x for two equally likely references 0.5 and 1.5 (a pixel whose
   * clean value the input leaves uncertain). relmse-sg's gradient vanishes at their mean
   * x = 1; relmse's is positive there (descent lowers x: the dark bias) and vanishes at
   * sum(y/(y^2+eps)) / sum(1/(y^2+eps)). */
  {
    float xb[2] = {1.0f, 1.0f}, yb[2] = {0.5f, 1.5f}, gb[2];
    double vb;
    CHECK(kpcn_loss_compute(KPCN_LOSS_RELMSE_SG, NULL, xb, yb, 1, 1, 2, 1, gb, &vb, 1) == KPCN_OK);
    CHECK_NEAR((double)gb[0] + gb[1], 0.0, 1e-7);
    CHECK(kpcn_loss_compute(KPCN_LOSS_RELMSE, NULL, xb, yb, 1, 1, 2, 1, gb, &vb, 1) == KPCN_OK);
    CHECK((double)gb[0] + gb[1] > 0.1);
    double a = 1.0 / (0.25 + 0.01), b = 1.0 / (2.25 + 0.01), xm = (0.5 * a + 1.5 * b) / (a + b);
    xb[0] = xb[1] = (float)xm;
    CHECK(kpcn_loss_compute(KPCN_LOSS_RELMSE, NULL, xb, yb, 1, 1, 2, 1, gb, &vb, 1) == KPCN_OK);
    CHECK_NEAR((double)gb[0] + gb[1], 0.0, 1e-6);
    kpcn_loss_kind kk;
    CHECK(kpcn_loss_parse("relmse-sg", &kk) == KPCN_OK && kk == KPCN_LOSS_RELMSE_SG);
    CHECK(kpcn_loss_parse("rell1-sg", &kk) == KPCN_OK && kk == KPCN_LOSS_RELL1_SG);
  }
  check_loss(KPCN_LOSS_SSIM, 2, 16, 14, 11, 3u); /* 6x4 valid positions, full window */
  check_loss(KPCN_LOSS_SSIM, 3, 12, 12, 7, 5u);  /* the small-window variant */
  check_loss(KPCN_LOSS_SSIM, 1, 5, 5, 5, 9u);    /* window == image: one position */

  /* identical images: SSIM loss 0, zero gradient; L1 exactly 0 */
  float a[4 * 20 * 20], gr[4 * 20 * 20];
  unsigned st = 1;
  for (int i = 0; i < 4 * 400; i++)
    a[i] = kt_randf(&st);
  double v = -1;
  CHECK(kpcn_loss_compute(KPCN_LOSS_SSIM, NULL, a, a, 2, 2, 20, 20, gr, &v, 0) == KPCN_OK);
  CHECK_NEAR(v, 0.0, 1e-12);
  double gmax = 0;
  for (int i = 0; i < 4 * 400; i++)
    gmax = kt_worst(gmax, fabs(gr[i]));
  CHECK(gmax < 1e-9);
  CHECK(kpcn_loss_compute(KPCN_LOSS_L1, NULL, a, a, 2, 2, 20, 20, gr, &v, 0) == KPCN_OK);
  CHECK(v == 0.0);

  /* SSIM value vs the metrics module (skimage-compatible, interior = valid positions):
   * 1 - loss must equal the metric on a 3-channel 30x26 image. */
  {
    enum { W = 30, H = 26 };
    static float x[3 * W * H], y[3 * W * H];
    unsigned s2 = 77;
    for (int i = 0; i < 3 * W * H; i++) {
      y[i] = kt_randf(&s2);
      x[i] = y[i] + 0.2f * (kt_randf(&s2) - 0.5f);
    }
    double lv;
    kpcn_metric_result r;
    CHECK(kpcn_loss_compute(KPCN_LOSS_SSIM, NULL, x, y, 1, 3, W, H, NULL, &lv, 0) == KPCN_OK);
    CHECK(kpcn_metric_planar(KPCN_METRIC_SSIM, x, y, W, H, 3, NULL, &r, NULL) == KPCN_OK);
    CHECK_NEAR(1.0 - lv, r.value, 1e-6);
    CHECK(kpcn_metric_planar(KPCN_METRIC_RELMSE, x, y, W, H, 3, NULL, &r, NULL) == KPCN_OK);
    CHECK(kpcn_loss_compute(KPCN_LOSS_RELMSE, NULL, x, y, 1, 3, W, H, NULL, &lv, 0) == KPCN_OK);
    CHECK_NEAR(lv, r.value, 1e-9 * r.value);
  }

  /* errors: window larger than the image, bad names, NULLs */
  kpcn_loss_settings ls;
  kpcn_loss_settings_defaults(&ls);
  CHECK(kpcn_loss_compute(KPCN_LOSS_SSIM, &ls, a, a, 1, 1, 8, 8, NULL, &v, 0) ==
        KPCN_ERR_INVALID_ARGUMENT);
  CHECK(strstr(kpcn_last_error(), "window") != NULL);
  kpcn_loss_kind k;
  CHECK(kpcn_loss_parse("huber", &k) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(strstr(kpcn_last_error(), "huber") != NULL);
  CHECK(kpcn_loss_parse("mse", &k) == KPCN_OK && k == KPCN_LOSS_L2);
  CHECK(kpcn_loss_compute(KPCN_LOSS_L1, NULL, NULL, a, 1, 1, 8, 8, NULL, &v, 0) != KPCN_OK);
  return kt_summary("train_loss");
}
