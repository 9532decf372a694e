/* The trainer's batch assembly, checked against the definitions: the wiring of targets,
 * inputs and albedo, and the two input conditionings a run can switch on (exposure
 * normalisation, the firefly bound), each recorded in the checkpoint so that a resume with
 * another setting is refused; the loss margin (kt_loss) against the interior's loss; and that
 * only the training split's patches are drawn. */
#include "train/train_internal.h"
#include "kpcn/train.h"
#include "testutil.h"
#include "train_fixture.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char *g_store;

static void settings(kpcn_train_settings *s, const char *out) { tf_settings(s, g_store, out); }

/* Batch wiring, checked against the definitions: recombining the stage-1 targets gives the
 * reference colour; the kernel's input is the features' colour; the albedo used for
 * recombination is the features' albedo; the diffuse and specular inputs are different
 * images. */
static void test_batch_wiring(void) {
  kpcn_train_settings s;
  settings(&s, tf_tmp("w.safetensors"));
  kpcn_trainer *t = NULL;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_OK);
  if (!t) return;
  CHECK(kt_batch_assemble(t) == KPCN_OK);
  size_t pp = (size_t)t->P * t->P, n3 = 3 * pp;
  float *c = malloc((size_t)t->N * n3 * sizeof(float));
  kpcn_recombine(t->target[0], t->target[1], t->albedo, t->arch.eps, t->N * n3, c);
  double maxrel = 0;
  for (size_t i = 0; i < t->N * n3; i++)
    maxrel = kt_worst(maxrel, fabs(c[i] - t->refc[i]) / (fabs(t->refc[i]) + 1e-3));
  CHECK(maxrel < 1e-5);
  int same_noisy = 1, same_alb = 1, same_rgb = 1;
  for (int b = 0; b < t->N; b++)
    for (int br = 0; br < 2; br++) {
      const float *f = t->feat[br] + (size_t)b * t->nfeat * pp;
      if (memcmp(f, t->noisy[br] + b * n3, n3 * sizeof(float))) same_noisy = 0;
      if (memcmp(f + 8 * pp, t->albedo + b * n3, n3 * sizeof(float))) same_alb = 0;
    }
  /* the diffuse and specular inputs are different images */
  if (memcmp(t->noisy[0], t->noisy[1], n3 * sizeof(float))) same_rgb = 0;
  CHECK(same_noisy && same_alb && !same_rgb);
  free(c);
  kpcn_trainer_destroy(t);
}

/* Runs s into `out` until tf_stop_cb stops it at iteration 2 (a checkpoint), then leaves s set
 * to resume it: the tests of settings a checkpoint must record. */
static void checkpoint_at_two(kpcn_train_settings *s, const char *out) {
  s->out_path = out;
  tf_stop_at = 2;
  s->progress = tf_stop_cb;
  int stopped = 0;
  kpcn_trainer *t = NULL;
  CHECK(kpcn_trainer_create(&t, s) == KPCN_OK);
  CHECK(t && kpcn_trainer_run(t, &stopped) == KPCN_OK && stopped == 1);
  kpcn_trainer_destroy(t);
  s->progress = NULL;
  s->resume = 1;
}

/* normalize_exposure: the same batch as without it, its noisy colour and targets at the
 * model's exposure (here set to 4x the source's): linear quantities x4, log-specular
 * expm1(.)/4 the same; recombining the targets still gives the (scaled) reference. */
static void test_batch_exposure(void) {
  kpcn_train_settings s;
  settings(&s, tf_tmp("x0.safetensors"));
  kpcn_trainer *a = NULL, *b = NULL;
  CHECK(kpcn_trainer_create(&a, &s) == KPCN_OK);
  s.out_path = tf_tmp("x1.safetensors");
  s.normalize_exposure = 1;
  CHECK(kpcn_trainer_create(&b, &s) == KPCN_OK);
  if (!a || !b) return;
  const double e = kpcn_patchstore_source(b->ps, 0)->exposure;
  CHECK(e > 0.0 && b->arch.exposure == (float)e);
  b->arch.exposure = (float)(4.0 * e);
  CHECK(kt_batch_assemble(a) == KPCN_OK && kt_batch_assemble(b) == KPCN_OK);
  const size_t n = (size_t)a->N * 3 * a->P * a->P;
  double lin = 0, spec = 0, comb = 0;
  float *c = malloc(n * sizeof(float));
  kpcn_recombine(b->target[0], b->target[1], b->albedo, b->arch.eps, n, c);
  for (size_t i = 0; i < n; i++) {
    const double r[4] = {b->noisy[0][i] / (4.0 * a->noisy[0][i]),
                         b->target[0][i] / (4.0 * a->target[0][i]), b->refc[i] / (4.0 * a->refc[i]),
                         0};
    for (int k = 0; k < 3; k++)
      if (isfinite(r[k]) && fabs(a->refc[i]) > 1e-6) lin = fmax(lin, fabs(r[k] - 1.0));
    spec = kt_worst(spec, fabs(expm1(b->noisy[1][i]) / 4.0 - expm1(a->noisy[1][i])) /
                              (1e-6 + fabs(expm1(a->noisy[1][i]))));
    spec = kt_worst(spec, fabs(expm1(b->target[1][i]) / 4.0 - expm1(a->target[1][i])) /
                              (1e-6 + fabs(expm1(a->target[1][i]))));
    comb = kt_worst(comb, fabs(c[i] - b->refc[i]) / (fabs(b->refc[i]) + 1e-3));
  }
  printf("normalize_exposure x4: linear %.2g, specular %.2g, recombined %.2g\n", lin, spec, comb);
  CHECK(lin < 1e-5 && spec < 1e-4 && comb < 1e-5);
  free(c);
  kpcn_trainer_destroy(a);
  kpcn_trainer_destroy(b);
  /* the checkpoint records the setting: resuming it without (or the reverse) is refused */
  checkpoint_at_two(&s, tf_tmp("x2.safetensors"));
  s.normalize_exposure = 0;
  CHECK(kpcn_trainer_create(&b, &s) == KPCN_ERR_FORMAT);
  CHECK(strstr(kpcn_last_error(), "exposure") != NULL);
  s.normalize_exposure = 1;
  CHECK(kpcn_trainer_create(&b, &s) == KPCN_OK && kpcn_trainer_iteration(b) == 2);
  kpcn_trainer_destroy(b);
}

/* firefly: the bound lowers only the diffuse branch's noisy colour, at the pixels it bounds
 * (never raises one), and leaves the specular branch, the albedo and every target alone; the
 * checkpoint records the ratio, so resuming with another (or without) is refused. */
static void test_batch_firefly(void) {
  kpcn_train_settings s;
  settings(&s, tf_tmp("f0.safetensors"));
  kpcn_trainer *a = NULL, *b = NULL;
  CHECK(kpcn_trainer_create(&a, &s) == KPCN_OK);
  s.out_path = tf_tmp("f1.safetensors");
  s.firefly = 1.0; /* the tightest ratio: the store's +-30 % noise (relative variance 0.44)
                      has local maxima */
  CHECK(kpcn_trainer_create(&b, &s) == KPCN_OK);
  if (!a || !b) return;
  CHECK(kt_batch_assemble(a) == KPCN_OK && kt_batch_assemble(b) == KPCN_OK);
  const size_t n = (size_t)a->N * 3 * a->P * a->P;
  size_t lowered = 0;
  int raised = 0, other = 0;
  for (size_t i = 0; i < n; i++) {
    lowered += b->noisy[0][i] < a->noisy[0][i];
    raised |= b->noisy[0][i] > a->noisy[0][i];
    other |= b->noisy[1][i] != a->noisy[1][i] || b->target[0][i] != a->target[0][i] ||
             b->target[1][i] != a->target[1][i] || b->albedo[i] != a->albedo[i] ||
             b->refc[i] != a->refc[i];
  }
  printf("firefly ratio 1: %zu of %zu diffuse colour values lowered\n", lowered, n);
  CHECK(lowered > 0 && lowered < n / 4 && !raised && !other);
  kpcn_trainer_destroy(a);
  kpcn_trainer_destroy(b);
  s.firefly = 0.5;
  CHECK(kpcn_trainer_create(&b, &s) == KPCN_ERR_INVALID_ARGUMENT && !b);
  CHECK(strstr(kpcn_last_error(), "firefly") != NULL);
  s.firefly = 4.0;
  checkpoint_at_two(&s, tf_tmp("f2.safetensors"));
  const double other_ratio[2] = {0.0, 3.0};
  for (int k = 0; k < 2; k++) {
    s.firefly = other_ratio[k];
    CHECK(kpcn_trainer_create(&b, &s) == KPCN_ERR_FORMAT);
    CHECK(strstr(kpcn_last_error(), "firefly") != NULL);
  }
  s.firefly = 4.0;
  CHECK(kpcn_trainer_create(&b, &s) == KPCN_OK && kpcn_trainer_iteration(b) == 2);
  kpcn_trainer_destroy(b);
}

/* Loss margin: with --loss-margin 2 the loss is that of the (P-4)^2 interior alone and its
 * gradient vanishes in the 2-pixel band. Truths: the mean of the per-element loss over the
 * interior in plain double loops (the definitions, as in test_train_loss), its central finite
 * differences w.r.t. the full-size prediction, and for SSIM the loss of the arrays cropped here. */
static double margin_naive(kpcn_loss_kind k, const double *x, const float *y, int planes, int P,
                           int m) {
  double s = 0;
  size_t cnt = 0;
  for (int p = 0; p < planes; p++)
    for (int r = m; r < P - m; r++)
      for (int c = m; c < P - m; c++, cnt++) {
        size_t i = ((size_t)p * P + r) * P + c;
        double d = x[i] - y[i];
        s += k == KPCN_LOSS_L1   ? fabs(d)
             : k == KPCN_LOSS_L2 ? d * d
                                 : d * d / (y[i] * (double)y[i] + 0.01);
      }
  return s / (double)cnt;
}

static void test_loss_margin(void) {
  enum { M = 2 };
  kpcn_train_settings s;
  settings(&s, tf_tmp("m.safetensors"));
  s.loss_margin = M;
  kpcn_trainer *t = NULL;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_OK);
  if (!t) return;
  const int P = t->P, Q = P - 2 * M, planes = t->N * 3;
  const size_t n = (size_t)planes * P * P, nq = (size_t)planes * Q * Q;
  float *x = malloc(n * sizeof(float)), *y = malloc(n * sizeof(float));
  float *g = malloc(n * sizeof(float)), *cx = malloc(nq * sizeof(float));
  float *cy = malloc(nq * sizeof(float)), *cg = malloc(nq * sizeof(float));
  double *xd = malloc(n * sizeof(double));
  unsigned st = 31;
  for (size_t i = 0; i < n; i++) {
    y[i] = kt_randf(&st) * 1.5f - 0.2f;
    float d = 0.05f + 0.3f * kt_randf(&st); /* |x - y| away from L1's kink */
    x[i] = y[i] + (kt_randf(&st) < 0.5f ? -d : d);
    xd[i] = x[i];
  }
  for (int p = 0; p < planes; p++) /* the interior, cropped here */
    for (int r = 0; r < Q; r++)
      for (int c = 0; c < Q; c++) {
        size_t i = ((size_t)p * P + r + M) * P + c + M, j = ((size_t)p * Q + r) * Q + c;
        cx[j] = x[i], cy[j] = y[i];
      }
  const kpcn_loss_kind kinds[] = {KPCN_LOSS_L1, KPCN_LOSS_L2, KPCN_LOSS_RELMSE, KPCN_LOSS_SSIM};
  for (int ki = 0; ki < 4; ki++) {
    const kpcn_loss_kind k = kinds[ki];
    double v = -1, ref = 0, maxrel = 0;
    for (size_t i = 0; i < n; i++)
      g[i] = NAN;
    CHECK(kt_loss(t, k, x, y, g, &v) == KPCN_OK);
    int band_zero = 1;
    for (int p = 0; p < planes; p++)
      for (int r = 0; r < P; r++)
        for (int c = 0; c < P; c++)
          if (r < M || r >= P - M || c < M || c >= P - M)
            band_zero &= g[((size_t)p * P + r) * P + c] == 0.0f;
    CHECK(band_zero);
    if (k == KPCN_LOSS_SSIM) { /* value and gradient of the cropped arrays, placed inside */
      CHECK(kpcn_loss_compute(k, &t->s.loss, cx, cy, t->N, 3, Q, Q, cg, &ref, 1) == KPCN_OK);
      CHECK_CLOSE(v, ref, 1e-12, 0.0);
      for (int p = 0; p < planes; p++)
        for (int r = 0; r < Q; r++)
          for (int c = 0; c < Q; c++) {
            double a = g[((size_t)p * P + r + M) * P + c + M], b = cg[((size_t)p * Q + r) * Q + c];
            maxrel = kt_worst(maxrel, fabs(a - b) / (fabs(b) + 1e-9));
          }
    } else {
      ref = margin_naive(k, xd, y, planes, P, M);
      CHECK_CLOSE(v, ref, 1e-9, 1e-12);
      for (int tr = 0; tr < 60; tr++) { /* central differences, interior and band */
        size_t i = (size_t)(kt_randf(&st) * (float)n) % n;
        double h = 1e-5, keep = xd[i];
        xd[i] = keep + h;
        double fp = margin_naive(k, xd, y, planes, P, M);
        xd[i] = keep - h;
        double fm = margin_naive(k, xd, y, planes, P, M);
        xd[i] = keep;
        double fd = (fp - fm) / (2 * h);
        maxrel = kt_worst(maxrel, fabs(fd - g[i]) / (fabs(fd) + 1e-3 / (double)nq + 1e-12));
      }
    }
    printf("loss margin %d, %s: loss %.6f (interior %.6f), max rel grad err %.2g\n", M,
           kpcn_loss_name(k), v, ref, maxrel);
    CHECK(maxrel <= 2e-3);
  }
  free(x), free(y), free(g), free(cx), free(cy), free(cg), free(xd);
  kpcn_trainer_destroy(t);
}

/* Only patches of sources marked "train" are drawn when any source is so marked (all of them
 * when none is): the index of training patches, built from the store's records alone. */
static void test_batch_split(void) {
  static const char *const splits[3] = {"train", "test", "val"};
  static const char *const none[2] = {"", ""};
  const char *p3 = tf_tmp("split3.kps"), *p0 = tf_tmp("split0.kps");
  CHECK(tf_make_split_store(p3, 20, 48, 40, 12, 1, 0, NULL, 0, splits, 3) == 0);
  CHECK(tf_make_split_store(p0, 20, 48, 40, 12, 1, 0, NULL, 0, none, 2) == 0);
  kpcn_train_settings s;
  tf_settings(&s, p3, tf_tmp("split.safetensors"));
  kpcn_trainer *t = NULL;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_OK);
  if (t) {
    CHECK(t->ntrain == 4);
    for (uint64_t k = 0; k < t->ntrain && k < 4; k++)
      CHECK(t->train_idx[k] == 3 * k);
    CHECK(kt_batch_assemble(t) == KPCN_OK);
    for (int b = 0; b < t->N; b++)
      CHECK(t->batch_idx[b] % 3 == 0);
  }
  kpcn_trainer_destroy(t);
  t = NULL;
  tf_settings(&s, p0, tf_tmp("split0.safetensors"));
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_OK);
  if (t) {
    CHECK(t->ntrain == 12);
    for (uint64_t k = 0; k < t->ntrain && k < 12; k++)
      CHECK(t->train_idx[k] == k);
  }
  kpcn_trainer_destroy(t);
}

int main(void) {
  g_store = tf_make_test_store("batch.kps");
  if (!g_store) return 1;
  test_batch_wiring();
  test_batch_exposure();
  test_batch_firefly();
  test_loss_margin();
  test_batch_split();
  return kt_summary("train_batch");
}
