/* kpcn/nn.h — the neural-network layer library of kpcn (DESIGN.md §5, seed ch. 4).
 *
 * What lives here
 *  - kpcn_arch   : the KPCN architecture as plain data (layers, channels, conv sizes,
 *                  dilations, kernel-prediction window K, input channel names, eps,
 *                  preprocessing version). Presets "paper" and "cpu".
 *  - kpcn_model  : the weights of the two branches (diffuse, specular) + the arch;
 *                  Xavier init from a seed; safetensors save/load with full validation.
 *  - kpcn_net    : one branch bound to a batch size N and spatial size H x W, executed on
 *                  oneDNN (fp32 or bf16 inference; fp32 training with backward pass).
 *  - kpcn_kpa_*  : the kernel-prediction layer (softmax over K² logits + weighted sum of
 *                  the K x K noisy neighbourhood), forward and backward, plain C + OpenMP.
 *
 * Network (one branch), for layer l = 0 .. n_hidden (n_layers = n_hidden + 1 convs):
 *   in_ch(0) = n_inputs, in_ch(l>0) = channels,
 *   out_ch(l < n_hidden) = channels (ReLU), out_ch(n_hidden) = K*K (linear logits), plus one
 *   source score channel when arch.source_weight.
 *   Conv l has size conv_size[l] (odd) and dilation dilation[l]; padding is "same"
 *   (zero padding of dilation*(size-1)/2), stride 1, so logits are N x K² x H x W.
 *
 * Tensor layouts at the API boundary: planar NCHW fp32, i.e. element (n,c,y,x) at
 *   ((n*C + c)*H + y)*W + x. Weights OIHW fp32 (out, in, ky, kx), bias [out].
 * Kernel-prediction logits index t = dy*K + dx, (dy,dx) in [0,K)², offset (dy-K/2, dx-K/2).
 *
 * Ownership: create/destroy pairs; a kpcn_net references (does not copy) its model's
 * weights and re-reads them at every forward, so an optimizer may update the model's
 * parameter arrays in place between iterations. Destroy nets before their model.
 * Thread counts are explicit (0 = all cores). Results are deterministic for a given
 * thread count (oneDNN 2.6 has no cross-thread-count determinism switch; the kpa layer
 * and init are deterministic regardless of threads).
 */
#ifndef KPCN_NN_H
#define KPCN_NN_H

#include "kpcn/common.h"

#ifdef __cplusplus
extern "C" {
#endif

#define KPCN_NN_MAX_LAYERS 32  /* conv layers per branch, including the output layer */
#define KPCN_NN_MAX_INPUTS 128 /* input channels per branch */
#define KPCN_NN_NAME_LEN 32    /* bytes per name, including the terminating NUL */
#define KPCN_NN_MAX_KERNEL 41  /* largest kernel-prediction window K */

/* ------------------------------------------------------------------ architecture */

typedef struct kpcn_arch {
  char name[KPCN_NN_NAME_LEN];       /* preset / free-form name, e.g. "paper" */
  int n_hidden;                      /* hidden conv layers (ReLU); n_layers = n_hidden + 1 */
  int channels;                      /* C: channels of every hidden layer, in [1, 1024] */
  int conv_size[KPCN_NN_MAX_LAYERS]; /* k per conv layer (odd, 1..11), [0..n_hidden] used */
  int dilation[KPCN_NN_MAX_LAYERS];  /* dilation per conv layer, in [1, 64] */
  int kernel_size;                   /* K: kernel-prediction window (odd, 3..KPCN_NN_MAX_KERNEL) */
  int n_inputs;                      /* input channels per branch (same list for both) */
  char inputs[KPCN_NN_MAX_INPUTS][KPCN_NN_NAME_LEN]; /* input channel names, in order */
  float eps;                         /* albedo epsilon of the diffuse demodulation */
  char preprocess[KPCN_NN_NAME_LEN]; /* preprocessing version string (denoise module) */
  /* Times the predicted kernel is applied (1..KPCN_NN_MAX_KPA_PASSES; 0 reads as 1). 1 is
   * Bako 2017; 2 applies the same per-pixel kernels to the first pass's output, so each
   * output pixel averages a (2K-1)² footprint at no extra network cost (docs/nn.md). */
  int kpa_passes;
  /* 1: the output layer predicts one more channel, a source score s per pixel, and the first
   * kernel pass weights every neighbour q by w(q) = e + (1 - e)·sigmoid(s(q)) (e =
   * KPCN_KPA_SOURCE_EPS), renormalising: out(p) = sum k(p,q) w(q) c(q) / sum k(p,q) w(q).
   * The network can so mark an outlier once and every kernel that reaches it drops it
   * (docs/nn.md, "Source weights"). 0 (default): Bako 2017's kernels. */
  int source_weight;
  /* The median exposure (kpcn_aov_exposure, kpcn/image.h) of the noisy images the model was
   * trained on (kpcn-train records it from its patch store). The denoiser shows the network
   * every input scaled to it (kpcn_denoiser_options.exposure). 0: not recorded. */
  float exposure;
} kpcn_arch;
#define KPCN_NN_MAX_KPA_PASSES 3
#define KPCN_KPA_SOURCE_EPS 1e-3f
/* a->kpa_passes with 0 read as 1 */
static inline int kpcn_arch_kpa_passes(const kpcn_arch *a) {
  return a->kpa_passes > 0 ? a->kpa_passes : 1;
}
/* Channels of the output layer: K² logits, then the source score when a->source_weight. */
static inline int kpcn_arch_logit_channels(const kpcn_arch *a) {
  return a->kernel_size * a->kernel_size + (a->source_weight ? 1 : 0);
}

/* Zeroes *a and sets a valid small default (the "cpu" shape, no inputs named). */
void kpcn_arch_defaults(kpcn_arch *a);

/* Fills *a with a preset: "paper" = 9 hidden x 100 ch x 5x5, K = 21 (seed ch. 4);
 * "cpu" = 6 hidden x 48 ch x 3x3, dilations 1,2,4,8,4,2 then a 3x3 linear layer, K = 11
 * (see docs/nn.md for the FLOP reasoning); "tiny" = 2 hidden x 8 ch x 3x3, K = 5 (tests).
 * Input names are NOT set by presets (those already in *a are kept, else n_inputs = 0): the
 * feature builder of the denoise module supplies them with kpcn_arch_set_inputs.
 * eps = 0.00316, preprocess = "kpcn-pre-1". */
kpcn_status kpcn_arch_preset(const char *name, kpcn_arch *a);

/* Sets the input channel list (n <= KPCN_NN_MAX_INPUTS, names < KPCN_NN_NAME_LEN bytes). */
kpcn_status kpcn_arch_set_inputs(kpcn_arch *a, int n, const char *const *names);

/* Checks every field; the error names the offending field ("arch.conv_size[3] = 4: ..."). */
kpcn_status kpcn_arch_validate(const kpcn_arch *a);

static inline int kpcn_arch_n_layers(const kpcn_arch *a) { return a->n_hidden + 1; }
/* Input / output channel count of conv layer l. */
int kpcn_arch_layer_in(const kpcn_arch *a, int l);
int kpcn_arch_layer_out(const kpcn_arch *a, int l);
/* Receptive-field radius of the conv stack in pixels: sum_l dilation*(size-1)/2. A pixel's
 * logits depend on inputs within this radius; the kernel-prediction output additionally
 * reads the noisy image within K/2 per pass. */
int kpcn_arch_conv_radius(const kpcn_arch *a);
/* Pixels around an output pixel that its value depends on, per input kind: the features
 * (through the logits of every pixel a later pass reads: conv radius + (passes-1)·K/2, + K/2
 * with source weights) and the noisy colour (passes·K/2). A tile computed on its core grown
 * by the larger of the two gives the untiled result. */
int kpcn_arch_receptive_radius(const kpcn_arch *a);
/* Convolution FLOPs (2 per multiply-add) per output pixel of ONE branch, forward only. */
double kpcn_arch_flops_per_pixel(const kpcn_arch *a);
/* Parameter count of one branch. */
size_t kpcn_arch_param_count(const kpcn_arch *a);

/* Architecture <-> JSON text (the form stored in the model file's __metadata__).
 * kpcn_arch_to_json returns a malloc'ed string (caller frees) or NULL on error. */
char *kpcn_arch_to_json(const kpcn_arch *a);
kpcn_status kpcn_arch_from_json(const char *json, kpcn_arch *a);

/* ------------------------------------------------------------------ model */

typedef enum kpcn_branch { KPCN_BRANCH_DIFFUSE = 0, KPCN_BRANCH_SPECULAR = 1 } kpcn_branch;
#define KPCN_N_BRANCHES 2

typedef struct kpcn_model kpcn_model;

/* A view of one conv layer's parameters (pointers into the model; valid until destroy). */
typedef struct kpcn_layer_view {
  float *weight; /* OIHW: [out][in][size][size] */
  float *bias;   /* [out] */
  int out_ch, in_ch, size, dilation;
  int relu; /* 1 for hidden layers, 0 for the output layer */
} kpcn_layer_view;

/* New model with Xavier/Glorot-uniform weights (limit sqrt(6/(fan_in+fan_out)), fan =
 * ch*size²) and zero biases, deterministic in `seed`. arch is copied. */
kpcn_status kpcn_model_create(const kpcn_arch *arch, uint64_t seed, kpcn_model **out);
/* Deep copy. */
kpcn_status kpcn_model_clone(const kpcn_model *m, kpcn_model **out);
/* A copy of m with `channels` (>= m's) hidden channels that computes the same function
 * (function-preserving widening, Net2Net-style): the old units keep their weights and
 * biases and get zero weights from the new channels; the new units get Xavier weights
 * (deterministic in seed) and zero biases. Their outgoing weights start at zero, so the
 * logits are unchanged (up to summation order), and training can use the added capacity
 * from the first step (the zero weights receive gradients). Metadata is copied. */
kpcn_status kpcn_model_widen(const kpcn_model *m, int channels, uint64_t seed, kpcn_model **out);
/* Sets how many times the model's kernels are applied (arch.kpa_passes, 1..
 * KPCN_NN_MAX_KPA_PASSES): the weights are kept, so a fine-tune can start a multi-pass model
 * from a single-pass one. */
kpcn_status kpcn_model_set_kpa_passes(kpcn_model *m, int passes);
/* Sets the albedo epsilon of the diffuse demodulation, diffuse / (albedo + eps) and its
 * inverse (arch.eps, in (0, 1)); the weights are kept. The smaller it is, the flatter the
 * demodulated irradiance across a texture edge (docs/denoiser.md, "The demodulation
 * epsilon"). */
kpcn_status kpcn_model_set_eps(kpcn_model *m, float eps);
/* Records the median exposure of the images the model was trained on (arch.exposure):
 * > 0, or 0 to clear. */
kpcn_status kpcn_model_set_exposure(kpcn_model *m, float exposure);
/* A copy of m with arch.source_weight = 1 that computes the same function: the new source
 * score channel of each branch's output layer gets zero weights and bias, so every weight
 * w(q) starts equal and the normalised kernels are unchanged (up to rounding); training then
 * moves it. m may already have source weights (a plain copy). Metadata is copied. */
kpcn_status kpcn_model_add_source_weight(const kpcn_model *m, kpcn_model **out);
/* Replaces branch b's weights in m by those of `from` (the other branch and the metadata stay
 * m's). The two branches are separate networks whose results are added (diffuse: albedo-
 * remodulated, specular: exp(.) - 1), so a model can take one branch from another model of the
 * same architecture. They must record the same exposure; a specular branch may come from a
 * model of another eps (eps is the diffuse branch's), a diffuse branch may not. Errors
 * (KPCN_ERR_FORMAT) name the mismatch; m is unchanged on error. */
kpcn_status kpcn_model_graft_branch(kpcn_model *m, const kpcn_model *from, kpcn_branch b);
void kpcn_model_destroy(kpcn_model *m);

const kpcn_arch *kpcn_model_arch(const kpcn_model *m);
kpcn_status kpcn_model_layer(kpcn_model *m, kpcn_branch b, int layer, kpcn_layer_view *out);

/* Safetensors I/O. Tensor names: "<branch>.conv<l>.weight" / ".bias", branch in
 * {diffuse, specular}, dtype F32, shapes [out,in,k,k] / [out]. __metadata__ (all string
 * values): "kpcn.format" = "kpcn-model-1", "kpcn.architecture" (kpcn_arch_to_json),
 * "kpcn.inputs" (JSON array), "kpcn.eps", "kpcn.preprocess", plus user entries.
 * Save is atomic (temp file + rename). Load validates header length vs file size, JSON,
 * dtypes, offsets (in range, non-overlapping, covering the data), shapes vs architecture,
 * presence of every tensor, finiteness; errors are KPCN_ERR_FORMAT naming the field or
 * tensor, KPCN_ERR_IO for open/read failures. */
kpcn_status kpcn_model_save(const kpcn_model *m, const char *path);
kpcn_status kpcn_model_load(const char *path, kpcn_model **out);
/* The same from a safetensors file's bytes in memory (a model built into an application's
 * binary; the bytes are only read, and may be freed after the call). Errors name "(memory)"
 * where kpcn_model_load names the file. kpcn_denoiser_create_with_model denoises with it. */
kpcn_status kpcn_model_load_memory(const void *data, size_t size, kpcn_model **out);
/* The file's name of one layer's weight or bias tensor ("diffuse.conv3.bias"). */
void kpcn_model_tensor_name(char *buf, size_t n, kpcn_branch b, int layer, int is_bias);

/* Free-form user metadata stored in __metadata__ (e.g. training iteration, dataset).
 * Keys must not start with "kpcn." (reserved). At most 4090 entries (a model file holds 4096
 * with the kpcn.* keys); a new key beyond that is refused, updating one is not. get returns
 * NULL when absent. */
kpcn_status kpcn_model_set_meta(kpcn_model *m, const char *key, const char *value);
const char *kpcn_model_get_meta(const kpcn_model *m, const char *key);
int kpcn_model_meta_count(const kpcn_model *m);
const char *kpcn_model_meta_key(const kpcn_model *m, int i);

/* ------------------------------------------------------------------ net (oneDNN) */

typedef enum kpcn_precision { KPCN_PREC_F32 = 0, KPCN_PREC_BF16 = 1 } kpcn_precision;

/* Activation layout between layers. AUTO: for f32 training nets, per layer nChw16c (nChw8c
 * on CPUs without AVX-512) where oneDNN has a jit kernel for the layer there (its f32
 * backward-weights is faster on it) and nhwc elsewhere, reordered between layers
 * (kpcn_net_stats.n_relayout); the same for f32 inference nets on CPUs without AVX-512 (the
 * AVX2 forward is 1.5-2x faster on nChw8c); for other nets nhwc (brgconv / AMX kernels), or
 * nChw16c when oneDNN has no optimized nhwc kernel for some layer (kpcn_net_stats.n_slow).
 * The others exist for benchmarking; all give the same results up to summation order. */
typedef enum kpcn_layout {
  KPCN_LAYOUT_AUTO = 0,
  KPCN_LAYOUT_NCHW16C = 1,
  KPCN_LAYOUT_NHWC = 2
} kpcn_layout;

typedef struct kpcn_net_options {
  int batch, height, width; /* N, H, W the net is bound to */
  kpcn_precision precision; /* BF16: weights+activations bf16, fp32 accumulate, fp32 I/O */
  int training;             /* 1: keep activations, enable kpcn_net_backward; with BF16 this is
                               mixed precision (bf16 activations, weight copies and output
                               gradients; weight/bias gradients in f32) */
  int input_grad;           /* 1: backward also computes dL/dinput */
  int nthreads;             /* 0 = all cores */
  kpcn_layout layout;       /* activation layout, AUTO by default */
  /* Floats from one input plane to the next (and from one image's to the next's, times
   * n_inputs); 0 = H*W, dense NCHW. A padded stride (kpcn_plane_stride) keeps the planes off
   * the same cache sets when H*W is a multiple of a power of two such as 1024x1024. */
  size_t input_plane_stride;
  /* 1: direct convolution only. 0 (default): fp32 inference runs 3x3 undilated layers with
   * oneDNN's Winograd F(2,3) kernels where it has them (2.25x fewer multiplies; rounding
   * differs from direct by ~1e-6 relative), in their own blocked layout. */
  int direct_conv;
} kpcn_net_options;

/* The padded plane stride for `pixels` floats: rounded up to 16 floats (64 bytes), then to
 * an odd multiple of 16, so consecutive planes start on different cache sets. */
size_t kpcn_plane_stride(size_t pixels);

void kpcn_net_options_defaults(kpcn_net_options *o); /* N=1, 64x64, F32, inference, 0 */

typedef struct kpcn_net kpcn_net;

/* Binds branch b of model m. m must outlive the net. */
kpcn_status kpcn_net_create(kpcn_model *m, kpcn_branch b, const kpcn_net_options *o,
                            kpcn_net **out);
void kpcn_net_destroy(kpcn_net *net);

/* Rebinds the net to the other branch of its model. Both branches share the arch, so the
 * primitives and buffers stay; only the weights it reads change (the next forward reorders
 * them, as every forward does). Lets one net's memory serve both branches of a denoiser. */
kpcn_status kpcn_net_set_branch(kpcn_net *net, kpcn_branch b);

/* Forward: input [N][n_inputs][H][W] fp32 (planes input_plane_stride apart) -> logits
 * [N][K²(+1 with a source weight)][H][W] fp32. Re-reads the model's weights each call. input may be NULL when the
 * caller has written it into kpcn_net_input_buffer (then no input reorder runs). */
kpcn_status kpcn_net_forward(kpcn_net *net, const float *input, float *logits);

/* The buffer the first layer reads, when it is pixel-major (an inference net whose first
 * layer runs nhwc, as on AVX-512 CPUs): input c of pixel (x, y) of image b at
 * ((b * H + y) * W + x) * pixel_stride + c, floats or (bf16 = 1) bfloat16. Writing the input
 * there and passing input = NULL to kpcn_net_forward[_logits] skips the net's input reorder
 * (a transposing conversion of n_inputs planes). NULL for training nets and other layouts;
 * valid until the net is destroyed. */
void *kpcn_net_input_buffer(kpcn_net *net, int *pixel_stride, int *bf16);

/* Where logit t of pixel (x, y) of image b lies: at
 *   b * image_stride + (t / block) * block_stride + (y * W + x) * pixel_stride + t % block
 * elements. Planar [N][K²][H][W]: block 1, block_stride H*W, pixel_stride 1; pixel-major
 * (nhwc): block >= K², pixel_stride >= K² (a bf16 inference net pads it to a multiple of 16);
 * oneDNN's nChw16c: block 16, pixel_stride 16. Elements are floats, or with bf16 = 1
 * bfloat16 values (uint16_t holding a float's upper half: a bf16 inference net's logits). */
typedef struct kpcn_logits_layout {
  size_t image_stride, block_stride;
  int block, pixel_stride;
  int bf16;
} kpcn_logits_layout;
/* The planar layout of an N x K² x H x W tensor. */
kpcn_logits_layout kpcn_logits_layout_planar(int K2, int h, int w);

/* Forward without the final reorder: *logits points at the last layer's output inside the
 * net (valid until the next forward or destroy) and *layout says how it is laid out, so the
 * kernel-prediction layer can read it in place (kpcn_kpa_forward_layout). When oneDNN's
 * layout is none of the above, the logits are reordered into a planar f32 buffer of the net.
 * bf16 inference nets leave bf16 logits (layout->bf16 = 1; training nets: always f32). */
kpcn_status kpcn_net_forward_logits(kpcn_net *net, const float *input, const void **logits,
                                    kpcn_logits_layout *layout);

/* Backward of the last forward (training nets only): dlogits [N][K²(+1 with a source
 * weight)][H][W] -> parameter gradients (overwritten, not accumulated; see kpcn_net_params)
 * and, when the net was created with input_grad, dinput [N][n_inputs][H][W], dense whatever
 * input_plane_stride says (may be NULL otherwise). */
kpcn_status kpcn_net_backward(kpcn_net *net, const float *dlogits, float *dinput);
/* Same, with dlogits in the layout the last kpcn_net_forward_logits reported (f32; the padding
 * of blocked layouts zero), as kpcn_kpa_backward_layout writes them: saves the transposing
 * reorder from planar. dlogits is only read. */
kpcn_status kpcn_net_backward_logits(kpcn_net *net, const float *dlogits, float *dinput);

/* Parameter list for an optimizer: value points into the model, grad into the net. Order:
 * conv0.weight, conv0.bias, conv1.weight, ... ; 2*n_layers entries. */
typedef struct kpcn_param {
  char name[48]; /* "diffuse.conv3.weight" — the safetensors name */
  float *value;
  float *grad;
  size_t count;
} kpcn_param;
int kpcn_net_param_count(const kpcn_net *net);
kpcn_status kpcn_net_params(kpcn_net *net, kpcn_param *out, int max);

/* Timing counters since creation (seconds): total forward/backward time and the part
 * spent in convolution primitives, for benchmarks. */
typedef struct kpcn_net_stats {
  double fwd_s, fwd_conv_s, bwd_s, bwd_conv_s;
  long n_fwd, n_bwd;
  size_t bytes;         /* memory held by the net (activations, scratchpad, weight copies) */
  int n_slow;           /* primitives running oneDNN's slow reference ("ref:") implementation */
  int n_bwdd_fwd;       /* layers whose backward-data runs as a forward conv (see net.c) */
  int n_relayout;       /* layers whose input is reordered from the previous layer's layout */
  int n_space_to_batch; /* dilated inference layers run undilated on d*d sub-images (net.c) */
} kpcn_net_stats;
void kpcn_net_get_stats(const kpcn_net *net, kpcn_net_stats *s);
/* Name of the oneDNN implementation chosen for conv layer l forward ("brgconv:..."). */
const char *kpcn_net_impl_name(const kpcn_net *net, int layer);

/* ------------------------------------------------------------------ kernel prediction */

/* Forward of softmax + kernel apply over N images:
 *   w[t](p) = softmax_t(logits[t](p)),  out[c](p) = sum_t w[t](p) * noisy[c](p + off(t)).
 * logits [N][K²][H][W], noisy and out [N][nc][H][W] (same weights for every channel c).
 * Border: noisy is clamped to the image (replicate edge), so weights always sum to 1 over
 * real pixels. weights (optional, [N][K²][H][W]) receives the softmax for backward; it may
 * alias logits (in-place). */
kpcn_status kpcn_kpa_forward(int K, int n, int nc, int h, int w, const float *logits,
                             const float *noisy, float *out, float *weights, int nthreads);
/* Same, with logits in any layout kpcn_logits_layout describes, f32 or bf16 (weights, when
 * given, are written planar f32). */
kpcn_status kpcn_kpa_forward_layout(int K, int n, int nc, int h, int w, const void *logits,
                                    const kpcn_logits_layout *layout, const float *noisy,
                                    float *out, float *weights, int nthreads);

/* Backward: given the softmax weights from the forward, the noisy input and dL/dout,
 * writes dL/dlogits [N][K²][H][W] (may alias weights) and, if dnoisy is non-NULL,
 * dL/dnoisy [N][nc][H][W] (overwritten; clamped reads accumulate onto edge pixels). */
kpcn_status kpcn_kpa_backward(int K, int n, int nc, int h, int w, const float *weights,
                              const float *noisy, const float *dout, float *dlogits, float *dnoisy,
                              int nthreads);
/* Same, with dlogits written in any layout kpcn_logits_layout describes (padding slots set
 * to zero), e.g. the one kpcn_net_forward_logits reported, for kpcn_net_backward_logits;
 * weights stay planar and dlogits must not alias them. The layout must be f32 (bf16 = 0). */
kpcn_status kpcn_kpa_backward_layout(int K, int n, int nc, int h, int w, const float *weights,
                                     const float *noisy, const float *dout, float *dlogits,
                                     const kpcn_logits_layout *layout, float *dnoisy, int nthreads);

/* The first kernel pass with source weights (arch.source_weight): channel K² of `logits`
 * (same layout) holds the source score s, w = KPCN_KPA_SOURCE_EPS + (1 - eps)·sigmoid(s), and
 *   out[c](p) = sum_t k_t(p) w(q) noisy[c](q) / sum_t k_t(p) w(q),  q = clamp(p + off(t)).
 * It runs the plain layer on nc + 1 channels: src1 ([N][nc+1][H][W], written) receives
 * w·noisy and w, acc1 ([N][nc+1][H][W], written) their filtered values (numerators and the
 * weight sum), out ([N][nc][H][W]) the quotient. With N = 1, src1 may alias noisy and out
 * may alias acc1 (planes line up). weights as kpcn_kpa_forward_layout. */
kpcn_status kpcn_kpa_forward_weighted(int K, int n, int nc, int h, int w, const void *logits,
                                      const kpcn_logits_layout *layout, const float *noisy,
                                      float *src1, float *acc1, float *out, float *weights,
                                      int nthreads);

/* Several passes with one set of kernels (arch.kpa_passes): pass p filters pass p-1's result,
 * the first the noisy image (with source weights when source_weight, above); out = the last
 * pass. mid (kpcn_kpa_passes_mid_floats()) receives what the backward needs: the results
 * before the last, then with source weights src1 and acc1; weights as above (planar softmax,
 * optional). */
kpcn_status kpcn_kpa_forward_passes(int K, int passes, int source_weight, int n, int nc, int h,
                                    int w, const void *logits, const kpcn_logits_layout *layout,
                                    const float *noisy, float *mid, float *out, float *weights,
                                    int nthreads);
/* Its backward: dL/dlogits (in `layout`, as kpcn_kpa_backward_layout writes them, the source
 * score channel included) of the whole chain, from the forward's weights, noisy and mid.
 * scratch: at least kpcn_kpa_passes_scratch_floats() floats. No dL/dnoisy. */
kpcn_status kpcn_kpa_backward_passes(int K, int passes, int source_weight, int n, int nc, int h,
                                     int w, const float *weights, const float *noisy,
                                     const float *mid, const float *dout, float *dlogits,
                                     const kpcn_logits_layout *layout, float *scratch,
                                     int nthreads);
size_t kpcn_kpa_passes_mid_floats(int passes, int source_weight, int n, int nc, int h, int w);
/* The scratch kpcn_kpa_backward_passes needs; the layout is required (0 for NULL). */
size_t kpcn_kpa_passes_scratch_floats(int passes, int source_weight, int n, int nc, int h, int w,
                                      const kpcn_logits_layout *layout);

#ifdef __cplusplus
}
#endif
#endif
