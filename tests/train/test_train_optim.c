/* Adam against an independent double-precision transcription of Kingma & Ba's
 * Algorithm 1, learning-rate schedule, clipping, Xavier bounds/moments, RNG, plot PNG. */
#include "kpcn/train.h"
#include "testutil.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static void test_adam(void) {
  enum { N1 = 37, N2 = 5000, N = N1 + N2, STEPS = 25 };
  static float p[N], g[N];
  static double pd[N], md[N], vd[N];
  unsigned st = 11;
  for (int i = 0; i < N; i++)
    pd[i] = p[i] = kt_randf(&st) - 0.5f;
  kpcn_adam_settings s;
  kpcn_adam_settings_defaults(&s);
  s.lr = 1e-2;
  s.decay_every = 10; /* make the decay visible in 25 steps */
  kpcn_adam *a = NULL;
  CHECK(kpcn_adam_create(&a, &s, N) == KPCN_OK);
  /* the second block learns at 3x the rate (lr_scale); the first reads 0 as 1 */
  kpcn_param_block blk[2] = {{p, g, N1, 0.0f}, {p + N1, g + N1, N2, 3.0f}};
  double maxerr = 0;
  for (int t = 1; t <= STEPS; t++) {
    for (int i = 0; i < N; i++)
      g[i] = (float)(sin(0.37 * i + t) * (1 + i % 3)); /* any gradient */
    CHECK(kpcn_adam_step(a, blk, 2, t % 2 ? 1 : 2, NULL) == KPCN_OK);
    double lr = 1e-2 * pow(0.96, (t - 1) / 10.0);
    for (int i = 0; i < N; i++) {
      md[i] = 0.9 * md[i] + 0.1 * g[i];
      vd[i] = 0.999 * vd[i] + 0.001 * (double)g[i] * g[i];
      double mh = md[i] / (1 - pow(0.9, t)), vh = vd[i] / (1 - pow(0.999, t));
      pd[i] -= (i < N1 ? lr : 3 * lr) * mh / (sqrt(vh) + 1e-8);
    }
  }
  for (int i = 0; i < N; i++)
    maxerr = kt_worst(maxerr, fabs(pd[i] - p[i]));
  printf("adam vs double reference (one block at 3x lr): max abs err %.3g\n", maxerr);
  CHECK(maxerr < 6e-5); /* float state vs double reference over 25 steps of size ~3e-2 */
  CHECK(kpcn_adam_steps(a) == STEPS);
  /* mismatched block total is an error */
  CHECK(kpcn_adam_step(a, blk, 1, 1, NULL) == KPCN_ERR_SIZE_MISMATCH);
  /* non-finite gradient rejected, nothing updated */
  float keep = p[3];
  g[7] = NAN;
  CHECK(kpcn_adam_step(a, blk, 2, 1, NULL) == KPCN_ERR_NONFINITE);
  CHECK(p[3] == keep && kpcn_adam_steps(a) == STEPS);
  kpcn_adam_destroy(a);
}

static void test_clip_and_schedule(void) {
  float p[3] = {0, 0, 0}, g[3] = {3, 4, 0}; /* ||g|| = 5 */
  kpcn_adam_settings s;
  kpcn_adam_settings_defaults(&s);
  s.clip_norm = 1.0;
  s.lr = 0.1;
  kpcn_adam *a;
  CHECK(kpcn_adam_create(&a, &s, 3) == KPCN_OK);
  kpcn_param_block b = {p, g, 3, 0.0f};
  double norm = 0;
  CHECK(kpcn_adam_step(a, &b, 1, 0, &norm) == KPCN_OK);
  CHECK_NEAR(norm, 5.0, 1e-12);
  /* first Adam step moves each coordinate by lr*sign(g) (up to eps): clipping scales g
   * uniformly, so check the moments instead: m = 0.1 * g * (1/5) */
  CHECK_NEAR(kpcn_adam_moment1(a)[0], 0.1 * 0.6, 1e-7);
  CHECK_NEAR(kpcn_adam_moment1(a)[1], 0.1 * 0.8, 1e-7);
  CHECK_NEAR(p[0], -0.1, 1e-6);
  kpcn_adam_destroy(a);
  kpcn_adam_settings_defaults(&s);
  CHECK_NEAR(kpcn_adam_lr_at(&s, 0), 1e-3, 1e-15);
  CHECK_NEAR(kpcn_adam_lr_at(&s, 100000), 0.96e-3, 1e-15);
  CHECK_NEAR(kpcn_adam_lr_at(&s, 50000), 1e-3 * sqrt(0.96), 1e-15);
  s.staircase = 1;
  CHECK_NEAR(kpcn_adam_lr_at(&s, 199999), 0.96e-3, 1e-15);
  s.lr = -1;
  CHECK(kpcn_adam_create(&a, &s, 3) == KPCN_ERR_INVALID_ARGUMENT);
}

static void test_xavier_rng(void) {
  enum { N = 200000 };
  static float w[N];
  kpcn_rng r, r2;
  kpcn_rng_seed(&r, 42);
  r2 = r;
  CHECK(kpcn_xavier_uniform(w, N, 100 * 25, 100 * 25, &r) == KPCN_OK);
  double a = sqrt(6.0 / 5000.0), mean = 0, var = 0, mx = 0;
  for (int i = 0; i < N; i++)
    mean += w[i], var += (double)w[i] * w[i], mx = fmax(mx, fabs(w[i]));
  mean /= N, var /= N;
  CHECK(mx <= a);
  CHECK(mx > 0.99 * a);
  CHECK_NEAR(mean, 0.0, 5 * a / sqrt(3.0 * N));
  CHECK_CLOSE(var, a * a / 3, 0.02, 0); /* U(-a,a) variance = a^2/3 = 2/(fan_in+fan_out) */
  /* same seed, same sequence (two generators seeded apart), other seeds other sequences;
   * the state is the whole generator (a copy continues the same sequence) */
  kpcn_rng_next(&r2);
  kpcn_rng r3 = r2;
  CHECK(kpcn_rng_next(&r2) == kpcn_rng_next(&r3));
  kpcn_rng s1, s2, s3;
  kpcn_rng_seed(&s1, 7);
  kpcn_rng_seed(&s2, 7);
  kpcn_rng_seed(&s3, 8);
  int same = 1, differ = 0;
  for (int i = 0; i < 16; i++) {
    const uint64_t v1 = kpcn_rng_next(&s1), v2 = kpcn_rng_next(&s2), v3 = kpcn_rng_next(&s3);
    same &= v1 == v2;
    differ += v1 != v3;
  }
  CHECK(same && differ == 16);
  unsigned hist[10] = {0};
  for (int i = 0; i < 100000; i++)
    hist[kpcn_rng_below(&r, 10)]++;
  for (int i = 0; i < 10; i++)
    CHECK(hist[i] > 9500 && hist[i] < 10500);
}

static void test_plot(void) {
  double x[50], y[50], y2[50];
  for (int i = 0; i < 50; i++)
    x[i] = i * 100, y[i] = exp(-i / 10.0), y2[i] = 0.5 * y[i] + 0.01;
  kpcn_plot_series s[2] = {{"train l1", x, y, 50}, {"val relmse", x, y2, 50}};
  kpcn_plot_settings ps;
  kpcn_plot_settings_defaults(&ps);
  ps.log_y = 1;
  ps.title = "curves";
  ps.xlabel = "iteration";
  ps.ylabel = "loss";
  const char *path = kt_tmpfile("plot.png");
  CHECK(kpcn_plot_png(path, &ps, s, 2) == KPCN_OK);
  FILE *f = fopen(path, "rb");
  CHECK(f != NULL);
  if (f) {
    unsigned char h[24];
    CHECK(fread(h, 1, 24, f) == 24);
    fclose(f);
    CHECK(memcmp(h, "\x89PNG\r\n\x1a\n", 8) == 0);
    unsigned w = (unsigned)h[16] << 24 | h[17] << 16 | h[18] << 8 | h[19];
    unsigned hh = (unsigned)h[20] << 24 | h[21] << 16 | h[22] << 8 | h[23];
    CHECK(w == 800 && hh == 500);
  }
  CHECK(kpcn_plot_png("/nonexistent-dir/x.png", &ps, s, 2) == KPCN_ERR_IO);
  CHECK(strstr(kpcn_last_error(), "/nonexistent-dir/x.png") != NULL);
}

int main(void) {
  test_adam();
  test_clip_and_schedule();
  test_xavier_rng();
  test_plot();
  return kt_summary("train_optim");
}
