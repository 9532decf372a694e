// ImageBuf adapter for the path tracer: scene file -> kpcn_render -> kpcn_aov_set -> ImageBuf.
#include "kpcn/ops_render.h"

#include "kpcn/oiio_convert.h"
#include "ops_internal.h"

#ifdef KPCN_HAVE_EMBREE
#include "kpcn/render.h"
#include "kpcn/scene.h"
#endif

namespace kpcn {
namespace ops {

bool render(OIIO::ImageBuf &dst, const std::string &scene_path, const RenderOptions &opt,
            OIIO::ROI roi, int nthreads) {
#ifndef KPCN_HAVE_EMBREE
  (void)scene_path, (void)opt, (void)roi, (void)nthreads;
  dst.errorfmt("render: this kpcn was built without the renderer (KPCN_WITH_EMBREE=OFF)");
  return false;
#else
  if (empty_roi(dst, roi, "render")) return false;
  if ((opt.width > 0) != (opt.height > 0) || opt.width < 0 || opt.height < 0) {
    dst.errorfmt("render: width and height are given together and > 0 (got {}x{})", opt.width,
                 opt.height);
    return false;
  }
  kpcn_scene *scene = nullptr;
  if (kpcn_scene_load(scene_path.c_str(), &scene) != KPCN_OK) {
    dst.errorfmt("render: {}", kpcn_last_error());
    return false;
  }
  kpcn_render_settings rs = kpcn_render_settings_defaults();
  rs.spp = opt.spp;
  rs.seed = opt.seed;
  rs.nthreads = nthreads;
  rs.width = opt.width, rs.height = opt.height;
  rs.albedo_spp = opt.albedo_spp;
  rs.albedo_footprint = opt.albedo_footprint;
  rs.color_only = opt.color_only ? 1 : 0;
  rs.max_bounces = opt.max_bounces;
  if (roi.defined()) {
    rs.crop_x = roi.xbegin, rs.crop_y = roi.ybegin;
    rs.crop_w = roi.width(), rs.crop_h = roi.height();
  }
  kpcn_scene_info info;
  kpcn_scene_get_info(scene, &info);
  const int W = opt.width ? opt.width : info.width, H = opt.height ? opt.height : info.height;
  kpcn_aov_set *set = nullptr;
  kpcn_status st = kpcn_render(scene, &rs, &set);
  kpcn_scene_destroy(scene);
  if (st != KPCN_OK) {
    dst.errorfmt("render: {}", kpcn_last_error());
    return false;
  }
  OIIO::ImageBuf out;
  const bool ok = from_aov_set(out, *set);
  kpcn_aov_destroy(set);
  if (!ok) {
    dst.errorfmt("render: {}", out.geterror());
    return false;
  }
  if (roi.defined()) { /* the window, where it lies in the whole image */
    out.set_origin(roi.xbegin, roi.ybegin);
    out.set_full(0, W, 0, H, 0, 1);
  }
  dst = std::move(out);
  return true;
#endif
}

OIIO::ImageBuf render(const std::string &scene_path, const RenderOptions &opt, OIIO::ROI roi,
                      int nthreads) {
  OIIO::ImageBuf dst;
  render(dst, scene_path, opt, roi, nthreads);
  return dst;
}

} // namespace ops
} // namespace kpcn
