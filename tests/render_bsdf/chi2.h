/* Pearson chi-square goodness-of-fit helpers for the sampling tests (Mitsuba/pbrt style):
 * cells with small expected counts are pooled, a cell with expected 0 but observed > 0 fails
 * outright, and the p-value comes from the regularised upper incomplete gamma function. */
#ifndef KPCN_TEST_CHI2_H
#define KPCN_TEST_CHI2_H

#include <math.h>
#include <stdio.h>
#include <stdlib.h>

/* Q(a, x) = Gamma(a, x) / Gamma(a): series for x < a + 1, Lentz continued fraction otherwise. */
static double kt_gamma_q(double a, double x) {
  if (x <= 0.0) return 1.0;
  double gln = lgamma(a);
  if (x < a + 1.0) {
    double ap = a, sum = 1.0 / a, del = sum;
    for (int n = 0; n < 100000; ++n) {
      ap += 1.0;
      del *= x / ap;
      sum += del;
      if (fabs(del) < fabs(sum) * 1e-15) break;
    }
    return 1.0 - sum * exp(-x + a * log(x) - gln);
  }
  double b = x + 1.0 - a, c = 1.0 / 1e-300, d = 1.0 / b, h = d;
  for (int i = 1; i < 100000; ++i) {
    double an = -i * (i - a);
    b += 2.0;
    d = an * d + b;
    if (fabs(d) < 1e-300) d = 1e-300;
    c = b + an / c;
    if (fabs(c) < 1e-300) c = 1e-300;
    d = 1.0 / d;
    double del = d * c;
    h *= del;
    if (fabs(del - 1.0) < 1e-15) break;
  }
  return exp(-x + a * log(x) - gln) * h;
}

/* Returns the p-value of observed vs expected over n cells (expected need not sum to the
 * observed total exactly; both should be counts of the same N). *why gets a reason on an
 * impossible cell. min_expected: cells below it are pooled (5 is customary). */
static double kt_chi2_test(const double *obs, const double *expd, int n, double min_expected,
                           const char **why) {
  double chsq = 0.0, pool_o = 0.0, pool_e = 0.0;
  double small_o = 0.0, small_e = INFINITY; /* the regular cell of least expected count */
  int dof = 0;
  *why = NULL;
  for (int i = 0; i < n; ++i) {
    if (expd[i] <= 0.0) {
      if (obs[i] > 0.0) {
        *why = "samples landed in a cell of zero expected probability";
        return 0.0;
      }
      continue;
    }
    if (expd[i] < min_expected) {
      pool_o += obs[i];
      pool_e += expd[i];
    } else {
      double d = obs[i] - expd[i];
      chsq += d * d / expd[i];
      dof++;
      if (expd[i] < small_e) small_e = expd[i], small_o = obs[i];
    }
  }
  if (pool_e > 0.0) {
    if (pool_e < min_expected && dof > 0) {
      /* too small even pooled: merged with the smallest regular cell, so the low-probability
       * cells always count (a pool expected at 4.9 that got 240 samples, or none, was left
       * out unless it got 50 times its share) and the merged cell is large enough for the
       * chi-square approximation */
      double d = small_o - small_e;
      chsq -= d * d / small_e;
      small_o += pool_o, small_e += pool_e;
      d = small_o - small_e;
      chsq += d * d / small_e;
    } else {
      double d = pool_o - pool_e;
      chsq += d * d / pool_e;
      dof++;
    }
  }
  dof -= 1;
  if (dof < 1) return 1.0;
  return kt_gamma_q(0.5 * dof, 0.5 * chsq);
}

#endif
