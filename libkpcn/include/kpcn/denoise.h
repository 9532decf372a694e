/* kpcn/denoise.h — the KPCN denoiser (Bako et al. 2017, seed chapter 4, DESIGN.md §5):
 * input preprocessing shared by inference AND training, the two-branch kernel-predicting
 * pipeline, classical baselines (cross-bilateral, non-local means), and an oidn.h-style
 * C API.
 *
 * ---------------------------------------------------------------------------------------
 * 1. Network input ("features"), feature version KPCN_FEATURES_VERSION. One list per branch
 *    (diffuse / specular), identical except for what "color" means:
 *
 *      diffuse branch:  color  = diffuse / (albedo + eps)            (per channel)
 *                       color.var = diffuse.var * mean_c 1/(albedo_c + eps)^2
 *      specular branch: color  = log(1 + max(specular, 0))           (per channel)
 *                       color.var = specular.var * mean_c 1/(1 + max(specular_c, 0))^2
 *
 *    Ordered channel list (36 channels; names as returned by kpcn_features_channel_names):
 *       0.. 2  color.R color.G color.B        preprocessed color (the branch's, above)
 *       3      color.var                      its transformed variance
 *       4.. 6  N.X N.Y N.Z                    normal, as stored (camera space)
 *       7      N.var
 *       8..10  albedo.R albedo.G albedo.B
 *      11      albedo.var
 *      12      Z                              depth normalised per image: (Z - off) * scale
 *      13      Z.var                          Z.var * scale^2
 *      14      visibility.V
 *      15      visibility.var
 *      16..25  dx.color.R dx.color.G dx.color.B dx.N.X dx.N.Y dx.N.Z
 *              dx.albedo.R dx.albedo.G dx.albedo.B dx.Z
 *      26..35  dy.<same ten, same order>
 *
 *    Gradients are central differences with replicated borders of the FULL image:
 *      dx f(x,y) = (f(min(x+1,W-1), y) - f(max(x-1,0), y)) / 2   (dy likewise in y),
 *    taken on the preprocessed / normalised values (color = the branch's preprocessed
 *    color, Z = normalised depth). Central differences keep mirror augmentation exact
 *    (mirroring negates dx). The region variant reads neighbours outside the region, so
 *    a tile's features equal the corresponding crop of the full image's features.
 *
 *    Depth normalisation is per image: off = min Z, scale = 1/(max Z - min Z) over the
 *    finite depth values of the WHOLE image (scale = 1 when the range is < 1e-12).
 *    Compute it once with kpcn_features_norm_compute on the full image and pass it when
 *    building features for tiles or training patches so they see identical inputs.
 *
 *    All buffers of the list plus the branch's color buffer and their variances are
 *    required; a missing one fails with KPCN_ERR_MISSING_CHANNEL naming it ("diffuse",
 *    "visibility.var" ...).
 *
 *    Exposure: "diffuse" and "specular" above are the buffers times norm.color_scale
 *    (variances times its square); 1 unless the denoiser normalises the exposure
 *    (kpcn_denoiser_options.exposure).
 *
 * 2. The kernel filters `noisy_pre` = feature channels 0..2 (the preprocessed noisy color).
 *    Recombination: c = (diffuse_out * (albedo + eps) + exp(specular_out) - 1) / color_scale
 *    (seed eq. 4.4 has a sign typo: "+1").
 * ---------------------------------------------------------------------------------------
 */
#ifndef KPCN_DENOISE_H
#define KPCN_DENOISE_H

#include "kpcn/common.h"
#include "kpcn/augment.h" /* kpcn_augment_xform */
#include "kpcn/image.h"
#include "kpcn/nn.h" /* kpcn_branch, kpcn_model */

#ifdef __cplusplus
extern "C" {
#endif

/* Version of the feature definition above; models record it in arch.preprocess and a
 * model whose preprocess string or input list differs is rejected by the denoiser. */
#define KPCN_FEATURES_VERSION 1
#define KPCN_FEATURES_PREPROCESS "kpcn-pre-1"
/* Number of input channels per branch. */
#define KPCN_FEATURES_COUNT 36
/* Default demodulation epsilon (Bako 2017 code uses 0.00316); models carry their own. */
#define KPCN_FEATURES_DEFAULT_EPS 0.00316f

/* kpcn_branch (KPCN_BRANCH_DIFFUSE / KPCN_BRANCH_SPECULAR) comes from kpcn/nn.h. */

/* "diffuse" / "specular" (NULL for other values). */
const char *kpcn_branch_name(int branch);

/* Number of feature channels of `branch` (KPCN_FEATURES_COUNT), or -1 for a bad branch. */
int kpcn_features_count(int branch);
/* Fills names[0..min(count,max)-1] with the ordered channel names (static strings) and
 * returns the count (or -1 for a bad branch). names may be NULL to query the count. */
int kpcn_features_channel_names(int branch, const char **names, int max);

/* Writes this feature list and KPCN_FEATURES_PREPROCESS into an architecture (use on a
 * preset before kpcn_model_create, so the model file records what it was trained on). */
kpcn_status kpcn_features_set_arch(kpcn_arch *arch);
/* Checks that a model's architecture expects exactly these features (names, count,
 * preprocess string, eps > 0); the error names the first mismatch. */
kpcn_status kpcn_features_check_arch(const kpcn_arch *arch);

/* Per-image normalisation shared by every tile/patch of one image. */
typedef struct kpcn_features_norm {
  float depth_offset; /* subtracted from Z */
  float depth_scale;  /* multiplies (Z - offset); Z.var is multiplied by scale^2 */
  float color_scale;  /* exposure: diffuse and specular are multiplied by it before the
                         colour transforms (their variances by its square), so the
                         network sees the image as if rendered that much brighter; the
                         denoiser divides its result by it. 1 = as rendered. */
} kpcn_features_norm;

/* Computes the normalisation of the full image `aov` (needs depth; NaN/Inf depths are
 * ignored). color_scale is set to 1 (the denoiser sets its own from kpcn_aov_exposure). */
kpcn_status kpcn_features_norm_compute(const kpcn_aov_set *aov, kpcn_features_norm *norm);

/* Builds the features of `branch` for the whole of `aov` (which may itself be a training
 * patch: pass the full image's norm). eps: demodulation epsilon (> 0). norm: NULL =
 * computed from `aov` itself.
 *   out_planar: [KPCN_FEATURES_COUNT][H][W] floats, caller-owned (may be NULL);
 *   noisy_pre:  [3][H][W] floats, the preprocessed noisy color the kernel filters
 *               (a copy of channels 0..2; may be NULL).
 * nthreads: 0 = all cores. Deterministic regardless of thread count. */
kpcn_status kpcn_features_build(const kpcn_aov_set *aov, int branch, float eps,
                                const kpcn_features_norm *norm, float *out_planar, float *noisy_pre,
                                int nthreads);

/* Same for the region [x0, x0+w) x [y0, y0+h) of `aov` (must lie inside it). Gradients
 * at the region's edge use the pixels outside it (replicated only at the IMAGE border),
 * so the result equals the crop of the full-image features. Outputs are w*h planes;
 * out_planar's planes lie out_stride floats apart (0 = w*h; see kpcn_plane_stride). */
kpcn_status kpcn_features_build_region(const kpcn_aov_set *aov, int branch, float eps,
                                       const kpcn_features_norm *norm, int x0, int y0, int w, int h,
                                       float *out_planar, size_t out_stride, float *noisy_pre,
                                       int nthreads);

/* Same features, pixel-major: feature c of region pixel (x, y) at
 * out[(y * w + x) * pixel_stride + c] (pixel_stride >= KPCN_FEATURES_COUNT; the slots past
 * the features are left as they are), as floats or, with bf16 = 1, as bfloat16 rounded to
 * nearest even the way vcvtneps2bf16 does (denormals to zero). That is the layout of a net's
 * own input buffer (kpcn_net_input_buffer), so the net can start without its input reorder:
 * the denoiser builds its features this way where the net allows it. */
kpcn_status kpcn_features_build_region_pixels(const kpcn_aov_set *aov, int branch, float eps,
                                              const kpcn_features_norm *norm, int x0, int y0, int w,
                                              int h, void *out, int pixel_stride, int bf16,
                                              float *noisy_pre, int nthreads);

/* ---- Forward/inverse colour transforms (per element, n = number of floats) ---- */

/* Diffuse demodulation: out[i] = diffuse[i] / (albedo[i] + eps). Used for training
 * targets: pass the REFERENCE diffuse and the albedo that recombination will use (the
 * noisy input's albedo), so that recombining the target reproduces the reference. */
void kpcn_demodulate_diffuse(const float *diffuse, const float *albedo, float eps, size_t n,
                             float *out);
/* Specular transform: out[i] = log(1 + max(specular[i], 0)). Training target for the
 * specular branch (reference specular). */
void kpcn_log_specular(const float *specular, size_t n, float *out);

/* Inverse transforms. out = diffuse_out * (albedo + eps); out = exp(spec_out) - 1. */
void kpcn_remodulate_diffuse(const float *diffuse_out, const float *albedo, float eps, size_t n,
                             float *out);
void kpcn_exp_specular(const float *spec_out, size_t n, float *out);

/* Recombination c = diffuse_out * (albedo + eps) + exp(spec_out) - 1 (n floats; typically
 * 3 planes of H*W). Any of diffuse_out/spec_out may be NULL (that term is omitted). */
void kpcn_recombine(const float *diffuse_out, const float *spec_out, const float *albedo, float eps,
                    size_t n, float *out);
/* Backward of kpcn_recombine: given dL/dc (grad_out), writes
 *   grad_diffuse[i] = grad_out[i] * (albedo[i] + eps)
 *   grad_spec[i]    = grad_out[i] * exp(spec_out[i])
 * (either output may be NULL). */
void kpcn_recombine_backward(const float *grad_out, const float *spec_out, const float *albedo,
                             float eps, size_t n, float *grad_diffuse, float *grad_spec);

/* Bounds isolated diffuse fireflies in place (the KPCN's input conditioning; the denoiser
 * runs it on a copy of its input when kpcn_denoiser_options.firefly > 0, the trainer on each
 * patch when kpcn_train_settings.firefly > 0). With E = mean_c diffuse_c / (albedo_c + eps)
 * (the diffuse branch's irradiance), a pixel whose E exceeds bound = ratio * (the largest E
 * of its 8 neighbours) + 0.01 * exposure (`exposure` if > 0, else kpcn_aov_exposure of `aov`:
 * a training patch passes its whole image's) and whose diffuse relative variance diffuse.var /
 * mean_c(diffuse_c)^2 exceeds 0.25 (its value rests on a few samples) has its diffuse scaled by
 * bound / E, its diffuse.var by the square, and color (if present) lowered by what diffuse lost.
 * Decisions read the E of the input, so the result does not depend on the order pixels are visited.
 * Why: at a partly covered pixel the small albedo turns one bright sample into a large
 * irradiance that neighbours' kernels spread (docs/denoiser.md). ratio >= 1. Needs diffuse
 * with its variance, albedo and specular. *count (may be NULL): pixels bounded. */
kpcn_status kpcn_aov_bound_fireflies(kpcn_aov_set *aov, float ratio, float eps, double exposure,
                                     int *count);

/* ======================================================================================
 * Denoiser (oidn.h style). Lifecycle:
 *   kpcn_denoiser_options o; kpcn_denoiser_options_defaults(&o); o.model_path = "m.safetensors";
 *   kpcn_denoiser *d; kpcn_denoiser_create(&d, &o);
 *   kpcn_denoiser_set_buffer(d, "diffuse", ptr, w, h, pixel_stride, row_stride); ...
 *   kpcn_denoiser_execute(d, out_rgb, w, h, pixel_stride, row_stride);
 *   kpcn_denoiser_destroy(d);
 * ====================================================================================== */

typedef enum kpcn_denoise_method {
  KPCN_DENOISE_KPCN = 0,      /* the network (needs model_path) */
  KPCN_DENOISE_BILATERAL = 1, /* feature-guided cross-bilateral filter */
  KPCN_DENOISE_NLMEANS = 2    /* feature-guided non-local means */
} kpcn_denoise_method;

/* Parameters of the classical baselines (defaults by kpcn_denoiser_options_defaults;
 * see docs/denoiser.md for why). */
typedef struct kpcn_baseline_params {
  int radius;          /* half window: (2r+1)^2 neighbours; bilateral 7, nlmeans 7 */
  float sigma_spatial; /* bilateral: pixel distance sigma (pixels) */
  float k_color;       /* color distance scale in units of the variance (both filters) */
  float sigma_normal;  /* feature distance sigmas (<= 0 disables that feature) */
  float sigma_albedo;
  float sigma_depth; /* on depth normalised per image */
  int patch_radius;  /* nlmeans: patch half size (3 -> 7x7 patches... see doc) */
} kpcn_baseline_params;

/* kpcn_denoiser_options.nthreads' upper bound (OpenMP aborts when it cannot start threads). */
#define KPCN_DENOISE_MAX_THREADS KPCN_MAX_THREADS

typedef struct kpcn_denoiser_options {
  int method;             /* kpcn_denoise_method */
  const char *model_path; /* safetensors model (method KPCN); copied at create */
  int bf16;               /* 1: bf16 inference (convolutions) */
  int tile;               /* KPCN tile size (output pixels per side); 0 = automatic: the
                             grid with the least overlap whose padded tile's buffers fit
                             an eighth of the machine's memory, kept within 1..3 GiB (a
                             1 Mpx frame: one tile on a 24 GB machine). A tile
                             >= the image size denoises in one piece. Tiles are padded by
                             >= kpcn_denoise_tile_overlap(arch) pixels, so every tile sees
                             the inputs the untiled image does; the result agrees across
                             tile sizes to float summation order (oneDNN sums in an order
                             that depends on the tensor's shape: up to ~2e-6 relative with
                             the shipped model, docs/denoiser.md), bit for bit only for
                             some sizes. A tile whose padded tiles would add up to more than
                             25 times the image is refused at execute. */
  int nthreads;           /* 0 = all cores; at most KPCN_DENOISE_MAX_THREADS. Results agree
                             across thread counts to float summation order (oneDNN's
                             choice of kernel depends on it), not always bit for bit */
  int direct_conv;        /* 1: no Winograd convolutions (kpcn_net_options.direct_conv) */
  int ensemble;           /* self-ensemble: 0 or 1 = off; 2, 4 or 8 = denoise that many
                             mirrored / rotated copies of the input and average the results
                             mapped back (kpcn_denoise_ensemble_xform), at that many times the
                             cost, plus one transformed copy of the input buffers and two
                             RGB images of memory. The transforms form a group, so the result
                             is exactly equivariant to them (up to float summation order). */
  /* KPCN only: the exposure (kpcn_aov_exposure, kpcn/image.h) the network is shown every
   * input at: the input's colour is scaled to it before the network and the result scaled
   * back, so renders in any units are denoised alike (denoise(s * img) = s * denoise(img),
   * bit for bit for powers of two). 0 (the default): the model's arch.exposure, the median
   * exposure of its training images (as rendered for a model that records none); > 0: that
   * exposure; KPCN_EXPOSURE_AS_RENDERED: the input as rendered. */
  float exposure;
  /* KPCN only: bound isolated diffuse fireflies before the network (kpcn_aov_bound_fireflies
   * with this ratio, the model's eps); 0 = off. kpcn_denoiser_options_defaults sets
   * KPCN_DENOISE_DEFAULT_FIREFLY. */
  float firefly;
  kpcn_baseline_params bilateral;
  kpcn_baseline_params nlmeans;
} kpcn_denoiser_options;

/* kpcn_denoiser_options.firefly's default (chosen on the validation pairs, docs/denoiser.md). */
#define KPCN_DENOISE_DEFAULT_FIREFLY 4.0f

/* kpcn_denoiser_options.exposure: show the network the input as rendered. */
#define KPCN_EXPOSURE_AS_RENDERED (-1.0f)

void kpcn_denoiser_options_defaults(kpcn_denoiser_options *o);

typedef struct kpcn_denoiser kpcn_denoiser;

/* Creates a denoiser (loads the model for method KPCN). *out owned by caller. A KPCN
 * denoiser keeps its network and tile buffers from one execute to the next (the memory of
 * one padded tile, freed by destroy), so later frames of the same size skip the setup; one
 * denoiser serves one execute at a time (use one per thread). */
kpcn_status kpcn_denoiser_create(kpcn_denoiser **out, const kpcn_denoiser_options *opts);
/* Creates a KPCN denoiser around an in-memory model (borrowed: it must outlive the
 * denoiser; used by training/evaluation and tests with randomly initialised models).
 * opts->method and opts->model_path are ignored: it is always the KPCN on `model`. */
kpcn_status kpcn_denoiser_create_with_model(kpcn_denoiser **out, kpcn_model *model,
                                            const kpcn_denoiser_options *opts);
void kpcn_denoiser_destroy(kpcn_denoiser *d); /* NULL: nothing; d is invalid afterwards */

/* Sets an input buffer by NAME: "color", "diffuse", "specular", "albedo", "normal",
 * "depth", "visibility" (kpcn_buffer_channels(b) channels) or a variance "<name>.var"
 * (1 channel). ptr is borrowed and stays set: every later execute reads it, so it must stay
 * valid until it is unset (ptr NULL) or the denoiser is destroyed. Channel c of pixel
 * (x, y) is read at ((const char*)ptr + y*row_stride + x*pixel_stride)[c * sizeof(float)];
 * pixel_stride 0 = packed (nch*4 bytes), row_stride 0 = width*pixel_stride; strides must be
 * whole floats, pixel_stride >= nch*4 and row_stride >= a row (else KPCN_ERR_INVALID_ARGUMENT:
 * pixels would overlap). A ".var" is the variance of the pixel's mean (sample variance / n),
 * averaged over the buffer's channels (docs/denoiser.md, "Feeding it from a renderer"). For
 * planar data call once per channel with kpcn_denoiser_set_buffer_channel. ptr NULL unsets. */
kpcn_status kpcn_denoiser_set_buffer(kpcn_denoiser *d, const char *name, const float *ptr,
                                     int width, int height, size_t pixel_stride, size_t row_stride);
/* Sets channel `channel` of buffer `name` alone (planar inputs; pixel_stride 0 = one float). */
kpcn_status kpcn_denoiser_set_buffer_channel(kpcn_denoiser *d, const char *name, int channel,
                                             const float *ptr, int width, int height,
                                             size_t pixel_stride, size_t row_stride);
/* Progress callback: fraction in [0,1], ending with 1; a non-zero return, the final call's
 * included, cancels that execute (KPCN_ERR_CANCELLED, the output untouched); the next
 * execute runs afresh. */
void kpcn_denoiser_set_progress(kpcn_denoiser *d, kpcn_progress_fn fn, void *user);

/* Denoises into out (RGB, 3 floats per pixel at out + y*row_stride + x*pixel_stride;
 * strides 0 = packed, checked as set_buffer's). width/height must match the inputs. Fails
 * naming every missing input buffer at once; out may alias an input (inputs are copied
 * first). */
kpcn_status kpcn_denoiser_execute(kpcn_denoiser *d, float *out, int width, int height,
                                  size_t pixel_stride, size_t row_stride);

/* Denoises a planar AOV set directly (no strided input buffers): out_planar is [3][H][W]. */
kpcn_status kpcn_denoiser_execute_aov(kpcn_denoiser *d, const kpcn_aov_set *aov, float *out_planar);

/* The predicted kernels (method KPCN): what the network decided for each pixel, for reading
 * and visualising the denoiser. kpcn_denoiser_kernel_info gives the model's kernel size K,
 * how many times the kernels are applied (arch kpa_passes) and the demodulation eps (either
 * of the last two may be NULL).
 * kpcn_denoiser_kernels_aov runs `branch` (KPCN_BRANCH_DIFFUSE / _SPECULAR) of the network
 * on `aov` exactly as an execute does (the same exposure scale, firefly bound and tiles; the
 * other branch is not run) and writes
 *   weights   [K*K][H][W]: pixel p's softmax weights; tap t = dy*K + dx reads the pixel
 *             p + (dx - K/2, dy - K/2), clamped to the image; each weight >= 0, the K*K
 *             sum to 1;
 *   noisy_pre [3][H][W] (may be NULL): the branch's preprocessed noisy colour (section 2
 *             above, at kpcn_denoise_stats.exposure_scale), what the first pass filters.
 * The branch's result is P passes of f <- sum_t weights[t] * f(p + offset(t)) from
 * f = noisy_pre, and the denoised colour is (diffuse_result * (albedo + eps) +
 * exp(specular_result) - 1) / exposure_scale. Refused for a self-ensemble (ensemble > 1: its
 * members have their own kernels) and for a model with source weights (its first pass is
 * weighted differently). */
kpcn_status kpcn_denoiser_kernel_info(const kpcn_denoiser *d, int *kernel_size, int *passes,
                                      float *eps);
kpcn_status kpcn_denoiser_kernels_aov(kpcn_denoiser *d, const kpcn_aov_set *aov, int branch,
                                      float *weights, float *noisy_pre);

/* Timing of the last execute (seconds), for benchmarks. */
typedef struct kpcn_denoise_stats {
  double total_s;        /* whole execute, including input assembly */
  double features_s;     /* feature building */
  double net_s;          /* network forward (kpcn_net_forward) */
  double conv_s;         /* part of net_s inside oneDNN convolution primitives */
  double kpa_s;          /* softmax + kernel apply */
  double other_s;        /* recombination, copies, net creation */
  double conv_flops;     /* convolution FLOPs executed (both branches, overlap included) */
  int tiles;             /* tiles processed (per branch) */
  int tiles_total;       /* tiles of the grid (per branch; with an ensemble, summed over its
                            members as tiles is) */
  int tile_w, tile_h;    /* output size of a full tile of that grid */
  int nets_created;      /* oneDNN networks built (0 on a warm execute of an unchanged size) */
  double exposure;       /* the input's kpcn_aov_exposure (0 when not measured) */
  double exposure_scale; /* the colour scale the network saw the input at (1 = as rendered) */
  int fireflies; /* pixels kpcn_aov_bound_fireflies bounded (kpcn_denoiser_options.firefly) */
} kpcn_denoise_stats;
/* The last execute's figures: zeroed when it starts (after its argument and size checks),
 * so after a failure or cancel they hold what was done until then; all zero for a NULL d. */
void kpcn_denoiser_get_stats(const kpcn_denoiser *d, kpcn_denoise_stats *s);

/* Largest ensemble size (the eight symmetries of the square). */
#define KPCN_DENOISE_MAX_ENSEMBLE 8
/* Transform i (0..7) of the self-ensemble: 0 identity, 1 mirror_h, 2 rot180, 3 mirror_h +
 * rot180 (= mirror_v), 4 rot90, 5 mirror_h + rot90, 6 rot270, 7 mirror_h + rot270; the first
 * 2, 4 and 8 each form a group. Returns KPCN_ERR_INVALID_ARGUMENT for other i. */
kpcn_status kpcn_denoise_ensemble_xform(int i, kpcn_augment_xform *x);

/* Overlap (pixels per side) a tile needs so tiled == untiled: kpcn_arch_receptive_radius
 * (max(conv radius + (passes-1)·K/2 [+ K/2 with source weights], passes·K/2); 0 for NULL) —
 * logits of an output pixel depend on inputs within the conv radius, each kernel pass reads
 * within K/2, and features are built from the full image. */
int kpcn_denoise_tile_overlap(const kpcn_arch *arch);

/* Convenience: denoises an AOV set into a new 3-channel image (R, G, B). */
kpcn_status kpcn_denoise_aov(const kpcn_aov_set *aov, const kpcn_denoiser_options *opts,
                             kpcn_image **out_rgb);
/* The same, also returning the execute's stats (the exposure measured and the scale applied,
 * timings); stats may be NULL. */
kpcn_status kpcn_denoise_aov_stats(const kpcn_aov_set *aov, const kpcn_denoiser_options *opts,
                                   kpcn_image **out_rgb, kpcn_denoise_stats *stats);

#ifdef __cplusplus
}
#endif
#endif
