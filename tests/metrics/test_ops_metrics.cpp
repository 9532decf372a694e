// oiio_ops metrics + conversion tests: kpcn::ops::compare/errormap agree with the C core and
// with values computed here; ImageBuf <-> kpcn_image / kpcn_aov_set round trips keep values,
// names and kpcn:* attributes; errors land on dst / in the result, naming the problem.
#include "kpcn/metrics.h"
#include "kpcn/oiio_convert.h"
#include "kpcn/ops_metrics.h"
extern "C" {
#include "testutil.h" // a C header without extern "C" guards
}

#include <OpenImageIO/imagebufalgo.h>

#include <cmath>
#include <cstring>
#include <string>

using OIIO::ImageBuf;
using OIIO::ImageSpec;
using OIIO::ROI;
using OIIO::TypeDesc;
namespace ops = kpcn::ops;

static ImageBuf make(int w, int h, const std::vector<std::string> &names, unsigned seed) {
  ImageSpec spec(w, h, (int)names.size(), TypeDesc::FLOAT);
  spec.channelnames = names;
  ImageBuf b(spec);
  unsigned st = seed;
  std::vector<float> px((size_t)w * h * names.size());
  for (auto &v : px)
    v = kt_randf(&st);
  b.set_pixels(ROI::All(), TypeDesc::FLOAT, px.data());
  return b;
}

int main() {
  const int w = 40, h = 30;
  ImageBuf x = make(w, h, {"R", "G", "B", "Z"}, 3), y = make(w, h, {"R", "G", "B"}, 9);
  // compare(): by name, defaults to the reference's channels; equals a direct loop.
  ops::MetricResult r = ops::compare(x, y, ops::Metric::RelMSE);
  CHECK(r.ok);
  double s = 0;
  for (int j = 0; j < h; ++j)
    for (int i = 0; i < w; ++i)
      for (int c = 0; c < 3; ++c) {
        float a = x.getchannel(i, j, 0, c), b = y.getchannel(i, j, 0, c);
        s += (double(a) - b) * (double(a) - b) / (double(b) * b + 0.01);
      }
  CHECK_CLOSE(r.value, s / (3.0 * w * h), 1e-12, 0);
  CHECK(r.nchannels == 3 && r.npixels == w * h && r.channel_names.size() == 3);
  // Default channels: an AOV reference with an RGB (denoised) test image, and two AOV images,
  // are compared on R,G,B (equal to naming them); RGBA images on all four channels.
  {
    ImageBuf aov =
        make(w, h, {"R", "G", "B", "albedo.R", "albedo.G", "albedo.B", "Z", "color.var"}, 21);
    ops::CompareOptions rgb;
    rgb.channels = {"R", "G", "B"};
    ops::MetricResult a = ops::compare(y, aov, ops::Metric::RelMSE),
                      b = ops::compare(y, aov, ops::Metric::RelMSE, rgb),
                      c = ops::compare(x, aov, ops::Metric::RelMSE),
                      d = ops::compare(x, aov, ops::Metric::RelMSE, rgb);
    CHECK(a.ok && b.ok && a.value == b.value && a.nchannels == 3 && a.channel_names[2] == "B");
    CHECK(c.ok && d.ok && c.value == d.value && c.nchannels == 3);
    ImageBuf p = make(w, h, {"R", "G", "B", "A"}, 5), q = make(w, h, {"R", "G", "B", "A"}, 6);
    ops::MetricResult e = ops::compare(p, q, ops::Metric::L1);
    CHECK(e.ok && e.nchannels == 4 && e.channel_names[3] == "A");
    // a reference without R,G,B: every one of its channels, as before
    ImageBuf z = make(w, h, {"Z"}, 7);
    ops::MetricResult f = ops::compare(x, z, ops::Metric::L1);
    CHECK(f.ok && f.nchannels == 1 && f.channel_names[0] == "Z");
  }
  // ROI: a window of both images.
  ROI roi(5, 25, 4, 20);
  ops::MetricResult rr = ops::compare(x, y, ops::Metric::L1, {}, roi);
  s = 0;
  for (int j = 4; j < 20; ++j)
    for (int i = 5; i < 25; ++i)
      for (int c = 0; c < 3; ++c)
        s += std::fabs(x.getchannel(i, j, 0, c) - y.getchannel(i, j, 0, c));
  CHECK(rr.ok);
  CHECK_CLOSE(rr.value, s / (3.0 * 20 * 16), 1e-12, 0);
  // Channel list + sRGB + SSIM: equals the C core on the same planes.
  ops::CompareOptions o;
  o.channels = {"G"};
  o.display_srgb = true;
  ops::MetricResult rs = ops::compare(x, y, ops::Metric::SSIM, o, {}, 2);
  std::string err;
  kpcn::ImagePtr gx = ops::to_kpcn_image(x, {"G"}, err), gy = ops::to_kpcn_image(y, {"G"}, err);
  CHECK(gx && gy);
  kpcn_metric_options co;
  kpcn_metric_options_defaults(&co);
  co.display = KPCN_DISPLAY_SRGB;
  kpcn_metric_result cr;
  CHECK(kpcn_metric_planar(KPCN_METRIC_SSIM, gx->data, gy->data, w, h, 1, &co, &cr, nullptr) ==
        KPCN_OK);
  CHECK(rs.ok && rs.value == cr.value);
  // errormap(): mean of the map = the metric; errors on dst.
  ImageBuf map;
  CHECK(ops::errormap(map, x, y, ops::Metric::RelMSE));
  CHECK(map.nchannels() == 3 && map.spec().channel_name(0) == "R");
  auto stats = OIIO::ImageBufAlgo::computePixelStats(map);
  CHECK_CLOSE((stats.avg[0] + stats.avg[1] + stats.avg[2]) / 3, r.value, 1e-6, 0); /* float avg */
  ImageBuf small = make(w - 1, h, {"R", "G", "B"}, 1), bad;
  CHECK(!ops::errormap(bad, x, small, ops::Metric::L1));
  CHECK(bad.geterror().find("sizes differ") != std::string::npos);
  o.channels = {"Q"};
  ops::MetricResult rq = ops::compare(x, y, ops::Metric::L1, o);
  CHECK(!rq.ok && rq.error.find("'Q'") != std::string::npos);
  ops::Metric m;
  CHECK(ops::metric_from_name("SSIM", m) && m == ops::Metric::SSIM);
  CHECK(!ops::metric_from_name("foo", m));
  // kpcn_image round trip keeps names and values.
  kpcn::ImagePtr ix = ops::to_kpcn_image(x, err);
  CHECK(ix && ix->nchannels == 4 && std::strcmp(ix->names[3], "Z") == 0);
  ImageBuf back = ops::from_kpcn_image(*ix);
  CHECK(back.spec().channelnames == x.spec().channelnames);
  auto cmp = OIIO::ImageBufAlgo::compare(back, x, 0.0f, 0.0f);
  CHECK(cmp.nfail == 0 && cmp.maxerror == 0);
  // A data window away from 0,0 and a channel list out of order: each plane is its channel.
  ImageBuf off = make(37, 9, {"A", "R", "G", "B", "Z"}, 11);
  off.set_origin(3, 5);
  kpcn::ImagePtr io = ops::to_kpcn_image(off, {"Z", "G"}, err);
  CHECK(io && io->width == 37 && io->height == 9);
  int same_px = 0;
  for (int y = 0; io && y < 9; ++y)
    for (int x = 0; x < 37; ++x)
      same_px += kpcn_image_plane(io.get(), 0)[y * 37 + x] == off.getchannel(3 + x, 5 + y, 0, 4) &&
                 kpcn_image_plane(io.get(), 1)[y * 37 + x] == off.getchannel(3 + x, 5 + y, 0, 2);
  CHECK(same_px == 37 * 9);
  // AOV set from the Tungsten EXR (through OIIO), and back.
  ImageBuf noisy(std::string(KPCN_TESTDATA) + "/tungsten-cornell/noisy_16spp.exr");
  kpcn::AovPtr set = ops::to_aov_set(noisy, err);
  CHECK(set != nullptr);
  if (set) {
    CHECK(set->spp == 16 && set->width == 256);
    CHECK(set->buf[KPCN_BUF_COLOR] && set->buf[KPCN_BUF_ALBEDO] && set->buf[KPCN_BUF_NORMAL]);
    CHECK(set->var[KPCN_BUF_COLOR] && !set->buf[KPCN_BUF_DIFFUSE]);
    CHECK(std::strcmp(set->scene, "tungsten cornell-box") == 0);
    ImageBuf again;
    CHECK(ops::from_aov_set(again, *set));
    CHECK(again.spec().get_int_attribute("kpcn:spp") == 16);
    // no albedo pass: no kpcn:albedoSpp; one: kept both ways
    CHECK(set->albedo_spp == 0 && again.spec().find_attribute("kpcn:albedoSpp") == nullptr);
    CHECK(set->albedo_footprint == 0 &&
          again.spec().find_attribute("kpcn:albedoFootprint") == nullptr);
    set->albedo_spp = 64;
    set->albedo_footprint = 2;
    ImageBuf with_pass;
    CHECK(ops::from_aov_set(with_pass, *set));
    CHECK(with_pass.spec().get_int_attribute("kpcn:albedoSpp") == 64);
    CHECK(with_pass.spec().get_int_attribute("kpcn:albedoFootprint") == 2);
    kpcn::AovPtr back = ops::to_aov_set(with_pass, err);
    CHECK(back && back->albedo_spp == 64 && back->albedo_footprint == 2 && back->spp == 16);
    ops::CompareOptions all;
    all.channels = {"R", "G", "B", "albedo.G", "N.Z", "Z", "visibility.V", "color.var"};
    ops::MetricResult same = ops::compare(again, noisy, ops::Metric::L1, all);
    CHECK(same.ok && same.value == 0.0);
  }
  ImageBuf missing(std::string(KPCN_TESTDATA) + "/no_such_file.exr");
  CHECK(!ops::to_kpcn_image(missing, err) && err.find("no_such_file.exr") != std::string::npos);
  return kt_summary("test_ops_metrics");
}
