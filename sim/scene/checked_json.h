#pragma once
// The checked JSON reader behind scene files (sim/scene/scene.h): typed values with ranges, names
// from an enum's table (solver/step/names.h), objects whose keys are checked against an allowed
// list (with a "did you mean" for a near miss), and messages that name the file, the key path and
// what was expected. Every problem is a SceneError.
#include <nlohmann/json.hpp>

#include <cstddef>
#include <cstdint>
#include <initializer_list>
#include <optional>
#include <string>
#include <string_view>
#include <utility>

#include "sim/scene/scene.h"
#include "solver/step/names.h"

namespace stokes::sim {
inline namespace scene {

using nlohmann::json;

/// An admissible closed or half-open interval for a number, and how to say it. (Units are
/// documented in scenes/README.md: metres, seconds, kg/m^3, Pa s, degrees.)
struct Range {
  double lo, hi;
  bool loOpen = false;  ///< lo itself excluded (positive numbers)
};

/// An admissible integer interval.
struct IntRange {
  std::int64_t lo, hi;
};

/// Longest string value accepted (bytes), and most entries of an array.
inline constexpr std::size_t kMaxStringBytes = 4096;
inline constexpr std::size_t kMaxArrayItems = 10'000;

/// What a reader needs to phrase its messages and resolve files.
struct Context {
  std::string source;   ///< file name shown in messages
  std::string baseDir;  ///< directory that relative mesh paths are resolved against
};

enum class TextKind { Line, Paragraph };

/// "1e+300", "NaN", "64": a number as a message shows it.
std::string formatNumber(double v);
/// Short, printable rendering of an offending value for a message.
std::string describe(const json& v);
std::string describeRange(const Range& r, bool withUpperBound);
std::string describeRange(const IntRange& r);
/// The allowed key closest to `key`, or "" when none is plausibly meant.
std::string closestKey(const std::string& key, std::initializer_list<const char*> allowed);
std::string joined(std::initializer_list<const char*> items);

std::string childPath(const std::string& path, std::string_view key);
std::string itemPath(const std::string& path, std::size_t index);
/// Throws SceneError "<file>: <path>: <message>".
[[noreturn]] void fail(const Context& ctx, const std::string& path, const std::string& message);
[[noreturn]] void failExpected(const Context& ctx, const std::string& path, const std::string& expected,
                               const json& got);

double readNumber(const json& v, const Context& ctx, const std::string& path, const Range& r);
std::int64_t readInteger(const json& v, const Context& ctx, const std::string& path, const IntRange& r);
bool readBool(const json& v, const Context& ctx, const std::string& path);
std::string readString(const json& v, const Context& ctx, const std::string& path, TextKind kind);
Vec3d readVec3(const json& v, const Context& ctx, const std::string& path, const Range& r);
/// A non-zero direction, normalised.
Vec3d readDirection(const json& v, const Context& ctx, const std::string& path);

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

/// A value of an enum with a name table (solver/step/names.h): one of its keys, or with `orAuto`
/// also "auto", read as nullopt (the solver decides).
template <class E>
std::optional<E> readNamed(const json& v, const Context& ctx, const std::string& path, bool orAuto = false) {
  if (v.is_string()) {
    const std::string& text = v.get_ref<const std::string&>();
    if (orAuto && text == "auto") return std::nullopt;
    if (const std::optional<E> e = solver::valueOf<E>(text)) return *e;
  }
  std::string names = orAuto ? "\"auto\"" : "";
  for (const std::string& key : solver::keysOf<E>()) names += (names.empty() ? "\"" : ", \"") + key + "\"";
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
  /// An enum named by its table (solver/step/names.h), or `fallback` when the key is absent.
  template <class E>
  E named(const char* key, E fallback) const {
    return has(key) ? *readNamed<E>(v_.at(key), ctx_, pathOf(key)) : fallback;
  }
  /// An enum named by its table or "auto"; nullopt (the solver decides) for "auto" or when absent.
  template <class E>
  std::optional<E> namedOrAuto(const char* key) const {
    return has(key) ? readNamed<E>(v_.at(key), ctx_, pathOf(key), /*orAuto=*/true) : std::nullopt;
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
    if (a.size() > kMaxArrayItems)
      fail(ctx_, pathOf(key), "expected at most " + std::to_string(kMaxArrayItems) + " entries, got " +
                                  std::to_string(a.size()));
    for (std::size_t i = 0; i < a.size(); ++i) f(a[i], itemPath(pathOf(key), i));
  }

 private:
  const json& v_;
  const Context& ctx_;
  std::string path_;
};

}  // namespace scene
}  // namespace stokes::sim
