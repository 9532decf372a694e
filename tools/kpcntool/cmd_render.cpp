// kpcntool --render: renders a scene file and pushes its AOV image (kpcn::ops::render), so a
// chain can render, denoise and measure without intermediate files.
//   --render[:spp=N][:seed=S][:res=WxH][:crop=x,y,w,h][:albedo_spp=N][:footprint=K]
//           [:color_only=1][:max_bounces=N] scene.json
#include "cli_parse.h"
#include "kpcn/ops_render.h"
#include "kpcntool.h"

#include <climits>
#include <cstdio>

namespace {

bool run_render(kpcntool::Context &ctx, const kpcntool::Modifiers &m,
                const std::vector<std::string> &args, std::string &err) {
  kpcn::ops::RenderOptions o;
  o.spp = (int)m.integer("spp", 0);
  o.seed = (int64_t)m.u64("seed", 1, (uint64_t)INT64_MAX, "2^63-1");
  o.albedo_spp = (int)m.integer("albedo_spp", 0);
  o.albedo_footprint = (int)m.integer("footprint", 0);
  o.color_only = m.flag("color_only", false);
  o.max_bounces = (int)m.integer("max_bounces", -1);
  if (o.spp < 0 || o.spp > (1 << 24)) {
    err = "spp must be in [1, 2^24] (0: the scene's; got " + std::to_string(o.spp) + ")";
    return false;
  }
  if (o.max_bounces < -1) {
    err = "max_bounces must be >= 0 (-1: the scene's)";
    return false;
  }
  int wh[2] = {0, 0}, c[4];
  static const long lo_wh[2] = {1, 1}, hi_wh[2] = {INT_MAX, INT_MAX};
  static const long lo_c[4] = {0, 0, 1, 1}, hi_c[4] = {INT_MAX, INT_MAX, INT_MAX, INT_MAX};
  if (m.has("res") && !cli_parse_int_list(m.str("res").c_str(), 'x', 2, lo_wh, hi_wh, wh)) {
    err = "res must be WxH with W, H >= 1 (got '" + m.str("res") + "')";
    return false;
  }
  o.width = wh[0], o.height = wh[1];
  OIIO::ROI roi;
  if (m.has("crop")) {
    if (!cli_parse_int_list(m.str("crop").c_str(), ',', 4, lo_c, hi_c, c)) {
      err = "crop must be x,y,w,h with w, h >= 1 (got '" + m.str("crop") + "')";
      return false;
    }
    roi = OIIO::ROI(c[0], c[0] + c[2], c[1], c[1] + c[3]);
  }
  OIIO::ImageBuf img;
  if (!kpcn::ops::render(img, args[0], o, roi, ctx.nthreads)) {
    err = img.geterror();
    return false;
  }
  ctx.push(std::move(img));
  return true;
}

bool reg = kpcntool::register_command(
    {"render",
     1,
     {"spp", "seed", "res", "crop", "albedo_spp", "footprint", "color_only", "max_bounces"},
     "render a Tungsten scene file and push its AOV image (spp=N, default the scene's; seed=S; "
     "res=WxH; crop=x,y,w,h; albedo_spp=N; footprint=K: the albedo footprint; color_only=1; "
     "max_bounces=N): the pixels kpcn-render writes for the same settings",
     run_render});

} // namespace
