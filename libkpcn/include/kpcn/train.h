/* kpcn/train.h — training the KPCN in C (seed chapters 4.4, 5, 6; DESIGN.md §5, §9).
 *
 * Pieces, usable on their own:
 *   - losses with gradients (L1, L2, relMSE, relL1, SSIM) on planar fp32 images;
 *   - Adam with exponential learning-rate decay and optional global-norm clipping;
 *   - Xavier init and the trainer's checkpointable RNG;
 *   - training curves: CSV log and a PNG plot;
 *   - the trainer (kpcn_trainer_*): patch store -> augmentation -> features -> two
 *     branches -> kernel prediction -> loss -> Adam, two stages, validation on full
 *     images, atomic checkpoints with bit-exact resume.
 * Conventions as in common.h: status returns, kpcn_last_error(), no printing, explicit
 * nthreads (0 = all cores). The losses, Adam and the curves give the same results for any
 * thread count; a training run is reproducible bit for bit for a seed AND a thread count
 * (oneDNN's convolutions sum in a thread-dependent order: other counts differ in the last
 * bits, about 1e-7 per weight after a few hundred iterations).
 */
#ifndef KPCN_TRAIN_H
#define KPCN_TRAIN_H

#include "kpcn/augment.h"
#include "kpcn/common.h"
#include "kpcn/nn.h"

#ifdef __cplusplus
extern "C" {
#endif

/* ====================================================================== losses ====
 * Images are planar fp32: n images x c planes x h rows x w columns, image-major.
 * Every loss is a MEAN (over all elements; for SSIM over all valid window positions of
 * all planes), so its scale does not depend on batch or patch size.
 *   l1     |x - y|
 *   l2     (x - y)^2                    (plain mean; the seed's 1/2 factor is dropped so
 *                                        the value equals the MSE metric)
 *   relmse (x - y)^2 / (y^2 + eps)      eps = rel_eps (0.01, as the relMSE metric)
 *   rell1  |x - y| / (|y| + eps)
 *   relmse-sg (x - y)^2 / (sg(x)^2 + eps)  the prediction's own square in the denominator,
 *                                        treated as a constant (stop-gradient; Lehtinen et
 *                                        al. 2018's HDR loss): the gradient is
 *                                        2 (x - y) / (x^2 + eps), zero where x = E[y], so
 *                                        unlike relmse it does not pull predictions dark
 *   rell1-sg  |x - y| / (|sg(x)| + eps)  the same for relative L1: gradient
 *                                        sign(x - y) / (|x| + eps), zero at the median of y
 *   ssim   1 - SSIM(x, y)               Wang 2004 per plane, Gaussian window
 *                                        (ssim_window x ssim_window, sigma ssim_sigma),
 *                                        C1 = (k1 L)^2, C2 = (k2 L)^2, L = ssim_range;
 *                                        only "valid" window positions (never padded)
 * relmse and rell1 divide by a function of the REFERENCE y only, so the denominator is
 * a constant w.r.t. the prediction x (Rousselle 2011, Bako 2017 normalise the same way);
 * the gradient does not differentiate it. Because 1/(y^2 + eps) weights darker references
 * more, their minimiser over a spread of plausible references lies below the mean: a dark
 * bias, which relmse-sg avoids. L1's subgradient at x == y is 0.
 */
typedef enum kpcn_loss_kind {
  KPCN_LOSS_L1 = 0,
  KPCN_LOSS_L2 = 1,
  KPCN_LOSS_RELMSE = 2,
  KPCN_LOSS_RELL1 = 3,
  KPCN_LOSS_SSIM = 4,
  KPCN_LOSS_RELMSE_SG = 5,
  KPCN_LOSS_RELL1_SG = 6
} kpcn_loss_kind;

typedef struct kpcn_loss_settings {
  double rel_eps;         /* 0.01 */
  int ssim_window;        /* odd; 11 (Wang 2004). 64x64 patches leave 54x54 valid positions. */
  float ssim_sigma;       /* 1.5 */
  float ssim_k1, ssim_k2; /* 0.01, 0.03 */
  float ssim_range;       /* dynamic range L, 1.0 */
} kpcn_loss_settings;

void kpcn_loss_settings_defaults(kpcn_loss_settings *s);
/* "l1", "l2", "relmse", "rell1", "ssim", "relmse-sg", "rell1-sg". */
const char *kpcn_loss_name(kpcn_loss_kind k);
/* Accepts the names above and "mse" for l2; error names the string. */
kpcn_status kpcn_loss_parse(const char *name, kpcn_loss_kind *out);

/* value = loss(pred, ref); grad (may be NULL) receives d value / d pred (n*c*h*w floats).
 * settings NULL = defaults. The value is summed in double in a fixed order. */
kpcn_status kpcn_loss_compute(kpcn_loss_kind kind, const kpcn_loss_settings *settings,
                              const float *pred, const float *ref, int n, int c, int w, int h,
                              float *grad, double *value, int nthreads);

/* ======================================================================= RNG ====
 * splitmix64: the whole state is one word, stored in checkpoints. */
typedef struct kpcn_rng {
  uint64_t state;
} kpcn_rng;
void kpcn_rng_seed(kpcn_rng *r, uint64_t seed);
uint64_t kpcn_rng_next(kpcn_rng *r);
double kpcn_rng_uniform(kpcn_rng *r);             /* [0, 1) with 53 bits */
uint32_t kpcn_rng_below(kpcn_rng *r, uint32_t n); /* [0, n) */

/* Xavier/Glorot uniform init: U(-a, a), a = sqrt(6/(fan_in+fan_out)); for a k x k conv
 * fan_in = Cin k^2, fan_out = Cout k^2. Draws `count` values in order from rng. */
kpcn_status kpcn_xavier_uniform(float *w, size_t count, int fan_in, int fan_out, kpcn_rng *rng);

/* ====================================================================== Adam ====
 * Kingma & Ba Algorithm 1: m = b1 m + (1-b1) g; v = b2 v + (1-b2) g^2;
 * p -= lr_t * m_hat / (sqrt(v_hat) + eps), m_hat = m/(1-b1^t), v_hat = v/(1-b2^t).
 * lr_t = lr * lr_decay^(t / decay_every)   (t = steps already taken; with staircase the
 * exponent is floored — TensorFlow's exponential_decay, which the seed used).
 * clip_norm > 0: gradients are scaled by min(1, clip_norm / ||g||_2) over ALL blocks. */
typedef struct kpcn_adam_settings {
  double lr;           /* 1e-3 (seed) */
  double beta1;        /* 0.9 */
  double beta2;        /* 0.999 */
  double eps;          /* 1e-8 */
  double lr_decay;     /* 0.96 (seed §6) */
  int64_t decay_every; /* 100000 (seed §6.4); <= 0 disables decay */
  int staircase;       /* 0 */
  double clip_norm;    /* 0 = off */
} kpcn_adam_settings;

void kpcn_adam_settings_defaults(kpcn_adam_settings *s);
/* Learning rate used for the step after `iter` completed steps. */
double kpcn_adam_lr_at(const kpcn_adam_settings *s, int64_t iter);

/* One contiguous parameter tensor and its gradient (same length). */
typedef struct kpcn_param_block {
  float *param;
  const float *grad;
  size_t count;
  float lr_scale; /* this block's learning rate = the schedule's x lr_scale (0 reads as 1) */
} kpcn_param_block;

/* Opaque optimizer for `count` parameters in total (the blocks passed to every step
 * must be the same sequence, summing to count). */
typedef struct kpcn_adam kpcn_adam;
kpcn_status kpcn_adam_create(kpcn_adam **out, const kpcn_adam_settings *s, size_t count);
void kpcn_adam_destroy(kpcn_adam *a);
/* One update of all blocks; grad_norm (may be NULL) receives the pre-clip L2 norm.
 * Fails with KPCN_ERR_NONFINITE when the gradient norm is not finite (nothing updated). */
kpcn_status kpcn_adam_step(kpcn_adam *a, const kpcn_param_block *blocks, int nblocks, int nthreads,
                           double *grad_norm);
/* Global L2 norm of the gradients (fixed-order reduction). */
double kpcn_grad_norm(const kpcn_param_block *blocks, int nblocks, int nthreads);
/* State access for checkpoints: moments are `count` floats each, in block order. */
size_t kpcn_adam_count(const kpcn_adam *a);
int64_t kpcn_adam_steps(const kpcn_adam *a);
void kpcn_adam_set_steps(kpcn_adam *a, int64_t t);
float *kpcn_adam_moment1(kpcn_adam *a);
float *kpcn_adam_moment2(kpcn_adam *a);
const kpcn_adam_settings *kpcn_adam_get_settings(const kpcn_adam *a);
/* Changes the base learning rate of later steps (the decay schedule still applies). */
void kpcn_adam_set_lr(kpcn_adam *a, double lr);

/* ============================================================ curves: PNG plot ====
 * Draws up to KPCN_PLOT_MAX_SERIES poly-lines on shared axes (x linear, y linear or
 * log10) with tick labels in a built-in 5x7 bitmap font, a title and a legend, and
 * writes an RGB PNG atomically (stb_image_write). NaN points are skipped. */
#define KPCN_PLOT_MAX_SERIES 8
typedef struct kpcn_plot_series {
  const char *label;
  const double *x, *y;
  int n;
} kpcn_plot_series;

typedef struct kpcn_plot_settings {
  int width, height; /* 800 x 500 */
  int log_y;         /* 1: y axis in log10 (non-positive values skipped) */
  const char *title, *xlabel, *ylabel;
} kpcn_plot_settings;

void kpcn_plot_settings_defaults(kpcn_plot_settings *s);
kpcn_status kpcn_plot_png(const char *path, const kpcn_plot_settings *s,
                          const kpcn_plot_series *series, int nseries);

/* =================================================================== trainer ====
 * Data: a patch store (kpcn/dataset.h) holding, per patch, the raw noisy AOV channels and
 * the reference channels "ref.R.. ref.diffuse.* ref.specular.*" (S x S, S = 65). Only
 * patches whose source split is "train" are drawn (all of them when no source is marked
 * "train"). Each sample: a random P x P crop of the S x S patch (the "shift" augmentation,
 * offsets 0..S-P), then one kpcn_augment_draw (colour swap, mirror, rotation) applied to
 * noisy and reference channels together, then the denoise module's feature builder with the
 * depth normalisation of the patch's SOURCE image (from the store's source statistics).
 *
 * Per branch b: logits = net_b(features_b); out_b = KPA(logits, noisy_pre_b) with "same"
 * borders (the kernel clamps at the patch edge, exactly as inference does at image edges).
 *   stage 1 (iterations < stage1_iters): loss1(out_diffuse, ref_diffuse / (albedo + eps))
 *            and loss1(out_specular, log(1 + ref_specular)), each branch its own Adam step;
 *   stage 2: c = recombine(out_diffuse, out_specular, albedo); loss2(c, ref color), one
 *            step of both branches through the recombination.
 * loss_margin > 0 excludes that many border pixels of the patch from the loss (the
 * gradient there is zero); 0 (default) uses every pixel, as the seed did.
 *
 * Determinism: batches come from a splitmix64 stream and kpcn_augment_draw(seed, counter);
 * every reduction is fixed-order; for a given seed AND thread count the weights after N
 * iterations are bitwise reproducible (oneDNN's convolutions are deterministic for a fixed
 * thread count only). A checkpoint holds weights, both Adam states, the RNG word, the
 * iteration and elapsed time, so --resume continues bit-exactly.
 */
typedef struct kpcn_train_progress {
  int64_t iter, total; /* iterations done, planned */
  int stage;           /* 1 or 2 */
  double loss;         /* mean training loss over the last log interval */
  double lr;
  double its_per_s; /* over the last log interval */
  double elapsed_s, eta_s;
  int has_val;                           /* 1 when validation ran at this iteration: */
  double val_relmse, val_ssim, val_psnr; /* means over the validation images */
  double val_relmse_geo;                 /* geometric mean of the per-pair relMSE */
} kpcn_train_progress;

/* The validation figure that picks the best model (kpcn_train_settings.best_by). The mean
 * relMSE is dominated by the pairs with the largest errors, in practice the few whose 1024-spp
 * references still carry caustic fireflies (v2val: glass-caustics' three pairs are 24 % of
 * the mean at every spp); the geometric mean weighs a relative change equally on every pair,
 * like the "x times below noisy" targets. */
typedef enum kpcn_val_select {
  KPCN_VAL_MEAN = 0,   /* arithmetic mean relMSE (the CSV's val_relmse) */
  KPCN_VAL_GEOMEAN = 1 /* geometric mean relMSE (val_relmse_geo) */
} kpcn_val_select;

/* Full-image validation figures of a model over the validation pairs. */
typedef struct kpcn_val_result {
  double relmse, ssim, psnr; /* means */
  double relmse_geo;         /* exp(mean(log relMSE)) */
} kpcn_val_result;

/* Called after every iteration; return non-zero to stop (the trainer then writes a
 * checkpoint and returns KPCN_OK with stopped = 1). */
typedef int (*kpcn_train_progress_fn)(void *user, const kpcn_train_progress *p);

typedef struct kpcn_train_settings {
  const char *store_path;  /* patch store (.kps), required */
  kpcn_arch arch;          /* architecture (inputs are set by the trainer); from a preset */
  const char *init_model;  /* optional model file to start from (fine-tuning) */
  int widen_channels;      /* > 0 (needs init_model): widen it to this many hidden channels
                              first (kpcn_model_widen with `seed`: same function, more
                              capacity); 0 = as it is */
  int kpa_passes;          /* > 0 (needs init_model): apply its kernels this many times
                              (kpcn_model_set_kpa_passes); 0 = as the model says. Without
                              init_model, arch.kpa_passes decides */
  float eps;               /* > 0 (needs init_model): set its demodulation epsilon
                              (kpcn_model_set_eps); 0 = as the model says. Without
                              init_model, arch.eps decides */
  int source_weight;       /* 1 (needs init_model): add the source score channel to it
                              (kpcn_model_add_source_weight: same function at the start).
                              Without init_model, arch.source_weight decides */
  double source_lr_scale;  /* > 0: the source score's weights and bias learn at this multiple
                              of the learning rate (a zero-initialised channel added to a
                              trained model moves ~lr per step under Adam); 0 = 1 */
  kpcn_loss_kind loss1;    /* stage-1 loss, default l1 (seed §4.4) */
  kpcn_loss_kind loss2;    /* stage-2 loss, default l1 (seed fine-tunes with ssim) */
  kpcn_loss_settings loss; /* defaults */
  int loss_margin;         /* 0 */
  kpcn_adam_settings adam; /* defaults; decay_every default 100000 */
  double stage2_lr;        /* base lr of stage-2 steps; 0 = adam.lr (fine-tuning the whole
                              pipeline usually wants a smaller step than pre-training) */
  kpcn_augment_draw_settings augment; /* defaults of augment.h (colour swap, mirror, rot90) */
  int crop_jitter;                    /* 1: random crop offset (shift); 0: centred crop */
  int normalize_exposure;   /* 1: each patch is shown at the model's exposure (arch.exposure, from
                               the store: needs a store whose sources record theirs), as the
                               denoiser shows every input: noisy colour and references scaled by
                               arch.exposure / the source image's exposure. 0: as rendered */
  double firefly;           /* >= 1: bound each patch's isolated diffuse fireflies with this ratio
                               before its features, as the denoiser bounds its input
                               (kpcn_aov_bound_fireflies, the floor from the source image's
                               exposure); 0 = patches as rendered */
  int frozen[2];            /* frozen[KPCN_BRANCH_*] = 1 (needs init_model): that branch keeps
                               the weights it starts with. In stage 2 it still runs forward
                               (the loss is on the recombined image) but takes no backward
                               pass and no Adam step; in stage 1 it does not run. One branch at
                               most: fine-tuning one branch leaves the other bit for bit as
                               it was. {0, 0} = both train */
  int batch;                /* 16 */
  int patch;                /* P, 64 (<= store patch size) */
  int64_t iters;            /* total iterations, 1000 */
  int64_t stage1_iters;     /* stage-1 iterations, default 0.6 * iters (seed 600k/1M) */
  int nthreads;             /* 0 = all cores */
  int bf16;                 /* 1: bf16 convs, f32 weights/grads/Adam; 0 = f32 */
  uint64_t seed;            /* 1 */
  int64_t log_every;        /* CSV row every N iterations, 10 */
  int64_t val_every;        /* 0 = only at the end */
  int64_t ckpt_every;       /* 0 = only at the end / on stop */
  double time_limit_s;      /* 0 = none: stop cleanly, checkpoint, stopped = 1 */
  const char *out_path;     /* final model, required (written atomically) */
  const char *ckpt_path;    /* NULL = "<out_path>.ckpt"; "" = none */
  const char *csv_path;     /* NULL = "<out_path>.csv"; "" = none */
  const char *plot_path;    /* NULL = "<out_path>.png"; "" = none */
  const char *best_path;    /* NULL/"" = none: after every validation that improves the
                               best_by figure, the model is also written here (atomically) */
  kpcn_val_select best_by;  /* KPCN_VAL_MEAN */
  const char *snapshot_dir; /* NULL/"" = none: every checkpoint (periodic, final) is also kept here
                               as ckpt_<iteration, 6 digits>.safetensors, for weight
                               averaging (kpcn_model_average); created if missing */
  int resume;               /* 1: continue from ckpt_path (must exist) */
  int nval;                 /* validation image pairs (full images) */
  const char *const *val_noisy; /* noisy AOV EXRs */
  const char *const *val_ref;   /* reference EXRs (color R G B used) */
  kpcn_log_fn log;
  void *log_user;
  kpcn_train_progress_fn progress;
  void *progress_user;
} kpcn_train_settings;

/* Defaults as documented above; arch = the "cpu" preset. */
void kpcn_train_settings_defaults(kpcn_train_settings *s);

typedef struct kpcn_trainer kpcn_trainer;

/* The checks kpcn_trainer_create makes before it reads anything: value ranges, option
 * combinations (a frozen branch needs init_model or resume, a named plot needs the CSV log)
 * and every output path (its folder exists, it is no directory, FIFO or device, and it is
 * none of the inputs: the store, init_model, a validation image). Reads and writes nothing,
 * so a front end can tell a usage mistake from a failure of the run (kpcn-train exits 2). */
kpcn_status kpcn_train_settings_check(const kpcn_train_settings *s);

/* Opens and validates the store (channels needed by the feature builder and the targets,
 * patch size >= P; a missing channel fails with KPCN_ERR_FORMAT naming it), loads the
 * validation images, creates the model (Xavier, seed) or loads init_model (its input list
 * must equal the feature list), or restores the checkpoint when resume is set. */
kpcn_status kpcn_trainer_create(kpcn_trainer **out, const kpcn_train_settings *s);
void kpcn_trainer_destroy(kpcn_trainer *t);

/* One iteration (stage chosen by the iteration count); loss receives the iteration's loss
 * (stage 1: sum of both branches' losses), may be NULL. */
kpcn_status kpcn_trainer_step(kpcn_trainer *t, double *loss);
/* Full-image validation of the current model over the validation pairs. */
kpcn_status kpcn_trainer_validate(kpcn_trainer *t, kpcn_val_result *out);
/* The same figures for the validation inputs as rendered (their colour against the
 * references): what a model must beat. kpcn_trainer_run logs them before it starts and warns
 * at the end when the model's geometric-mean relMSE is above them. */
kpcn_status kpcn_trainer_validate_noisy(kpcn_trainer *t, kpcn_val_result *out);
/* Atomic checkpoint / restore (the arch, batch, patch and seed must match the trainer). */
kpcn_status kpcn_trainer_save_checkpoint(kpcn_trainer *t, const char *path);
kpcn_status kpcn_trainer_load_checkpoint(kpcn_trainer *t, const char *path);
/* Runs to s->iters (or the time limit / a stop request): logs, validates, checkpoints,
 * writes the model, the CSV and the plot. stopped (may be NULL) = 1 if it stopped early. */
kpcn_status kpcn_trainer_run(kpcn_trainer *t, int *stopped);

int64_t kpcn_trainer_iteration(const kpcn_trainer *t);
/* The stage-1 length in use: the settings' or, left to its default, 0.6 * iters, or on a
 * resume the checkpoint's. */
int64_t kpcn_trainer_stage1_iters(const kpcn_trainer *t);
kpcn_model *kpcn_trainer_model(kpcn_trainer *t);
/* Conv FLOPs (forward + backward, both branches) of one iteration, for benchmarks:
 * 3 x forward FLOPs (forward, backward-data, backward-weights) less the first layer's
 * backward-data, which is never computed. A frozen branch counts its forward only, as in a
 * stage-2 iteration (in stage 1 it does not run). */
double kpcn_trainer_flops_per_iter(const kpcn_trainer *t);

/* Cumulative wall time of the trainer's iterations by part (seconds), for benchmarks. */
typedef struct kpcn_train_timing {
  double batch_s; /* patch reads, crop, augmentation, features, targets */
  double net_s;   /* kpcn_net_forward + kpcn_net_backward, both branches */
  double conv_s;  /* part of net_s inside oneDNN convolutions (kpcn_net_get_stats) */
  double kpa_s;   /* kernel-prediction forward + backward */
  double loss_s;  /* loss, recombination and their gradients */
  double adam_s;  /* optimizer steps */
  double total_s; /* whole kpcn_trainer_step calls */
  int64_t steps;
} kpcn_train_timing;
void kpcn_trainer_get_timing(const kpcn_trainer *t, kpcn_train_timing *out);

/* The weights a training checkpoint holds, as a model of its architecture (metadata: none
 * beyond the architecture). Errors name the file and the missing or malformed part. */
kpcn_status kpcn_checkpoint_load_model(const char *path, kpcn_model **out);
/* Weight averaging (SWA): the element-wise mean (accumulated in double) of the weights of n
 * model files and/or training checkpoints of one architecture — snapshots of one run. The
 * result carries the first file's metadata plus "train.averaged_snapshots" = n. A file of
 * another architecture is an error naming it; so is one of the same network that records
 * another exposure (arch.exposure: it expects inputs at another scale), with the fix named. */
kpcn_status kpcn_model_average(const char *const *paths, int n, kpcn_model **out);

/* Writes the training-curve plot from a CSV written by the trainer (any columns named
 * loss, val_relmse, val_ssim of the header are drawn against iter). */
kpcn_status kpcn_train_plot_csv(const char *csv_path, const char *png_path, const char *title);
/* One column (ycol, e.g. "loss", "val_relmse"; "val_ssim" is drawn as 1 - SSIM) of several
 * runs' CSVs against xcol ("iter" or "elapsed_s"), one labelled line per run (<= 8). */
kpcn_status kpcn_train_plot_compare(const char *png_path, const char *title, const char *xcol,
                                    const char *ycol, int log_y, int nruns,
                                    const char *const *labels, const char *const *csv_paths);

#ifdef __cplusplus
}
#endif
#endif
