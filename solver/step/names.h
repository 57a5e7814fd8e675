#pragma once
// One table of names per option enum: the key a user writes (command line, scene file, JSON
// schema) and the label a report prints (start line, stats.csv, diagnostics). Every reader and
// writer of a name goes through the table, so a value is spelt once.
//
// An enum E opts in with `constexpr std::span<const NamedValue<E>> namesOf(E)` next to it, listing
// every value in declaration order (found by argument-dependent lookup).
#include <cstddef>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace stokes::solver {
inline namespace step {

template <class E>
struct NamedValue {
  E value;
  const char* key;    ///< what a user writes: "jacobi", "pv", ...
  const char* label;  ///< what a report prints: "Jacobi", "pressure-velocity", ...
};

/// True when `table` lists the values 0, 1, ..., size-1 in order (checked by static_assert next
/// to each table, so that a new enumerator without a name fails to compile).
template <class E, std::size_t N>
constexpr bool listsEveryValueInOrder(const NamedValue<E> (&table)[N], E last) {
  for (std::size_t i = 0; i < N; ++i)
    if (static_cast<std::size_t>(table[i].value) != i) return false;
  return static_cast<std::size_t>(last) + 1 == N;
}

template <class E>
constexpr const NamedValue<E>& entryOf(E value) {
  const auto table = namesOf(value);
  return table[static_cast<std::size_t>(value)];
}

/// The key a user writes for `value`.
template <class E>
constexpr const char* keyOf(E value) {
  return entryOf(value).key;
}

/// The label a report prints for `value`.
template <class E>
constexpr const char* labelOf(E value) {
  return entryOf(value).label;
}

/// The label of any named option value (reports, messages): toString(PreconditionerKind::Jacobi)
/// is "Jacobi".
template <class E>
  requires requires(E e) { namesOf(e); }
constexpr const char* toString(E value) {
  return labelOf(value);
}

/// Every key of E, in declaration order.
template <class E>
std::vector<std::string> keysOf() {
  std::vector<std::string> keys;
  for (const NamedValue<E>& v : namesOf(E{})) keys.emplace_back(v.key);
  return keys;
}

/// "a, b or c": the keys of E for a message.
template <class E>
std::string keyList() {
  const std::vector<std::string> keys = keysOf<E>();
  std::string s;
  for (std::size_t i = 0; i < keys.size(); ++i) s += (i == 0 ? "" : i + 1 == keys.size() ? " or " : ", ") + keys[i];
  return s;
}

/// The value whose key is `key`, or nullopt.
template <class E>
std::optional<E> valueOf(std::string_view key) {
  for (const NamedValue<E>& v : namesOf(E{}))
    if (key == v.key) return v.value;
  return std::nullopt;
}

/// The value whose key is `key`; std::invalid_argument "unknown <what> '<key>' (a, b or c)" else.
template <class E>
E parseKey(std::string_view key, const char* what) {
  if (const std::optional<E> v = valueOf<E>(key)) return *v;
  throw std::invalid_argument("unknown " + std::string(what) + " '" + std::string(key) + "' (" + keyList<E>() + ")");
}

}  // namespace step
}  // namespace stokes::solver
