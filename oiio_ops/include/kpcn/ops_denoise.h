// kpcn/ops_denoise.h — ImageBufAlgo-style denoise op (DESIGN.md §8) over the C denoiser in
// kpcn/denoise.h. The source ImageBuf is a multi-channel AOV image (canonical channel names
// or aliases, see kpcn/image.h); the result is a 3-channel float RGB image (R, G, B).
#pragma once

#include <OpenImageIO/imagebuf.h>

#include <string>

#include "kpcn/denoise.h"

namespace kpcn {
namespace ops {

struct DenoiseOptions {
  // "kpcn" (needs model), "bilateral" or "nlmeans".
  std::string method = "kpcn";
  std::string model; // safetensors model file (method "kpcn")
  bool bf16 = false; // bf16 convolutions
  int tile = 0;      // KPCN tile size in output pixels per side, 0 = automatic/untiled
  int ensemble = 1;  // self-ensemble size 1, 2, 4 or 8 (kpcn_denoiser_options.ensemble)
  // the exposure the network is shown every input at (kpcn_denoiser_options.exposure):
  // 0 = the model's, > 0 = that one, KPCN_EXPOSURE_AS_RENDERED = as rendered
  float exposure = 0.0f;
  // bound isolated diffuse fireflies first (kpcn_denoiser_options.firefly): the ratio, 0 = off
  float firefly = KPCN_DENOISE_DEFAULT_FIREFLY;
  // Baseline parameters; defaults of kpcn_denoiser_options_defaults when left alone.
  kpcn_denoiser_options c_options() const;
};

// Denoises the AOV image `aovs` into dst (3 channels R,G,B, float). The whole image is
// denoised (per-image normalisation needs it); roi (default: all; inside the data window,
// its channel range ignored) selects which part of the result is stored in dst, where it lies
// in the input (dst keeps the input's origin and full window). Errors (missing buffer named, bad
// model ...) are reported with dst.errorfmt and a false return. Where the KPCN measured the input's
// exposure, dst's spec carries float attributes kpcn:exposure (the input's, kpcn_aov_exposure) and
// kpcn:exposureScale (the factor the network was shown it at).
bool denoise(OIIO::ImageBuf &dst, const OIIO::ImageBuf &aovs, const DenoiseOptions &opt,
             OIIO::ROI roi = {}, int nthreads = 0);
OIIO::ImageBuf denoise(const OIIO::ImageBuf &aovs, const DenoiseOptions &opt, OIIO::ROI roi = {},
                       int nthreads = 0);

// The KPCN's predicted kernels of one branch ("diffuse" or "specular") for every pixel of
// `aovs` (kpcn_denoiser_kernels_aov: the same exposure, firefly bound and tiles as denoise;
// opt.ensemble must be 1). dst (float) holds channels pre.R pre.G pre.B, the branch's
// preprocessed noisy colour, then kernel.000 ... kernel.(K*K-1), the softmax weights (tap t =
// dy*K + dx reads the pixel (x + dx - K/2, y + dy - K/2), clamped to the image), and the
// attributes kpcn:branch (string), kpcn:kernelSize and kpcn:kernelPasses (int), kpcn:eps and
// kpcn:exposureScale (float): everything needed to redo the branch's filtering and
// recombination (kpcn/denoise.h). roi and errors as for denoise.
bool denoise_kernels(OIIO::ImageBuf &dst, const OIIO::ImageBuf &aovs, const DenoiseOptions &opt,
                     const std::string &branch, OIIO::ROI roi = {}, int nthreads = 0);
OIIO::ImageBuf denoise_kernels(const OIIO::ImageBuf &aovs, const DenoiseOptions &opt,
                               const std::string &branch, OIIO::ROI roi = {}, int nthreads = 0);

} // namespace ops
} // namespace kpcn
