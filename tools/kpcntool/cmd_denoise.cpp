// kpcntool --denoise: pops an AOV image, pushes the denoised RGB image.
//   --denoise:model=m.safetensors[:bf16=1][:tile=N][:ensemble=N]
//   --denoise:method=bilateral|nlmeans
#include "kpcn/ops_denoise.h"
#include "kpcntool.h"

namespace {

bool run_denoise(kpcntool::Context &ctx, const kpcntool::Modifiers &m,
                 const std::vector<std::string> &, std::string &err) {
  kpcn::ops::DenoiseOptions opt;
  opt.model = m.str("model");
  opt.method = m.str("method", opt.model.empty() ? "" : "kpcn");
  if (opt.method.empty()) {
    err = "give model=<file.safetensors> or method=bilateral|nlmeans";
    return false;
  }
  if (opt.method != "kpcn" && opt.method != "bilateral" && opt.method != "nlmeans") {
    err = "unknown method '" + opt.method + "' (kpcn, bilateral, nlmeans)";
    return false;
  }
  opt.bf16 = m.integer("bf16", 0) != 0;
  long tile = m.integer("tile", 0);
  if (tile < 0 || tile > 65536) {
    err = "tile must be in [0, 65536] (got " + std::to_string(tile) + ")";
    return false;
  }
  opt.tile = (int)tile;
  long ensemble = m.integer("ensemble", 1);
  if (ensemble != 1 && ensemble != 2 && ensemble != 4 && ensemble != 8) {
    err = "ensemble must be 1, 2, 4 or 8 (got " + std::to_string(ensemble) + ")";
    return false;
  }
  opt.ensemble = (int)ensemble;
  OIIO::ImageBuf src = ctx.pop();
  OIIO::ImageBuf dst;
  if (!kpcn::ops::denoise(dst, src, opt, {}, ctx.nthreads)) {
    err = dst.geterror();
    ctx.push(std::move(src)); // leave the stack as it was
    return false;
  }
  ctx.push(std::move(dst));
  return true;
}

bool reg = kpcntool::register_command(
    {"denoise",
     0,
     {"model", "method", "bf16", "tile", "ensemble"},
     "denoise the top AOV image (model=m.safetensors | method=bilateral|nlmeans, bf16=1, tile=N, "
     "ensemble=2|4|8: average over mirrored/rotated copies)",
     run_denoise});

} // namespace
