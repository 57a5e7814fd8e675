#include "sim/scene.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <limits>
#include <set>
#include <sstream>
#include <string_view>
#include <utility>

namespace stokes::sim {

using nlohmann::json;
namespace fs = std::filesystem;

namespace {

// ---- limits -------------------------------------------------------------------------------------
// Sane bounds: anything outside them is a typo or an attack, not a scene.

constexpr std::uintmax_t kMaxSceneFileBytes = 16u << 20;  // 16 MiB
constexpr std::size_t kMaxShapes = 10'000;                // per array (liquid, solids, emitters)
constexpr std::size_t kMaxStringBytes = 4096;
constexpr double kBig = 1e6;  // metres, seconds, m/s: anything larger is not a scene

/// An admissible closed or half-open interval for a number, and how to say it. (Units are
/// documented in scenes/README.md: metres, seconds, kg/m^3, Pa s, degrees.)
struct Range {
  double lo, hi;
  bool loOpen = false;  ///< lo itself excluded (positive numbers)
};

constexpr Range kCoordinate{-kBig, kBig, false};
constexpr Range kLength{0.0, kBig, true};
constexpr Range kVelocity{-1e4, 1e4, false};
constexpr Range kAcceleration{-1e4, 1e4, false};
constexpr Range kTime{0.0, 1e7, false};
constexpr Range kAngle{-36000.0, 36000.0, false};
constexpr Range kScale{0.0, kBig, true};
constexpr Range kDensity{0.0, 1e7, true};
constexpr Range kViscosity{0.0, 1e12, false};
constexpr Range kFps{0.0, 1e5, true};
constexpr Range kCfl{0.0, 100.0, true};
constexpr Range kTolerance{0.0, 0.5, true};
constexpr Range kUnitComponent{-kBig, kBig, false};
constexpr Range kFraction{0.0, 1.0, false};

/// An admissible integer interval.
struct IntRange {
  std::int64_t lo, hi;
};

constexpr IntRange kResolution{1, 4096};
constexpr IntRange kFrames{1, 1'000'000};
constexpr IntRange kSubsteps{1, 100'000};
constexpr IntRange kTile{2, 256};
constexpr IntRange kPadding{1, 255};
constexpr IntRange kBand{0, 64};
constexpr IntRange kMinRegion{1, 4096};
constexpr IntRange kSmootherDegree{0, 16};
constexpr IntRange kIterations{1, 100'000'000};
constexpr IntRange kParticlesPerAxis{1, 8};
constexpr IntRange kPixels{16, 16384};
constexpr IntRange kRetries{0, 10};
constexpr IntRange kMeshSubdivisions{0, 3};
constexpr IntRange kCheckpointEvery{0, 1'000'000};
constexpr IntRange kSeed{0, std::numeric_limits<std::int64_t>::max()};

// ---- formatting ---------------------------------------------------------------------------------

std::string formatNumber(double v) {
  if (std::isnan(v)) return "NaN";
  if (std::isinf(v)) return v > 0 ? "an overflowing number (inf)" : "an overflowing number (-inf)";
  char buf[64];
  if (v == std::floor(v) && std::abs(v) < 1e15) std::snprintf(buf, sizeof buf, "%.0f", v);
  else std::snprintf(buf, sizeof buf, "%.9g", v);
  return buf;
}

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

// ---- key suggestions ----------------------------------------------------------------------------

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

// ---- typed value readers ------------------------------------------------------------------------

/// What a reader needs to phrase its messages and resolve files.
struct Context {
  std::string source;   ///< file name shown in messages
  std::string baseDir;  ///< directory that relative mesh paths are resolved against
};

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

enum class TextKind { Line, Paragraph };

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
  Vec3d n = readVec3(v, ctx, path, kUnitComponent);
  const double length = n.length();
  if (!(length > 1e-12)) failExpected(ctx, path, "a non-zero direction vector", v);
  return n / length;
}

template <class E>
using Choices = std::initializer_list<std::pair<const char*, E>>;

template <class E>
E readChoice(const json& v, const Context& ctx, const std::string& path, Choices<E> choices) {
  std::string names;
  for (const auto& [name, value] : choices) names += (names.empty() ? "\"" : ", \"") + std::string(name) + "\"";
  if (v.is_string())
    for (const auto& [name, value] : choices)
      if (v.get_ref<const std::string&>() == name) return value;
  failExpected(ctx, path, "one of " + names, v);
}

/// A JSON object at a key path: checks its keys against an allowed list and reads typed fields,
/// with defaults for optional ones and a clear message for missing required ones.
class ObjectReader {
 public:
  ObjectReader(const json& v, const Context& ctx, std::string path, const char* what = "an object")
      : v_(v), ctx_(ctx), path_(std::move(path)) {
    if (!v.is_object()) failExpected(ctx_, path_, what, v);
  }

  /// Every key must be one of `allowed`; an unknown one is reported with the closest known key.
  void allowOnly(std::initializer_list<const char*> allowed, const std::string& context = "") const {
    for (const auto& item : v_.items()) {
      const std::string& key = item.key();  // (not a structured binding: clang 14 cannot capture one)
      if (std::any_of(allowed.begin(), allowed.end(), [&](const char* k) { return key == k; })) continue;
      const std::string suggestion = closestKey(key, allowed);
      std::string printable = key.size() > 60 ? key.substr(0, 60) + "..." : key;
      for (char& c : printable)
        if (static_cast<unsigned char>(c) < 0x20) c = '?';
      fail(ctx_, childPath(path_, printable),
           "unknown key" + context + (suggestion.empty() ? "" : " (did you mean \"" + suggestion + "\"?)") +
               "; expected one of: " + joined(allowed));
    }
  }

  const std::string& path() const { return path_; }
  const Context& context() const { return ctx_; }
  bool has(const char* key) const { return v_.contains(key); }
  std::string pathOf(const char* key) const { return childPath(path_, key); }

  const json& required(const char* key, const std::string& expected) const {
    const auto it = v_.find(key);
    if (it == v_.end()) fail(ctx_, pathOf(key), "missing required key (expected " + expected + ")");
    return *it;
  }

  double number(const char* key, const Range& r) const {
    return readNumber(required(key, describeRange(r, false)), ctx_, pathOf(key), r);
  }
  double number(const char* key, const Range& r, double fallback) const {
    return has(key) ? readNumber(v_.at(key), ctx_, pathOf(key), r) : fallback;
  }
  std::int64_t integer(const char* key, const IntRange& r) const {
    return readInteger(required(key, describeRange(r)), ctx_, pathOf(key), r);
  }
  std::int64_t integer(const char* key, const IntRange& r, std::int64_t fallback) const {
    return has(key) ? readInteger(v_.at(key), ctx_, pathOf(key), r) : fallback;
  }
  bool boolean(const char* key, bool fallback) const {
    return has(key) ? readBool(v_.at(key), ctx_, pathOf(key)) : fallback;
  }
  std::string string(const char* key, TextKind kind = TextKind::Line) const {
    return readString(required(key, "a string"), ctx_, pathOf(key), kind);
  }
  std::string string(const char* key, TextKind kind, const std::string& fallback) const {
    return has(key) ? readString(v_.at(key), ctx_, pathOf(key), kind) : fallback;
  }
  Vec3d vec3(const char* key, const Range& r) const {
    return readVec3(required(key, "an array of 3 numbers [x, y, z]"), ctx_, pathOf(key), r);
  }
  Vec3d vec3(const char* key, const Range& r, const Vec3d& fallback) const {
    return has(key) ? readVec3(v_.at(key), ctx_, pathOf(key), r) : fallback;
  }
  std::optional<Vec3d> optionalVec3(const char* key, const Range& r) const {
    if (!has(key)) return std::nullopt;
    return readVec3(v_.at(key), ctx_, pathOf(key), r);
  }
  Vec3d direction(const char* key) const {
    return readDirection(required(key, "a non-zero direction vector [x, y, z]"), ctx_, pathOf(key));
  }
  template <class E>
  E choice(const char* key, Choices<E> choices) const {
    return readChoice(required(key, "a string naming the kind"), ctx_, pathOf(key), choices);
  }
  template <class E>
  E choice(const char* key, Choices<E> choices, E fallback) const {
    return has(key) ? readChoice(v_.at(key), ctx_, pathOf(key), choices) : fallback;
  }
  ObjectReader object(const char* key, const char* expected) const {
    return ObjectReader(required(key, expected), ctx_, pathOf(key), expected);
  }
  std::optional<ObjectReader> optionalObject(const char* key, const char* expected) const {
    if (!has(key)) return std::nullopt;
    return ObjectReader(v_.at(key), ctx_, pathOf(key), expected);
  }

  /// Calls f(item, itemPath) for each element of an optional array (absent = empty).
  template <class F>
  void forEachItem(const char* key, F&& f) const {
    if (!has(key)) return;
    const json& a = v_.at(key);
    if (!a.is_array()) failExpected(ctx_, pathOf(key), "an array", a);
    if (a.size() > kMaxShapes)
      fail(ctx_, pathOf(key), "expected at most " + std::to_string(kMaxShapes) + " entries, got " +
                                  std::to_string(a.size()));
    for (std::size_t i = 0; i < a.size(); ++i) f(a[i], itemPath(pathOf(key), i));
  }

 private:
  const json& v_;
  const Context& ctx_;
  std::string path_;
};

/// `max` must exceed `min` on every axis (boxes, the domain).
void requireOrderedCorners(const ObjectReader& r, const Vec3d& lo, const Vec3d& hi) {
  for (int a = 0; a < 3; ++a)
    if (!(hi[a] > lo[a]))
      fail(r.context(), itemPath(r.pathOf("max"), a),
           "expected a value greater than " + itemPath(r.pathOf("min"), a) + " (= " + formatNumber(lo[a]) +
               "), got " + formatNumber(hi[a]));
}

bool boxesOverlap(const Vec3d& aMin, const Vec3d& aMax, const Vec3d& bMin, const Vec3d& bMax) {
  for (int a = 0; a < 3; ++a)
    if (aMax[a] <= bMin[a] || bMax[a] <= aMin[a]) return false;
  return true;
}

double distanceToBox(const Vec3d& p, const Vec3d& lo, const Vec3d& hi) {
  Vec3d d;
  for (int a = 0; a < 3; ++a) d[a] = std::max({lo[a] - p[a], 0.0, p[a] - hi[a]});
  return d.length();
}

std::string boxText(const Vec3d& lo, const Vec3d& hi) {
  auto v = [](const Vec3d& p) {
    return "[" + formatNumber(p[0]) + ", " + formatNumber(p[1]) + ", " + formatNumber(p[2]) + "]";
  };
  return v(lo) + " - " + v(hi);
}

// ---- sections -----------------------------------------------------------------------------------

void parseDomain(const ObjectReader& r, Scene& s) {
  r.allowOnly({"min", "max", "open_top"});
  s.domainMin = r.vec3("min", kCoordinate);
  s.domainMax = r.vec3("max", kCoordinate);
  requireOrderedCorners(r, s.domainMin, s.domainMax);
  s.openTop = r.boolean("open_top", false);
}

void parseMaterial(const ObjectReader& r, Scene& s) {
  r.allowOnly({"density", "viscosity"});
  s.material.density = r.number("density", kDensity);
  s.material.viscosity = r.number("viscosity", kViscosity);
}

void parseModel(const ObjectReader& r, ModelDesc& m) {
  r.allowOnly({"type", "tile", "padding", "band_air", "band_solid", "min_region", "tile_cache"});
  m.type = r.choice<ModelType>(
      "type", {{"uniform", ModelType::Uniform}, {"affine", ModelType::Affine}, {"quadratic", ModelType::Quadratic}},
      ModelType::Uniform);
  m.tile = static_cast<int>(r.integer("tile", kTile, m.tile));
  m.padding = static_cast<int>(r.integer("padding", kPadding, m.padding));
  if (m.padding >= m.tile)
    fail(r.context(), r.pathOf("padding"),
         "expected a padding smaller than the tile (" + std::to_string(m.tile) + "), got " + std::to_string(m.padding));
  m.bandAir = static_cast<int>(r.integer("band_air", kBand, m.bandAir));
  m.bandSolid = static_cast<int>(r.integer("band_solid", kBand, m.bandSolid));
  m.minRegion = static_cast<int>(r.integer("min_region", kMinRegion, m.minRegion));
  m.tileCache = r.choice<TileCache>(
      "tile_cache", {{"none", TileCache::None}, {"library", TileCache::Library}, {"shapes", TileCache::Shapes}},
      m.tileCache);
}

void parseSolver(const ObjectReader& r, SolverDesc& s) {
  r.allowOnly({"tolerance", "max_iterations", "preconditioner", "rows", "stencils", "multigrid_degree", "warm_start",
               "retries", "backend"});
  s.tolerance = r.number("tolerance", kTolerance, s.tolerance);
  s.maxIterations = static_cast<int>(r.integer("max_iterations", kIterations, s.maxIterations));
  s.preconditioner = r.choice<PreconditionerType>("preconditioner",
                                                  {{"none", PreconditionerType::None},
                                                   {"jacobi", PreconditionerType::Jacobi},
                                                   {"multigrid", PreconditionerType::Multigrid}},
                                                  s.preconditioner);
  s.rows = r.choice<KrylovRows>(
      "rows", {{"auto", KrylovRows::Auto}, {"compact", KrylovRows::Compact}, {"padded", KrylovRows::Padded}}, s.rows);
  s.rowStencils = r.choice<bool>("stencils", {{"rows", true}, {"blocks", false}}, s.rowStencils);
  s.warmStart = r.boolean("warm_start", s.warmStart);
  s.multigridDegree = static_cast<int>(r.integer("multigrid_degree", kSmootherDegree, s.multigridDegree));
  s.retries = static_cast<int>(r.integer("retries", kRetries, s.retries));
  s.backend = r.choice<SolverBackend>("backend", {{"in-house", SolverBackend::InHouse}, {"petsc", SolverBackend::Petsc}},
                                      s.backend);
}

enum class ShapeRole { Liquid, Solid };

/// Resolves a mesh path against the scene's directory and checks that the file is there.
std::string resolveMeshFile(const ObjectReader& r) {
  const std::string file = r.string("file");
  if (file.empty()) fail(r.context(), r.pathOf("file"), "expected the path of an OBJ file, got \"\"");
  fs::path p(file);
  if (p.is_relative() && !r.context().baseDir.empty()) p = fs::path(r.context().baseDir) / p;
  p = p.lexically_normal();
  std::error_code ec;
  if (!fs::is_regular_file(p, ec))
    fail(r.context(), r.pathOf("file"),
         "expected an existing OBJ file (relative paths start at the scene file's directory), got \"" + file +
             "\" (looked for " + p.string() + ")");
  return p.string();
}

ShapeDesc parseShape(const json& v, const Context& ctx, const std::string& path, ShapeRole role) {
  const ObjectReader r(v, ctx, path, "a shape object {\"shape\": ...}");
  using K = ShapeDesc::Kind;
  ShapeDesc s;
  s.kind = role == ShapeRole::Liquid
               ? r.choice<K>("shape", {{"box", K::Box}, {"sphere", K::Sphere}, {"mesh", K::Mesh}})
               : r.choice<K>("shape", {{"box", K::Box}, {"sphere", K::Sphere}, {"plane", K::Plane}, {"mesh", K::Mesh}});
  const std::string forKind = std::string(" for a ") + toString(s.kind);
  switch (s.kind) {
    case K::Box:
      r.allowOnly({"shape", "min", "max", "velocity"}, forKind);
      s.min = r.vec3("min", kCoordinate);
      s.max = r.vec3("max", kCoordinate);
      requireOrderedCorners(r, s.min, s.max);
      break;
    case K::Sphere:
      r.allowOnly({"shape", "center", "radius", "velocity"}, forKind);
      s.center = r.vec3("center", kCoordinate);
      s.radius = r.number("radius", kLength);
      break;
    case K::Plane:
      r.allowOnly({"shape", "point", "normal", "velocity"}, forKind);
      s.point = r.vec3("point", kCoordinate);
      s.normal = r.direction("normal");
      break;
    case K::Mesh:
      r.allowOnly({"shape", "file", "scale", "rotation_degrees", "translation", "velocity"}, forKind);
      s.meshPath = resolveMeshFile(r);
      s.placement.scale = r.number("scale", kScale, 1.0);
      s.placement.rotationDegrees = r.vec3("rotation_degrees", kAngle, Vec3d(0.0));
      s.placement.translation = r.vec3("translation", kCoordinate, Vec3d(0.0));
      break;
  }
  s.velocity = r.vec3("velocity", kVelocity, Vec3d(0.0));
  return s;
}

/// Initial liquid must touch the domain, or the scene starts empty by mistake. (Meshes are not
/// checked here: their extent is only known once the OBJ file is read.)
void requireLiquidInDomain(const ShapeDesc& s, const Scene& scene, const Context& ctx, const std::string& path) {
  const bool outside =
      (s.kind == ShapeDesc::Kind::Box && !boxesOverlap(s.min, s.max, scene.domainMin, scene.domainMax)) ||
      (s.kind == ShapeDesc::Kind::Sphere && distanceToBox(s.center, scene.domainMin, scene.domainMax) >= s.radius);
  if (outside)
    fail(ctx, path, std::string("expected a ") + toString(s.kind) + " overlapping the domain " +
                        boxText(scene.domainMin, scene.domainMax) + ", but it lies entirely outside");
}

void parseShapes(const ObjectReader& root, const char* key, ShapeRole role, Scene& scene) {
  auto& out = role == ShapeRole::Liquid ? scene.liquid : scene.solids;
  root.forEachItem(key, [&](const json& item, const std::string& path) {
    out.push_back(parseShape(item, root.context(), path, role));
    if (role == ShapeRole::Liquid) requireLiquidInDomain(out.back(), scene, root.context(), path);
  });
}

EmitterDesc parseEmitter(const json& v, const Context& ctx, const std::string& path, const Scene& scene) {
  const ObjectReader r(v, ctx, path, "an emitter object {\"shape\": ...}");
  using K = EmitterDesc::Kind;
  EmitterDesc e;
  e.kind = r.choice<K>("shape", {{"disc", K::Disc}, {"box", K::Box}});
  if (e.kind == K::Disc) {
    r.allowOnly({"shape", "center", "radius", "normal", "thickness", "velocity", "start", "stop"}, " for a disc");
    e.center = r.vec3("center", kCoordinate);
    e.radius = r.number("radius", kLength);
    e.normal = r.direction("normal");
    e.thickness = r.number("thickness", kLength, scene.dx());
    if (distanceToBox(e.center, scene.domainMin, scene.domainMax) > 0.0)
      fail(ctx, r.pathOf("center"), "expected a point inside the domain " + boxText(scene.domainMin, scene.domainMax));
  } else {
    r.allowOnly({"shape", "min", "max", "velocity", "start", "stop"}, " for a box");
    e.min = r.vec3("min", kCoordinate);
    e.max = r.vec3("max", kCoordinate);
    requireOrderedCorners(r, e.min, e.max);
    if (!boxesOverlap(e.min, e.max, scene.domainMin, scene.domainMax))
      fail(ctx, path, "expected a box overlapping the domain " + boxText(scene.domainMin, scene.domainMax) +
                          ", but it lies entirely outside");
  }
  e.velocity = r.vec3("velocity", kVelocity);
  e.start = r.number("start", kTime, 0.0);
  if (r.has("stop")) {
    e.stop = r.number("stop", kTime);
    if (!(e.stop > e.start))
      fail(ctx, r.pathOf("stop"), "expected a time after start (" + formatNumber(e.start) + " s), got " +
                                      formatNumber(e.stop));
  }
  return e;
}

void parseEmitters(const ObjectReader& root, Scene& scene) {
  root.forEachItem("emitters", [&](const json& item, const std::string& path) {
    scene.emitters.push_back(parseEmitter(item, root.context(), path, scene));
  });
}

void parseOutput(const ObjectReader& r, OutputDesc& o) {
  r.allowOnly(
      {"particles", "preview", "preview_width", "preview_height", "camera", "checkpoint_every", "mesh",
       "mesh_subdivisions", "up_axis"});
  o.mesh = r.boolean("mesh", o.mesh);
  o.meshSubdivisions = static_cast<int>(r.integer("mesh_subdivisions", kMeshSubdivisions, o.meshSubdivisions));
  o.zUp = r.choice<bool>("up_axis", {{"y", false}, {"z", true}}, o.zUp);
  o.checkpointEvery = static_cast<int>(r.integer("checkpoint_every", kCheckpointEvery, o.checkpointEvery));
  o.particles = r.boolean("particles", o.particles);
  o.preview = r.boolean("preview", o.preview);
  o.previewWidth = static_cast<int>(r.integer("preview_width", kPixels, o.previewWidth));
  o.previewHeight = static_cast<int>(r.integer("preview_height", kPixels, o.previewHeight));
  if (const auto camera = r.optionalObject("camera", "an object {\"eye\": [x, y, z], \"target\": [x, y, z]}")) {
    camera->allowOnly({"eye", "target"});
    CameraDesc c;
    c.eye = camera->vec3("eye", kCoordinate);
    c.target = camera->vec3("target", kCoordinate);
    if ((c.eye - c.target).length() <= 0.0)
      fail(r.context(), camera->pathOf("target"), "expected a target different from the eye position");
    o.camera = c;
  }
}

/// The file's value, or the override checked against the same range.
int resolutionOrOverride(const ObjectReader& root, const char* key, const IntRange& range,
                         const std::optional<int>& override) {
  if (!override) return static_cast<int>(root.integer(key, range));
  if (root.has(key)) root.integer(key, range);  // the file's own value is still checked
  return static_cast<int>(readInteger(json(*override), root.context(), std::string(key) + " (override)", range));
}

void requireSomeLiquid(const ObjectReader& root, const Scene& s) {
  if (s.liquid.empty() && s.emitters.empty())
    fail(root.context(), "liquid",
         "expected at least one liquid shape or emitter (the scene has neither \"liquid\" nor \"emitters\")");
}

// ---- JSON text ----------------------------------------------------------------------------------

/// SAX handler that builds the DOM (nlohmann's own builder) and rejects duplicate keys, which the
/// DOM parser would otherwise resolve silently by keeping the last value.
class StrictSax {
 public:
  using Dom = nlohmann::detail::json_sax_dom_parser<json>;
  explicit StrictSax(json& root) : dom_(root) {}

  bool null() { return value() && dom_.null(); }
  bool boolean(bool v) { return value() && dom_.boolean(v); }
  bool number_integer(json::number_integer_t v) { return value() && dom_.number_integer(v); }
  bool number_unsigned(json::number_unsigned_t v) { return value() && dom_.number_unsigned(v); }
  bool number_float(json::number_float_t v, const std::string& s) { return value() && dom_.number_float(v, s); }
  bool string(std::string& v) { return value() && dom_.string(v); }
  bool binary(json::binary_t& v) { return value() && dom_.binary(v); }
  bool start_object(std::size_t n) {
    value();
    frames_.push_back({false, {}, {}, 0});
    return dom_.start_object(n);
  }
  bool end_object() {
    frames_.pop_back();
    return dom_.end_object();
  }
  bool start_array(std::size_t n) {
    value();
    frames_.push_back({true, {}, {}, 0});
    return dom_.start_array(n);
  }
  bool end_array() {
    frames_.pop_back();
    return dom_.end_array();
  }
  bool key(std::string& k) {
    Frame& f = frames_.back();
    f.lastKey = k;
    if (!f.keys.insert(k).second) {
      duplicatePath_ = currentPath();
      return false;  // stops the parse
    }
    return dom_.key(k);
  }
  template <class Exception>
  bool parse_error(std::size_t position, const std::string& token, const Exception& ex) {
    return dom_.parse_error(position, token, ex);
  }

  const std::string& duplicatePath() const { return duplicatePath_; }

  /// Path of the value being read when the parser stopped (the next element or the last key).
  std::string pendingValuePath() const {
    std::string path;
    for (std::size_t i = 0; i < frames_.size(); ++i) {
      const Frame& f = frames_[i];
      const bool last = i + 1 == frames_.size();
      path = f.isArray ? itemPath(path, last ? f.index : f.index - 1) : childPath(path, f.lastKey);
    }
    return path;
  }

 private:
  struct Frame {
    bool isArray;
    std::set<std::string> keys;
    std::string lastKey;
    std::size_t index;
  };

  /// Counts array elements so that paths can name them.
  bool value() {
    if (!frames_.empty() && frames_.back().isArray) ++frames_.back().index;
    return true;
  }

  std::string currentPath() const {
    std::string path;
    for (const Frame& f : frames_)
      path = f.isArray ? itemPath(path, f.index - 1) : childPath(path, f.lastKey);
    return path;
  }

  Dom dom_;
  std::vector<Frame> frames_;
  std::string duplicatePath_;
};

/// Line and column (1-based) of a byte offset.
std::pair<std::size_t, std::size_t> lineColumn(const std::string& text, std::size_t byte) {
  std::size_t line = 1, column = 1;
  for (std::size_t i = 0; i < std::min(byte, text.size()); ++i) {
    if (text[i] == '\n') ++line, column = 1;
    else ++column;
  }
  return {line, column};
}

/// nlohmann quotes everything it read of a bad token ("last read: '<whole string>'"); keep the end.
std::string shortenedLastRead(std::string what) {
  constexpr std::size_t kKept = 40;
  const std::string marker = "last read: '";
  const std::size_t start = what.find(marker);
  if (start == std::string::npos) return what;
  const std::size_t from = start + marker.size();
  std::size_t to = what.rfind("'; expected");
  if (to == std::string::npos || to < from) to = what.size() - (what.back() == '\'' ? 1 : 0);
  if (to - from > kKept) what.replace(from, to - from - kKept, "...");
  return what;
}

json parseJsonText(const std::string& text, const Context& ctx) {
  json root;
  StrictSax sax(root);
  try {
    json::sax_parse(text, &sax);
  } catch (const json::parse_error& e) {
    const std::string what = shortenedLastRead(e.what());
    const std::size_t detail = what.find("syntax error");
    const std::size_t byte = e.byte > 0 ? e.byte - 1 : 0;  // nlohmann counts from 1
    const auto [line, column] = lineColumn(text, byte);
    throw SceneError(ctx.source + ": line " + std::to_string(line) + ", column " + std::to_string(column) +
                     " (byte " + std::to_string(byte) + "): JSON " +
                     (detail == std::string::npos ? std::string("error: ") + what : what.substr(detail)));
  } catch (const json::out_of_range& e) {  // a number literal beyond the range of a double
    const std::string what = e.what();
    const std::size_t detail = what.find("] ");
    fail(ctx, sax.pendingValuePath(),
         "expected a number, got " + (detail == std::string::npos ? what : what.substr(detail + 2)));
  } catch (const json::exception& e) {
    throw SceneError(ctx.source + ": invalid JSON: " + e.what());
  }
  if (!sax.duplicatePath().empty())
    fail(ctx, sax.duplicatePath(), "duplicate key (each key may appear once per object)");
  return root;
}

Scene parseWithContext(const json& j, const Context& ctx, const SceneOverrides& overrides) {
  const ObjectReader root(j, ctx, "", "a JSON object {\"name\": ..., \"domain\": ..., ...}");
  // "$schema": the JSON Schema editors check the file against (scenes/scene.schema.json); ignored
  root.allowOnly({"$schema", "name", "description", "domain", "resolution", "frames", "fps", "cfl", "max_substeps",
                  "material", "gravity", "viscosity", "model", "solver", "particles_per_cell_axis", "reseed",
                  "keep_volume", "volume_control", "liquid", "solids", "emitters", "output", "seed"});
  Scene s;
  s.name = root.string("name");
  s.description = root.string("description", TextKind::Paragraph, "");
  parseDomain(root.object("domain", "an object {\"min\": [x, y, z], \"max\": [x, y, z]}"), s);
  s.resolution = resolutionOrOverride(root, "resolution", kResolution, overrides.resolution);
  s.frames = resolutionOrOverride(root, "frames", kFrames, overrides.frames);
  s.fps = root.number("fps", kFps, s.fps);
  s.cfl = root.number("cfl", kCfl, s.cfl);
  s.maxSubsteps = static_cast<int>(root.integer("max_substeps", kSubsteps, s.maxSubsteps));
  parseMaterial(root.object("material", "an object {\"density\": rho, \"viscosity\": mu}"), s);
  s.gravity = root.optionalVec3("gravity", kAcceleration);
  s.viscosity = root.choice<ViscosityMode>(
      "viscosity",
      {{"coupled", ViscosityMode::Coupled}, {"decoupled", ViscosityMode::Decoupled}, {"none", ViscosityMode::None}},
      ViscosityMode::Coupled);
  if (const auto model = root.optionalObject("model", "an object {\"type\": ...}")) parseModel(*model, s.model);
  if (const auto solver = root.optionalObject("solver", "an object {\"tolerance\": ...}")) parseSolver(*solver, s.solver);
  s.particlesPerCellAxis = static_cast<int>(root.integer("particles_per_cell_axis", kParticlesPerAxis, 2));
  s.reseed = root.boolean("reseed", s.reseed);
  s.keepVolume = root.boolean("keep_volume", s.keepVolume);
  s.volumeControl = root.number("volume_control", kFraction, s.volumeControl);
  parseShapes(root, "liquid", ShapeRole::Liquid, s);
  parseShapes(root, "solids", ShapeRole::Solid, s);
  parseEmitters(root, s);
  requireSomeLiquid(root, s);
  if (const auto output = root.optionalObject("output", "an object {\"preview\": ...}")) parseOutput(*output, s.output);
  s.seed = static_cast<std::uint64_t>(root.integer("seed", kSeed, 1));
  return s;
}

}  // namespace

// ---- public API ---------------------------------------------------------------------------------

double Scene::dx() const {
  const Vec3d extent = domainMax - domainMin;
  return std::max({extent[0], extent[1], extent[2]}) / resolution;
}

openvdb::Coord Scene::resolutionCells() const {
  const Vec3d extent = domainMax - domainMin;
  const double longest = std::max({extent[0], extent[1], extent[2]});
  const double h = dx();
  openvdb::Coord cells;
  for (int a = 0; a < 3; ++a)
    cells[a] = extent[a] == longest ? resolution : std::max(1, static_cast<int>(std::lround(extent[a] / h)));
  return cells;
}

Scene parseScene(const json& j, const std::string& sourceName, const std::string& baseDir,
                 const SceneOverrides& overrides) {
  return parseWithContext(j, Context{sourceName, baseDir}, overrides);
}

Scene parseSceneText(const std::string& text, const std::string& sourceName, const std::string& baseDir,
                     const SceneOverrides& overrides) {
  const Context ctx{sourceName, baseDir};
  return parseWithContext(parseJsonText(text, ctx), ctx, overrides);
}

Scene loadScene(const std::string& path, const SceneOverrides& overrides) {
  std::error_code ec;
  const fs::file_status status = fs::status(path, ec);
  if (ec || !fs::exists(status)) throw SceneError(path + ": cannot open the scene file: no such file");
  if (!fs::is_regular_file(status)) throw SceneError(path + ": cannot open the scene file: not a regular file");
  const std::uintmax_t size = fs::file_size(path, ec);
  if (ec || size > kMaxSceneFileBytes)
    throw SceneError(path + ": the scene file is larger than " + std::to_string(kMaxSceneFileBytes) +
                     " bytes; scene files describe shapes, not data");
  std::ifstream in(path, std::ios::binary);
  std::ostringstream text;
  if (!(in && text << in.rdbuf())) throw SceneError(path + ": cannot read the scene file");
  Scene s = parseSceneText(text.str(), path, fs::path(path).parent_path().string(), overrides);
  s.sourcePath = path;
  return s;
}

const char* toString(ViscosityMode m) {
  switch (m) {
    case ViscosityMode::Coupled: return "coupled";
    case ViscosityMode::Decoupled: return "decoupled";
    case ViscosityMode::None: return "none";
  }
  return "?";
}

const char* toString(ModelType m) {
  switch (m) {
    case ModelType::Uniform: return "uniform";
    case ModelType::Affine: return "affine";
    case ModelType::Quadratic: return "quadratic";
  }
  return "?";
}

const char* toString(TileCache c) {
  switch (c) {
    case TileCache::None: return "none";
    case TileCache::Library: return "library";
    case TileCache::Shapes: return "shapes";
  }
  return "?";
}

const char* toString(PreconditionerType p) {
  switch (p) {
    case PreconditionerType::None: return "none";
    case PreconditionerType::Jacobi: return "jacobi";
    case PreconditionerType::Multigrid: return "multigrid";
  }
  return "?";
}

}  // namespace stokes::sim
