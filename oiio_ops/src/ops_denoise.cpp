// ImageBuf adapter for the denoiser: ImageBuf -> kpcn_aov_set -> kpcn_denoise_aov -> ImageBuf.
#include "kpcn/ops_denoise.h"

#include <OpenImageIO/imagebufalgo.h>

#include "kpcn/oiio_convert.h"

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
    // libkpcn's denoiser messages already say "denoise: ..."
    const std::string e = kpcn_last_error();
    dst.errorfmt("{}{}", e.rfind("denoise", 0) == 0 ? "" : "denoise: ", e);
    return false;
  }
  ImagePtr out(rgb);
  OIIO::ImageBuf full = from_kpcn_image(*out);
  if (o.method == KPCN_DENOISE_KPCN && st.exposure > 0.0) {
    // what the network was shown (docs/denoiser.md, "Exposure"), kept in the file's header
    full.specmod().attribute("kpcn:exposure", (float)st.exposure);
    full.specmod().attribute("kpcn:exposureScale", (float)st.exposure_scale);
  }
  if (full.has_error()) {
    dst.errorfmt("denoise: {}", full.geterror());
    return false;
  }
  // The AOV image's data window may not start at 0,0: put the result where the input was.
  const OIIO::ImageSpec &ss = aovs.spec();
  full.set_origin(ss.x, ss.y);
  full.set_full(ss.full_x, ss.full_x + ss.full_width, ss.full_y, ss.full_y + ss.full_height, 0, 1);
  if (!roi.defined()) {
    dst = std::move(full);
    return true;
  }
  // The region of the result, where it was (crop, not cut: cut moves it to 0,0); the ROI's
  // channel range is ignored, the result is R,G,B.
  roi.chbegin = 0;
  roi.chend = 3;
  if (!full.roi().contains(roi)) {
    dst.errorfmt("denoise: the region {} is not inside the image's data window {}", roi,
                 full.roi());
    return false;
  }
  return OIIO::ImageBufAlgo::crop(dst, full, roi, nthreads);
}

OIIO::ImageBuf denoise(const OIIO::ImageBuf &aovs, const DenoiseOptions &opt, OIIO::ROI roi,
                       int nthreads) {
  OIIO::ImageBuf dst;
  denoise(dst, aovs, opt, roi, nthreads);
  return dst;
}

} // namespace ops
} // namespace kpcn
