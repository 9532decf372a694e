// kpcntool --denoise: pops an AOV image, pushes the denoised RGB image.
//   --denoise:model=m.safetensors[:bf16=1][:tile=N][:ensemble=N][:exposure=auto|off|E]
//            [:firefly=R|off]
//   --denoise:method=bilateral|nlmeans
// kpcntool --kernels: pops an AOV image, pushes the KPCN's kernels of one branch.
//   --kernels:model=m.safetensors[:branch=diffuse|specular][:bf16=1][:tile=N][:exposure=..]
//            [:firefly=..]
#include "kpcn/oiio_convert.h"
#include "kpcn/ops_denoise.h"
#include "cli_parse.h"
#include "kpcntool.h"

#include <cstdlib>

namespace {

// exposure=auto (the model's), off (as rendered) or a number > 0.
bool parse_exposure(const std::string &v, kpcn::ops::DenoiseOptions &opt, std::string &err) {
  if (v == "auto" || v == "off") {
    opt.exposure = v == "auto" ? 0.0f : KPCN_EXPOSURE_AS_RENDERED;
    return true;
  }
  double e = 0;
  // (float)e must stay > 0: 0 is the library's "auto"
  if (!cli_parse_double(v.c_str(), &e) || !(e > 0.0 && e < 1e30) || !((float)e > 0.0f)) {
    err = "exposure must be auto, off or a number > 0 and < 1e30 that a float holds (got '" + v +
          "')";
    return false;
  }
  opt.exposure = (float)e;
  return true;
}

// firefly=off or a ratio >= 1 (absent: kpcn_denoiser_options' own).
bool parse_firefly(const kpcntool::Modifiers &m, kpcn::ops::DenoiseOptions &opt, std::string &err) {
  if (!m.has("firefly")) return true;
  const std::string v = m.str("firefly");
  if (v == "off") {
    opt.firefly = 0.0f;
    return true;
  }
  double r = 0;
  if (!cli_parse_double(v.c_str(), &r) || !(r >= 1.0 && r < 1e30)) {
    err = "firefly must be off or a ratio in [1, 1e30) (got '" + v + "')";
    return false;
  }
  opt.firefly = (float)r;
  return true;
}

// The KPCN's modifiers that --denoise and --kernels share: bf16, tile, exposure, firefly.
bool parse_kpcn_options(const kpcntool::Modifiers &m, kpcn::ops::DenoiseOptions &opt,
                        std::string &err) {
  opt.bf16 = m.flag("bf16", false);
  long tile = m.integer("tile", 0);
  if (tile < 0 || tile > 65536) {
    err = "tile must be in [0, 65536] (got " + std::to_string(tile) + ")";
    return false;
  }
  opt.tile = (int)tile;
  return parse_exposure(m.str("exposure", "auto"), opt, err) && parse_firefly(m, opt, err);
}

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
  if (opt.method != "kpcn")
    for (const char *k : {"model", "bf16", "tile", "ensemble", "exposure", "firefly"})
      if (m.has(k)) {
        err =
            "modifier '" + std::string(k) + "' applies only to the KPCN, not method=" + opt.method;
        return false;
      }
  if (!parse_kpcn_options(m, opt, err)) return false;
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

// --kernels: pops an AOV image, pushes the KPCN's predicted kernels of one branch.
bool run_kernels(kpcntool::Context &ctx, const kpcntool::Modifiers &m,
                 const std::vector<std::string> &, std::string &err) {
  kpcn::ops::DenoiseOptions opt;
  opt.model = m.str("model");
  if (opt.model.empty()) {
    err = "give model=<file.safetensors> (only the KPCN predicts kernels)";
    return false;
  }
  const std::string branch = m.str("branch", "diffuse");
  if (branch != "diffuse" && branch != "specular") {
    err = "branch must be diffuse or specular (got '" + branch + "')";
    return false;
  }
  if (!parse_kpcn_options(m, opt, err)) return false;
  OIIO::ImageBuf src = ctx.pop();
  OIIO::ImageBuf dst;
  if (!kpcn::ops::denoise_kernels(dst, src, opt, branch, {}, ctx.nthreads)) {
    err = dst.geterror();
    ctx.push(std::move(src)); // leave the stack as it was
    return false;
  }
  ctx.push(std::move(dst));
  return true;
}

// --exposure: the top AOV image's exposure (kpcn_aov_exposure), as a result; the stack is
// left as it is.
bool run_exposure(kpcntool::Context &ctx, const kpcntool::Modifiers &,
                  const std::vector<std::string> &, std::string &err) {
  kpcn::AovPtr set = kpcn::ops::to_aov_set(ctx.top(), err);
  if (!set) return false;
  double e = 0.0;
  if (kpcn_aov_exposure(set.get(), &e) != KPCN_OK) {
    err = kpcn_last_error();
    return false;
  }
  ctx.add_result("exposure", e);
  return true;
}

bool reg_exposure = kpcntool::register_command(
    {"exposure",
     0,
     {},
     "exposure of the top AOV image: median 8x8-block mean luminance of diffuse + specular "
     "(--denoise scales it to the model's exposure)",
     run_exposure});

bool reg_kernels = kpcntool::register_command(
    {"kernels",
     0,
     {"model", "branch", "bf16", "tile", "exposure", "firefly"},
     "the KPCN's predicted kernels of the top AOV image (model=m.safetensors, "
     "branch=diffuse|specular, default diffuse; bf16, tile, exposure, firefly as --denoise): "
     "channels pre.R/G/B (the preprocessed noisy colour) and kernel.000 .. kernel.K*K-1 (tap "
     "dy*K + dx)",
     run_kernels});

bool reg = kpcntool::register_command(
    {"denoise",
     0,
     {"model", "method", "bf16", "tile", "ensemble", "exposure", "firefly"},
     "denoise the top AOV image (model=m.safetensors | method=bilateral|nlmeans, bf16=1, tile=N, "
     "ensemble=1|2|4|8: average over mirrored/rotated copies, exposure=auto|off|E: the exposure "
     "the network is shown every input at, default the model's; firefly=R|off: bound isolated "
     "diffuse fireflies to R x their brightest neighbour first, default 4)",
     run_denoise});

} // namespace
