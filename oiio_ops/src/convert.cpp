// ImageBuf <-> kpcn_image / kpcn_aov_set conversions (see kpcn/oiio_convert.h).
#include "kpcn/oiio_convert.h"
#include "ops_internal.h"

#include <algorithm>
#include <climits>

#include <OpenImageIO/imagebufalgo.h>

#include <cstring>
#include <limits>

using namespace OIIO;

namespace kpcn {
namespace ops {

std::vector<std::string> split_names(const std::string &list, char sep) {
  std::vector<std::string> out;
  size_t start = 0;
  while (start <= list.size()) {
    size_t e = list.find(sep, start);
    if (e == std::string::npos) e = list.size();
    if (e > start) out.push_back(list.substr(start, e - start));
    start = e + 1;
  }
  return out;
}

int channel_index(const ImageSpec &spec, const std::string &name) {
  return spec.channelindex(name);
}

// "image 'name'" for messages; images made in memory have no name.
static std::string desc(const ImageBuf &b) {
  std::string n = std::string(b.name());
  return n.empty() ? std::string("image (in memory)") : "image '" + n + "'";
}

// Reads channels idx[k] of `src` over `roi` into the planar float planes dst[k] (NULL: not
// wanted) in one pass: blocks of rows, all channels idx spans, into an interleaved scratch,
// then scattered to the planes. One get_pixels call per channel walked the whole interleaved
// image once per channel (~0.5 s for a 1-Mpixel, 24-channel AOV file, a tenth of a CLI denoise).
static bool read_planes(const ImageBuf &src, ROI roi, const std::vector<int> &idx,
                        const std::vector<float *> &dst, std::string &err) {
  int c0 = INT_MAX, c1 = -1;
  for (size_t k = 0; k < idx.size(); ++k)
    if (dst[k]) c0 = std::min(c0, idx[k]), c1 = std::max(c1, idx[k]);
  if (c1 < 0) return true;
  const int nc = c1 - c0 + 1, w = roi.width(), h = roi.height();
  const int rows = std::max(1, std::min(h, (int)((256u << 10) / (sizeof(float) * nc * w)) + 1));
  std::vector<float> buf((size_t)rows * w * nc);
  for (int y0 = 0; y0 < h; y0 += rows) {
    const int n = std::min(rows, h - y0);
    ROI r(roi.xbegin, roi.xend, roi.ybegin + y0, roi.ybegin + y0 + n, roi.zbegin, roi.zend, c0,
          c1 + 1);
    if (!src.get_pixels(r, TypeDesc::FLOAT, buf.data())) {
      err = "cannot read pixels of " + desc(src) + ": " + src.geterror();
      return false;
    }
    const size_t px = (size_t)n * w, off = (size_t)y0 * w;
    for (size_t k = 0; k < idx.size(); ++k) {
      if (!dst[k]) continue;
      const float *in = buf.data() + (idx[k] - c0);
      float *out = dst[k] + off;
      for (size_t i = 0; i < px; ++i)
        out[i] = in[i * nc];
    }
  }
  return true;
}

static bool check_source(const ImageBuf &src, ROI &roi, std::string &err) {
  if (!src.initialized()) {
    err = desc(src) + " is not initialized";
    if (src.has_error()) err += " (" + src.geterror(false) + ")"; // e.g. the file is missing
    return false;
  }
  // get_pixels on deep data crashed (OIIO 2.4 reads it as flat pixels); ImageBufAlgo and
  // kpcntool refuse it
  if (src.deep()) {
    err = desc(src) + " is a deep image: deep images are not supported";
    return false;
  }
  // A file-backed ImageBuf reads lazily; unreadable / truncated files surface in get_pixels
  // (read_plane names the file).
  if (!roi.defined()) roi = src.roi();
  // get_pixels would fill what lies outside the data window with zeros (and read channel -1)
  ROI inside = roi;
  inside.chbegin = 0;
  inside.chend = src.nchannels();
  if (roi.chbegin < 0 || !src.roi().contains(inside)) {
    err = "the region " + std::to_string(roi.width()) + "x" + std::to_string(roi.height()) + "+" +
          std::to_string(roi.xbegin) + "+" + std::to_string(roi.ybegin) + " (channels " +
          std::to_string(roi.chbegin) + ".." + std::to_string(roi.chend) + ") is not inside " +
          desc(src) + "'s data window";
    return false;
  }
  if (roi.width() <= 0 || roi.height() <= 0 || roi.depth() != 1) {
    err = desc(src) + " has an unsupported size " + std::to_string(roi.width()) + "x" +
          std::to_string(roi.height()) + "x" + std::to_string(roi.depth());
    return false;
  }
  return true;
}

static ImagePtr make_image(int w, int h, const std::vector<std::string> &names, std::string &err) {
  std::vector<const char *> cn;
  for (auto &n : names)
    cn.push_back(n.c_str());
  kpcn_image *img = nullptr;
  if (kpcn_image_create(&img, w, h, (int)cn.size(), cn.data()) != KPCN_OK) {
    err = kpcn_last_error();
    return nullptr;
  }
  return ImagePtr(img);
}

ImagePtr to_kpcn_image(const ImageBuf &src, std::string &err, ROI roi) {
  bool whole_channels = !roi.defined();
  if (!check_source(src, roi, err)) return nullptr;
  const ImageSpec &spec = src.spec();
  if (whole_channels) {
    roi.chbegin = 0;
    roi.chend = spec.nchannels;
  }
  roi.chend = std::min(roi.chend, spec.nchannels);
  std::vector<std::string> names;
  for (int c = roi.chbegin; c < roi.chend; ++c)
    names.push_back(std::string(spec.channel_name(c)).empty() ? std::to_string(c)
                                                              : std::string(spec.channel_name(c)));
  if (names.empty()) {
    err = desc(src) + " has no channels in the requested range";
    return nullptr;
  }
  ImagePtr img = make_image(roi.width(), roi.height(), names, err);
  if (!img) return nullptr;
  std::vector<int> idx;
  std::vector<float *> dst;
  for (int c = roi.chbegin; c < roi.chend; ++c) {
    idx.push_back(c);
    dst.push_back(kpcn_image_plane(img.get(), c - roi.chbegin));
  }
  if (!read_planes(src, roi, idx, dst, err)) return nullptr;
  return img;
}

ImagePtr to_kpcn_image(const ImageBuf &src, const std::vector<std::string> &channels,
                       std::string &err, ROI roi) {
  if (!check_source(src, roi, err)) return nullptr;
  std::vector<int> idx;
  for (auto &n : channels) {
    int i = src.spec().channelindex(n);
    if (i < 0) {
      err = desc(src) + " has no channel '" + n + "'";
      return nullptr;
    }
    idx.push_back(i);
  }
  if (idx.empty()) {
    err = "empty channel list for " + desc(src);
    return nullptr;
  }
  ImagePtr img = make_image(roi.width(), roi.height(), channels, err);
  if (!img) return nullptr;
  std::vector<float *> dst;
  for (size_t k = 0; k < idx.size(); ++k)
    dst.push_back(kpcn_image_plane(img.get(), (int)k));
  if (!read_planes(src, roi, idx, dst, err)) return nullptr;
  return img;
}

bool from_kpcn_image(ImageBuf &dst, const kpcn_image &img) {
  ImageSpec spec(img.width, img.height, img.nchannels, TypeDesc::FLOAT);
  spec.channelnames.clear();
  for (int c = 0; c < img.nchannels; ++c)
    spec.channelnames.emplace_back(img.names && img.names[c] ? img.names[c]
                                                             : std::to_string(c).c_str());
  dst.reset(spec);
  size_t plane = (size_t)img.width * img.height;
  // Planar -> interleaved via strides: one channel at a time.
  for (int c = 0; c < img.nchannels; ++c) {
    ROI r(0, img.width, 0, img.height, 0, 1, c, c + 1);
    if (!dst.set_pixels(r, TypeDesc::FLOAT, img.data + (size_t)c * plane)) {
      dst.errorfmt("cannot store channel {}: {}", c, dst.geterror());
      return false;
    }
  }
  return true;
}

ImageBuf from_kpcn_image(const kpcn_image &img) {
  ImageBuf dst;
  from_kpcn_image(dst, img);
  return dst;
}

AovPtr to_aov_set(const ImageBuf &src, std::string &err) {
  ROI roi;
  if (!check_source(src, roi, err)) return nullptr;
  const ImageSpec &spec = src.spec();
  // Straight into the set's planes (kpcn_aov_create_for_channels maps the names as
  // kpcn_aov_from_image does), without a whole-image copy in between.
  std::vector<std::string> names;
  std::vector<const char *> cn;
  for (int c = 0; c < spec.nchannels; ++c)
    names.push_back(spec.channel_name(c).empty() ? std::to_string(c)
                                                 : std::string(spec.channel_name(c)));
  for (auto &n : names)
    cn.push_back(n.c_str());
  std::vector<float *> dst(names.size() + 1, nullptr);
  std::vector<int> idx;
  for (int c = 0; c < spec.nchannels; ++c)
    idx.push_back(c);
  kpcn_aov_set *set = nullptr;
  if (kpcn_aov_create_for_channels(&set, roi.width(), roi.height(), (int)cn.size(), cn.data(),
                                   dst.data(), "image") != KPCN_OK) {
    err = desc(src) + ": " + kpcn_last_error();
    return nullptr;
  }
  AovPtr out(set);
  dst.resize(idx.size());
  if (!read_planes(src, roi, idx, dst, err)) return nullptr;
  out->spp = spec.get_int_attribute("kpcn:spp", -1);
  out->albedo_spp = std::max(0, spec.get_int_attribute("kpcn:albedoSpp", 0));
  out->albedo_footprint = std::max(0, spec.get_int_attribute("kpcn:albedoFootprint", 0));
  // The seed may exceed an int: accept int attributes and decimal strings.
  const ParamValue *p = spec.find_attribute("kpcn:seed");
  if (p) {
    if (p->type() == TypeDesc::STRING)
      out->seed = std::strtoll(p->get_string().c_str(), nullptr, 10);
    else
      out->seed = p->get_int(-1);
  } else {
    out->seed = -1;
  }
  std::string scene = spec.get_string_attribute("kpcn:scene");
  std::string version = spec.get_string_attribute("kpcn:version");
  std::snprintf(out->scene, sizeof out->scene, "%s", scene.c_str());
  std::snprintf(out->version, sizeof out->version, "%s", version.c_str());
  return out;
}

bool from_aov_set(ImageBuf &dst, const kpcn_aov_set &set) {
  kpcn_image *img = nullptr;
  if (kpcn_aov_to_image(&img, &set) != KPCN_OK) {
    dst.errorfmt("{}", kpcn_last_error());
    return false;
  }
  ImagePtr guard(img);
  if (!from_kpcn_image(dst, *img)) return false;
  ImageSpec &spec = dst.specmod();
  if (set.spp >= 0) spec.attribute("kpcn:spp", set.spp);
  if (set.albedo_spp > 0) spec.attribute("kpcn:albedoSpp", set.albedo_spp);
  if (set.albedo_footprint > 1) spec.attribute("kpcn:albedoFootprint", set.albedo_footprint);
  if (set.seed >= 0) {
    if (set.seed <= std::numeric_limits<int>::max())
      spec.attribute("kpcn:seed", (int)set.seed);
    else
      spec.attribute("kpcn:seed", std::to_string(set.seed));
  }
  if (set.scene[0]) spec.attribute("kpcn:scene", set.scene);
  if (set.version[0]) spec.attribute("kpcn:version", set.version);
  return true;
}

ImageBuf from_aov_set(const kpcn_aov_set &set) {
  ImageBuf dst;
  from_aov_set(dst, set);
  return dst;
}

bool empty_roi(OIIO::ImageBuf &dst, OIIO::ROI roi, const char *what) {
  if (!roi.defined() || (roi.width() > 0 && roi.height() > 0 && roi.depth() == 1)) return false;
  dst.errorfmt("{}: the region {} holds no pixels", what, roi);
  return true;
}

} // namespace ops
} // namespace kpcn
