// kpcntool augmentation commands (DESIGN.md §6). Each acts on the top image, or on every
// image of the stack with :all=1 (so a noisy/reference pair gets the same transform):
//   --mirror[:dir=h|v]  --rotate:deg=90  --colorswap:perm=BRG  --shift:dx=5:dy=-3
//   --augment:seed=S[:index=I:shift=N:mirror_v=1:oneof=1]  one random draw, whole stack
//   --patches:size=65:count=400:seed=1[:stride=S:cull=0.9:tol=0.05:abs=0.01:importance=1
//             :out=DIR|FILE.kps]  patches of noisy (second from top) + reference (top)
#include "kpcn/ops_augment.h"
#include "kpcntool.h"

#include <cmath>
#include <cstdio>
#include <memory>

namespace {

using kpcntool::Context;
using kpcntool::Modifiers;

// Applies op to the top image, or to every stack image with :all=1.
template <class F> bool each(Context &ctx, const Modifiers &m, std::string &err, F &&op) {
  if (ctx.stack.empty()) {
    err = "needs an image on the stack";
    return false;
  }
  size_t first = m.flag("all", false) ? 0 : ctx.stack.size() - 1;
  for (size_t i = first; i < ctx.stack.size(); i++) {
    OIIO::ImageBuf dst;
    if (!op(dst, ctx.stack[i])) {
      err = dst.geterror();
      if (err.empty()) err = "failed";
      return false;
    }
    ctx.stack[i] = std::move(dst);
  }
  return true;
}

bool cmd_mirror(Context &ctx, const Modifiers &m, const std::vector<std::string> &,
                std::string &err) {
  std::string d = m.str("dir", "h");
  if (d != "h" && d != "v") {
    err = "modifier 'dir' must be h or v (got '" + d + "')";
    return false;
  }
  return each(ctx, m, err, [&](OIIO::ImageBuf &dst, const OIIO::ImageBuf &src) {
    return kpcn::ops::mirror(dst, src, d == "v", ctx.nthreads);
  });
}

bool cmd_rotate(Context &ctx, const Modifiers &m, const std::vector<std::string> &,
                std::string &err) {
  double deg = m.num("deg", 90.0);
  return each(ctx, m, err, [&](OIIO::ImageBuf &dst, const OIIO::ImageBuf &src) {
    return kpcn::ops::rotate(dst, src, deg, ctx.nthreads);
  });
}

bool cmd_colorswap(Context &ctx, const Modifiers &m, const std::vector<std::string> &,
                   std::string &err) {
  if (!m.has("perm")) {
    err = "needs :perm=XYZ, a permutation of RGB such as BRG";
    return false;
  }
  std::string p = m.str("perm");
  return each(ctx, m, err, [&](OIIO::ImageBuf &dst, const OIIO::ImageBuf &src) {
    return kpcn::ops::colorswap(dst, src, p, ctx.nthreads);
  });
}

bool cmd_shift(Context &ctx, const Modifiers &m, const std::vector<std::string> &,
               std::string &err) {
  long dx = m.integer("dx", 0), dy = m.integer("dy", 0);
  return each(ctx, m, err, [&](OIIO::ImageBuf &dst, const OIIO::ImageBuf &src) {
    return kpcn::ops::shift(dst, src, (int)dx, (int)dy, ctx.nthreads);
  });
}

bool cmd_augment(Context &ctx, const Modifiers &m, const std::vector<std::string> &,
                 std::string &err) {
  kpcn_augment_draw_settings ds;
  kpcn_augment_draw_defaults(&ds);
  ds.mirror_v = m.flag("mirror_v", false);
  ds.max_shift = (int)m.integer("shift", 0);
  ds.mode = m.flag("oneof", false) ? KPCN_AUGMENT_ONE_OF : KPCN_AUGMENT_ALL;
  if (ds.max_shift < 0) {
    err = "modifier 'shift' must be >= 0";
    return false;
  }
  kpcn_augment_xform x;
  kpcn_augment_draw(&x, &ds, m.u64("seed", 1), m.u64("index", 0));
  Modifiers all = m;
  all.kv["all"] = "1"; // one draw for the whole stack keeps pairs aligned
  return each(ctx, all, err, [&](OIIO::ImageBuf &dst, const OIIO::ImageBuf &src) {
    return kpcn::ops::augment(dst, src, x, ctx.nthreads);
  });
}

bool cmd_patches(Context &ctx, const Modifiers &m, const std::vector<std::string> &,
                 std::string &err) {
  if (ctx.stack.empty()) {
    err = "needs the noisy image (and optionally the reference on top of it)";
    return false;
  }
  kpcn_patch_settings s;
  kpcn_patch_settings_defaults(&s);
  if (m.has("stride") && m.has("count")) {
    err = "count= (random patches) and stride= (a regular grid) exclude each other";
    return false;
  }
  s.size = (int)m.integer("size", 65);
  s.count = m.has("stride") ? 0 : (int)m.integer("count", 400);
  // kpcn-dataset patches' --per-image limit: 99999999 ran for ten minutes and filled the disk
  if (s.count > (1 << 20)) {
    err = "count=" + std::to_string(s.count) + " is more than 1048576 patches per image";
    return false;
  }
  s.stride = (int)m.integer("stride", 0);
  s.seed = m.u64("seed", 1);
  s.cull = m.num("cull", 0.9);
  s.cull_tol = m.num("tol", 0.05);
  s.cull_abs = m.num("abs", 0.01);
  s.importance = m.flag("importance", false);
  s.nthreads = ctx.nthreads;
  bool pair = ctx.stack.size() >= 2;
  const OIIO::ImageBuf &noisy = pair ? ctx.stack[ctx.stack.size() - 2] : ctx.stack.back();
  OIIO::ImageBuf none;
  const OIIO::ImageBuf &ref = pair ? ctx.stack.back() : none;
  std::vector<kpcn_patch_origin> o;
  kpcn_patch_stats st;
  if (!kpcn::ops::select_patches(noisy, ref, s, o, st, err)) return false;
  ctx.add_result("patches_candidates", (double)st.candidates);
  ctx.add_result("patches_kept", (double)st.kept);
  ctx.add_result("patches_culled", (double)st.culled);
  if (!m.has("out")) return true;
  // Written with the -o files, after every command succeeded (no partial output).
  const std::string out = m.str("out");
  if (out.empty()) {
    err = "modifier 'out' needs a directory or a .kps file";
    return false;
  }
  const bool kps =
      out.size() > 4 && out.compare(out.size() - 4, 4, ".kps") == 0; // as write_patches
  if (kps && !pair) { // it failed at write time, naming a missing 'ref.R'
    err = "a patch store needs the noisy image and its reference on top of it (two images)";
    return false;
  }
  if (o.empty()) { // a store or folder of nothing, which training only refuses later
    err = "no patch kept (" + std::to_string(st.candidates) +
          " candidates, all culled at cull=" + m.str("cull", "0.9") + "): nothing to write";
    return false;
  }
  auto imgs = std::make_shared<const std::pair<OIIO::ImageBuf, OIIO::ImageBuf>>(noisy, ref);
  const int size = s.size;
  char settings[512];
  std::snprintf(settings, sizeof settings,
                "{\"size\":%d,\"count\":%d,\"stride\":%d,\"seed\":%llu,\"cull\":%.9g,"
                "\"tol\":%.9g,\"abs\":%.9g,\"importance\":%d}",
                s.size, s.count, s.stride, (unsigned long long)s.seed, s.cull, s.cull_tol,
                s.cull_abs, s.importance ? 1 : 0);
  const std::string sj = settings;
  ctx.outputs.push_back({"--patches:out=" + out, out, !kps,
                         [imgs, o, size, st, sj](const std::string &tmp, std::string &e) {
                           return kpcn::ops::write_patches(tmp, imgs->first, imgs->second, o, size,
                                                           e, &st, sj);
                         }});
  return true;
}

bool r1 = kpcntool::register_command({"mirror",
                                      0,
                                      {"dir", "all"},
                                      "mirror the top image (:dir=h|v; N.X resp. N.Y negated; "
                                      ":all=1 every stack image)",
                                      cmd_mirror});
bool r2 = kpcntool::register_command({"rotate",
                                      0,
                                      {"deg", "all"},
                                      "rotate counter-clockwise (:deg=90; multiples of 90 exact, "
                                      "others bilinear: alters noise statistics)",
                                      cmd_rotate});
bool r3 =
    kpcntool::register_command({"colorswap",
                                0,
                                {"perm", "all"},
                                "permute RGB of every colour buffer (:perm=XYZ required, e.g. BRG)",
                                cmd_colorswap});
bool r4 = kpcntool::register_command(
    {"shift", 0, {"dx", "dy", "all"}, "translate with wrap-around (:dx=N:dy=N)", cmd_shift});
bool r5 = kpcntool::register_command({"augment",
                                      0,
                                      {"seed", "index", "shift", "mirror_v", "oneof"},
                                      "one random draw (colour swap, mirror, rotate[, shift]) "
                                      "applied to every image on the stack",
                                      cmd_augment});
bool r6 = kpcntool::register_command(
    {"patches",
     0,
     {"size", "count", "stride", "seed", "cull", "tol", "abs", "importance", "out"},
     "select patches of noisy (2nd) / reference (top) with flat-patch culling; "
     ":out=DIR writes EXR pairs, :out=F.kps a patch store; prints kept/culled",
     cmd_patches});

} // namespace
