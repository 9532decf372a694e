// kpcn/ops_render.h — the path tracer as an ImageBufAlgo-style op (DESIGN.md §8): a Tungsten
// scene file rendered into an AOV ImageBuf with the channels, variances and kpcn:* attributes
// kpcn-render writes (docs/aov-exr.md), so a chain can render, denoise and measure without
// files in between (`kpcntool --render:spp=16 scene.json --denoise:model=m -o out.exr`).
#pragma once

#include <OpenImageIO/imagebuf.h>

#include <cstdint>
#include <string>

namespace kpcn {
namespace ops {

struct RenderOptions {
  int spp = 0;      // 0: the scene's renderer.spp
  int64_t seed = 1; // 0 .. 2^63-1
  int width = 0;    // resolution override, 0 = the scene's (both or neither)
  int height = 0;
  int albedo_spp = 0;       // kpcn_render_settings.albedo_spp (0 = off)
  int albedo_footprint = 0; // kpcn_render_settings.albedo_footprint (0 or 1 = off)
  bool color_only = false;  // R,G,B and color.var only
  int max_bounces = -1;     // -1: the scene's
};

// Renders scene_path into dst. roi (default: the whole image) is a window of the (possibly
// overridden) image, which dst then covers, at its place (origin roi.xbegin, roi.ybegin; full
// window the image); its channel range is ignored. The pixels equal kpcn-render's for the same
// settings bit for bit, whatever nthreads is (0 = all cores). Errors (an unreadable scene, a
// window outside the image, a build without the renderer) go to dst.errorfmt with false.
bool render(OIIO::ImageBuf &dst, const std::string &scene_path, const RenderOptions &opt = {},
            OIIO::ROI roi = {}, int nthreads = 0);
OIIO::ImageBuf render(const std::string &scene_path, const RenderOptions &opt = {},
                      OIIO::ROI roi = {}, int nthreads = 0);

} // namespace ops
} // namespace kpcn
