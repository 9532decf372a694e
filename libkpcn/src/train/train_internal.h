/* Private state of the trainer, shared by trainer.c, batch.c, checkpoint.c, run.c. */
#ifndef KPCN_TRAIN_INTERNAL_H
#define KPCN_TRAIN_INTERNAL_H

#include "kpcn/dataset.h"
#include "kpcn/denoise.h"
#include "kpcn/image.h"
#include "kpcn/nn.h"
#include "kpcn/train.h"

#define KT_NB KPCN_N_BRANCHES

struct kpcn_trainer {
  kpcn_train_settings s; /* copy; the string members below own their text */
  char *store_path, *out_path, *ckpt_path, *csv_path, *plot_path, *init_model, *best_path;
  char *snapshot_dir;
  int nt; /* resolved thread count */

  /* patch store */
  kpcn_patchstore *ps;
  int S, nch;                    /* store patch size and channel count */
  int ch_buf[KPCN_BUF_COUNT][3]; /* store channel of noisy buffer planes, -1 absent */
  int ch_var[KPCN_BUF_COUNT];    /* store channel of noisy variances, -1 absent */
  int ch_ref_color[3], ch_ref_diff[3], ch_ref_spec[3];
  uint64_t *train_idx; /* patches drawn for training (split "train") */
  uint64_t ntrain;

  /* model, nets, optimizers */
  kpcn_arch arch;
  kpcn_model *model;
  kpcn_net *net[KT_NB];
  kpcn_param *params[KT_NB];
  kpcn_param_block *blocks[KT_NB];
  int nparams[KT_NB], nblocks[KT_NB]; /* blocks: params, the source score's split off */
  kpcn_adam *adam[KT_NB];

  /* progress state (all of it is in the checkpoint) */
  kpcn_rng rng;
  int64_t iter;
  double elapsed_prev; /* seconds of earlier sessions (resume) */
  int stage1_default;  /* stage1_iters was not given (0.6 * iters): a resume keeps the
                          checkpoint's, so --iters may grow */
  /* training loss summed since the last CSV row, and its count: kept in checkpoints, so the
   * first row after a resume averages the same iterations as an uninterrupted run's */
  double log_loss_sum;
  int64_t log_loss_n;

  /* batch tensors, N x C x P x P */
  int N, P, K2, nfeat;
  float *feat[KT_NB], *noisy[KT_NB], *logits[KT_NB], *out[KT_NB], *target[KT_NB], *grad[KT_NB];
  /* dlogits in the layout the net left its logits in (lay), allocated at the first forward */
  float *dlogits[KT_NB];
  /* arch.kpa_passes > 1: each branch's results of the passes before the last (input of the
   * next), [passes-1][N][3][P][P], and the backward's scratch (kpcn_kpa_backward_passes) */
  float *mid[KT_NB], *kpa_scratch;
  size_t kpa_scratch_n;
  int passes;
  kpcn_logits_layout lay[KT_NB];
  float *albedo, *refc, *comb, *gcomb;
  float *lossbuf; /* margin crops: 3 tensors of N x 3 x (P-2m)^2 */
  /* per-thread scratch for sample assembly: raw S x S patch, crop, augmented, canonical */
  float *scratch;
  size_t scratch_per_thread;
  uint64_t *batch_idx;
  int *batch_ox, *batch_oy;

  /* validation images */
  int nval;
  kpcn_aov_set **val_aov;
  float **val_ref; /* 3 planes each (reference color) */
  kpcn_train_timing timing;
  kpcn_val_result last_val;
  int have_val;
  /* the init model's own recorded exposure (0: none, or no init model), before
   * record_exposure replaced it with the store's: run.c validates the model as given too */
  float init_exposure;
  double best_val; /* lowest best_by figure written to best_path (run.c), +inf if none */
  int ckpt_best;   /* a resumed checkpoint recorded best_val (checkpoint.c): 1 = a figure,
                      2 = "none" (no best model kept before it), 0 = no record (older ones) */
};

/* batch.c */
kpcn_status kt_batch_setup(kpcn_trainer *t);
kpcn_status kt_batch_assemble(kpcn_trainer *t);
size_t kt_scratch_floats(int S, int P, int nch);
/* Loss over the interior (margin) of N x 3 x P x P tensors; grad is full size. */
kpcn_status kt_loss(kpcn_trainer *t, kpcn_loss_kind kind, const float *pred, const float *ref,
                    float *grad, double *value);

/* checkpoint.c */
kpcn_status kt_checkpoint_save(kpcn_trainer *t, const char *path);
kpcn_status kt_checkpoint_load(kpcn_trainer *t, const char *path);

/* trainer.c */
double kt_now(void);
/* "none", "diffuse" or "specular": the branch the settings freeze */
const char *kt_frozen_name(const kpcn_train_settings *s);
/* Learning rate of the step after `iter` completed steps (stage 2 uses stage2_lr). */
double kt_lr_at(const kpcn_trainer *t, int64_t iter);

#endif
