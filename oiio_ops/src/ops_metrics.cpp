// Metrics over ImageBufs (kpcn/ops_metrics.h): convert, call libkpcn, convert back.
#include "kpcn/ops_metrics.h"

#include "kpcn/metrics.h"
#include "kpcn/oiio_convert.h"

using namespace OIIO;

namespace kpcn {
namespace ops {

const char *metric_name(Metric m) { return kpcn_metric_name((kpcn_metric)m); }

bool metric_from_name(const std::string &name, Metric &m) {
  int i = kpcn_metric_from_name(name.c_str());
  if (i < 0) return false;
  m = (Metric)i;
  return true;
}

// Name for messages: the file name, or the role for images made in memory.
static std::string label(const ImageBuf &b, const char *role) {
  std::string n = std::string(b.name());
  return n.empty() ? std::string(role) : "'" + n + "'";
}

static std::string size_str(const ROI &r) {
  return std::to_string(r.width()) + "x" + std::to_string(r.height());
}

// The channels compared when the caller names none: R,G,B for an AOV pair, else every channel
// of the reference (an empty list), by libkpcn's one rule (kpcn_metric_default_rgb).
static std::vector<std::string> default_channels(const ImageBuf &x, const ImageBuf &ref) {
  auto names = [](const ImageBuf &b) {
    std::vector<const char *> n;
    for (const std::string &s : b.spec().channelnames)
      n.push_back(s.c_str());
    return n;
  };
  const std::vector<const char *> nx = names(x), ny = names(ref);
  if (kpcn_metric_default_rgb(nx.data(), (int)nx.size(), ny.data(), (int)ny.size()))
    return {"R", "G", "B"};
  return {};
}

// Shared body of compare() and errormap(): map != nullptr requests the error image.
static MetricResult run(const ImageBuf &x, const ImageBuf &ref, Metric m, const CompareOptions &opt,
                        ROI roi, int nthreads, ImagePtr *map) {
  MetricResult r;
  const char *what = metric_name(m);
  if ((int)m < 0 || (int)m >= KPCN_METRIC_COUNT) {
    r.error = "unknown metric id " + std::to_string((int)m);
    return r;
  }
  // an input that is not an image (a missing file, an empty ImageBuf) is named as such, with
  // OIIO's reason, not as a 0x0 size mismatch
  for (const ImageBuf *b : {&x, &ref})
    if (!b->initialized()) {
      r.error = std::string(what) + ": " +
                label(*b, b == &x ? "the test image" : "the reference image") +
                " is not initialized";
      if (b->has_error()) r.error += " (" + b->geterror(false) + ")";
      return r;
    }
  // The channel range of a caller's ROI is ignored (channels are matched by name, and the two
  // images may order them differently); its pixel window must lie inside both images.
  ROI rx = roi.defined() ? roi : x.roi(), ry = roi.defined() ? roi : ref.roi();
  rx.chbegin = ry.chbegin = 0;
  rx.chend = x.nchannels();
  ry.chend = ref.nchannels();
  if (roi.defined() && (!x.roi().contains(rx) || !ref.roi().contains(ry))) {
    r.error = std::string(what) + ": the region " + size_str(rx) + "+" + std::to_string(rx.xbegin) +
              "+" + std::to_string(rx.ybegin) + " is not inside both images' data windows";
    return r;
  }
  if (rx.width() != ry.width() || rx.height() != ry.height()) {
    r.error = std::string(what) + ": image sizes differ (" + label(x, "the test image") + " is " +
              size_str(rx) + ", " + label(ref, "the reference image") + " is " + size_str(ry) + ")";
    return r;
  }
  // Pixels are compared by position: two crops of one render at different offsets (a data
  // window is where an image's pixels sit) hold different regions, not a noisy/reference pair.
  if (rx.xbegin != ry.xbegin || rx.ybegin != ry.ybegin) {
    auto window = [](const ROI &r) {
      return size_str(r) + "+" + std::to_string(r.xbegin) + "+" + std::to_string(r.ybegin);
    };
    r.error = std::string(what) + ": the images cover different pixels (" +
              label(x, "the test image") + " has the data window " + window(rx) + ", " +
              label(ref, "the reference image") + " " + window(ry) +
              "): crop or shift them to the same window first";
    return r;
  }
  // A scalar metric counts a channel listed twice twice (metrics.md), but an error map would
  // get two planes of one name (OIIO wrote the second as 'channel1').
  for (size_t i = 0; map && i < opt.channels.size(); i++)
    for (size_t j = 0; j < i; j++)
      if (opt.channels[i] == opt.channels[j]) {
        r.error = std::string(what) + ": the channel list names '" + opt.channels[i] +
                  "' twice (an error map has one channel per name)";
        return r;
      }
  std::string err;
  const std::vector<std::string> chans =
      opt.channels.empty() ? default_channels(x, ref) : opt.channels;
  ImagePtr ix = chans.empty() ? to_kpcn_image(x, err, rx) : to_kpcn_image(x, chans, err, rx);
  if (!ix) {
    r.error = std::string(what) + ": test image: " + err;
    return r;
  }
  ImagePtr iy = chans.empty() ? to_kpcn_image(ref, err, ry) : to_kpcn_image(ref, chans, err, ry);
  if (!iy) {
    r.error = std::string(what) + ": reference image: " + err;
    return r;
  }
  kpcn_metric_options o;
  kpcn_metric_options_defaults(&o);
  o.display = opt.display_srgb ? KPCN_DISPLAY_SRGB : KPCN_DISPLAY_LINEAR;
  o.data_range = opt.data_range;
  o.eps = opt.eps;
  o.nthreads = nthreads;
  kpcn_metric_result res{};
  kpcn_image *em = nullptr;
  // the list chosen above, passed on: without it the C default would take R,G,B again from
  // an explicit R,G,B,Z (both images hold a channel other than R,G,B,A)
  std::vector<const char *> names;
  for (const std::string &c : chans)
    names.push_back(c.c_str());
  kpcn_status s =
      kpcn_metric_image((kpcn_metric)m, ix.get(), iy.get(), names.empty() ? nullptr : names.data(),
                        (int)names.size(), &o, &res, map ? &em : nullptr);
  if (s != KPCN_OK) {
    r.error = kpcn_last_error();
    r.nonfinite = res.nonfinite;
    return r;
  }
  if (map) map->reset(em);
  r.ok = true;
  r.value = res.value;
  r.npixels = res.npixels;
  r.nonfinite = res.nonfinite;
  r.nchannels = res.nchannels;
  // Compared channels: the reference's (matched by name in kpcn_metric_image).
  for (int c = 0; c < iy->nchannels; ++c)
    r.channel_names.push_back(iy->names[c]);
  return r;
}

MetricResult compare(const ImageBuf &x, const ImageBuf &ref, Metric m, const CompareOptions &opt,
                     ROI roi, int nthreads) {
  return run(x, ref, m, opt, roi, nthreads, nullptr);
}

bool errormap(ImageBuf &dst, const ImageBuf &x, const ImageBuf &ref, Metric m,
              const CompareOptions &opt, ROI roi, int nthreads, MetricResult *result) {
  ImagePtr map;
  MetricResult r = run(x, ref, m, opt, roi, nthreads, &map);
  if (result) *result = r;
  if (!r.ok) {
    dst.errorfmt("{}", r.error);
    return false;
  }
  // where the compared pixels are in x: its origin (or the ROI's) and full window, read before
  // dst is written (dst may be x itself: writing first lost x's windows)
  const ImageSpec xs = x.spec();
  if (!from_kpcn_image(dst, *map)) return false;
  dst.set_origin(roi.defined() ? roi.xbegin : xs.x, roi.defined() ? roi.ybegin : xs.y);
  dst.set_full(xs.full_x, xs.full_x + xs.full_width, xs.full_y, xs.full_y + xs.full_height, 0, 1);
  return true;
}

ImageBuf errormap(const ImageBuf &x, const ImageBuf &ref, Metric m, const CompareOptions &opt,
                  ROI roi, int nthreads) {
  ImageBuf dst;
  errormap(dst, x, ref, m, opt, roi, nthreads);
  return dst;
}

} // namespace ops
} // namespace kpcn
