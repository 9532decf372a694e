// ImageBuf adapters over libkpcn's augment module (kpcn/ops_augment.h).
#include "kpcn/ops_augment.h"

#include "kpcn/dataset.h"
#include "kpcn/exr.h"
#include "kpcn/oiio_convert.h"

#include <OpenImageIO/imagebufalgo.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <sys/stat.h>
#include <utility>

namespace kpcn {
namespace ops {

namespace {

// Where a transform puts an image's pixels in its frame (display window). Mirrors and quarter
// turns act on the whole frame, as oiiotool's --flop, --flip and --rotate90 do, so a crop (a
// --render crop) keeps its place in the transformed frame; a shift wraps inside the pixels
// and moves nothing.
OIIO::ImageSpec transformed_frame(const OIIO::ImageSpec &s, const kpcn_augment_xform &x) {
  OIIO::ImageSpec f = s;
  int rx = s.x - s.full_x, ry = s.y - s.full_y;
  if (x.mirror_h) rx = s.full_width - rx - s.width;
  if (x.mirror_v) ry = s.full_height - ry - s.height;
  for (int t = 0; t < ((x.rot90 % 4) + 4) % 4; t++) {
    // one counter-clockwise turn: pixel (u, v) of a frame W wide goes to (v, W - 1 - u)
    const int nry = f.full_width - rx - f.width;
    rx = ry;
    ry = nry;
    std::swap(f.width, f.height);
    std::swap(f.full_width, f.full_height);
  }
  f.x = s.full_x + rx;
  f.y = s.full_y + ry;
  return f;
}

// Runs f on src's pixels and writes the result to dst (which may be src). The planar round
// trip carries neither the header attributes (kpcn:spp ...) nor the data window's place, so
// both are taken from src first (dst.reset would clear them when dst is src) and put back:
// moved by geom's mirrors and turns when given (transformed_frame), else (a rotation by another
// angle, which keeps the size) where src's were.
template <class F>
bool apply(OIIO::ImageBuf &dst, const OIIO::ImageBuf &src, const kpcn_augment_xform *geom, F &&f) {
  const OIIO::ImageSpec where = geom ? transformed_frame(src.spec(), *geom) : src.spec();
  std::string err;
  ImagePtr in = to_kpcn_image(src, err);
  if (!in) {
    dst.errorfmt("{}", err);
    return false;
  }
  kpcn_image *out = nullptr;
  if (f(&out, in.get()) != KPCN_OK) {
    dst.errorfmt("{}", kpcn_last_error());
    return false;
  }
  ImagePtr o(out);
  if (!from_kpcn_image(dst, *o)) {
    if (!dst.has_error()) dst.errorfmt("cannot convert the augmented image");
    return false;
  }
  for (const auto &p : where.extra_attribs)
    dst.specmod().attribute(p.name().string(), p.type(), p.data());
  dst.set_origin(where.x, where.y);
  dst.set_full(where.full_x, where.full_x + where.full_width, where.full_y,
               where.full_y + where.full_height, 0, 1);
  return true;
}

// Arbitrary-angle rotation of a kpcn_image (same size).
kpcn_status rotate_any_image(kpcn_image **out, const kpcn_image *in, double deg, int nthreads) {
  kpcn_image *o = nullptr;
  kpcn_status s =
      kpcn_image_create(&o, in->width, in->height, in->nchannels, (const char *const *)in->names);
  if (s != KPCN_OK) return s;
  s = kpcn_augment_rotate_any_planes(o->data, in->data, in->nchannels,
                                     (const char *const *)in->names, in->width, in->height, deg,
                                     nthreads);
  if (s != KPCN_OK) {
    kpcn_image_destroy(o);
    return s;
  }
  *out = o;
  return KPCN_OK;
}

// Converts the noisy image and, when given, the reference image. Only an empty ImageBuf is no
// reference: one naming a file that failed to open was taken as none, without a word. A
// reference must cover the noisy image's pixels (directory output cut misaligned patches).
bool to_aov_pair(const OIIO::ImageBuf &noisy, const OIIO::ImageBuf &ref, AovPtr &n, AovPtr &r,
                 std::string &err) {
  n = to_aov_set(noisy, err);
  if (!n) return false;
  if (ref.initialized() || ref.has_error() || !ref.name().empty()) {
    r = to_aov_set(ref, err);
    if (!r) return false;
    if (r->width != n->width || r->height != n->height || ref.xbegin() != noisy.xbegin() ||
        ref.ybegin() != noisy.ybegin()) {
      err = "reference " + std::to_string(r->width) + "x" + std::to_string(r->height) + " at (" +
            std::to_string(ref.xbegin()) + ", " + std::to_string(ref.ybegin()) + ") vs noisy " +
            std::to_string(n->width) + "x" + std::to_string(n->height) + " at (" +
            std::to_string(noisy.xbegin()) + ", " + std::to_string(noisy.ybegin()) +
            "): the images must cover the same pixels";
      return false;
    }
  }
  return true;
}

} // namespace

bool augment(OIIO::ImageBuf &dst, const OIIO::ImageBuf &src, const kpcn_augment_xform &x,
             int nthreads) {
  return apply(dst, src, &x, [&](kpcn_image **o, const kpcn_image *i) {
    return kpcn_augment_image(o, i, &x, nthreads);
  });
}
OIIO::ImageBuf augment(const OIIO::ImageBuf &src, const kpcn_augment_xform &x, int nthreads) {
  OIIO::ImageBuf d;
  augment(d, src, x, nthreads);
  return d;
}

bool mirror(OIIO::ImageBuf &dst, const OIIO::ImageBuf &src, bool vertical, int nthreads) {
  kpcn_augment_xform x;
  kpcn_augment_identity(&x);
  (vertical ? x.mirror_v : x.mirror_h) = 1;
  return augment(dst, src, x, nthreads);
}
OIIO::ImageBuf mirror(const OIIO::ImageBuf &src, bool vertical, int nthreads) {
  OIIO::ImageBuf d;
  mirror(d, src, vertical, nthreads);
  return d;
}

bool rotate(OIIO::ImageBuf &dst, const OIIO::ImageBuf &src, double degrees, int nthreads) {
  if (!std::isfinite(degrees)) {
    dst.errorfmt("rotate: angle {} is not finite", degrees);
    return false;
  }
  // reduced to [0, 360) first (fmod is exact): degrees / 90 lost the fraction of a large
  // angle (1e18 was taken as a quarter-turn multiple) and llround overflowed past 2^63
  double r = std::fmod(degrees, 360.0);
  if (r < 0.0) r += 360.0;
  const double q = r / 90.0;
  if (std::fabs(q - std::round(q)) < 1e-12) {
    kpcn_augment_xform x;
    kpcn_augment_identity(&x);
    x.rot90 = (int)std::lround(q) % 4;
    return augment(dst, src, x, nthreads);
  }
  return apply(dst, src, nullptr, [&](kpcn_image **o, const kpcn_image *i) {
    return rotate_any_image(o, i, r, nthreads); // reduced: 1e18's sin and cos are not 280's
  });
}
OIIO::ImageBuf rotate(const OIIO::ImageBuf &src, double degrees, int nthreads) {
  OIIO::ImageBuf d;
  rotate(d, src, degrees, nthreads);
  return d;
}

bool colorswap(OIIO::ImageBuf &dst, const OIIO::ImageBuf &src, const std::string &perm,
               int nthreads) {
  kpcn_augment_xform x;
  kpcn_augment_identity(&x);
  if (kpcn_augment_parse_perm(perm.c_str(), x.perm) != KPCN_OK) {
    dst.errorfmt("{}", kpcn_last_error());
    return false;
  }
  return augment(dst, src, x, nthreads);
}
OIIO::ImageBuf colorswap(const OIIO::ImageBuf &src, const std::string &perm, int nthreads) {
  OIIO::ImageBuf d;
  colorswap(d, src, perm, nthreads);
  return d;
}

bool shift(OIIO::ImageBuf &dst, const OIIO::ImageBuf &src, int dx, int dy, int nthreads) {
  kpcn_augment_xform x;
  kpcn_augment_identity(&x);
  x.dx = dx;
  x.dy = dy;
  return augment(dst, src, x, nthreads);
}
OIIO::ImageBuf shift(const OIIO::ImageBuf &src, int dx, int dy, int nthreads) {
  OIIO::ImageBuf d;
  shift(d, src, dx, dy, nthreads);
  return d;
}

bool select_patches(const OIIO::ImageBuf &noisy, const OIIO::ImageBuf &ref,
                    const kpcn_patch_settings &s, std::vector<kpcn_patch_origin> &out,
                    kpcn_patch_stats &stats, std::string &err) {
  AovPtr n, r;
  if (!to_aov_pair(noisy, ref, n, r, err)) return false;
  kpcn_patch_origin *o = nullptr;
  int cnt = 0;
  if (kpcn_patches_select(&o, &cnt, &stats, n.get(), r.get(), &s) != KPCN_OK) {
    err = kpcn_last_error();
    return false;
  }
  out.assign(o, o + cnt);
  std::free(o);
  return true;
}

bool write_patches(const std::string &out, const OIIO::ImageBuf &noisy, const OIIO::ImageBuf &ref,
                   const std::vector<kpcn_patch_origin> &origins, int size, std::string &err,
                   const kpcn_patch_stats *stats, const std::string &settings_json) {
  AovPtr n, r;
  if (!to_aov_pair(noisy, ref, n, r, err)) return false;
  bool kps = out.size() > 4 && out.compare(out.size() - 4, 4, ".kps") == 0;
  if (kps && !r) {
    err = "a patch store needs a reference image (its training target)";
    return false;
  }
  if (kps) {
    kpcn_patchstore_settings ss;
    kpcn_patchstore_settings_defaults(&ss);
    ss.patch_size = size;
    if (!settings_json.empty()) ss.settings_json = settings_json.c_str();
    kpcn_patchstore_writer *w = nullptr;
    if (kpcn_patchstore_create(&w, out.c_str(), &ss) != KPCN_OK) {
      err = kpcn_last_error();
      return false;
    }
    kpcn_patch_source src;
    std::memset(&src, 0, sizeof src);
    std::snprintf(src.scene, sizeof src.scene, "%.127s", n->scene);
    std::snprintf(src.noisy, sizeof src.noisy, "%s", noisy.name().c_str());
    std::snprintf(src.reference, sizeof src.reference, "%s", ref.name().c_str());
    src.spp = n->spp;
    src.ref_spp = r ? r->spp : -1;
    uint32_t sid = 0;
    if (kpcn_patch_source_image_stats(&src, n.get()) != KPCN_OK ||
        kpcn_patchstore_add_source(w, &src, &sid) != KPCN_OK) {
      err = kpcn_last_error();
      kpcn_patchstore_abort(w);
      return false;
    }
    if (stats) kpcn_patchstore_add_stats(w, stats->candidates, stats->kept, stats->culled);
    for (const auto &o : origins) {
      kpcn_patch_record rec = {sid, o.x, o.y, 0, o.flat_frac, o.weight, 0};
      if (kpcn_patchstore_append_aov(w, &rec, n.get(), r.get()) != KPCN_OK) {
        err = kpcn_last_error();
        kpcn_patchstore_abort(w);
        return false;
      }
    }
    if (kpcn_patchstore_finish(w) != KPCN_OK) {
      err = kpcn_last_error();
      return false;
    }
    return true;
  }
  if (mkdir(out.c_str(), 0777) != 0 && errno != EEXIST) {
    err = "cannot create directory '" + out + "': " + std::strerror(errno);
    return false;
  }
  for (size_t i = 0; i < origins.size(); i++) {
    for (int k = 0; k < (r ? 2 : 1); k++) {
      kpcn_aov_set *c = nullptr;
      const kpcn_aov_set *s = k ? r.get() : n.get();
      if (kpcn_augment_crop_aov(&c, s, origins[i].x, origins[i].y, size, size) != KPCN_OK) {
        err = kpcn_last_error();
        return false;
      }
      AovPtr cp(c);
      char name[64];
      std::snprintf(name, sizeof name, "/%s_%04zu.exr", k ? "ref" : "noisy", i);
      if (kpcn_exr_write_aov((out + name).c_str(), c, nullptr) != KPCN_OK) {
        err = kpcn_last_error();
        return false;
      }
    }
  }
  return true;
}

} // namespace ops
} // namespace kpcn
