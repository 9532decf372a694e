/* Trainer end to end on a synthetic store (determinism and checkpoint/resume are in
 * test_train_resume.c): both stages, full-image validation, the best model, CSV/plot outputs,
 * --init conversions (kernel passes, source weights, widening), and clear errors for a store
 * with the wrong channel list, a garbage store and a model with other inputs; weight averaging
 * (SWA) of checkpoints and model files, and the snapshots kept for it; fine-tuning one branch
 * with the other frozen. */
#include "kpcn/exr.h"
#include "train/train_internal.h"
#include "kpcn/train.h"
#include "testutil.h"
#include "train_fixture.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

static const char *g_store;
static void settings(kpcn_train_settings *s, const char *out) { tf_settings(s, g_store, out); }

static float *weights(kpcn_trainer *t, size_t *n) {
  return tf_model_weights(kpcn_trainer_model(t), n);
}

/* Two pairs: the trainer's mean and geometric mean equal those of the two single-pair
 * figures (same seed, so the same initial model); --best-by geomean picks by the latter. */
static void test_validation_geomean(void) {
  const char *vn[2], *vr[2];
  double one[2];
  kpcn_train_settings s;
  for (int k = 0; k < 2; k++) {
    kpcn_aov_set *n, *r;
    CHECK(tf_make_pair(&n, &r, 40, 32, 20 + 7 * k, 0) == 0);
    vn[k] = tf_tmp(k ? "g1_noisy.exr" : "g0_noisy.exr");
    vr[k] = tf_tmp(k ? "g1_ref.exr" : "g0_ref.exr");
    CHECK(kpcn_exr_write_aov(vn[k], n, NULL) == KPCN_OK);
    CHECK(kpcn_exr_write_aov(vr[k], r, NULL) == KPCN_OK);
    kpcn_aov_destroy(n), kpcn_aov_destroy(r);
  }
  for (int k = 0; k < 3; k++) { /* pair 0, pair 1, both */
    settings(&s, tf_tmp("g.safetensors"));
    s.nthreads = 1;
    s.nval = k < 2 ? 1 : 2, s.val_noisy = vn + (k < 2 ? k : 0), s.val_ref = vr + (k < 2 ? k : 0);
    kpcn_trainer *t = NULL;
    CHECK(kpcn_trainer_create(&t, &s) == KPCN_OK);
    if (!t) return;
    kpcn_val_result v;
    CHECK(kpcn_trainer_validate(t, &v) == KPCN_OK);
    kpcn_trainer_destroy(t);
    if (k < 2) {
      one[k] = v.relmse;
      continue;
    }
    const double mean = 0.5 * (one[0] + one[1]), geo = sqrt(one[0] * one[1]);
    printf("validation relMSE of two pairs %.6g, %.6g: mean %.6g (expect %.6g), geometric mean "
           "%.6g (expect %.6g)\n",
           one[0], one[1], v.relmse, mean, v.relmse_geo, geo);
    CHECK(fabs(one[0] - one[1]) > 0.05 * one[0]); /* the pairs differ, so the means do */
    CHECK(fabs(v.relmse - mean) <= 1e-9 * mean);
    CHECK(fabs(v.relmse_geo - geo) <= 1e-9 * geo);
  }
  /* a run choosing by the geometric mean writes it to the CSV and a best model */
  settings(&s, tf_tmp("g.safetensors"));
  s.nthreads = 1, s.nval = 2, s.val_noisy = vn, s.val_ref = vr, s.val_every = 3;
  s.best_by = KPCN_VAL_GEOMEAN;
  s.best_path = tf_tmp("g_best.safetensors");
  remove(s.best_path);
  kpcn_trainer *t = NULL;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_OK);
  CHECK(t && kpcn_trainer_run(t, NULL) == KPCN_OK);
  kpcn_trainer_destroy(t);
  FILE *f = fopen(tf_tmp("g.safetensors.csv"), "r");
  char line[512] = "";
  CHECK(f && fgets(line, sizeof line, f));
  CHECK(strstr(line, ",val_psnr,val_relmse_geo\n") != NULL);
  if (f) fclose(f);
  kpcn_model *bm = NULL;
  CHECK(kpcn_model_load(s.best_path, &bm) == KPCN_OK);
  kpcn_model_destroy(bm);
  s.best_by = (kpcn_val_select)7;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_ERR_INVALID_ARGUMENT);
}

/* Trains the settings() model with one validation pair (files tagged `tag`) into `path`;
 * *val receives its validation. Then *s is set up for a run from that model into `next`. */
static int train_then_init(const char *path, const char *next, const char *tag, const char **vn,
                           const char **vr, kpcn_val_result *val, kpcn_train_settings *s) {
  settings(s, path);
  tf_val_pair(s, tag, vn, vr);
  kpcn_trainer *t = NULL;
  CHECK(kpcn_trainer_create(&t, s) == KPCN_OK);
  if (!t) return 0;
  CHECK(kpcn_trainer_run(t, NULL) == KPCN_OK);
  CHECK(kpcn_trainer_validate(t, val) == KPCN_OK);
  kpcn_trainer_destroy(t);
  settings(s, next);
  tf_val_pair(s, tag, vn, vr);
  s->init_model = path;
  return 1;
}

/* The run set up in *s starts from a converted model that computes the same function as the
 * one validated at `before`: its validation equals it to `tol` (relative); then it trains.
 * *arch receives the converted model's architecture. */
static void same_function_then_train(const kpcn_train_settings *s, const char *what, double before,
                                     double tol, kpcn_arch *arch) {
  memset(arch, 0, sizeof *arch);
  kpcn_trainer *t = NULL;
  CHECK(kpcn_trainer_create(&t, s) == KPCN_OK);
  if (!t) return;
  *arch = *kpcn_model_arch(kpcn_trainer_model(t));
  kpcn_val_result after;
  CHECK(kpcn_trainer_validate(t, &after) == KPCN_OK);
  printf("%s: validation relMSE %.9g before, %.9g after\n", what, before, after.relmse);
  CHECK(fabs(after.relmse - before) <= tol * before);
  CHECK(kpcn_trainer_run(t, NULL) == KPCN_OK);
  kpcn_trainer_destroy(t);
}

/* --init with kpa_passes: the one-pass model's weights go on as a two-pass model, saved as
 * one; its validation differs from the same weights in one pass. */
static void test_init_passes(void) {
  const char *vn[1], *vr[1];
  kpcn_train_settings s;
  kpcn_val_result one, two;
  if (!train_then_init(tf_tmp("p1.safetensors"), tf_tmp("p2.safetensors"), "p", vn, vr, &one, &s))
    return;
  kpcn_trainer *t = NULL;
  s.kpa_passes = 2;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_OK);
  if (!t) return;
  CHECK(kpcn_model_arch(kpcn_trainer_model(t))->kpa_passes == 2);
  CHECK(kpcn_trainer_validate(t, &two) == KPCN_OK);
  printf("one-pass model as two passes: validation relMSE %.6g -> %.6g\n", one.relmse, two.relmse);
  CHECK(two.relmse != one.relmse);
  CHECK(kpcn_trainer_run(t, NULL) == KPCN_OK);
  kpcn_trainer_destroy(t);
  kpcn_model *m = NULL;
  CHECK(kpcn_model_load(tf_tmp("p2.safetensors"), &m) == KPCN_OK);
  CHECK(m && kpcn_model_arch(m)->kpa_passes == 2);
  kpcn_model_destroy(m);
  s.kpa_passes = KPCN_NN_MAX_KPA_PASSES + 1;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(strstr(kpcn_last_error(), "kpa_passes") != NULL);
}

/* L1 norm of both branches' source-score weights and biases in a model file; *nonzero counts
 * the entries that are not zero. */
static double score_l1(const char *path, int *nonzero) {
  kpcn_model *m = NULL;
  *nonzero = 0;
  CHECK(kpcn_model_load(path, &m) == KPCN_OK);
  if (!m) return 0;
  const kpcn_arch *a = kpcn_model_arch(m);
  CHECK(a->source_weight == 1);
  double l1 = 0;
  for (int b = 0; b < 2; b++) {
    kpcn_layer_view v;
    kpcn_model_layer(m, (kpcn_branch)b, a->n_hidden, &v);
    const size_t row = (size_t)v.in_ch * v.size * v.size, K2 = (size_t)v.out_ch - 1;
    for (size_t i = 0; i <= row; i++) {
      const float x = i < row ? v.weight[row * K2 + i] : v.bias[K2];
      *nonzero += x != 0.f;
      l1 += fabs(x);
    }
  }
  kpcn_model_destroy(m);
  return l1;
}

/* --init with source_weight: the model gains a zero source-score channel, so it validates to
 * the same relMSE (same function up to rounding), trains, and the score channel's weights
 * move (its gradient reaches them). */
static void test_init_source_weight(void) {
  const char *vn[1], *vr[1];
  kpcn_train_settings s;
  kpcn_val_result plain;
  const char *base = tf_tmp("s1.safetensors");
  if (!train_then_init(base, tf_tmp("s2.safetensors"), "s", vn, vr, &plain, &s)) return;
  kpcn_trainer *t = NULL;
  kpcn_arch a;
  s.source_weight = 1;
  same_function_then_train(&s, "plain model with a zero source score", plain.relmse, 1e-5, &a);
  CHECK(a.source_weight == 1);
  int moved = 0;
  const double l1 = score_l1(tf_tmp("s2.safetensors"), &moved);
  printf("source-score weights moved by training: %d, L1 %.4g\n", moved, l1);
  CHECK(moved > 0);
  /* --source-lr-scale: the same run with the score learning at 20x moves it much further */
  settings(&s, tf_tmp("s3.safetensors"));
  tf_val_pair(&s, "s", vn, vr);
  s.init_model = base;
  s.source_weight = 1;
  s.source_lr_scale = 20;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_OK);
  if (!t) return;
  CHECK(kpcn_trainer_run(t, NULL) == KPCN_OK);
  kpcn_trainer_destroy(t);
  const double l20 = score_l1(tf_tmp("s3.safetensors"), &moved);
  printf("with --source-lr-scale 20: L1 %.4g (%.1fx)\n", l20, l20 / l1);
  CHECK(l20 > 8 * l1);
}

/* --widen: a 16-channel model widened to 32 validates to the same relMSE (same function),
 * trains, and ends with 32 channels; without an init model, or narrower, it is an error. */
static void test_widen(void) {
  const char *vn[1], *vr[1];
  kpcn_train_settings s;
  kpcn_val_result narrow;
  if (!train_then_init(tf_tmp("w16.safetensors"), tf_tmp("w32.safetensors"), "w", vn, vr, &narrow,
                       &s))
    return;
  kpcn_trainer *t = NULL;
  kpcn_arch a;
  s.widen_channels = 32;
  same_function_then_train(&s, "widened 16 -> 32 channels", narrow.relmse, 1e-6, &a);
  CHECK(a.channels == 32);
  kpcn_model *m = NULL;
  CHECK(kpcn_model_load(tf_tmp("w32.safetensors"), &m) == KPCN_OK);
  CHECK(m && kpcn_model_arch(m)->channels == 32);
  kpcn_model_destroy(m);
  s.widen_channels = 8; /* narrower than the model */
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(strstr(kpcn_last_error(), "w16.safetensors") != NULL);
  s.init_model = NULL, s.widen_channels = 32;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(strstr(kpcn_last_error(), "init model") != NULL);
}

static void test_validation(void) {
  kpcn_train_settings s;
  settings(&s, tf_tmp("v.safetensors"));
  const char *vn[1], *vr[1];
  tf_val_pair(&s, "val", vn, vr);
  s.val_every = 3;
  kpcn_trainer *t;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_OK);
  if (!t) {
    fprintf(stderr, "%s\n", kpcn_last_error());
    return;
  }
  kpcn_val_result vr0;
  CHECK(kpcn_trainer_validate(t, &vr0) == KPCN_OK);
  CHECK(vr0.relmse > 0 && vr0.relmse < 10 && vr0.ssim > -1 && vr0.ssim < 1 && vr0.psnr > 0);
  CHECK(fabs(vr0.relmse_geo - vr0.relmse) <= 1e-12 * vr0.relmse); /* one pair: equal */
  CHECK(kpcn_trainer_run(t, NULL) == KPCN_OK);
  kpcn_trainer_destroy(t);
  FILE *f = fopen(tf_tmp("v.safetensors.csv"), "r");
  int vrows = 0;
  char line[512];
  while (f && fgets(line, sizeof line, f)) {
    char *last = strrchr(line, ',');
    if (line[0] != 'i' && last && last[1] != '\n' && last[1] != 0) vrows++;
  }
  if (f) fclose(f);
  CHECK(vrows == 2); /* iterations 3 and 6 */
  /* a missing validation file is named */
  const char *bad[1] = {"/nonexistent/val.exr"};
  s.val_noisy = bad;
  CHECK(kpcn_trainer_create(&t, &s) != KPCN_OK);
  CHECK(strstr(kpcn_last_error(), "/nonexistent/val.exr") != NULL);
}

/* --best keeps the model of the lowest validation relMSE; --lr2 is the base lr of stage 2 */
static void test_best_and_stage2_lr(void) {
  kpcn_train_settings s;
  settings(&s, tf_tmp("b.safetensors"));
  const char *vn[1], *vr[1], *best = tf_tmp("b.best.safetensors");
  tf_val_pair(&s, "best", vn, vr);
  s.val_every = 1, s.log_every = 1;
  s.best_path = best;
  s.stage2_lr = 1e-4;
  s.adam.lr = 5e-2; /* large steps: validation goes up and down, so best != last */
  kpcn_trainer *t;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_OK);
  if (!t) return;
  for (int i = 0; i < 3; i++)
    CHECK(kpcn_trainer_step(t, NULL) == KPCN_OK);
  CHECK(kpcn_adam_get_settings(t->adam[0])->lr == 5e-2); /* stage 1 */
  CHECK(kpcn_trainer_step(t, NULL) == KPCN_OK);
  CHECK(kpcn_adam_get_settings(t->adam[0])->lr == 1e-4 &&
        kpcn_adam_get_settings(t->adam[1])->lr == 1e-4);
  kpcn_trainer_destroy(t);
  unlink(best);
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_OK);
  CHECK(kpcn_trainer_run(t, NULL) == KPCN_OK);
  kpcn_trainer_destroy(t);
  /* the best file holds the iteration whose CSV val_relmse is the minimum */
  FILE *f = fopen(tf_tmp("b.safetensors.csv"), "r");
  char line[512];
  double bestv = 1e300;
  long long bestit = -1, lastit = -1;
  while (f && fgets(line, sizeof line, f)) {
    if (line[0] == 'i') continue;
    lastit = atoll(line);
    const char *c = line;
    for (int k = 0; k < 6 && c; k++)
      c = strchr(c, ','), c = c ? c + 1 : NULL;
    if (c && *c != ',' && strtod(c, NULL) < bestv) bestv = strtod(c, NULL), bestit = atoll(line);
  }
  if (f) fclose(f);
  kpcn_model *m = NULL;
  CHECK(bestit > 0 && kpcn_model_load(best, &m) == KPCN_OK);
  CHECK(bestit != lastit); /* else the best file could be the last model by accident */
  if (m) {
    const char *it = kpcn_model_get_meta(m, "train.iterations");
    CHECK(it && atoll(it) == bestit);
    kpcn_model_destroy(m);
  }
  /* best without validation images is refused */
  s.nval = 0;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(strstr(kpcn_last_error(), "validation") != NULL);
}

/* --snapshots: every checkpoint (periodic and final) is kept, and snapshot 4 holds exactly the
 * weights of 4 iterations (a second trainer stepped by hand). */
static void test_snapshots(void) {
  kpcn_train_settings s;
  settings(&s, tf_tmp("snap.safetensors"));
  s.ckpt_every = 2;
  s.snapshot_dir = tf_tmp("snaps");
  kpcn_trainer *t = NULL;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_OK);
  CHECK(t && kpcn_trainer_run(t, NULL) == KPCN_OK);
  kpcn_trainer_destroy(t);
  char p2[600], p4[600], p6[600];
  snprintf(p2, sizeof p2, "%s/ckpt_000002.safetensors", s.snapshot_dir);
  snprintf(p4, sizeof p4, "%s/ckpt_000004.safetensors", s.snapshot_dir);
  snprintf(p6, sizeof p6, "%s/ckpt_000006.safetensors", s.snapshot_dir);
  CHECK(access(p2, F_OK) == 0 && access(p4, F_OK) == 0 && access(p6, F_OK) == 0); /* + final */
  s.snapshot_dir = NULL;
  t = NULL;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_OK);
  for (int i = 0; t && i < 4; i++)
    CHECK(kpcn_trainer_step(t, NULL) == KPCN_OK);
  kpcn_model *m = NULL;
  CHECK(kpcn_checkpoint_load_model(p4, &m) == KPCN_OK);
  if (t && m) {
    size_t n1, n2;
    float *w1 = weights(t, &n1), *w2 = tf_model_weights(m, &n2);
    CHECK(n1 == n2 && memcmp(w1, w2, n1 * sizeof(float)) == 0);
    free(w1), free(w2);
  }
  kpcn_model_destroy(m);
  kpcn_trainer_destroy(t);
  /* ckpt_path "" = no checkpoint (it tried to rename its temp file to ""): the run and its
   * snapshots still complete; resuming from no checkpoint is refused by name */
  settings(&s, tf_tmp("nockpt.safetensors"));
  s.ckpt_every = 2;
  s.ckpt_path = "";
  s.snapshot_dir = tf_tmp("snaps_nockpt");
  t = NULL;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_OK);
  CHECK(t && kpcn_trainer_run(t, NULL) == KPCN_OK);
  kpcn_trainer_destroy(t);
  snprintf(p2, sizeof p2, "%s/ckpt_000002.safetensors", s.snapshot_dir);
  CHECK(access(s.out_path, F_OK) == 0 && access(p2, F_OK) == 0);
  s.resume = 1;
  t = NULL;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_ERR_INVALID_ARGUMENT && t == NULL);
  CHECK(strstr(kpcn_last_error(), "checkpoint path is empty") != NULL);
}

/* Weight averaging of two checkpoints and a model file against the mean computed here; a
 * file of another architecture and a non-model are errors naming the file. */
static void test_average(void) {
  kpcn_train_settings s;
  settings(&s, tf_tmp("avg.safetensors"));
  kpcn_trainer *t = NULL;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_OK);
  if (!t) return;
  float *w[3];
  size_t n[3];
  const char *in[3] = {tf_tmp("avg1.ckpt"), tf_tmp("avg2.ckpt"), tf_tmp("avg3.safetensors")};
  for (int k = 0; k < 2; k++) {
    CHECK(kpcn_trainer_step(t, NULL) == KPCN_OK);
    CHECK(kpcn_trainer_save_checkpoint(t, in[k]) == KPCN_OK);
    w[k] = weights(t, &n[k]);
  }
  kpcn_model *m3 = NULL, *avg = NULL;
  CHECK(kpcn_model_create(kpcn_model_arch(kpcn_trainer_model(t)), 77, &m3) == KPCN_OK);
  CHECK(kpcn_model_save(m3, in[2]) == KPCN_OK);
  w[2] = tf_model_weights(m3, &n[2]);
  CHECK(kpcn_model_average(in, 3, &avg) == KPCN_OK);
  if (avg) {
    size_t na;
    float *wa = tf_model_weights(avg, &na);
    double worst = 0;
    CHECK(na == n[0] && n[0] == n[1] && n[1] == n[2]);
    for (size_t i = 0; i < na && na == n[0]; i++) {
      double want = ((double)w[0][i] + w[1][i] + w[2][i]) / 3;
      worst = kt_worst(worst, fabs(wa[i] - want) / fmax(fabs(want), 1e-6));
    }
    CHECK(worst < 1e-6);
    CHECK(memcmp(w[0], w[1], n[0] * sizeof(float)) != 0); /* the snapshots differ */
    CHECK(kpcn_model_get_meta(avg, "train.averaged_snapshots") &&
          !strcmp(kpcn_model_get_meta(avg, "train.averaged_snapshots"), "3"));
    free(wa);
  }
  kpcn_model_destroy(avg);
  /* another architecture */
  kpcn_arch other = *kpcn_model_arch(m3);
  other.channels = 32;
  kpcn_model *mo = NULL;
  const char *bad[2] = {in[0], tf_tmp("avg_other.safetensors")};
  CHECK(kpcn_model_create(&other, 1, &mo) == KPCN_OK && kpcn_model_save(mo, bad[1]) == KPCN_OK);
  kpcn_model_destroy(mo);
  mo = NULL;
  avg = NULL;
  CHECK(kpcn_model_average(bad, 2, &avg) == KPCN_ERR_FORMAT && avg == NULL);
  CHECK(strstr(kpcn_last_error(), "avg_other") && strstr(kpcn_last_error(), "architecture"));
  /* the same network with another recorded exposure: named as such, with the way out */
  CHECK(kpcn_model_create(kpcn_model_arch(m3), 2, &mo) == KPCN_OK);
  if (mo) {
    const char *other_exposure[2] = {in[2], tf_tmp("avg_exposure.safetensors")};
    CHECK(kpcn_model_set_exposure(mo, 2.5f * kpcn_model_arch(m3)->exposure + 0.5f) == KPCN_OK);
    CHECK(kpcn_model_save(mo, other_exposure[1]) == KPCN_OK);
    CHECK(kpcn_model_average(other_exposure, 2, &avg) == KPCN_ERR_FORMAT && avg == NULL);
    CHECK(strstr(kpcn_last_error(), "avg_exposure") && strstr(kpcn_last_error(), "exposure") &&
          strstr(kpcn_last_error(), "--record-exposure") &&
          !strstr(kpcn_last_error(), "architecture"));
    kpcn_model_destroy(mo);
    mo = NULL;
  }
  /* a checkpoint with a NaN weight (the first float of the first tensor) */
  {
    FILE *src = fopen(in[0], "rb"), *dst = fopen(tf_tmp("avg_nan.ckpt"), "wb");
    CHECK(src && dst);
    if (src && dst) {
      unsigned char buf[1 << 16];
      size_t r;
      while ((r = fread(buf, 1, sizeof buf, src)) > 0)
        fwrite(buf, 1, r, dst);
    }
    if (src) fclose(src);
    if (dst) fclose(dst);
    FILE *f = fopen(tf_tmp("avg_nan.ckpt"), "r+b");
    unsigned char len8[8];
    uint64_t hl = 0;
    CHECK(f && fread(len8, 1, 8, f) == 8);
    for (int i = 0; i < 8; i++)
      hl |= (uint64_t)len8[i] << (8 * i);
    float nan = NAN;
    if (f) {
      fseek(f, (long)(8 + hl), SEEK_SET);
      fwrite(&nan, 4, 1, f);
      fclose(f);
    }
    const char *nanin[1] = {tf_tmp("avg_nan.ckpt")};
    CHECK(kpcn_model_average(nanin, 1, &avg) == KPCN_ERR_FORMAT && avg == NULL);
    CHECK(strstr(kpcn_last_error(), "not finite") != NULL);
  }
  /* not a model at all */
  const char *junk[1] = {g_store};
  CHECK(kpcn_model_average(junk, 1, &avg) == KPCN_ERR_FORMAT && avg == NULL);
  CHECK(strstr(kpcn_last_error(), "neither a model") != NULL);
  kpcn_model_destroy(mo);
  kpcn_model_destroy(m3);
  for (int k = 0; k < 3; k++)
    free(w[k]);
  kpcn_trainer_destroy(t);
}

/* One branch's weights and biases of a model file, concatenated (malloc'ed); *n the count. */
static float *branch_weights(const char *path, kpcn_branch b, size_t *n) {
  kpcn_model *m = NULL;
  *n = 0;
  CHECK(kpcn_model_load(path, &m) == KPCN_OK);
  if (!m) return NULL;
  const kpcn_arch *a = kpcn_model_arch(m);
  float *w = malloc(kpcn_arch_param_count(a) * sizeof(float));
  for (int l = 0; l < kpcn_arch_n_layers(a); l++) {
    kpcn_layer_view v;
    kpcn_model_layer(m, b, l, &v);
    const size_t nw = (size_t)v.out_ch * v.in_ch * v.size * v.size;
    memcpy(w + *n, v.weight, nw * sizeof(float)), *n += nw;
    memcpy(w + *n, v.bias, (size_t)v.out_ch * sizeof(float)), *n += (size_t)v.out_ch;
  }
  kpcn_model_destroy(m);
  return w;
}

/* 1 if branch b of the two model files holds the same bits. */
static int same_branch(const char *p1, const char *p2, kpcn_branch b) {
  size_t n1, n2;
  float *w1 = branch_weights(p1, b, &n1), *w2 = branch_weights(p2, b, &n2);
  const int same = w1 && w2 && n1 == n2 && memcmp(w1, w2, n1 * sizeof(float)) == 0;
  free(w1), free(w2);
  return same;
}

static int meta_is(const char *path, const char *key, const char *want) {
  kpcn_model *m = NULL;
  CHECK(kpcn_model_load(path, &m) == KPCN_OK);
  const char *v = m ? kpcn_model_get_meta(m, key) : NULL;
  const int ok = v && !strcmp(v, want);
  kpcn_model_destroy(m);
  return ok;
}

/* --freeze: a run from a trained model through both stages with one branch frozen leaves that
 * branch bit for bit as it started and moves the other, and the model says which it froze; the
 * same run stopped in stage 2 and resumed ends with the uninterrupted run's weights; a resume
 * that freezes otherwise, both branches frozen and a frozen branch with no model to start from
 * are refused. */
static void test_freeze(void) {
  const char *vn[1], *vr[1];
  kpcn_train_settings s;
  kpcn_val_result v;
  const char *base = tf_tmp("f0.safetensors");
  if (!train_then_init(base, tf_tmp("fd.safetensors"), "f", vn, vr, &v, &s)) return;
  static const char *const names[2] = {"diffuse", "specular"};
  const char *outs[2] = {tf_tmp("fd.safetensors"), tf_tmp("fs.safetensors")};
  kpcn_trainer *t = NULL;
  for (int fb = 0; fb < 2; fb++) {
    s.out_path = outs[fb];
    s.frozen[fb] = 1, s.frozen[!fb] = 0;
    CHECK(kpcn_trainer_create(&t, &s) == KPCN_OK);
    if (!t) return;
    CHECK(kpcn_trainer_run(t, NULL) == KPCN_OK);
    kpcn_trainer_destroy(t);
    t = NULL;
    const int kept = same_branch(base, outs[fb], (kpcn_branch)fb);
    const int moved = !same_branch(base, outs[fb], (kpcn_branch)!fb);
    printf("%s frozen: kept bit for bit %d, the other branch moved %d\n", names[fb], kept, moved);
    CHECK(kept && moved);
    CHECK(meta_is(outs[fb], "train.frozen", names[fb]));
  }
  CHECK(meta_is(base, "train.frozen", "none"));
  /* stopped at iteration 4 (stage 2) and resumed: the uninterrupted run's model, bit for bit */
  const char *res = tf_tmp("fr.safetensors");
  s.out_path = res;
  s.frozen[0] = 0, s.frozen[1] = 1;
  s.progress = tf_stop_cb;
  tf_stop_at = 4;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_OK);
  if (!t) return;
  int stopped = 0;
  CHECK(kpcn_trainer_run(t, &stopped) == KPCN_OK && stopped);
  kpcn_trainer_destroy(t);
  s.progress = NULL;
  s.resume = 1;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_OK);
  if (!t) return;
  CHECK(kpcn_trainer_run(t, NULL) == KPCN_OK);
  kpcn_trainer_destroy(t);
  t = NULL;
  CHECK(same_branch(res, outs[1], KPCN_BRANCH_DIFFUSE) &&
        same_branch(res, outs[1], KPCN_BRANCH_SPECULAR));
  /* its checkpoint, resumed with the other branch frozen or none, is refused by name */
  s.frozen[0] = 1, s.frozen[1] = 0;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_ERR_FORMAT && !t);
  CHECK(strstr(kpcn_last_error(), "specular branch frozen") != NULL);
  s.frozen[0] = 0;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_ERR_FORMAT && !t);
  CHECK(strstr(kpcn_last_error(), "freezes none") != NULL);
  /* the base run's checkpoint (both branches trained) resumed with one frozen */
  s.out_path = base;
  s.frozen[1] = 1;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_ERR_FORMAT && !t);
  CHECK(strstr(kpcn_last_error(), "with no branch frozen, this run freezes specular") != NULL);
  s.resume = 0;
  s.frozen[0] = s.frozen[1] = 1;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_ERR_INVALID_ARGUMENT && !t);
  CHECK(strstr(kpcn_last_error(), "both branches are frozen") != NULL);
  s.frozen[0] = 0;
  s.init_model = NULL;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_ERR_INVALID_ARGUMENT && !t);
  CHECK(strstr(kpcn_last_error(), "freezing the specular branch needs a model") != NULL);
}

static void test_bad_stores(void) {
  kpcn_train_settings s;
  kpcn_trainer *t = NULL;
  /* a store without the reference specular channels */
  const char *chans[30];
  int nc = 0;
  for (int i = 0; i < KPCN_PATCHSTORE_NUM_DEFAULT; i++)
    if (strncmp(kpcn_patchstore_default_channels[i], "ref.specular", 12) != 0)
      chans[nc++] = kpcn_patchstore_default_channels[i];
  const char *p2 = tf_tmp("nospec.kps");
  CHECK(tf_make_store(p2, 20, 40, 40, 4, 3, 0, chans, nc) == 0);
  settings(&s, tf_tmp("x.safetensors"));
  s.store_path = p2;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_ERR_FORMAT);
  CHECK(strstr(kpcn_last_error(), "ref.specular.R") != NULL);
  CHECK(strstr(kpcn_last_error(), "nospec.kps") != NULL);
  /* garbage file */
  const char *g = tf_tmp("garbage.kps");
  FILE *f = fopen(g, "wb");
  fputs("this is not a patch store", f);
  fclose(f);
  s.store_path = g;
  CHECK(kpcn_trainer_create(&t, &s) != KPCN_OK);
  CHECK(strstr(kpcn_last_error(), "garbage.kps") != NULL);
  /* patch larger than the store's */
  settings(&s, tf_tmp("x.safetensors"));
  s.patch = 32;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(strstr(kpcn_last_error(), "32") != NULL);
  /* a model whose input list differs from the feature builder's */
  kpcn_arch a;
  kpcn_arch_preset("tiny", &a);
  const char *names[3] = {"R", "G", "B"};
  kpcn_arch_set_inputs(&a, 3, names);
  kpcn_model *m;
  CHECK(kpcn_model_create(&a, 1, &m) == KPCN_OK);
  CHECK(kpcn_model_save(m, tf_tmp("rgb.safetensors")) == KPCN_OK);
  kpcn_model_destroy(m);
  settings(&s, tf_tmp("x.safetensors"));
  s.init_model = tf_tmp("rgb.safetensors");
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_ERR_FORMAT);
  CHECK(strstr(kpcn_last_error(), "input channels") != NULL);
  /* NaN in the patch data (every 64th 4-byte word of the payload set to 0xff bytes: NaN as
   * f32 and f16): the run stops naming the patch and channel, not as a "diverged" loss */
  {
    FILE *in = fopen(g_store, "rb"), *outf = fopen(tf_tmp("nan.kps"), "wb");
    CHECK(in && outf);
    unsigned char hdr[64];
    if (in && outf && fread(hdr, 1, 64, in) == 64) {
      uint64_t index_offset;
      memcpy(&index_offset, hdr + 40, 8);
      fwrite(hdr, 1, 64, outf);
      int ch;
      for (uint64_t pos = 64; (ch = fgetc(in)) != EOF; pos++)
        fputc(pos >= KPCN_PATCHSTORE_DATA_OFFSET && pos < index_offset && (pos / 4) % 64 == 0 ? 0xff
                                                                                              : ch,
              outf);
    }
    if (in) fclose(in);
    if (outf) fclose(outf);
    /* a run that fails before its first checkpoint leaves no CSV log of its own, and an
     * earlier run's log at that name as it was (it was replaced by the failed run's rows,
     * beside the earlier run's model) */
    settings(&s, tf_tmp("nan.safetensors"));
    s.store_path = tf_tmp("nan.kps");
    CHECK(kpcn_trainer_create(&t, &s) == KPCN_OK);
    CHECK(t && kpcn_trainer_run(t, NULL) == KPCN_ERR_NONFINITE);
    CHECK(strstr(kpcn_last_error(), "non-finite value in channel") != NULL);
    kpcn_trainer_destroy(t);
    t = NULL;
    FILE *lone = fopen(tf_tmp("nan.safetensors.csv"), "rb");
    CHECK(lone == NULL);
    if (lone) fclose(lone);
    settings(&s, tf_tmp("nan.safetensors"));
    CHECK(kpcn_trainer_create(&t, &s) == KPCN_OK);
    CHECK(t && kpcn_trainer_run(t, NULL) == KPCN_OK);
    kpcn_trainer_destroy(t);
    t = NULL;
    long before_len = 0, after_len = 0;
    char *before = kt_slurp(tf_tmp("nan.safetensors.csv"), &before_len);
    settings(&s, tf_tmp("nan.safetensors"));
    s.store_path = tf_tmp("nan.kps");
    CHECK(kpcn_trainer_create(&t, &s) == KPCN_OK);
    CHECK(t && kpcn_trainer_run(t, NULL) == KPCN_ERR_NONFINITE);
    kpcn_trainer_destroy(t);
    t = NULL;
    char *after = kt_slurp(tf_tmp("nan.safetensors.csv"), &after_len);
    CHECK(before && after && before_len > 0 && before_len == after_len &&
          !memcmp(before, after, (size_t)before_len));
    free(before), free(after);
  }
  /* resume without a checkpoint */
  settings(&s, tf_tmp("nockpt.safetensors"));
  s.resume = 1;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_ERR_IO);
  CHECK(strstr(kpcn_last_error(), "nockpt.safetensors.ckpt") != NULL);
  /* an output that is the patch store (or another output) is refused before anything is
   * written; the store is intact */
  settings(&s, tf_tmp("clash.safetensors"));
  s.csv_path = s.store_path;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(strstr(kpcn_last_error(), "the patch store (--store) and the CSV log (--csv)") != NULL);
  settings(&s, tf_tmp("clash.safetensors"));
  s.plot_path = tf_tmp("./clash.safetensors");
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(strstr(kpcn_last_error(), "the model (-o) and the plot (--plot)") != NULL);
  {
    kpcn_patchstore *ps = NULL;
    CHECK(kpcn_patchstore_open(&ps, g_store, NULL, 0) == KPCN_OK);
    kpcn_patchstore_close(ps);
  }
  /* an SSIM window that is even or larger than the loss region is refused at create */
  settings(&s, tf_tmp("ssimwin.safetensors"));
  s.loss2 = KPCN_LOSS_SSIM;
  s.loss.ssim_window = 4;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_ERR_INVALID_ARGUMENT);
  CHECK(strstr(kpcn_last_error(), "window 4 must be odd") != NULL);
  s.loss.ssim_window = s.patch + 1;
  CHECK(kpcn_trainer_create(&t, &s) == KPCN_ERR_INVALID_ARGUMENT);
}

int main(void) {
  g_store = tf_make_test_store("train.kps");
  if (!g_store) return 1;
  test_init_passes();
  test_init_source_weight();
  test_validation();
  test_widen();
  test_validation_geomean();
  test_best_and_stage2_lr();
  test_average();
  test_snapshots();
  test_bad_stores();
  test_freeze();
  return kt_summary("train_pipeline");
}
