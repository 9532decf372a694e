// kpcntool's outputs: image writing and the all-or-nothing commit of every file a command line
// produces (`-o`, `--patches:out=`), see kpcntool.h.
#include "kpcntool.h"

#include "kpcn/common.h"

#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cctype>
#include <csignal>
#include <cstdio>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <sys/statvfs.h>
#include <system_error>
#include <unistd.h>

namespace fs = std::filesystem;

namespace kpcntool {

// The extension as written ("PNG" for "a/b.PNG"), "" when the file name has none.
static std::string raw_ext(const std::string &path) {
  size_t dot = path.find_last_of('.');
  size_t slash = path.find_last_of('/');
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
  return path.substr(dot + 1);
}

std::string lower_ext(const std::string &path) {
  std::string e = raw_ext(path);
  for (char &c : e)
    c = (char)std::tolower((unsigned char)c);
  return e;
}

bool output_format_ok(const std::string &path, std::string &err) {
  const std::string ext = lower_ext(path);
  if (ext.empty()) {
    err = "'" + path + "' has no file extension to choose the format from";
    return false;
  }
  if (!OIIO::ImageOutput::create(path)) {
    OIIO::geterror(); // consumed: the message below says it
    err = "no image format writes '." + ext + "' files ('" + path + "')";
    return false;
  }
  return true;
}

// 1 uint8, 2 uint16, 3 half, 4 float (and the other wide types): how wide a type is.
static int type_rank(OIIO::TypeDesc t) {
  switch (t.basetype) {
  case OIIO::TypeDesc::UNKNOWN: return 0;
  case OIIO::TypeDesc::UINT8:
  case OIIO::TypeDesc::INT8: return 1;
  case OIIO::TypeDesc::UINT16:
  case OIIO::TypeDesc::INT16: return 2;
  case OIIO::TypeDesc::HALF: return 3;
  default: return 4;
  }
}

void note_input_type(Context &ctx, OIIO::TypeDesc file_type) {
  if (type_rank(file_type) > type_rank(ctx.input_type)) ctx.input_type = file_type;
}

static bool is_any_of(const std::string &ext, std::initializer_list<const char *> list) {
  return std::any_of(list.begin(), list.end(), [&](const char *e) { return ext == e; });
}

OIIO::TypeDesc output_type(const Context &ctx, const OIIO::ImageBuf &img, const std::string &ext) {
  if (ctx.output_type != OIIO::TypeDesc::UNKNOWN) return ctx.output_type;
  // as oiiotool: an image as read keeps its file's type, a computed one the inputs' (widest)
  const OIIO::TypeDesc t = img.name().empty() ? ctx.input_type : img.nativespec().format;
  const int r = type_rank(t);
  if (is_any_of(ext, {"png", "jpg", "jpeg", "jpe", "jfif", "bmp", "tga", "ppm", "pgm", "pnm", "pbm",
                      "gif", "ico", "webp"}))
    return r == 2 && is_any_of(ext, {"png", "ppm", "pgm", "pnm"}) ? OIIO::TypeDesc::UINT16
                                                                  : OIIO::TypeDesc::UINT8;
  static const OIIO::TypeDesc by_rank[] = {OIIO::TypeDesc::FLOAT, OIIO::TypeDesc::UINT8,
                                           OIIO::TypeDesc::UINT16, OIIO::TypeDesc::HALF,
                                           OIIO::TypeDesc::FLOAT};
  return by_rank[r];
}

// The frame limits whole_frame applies, without filling anything.
static bool frame_fits(const OIIO::ImageBuf &img, std::string &err) {
  const OIIO::ROI full = img.roi_full();
  const std::string what = "its display window is " + std::to_string(full.width()) + "x" +
                           std::to_string(full.height()) + " (its pixels " +
                           std::to_string(img.spec().width) + "x" +
                           std::to_string(img.spec().height) + "), too large to fill";
  if (full.width() > KPCN_MAX_DIM || full.height() > KPCN_MAX_DIM ||
      (int64_t)full.width() * full.height() > KPCN_MAX_PIXELS) {
    err = what + " (limit " + std::to_string(KPCN_MAX_DIM) + " per side, " +
          std::to_string(KPCN_MAX_PIXELS) + " pixels)";
    return false;
  }
  // the filled frame is float, as every image here; with the image itself and OIIO's copy for
  // writing, three of them must fit in what the machine has available
  const double bytes = (double)full.width() * full.height() * img.nchannels() * sizeof(float);
  const uint64_t avail = kpcn_available_memory();
  if (avail && 3.0 * bytes > (double)avail) {
    char b[160];
    std::snprintf(b, sizeof b,
                  " (%.1f GB of %d channels, with the copies made to write it more "
                  "than the %.1f GB available)",
                  bytes * 1e-9, img.nchannels(), (double)avail * 1e-9);
    err = what + b;
    return false;
  }
  return true;
}

bool output_fits(const OIIO::ImageBuf &img, const std::string &ext, std::string &err) {
  auto out = OIIO::ImageOutput::create("x." + ext);
  if (!out) {
    OIIO::geterror();
    return true; // not a writable format: output_format_ok said so when the line was parsed
  }
  // OIIO 2.4's DPX writer claims any channel count but aborts on 2 or more than 4
  if (ext == "dpx" && (img.nchannels() == 2 || img.nchannels() > 4)) {
    err = "the image has " + std::to_string(img.nchannels()) +
          " channels and .dpx files hold 1, 3 or 4: select them first (--ch R,G,B)";
    return false;
  }
  if (img.nchannels() > 4 && !out->supports("nchannels")) {
    err = "the image has " + std::to_string(img.nchannels()) + " channels and ." + ext +
          " files hold at most 4: select them first (--ch R,G,B)";
    return false;
  }
  if (out->supports("displaywindow") || img.roi() == img.roi_full() || frame_fits(img, err))
    return true;
  err += ": ." + ext + " files have no display window; write EXR, which keeps both windows";
  return false;
}

bool whole_frame(const OIIO::ImageBuf &img, OIIO::ImageBuf &out, int nthreads, std::string &err) {
  const OIIO::ROI full = img.roi_full();
  if (img.roi() == full) {
    out = img;
    return true;
  }
  // a header's display window can be far larger than its pixels (OIIO aborts when the padded
  // buffer cannot be allocated): the same size limits as any image read
  if (!frame_fits(img, err)) return false;
  out = OIIO::ImageBufAlgo::crop(img, full, nthreads);
  if (out.has_error()) {
    err = out.geterror();
    return false;
  }
  return true;
}

// A 16-bit binary PNM (P5 grey, P6 RGB: the header, then big-endian samples). OIIO 2.4's PNM
// writer takes its depth from oiio:BitsPerSample (8 when absent) rather than the pixel type,
// and given 16 it writes garbled samples (as oiiotool -d uint16 -o x.ppm does), so 16-bit PNM
// is written here; OIIO's PNM reader reads it back exactly (tested).
static bool write_pnm16(const OIIO::ImageBuf &w, const std::string &file, std::string &err) {
  const OIIO::ROI r = w.roi();
  const size_t n = (size_t)r.width() * (size_t)r.height() * (size_t)w.nchannels();
  std::vector<float> px(n);
  if (!w.get_pixels(r, OIIO::TypeDesc::FLOAT, px.data())) {
    err = w.geterror();
    return false;
  }
  // rounded to nearest, as OIIO's writers convert (its get_pixels to UINT16 truncated some
  // values a step low); NaN as 0
  std::vector<unsigned char> be(2 * n);
  for (size_t i = 0; i < n; ++i) {
    const float v = px[i] > 0.0f ? (px[i] < 1.0f ? px[i] : 1.0f) : 0.0f;
    const unsigned q = (unsigned)(v * 65535.0f + 0.5f);
    be[2 * i] = (unsigned char)(q >> 8), be[2 * i + 1] = (unsigned char)(q & 0xff);
  }
  FILE *f = std::fopen(file.c_str(), "wb");
  if (!f) {
    err = std::string("cannot create it: ") + std::strerror(errno);
    return false;
  }
  bool ok = std::fprintf(f, "P%c\n%d %d\n65535\n", w.nchannels() == 1 ? '5' : '6', r.width(),
                         r.height()) > 0 &&
            std::fwrite(be.data(), 1, be.size(), f) == be.size();
  const int e = ok ? 0 : errno;
  if (std::fclose(f) != 0 && ok) ok = false;
  if (!ok) err = std::string("writing it failed: ") + std::strerror(e ? e : errno);
  return ok;
}

bool write_image(const OIIO::ImageBuf &img, const std::string &file, OIIO::TypeDesc fmt,
                 std::string &err) {
  auto out = OIIO::ImageOutput::create(file);
  if (!out) {
    err = OIIO::geterror();
    return false;
  }
  OIIO::ImageBuf framed; // only where filled: a copy of img would double its memory
  const bool fill = !out->supports("displaywindow") && img.roi() != img.roi_full();
  if (fill && !whole_frame(img, framed, 0, err)) return false;
  const OIIO::ImageBuf &w = fill ? framed : img;
  if (fmt == OIIO::TypeDesc::UINT16 && is_any_of(lower_ext(file), {"ppm", "pgm", "pnm"}) &&
      (w.nchannels() == 1 || w.nchannels() == 3))
    return write_pnm16(w, file, err);
  if (!w.write(file, fmt)) {
    err = w.geterror();
    if (err.empty()) err = "the image writer failed";
    return false;
  }
  return true;
}

// The output's path without trailing slashes ("patches/" names the directory "patches"; only
// "/" itself keeps its slash), so its temporary path lies next to it, never inside it.
static std::string bare_path(const Context::Output &o) {
  std::string p = o.path;
  while (p.size() > 1 && p.back() == '/')
    p.pop_back();
  return p;
}

// Next to the output, unique per output (the same path may be queued twice: the later wins, as
// if written in turn) and keeping the extension, by which image writers and --patches choose
// the format.
// A file output that is a symbolic link is written through (its target replaced), as
// libkpcn's writers do. A name near the file-name limit gets a short hidden temporary
// (".kpcn.tmpPID_I.ext") in the same folder.
static std::string target_path(const Context::Output &o) {
  std::error_code ec;
  const std::string p = bare_path(o);
  if (!o.is_dir && fs::is_symlink(p, ec)) {
    fs::path t = fs::canonical(p, ec);
    if (!ec) return t.string();
  }
  return p;
}

static std::string temp_path(const Context::Output &o, size_t index) {
  const std::string p = target_path(o);
  std::string t = ".tmp" + std::to_string((long)getpid()) + "_" + std::to_string(index);
  std::string e = raw_ext(o.path);
  if (!o.is_dir && !e.empty()) t += "." + e;
  const size_t slash = p.find_last_of('/');
  const size_t base = slash == std::string::npos ? p.size() : p.size() - slash - 1;
  if (base + t.size() > 255) // NAME_MAX
    return p.substr(0, slash == std::string::npos ? 0 : slash + 1) + ".kpcn" + t;
  return p + t;
}

// Some image writers report no error when the disk fills: OIIO 2.4's PNG writer closes a
// truncated file with success, its BMP and FITS writers (which seek) leave holes where the
// writes failed, and its IFF reader reads a truncated file back as black without a word. A
// write that ran out of space leaves the file system with no free block (the kernel writes
// what fits), so an image after which none is left (for this user: root may use the reserved
// blocks) is refused as possibly incomplete; then every image other than EXR (whose writer
// reports it) is also read back whole, 64 rows (or a band of tiles) at a time.
static bool verify_written(const std::string &file, std::string &err) {
  struct statvfs vs;
  if (statvfs(file.c_str(), &vs) == 0 && (geteuid() == 0 ? vs.f_bfree : vs.f_bavail) == 0) {
    err = "the disk is full after writing it (no free block left), so it may be incomplete";
    return false;
  }
  if (lower_ext(file) == "exr") return true;
  auto in = OIIO::ImageInput::open(file);
  if (!in) {
    err = "the written file cannot be read back (disk full?): " + OIIO::geterror();
    return false;
  }
  const OIIO::ImageSpec &sp = in->spec();
  // a tiled file (IFF always is) is read by whole tile rows: OIIO 2.4's read_scanlines
  // divides by zero on some tiled files
  const int band = sp.tile_width > 0 ? std::max(1, 64 / sp.tile_height) * sp.tile_height : 64;
  std::vector<float> rows((size_t)sp.width * band * (size_t)sp.nchannels);
  for (int y = sp.y; y < sp.y + sp.height; y += band) {
    const int y1 = std::min(y + band, sp.y + sp.height);
    const bool ok =
        sp.tile_width > 0
            ? in->read_tiles(0, 0, sp.x, sp.x + sp.width, y, y1, sp.z, sp.z + std::max(1, sp.depth),
                             0, sp.nchannels, OIIO::TypeDesc::FLOAT, rows.data())
            : in->read_scanlines(0, 0, y, y1, 0, 0, sp.nchannels, OIIO::TypeDesc::FLOAT,
                                 rows.data());
    if (!ok) {
      err = "the written file is incomplete (disk full?): " + in->geterror();
      return false;
    }
  }
  return true;
}

// Set while the outputs are being written: an image library that ends the process instead of
// returning an error (libjpeg's default handler calls exit() when the disk is full) leaves
// neither a temporary (of this output or of those written before it) nor a silent exit behind.
static std::string g_writing_what;
static const std::vector<std::string> *g_writing_tmps = nullptr;
static void cleanup_at_exit() {
  if (!g_writing_tmps) return;
  std::error_code ec;
  for (const std::string &t : *g_writing_tmps)
    fs::remove_all(t, ec);
  std::fprintf(stderr,
               "kpcntool: error: %s: the image library ended the program while writing "
               "it (disk full?); nothing was written\n",
               g_writing_what.c_str());
}

// The same for an image library that aborts or crashes on what it cannot write (OIIO 2.4
// asserts on some DPX channel counts, or when a buffer cannot be allocated, and divided by
// zero reading back a tiled IFF): outside a write the default.
// Only unlink and write, which are async-signal-safe, touch the outside world here; a
// directory output (--patches:out=) is left for the next run to replace.
static void abort_while_writing(int sig) {
  if (g_writing_tmps) {
    for (const std::string &t : *g_writing_tmps)
      (void)unlink(t.c_str());
    static const char msg[] = "kpcntool: error: the image library aborted or crashed while "
                              "writing an output; nothing was written\n";
    (void)!write(2, msg, sizeof msg - 1);
  }
  std::signal(sig, SIG_DFL);
  std::raise(sig);
}

// A directory output may merge into an existing directory (its files are replaced one by one).
static bool move_into_place(const Context::Output &o, const std::string &tmp, std::string &err) {
  std::error_code ec;
  const std::string path = bare_path(o);
  if (o.is_dir && fs::is_directory(path, ec)) {
    for (const fs::directory_entry &e : fs::directory_iterator(tmp, ec)) {
      fs::rename(e.path(), fs::path(path) / e.path().filename(), ec);
      if (ec) break;
    }
    if (!ec) fs::remove(tmp, ec);
  } else {
    fs::rename(tmp, target_path(o), ec);
  }
  if (ec) err = "cannot move '" + tmp + "' to '" + o.path + "': " + ec.message();
  return !ec;
}

bool commit_outputs(const std::vector<Context::Output> &outputs, std::string &failed,
                    std::string &err) {
  std::vector<std::string> tmp;
  auto clean = [&]() {
    std::error_code ec;
    for (const std::string &t : tmp)
      fs::remove_all(t, ec);
  };
  for (size_t i = 0; i < outputs.size(); ++i) {
    const Context::Output &o = outputs[i];
    std::error_code ec;
    const std::string path = bare_path(o);
    if (o.is_dir && fs::exists(path, ec) && !fs::is_directory(path, ec)) {
      failed = o.what;
      err = "'" + o.path + "' exists and is not a directory";
      clean();
      return false;
    }
    tmp.push_back(temp_path(o, i));
    static const bool registered = [] {
      bool r = std::atexit(cleanup_at_exit) == 0;
      for (int sig : {SIGABRT, SIGFPE, SIGSEGV, SIGBUS})
        r = std::signal(sig, abort_while_writing) != SIG_ERR && r;
      return r;
    }();
    (void)registered;
    g_writing_what = o.what;
    g_writing_tmps = &tmp;
    const bool ok = o.write(tmp.back(), err) && (!o.image || verify_written(tmp.back(), err));
    g_writing_tmps = nullptr;
    if (!ok) {
      failed = o.what;
      err = "cannot write '" + o.path + "': " + err;
      clean();
      return false;
    }
  }
  // Every output is complete; only renames are left (one directory each, so they do not fail
  // for want of space).
  for (size_t i = 0; i < outputs.size(); ++i) {
    if (!move_into_place(outputs[i], tmp[i], err)) {
      failed = outputs[i].what;
      clean();
      return false;
    }
  }
  return true;
}

} // namespace kpcntool
