/* The trainer: set-up (store, model, nets, optimizers, validation images), one training
 * iteration of either stage, and full-image validation. The loop with logging and
 * checkpoints is in run.c; batches in batch.c; checkpoints in checkpoint.c. */
#define _GNU_SOURCE /* realpath */
#include "core/internal.h"
#include "denoise/denoise_internal.h"
#include "kpcn/exr.h"
#include "kpcn/metrics.h"
#include "train/train_internal.h"

#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>

double kt_now(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

double kt_lr_at(const kpcn_trainer *t, int64_t iter) {
  kpcn_adam_settings a = t->s.adam;
  if (iter >= t->s.stage1_iters && t->s.stage2_lr > 0) a.lr = t->s.stage2_lr;
  return kpcn_adam_lr_at(&a, iter);
}

void kpcn_train_settings_defaults(kpcn_train_settings *s) {
  memset(s, 0, sizeof *s);
  kpcn_arch_preset("cpu", &s->arch);
  s->loss1 = KPCN_LOSS_L1;
  s->loss2 = KPCN_LOSS_L1;
  kpcn_loss_settings_defaults(&s->loss);
  kpcn_adam_settings_defaults(&s->adam);
  kpcn_augment_draw_defaults(&s->augment);
  s->crop_jitter = 1;
  s->batch = 16;
  s->patch = 64;
  s->iters = 1000;
  s->stage1_iters = -1; /* -> 0.6 * iters */
  s->seed = 1;
  s->log_every = 10;
}

const char *kt_frozen_name(const kpcn_train_settings *s) {
  return s->frozen[KPCN_BRANCH_DIFFUSE]    ? "diffuse"
         : s->frozen[KPCN_BRANCH_SPECULAR] ? "specular"
                                           : "none";
}

static char *dup_or_null(const char *s) {
  if (!s) return NULL;
  size_t n = strlen(s) + 1;
  char *d = kpcn_alloc(n, "string");
  if (d) memcpy(d, s, n);
  return d;
}

static char *with_suffix(const char *base, const char *suffix) {
  size_t n = strlen(base) + strlen(suffix) + 1;
  char *d = kpcn_alloc(n, "path");
  if (d) snprintf(d, n, "%s%s", base, suffix);
  return d;
}

/* An output's path as the trainer uses it (owned): the one given, or the model's path with
 * `suffix` when none was (an empty one turns the output off). */
static char *output_path(const char *given, const char *model, const char *suffix) {
  return given ? dup_or_null(given) : with_suffix(model, suffix);
}

void kpcn_trainer_destroy(kpcn_trainer *t) {
  if (!t) return;
  for (int b = 0; b < KT_NB; b++) {
    kpcn_net_destroy(t->net[b]);
    kpcn_adam_destroy(t->adam[b]);
    free(t->params[b]);
    free(t->blocks[b]);
    free(t->feat[b]), free(t->noisy[b]), free(t->logits[b]), free(t->out[b]);
    free(t->target[b]), free(t->grad[b]), free(t->dlogits[b]), free(t->mid[b]);
  }
  free(t->kpa_scratch);
  kpcn_model_destroy(t->model);
  if (t->ps) kpcn_patchstore_close(t->ps);
  free(t->albedo), free(t->refc), free(t->comb), free(t->gcomb), free(t->lossbuf);
  free(t->scratch), free(t->batch_idx), free(t->batch_ox), free(t->batch_oy), free(t->train_idx);
  for (int i = 0; i < t->nval; i++) {
    kpcn_aov_destroy(t->val_aov ? t->val_aov[i] : NULL);
    free(t->val_ref ? t->val_ref[i] : NULL);
  }
  free(t->val_aov), free(t->val_ref);
  free(t->store_path), free(t->out_path), free(t->ckpt_path), free(t->csv_path);
  free(t->plot_path), free(t->init_model), free(t->best_path), free(t->snapshot_dir);
  free(t);
}

static kpcn_status check_inputs(const kpcn_trainer *t, const kpcn_arch *a, const char *what) {
  const char *names[KPCN_NN_MAX_INPUTS];
  int n = kpcn_features_channel_names(KPCN_BRANCH_DIFFUSE, names, KPCN_NN_MAX_INPUTS);
  if (a->n_inputs != n)
    return kpcn_fail(KPCN_ERR_FORMAT,
                     "%s has %d input channels but the feature builder (version %d) makes %d", what,
                     a->n_inputs, KPCN_FEATURES_VERSION, n);
  for (int i = 0; i < n; i++)
    if (strcmp(a->inputs[i], names[i]) != 0)
      return kpcn_fail(KPCN_ERR_FORMAT,
                       "%s input channel %d is '%s', the feature builder makes '%s' there", what, i,
                       a->inputs[i], names[i]);
  (void)t;
  return KPCN_OK;
}

static kpcn_status load_validation(kpcn_trainer *t) {
  t->nval = t->s.nval;
  if (!t->nval) return KPCN_OK;
  t->val_aov = kpcn_calloc((size_t)t->nval, sizeof *t->val_aov, "validation images");
  t->val_ref = kpcn_calloc((size_t)t->nval, sizeof *t->val_ref, "validation references");
  if (!t->val_aov || !t->val_ref) return kpcn_last_status();
  for (int i = 0; i < t->nval; i++) {
    kpcn_aov_set *ref = NULL;
    KPCN_TRY(kpcn_exr_read_aov(t->s.val_noisy[i], &t->val_aov[i]));
    /* the denoiser refuses these at the first validation, after hours of training (and the
     * run is lost with it): a missing AOV buffer or a non-finite value, now instead */
    if (kpcn_pipeline_require(t->val_aov[i]) != KPCN_OK)
      return kpcn_fail_context("validation input '%s'", t->s.val_noisy[i]);
    const char *nf = NULL;
    const size_t nbad = kpcn_aov_count_nonfinite(t->val_aov[i], &nf);
    if (nbad)
      return kpcn_fail(KPCN_ERR_NONFINITE,
                       "validation input '%s': %zu non-finite value(s) (NaN/Inf), the first in "
                       "'%s'",
                       t->s.val_noisy[i], nbad, nf ? nf : "?");
    KPCN_TRY(kpcn_exr_read_aov(t->s.val_ref[i], &ref));
    kpcn_status st = kpcn_aov_require(ref, KPCN_BUF_COLOR, 0, t->s.val_ref[i]);
    if (st == KPCN_OK &&
        (ref->width != t->val_aov[i]->width || ref->height != t->val_aov[i]->height))
      st = kpcn_fail(KPCN_ERR_SIZE_MISMATCH, "validation pair '%s' (%dx%d) / '%s' (%dx%d)",
                     t->s.val_noisy[i], t->val_aov[i]->width, t->val_aov[i]->height,
                     t->s.val_ref[i], ref->width, ref->height);
    if (st == KPCN_OK) {
      size_t n = 3 * kpcn_aov_plane_size(ref);
      t->val_ref[i] = kpcn_alloc(n * sizeof(float), "validation reference");
      if (t->val_ref[i])
        memcpy(t->val_ref[i], ref->buf[KPCN_BUF_COLOR], n * sizeof(float));
      else
        st = kpcn_last_status();
      /* the metrics would leave such pixels out silently, and --best would choose by them */
      for (size_t k = 0; st == KPCN_OK && k < n; k++)
        if (!isfinite(t->val_ref[i][k]))
          st = kpcn_fail(KPCN_ERR_NONFINITE,
                         "validation reference '%s': non-finite colour at pixel (%zu, %zu)",
                         t->s.val_ref[i], k % (n / 3) % (size_t)ref->width,
                         k % (n / 3) / (size_t)ref->width); /* planar: R, G, B planes */
    }
    kpcn_aov_destroy(ref);
    KPCN_TRY(st);
  }
  return KPCN_OK;
}

static float *talloc(size_t n, kpcn_status *st) {
  float *p = kpcn_alloc(n * sizeof(float), "training tensor");
  if (!p) *st = kpcn_last_status();
  return p;
}

static kpcn_status setup_nets(kpcn_trainer *t) {
  kpcn_net_options no;
  kpcn_net_options_defaults(&no);
  no.batch = t->N;
  no.height = no.width = t->P;
  no.training = 1;
  no.nthreads = t->nt;
  no.precision = t->s.bf16 ? KPCN_PREC_BF16 : KPCN_PREC_F32;
  for (int b = 0; b < KT_NB; b++) {
    KPCN_TRY(kpcn_net_create(t->model, (kpcn_branch)b, &no, &t->net[b]));
    int np = kpcn_net_param_count(t->net[b]);
    t->params[b] = kpcn_calloc((size_t)np, sizeof(kpcn_param), "parameter list");
    /* two spare blocks: the source score's row and bias split off the output layer's */
    t->blocks[b] = kpcn_calloc((size_t)np + 2, sizeof(kpcn_param_block), "parameter blocks");
    if (!t->params[b] || !t->blocks[b]) return kpcn_last_status();
    KPCN_TRY(kpcn_net_params(t->net[b], t->params[b], np));
    size_t total = 0;
    int nb = 0;
    const int split = t->arch.source_weight && t->s.source_lr_scale > 0;
    for (int i = 0; i < np; i++) {
      kpcn_param_block blk = {t->params[b][i].value, t->params[b][i].grad, t->params[b][i].count,
                              0.0f};
      total += blk.count;
      /* the output layer (weight 2·n_hidden, bias 2·n_hidden + 1): its last row (OIHW) or
       * element is the source score's; same order, so Adam's state lines up either way */
      if (split && (i == 2 * t->arch.n_hidden || i == 2 * t->arch.n_hidden + 1)) {
        const size_t row =
            i == 2 * t->arch.n_hidden ? blk.count / (size_t)kpcn_arch_logit_channels(&t->arch) : 1;
        kpcn_param_block head = blk, score = blk;
        head.count = blk.count - row;
        score.param += head.count, score.grad += head.count, score.count = row;
        score.lr_scale = (float)t->s.source_lr_scale;
        t->blocks[b][nb++] = head;
        t->blocks[b][nb++] = score;
      } else {
        t->blocks[b][nb++] = blk;
      }
    }
    t->nparams[b] = np;
    t->nblocks[b] = nb;
    KPCN_TRY(kpcn_adam_create(&t->adam[b], &t->s.adam, total));
  }
  return KPCN_OK;
}

/* The model records the median exposure of its training images (arch.exposure), at which the
 * denoiser shows it every input: the store's, replacing an init model's (the model is now
 * trained on this store). A store written before sources carried an exposure leaves it as
 * it was. Deterministic in the store, so a resumed run has the same arch. */
static kpcn_status record_exposure(kpcn_trainer *t) {
  double m;
  KPCN_TRY(kpcn_patchstore_exposure(t->ps, &m));
  if (t->s.normalize_exposure)
    for (int i = 0; i < kpcn_patchstore_nsources(t->ps); i++) {
      const kpcn_patch_source *src = kpcn_patchstore_source(t->ps, i);
      if (!(src->exposure > 0.0))
        return kpcn_fail(KPCN_ERR_FORMAT,
                         "normalize_exposure: patch store '%s' source %d (%s) records no "
                         "exposure (written before kpcn-dataset recorded them: run kpcn-dataset "
                         "patches again)",
                         t->store_path, i, src->scene);
    }
  if (t->s.init_model && !t->s.resume) t->init_exposure = kpcn_model_arch(t->model)->exposure;
  if (!(m > 0.0)) return KPCN_OK;
  KPCN_TRY(kpcn_model_set_exposure(t->model, (float)m));
  t->arch = *kpcn_model_arch(t->model);
  return KPCN_OK;
}

/* The store and the initial model are read, the rest written: no two may be one file (a CSV
 * written over the patch store destroys it). */
static kpcn_status check_output_paths(const kpcn_train_settings *s, const char *const path[7]) {
  static const char *what[7] = {
      "the patch store (--store)", "the initial model (--init)", "the model (-o)",
      "the checkpoint (--ckpt)",   "the CSV log (--csv)",        "the plot (--plot)",
      "the best model (--best)"};
  for (int i = 0; i < 7; i++)
    for (int j = i + 1; j < 7; j++) {
      if (!path[i] || !path[j] || !*path[i] || !*path[j]) continue;
      if (i == 1 && j == 2) continue; /* fine-tuning a model in place is allowed */
      if (kpcn_same_file(path[i], path[j]))
        return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "%s and %s are the same file '%s'", what[i],
                         what[j], path[j]);
    }
  /* The plot is a PNG: under another extension it would be mislabelled. */
  if (path[5] && *path[5])
    KPCN_TRY(kpcn_check_extension(path[5], ".png", "the plot (--plot)", "PNG"));
  /* Every output checked now, not when it is first written (the plot after the last
   * iteration): a missing folder or a device there would cost the whole run. The model's own
   * path may not be empty; '' turns the others off. */
  for (int i = 2; i < 7; i++) {
    if (!path[i] || (i > 2 && !*path[i])) continue;
    KPCN_TRY(kpcn_check_output_path(path[i], what[i]));
    for (int v = 0; v < s->nval; v++) {
      KPCN_TRY(
          kpcn_check_not_input(path[i], what[i], s->val_noisy[v], "a --val or --val-store input"));
      KPCN_TRY(kpcn_check_not_input(path[i], what[i], s->val_ref[v],
                                    "a --val or --val-store reference"));
    }
  }
  return KPCN_OK;
}

kpcn_status kpcn_train_settings_check(const kpcn_train_settings *s) {
  if (!s) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_train_settings_check: NULL");
  if (!s->store_path) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "no patch store given");
  if (!s->out_path) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "no output model path given");
  if (s->batch < 1 || s->batch > 256)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "batch %d out of range 1..256", s->batch);
  if (s->best_by != KPCN_VAL_MEAN && s->best_by != KPCN_VAL_GEOMEAN)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "unknown best_by %d", (int)s->best_by);
  if (s->patch < 8 || s->patch > 1024)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "patch %d out of range 8..1024", s->patch);
  if (s->iters < 0)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "iters %lld < 0", (long long)s->iters);
  if (!(s->firefly == 0.0 || (s->firefly >= 1.0 && s->firefly <= 1e30)))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "firefly %g must be 0 (off) or a ratio >= 1",
                     s->firefly);
  if (s->loss_margin < 0 || 2 * s->loss_margin >= s->patch)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "loss margin %d too large for patch %d",
                     s->loss_margin, s->patch);
  if ((s->loss1 == KPCN_LOSS_SSIM || s->loss2 == KPCN_LOSS_SSIM) &&
      (s->loss.ssim_window < 1 || s->loss.ssim_window % 2 == 0 ||
       s->loss.ssim_window > s->patch - 2 * s->loss_margin))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "SSIM loss: window %d must be odd and no larger than the %d-pixel loss "
                     "region (patch %d less twice the loss margin %d)",
                     s->loss.ssim_window, s->patch - 2 * s->loss_margin, s->patch, s->loss_margin);
  if (!(s->stage2_lr >= 0) || s->stage2_lr > 1)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "stage-2 learning rate %g out of range",
                     s->stage2_lr);
  if (s->best_path && *s->best_path && !s->nval)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "keeping the best model needs validation images (--val)");
  if (s->frozen[0] && s->frozen[1])
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "both branches are frozen: there would be nothing to train");
  if ((s->frozen[0] || s->frozen[1]) && !s->init_model && !s->resume)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "freezing the %s branch needs a model to start from (init_model) or a "
                     "checkpoint to resume: a frozen branch of random weights would stay random",
                     s->frozen[0] ? "diffuse" : "specular");
  if (s->nval < 0 || (s->nval && (!s->val_noisy || !s->val_ref)))
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "validation list is inconsistent");
  if (s->widen_channels > 0 && !s->init_model)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "widening (widen_channels, kpcn-train --widen) needs an init model to "
                     "widen (init_model, --init)");
  /* the architecture a fresh run builds (an init model brings its own): an even kernel or
   * conv size is a usage mistake, refused before the store is read */
  if (!s->init_model) {
    kpcn_arch a = s->arch;
    if (a.n_inputs == 0) { /* kpcn_trainer_create sets the feature builder's list */
      const char *names[KPCN_NN_MAX_INPUTS];
      int n = kpcn_features_channel_names(KPCN_BRANCH_DIFFUSE, names, KPCN_NN_MAX_INPUTS);
      KPCN_TRY(kpcn_arch_set_inputs(&a, n, names));
    }
    if (kpcn_arch_validate(&a) != KPCN_OK)
      return kpcn_fail_context("architecture (--preset, --layers, --channels, --conv, --kernel, "
                               "--dilations)");
  }
  /* a plot asked for by name is drawn from the CSV log: without the log it would silently
   * not exist (the default plot simply goes with the log) */
  if (s->plot_path && *s->plot_path && s->csv_path && !*s->csv_path)
    return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                     "the plot (--plot) '%s' is drawn from the CSV log, which --csv '' turns off",
                     s->plot_path);
  /* the outputs as kpcn_trainer_create names them */
  char *ckpt = output_path(s->ckpt_path, s->out_path, ".ckpt");
  char *csv = output_path(s->csv_path, s->out_path, ".csv");
  char *plot = output_path(s->plot_path, s->out_path, ".png");
  kpcn_status st = KPCN_ERR_OUT_OF_MEMORY;
  if (ckpt && csv && plot) {
    const char *path[7] = {s->store_path,
                           s->init_model,
                           s->out_path,
                           ckpt,
                           csv,
                           plot,
                           s->best_path && *s->best_path ? s->best_path : NULL};
    st = check_output_paths(s, path);
  }
  free(ckpt), free(csv), free(plot);
  return st;
}

kpcn_status kpcn_trainer_create(kpcn_trainer **out, const kpcn_train_settings *s) {
  if (!out || !s) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_trainer_create: NULL");
  *out = NULL;
  KPCN_TRY(kpcn_train_settings_check(s));
  kpcn_trainer *t = kpcn_calloc(1, sizeof *t, "trainer");
  if (!t) return kpcn_last_status();
  t->s = *s;
  t->stage1_default = t->s.stage1_iters < 0;
  if (t->s.stage1_iters < 0) t->s.stage1_iters = (int64_t)llround(0.6 * (double)s->iters);
  if (t->s.log_every < 1) t->s.log_every = 1;
  t->store_path = dup_or_null(s->store_path);
  t->out_path = dup_or_null(s->out_path);
  t->ckpt_path = output_path(s->ckpt_path, s->out_path, ".ckpt");
  t->csv_path = output_path(s->csv_path, s->out_path, ".csv");
  t->plot_path = output_path(s->plot_path, s->out_path, ".png");
  t->init_model = dup_or_null(s->init_model);
  t->best_path = s->best_path && *s->best_path ? dup_or_null(s->best_path) : NULL;
  t->s.best_path = t->best_path;
  t->snapshot_dir = s->snapshot_dir && *s->snapshot_dir ? dup_or_null(s->snapshot_dir) : NULL;
  t->s.snapshot_dir = t->snapshot_dir;
  t->best_val = INFINITY;
  t->s.store_path = t->store_path, t->s.out_path = t->out_path, t->s.ckpt_path = t->ckpt_path;
  t->s.csv_path = t->csv_path, t->s.plot_path = t->plot_path, t->s.init_model = t->init_model;
  t->nt = kpcn_resolve_threads(s->nthreads);
  t->N = s->batch;
  t->P = s->patch;
  kpcn_status st = KPCN_OK;
#define GO(x)                                                                                      \
  do {                                                                                             \
    if ((st = (x)) != KPCN_OK) goto fail;                                                          \
  } while (0)
  if (!t->store_path || !t->out_path || !t->ckpt_path || !t->csv_path || !t->plot_path)
    GO(KPCN_ERR_OUT_OF_MEMORY);
  /* architecture with the feature builder's inputs */
  t->arch = s->arch;
  {
    const char *names[KPCN_NN_MAX_INPUTS];
    int n = kpcn_features_channel_names(KPCN_BRANCH_DIFFUSE, names, KPCN_NN_MAX_INPUTS);
    GO(kpcn_arch_set_inputs(&t->arch, n, names));
  }
  if (t->init_model) {
    GO(kpcn_model_load(t->init_model, &t->model));
    if (s->widen_channels > 0) {
      kpcn_model *wide = NULL;
      st = kpcn_model_widen(t->model, s->widen_channels, s->seed, &wide);
      if (st != KPCN_OK) kpcn_fail_context("widening model '%s'", t->init_model);
      GO(st);
      kpcn_model_destroy(t->model);
      t->model = wide;
    }
    if (s->kpa_passes > 0) GO(kpcn_model_set_kpa_passes(t->model, s->kpa_passes));
    if (s->eps > 0) GO(kpcn_model_set_eps(t->model, s->eps));
    if (s->source_weight && !kpcn_model_arch(t->model)->source_weight) {
      kpcn_model *sw = NULL;
      GO(kpcn_model_add_source_weight(t->model, &sw));
      kpcn_model_destroy(t->model);
      t->model = sw;
    }
    t->arch = *kpcn_model_arch(t->model);
    if (s->source_lr_scale > 0 && !t->arch.source_weight)
      GO(kpcn_fail(KPCN_ERR_INVALID_ARGUMENT,
                   "source_lr_scale (--source-lr-scale) has no effect: model '%s' predicts no "
                   "source weight (add one with source_weight, --source-weight)",
                   t->init_model));
    char what[600];
    snprintf(what, sizeof what, "model '%s'", t->init_model);
    GO(check_inputs(t, &t->arch, what));
  } else {
    GO(kpcn_arch_validate(&t->arch));
    GO(kpcn_model_create(&t->arch, s->seed, &t->model));
  }
  t->nfeat = t->arch.n_inputs;
  t->K2 = t->arch.kernel_size * t->arch.kernel_size;
  t->passes = kpcn_arch_kpa_passes(&t->arch);
  GO(kpcn_patchstore_open(&t->ps, t->store_path, NULL, 0));
  GO(kt_batch_setup(t));
  GO(record_exposure(t));
  GO(load_validation(t));
  /* only now that every input has been read: a failed create leaves nothing behind */
  if (t->snapshot_dir && mkdir(t->snapshot_dir, 0777) != 0 && errno != EEXIST)
    GO(kpcn_fail(KPCN_ERR_IO, "cannot create snapshot directory '%s': %s", t->snapshot_dir,
                 strerror(errno)));
  struct stat sd; /* EEXIST also for a file of that name, which would fail at the first save */
  if (t->snapshot_dir && (stat(t->snapshot_dir, &sd) != 0 || !S_ISDIR(sd.st_mode)))
    GO(kpcn_fail(KPCN_ERR_IO, "snapshot directory '%s' exists and is not a directory",
                 t->snapshot_dir));
  GO(setup_nets(t));
  {
    size_t pp = (size_t)t->P * t->P, N = (size_t)t->N;
    for (int b = 0; b < KT_NB; b++) {
      t->feat[b] = talloc(N * t->nfeat * pp, &st);
      t->noisy[b] = talloc(N * 3 * pp, &st);
      t->logits[b] = talloc(N * t->K2 * pp, &st);
      t->out[b] = talloc(N * 3 * pp, &st);
      t->target[b] = talloc(N * 3 * pp, &st);
      t->grad[b] = talloc(N * 3 * pp, &st);
      const size_t nm =
          kpcn_kpa_passes_mid_floats(t->passes, t->arch.source_weight, t->N, 3, t->P, t->P);
      if (nm) t->mid[b] = talloc(nm, &st);
    }
    t->albedo = talloc(N * 3 * pp, &st);
    t->refc = talloc(N * 3 * pp, &st);
    t->comb = talloc(N * 3 * pp, &st);
    t->gcomb = talloc(N * 3 * pp, &st);
    t->lossbuf = talloc(3 * N * 3 * pp, &st);
    t->scratch_per_thread = kt_scratch_floats(t->S, t->P, t->nch);
    t->scratch = talloc((size_t)t->nt * t->scratch_per_thread, &st);
    t->batch_idx = kpcn_calloc(N, sizeof(uint64_t), "batch");
    t->batch_ox = kpcn_calloc(N, sizeof(int), "batch");
    t->batch_oy = kpcn_calloc(N, sizeof(int), "batch");
    if (!t->batch_idx || !t->batch_ox || !t->batch_oy) st = KPCN_ERR_OUT_OF_MEMORY;
    GO(st);
  }
  kpcn_rng_seed(&t->rng, s->seed);
  if (s->resume && !*t->ckpt_path)
    GO(kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "resume: the checkpoint path is empty (--ckpt '')"));
  if (s->resume) GO(kt_checkpoint_load(t, t->ckpt_path));
  *out = t;
  return KPCN_OK;
fail:
  kpcn_trainer_destroy(t);
  return st;
#undef GO
}

int64_t kpcn_trainer_iteration(const kpcn_trainer *t) { return t ? t->iter : 0; }
int64_t kpcn_trainer_stage1_iters(const kpcn_trainer *t) { return t ? t->s.stage1_iters : 0; }
kpcn_model *kpcn_trainer_model(kpcn_trainer *t) { return t ? t->model : NULL; }

double kpcn_trainer_flops_per_iter(const kpcn_trainer *t) {
  /* forward F + backward-weights F + backward-data F minus the first layer's (no input
   * gradient is needed), per pixel of each branch */
  const kpcn_arch *a = &t->arch;
  double f = 0, first = 0;
  for (int l = 0; l < kpcn_arch_n_layers(a); l++) {
    double k = a->conv_size[l];
    double fl = 2.0 * kpcn_arch_layer_in(a, l) * kpcn_arch_layer_out(a, l) * k * k;
    f += fl;
    if (l == 0) first = fl;
  }
  /* a frozen branch only runs forward (stage 2) */
  double per_px = 0;
  for (int b = 0; b < KT_NB; b++)
    per_px += t->s.frozen[b] ? f : 3 * f - first;
  return (double)t->N * t->P * t->P * per_px;
}

void kpcn_trainer_get_timing(const kpcn_trainer *t, kpcn_train_timing *out) {
  *out = t->timing;
  out->conv_s = 0;
  for (int b = 0; b < KT_NB; b++) {
    kpcn_net_stats ns;
    kpcn_net_get_stats(t->net[b], &ns);
    out->conv_s += ns.fwd_conv_s + ns.bwd_conv_s;
  }
}

/* forward of one branch: logits (read where and as the net left them, no reorder) -> planar
 * softmax weights in t->logits -> out */
static kpcn_status branch_forward(kpcn_trainer *t, int b) {
  double t0 = kt_now();
  const void *lg;
  KPCN_TRY(kpcn_net_forward_logits(t->net[b], t->feat[b], &lg, &t->lay[b]));
  if (!t->dlogits[b]) {
    t->dlogits[b] = kpcn_alloc(sizeof(float) * (size_t)t->N * t->lay[b].image_stride, "dlogits");
    if (!t->dlogits[b]) return KPCN_ERR_OUT_OF_MEMORY;
  }
  const size_t ns = kpcn_kpa_passes_scratch_floats(t->passes, t->arch.source_weight, t->N, 3, t->P,
                                                   t->P, &t->lay[b]);
  if (ns > t->kpa_scratch_n) {
    free(t->kpa_scratch);
    t->kpa_scratch = kpcn_alloc(sizeof(float) * ns, "kernel-pass scratch");
    if (!t->kpa_scratch) return KPCN_ERR_OUT_OF_MEMORY;
    t->kpa_scratch_n = ns;
  }
  double t1 = kt_now();
  /* the first pass leaves the planar softmax weights in t->logits for the backward */
  kpcn_status st = kpcn_kpa_forward_passes(t->arch.kernel_size, t->passes, t->arch.source_weight,
                                           t->N, 3, t->P, t->P, lg, &t->lay[b], t->noisy[b],
                                           t->mid[b], t->out[b], t->logits[b], t->nt);
  t->timing.net_s += t1 - t0;
  t->timing.kpa_s += kt_now() - t1;
  return st;
}

/* backward of one branch from dL/dout in t->grad[b], then its Adam step */
static kpcn_status branch_backward_step(kpcn_trainer *t, int b) {
  double t0 = kt_now();
  KPCN_TRY(kpcn_kpa_backward_passes(t->arch.kernel_size, t->passes, t->arch.source_weight, t->N, 3,
                                    t->P, t->P, t->logits[b], t->noisy[b], t->mid[b], t->grad[b],
                                    t->dlogits[b], &t->lay[b], t->kpa_scratch, t->nt));
  double t1 = kt_now();
  KPCN_TRY(kpcn_net_backward_logits(t->net[b], t->dlogits[b], NULL));
  double t2 = kt_now();
  kpcn_status st = kpcn_adam_step(t->adam[b], t->blocks[b], t->nblocks[b], t->nt, NULL);
  t->timing.kpa_s += t1 - t0;
  t->timing.net_s += t2 - t1;
  t->timing.adam_s += kt_now() - t2;
  return st;
}

static kpcn_status trainer_step(kpcn_trainer *t, double *loss);

kpcn_status kpcn_trainer_step(kpcn_trainer *t, double *loss) {
  if (!t) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "kpcn_trainer_step: NULL trainer");
  unsigned csr = kpcn_fast_fp_begin(t->nt);
  kpcn_status s = trainer_step(t, loss);
  kpcn_fast_fp_end(csr, t->nt);
  return s;
}

static kpcn_status trainer_step(kpcn_trainer *t, double *loss) {
  double t_start = kt_now();
  KPCN_TRY(kt_batch_assemble(t));
  t->timing.batch_s += kt_now() - t_start;
  double total = 0, tl;
  if (t->iter < t->s.stage1_iters) {
    for (int b = 0; b < KT_NB; b++) {
      double v;
      if (t->s.frozen[b]) continue; /* its own target only: nothing to learn, nothing to run */
      KPCN_TRY(branch_forward(t, b));
      tl = kt_now();
      KPCN_TRY(kt_loss(t, t->s.loss1, t->out[b], t->target[b], t->grad[b], &v));
      t->timing.loss_s += kt_now() - tl;
      KPCN_TRY(branch_backward_step(t, b));
      total += v;
    }
  } else {
    size_t n = (size_t)t->N * 3 * t->P * t->P;
    if (t->s.stage2_lr > 0)
      for (int b = 0; b < KT_NB; b++)
        kpcn_adam_set_lr(t->adam[b], t->s.stage2_lr);
    for (int b = 0; b < KT_NB; b++)
      KPCN_TRY(branch_forward(t, b));
    tl = kt_now();
    kpcn_recombine(t->out[0], t->out[1], t->albedo, t->arch.eps, n, t->comb);
    KPCN_TRY(kt_loss(t, t->s.loss2, t->comb, t->refc, t->gcomb, &total));
    kpcn_recombine_backward(t->gcomb, t->out[1], t->albedo, t->arch.eps, n, t->grad[0], t->grad[1]);
    t->timing.loss_s += kt_now() - tl;
    for (int b = 0; b < KT_NB; b++)
      if (!t->s.frozen[b]) KPCN_TRY(branch_backward_step(t, b));
  }
  if (!isfinite(total))
    return kpcn_fail(KPCN_ERR_NONFINITE, "training loss is %g at iteration %lld", total,
                     (long long)t->iter);
  t->iter++;
  t->timing.total_s += kt_now() - t_start;
  t->timing.steps++;
  if (loss) *loss = total;
  return KPCN_OK;
}

/* relMSE, SSIM and PSNR of one validation image (planar RGB) against pair i's reference,
 * added to acc[3] and (relMSE's log) to *acc_log. */
static kpcn_status add_val_figures(const kpcn_trainer *t, int i, const float *img,
                                   const kpcn_metric_options *mo, double acc[3], double *acc_log) {
  static const kpcn_metric ms[3] = {KPCN_METRIC_RELMSE, KPCN_METRIC_SSIM, KPCN_METRIC_PSNR};
  const kpcn_aov_set *a = t->val_aov[i];
  for (int m = 0; m < 3; m++) {
    kpcn_metric_result r;
    KPCN_TRY(kpcn_metric_planar(ms[m], img, t->val_ref[i], a->width, a->height, 3, mo, &r, NULL));
    acc[m] += r.value;
    /* a denoised image equal to its reference would give log 0: 1e-30 keeps it finite (and
     * far below any real figure) */
    if (m == 0) *acc_log += log(fmax(r.value, 1e-30));
  }
  return KPCN_OK;
}

static void val_means(const kpcn_trainer *t, const double acc[3], double acc_log,
                      kpcn_val_result *out) {
  out->relmse = acc[0] / t->nval;
  out->ssim = acc[1] / t->nval;
  out->psnr = acc[2] / t->nval;
  out->relmse_geo = exp(acc_log / t->nval);
}

kpcn_status kpcn_trainer_validate(kpcn_trainer *t, kpcn_val_result *out) {
  if (!t->nval) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "no validation images given");
  kpcn_denoiser_options o;
  kpcn_denoiser_options_defaults(&o);
  o.method = KPCN_DENOISE_KPCN;
  o.nthreads = t->nt;
  kpcn_denoiser *d = NULL;
  KPCN_TRY(kpcn_denoiser_create_with_model(&d, t->model, &o));
  kpcn_metric_options mo;
  kpcn_metric_options_defaults(&mo);
  mo.nthreads = t->nt;
  double acc[3] = {0, 0, 0}, acc_log = 0;
  kpcn_status st = KPCN_OK;
  for (int i = 0; i < t->nval && st == KPCN_OK; i++) {
    const kpcn_aov_set *a = t->val_aov[i];
    float *den = kpcn_alloc(3 * kpcn_aov_plane_size(a) * sizeof(float), "validation output");
    if (!den) {
      st = kpcn_last_status();
      break;
    }
    st = kpcn_denoiser_execute_aov(d, a, den);
    if (st == KPCN_OK) st = add_val_figures(t, i, den, &mo, acc, &acc_log);
    free(den);
    if (st != KPCN_OK) kpcn_fail_context("validating on '%s'", t->s.val_noisy[i]);
  }
  kpcn_denoiser_destroy(d);
  KPCN_TRY(st);
  val_means(t, acc, acc_log, &t->last_val);
  t->have_val = 1;
  if (out) *out = t->last_val;
  return KPCN_OK;
}

kpcn_status kpcn_trainer_validate_noisy(kpcn_trainer *t, kpcn_val_result *out) {
  if (!t || !out) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "validate_noisy: NULL argument");
  if (!t->nval) return kpcn_fail(KPCN_ERR_INVALID_ARGUMENT, "no validation images given");
  kpcn_metric_options mo;
  kpcn_metric_options_defaults(&mo);
  mo.nthreads = t->nt;
  double acc[3] = {0, 0, 0}, acc_log = 0;
  for (int i = 0; i < t->nval; i++) {
    const kpcn_aov_set *a = t->val_aov[i];
    const size_t P = kpcn_aov_plane_size(a);
    const float *col = a->buf[KPCN_BUF_COLOR];
    float *sum = NULL;
    if (!col) { /* the colour is diffuse + specular (the trainer's inputs have both) */
      sum = kpcn_alloc(3 * P * sizeof(float), "validation colour");
      if (!sum) return kpcn_last_status();
      for (size_t k = 0; k < 3 * P; k++)
        sum[k] = a->buf[KPCN_BUF_DIFFUSE][k] + a->buf[KPCN_BUF_SPECULAR][k];
      col = sum;
    }
    kpcn_status st = add_val_figures(t, i, col, &mo, acc, &acc_log);
    free(sum);
    if (st != KPCN_OK) return kpcn_fail_context("measuring the noisy '%s'", t->s.val_noisy[i]);
  }
  val_means(t, acc, acc_log, out);
  return KPCN_OK;
}
