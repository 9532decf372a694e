// kpcntool command registry and the small Context/Modifiers helpers (see kpcntool.h).
#include "kpcntool.h"

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstdlib>

namespace kpcntool {

// Function-local static: commands register from static initializers of other files, whose
// order relative to this file is unspecified.
static std::map<std::string, Command> &registry() {
  static std::map<std::string, Command> r;
  return r;
}

bool register_command(Command c) {
  std::string name = c.name;
  registry()[name] = std::move(c);
  return true;
}

const Command *find_command(const std::string &name) {
  auto it = registry().find(name);
  return it == registry().end() ? nullptr : &it->second;
}

std::vector<const Command *> all_commands() {
  std::vector<const Command *> v;
  for (auto &kv : registry())
    v.push_back(&kv.second);
  return v;
}

double Modifiers::num(const std::string &k, double def) const {
  auto it = kv.find(k);
  if (it == kv.end()) return def;
  const char *s = it->second.c_str();
  char *end = nullptr;
  errno = 0;
  double v = std::strtod(s, &end);
  if (end == s || *end != 0 || errno == ERANGE)
    throw Error("modifier '" + k + "' needs a number (got '" + it->second + "')");
  return v;
}

long Modifiers::integer(const std::string &k, long def) const {
  auto it = kv.find(k);
  if (it == kv.end()) return def;
  const char *s = it->second.c_str();
  char *end = nullptr;
  errno = 0;
  long v = std::strtol(s, &end, 10);
  if (end == s || *end != 0 || errno == ERANGE)
    throw Error("modifier '" + k + "' needs an integer (got '" + it->second + "')");
  return v;
}

OIIO::ImageBuf Context::pop() {
  if (stack.empty()) throw Error("the image stack is empty");
  OIIO::ImageBuf b = std::move(stack.back());
  stack.pop_back();
  return b;
}

OIIO::ImageBuf &Context::top() {
  if (stack.empty()) throw Error("the image stack is empty");
  return stack.back();
}

void Context::add_result(const std::string &key, double value) {
  std::string k = key;
  for (int n = 2;; ++n) {
    bool taken = std::any_of(results.begin(), results.end(),
                             [&](const std::pair<std::string, double> &p) { return p.first == k; });
    if (!taken) break;
    k = key + "_" + std::to_string(n);
  }
  results.emplace_back(k, value);
}

std::string printable(const std::string &s, bool keep_newlines) {
  std::string o;
  const size_t n = s.size();
  for (size_t i = 0; i < n;) {
    unsigned char c = (unsigned char)s[i];
    size_t len = c < 0x80 ? 1 : (c >> 5) == 6 ? 2 : (c >> 4) == 14 ? 3 : (c >> 3) == 30 ? 4 : 0;
    bool ok = len > 0 && i + len <= n;
    for (size_t k = 1; ok && k < len; ++k)
      ok = ((unsigned char)s[i + k] >> 6) == 2;
    if (ok && len == 1 && (c < 0x20 || c == 0x7f) && !(keep_newlines && c == '\n')) ok = false;
    if (ok) {
      o.append(s, i, len);
      i += len;
    } else {
      char esc[8];
      std::snprintf(esc, sizeof esc, "\\x%02x", c);
      o += esc;
      ++i;
    }
  }
  return o;
}

} // namespace kpcntool
