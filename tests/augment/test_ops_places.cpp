// The ImageBuf ops keep where the pixels are and what the header says: a data window away from
// 0,0 stays where it was through colorswap / shift, and moves inside its frame (display
// window) through a mirror or quarter turn as with oiiotool's --flop / --rotate90 (also in
// place, dst == src, which must not lose the kpcn:* attributes); it stays through errormap and
// through a denoise with a ROI; a
// ROI outside the data window is an error, not a comparison against zeros. The same for the
// kernel export (denoise_kernels).
#include "kpcn/ops_augment.h"
#include "kpcn/ops_denoise.h"
#include "kpcn/ops_metrics.h"

extern "C" {
#include "testutil.h" // a C header without extern "C" guards
}

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imagebufalgo.h>

#include <string>

using OIIO::ImageBuf;
using OIIO::ImageSpec;
using OIIO::ROI;
using OIIO::TypeDesc;
namespace ops = kpcn::ops;

static bool placed_like(const ImageBuf &b, const ImageBuf &src) {
  const OIIO::ImageSpec &a = b.spec(), &s = src.spec();
  return a.x == s.x && a.y == s.y && a.full_x == s.full_x && a.full_y == s.full_y &&
         a.full_width == s.full_width && a.full_height == s.full_height;
}

int main() {
  ImageBuf aov(std::string(KPCN_TESTDATA) + "/dataset/sample_noisy.exr");
  CHECK(aov.read(0, 0, true, OIIO::TypeDesc::FLOAT));
  aov.set_origin(3, 5); // a crop of a larger frame
  aov.set_full(0, 40, 0, 50, 0, 1);
  CHECK(aov.spec().get_int_attribute("kpcn:spp") == 4);

  const int w = aov.spec().width, h = aov.spec().height;
  ImageBuf m = ops::mirror(aov), c = ops::colorswap(aov, "BRG"), s = ops::shift(aov, 2, 1);
  ImageBuf mv = ops::mirror(aov, true), r = ops::rotate(aov, 90.0);
  CHECK(!m.has_error() && m.spec().x == 40 - 3 - w && m.spec().y == 5 &&
        m.spec().full_width == 40 && m.spec().get_int_attribute("kpcn:spp") == 4);
  CHECK(!mv.has_error() && mv.spec().x == 3 && mv.spec().y == 50 - 5 - h);
  // a quarter turn counter-clockwise: the 40x50 frame becomes 50x40, pixel (u, v) -> (v, 39 - u)
  CHECK(!r.has_error() && r.spec().x == 5 && r.spec().y == 40 - 3 - w &&
        r.spec().full_width == 50 && r.spec().full_height == 40 && r.spec().width == h);
  CHECK(!c.has_error() && placed_like(c, aov));
  CHECK(!s.has_error() && placed_like(s, aov));
  ImageBuf inplace = aov; // dst == src: the attributes survive, the place moves as above
  CHECK(ops::mirror(inplace, inplace));
  CHECK(inplace.spec().x == m.spec().x && inplace.spec().get_int_attribute("kpcn:spp") == 4);
  ImageBuf twice;
  CHECK(ops::mirror(twice, inplace)); // mirroring twice is the identity, pixel for pixel
  CHECK(placed_like(twice, aov) && OIIO::ImageBufAlgo::compare(twice, aov, 0.0f, 0.0f).nfail == 0);

  // errormap: the map lies where x's compared pixels lie
  ImageBuf map;
  CHECK(ops::errormap(map, aov, c, ops::Metric::L1));
  CHECK(placed_like(map, aov));
  ROI win(10, 20, 12, 30);
  CHECK(ops::errormap(map, aov, c, ops::Metric::L1, {}, win));
  CHECK(map.spec().x == 10 && map.spec().y == 12 && map.spec().width == 10);
  // a window outside the data window (which starts at 3,5) is an error naming it
  ops::MetricResult out = ops::compare(aov, c, ops::Metric::L1, {}, ROI(0, 10, 0, 10));
  CHECK(!out.ok && out.error.find("not inside") != std::string::npos);

  // denoise: the whole result keeps the input's place; a ROI's part is stored where it was
  ops::DenoiseOptions o;
  o.method = "bilateral";
  ImageBuf d = ops::denoise(aov, o), part = ops::denoise(aov, o, win);
  CHECK(!d.has_error() && placed_like(d, aov) && d.nchannels() == 3);
  CHECK(!part.has_error() && part.spec().x == 10 && part.spec().y == 12 &&
        part.spec().width == 10 && part.spec().height == 18);
  CHECK(OIIO::ImageBufAlgo::compare(part, d, 0.0f, 0.0f, win).nfail == 0);
  ImageBuf bad = ops::denoise(aov, o, ROI(0, 10, 0, 10));
  CHECK(bad.has_error() && bad.geterror().find("not inside") != std::string::npos);

  // denoise_kernels (the shipped model): the same placement rules; all 3 + K² channels of a
  // ROI's part are the whole result's there; a baseline has no kernels
  ops::DenoiseOptions k;
  k.model = std::string(KPCN_TESTDATA) + "/models/kpcn-cpu.safetensors";
  ImageBuf kf, kp;
  CHECK(ops::denoise_kernels(kf, aov, k, "specular"));
  CHECK(ops::denoise_kernels(kp, aov, k, "specular", win));
  CHECK(placed_like(kf, aov) && kf.nchannels() == 3 + 11 * 11);
  CHECK(kf.spec().get_int_attribute("kpcn:kernelSize") == 11);
  CHECK(kf.spec().get_string_attribute("kpcn:branch") == "specular");
  CHECK(kp.spec().x == 10 && kp.spec().y == 12 && kp.nchannels() == kf.nchannels());
  CHECK(OIIO::ImageBufAlgo::compare(kp, kf, 0.0f, 0.0f, win).nfail == 0);
  ImageBuf kb;
  CHECK(!ops::denoise_kernels(kb, aov, o, "diffuse"));
  CHECK(kb.geterror().find("predicts no kernels") != std::string::npos);
  ops::DenoiseOptions unk = k; // an unknown method is named as such, with or without a model
  unk.method = "foo";
  CHECK(!ops::denoise_kernels(kb, aov, unk, "diffuse") &&
        kb.geterror().find("unknown method 'foo'") != std::string::npos);
  CHECK(!ops::denoise_kernels(kb, aov, k, "albedo"));
  CHECK(kb.geterror().find("albedo") != std::string::npos);
  // the value-returning form (session 60: only the dst form existed)
  ImageBuf kv = ops::denoise_kernels(aov, k, "specular", win);
  CHECK(!kv.has_error() && OIIO::ImageBufAlgo::compare(kv, kp, 0.0f, 0.0f).nfail == 0);

  // session 60 (a review of the C++ face): an empty ROI is an error (it returned true with an
  // uninitialised dst); errormap in place keeps x's windows; a deep image is refused, not a
  // crash
  ImageBuf e;
  CHECK(!ops::denoise(e, aov, o, ROI(5, 5, 5, 9)));
  CHECK(e.geterror().find("holds no pixels") != std::string::npos);
  CHECK(!ops::denoise_kernels(e, aov, k, "diffuse", ROI(3, 3, 0, 8)));
  CHECK(e.geterror().find("holds no pixels") != std::string::npos);
  ImageBuf ip = aov;
  CHECK(ops::errormap(ip, ip, c, ops::Metric::L1, {}, win));
  CHECK(ip.spec().x == 10 && ip.spec().y == 12 && ip.spec().full_width == 40 &&
        ip.spec().full_height == 50);
  ip = aov;
  CHECK(ops::errormap(ip, ip, c, ops::Metric::L1));
  CHECK(placed_like(ip, aov));
  ImageSpec ds(8, 8, 3, TypeDesc::FLOAT);
  ds.deep = true;
  ImageBuf deep(ds), dd;
  CHECK(!ops::mirror(dd, deep) && dd.geterror().find("deep") != std::string::npos);
  CHECK(!ops::denoise(dd, deep, o) && dd.geterror().find("deep") != std::string::npos);
  ops::MetricResult dr = ops::compare(deep, deep, ops::Metric::L1);
  CHECK(!dr.ok && dr.error.find("deep") != std::string::npos);
  // a missing file or an empty ImageBuf is named as such (it read as a 0x0 size mismatch)
  ImageBuf nofile(std::string(KPCN_TESTDATA) + "/no_such_file.exr");
  ops::MetricResult nr = ops::compare(nofile, aov, ops::Metric::L1);
  CHECK(!nr.ok && nr.error.find("not initialized") != std::string::npos &&
        nr.error.find("sizes differ") == std::string::npos);
  nr = ops::compare(aov, ImageBuf(), ops::Metric::L1);
  CHECK(!nr.ok && nr.error.find("the reference image is not initialized") != std::string::npos);

  // session 62 (a second review of the C++ face):
  // a large angle is reduced to [0, 360) first: 1e18 degrees is 280 (it was taken as an exact
  // quarter-turn multiple, the identity), -90 is 270
  ImageBuf big = ops::rotate(aov, 1e18), r280 = ops::rotate(aov, 280.0);
  CHECK(!big.has_error() && OIIO::ImageBufAlgo::compare(big, r280, 0.0f, 0.0f).nfail == 0 &&
        OIIO::ImageBufAlgo::compare(big, aov, 0.0f, 0.0f).nfail != 0);
  ImageBuf rm90 = ops::rotate(aov, -90.0), r270 = ops::rotate(aov, 270.0 + 360.0 * 1e6);
  CHECK(OIIO::ImageBufAlgo::compare(rm90, r270, 0.0f, 0.0f).nfail == 0 && placed_like(rm90, r270));
  // patches: a reference naming a file that failed to open is an error, not "no reference";
  // one covering other pixels is refused before anything is written (the directory form cut
  // misaligned pairs); a patch store without a reference says that it needs one
  kpcn_patch_settings ps;
  kpcn_patch_settings_defaults(&ps);
  ps.size = 8;
  std::vector<kpcn_patch_origin> po;
  kpcn_patch_stats pst;
  std::string perr;
  CHECK(!ops::select_patches(aov, nofile, ps, po, pst, perr) &&
        perr.find("not initialized") != std::string::npos);
  CHECK(ops::select_patches(aov, aov, ps, po, pst, perr) && !po.empty());
  const std::string pdir = kt_tmpfile("ops_patches");
  OIIO::Filesystem::remove_all(pdir);
  CHECK(!ops::write_patches(pdir, aov, nofile, po, 8, perr));
  ImageBuf moved = aov;
  moved.set_origin(4, 5);
  CHECK(!ops::write_patches(pdir, aov, moved, po, 8, perr) &&
        perr.find("must cover the same pixels") != std::string::npos);
  ImageBuf small = OIIO::ImageBufAlgo::cut(aov, ROI(3, 3 + w - 2, 5, 5 + h));
  CHECK(!ops::write_patches(pdir, aov, small, po, 8, perr) &&
        perr.find("must cover the same pixels") != std::string::npos);
  CHECK(!OIIO::Filesystem::exists(pdir)); // refused before the folder was made
  CHECK(!ops::write_patches(pdir + ".kps", aov, ImageBuf(), po, 8, perr) &&
        perr.find("needs a reference image") != std::string::npos);
  CHECK(ops::write_patches(pdir, aov, aov, po, 8, perr));
  return kt_summary("test_ops_places");
}
