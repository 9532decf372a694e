// Core kpcntool commands: -o, --threads, --json, --info, --ch, --ociodisplay, --colormap, --mosaic,
// plus the shared read_image / write_image helpers (see kpcntool.h, docs/kpcntool.md).
#include "cli_parse.h"
#include "kpcntool.h"

#include "kpcn/image.h"
#include "kpcn/oiio_convert.h"

#include <OpenImageIO/color.h>
#include <OpenImageIO/half.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imageio.h>
#include <OpenImageIO/strutil.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <sstream>
#include <sys/stat.h>
#include <unistd.h>

using OIIO::ImageBuf;
using OIIO::ImageSpec;
using OIIO::TypeDesc;
namespace IBA = OIIO::ImageBufAlgo;

namespace kpcntool {

bool read_image(ImageBuf &dst, const std::string &path, std::string &err) {
  const char *why = nullptr; // a FIFO or device would block or never end in OIIO's reader
  FILE *probe = kpcn_fopen_input(path.c_str(), &why);
  if (!probe) {
    err = "cannot open '" + path + "': " + why;
    return false;
  }
  std::fclose(probe);
  ImageBuf b(path);
  if (!b.init_spec(path, 0, 0)) {
    err = "cannot read '" + path + "': " + b.geterror();
    return false;
  }
  const ImageSpec &sp = b.spec();
  /* a deep image reads as a flat one here, and the operations then crashed inside OIIO */
  if (sp.deep) {
    err = "'" + path + "' is a deep image: deep images are not supported";
    return false;
  }
  /* the other parts of a multi-part EXR (a Blender multilayer file's passes) are not read:
   * say so, rather than a "missing buffer" later */
  if (b.nsubimages() > 1)
    std::fprintf(stderr,
                 "kpcntool: warning: '%s' holds %d parts (subimages); only the first, with %d "
                 "channels, is read (kpcn reads single-part files: merge the passes into one "
                 "part first)\n",
                 path.c_str(), b.nsubimages(), sp.nchannels);
  if (sp.width <= 0 || sp.height <= 0 || sp.depth != 1 || sp.nchannels <= 0 ||
      sp.width > KPCN_MAX_DIM || sp.height > KPCN_MAX_DIM ||
      (int64_t)sp.width * sp.height > KPCN_MAX_PIXELS) {
    err = "'" + path + "' has an unsupported or absurd size " + std::to_string(sp.width) + "x" +
          std::to_string(sp.height) + "x" + std::to_string(sp.depth) + " with " +
          std::to_string(sp.nchannels) + " channels";
    return false;
  }
  if (!b.read(0, 0, true, TypeDesc::FLOAT)) {
    err = "cannot read '" + path + "' (truncated or corrupt?): " + b.geterror();
    return false;
  }
  dst = std::move(b);
  return true;
}

namespace {

// "image 'file.exr'", or "the top image" for images computed in this run (they have no name).
std::string img_desc(const ImageBuf &b, const char *role = "the top image") {
  std::string n = std::string(b.name());
  return n.empty() ? std::string(role) : "image '" + n + "'";
}

bool cmd_output(Context &ctx, const Modifiers &, const std::vector<std::string> &a,
                std::string &err) {
  const std::string &path = a[0];
  const std::string ext = lower_ext(path); // a writable format: checked when parsed (main.cpp)
  if (!output_fits(ctx.top(), ext, err)) return false;
  const TypeDesc fmt = output_type(ctx, ctx.top(), ext);
  // A deep copy: later commands may change the top.
  auto img = std::make_shared<const ImageBuf>(ctx.top());
  ctx.outputs.push_back({"-o " + path, path, false,
                         [img, fmt](const std::string &tmp, std::string &e) {
                           return write_image(*img, tmp, fmt, e);
                         },
                         true});
  return true;
}

// -d TYPE: the pixel type of the following -o files (oiiotool's -d).
bool cmd_datatype(Context &ctx, const Modifiers &, const std::vector<std::string> &a,
                  std::string &err) {
  static const std::pair<const char *, TypeDesc> types[] = {{"uint8", TypeDesc::UINT8},
                                                            {"uint16", TypeDesc::UINT16},
                                                            {"half", TypeDesc::HALF},
                                                            {"float", TypeDesc::FLOAT}};
  for (const auto &t : types)
    if (a[0] == t.first) {
      ctx.output_type = t.second;
      return true;
    }
  err = "pixel type '" + printable(a[0]) + "' is not one of uint8, uint16, half, float";
  return false;
}

bool cmd_threads(Context &ctx, const Modifiers &, const std::vector<std::string> &a,
                 std::string &err) {
  int n;
  if (!cli_parse_int(a[0].c_str(), 0, KPCN_MAX_THREADS, &n)) {
    err = "thread count must be an integer in [0, " + std::to_string(KPCN_MAX_THREADS) +
          "] (got '" + a[0] + "')";
    return false;
  }
  ctx.nthreads = (int)n;
  OIIO::attribute("threads", (int)n);
  return true;
}

bool cmd_json(Context &ctx, const Modifiers &, const std::vector<std::string> &, std::string &) {
  ctx.json = true;
  return true;
}

std::string quote(const std::string &s) {
  std::string o = "\"";
  for (char c : printable(s)) {
    if (c == '"' || c == '\\') o += '\\';
    o += c;
  }
  return o + "\"";
}

// Element i of a numeric attribute (ParamValue's get_*_indexed do not read vector aggregates).
double attr_element(const OIIO::ParamValue &p, int i) {
  const void *d = p.data();
  switch (p.type().basetype) {
  case TypeDesc::UINT8: return ((const uint8_t *)d)[i];
  case TypeDesc::INT8: return ((const int8_t *)d)[i];
  case TypeDesc::UINT16: return ((const uint16_t *)d)[i];
  case TypeDesc::INT16: return ((const int16_t *)d)[i];
  case TypeDesc::UINT32: return ((const uint32_t *)d)[i];
  case TypeDesc::INT32: return ((const int32_t *)d)[i];
  case TypeDesc::UINT64: return (double)((const uint64_t *)d)[i];
  case TypeDesc::INT64: return (double)((const int64_t *)d)[i];
  case TypeDesc::HALF: return ((const half *)d)[i];
  case TypeDesc::FLOAT: return ((const float *)d)[i];
  case TypeDesc::DOUBLE: return ((const double *)d)[i];
  default: return NAN;
  }
}

// An attribute as JSON: a number, an array of numbers (non-finite ones null), else a string.
std::string json_value(const OIIO::ParamValue &p) {
  const TypeDesc t = p.type();
  const bool numeric = t.basetype >= TypeDesc::UINT8 && t.basetype <= TypeDesc::DOUBLE;
  if (!numeric) return quote(p.get_string());
  const int n = p.nvalues() * (int)t.numelements() * (int)t.aggregate;
  std::ostringstream o;
  o.precision(17);
  for (int i = 0; i < n; ++i) {
    const double v = attr_element(p, i);
    o << (i ? ", " : "");
    if (std::isfinite(v))
      o << v;
    else
      o << "null";
  }
  return n == 1 ? o.str() : "[" + o.str() + "]";
}

bool cmd_info(Context &ctx, const Modifiers &, const std::vector<std::string> &, std::string &) {
  const ImageBuf &b = ctx.top();
  const ImageSpec &sp = b.spec();
  std::vector<std::string> names;
  std::vector<const char *> cn;
  for (int c = 0; c < sp.nchannels; ++c)
    names.push_back(std::string(sp.channel_name(c)));
  for (auto &n : names)
    cn.push_back(n.c_str());
  int chan[KPCN_BUF_COUNT][3], var[KPCN_BUF_COUNT];
  std::string aov_error;
  if (kpcn_aov_map_channels(cn.data(), (int)cn.size(), chan, var, std::string(b.name()).c_str()) !=
      KPCN_OK)
    aov_error = kpcn_last_error();
  std::ostringstream txt, js;
  std::string chlist;
  for (auto &n : names)
    chlist += (chlist.empty() ? "" : ",") + n;
  txt << (b.name().empty() ? std::string("(top image)") : std::string(b.name())) << ": " << sp.width
      << "x" << sp.height << ", " << sp.nchannels << " channels (" << chlist << "), "
      << b.nativespec().format.c_str() << "\n";
  js << "{\"file\": " << quote(std::string(b.name())) << ", \"width\": " << sp.width
     << ", \"height\": " << sp.height << ", \"channels\": [";
  for (size_t i = 0; i < names.size(); ++i)
    js << (i ? ", " : "") << quote(names[i]);
  js << "], \"buffers\": {";
  bool first = true;
  for (int bi = 0; bi < KPCN_BUF_COUNT && aov_error.empty(); ++bi) {
    kpcn_buffer buf = (kpcn_buffer)bi;
    if (chan[bi][0] < 0) continue;
    std::string src;
    for (int c = 0; c < kpcn_buffer_channels(buf); ++c)
      src += (c ? "," : "") + names[chan[bi][c]];
    std::string vs = var[bi] >= 0 ? names[var[bi]] : "";
    txt << "  buffer " << kpcn_buffer_name(buf) << ": " << src
        << (vs.empty() ? "" : "  variance: " + vs) << "\n";
    js << (first ? "" : ", ") << quote(kpcn_buffer_name(buf)) << ": {\"channels\": " << quote(src)
       << ", \"variance\": " << (vs.empty() ? "null" : quote(vs)) << "}";
    first = false;
  }
  js << "}";
  if (!aov_error.empty()) {
    txt << "  AOV buffers: " << aov_error << "\n";
    js << ", \"aov_error\": " << quote(aov_error);
  }
  for (const char *attr : {"kpcn:spp", "kpcn:albedoSpp", "kpcn:albedoFootprint", "kpcn:seed",
                           "kpcn:scene", "kpcn:version"}) {
    const OIIO::ParamValue *p = sp.find_attribute(attr);
    if (!p) continue;
    txt << "  " << attr << ": " << p->get_string() << "\n";
    js << ", " << quote(attr) << ": " << json_value(*p);
  }
  js << "}";
  if (ctx.json)
    ctx.add_json_item("info", js.str());
  else
    std::fputs(printable(txt.str(), true).c_str(), stdout);
  return true;
}

// --ch R,G,B | R=albedo.R,G=albedo.G,B=albedo.B | A=1.0 (like oiiotool's --ch).
bool cmd_ch(Context &ctx, const Modifiers &, const std::vector<std::string> &a, std::string &err) {
  const ImageBuf &src = ctx.top();
  std::vector<std::string> items = kpcn::ops::split_names(a[0]);
  if (items.empty()) {
    err = "empty channel list";
    return false;
  }
  std::vector<int> order;
  std::vector<float> values;
  std::vector<std::string> names;
  for (auto &item : items) {
    // as oiiotool: blanks around an item are not part of it ("R, G, B")
    const std::string it = std::string(OIIO::Strutil::strip(item, " \t"));
    size_t eq = it.find('=');
    std::string newname = it.substr(0, eq), from = eq == std::string::npos ? it : it.substr(eq + 1);
    double d = 0;
    const bool number = cli_parse_double(from.c_str(), &d); // decimal and finite only
    // after '=' a number is a constant, as in oiiotool, even where a channel has that name
    int idx = eq != std::string::npos && number ? -1 : src.spec().channelindex(from);
    float v = 0.f;
    // as oiiotool: a bare number that names no channel is a channel index ("0,1,2"); after
    // '=' it is a constant ("A=1")
    if (idx < 0 && eq == std::string::npos &&
        cli_parse_int(from.c_str(), 0, src.nchannels() - 1, &idx))
      newname = src.spec().channel_name(idx);
    else if (idx < 0 && eq == std::string::npos && !from.empty() &&
             from.find_first_not_of("0123456789") == std::string::npos) {
      err = img_desc(src) + " has no channel '" + from + "' (channel indices are 0 to " +
            std::to_string(src.nchannels() - 1) + ")";
      return false;
    }
    if (idx < 0) {
      char *end = nullptr;
      std::strtof(from.c_str(), &end); // what strtof reads as a number: " 1", hex, inf, nan
      if (eq == std::string::npos || (!number && (end == from.c_str() || *end))) {
        err = img_desc(src) + " has no channel '" + from + "'";
        return false;
      }
      v = (float)d;
      if (!number || !std::isfinite(v)) {
        err =
            "channel '" + newname + "': the constant '" + from + "' is not a finite decimal float";
        return false;
      }
    }
    if (newname.empty() || std::find(names.begin(), names.end(), newname) != names.end()) {
      err = newname.empty() ? "an empty channel name in '" + a[0] + "'"
                            : "channel name '" + newname + "' appears twice";
      return false;
    }
    order.push_back(idx);
    values.push_back(v);
    names.push_back(newname);
  }
  ImageBuf dst;
  if (!IBA::channels(dst, src, (int)order.size(), order, values, names, false, ctx.nthreads)) {
    err = dst.geterror();
    return false;
  }
  ctx.pop();
  ctx.push(std::move(dst));
  return true;
}

// $OCIO; else the config installed next to this executable (<bin>/../share/kpcn/ocio: an
// install moved or made with `cmake --install --prefix` elsewhere); else the source tree's
// (a build-tree kpcntool); else the configured install path.
std::string default_ocio_config() {
  const char *env = std::getenv("OCIO");
  if (env && *env) return env;
  struct stat st;
  char exe[4096];
  ssize_t n = readlink("/proc/self/exe", exe, sizeof exe - 1);
  if (n > 0) {
    exe[n] = '\0';
    std::string dir(exe);
    dir.erase(dir.find_last_of('/') + 1);
    std::string installed = dir + "../share/kpcn/ocio/config.ocio";
    if (stat(installed.c_str(), &st) == 0) return installed;
  }
  if (stat(KPCN_DEFAULT_OCIO, &st) == 0) return KPCN_DEFAULT_OCIO;
  return KPCN_INSTALLED_OCIO;
}

// The colour space the display transform starts from: from= when given; else the image's own
// (its oiio:ColorSpace, which OIIO's readers set: "sRGB" for an 8-bit PNG, "Linear" for EXR),
// as oiiotool does, with "Linear" meaning the config's scene_linear; scene_linear when the image
// names none. A space the config does not know is an error naming it and from=.
bool display_source_space(const OIIO::ColorConfig &cc, const std::string &path, const Modifiers &m,
                          const ImageBuf &img, std::string &from, std::string &err) {
  if (m.has("from")) {
    from = m.str("from");
    return true;
  }
  from = std::string(img.spec().get_string_attribute("oiio:ColorSpace"));
  if (from.empty() || OIIO::Strutil::iequals(from, "linear")) {
    from = "scene_linear";
    return true;
  }
  auto known = [&](const std::string &n) { return OIIO::Strutil::iequals(n, from); };
  for (const std::string &cs : cc.getColorSpaceNames()) {
    std::vector<std::string> names = cc.getAliases(cs);
    names.push_back(cs);
    if (std::any_of(names.begin(), names.end(), known)) return true;
  }
  for (const std::string &role : cc.getRoles())
    if (known(role)) return true;
  err = img_desc(img) + " is tagged as colour space '" + printable(from) +
        "' (oiio:ColorSpace), which OCIO config '" + path +
        "' does not define: give :from= the space its values are in";
  return false;
}

bool cmd_ociodisplay(Context &ctx, const Modifiers &m, const std::vector<std::string> &,
                     std::string &err) {
  std::string path = m.str("config", default_ocio_config());
  struct stat st;
  if (stat(path.c_str(), &st) != 0) {
    err = "OCIO config '" + path + "' not found";
    return false;
  }
  // One ColorConfig per path for the process: building processors is the expensive part.
  static std::map<std::string, std::unique_ptr<OIIO::ColorConfig>> configs;
  auto &cc = configs[path];
  if (!cc) cc.reset(new OIIO::ColorConfig(path));
  if (cc->has_error()) {
    err = "OCIO config '" + path + "': " + cc->geterror();
    cc.reset();
    return false;
  }
  std::string display = m.str("display", cc->getDefaultDisplayName());
  bool found = false;
  for (int i = 0; i < cc->getNumDisplays(); ++i)
    found = found || display == cc->getDisplayNameByIndex(i);
  if (!found) {
    err = "display '" + display + "' is not in OCIO config '" + path + "'";
    return false;
  }
  std::string view = m.str("view", cc->getDefaultViewName(display));
  found = false;
  for (int i = 0; i < cc->getNumViews(display); ++i)
    found = found || view == cc->getViewNameByIndex(display, i);
  if (!found) {
    err = "view '" + view + "' of display '" + display + "' is not in OCIO config '" + path + "'";
    return false;
  }
  // OIIO 2.4 ignores a look the config does not define; name it instead. Blanks around a
  // name are not part of it ("A, B"), as in oiiotool.
  std::string looks;
  for (std::string item : kpcn::ops::split_names(m.str("looks"))) {
    item = std::string(OIIO::Strutil::strip(item, " \t"));
    looks += (looks.empty() ? "" : ",") + item;
    std::string look = item;
    if (!look.empty() && (look[0] == '+' || look[0] == '-')) look.erase(0, 1);
    found = false;
    for (int i = 0; i < cc->getNumLooks(); ++i)
      found = found || look == cc->getLookNameByIndex(i);
    if (!found) {
      err = "look '" + look + "' is not in OCIO config '" + path + "'" +
            (cc->getNumLooks() ? "" : " (it defines no looks)");
      return false;
    }
  }
  ImageBuf src = ctx.top();
  // AOV images (any channel other than R, G, B, A: metrics.md's rule) and images whose colour
  // channels are out of order: the colour only, R,G,B and A when present. Fewer than three
  // channels go to OCIO as they are.
  bool reduce = src.spec().channelindex("R") > 0;
  for (int c = 0; c < src.nchannels() && src.nchannels() >= 3; ++c) {
    const std::string &n = src.spec().channelnames[(size_t)c];
    reduce = reduce || (n != "R" && n != "G" && n != "B" && n != "A");
  }
  if (reduce) {
    std::vector<int> order;
    for (const char *c : {"R", "G", "B", "A"}) {
      int i = src.spec().channelindex(c);
      if (i >= 0) order.push_back(i);
    }
    if (order.size() < 3) {
      err = img_desc(src) + " has " + std::to_string(src.nchannels()) +
            " channels but no R,G,B to display (use --ch)";
      return false;
    }
    ImageBuf rgb;
    if (!IBA::channels(rgb, src, (int)order.size(), order, {}, {}, true, ctx.nthreads)) {
      err = rgb.geterror();
      return false;
    }
    src = std::move(rgb);
  } else if (src.nchannels() < 3) {
    err = img_desc(src) + " has " + std::to_string(src.nchannels()) +
          " channel(s); the display transform needs R,G,B";
    return false;
  }
  std::string from;
  if (!display_source_space(*cc, path, m, src, from, err)) return false;
  // OIIO 2.4's ociodisplay ignores its looks argument, so the looks are applied first, in the
  // source space (as `oiiotool --ociolook:from=S:to=S L --ociodisplay` does).
  if (!looks.empty()) {
    ImageBuf looked;
    if (!IBA::ociolook(looked, src, looks, from, from, false, false, "", "", cc.get(), {},
                       ctx.nthreads)) {
      err = "looks '" + looks + "': " + looked.geterror();
      return false;
    }
    src = std::move(looked);
  }
  ImageBuf dst;
  if (!IBA::ociodisplay(dst, src, display, view, from, "", false, "", "", cc.get(), {},
                        ctx.nthreads)) {
    err = dst.geterror();
    return false;
  }
  dst.specmod().attribute("oiio:ColorSpace", display);
  ctx.pop();
  ctx.push(std::move(dst));
  return true;
}

// False-colour display of a scalar image (an error map): the per-pixel mean of the channels,
// divided by max (default: its 99th percentile over the finite pixels) and clamped to [0, 1],
// through OIIO's colour map. The result is display-referred RGB: write it as is, do not pass
// it through --ociodisplay. Non-finite pixels map to 0.
bool cmd_colormap(Context &ctx, const Modifiers &m, const std::vector<std::string> &,
                  std::string &err) {
  const ImageBuf &src = ctx.top();
  const int nch = src.nchannels();
  ImageBuf mean =
      IBA::channel_sum(src, std::vector<float>((size_t)nch, 1.0f / nch), {}, ctx.nthreads);
  std::vector<float> finite(mean.spec().image_pixels());
  if (mean.has_error() || !mean.get_pixels(mean.roi(), TypeDesc::FLOAT, finite.data())) {
    err = mean.geterror();
    return false;
  }
  finite.erase(
      std::remove_if(finite.begin(), finite.end(), [](float v) { return !std::isfinite(v); }),
      finite.end());
  IBA::fixNonFinite(mean, mean, IBA::NONFINITE_BLACK, nullptr, {}, ctx.nthreads);
  // absent: the 99th percentile (an empty max= is a bad value, not the default)
  const bool auto_max = !m.has("max");
  double mx = auto_max ? 0.0 : m.num("max", 0.0);
  if (auto_max && !finite.empty()) {
    size_t k = (size_t)std::floor(0.99 * (double)(finite.size() - 1));
    std::nth_element(finite.begin(), finite.begin() + (long)k, finite.end());
    mx = finite[k];
  }
  if (auto_max && finite.empty()) {
    err = "every pixel of the image is NaN or Inf: nothing to scale the map by";
    return false;
  }
  if (!(mx > 0.0) || !std::isfinite(mx)) {
    err = auto_max
              ? "the image's 99th percentile is " + std::to_string(mx) + ": give a positive :max="
              : "modifier 'max' must be positive (got '" + m.str("max") + "')";
    return false;
  }
  ImageBuf scaled;
  if (!IBA::mul(scaled, mean, (float)(1.0 / mx), {}, ctx.nthreads) ||
      !IBA::clamp(scaled, scaled, 0.0f, 1.0f, false, {}, ctx.nthreads)) {
    err = scaled.geterror();
    return false;
  }
  std::string map = m.str("map", "inferno");
  ImageBuf dst = IBA::color_map(scaled, 0, map, {}, ctx.nthreads);
  if (dst.has_error()) {
    err = "colour map '" + map + "': " + dst.geterror();
    return false;
  }
  dst.specmod().attribute("oiio:ColorSpace", "sRGB");
  ctx.pop();
  ctx.push(std::move(dst));
  return true;
}

bool cmd_mosaic(Context &ctx, const Modifiers &m, const std::vector<std::string> &,
                std::string &err) {
  std::vector<std::string> labels = kpcn::ops::split_names(m.str("labels"));
  long n = m.integer("n", labels.empty() ? 2 : (long)labels.size());
  if (n < 1 || n > (long)ctx.stack.size()) {
    err = "n=" + std::to_string(n) + " but the stack holds " + std::to_string(ctx.stack.size()) +
          " image(s)";
    return false;
  }
  if (!labels.empty() && (long)labels.size() != n) {
    err = std::to_string(labels.size()) + " labels for " + std::to_string(n) + " images";
    return false;
  }
  size_t base = ctx.stack.size() - (size_t)n; // left to right = bottom to top
  // Each tile is its image's whole frame (display window): an image whose pixels cover part
  // of it (a --render crop) is padded with black, as oiiotool's --mosaic does.
  std::vector<ImageBuf> tiles((size_t)n);
  for (long i = 0; i < n; ++i) {
    ImageBuf &t = tiles[(size_t)i];
    if (!whole_frame(ctx.stack[base + i], t, ctx.nthreads, err)) {
      err = "image " + std::to_string(i + 1) + " (" + img_desc(ctx.stack[base + i], "computed") +
            "): " + err;
      return false;
    }
    // OIIO 2.4's paste ignores the source's origin: a frame not at 0,0 pasted black
    t.set_origin(0, 0);
    t.set_full(0, t.spec().width, 0, t.spec().height, 0, 1);
  }
  int nch = tiles[0].nchannels(), W = 0, H = 0;
  for (long i = 0; i < n; ++i) {
    const ImageBuf &b = tiles[(size_t)i];
    if (b.nchannels() != nch) {
      err = "image " + std::to_string(i + 1) + " (" + img_desc(ctx.stack[base + i], "computed") +
            ") has " + std::to_string(b.nchannels()) + " channels, image 1 has " +
            std::to_string(nch);
      return false;
    }
    W += b.spec().width;
    H = std::max(H, b.spec().height);
  }
  ImageSpec spec(W, H, nch, TypeDesc::FLOAT);
  spec.channelnames = ctx.stack[base].spec().channelnames;
  ImageBuf dst(spec);
  IBA::zero(dst);
  int x = 0;
  long fontsize = m.integer("fontsize", 16);
  if (fontsize < 1 || fontsize > 1000) {
    err = "fontsize=" + std::to_string(fontsize) + " is outside [1, 1000]";
    return false;
  }
  std::string font = m.str("font", "DejaVuSans");
  std::vector<float> white((size_t)nch, 1.0f);
  bool warned = false;
  for (long i = 0; i < n; ++i) {
    const ImageBuf &b = tiles[(size_t)i];
    if (!IBA::paste(dst, x, 0, 0, 0, b)) {
      err = dst.geterror();
      return false;
    }
    /* OIIO 2.4's render_text asserts (aborts) when the text's origin lies outside the image,
     * so a label that cannot start inside its tile is not drawn */
    if (!labels.empty() && !warned && (b.spec().width <= 4 || 4 + fontsize > b.spec().height)) {
      std::fprintf(stderr,
                   "kpcntool: warning: --mosaic: labels not drawn (fontsize %ld does not fit "
                   "a %dx%d tile)\n",
                   fontsize, b.spec().width, b.spec().height);
      warned = true;
    }
    if (!labels.empty() && !warned &&
        !IBA::render_text(dst, x + 4, 4 + (int)fontsize, labels[i], (int)fontsize, font, white,
                          IBA::TextAlignX::Left, IBA::TextAlignY::Baseline, 1)) {
      std::fprintf(stderr, "kpcntool: warning: --mosaic: labels not drawn (%s)\n",
                   dst.geterror().c_str());
      warned = true;
    }
    /* the next tile is pasted over whatever runs past this one: say so, not a silent "nlmea" */
    const OIIO::ROI ts =
        labels.empty() || warned ? OIIO::ROI() : IBA::text_size(labels[i], (int)fontsize, font);
    if (ts.defined() && 4 + ts.width() > b.spec().width)
      std::fprintf(stderr,
                   "kpcntool: warning: --mosaic: label '%s' needs %d px at fontsize %ld, its "
                   "%d-px tile has %d: it is cut off (lower fontsize)\n",
                   labels[i].c_str(), ts.width(), fontsize, b.spec().width, b.spec().width - 4);
    x += b.spec().width;
  }
  ctx.stack.resize(base);
  ctx.push(std::move(dst));
  return true;
}

bool r1 = register_command({"o",
                            1,
                            {},
                            "queue the top image for writing to a file (the input files' pixel "
                            "type or -d's; written atomically after all commands succeed)",
                            cmd_output});
bool r1d = register_command({"d",
                             1,
                             {},
                             "pixel type of the following -o files: uint8|uint16|half|float "
                             "(default: the widest input file's, as far as the format holds it)",
                             cmd_datatype});
bool r2 = register_command(
    {"threads", 1, {}, "threads for the following commands (0 = all)", cmd_threads});
bool r3 = register_command({"json", 0, {}, "print results as one JSON object", cmd_json});
bool r4 = register_command({"info",
                            0,
                            {},
                            "describe the top image: size, channels, AOV "
                            "buffers, kpcn:* attributes",
                            cmd_info});
bool r5 = register_command({"ch",
                            1,
                            {},
                            "select/rename channels of the top image: R,G,B or "
                            "R=albedo.R,... or A=1",
                            cmd_ch});
bool r6 = register_command({"ociodisplay",
                            0,
                            {"display", "view", "config", "from", "looks"},
                            "OCIO display transform of the top image (default config: "
                            "$OCIO or testdata/ocio/config.ocio)",
                            cmd_ociodisplay});
bool r7b =
    register_command({"colormap",
                      0,
                      {"map", "max"},
                      "false-colour display of the top image's channel mean / max "
                      "(map=inferno|viridis|magma|plasma|turbo|heat|..., max=99th percentile)",
                      cmd_colormap});
bool r7 = register_command({"mosaic",
                            0,
                            {"n", "labels", "font", "fontsize"},
                            "pop n images, push them side by side (left = deepest), with labels",
                            cmd_mosaic});

} // namespace
} // namespace kpcntool
