#include "sim/scene/checked_json.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <vector>

namespace stokes::sim {
inline namespace scene {

namespace {

constexpr Range kAnyComponent{-1e6, 1e6, false};  // of a direction, before it is normalised

const char* typeName(const json& v) {
  switch (v.type()) {
    case json::value_t::null: return "null";
    case json::value_t::object: return "an object";
    case json::value_t::array: return "an array";
    case json::value_t::string: return "a string";
    case json::value_t::boolean: return "a boolean";
    case json::value_t::binary: return "binary data";
    case json::value_t::discarded: return "a discarded value";
    default: return "a number";
  }
}

/// Optimal string alignment distance (Levenshtein with adjacent transpositions).
std::size_t editDistance(std::string_view a, std::string_view b) {
  std::vector<std::vector<std::size_t>> d(a.size() + 1, std::vector<std::size_t>(b.size() + 1));
  for (std::size_t i = 0; i <= a.size(); ++i) d[i][0] = i;
  for (std::size_t j = 0; j <= b.size(); ++j) d[0][j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i)
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t cost = a[i - 1] == b[j - 1] ? 0 : 1;
      d[i][j] = std::min({d[i - 1][j] + 1, d[i][j - 1] + 1, d[i - 1][j - 1] + cost});
      if (i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1])
        d[i][j] = std::min(d[i][j], d[i - 2][j - 2] + 1);
    }
  return d[a.size()][b.size()];
}

/// "openTop", "Open-Top" -> "opentop": spellings that differ only in case and separators.
std::string squashed(std::string_view s) {
  std::string out;
  for (char c : s)
    if (c != '_' && c != '-' && c != ' ') out += static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return out;
}

}  // namespace

/// The allowed key closest to `key`, or "" when none is plausibly meant.
std::string closestKey(const std::string& key, std::initializer_list<const char*> allowed) {
  constexpr std::size_t kLongestCompared = 64;
  if (key.size() > kLongestCompared) return {};
  for (const char* candidate : allowed)
    if (squashed(key) == squashed(candidate)) return candidate;
  constexpr std::size_t kShortestPrefix = 3;  // "tile_ca" -> "tile_cache"
  if (key.size() >= kShortestPrefix)
    for (const char* candidate : allowed)
      if (std::string_view(candidate).starts_with(key)) return candidate;
  std::string best;
  std::size_t bestDistance = std::numeric_limits<std::size_t>::max();
  for (const char* candidate : allowed) {
    const std::size_t d = editDistance(key, candidate);
    const std::size_t tolerated = std::max<std::size_t>(2, std::max(key.size(), std::strlen(candidate)) / 3);
    if (d <= tolerated && d < bestDistance) bestDistance = d, best = candidate;
  }
  return best;
}

std::string joined(std::initializer_list<const char*> items) {
  std::string s;
  for (const char* item : items) s += (s.empty() ? "" : ", ") + std::string(item);
  return s;
}

std::string formatNumber(double v) {
  if (std::isnan(v)) return "NaN";
  if (std::isinf(v)) return v > 0 ? "an overflowing number (inf)" : "an overflowing number (-inf)";
  char buf[64];
  if (v == std::floor(v) && std::abs(v) < 1e15) std::snprintf(buf, sizeof buf, "%.0f", v);
  else std::snprintf(buf, sizeof buf, "%.9g", v);
  return buf;
}

/// Short, printable rendering of an offending value for a message.
std::string describe(const json& v) {
  if (v.is_number()) return formatNumber(v.get<double>());
  constexpr std::size_t kShown = 60;
  std::string text = v.dump(-1, ' ', false, json::error_handler_t::replace);
  if (text.size() > kShown) text = text.substr(0, kShown) + "...";
  if (v.is_null()) return text;
  return text + " (" + typeName(v) + ")";
}

std::string describeRange(const Range& r, bool withUpperBound) {
  std::string s;
  if (r.lo == 0.0 && r.loOpen) s = "a positive number";
  else if (r.lo == 0.0) s = "a number >= 0";
  else if (r.lo == -r.hi) s = "a number in [" + formatNumber(r.lo) + ", " + formatNumber(r.hi) + "]";
  else s = "a number >= " + formatNumber(r.lo);
  if (withUpperBound && r.lo != -r.hi) s += " no larger than " + formatNumber(r.hi);
  return s;
}

std::string describeRange(const IntRange& r) {
  return "an integer in [" + std::to_string(r.lo) + ", " + std::to_string(r.hi) + "]";
}

std::string childPath(const std::string& path, std::string_view key) {
  return path.empty() ? std::string(key) : path + "." + std::string(key);
}

std::string itemPath(const std::string& path, std::size_t index) {
  return path + "[" + std::to_string(index) + "]";
}

[[noreturn]] void fail(const Context& ctx, const std::string& path, const std::string& message) {
  throw SceneError(ctx.source + ": " + (path.empty() ? std::string("top level") : path) + ": " + message);
}

[[noreturn]] void failExpected(const Context& ctx, const std::string& path, const std::string& expected,
                               const json& got) {
  fail(ctx, path, "expected " + expected + ", got " + describe(got));
}

double readNumber(const json& v, const Context& ctx, const std::string& path, const Range& r) {
  if (!v.is_number()) failExpected(ctx, path, describeRange(r, false), v);
  const double x = v.get<double>();
  if (!std::isfinite(x)) failExpected(ctx, path, describeRange(r, true), v);
  if (x < r.lo || (r.loOpen && x == r.lo)) failExpected(ctx, path, describeRange(r, false), v);
  if (x > r.hi) failExpected(ctx, path, describeRange(r, true), v);
  return x;
}

std::int64_t readInteger(const json& v, const Context& ctx, const std::string& path, const IntRange& r) {
  const std::string expected = describeRange(r);
  if (v.is_number_unsigned()) {
    const auto u = v.get<std::uint64_t>();
    if (u > static_cast<std::uint64_t>(r.hi) || static_cast<std::int64_t>(u) < r.lo)
      failExpected(ctx, path, expected, v);
    return static_cast<std::int64_t>(u);
  }
  if (v.is_number_integer()) {
    const auto i = v.get<std::int64_t>();
    if (i < r.lo || i > r.hi) failExpected(ctx, path, expected, v);
    return i;
  }
  if (v.is_number_float()) {  // 64.0 is accepted as 64; 64.5 and 1e300 are not
    const double x = v.get<double>();
    // the bounds as doubles round up near 2^63 (INT64_MAX becomes 2^63): x must also stay below 2^63
    // for the conversion to be defined
    if (!std::isfinite(x) || x != std::floor(x) || x < static_cast<double>(r.lo) || x > static_cast<double>(r.hi) ||
        x >= 0x1p63 || x < -0x1p63 || static_cast<std::int64_t>(x) > r.hi || static_cast<std::int64_t>(x) < r.lo)
      failExpected(ctx, path, expected, v);
    return static_cast<std::int64_t>(x);
  }
  failExpected(ctx, path, expected, v);
}

bool readBool(const json& v, const Context& ctx, const std::string& path) {
  if (!v.is_boolean()) failExpected(ctx, path, "true or false", v);
  return v.get<bool>();
}

std::string readString(const json& v, const Context& ctx, const std::string& path, TextKind kind) {
  if (!v.is_string()) failExpected(ctx, path, "a string", v);
  const auto& s = v.get_ref<const std::string&>();
  if (s.size() > kMaxStringBytes)
    fail(ctx, path, "expected a string of at most " + std::to_string(kMaxStringBytes) + " bytes, got " +
                        std::to_string(s.size()) + " bytes");
  for (char c : s) {
    const auto u = static_cast<unsigned char>(c);
    const bool allowedControl = kind == TextKind::Paragraph && (c == '\n' || c == '\t');
    if ((u < 0x20 && !allowedControl) || u == 0x7f)
      failExpected(ctx, path, "a string without control characters", v);
  }
  return s;
}

Vec3d readVec3(const json& v, const Context& ctx, const std::string& path, const Range& r) {
  if (!v.is_array() || v.size() != 3) failExpected(ctx, path, "an array of 3 numbers [x, y, z]", v);
  Vec3d out;
  for (int i = 0; i < 3; ++i) out[i] = readNumber(v[static_cast<std::size_t>(i)], ctx, itemPath(path, i), r);
  return out;
}

Vec3d readDirection(const json& v, const Context& ctx, const std::string& path) {
  Vec3d n = readVec3(v, ctx, path, kAnyComponent);
  const double length = n.length();
  if (!(length > 1e-12)) failExpected(ctx, path, "a non-zero direction vector", v);
  return n / length;
}

}  // namespace scene
}  // namespace stokes::sim
