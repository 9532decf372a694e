// kpcntool — oiiotool-style command line over kpcn's image operations (docs/kpcntool.md).
//
// Two passes: the whole command line is parsed and checked first (unknown command or
// modifier, missing arguments -> exit 2, nothing read or written), then the steps run left to
// right. `-o` outputs are written only after every step succeeded (exit 1 otherwise), so a
// failing command line never leaves a partial or stale output file.
#include "kpcntool.h"

#include "kpcn/common.h"

#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <exception>
#include <sstream>
#include <sys/stat.h>

namespace {

struct Step {
  const kpcntool::Command *cmd = nullptr; // nullptr: read the image file `file`
  std::string token;                      // as written, for messages
  kpcntool::Modifiers mods;
  std::vector<std::string> args;
  std::string file;
};

void print_help() {
  std::printf(
      "kpcntool %s — image stack tool for kpcn (oiiotool-style)\n\n"
      "usage: kpcntool [file | --command[:key=value...] [args]] ...\n\n"
      "File names push the image (all channels, as float) on the stack; commands act on the\n"
      "top of the stack, left to right. Metrics compare the two top images (second-from-top\n"
      "is the test image x, the top is the reference y) and print their results at the end\n"
      "(one JSON object with --json). Outputs (-o) are written only if every command\n"
      "succeeded. Exit status: 0 ok, 1 runtime error, 2 usage error.\n\n"
      "commands:\n",
      KPCN_VERSION_STRING);
  std::printf("  %-14s %s\n", "--help", "print this help");
  std::printf("  %-14s %s\n", "--version",
              "print the versions and the instruction set (avx512 or avx2) in use");
  for (const kpcntool::Command *c : kpcntool::all_commands()) {
    std::string name = (c->name.size() == 1 ? "-" : "--") + c->name;
    for (int i = 0; i < c->nargs; ++i)
      name += " ARG";
    std::printf("  %-14s %s\n", name.c_str(), c->help.c_str());
    if (!c->modifiers.empty()) {
      std::string m;
      for (auto &k : c->modifiers)
        m += (m.empty() ? "" : ", ") + k;
      std::printf("  %-14s   modifiers: %s\n", "", m.c_str());
    }
  }
}

std::string json_number(double v) {
  if (!std::isfinite(v)) return "null"; // JSON has no inf/nan (e.g. PSNR of equal images)
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  return buf;
}

std::string json_string(const std::string &s) {
  std::string o = "\"";
  for (char ch : s) {
    if (ch == '"' || ch == '\\') {
      o += '\\';
      o += ch;
    } else if ((unsigned char)ch < 0x20) {
      char b[8];
      std::snprintf(b, sizeof b, "\\u%04x", ch);
      o += b;
    } else {
      o += ch;
    }
  }
  return o + "\"";
}

// The files the steps write (-o, --patches:out=F.kps), checked before any work: an output must be
// writable as a new file renamed into place (not a device, FIFO or directory, in an existing
// folder) and must not be a model or scene a step reads. An input image may be written over (an
// edit in place, as with oiiotool): every image is read whole before any output is written.
bool check_files(const std::vector<Step> &steps, std::string &err) {
  std::vector<std::pair<std::string, std::string>> outs, ins; // (path, role): ins are models
  for (const Step &st : steps) {
    if (!st.cmd) continue;
    if (st.cmd->name == "o") outs.push_back({st.args[0], "-o"});
    const std::string out = st.mods.str("out"), model = st.mods.str("model");
    if (out.size() > 4 && out.compare(out.size() - 4, 4, ".kps") == 0) { // as cmd_patches
      outs.push_back({out, "out="});
    } else if (!out.empty()) {
      // a folder of EXR pairs, merged into when it exists: then it must be a directory; a new
      // one needs its parent folder, checked as for a new file of that name
      std::string bare = out;
      while (bare.size() > 1 && bare.back() == '/')
        bare.pop_back();
      struct stat sb;
      if (stat(bare.c_str(), &sb) == 0 && !S_ISDIR(sb.st_mode)) {
        err = "out= '" + out + "' exists and is not a directory";
        return false;
      }
      if (stat(bare.c_str(), &sb) != 0 && kpcn_check_output_path(bare.c_str(), "out=") != KPCN_OK) {
        err = kpcn_last_error();
        return false;
      }
    }
    if (!model.empty()) ins.push_back({model, "model"});
    if (st.cmd->name == "render") ins.push_back({st.args[0], "the scene of --render"});
  }
  for (const auto &o : outs) {
    kpcn_status s = kpcn_check_output_path(o.first.c_str(), o.second.c_str());
    for (size_t k = 0; s == KPCN_OK && k < ins.size(); ++k)
      s = kpcn_check_not_input(o.first.c_str(), o.second.c_str(), ins[k].first.c_str(),
                               ins[k].second.c_str());
    if (s != KPCN_OK) {
      err = kpcn_last_error();
      return false;
    }
  }
  return true;
}

// Parses argv into steps; returns false with err on a usage error.
bool parse(int argc, char **argv, std::vector<Step> &steps, std::string &err) {
  for (int i = 1; i < argc; ++i) {
    std::string a = argv[i];
    Step st;
    st.token = a;
    if (a.size() < 2 || a[0] != '-') {
      st.file = a;
      steps.push_back(std::move(st));
      continue;
    }
    std::string body = a.substr(a[1] == '-' ? 2 : 1);
    std::vector<std::string> parts;
    std::stringstream ss(body);
    for (std::string p; std::getline(ss, p, ':');)
      parts.push_back(p);
    if (parts.empty() || parts[0].empty()) {
      err = "malformed command '" + a + "'";
      return false;
    }
    st.cmd = kpcntool::find_command(parts[0]);
    if (!st.cmd) {
      err = "unknown command '" + a.substr(0, a.find(':')) + "' (see --help)";
      return false;
    }
    for (size_t k = 1; k < parts.size(); ++k) {
      size_t eq = parts[k].find('=');
      std::string key = parts[k].substr(0, eq);
      bool known = false;
      for (auto &m : st.cmd->modifiers)
        known = known || m == key;
      if (!known) {
        std::string accepted;
        for (auto &m : st.cmd->modifiers)
          accepted += (accepted.empty() ? "" : ", ") + m;
        err = "unknown modifier '" + key + "' for --" + st.cmd->name +
              (accepted.empty() ? " (it takes none)" : " (accepted: " + accepted + ")");
        return false;
      }
      if (eq == std::string::npos) {
        err = "modifier '" + key + "' of --" + st.cmd->name + " needs a value (" + key + "=...)";
        return false;
      }
      if (st.mods.has(key)) {
        err = "modifier '" + key + "' of --" + st.cmd->name + " is given twice";
        return false;
      }
      st.mods.kv[key] = parts[k].substr(eq + 1);
    }
    for (int n = 0; n < st.cmd->nargs; ++n) {
      if (i + 1 >= argc) {
        err = "command '" + a + "' needs " + std::to_string(st.cmd->nargs) + " argument(s)";
        return false;
      }
      st.args.push_back(argv[++i]);
    }
    if (st.cmd->name == "o" && !kpcntool::output_format_ok(st.args[0], err)) {
      err = "-o " + st.args[0] + ": " + err;
      return false;
    }
    steps.push_back(std::move(st));
  }
  return check_files(steps, err);
}

void print_results(const kpcntool::Context &ctx) {
  if (ctx.json) {
    std::string o = "{";
    bool first = true;
    for (auto &r : ctx.results) {
      o += (first ? "" : ", ") + json_string(r.first) + ": " + json_number(r.second);
      first = false;
    }
    for (auto &r : ctx.json_items) {
      o += (first ? "" : ", ") + json_string(r.first) + ": " + r.second;
      first = false;
    }
    std::printf("%s}\n", o.c_str());
    return;
  }
  for (auto &r : ctx.results)
    std::printf("%-16s %.9g\n", (r.first + ":").c_str(), r.second);
}

} // namespace

int main(int argc, char **argv) {
  for (int i = 1; i < argc; ++i) {
    std::string a = argv[i];
    // -x and --x are one command everywhere else on the command line (kpcntool.md)
    if (a == "--help" || a == "-help" || a == "-h") {
      print_help();
      return 0;
    }
    if (a == "--version" ||
        a == "-version") { // the library, its dependencies and the instruction set in use
      const int v = OIIO::openimageio_version();
      std::printf("kpcntool %s\n%s, OpenImageIO %d.%d.%d\n", KPCN_VERSION_STRING, kpcn_build_info(),
                  v / 10000, v / 100 % 100, v % 100);
      return 0;
    }
  }
  std::vector<Step> steps;
  std::string err;
  if (!parse(argc, argv, steps, err)) {
    std::fprintf(stderr, "kpcntool: error: %s\n", kpcntool::printable(err, true).c_str());
    return 2;
  }
  // --json and --threads only set how the other steps run.
  if (std::all_of(steps.begin(), steps.end(), [](const Step &st) {
        return st.cmd && (st.cmd->name == "json" || st.cmd->name == "threads");
      })) {
    std::fprintf(stderr, "kpcntool: error: nothing to do (see --help)\n");
    return 2;
  }
  kpcntool::Context ctx;
  // --json is global (it only changes how results are printed), wherever it appears.
  for (Step &st : steps)
    if (st.cmd && st.cmd->name == "json") ctx.json = true;
  for (Step &st : steps) {
    bool ok = false;
    err.clear();
    try {
      if (!st.cmd) {
        OIIO::ImageBuf buf;
        ok = kpcntool::read_image(buf, st.file, err);
        if (ok) kpcntool::note_input_type(ctx, buf.nativespec().format);
        if (ok) ctx.push(std::move(buf));
      } else {
        ok = st.cmd->run(ctx, st.mods, st.args, err);
      }
    } catch (const std::exception &e) {
      ok = false;
      err = e.what();
    }
    if (!ok) {
      if (err.empty()) err = "failed";
      std::string what = st.token; // the command as written, with its arguments (-o x.png)
      for (const std::string &a : st.args)
        what += " " + a;
      std::fprintf(stderr, "kpcntool: error: %s: %s\n", kpcntool::printable(what).c_str(),
                   kpcntool::printable(err, true).c_str());
      return 1;
    }
  }
  std::string failed;
  if (!kpcntool::commit_outputs(ctx.outputs, failed, err)) {
    std::fprintf(stderr, "kpcntool: error: %s: %s\n", kpcntool::printable(failed).c_str(),
                 kpcntool::printable(err, true).c_str());
    return 1;
  }
  print_results(ctx);
  return 0;
}
