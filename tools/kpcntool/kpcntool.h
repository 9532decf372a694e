// kpcntool command registry. kpcntool follows oiiotool: an image stack, commands applied
// left to right, `-o file` writes the top, `--cmd:key=value:key2=value2` modifiers.
// Each command family lives in its own cmd_*.cpp file and registers itself with a static
// initializer, so adding commands never edits main.cpp:
//
//   static bool reg = kpcntool::register_command({"ssim", 0, {"json"}, "help text",
//       [](kpcntool::Context &ctx, const kpcntool::Modifiers &m,
//          const std::vector<std::string> &args, std::string &err) -> bool { ... }});
#pragma once
#include <OpenImageIO/imagebuf.h>

#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <vector>

namespace kpcntool {

struct Modifiers {
  std::map<std::string, std::string> kv;
  bool has(const std::string &k) const { return kv.count(k) != 0; }
  std::string str(const std::string &k, const std::string &def = "") const {
    auto it = kv.find(k);
    return it == kv.end() ? def : it->second;
  }
  // Parse helpers: on a malformed value they throw kpcntool::Error naming the modifier.
  double num(const std::string &k, double def) const; // finite
  long integer(const std::string &k, long def) const; // within int's range
  // seeds, indices: digits only, at most max (named in the error as max_text)
  uint64_t u64(const std::string &k, uint64_t def, uint64_t max = UINT64_MAX,
               const char *max_text = "2^64-1") const;
  bool flag(const std::string &k, bool def) const; // exactly 0 or 1
};

struct Error : std::runtime_error {
  using std::runtime_error::runtime_error;
};

struct Context {
  std::vector<OIIO::ImageBuf> stack; // back() is the top
  bool json = false;                 // --json: machine-readable results
  int nthreads = 0;                  // --threads N (0 = all cores)
  // -d TYPE: the pixel type of the following -o files; UNKNOWN until given (then each -o
  // takes input_type, as far as its format holds it: output_type() in output.cpp).
  OIIO::TypeDesc output_type = OIIO::TypeDesc::UNKNOWN;
  // The widest pixel type of the image files read so far (uint8 < uint16 < half < float);
  // UNKNOWN before the first, when outputs default to float.
  OIIO::TypeDesc input_type = OIIO::TypeDesc::UNKNOWN;
  // Results of measuring commands, printed at exit (as one JSON object with --json).
  std::vector<std::pair<std::string, double>> results;
  // Extension (main/cmd_core owner): non-numeric results as raw JSON text, e.g. --info.
  std::vector<std::pair<std::string, std::string>> json_items;
  // Extension: files written only after every command succeeded (`-o`, `--patches:out=`):
  // write() makes the output at a temporary path next to `path` (a file, or a directory if
  // is_dir); commit_outputs renames them all into place once every write succeeded, so a
  // failing command line leaves none of them.
  struct Output {
    std::string what; // the step that queued it, for messages: "-o out.png"
    std::string path;
    bool is_dir = false;
    std::function<bool(const std::string &tmp, std::string &err)> write;
    bool image = false; // an image file, read back whole after writing (see output.cpp)
  };
  std::vector<Output> outputs;
  // Extension: records a numeric result under a unique key (key, key_2, key_3 ...).
  // the key as stored: `key`, or key_2, key_3 ... when the line measures it again
  std::string add_result(const std::string &key, double value);
  // Extension: records a raw JSON result (--info) under a unique key, as add_result does.
  void add_json_item(const std::string &key, std::string json);
  // key, or key_2, key_3 ... : the first not yet taken by a result or a JSON item
  std::string unique_key(const std::string &key) const;
  OIIO::ImageBuf pop();  // throws Error on an empty stack
  OIIO::ImageBuf &top(); // throws Error on an empty stack
  void push(OIIO::ImageBuf buf) { stack.push_back(std::move(buf)); }
};

struct Command {
  std::string name;                   // without dashes: "ssim" is invoked as --ssim
  int nargs;                          // positional arguments it consumes
  std::vector<std::string> modifiers; // accepted :key=value keys; others are an error
  std::string help;                   // one line for --help
  // Returns false and sets err (naming the problem) on failure; may also throw Error.
  std::function<bool(Context &, const Modifiers &, const std::vector<std::string> &, std::string &)>
      run;
};

bool register_command(Command c);

// Extensions used by main.cpp (implemented in registry.cpp / cmd_core.cpp).
const Command *find_command(const std::string &name); // nullptr if unknown
std::vector<const Command *> all_commands();          // sorted by name
// The pixel type an -o file of extension ext (lower case) gets for img: the -d type when
// given, else, as in oiiotool, the type of img's file when img is an image as read, or the
// widest input type when img was computed (float when nothing was read), as far as the format
// holds it: 8-bit formats (PNG, JPEG, ...) get uint8, PNG and PNM uint16 for 16-bit data.
OIIO::TypeDesc output_type(const Context &ctx, const OIIO::ImageBuf &img, const std::string &ext);
// Folds the pixel type of a file just read into ctx.input_type.
void note_input_type(Context &ctx, OIIO::TypeDesc file_type);
// Checks that img can be written to a file of extension ext: more channels than R,G,B,A only
// to formats that hold any number (EXR, TIFF), and a frame that whole_frame can fill for formats
// without display windows; false with err saying which and what to do.
bool output_fits(const OIIO::ImageBuf &img, const std::string &ext, std::string &err);
// out = img's whole frame (display window): img itself, or padded with black where its pixels
// (data window) cover part of it, as oiiotool does for formats without windows and --mosaic.
// A display window beyond the image size limits is an error (false, err says so).
bool whole_frame(const OIIO::ImageBuf &img, OIIO::ImageBuf &out, int nthreads, std::string &err);
// Writes img to file in pixel type fmt (the format chosen by the file's extension). A format
// without display windows (PNG, JPEG, ...) gets the whole frame: an image whose pixels cover part
// of it (a --render crop) is padded with black to its display window, as oiiotool does. Returns
// false with err on failure.
bool write_image(const OIIO::ImageBuf &img, const std::string &file, OIIO::TypeDesc fmt,
                 std::string &err);
// "png" for "a/b.PNG", "" when the name has no extension.
std::string lower_ext(const std::string &path);
// True when path's extension names a format OIIO can write; else false with err saying why.
// Checked when the command line is parsed, so a bad -o fails before a long denoise runs.
bool output_format_ok(const std::string &path, std::string &err);
// Writes every pending output (Context::outputs) to its temporary path, then renames them all
// into place. On failure removes every temporary, sets failed to the output's `what` and err to
// why, and returns false.
bool commit_outputs(const std::vector<Context::Output> &outputs, std::string &failed,
                    std::string &err);
// Reads an image file fully as float; false with err naming the file on failure.
bool read_image(OIIO::ImageBuf &dst, const std::string &path, std::string &err);
// Text that came from a file (channel names, attributes, messages quoting them), made safe to
// print: control characters (except newline if keep_newlines) and bytes that are not valid
// UTF-8 become \xNN, so a damaged file can neither send escape sequences to the terminal nor
// make the output invalid UTF-8.
std::string printable(const std::string &s, bool keep_newlines = false);

} // namespace kpcntool
