// kpcntool metric commands: --l1 --mse --relmse --rell1 --psnr --ssim compare the two top
// images (second-from-top = test image, top = reference) without changing the stack;
// --errormap:metric=M pops both and pushes the per-pixel error image.
// Modifiers: channels=R,G,B  display=srgb|linear  range=1  eps=0.01  allow_nonfinite=0|1.
#include "kpcn/ops_metrics.h"
#include "kpcn/oiio_convert.h"
#include "kpcntool.h"

namespace {

using kpcn::ops::Metric;

const std::vector<std::string> kMods = {"channels", "display", "range", "eps", "allow_nonfinite"};

bool options(const kpcntool::Modifiers &m, kpcn::ops::CompareOptions &o, std::string &err) {
  o.channels = kpcn::ops::split_names(m.str("channels"));
  std::string d = m.str("display", "linear");
  if (d != "linear" && d != "srgb" && d != "sRGB") {
    err = "modifier 'display' must be srgb or linear (got '" + d + "')";
    return false;
  }
  o.display_srgb = d != "linear";
  (void)m.flag("allow_nonfinite", false); // checked here, used only when NaN/Inf appear
  o.data_range = m.num("range", 1.0);
  o.eps = m.num("eps", 0.01);
  if (!(o.data_range > 0)) {
    err = "modifier 'range' must be positive (got '" + m.str("range") + "')";
    return false;
  }
  if (!(o.eps > 0)) {
    err = "modifier 'eps' must be > 0 (got '" + m.str("eps") + "')";
    return false;
  }
  return true;
}

// Non-finite pixels are an error unless allow_nonfinite=1 (they are then excluded).
bool check_nonfinite(const kpcn::ops::MetricResult &r, const kpcntool::Modifiers &m,
                     const OIIO::ImageBuf &x, const OIIO::ImageBuf &y, std::string &err) {
  if (r.nonfinite == 0 || m.flag("allow_nonfinite", false)) return true;
  auto nm = [](const OIIO::ImageBuf &b, const char *role) {
    return b.name().empty() ? std::string(role) : "'" + std::string(b.name()) + "'";
  };
  err = std::to_string(r.nonfinite) + " pixel(s) hold NaN/Inf in " + nm(x, "the test image") +
        " or " + nm(y, "the reference image") + " (add :allow_nonfinite=1 to exclude them)";
  return false;
}

// The two comparison operands are the top two stack images (test, then reference); also
// parses the comparison modifiers into o.
bool top_pair(const kpcntool::Context &ctx, const kpcntool::Modifiers &m,
              kpcn::ops::CompareOptions &o, std::string &err) {
  if (ctx.stack.size() < 2) {
    err = "needs two images on the stack (test image, then reference); found " +
          std::to_string(ctx.stack.size());
    return false;
  }
  return options(m, o, err);
}

bool run_metric(Metric metric, kpcntool::Context &ctx, const kpcntool::Modifiers &m,
                std::string &err) {
  kpcn::ops::CompareOptions o;
  if (!top_pair(ctx, m, o, err)) return false;
  const OIIO::ImageBuf &x = ctx.stack[ctx.stack.size() - 2], &y = ctx.stack.back();
  kpcn::ops::MetricResult r = kpcn::ops::compare(x, y, metric, o, {}, ctx.nthreads);
  // Non-finite pixels are reported naming both files even when they leave the metric nothing
  // to average (the library's own message names neither).
  if (!check_nonfinite(r, m, x, y, err)) return false;
  if (!r.ok) {
    err = r.error;
    return false;
  }
  // the count's key follows the value's own (l1_2 -> l1_2_nonfinite_pixels: it was
  // l1_nonfinite_pixels, read as the first --l1's)
  const std::string key = ctx.add_result(kpcn::ops::metric_name(metric), r.value);
  if (r.nonfinite) ctx.add_result(key + "_nonfinite_pixels", (double)r.nonfinite);
  return true;
}

bool run_errormap(kpcntool::Context &ctx, const kpcntool::Modifiers &m,
                  const std::vector<std::string> &, std::string &err) {
  Metric metric;
  std::string name = m.str("metric", "relmse");
  if (!kpcn::ops::metric_from_name(name, metric)) {
    err = "unknown metric '" + name + "' (l1, mse, relmse, rell1, psnr, ssim)";
    return false;
  }
  kpcn::ops::CompareOptions o;
  if (!top_pair(ctx, m, o, err)) return false;
  const OIIO::ImageBuf &x = ctx.stack[ctx.stack.size() - 2], &y = ctx.stack.back();
  OIIO::ImageBuf map;
  kpcn::ops::MetricResult r;
  if (!kpcn::ops::errormap(map, x, y, metric, o, {}, ctx.nthreads, &r)) {
    err = map.geterror();
    return false;
  }
  if (!check_nonfinite(r, m, x, y, err)) return false;
  ctx.stack.resize(ctx.stack.size() - 2);
  ctx.push(std::move(map));
  return true;
}

template <Metric M>
bool run_one(kpcntool::Context &ctx, const kpcntool::Modifiers &m, const std::vector<std::string> &,
             std::string &err) {
  return run_metric(M, ctx, m, err);
}

std::vector<std::string> with_metric() {
  std::vector<std::string> v = kMods;
  v.push_back("metric");
  return v;
}

bool r1 = kpcntool::register_command(
    {"l1", 0, kMods, "mean |x-y| of the two top images (x below, reference y on top)",
     run_one<Metric::L1>});
bool r2 = kpcntool::register_command(
    {"mse", 0, kMods, "mean (x-y)^2 of the two top images", run_one<Metric::MSE>});
bool r3 = kpcntool::register_command(
    {"relmse", 0, kMods, "mean (x-y)^2/(y^2+eps) of the two top images", run_one<Metric::RelMSE>});
bool r4 = kpcntool::register_command(
    {"rell1", 0, kMods, "mean |x-y|/(|y|+eps) of the two top images", run_one<Metric::RelL1>});
bool r5 = kpcntool::register_command(
    {"psnr", 0, kMods, "10 log10(range^2/MSE) of the two top images", run_one<Metric::PSNR>});
bool r6 = kpcntool::register_command({"ssim", 0, kMods,
                                      "SSIM (Wang 2004, 11x11 Gaussian 1.5) of the two top images",
                                      run_one<Metric::SSIM>});
bool r7 = kpcntool::register_command(
    {"errormap", 0, with_metric(),
     "pop the two top images, push the per-pixel error image (metric=relmse|l1|...|ssim)",
     run_errormap});

} // namespace
