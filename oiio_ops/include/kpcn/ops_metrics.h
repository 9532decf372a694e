// kpcn/ops_metrics.h — image metrics as ImageBufAlgo-style operations (DESIGN.md §7, §8).
//
// Thin adapters over libkpcn's metrics (kpcn/metrics.h has the definitions, the SSIM
// details and the non-finite policy):
//
//   MetricResult r = kpcn::ops::compare(x, ref, kpcn::ops::Metric::SSIM, opt);
//   if (!r.ok) ... r.error ...
//   ImageBuf map;  kpcn::ops::errormap(map, x, ref, Metric::RelMSE, opt);   // errors on map
//
// x is the image under test, ref the reference (relMSE/relL1 divide by the reference).
// Channels are matched by name: opt.channels, or, when empty, R,G,B if both images have them
// and either is an AOV image (a channel other than R,G,B,A), else every channel of ref (which
// must all exist in x). `roi` selects a pixel window (same window in both images, in each image's
// own coordinates; default: the whole data window; the ROI's channel range is ignored — use
// opt.channels; a window outside either image's data window is an error). Images must have
// the same size. errormap's image lies where the compared pixels lie in x (its origin, or the
// ROI's, and x's full window). nthreads 0 = all cores.
#pragma once

#include <OpenImageIO/imagebuf.h>

#include <cstdint>
#include <limits>
#include <string>
#include <vector>

namespace kpcn {
namespace ops {

enum class Metric { L1 = 0, MSE, RelMSE, RelL1, PSNR, SSIM };

// "l1", "mse", "relmse", "rell1", "psnr", "ssim".
const char *metric_name(Metric m);
// Case-insensitive; false if unknown.
bool metric_from_name(const std::string &name, Metric &m);

struct CompareOptions {
  std::vector<std::string> channels; // empty: see above (R,G,B of AOV images)
  bool display_srgb = false;         // clamp to [0,1] + sRGB-encode both before comparing
  double data_range = 1.0;           // SSIM data range, PSNR peak
  double eps = 0.01;                 // relMSE / relL1 epsilon
};

struct MetricResult {
  bool ok = false;
  std::string error;                                       // set when !ok, names the problem
  double value = std::numeric_limits<double>::quiet_NaN(); // mean over valid pixels/channels
  int64_t npixels = 0;                                     // pixels averaged
  int64_t nonfinite = 0;                                   // pixels excluded (NaN/Inf in x or ref)
  int nchannels = 0;                                       // channels compared
  std::vector<std::string> channel_names;                  // which ones
};

MetricResult compare(const OIIO::ImageBuf &x, const OIIO::ImageBuf &ref, Metric m,
                     const CompareOptions &opt = {}, OIIO::ROI roi = {}, int nthreads = 0);

// Per-pixel error image: one float channel per compared channel, named like it (see
// kpcn/metrics.h for what each metric's map holds; excluded non-finite pixels are NaN).
// Returns false with the message on dst (dst.geterror()). `result` (optional) receives the
// scalar result computed along the way.
bool errormap(OIIO::ImageBuf &dst, const OIIO::ImageBuf &x, const OIIO::ImageBuf &ref, Metric m,
              const CompareOptions &opt = {}, OIIO::ROI roi = {}, int nthreads = 0,
              MetricResult *result = nullptr);
OIIO::ImageBuf errormap(const OIIO::ImageBuf &x, const OIIO::ImageBuf &ref, Metric m,
                        const CompareOptions &opt = {}, OIIO::ROI roi = {}, int nthreads = 0);

} // namespace ops
} // namespace kpcn
