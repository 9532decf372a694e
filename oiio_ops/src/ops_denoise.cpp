// ImageBuf adapter for the denoiser: ImageBuf -> kpcn_aov_set -> kpcn_denoise_aov -> ImageBuf.
#include "kpcn/ops_denoise.h"

#include <OpenImageIO/imagebufalgo.h>

#include <cstdio>
#include <memory>
#include <vector>

#include "kpcn/oiio_convert.h"
#include "ops_internal.h"

namespace kpcn {
namespace ops {

kpcn_denoiser_options DenoiseOptions::c_options() const {
  kpcn_denoiser_options o;
  kpcn_denoiser_options_defaults(&o);
  o.method = method == "bilateral" ? KPCN_DENOISE_BILATERAL
             : method == "nlmeans" ? KPCN_DENOISE_NLMEANS
                                   : KPCN_DENOISE_KPCN;
  o.model_path = model.empty() ? nullptr : model.c_str();
  o.bf16 = bf16 ? 1 : 0;
  o.tile = tile;
  o.ensemble = ensemble;
  o.exposure = exposure;
  o.firefly = firefly;
  return o;
}

namespace {

// Stores `full`, computed from the whole of `aovs`, in dst: where the input was (the AOV
// image's data window may not start at 0,0), cropped to roi when one is given (crop, not cut:
// cut moves it to 0,0; the ROI's channel range is ignored, every channel of full is kept).
bool place_result(OIIO::ImageBuf &dst, OIIO::ImageBuf &full, const OIIO::ImageBuf &aovs,
                  OIIO::ROI roi, int nthreads, const char *what) {
  if (full.has_error()) {
    dst.errorfmt("{}: {}", what, full.geterror());
    return false;
  }
  const OIIO::ImageSpec &ss = aovs.spec();
  full.set_origin(ss.x, ss.y);
  full.set_full(ss.full_x, ss.full_x + ss.full_width, ss.full_y, ss.full_y + ss.full_height, 0, 1);
  if (!roi.defined()) {
    dst = std::move(full);
    return true;
  }
  roi.chbegin = 0;
  roi.chend = full.nchannels();
  if (!full.roi().contains(roi)) {
    dst.errorfmt("{}: the region {} is not inside the image's data window {}", what, roi,
                 full.roi());
    return false;
  }
  if (!OIIO::ImageBufAlgo::crop(dst, full, roi, nthreads) || dst.has_error()) {
    if (!dst.has_error()) dst.errorfmt("{}: cropping to the region {} failed", what, roi);
    return false;
  }
  return true;
}

// The C library's last error for dst, prefixed with `what` unless it already names the
// denoiser ("denoise: ...", "denoiser_kernels: ...", as most of libkpcn's denoiser messages do).
void c_error(OIIO::ImageBuf &dst, const char *what) {
  const std::string e = kpcn_last_error();
  dst.errorfmt("{}{}", e.rfind("denoise", 0) == 0 ? "" : std::string(what) + ": ", e);
}

} // namespace

bool denoise(OIIO::ImageBuf &dst, const OIIO::ImageBuf &aovs, const DenoiseOptions &opt,
             OIIO::ROI roi, int nthreads) {
  if (opt.method != "kpcn" && opt.method != "bilateral" && opt.method != "nlmeans") {
    dst.errorfmt("denoise: unknown method '{}' (kpcn, bilateral, nlmeans)", opt.method);
    return false;
  }
  if (opt.method == "kpcn" && opt.model.empty()) {
    dst.errorfmt("denoise: method kpcn needs a model file (model=...)");
    return false;
  }
  if (empty_roi(dst, roi, "denoise")) return false;
  std::string err;
  AovPtr set = to_aov_set(aovs, err);
  if (!set) {
    dst.errorfmt("denoise: {}", err);
    return false;
  }
  kpcn_denoiser_options o = opt.c_options();
  o.nthreads = nthreads;
  kpcn_image *rgb = nullptr;
  kpcn_denoise_stats st{};
  if (kpcn_denoise_aov_stats(set.get(), &o, &rgb, &st) != KPCN_OK) {
    c_error(dst, "denoise");
    return false;
  }
  ImagePtr out(rgb);
  OIIO::ImageBuf full = from_kpcn_image(*out);
  if (o.method == KPCN_DENOISE_KPCN && st.exposure > 0.0) {
    // what the network was shown (docs/denoiser.md, "Exposure"), kept in the file's header
    full.specmod().attribute("kpcn:exposure", (float)st.exposure);
    full.specmod().attribute("kpcn:exposureScale", (float)st.exposure_scale);
  }
  return place_result(dst, full, aovs, roi, nthreads, "denoise");
}

bool denoise_kernels(OIIO::ImageBuf &dst, const OIIO::ImageBuf &aovs, const DenoiseOptions &opt,
                     const std::string &branch, OIIO::ROI roi, int nthreads) {
  if (opt.method != "kpcn" && opt.method != "bilateral" && opt.method != "nlmeans") {
    dst.errorfmt("denoise_kernels: unknown method '{}' (kpcn, bilateral, nlmeans)", opt.method);
    return false;
  }
  if (opt.method != "kpcn") {
    dst.errorfmt("denoise_kernels: method {} predicts no kernels: only the KPCN does", opt.method);
    return false;
  }
  if (opt.model.empty()) {
    dst.errorfmt("denoise_kernels: the KPCN needs a model file (model=...)");
    return false;
  }
  if (branch != "diffuse" && branch != "specular") {
    dst.errorfmt("denoise_kernels: unknown branch '{}' (diffuse, specular)", branch);
    return false;
  }
  if (empty_roi(dst, roi, "denoise_kernels")) return false;
  std::string err;
  AovPtr set = to_aov_set(aovs, err);
  if (!set) {
    dst.errorfmt("denoise_kernels: {}", err);
    return false;
  }
  kpcn_denoiser_options o = opt.c_options();
  o.nthreads = nthreads;
  kpcn_denoiser *d = nullptr;
  if (kpcn_denoiser_create(&d, &o) != KPCN_OK) {
    c_error(dst, "denoise_kernels");
    return false;
  }
  std::unique_ptr<kpcn_denoiser, void (*)(kpcn_denoiser *)> own(d, kpcn_denoiser_destroy);
  int K = 0, passes = 0;
  float eps = 0.0f;
  if (kpcn_denoiser_kernel_info(d, &K, &passes, &eps) != KPCN_OK) {
    c_error(dst, "denoise_kernels");
    return false;
  }
  // channels: the preprocessed colour, then tap t = dy*K + dx as kernel.TTT
  std::vector<std::string> names = {"pre.R", "pre.G", "pre.B"};
  for (int t = 0; t < K * K; t++) {
    char n[32];
    std::snprintf(n, sizeof n, "kernel.%03d", t);
    names.push_back(n);
  }
  std::vector<const char *> cnames;
  for (const std::string &n : names)
    cnames.push_back(n.c_str());
  kpcn_image *img = nullptr;
  if (kpcn_image_create(&img, set->width, set->height, (int)cnames.size(), cnames.data()) !=
      KPCN_OK) {
    c_error(dst, "denoise_kernels");
    return false;
  }
  ImagePtr out(img);
  const size_t P = kpcn_aov_plane_size(set.get());
  const int b = branch == "diffuse" ? KPCN_BRANCH_DIFFUSE : KPCN_BRANCH_SPECULAR;
  if (kpcn_denoiser_kernels_aov(d, set.get(), b, img->data + 3 * P, img->data) != KPCN_OK) {
    c_error(dst, "denoise_kernels");
    return false;
  }
  kpcn_denoise_stats st{};
  kpcn_denoiser_get_stats(d, &st);
  OIIO::ImageBuf full = from_kpcn_image(*out);
  OIIO::ImageSpec &spec = full.specmod();
  spec.attribute("kpcn:branch", branch);
  spec.attribute("kpcn:kernelSize", K);
  spec.attribute("kpcn:kernelPasses", passes);
  spec.attribute("kpcn:eps", eps);
  spec.attribute("kpcn:exposureScale", (float)st.exposure_scale);
  return place_result(dst, full, aovs, roi, nthreads, "denoise_kernels");
}

OIIO::ImageBuf denoise(const OIIO::ImageBuf &aovs, const DenoiseOptions &opt, OIIO::ROI roi,
                       int nthreads) {
  OIIO::ImageBuf dst;
  denoise(dst, aovs, opt, roi, nthreads);
  return dst;
}

OIIO::ImageBuf denoise_kernels(const OIIO::ImageBuf &aovs, const DenoiseOptions &opt,
                               const std::string &branch, OIIO::ROI roi, int nthreads) {
  OIIO::ImageBuf dst;
  denoise_kernels(dst, aovs, opt, branch, roi, nthreads);
  return dst;
}

} // namespace ops
} // namespace kpcn
