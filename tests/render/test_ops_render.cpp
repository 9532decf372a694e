// kpcn::ops::render (kpcn/ops_render.h): the ImageBuf op's pixels are kpcn_render's bit for bit
// (every channel, whatever nthreads), a window lies where it is in the image and equals that
// part of the whole render, the kpcn:* attributes are kpcn-render's, errors land on dst.
#include "kpcn/oiio_convert.h"
#include "kpcn/ops_render.h"
#include "kpcn/render.h"
#include "kpcn/scene.h"
extern "C" {
#include "testutil.h" // a C header without extern "C" guards
}

#include <OpenImageIO/imagebufalgo.h>

#include <string>

#define CORNELL KPCN_TESTDATA "/scenes/cornell-box/scene.json"

namespace ops = kpcn::ops;

int main() {
  ops::RenderOptions o;
  o.spp = 8, o.seed = 5, o.width = 40, o.height = 30;
  OIIO::ImageBuf a;
  CHECK(ops::render(a, CORNELL, o, {}, 2));
  // the C library's render of the same settings, converted
  kpcn_scene *s = nullptr;
  CHECK(kpcn_scene_load(CORNELL, &s) == KPCN_OK);
  kpcn_render_settings rs = kpcn_render_settings_defaults();
  rs.spp = 8, rs.seed = 5, rs.width = 40, rs.height = 30, rs.nthreads = 1;
  kpcn_aov_set *set = nullptr;
  CHECK(s && kpcn_render(s, &rs, &set) == KPCN_OK);
  kpcn_scene_destroy(s);
  OIIO::ImageBuf c = ops::from_aov_set(*set);
  kpcn_aov_destroy(set);
  CHECK(a.nchannels() == 24 && a.spec().channelnames == c.spec().channelnames);
  auto cmp = OIIO::ImageBufAlgo::compare(a, c, 0.0f, 0.0f);
  CHECK(cmp.nfail == 0 && cmp.maxerror == 0);
  CHECK(a.spec().get_int_attribute("kpcn:spp") == 8);
  CHECK(a.spec().get_string_attribute("kpcn:scene") == CORNELL);

  // a window: at its place, the same pixels as that part of the whole image
  OIIO::ROI roi(8, 24, 5, 17);
  OIIO::ImageBuf w = ops::render(CORNELL, o, roi, 1);
  CHECK(!w.has_error() && w.spec().x == 8 && w.spec().y == 5 && w.spec().width == 16 &&
        w.spec().height == 12 && w.spec().full_width == 40 && w.spec().full_height == 30);
  OIIO::ImageBuf part = OIIO::ImageBufAlgo::cut(a, roi);
  OIIO::ImageBuf wc = OIIO::ImageBufAlgo::cut(w, roi);
  auto cw = OIIO::ImageBufAlgo::compare(wc, part, 0.0f, 0.0f);
  CHECK(cw.nfail == 0 && cw.maxerror == 0);

  // colour only, and the errors
  o.color_only = true;
  OIIO::ImageBuf co = ops::render(CORNELL, o);
  CHECK(co.nchannels() == 4 && co.spec().channel_name(3) == "color.var");
  OIIO::ImageBuf bad;
  CHECK(!ops::render(bad, "no_such_scene.json", o));
  CHECK(bad.geterror().find("no_such_scene.json") != std::string::npos);
  CHECK(!ops::render(bad, CORNELL, o, OIIO::ROI(30, 50, 0, 10)));
  CHECK(bad.geterror().find("lies outside") != std::string::npos);
  // an empty or zero-depth window is an error (an all-zero one rendered the whole image: the
  // library's "no crop")
  CHECK(!ops::render(bad, CORNELL, o, OIIO::ROI(0, 0, 0, 0)) &&
        bad.geterror().find("holds no pixels") != std::string::npos);
  CHECK(!ops::render(bad, CORNELL, o, OIIO::ROI(2, 6, 1, 5, 0, 0)) &&
        bad.geterror().find("holds no pixels") != std::string::npos);
  o.width = 10, o.height = 0;
  CHECK(!ops::render(bad, CORNELL, o) &&
        bad.geterror().find("width and height") != std::string::npos);
  // a negative max_bounces other than -1 (the scene's) was taken as -1 without a word
  o.width = 8, o.height = 8, o.max_bounces = -7;
  CHECK(!ops::render(bad, CORNELL, o) &&
        bad.geterror().find("max_bounces: -7 must be >= 0") != std::string::npos);
  return kt_summary("ops_render");
}
