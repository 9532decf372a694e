// kpcntool command registry and the small Context/Modifiers helpers (see kpcntool.h).
#include "cli_parse.h"
#include "kpcntool.h"

#include <algorithm>
#include <cerrno>
#include <climits>
#include <cmath>
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
  double v = 0;
  if (!cli_parse_double(it->second.c_str(), &v)) // decimal only: no blanks, hex, inf or nan
    throw Error("modifier '" + k + "' needs a finite number (got '" + it->second + "')");
  return v;
}

long Modifiers::integer(const std::string &k, long def) const {
  auto it = kv.find(k);
  if (it == kv.end()) return def;
  long long v = 0;
  if (!cli_parse_ll(it->second.c_str(), INT_MIN, INT_MAX, &v)) // digits, a '-' at most
    throw Error("modifier '" + k + "' needs an integer in [" + std::to_string(INT_MIN) + ", " +
                std::to_string(INT_MAX) + "] (got '" + it->second + "')");
  return (long)v;
}

uint64_t Modifiers::u64(const std::string &k, uint64_t def, uint64_t max,
                        const char *max_text) const {
  auto it = kv.find(k);
  if (it == kv.end()) return def;
  const std::string &v = it->second;
  bool digits =
      !v.empty() && std::all_of(v.begin(), v.end(), [](char c) { return c >= '0' && c <= '9'; });
  errno = 0;
  unsigned long long u = digits ? std::strtoull(v.c_str(), nullptr, 10) : 0;
  if (!digits || errno == ERANGE || u > max)
    throw Error("modifier '" + k + "' needs an integer in [0, " + max_text + "] (got '" + v + "')");
  return (uint64_t)u;
}

bool Modifiers::flag(const std::string &k, bool def) const {
  auto it = kv.find(k);
  if (it == kv.end()) return def;
  if (it->second != "0" && it->second != "1")
    throw Error("modifier '" + k + "' must be 0 or 1 (got '" + it->second + "')");
  return it->second == "1";
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

std::string Context::unique_key(const std::string &key) const {
  std::string k = key;
  for (int n = 2;; ++n) {
    auto same = [&](const auto &p) { return p.first == k; };
    if (std::none_of(results.begin(), results.end(), same) &&
        std::none_of(json_items.begin(), json_items.end(), same))
      return k;
    k = key + "_" + std::to_string(n);
  }
}

std::string Context::add_result(const std::string &key, double value) {
  std::string k = unique_key(key);
  results.emplace_back(k, value);
  return k;
}

void Context::add_json_item(const std::string &key, std::string json) {
  json_items.emplace_back(unique_key(key), std::move(json));
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
