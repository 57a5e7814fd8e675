#pragma once
// Temporally consistent tiles (docs/design.md §3.8, "Temporally consistent tiles"): what the
// tiling of one step leaves to the next. Fixed-size tiles are a function of the region alone
// (sparse_grid/tiling.h): a region that did not change gives the same tile, and the library
// (tile_library.h) its factorisation. Adaptive tiles also read the step's velocity u* (the octree
// splits a cube where the polynomial misses it), so a cube whose region did not change could still
// split one step and merge the next. The history keeps each cube's decision with a fingerprint of
// the region it was taken on; the next step reuses it where the same cube holds the same cells,
// and decides afresh (fitting u*) elsewhere.
//
// The owner (the simulator) calls advance() after a step that succeeded and forgetRecorded() after
// one that failed; a checkpoint stores state() so that a resumed run decides as the uninterrupted
// one did.
#include <algorithm>
#include <array>
#include <cstdint>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <tuple>
#include <vector>

#include "sparse_grid/block_layout.h"

namespace stokes::solver {
inline namespace reduced {

/// A fingerprint of a set of cells that does not depend on their order (nor on the slots the
/// layout gives them): the sum of a 64-bit mix (splitmix64) of each cell's packed coordinates.
template <int Dim>
std::uint64_t cellSetFingerprint(const sparse_grid::BlockLayout<Dim>& layout, const std::vector<std::size_t>& cells) {
  std::uint64_t sum = 0;
  for (std::size_t s : cells) {
    const auto c = layout.cellOf(s);
    std::uint64_t z = (std::uint64_t(std::uint32_t(c[0])) << 42) ^ (std::uint64_t(std::uint32_t(c[1])) << 21) ^
                      std::uint64_t(std::uint32_t(c[2]));
    z += 0x9e3779b97f4a7c15ull;
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    sum += z ^ (z >> 31);
  }
  return sum + cells.size();
}

class TileHistory {
 public:
  /// One octree decision: whether the cube of `edge` cells at `corner`, holding the region of
  /// fingerprint `region`, split.
  struct Decision {
    std::array<int, 3> corner{};
    int edge = 0;
    std::uint64_t region = 0;
    bool split = false;
    auto key() const { return std::tuple(corner, edge, region); }
  };
  /// What one step leaves: its decisions and its tiles' fingerprints, both sorted.
  struct State {
    std::vector<Decision> decisions;
    std::vector<std::uint64_t> tiles;

    /// The decisions as plain words (a Decision has padding bytes), 6 per decision: the corner,
    /// the edge, the region, the split; for checkpoints and messages. fromWords() reverses it.
    std::vector<std::int64_t> decisionWords() const {
      std::vector<std::int64_t> w;
      w.reserve(6 * decisions.size());
      for (const Decision& d : decisions)
        w.insert(w.end(), {d.corner[0], d.corner[1], d.corner[2], d.edge, std::int64_t(d.region), d.split ? 1 : 0});
      return w;
    }
    static State fromWords(const std::vector<std::int64_t>& words, std::vector<std::uint64_t> tiles) {
      if (words.size() % 6 != 0) throw std::invalid_argument("TileHistory: decision words not a multiple of 6");
      State s;
      for (std::size_t i = 0; i < words.size(); i += 6)
        s.decisions.push_back({{int(words[i]), int(words[i + 1]), int(words[i + 2])}, int(words[i + 3]),
                               std::uint64_t(words[i + 4]), words[i + 5] != 0});
      s.tiles = std::move(tiles);
      return s;
    }
  };

  /// The previous step's decision on this cube and region, if it took one.
  std::optional<bool> previousDecision(const std::array<int, 3>& corner, int edge, std::uint64_t region) const {
    const Decision probe{corner, edge, region, false};
    const auto it = std::lower_bound(previous_.decisions.begin(), previous_.decisions.end(), probe, byKey);
    if (it == previous_.decisions.end() || it->key() != probe.key()) return std::nullopt;
    return it->split;
  }
  /// Whether the previous step had a tile of these cells.
  bool hadTile(std::uint64_t fingerprint) const {
    return std::binary_search(previous_.tiles.begin(), previous_.tiles.end(), fingerprint);
  }

  /// Records this step's decision (thread-safe; a cube decided twice in one step, as the two solves
  /// of a decoupled step do, keeps the first).
  void record(const Decision& d) {
    std::lock_guard<std::mutex> lock(mutex_);
    next_.decisions.push_back(d);
  }
  void recordTile(std::uint64_t fingerprint) {
    std::lock_guard<std::mutex> lock(mutex_);
    next_.tiles.push_back(fingerprint);
  }

  /// This step's record becomes what the next step reads.
  void advance() {
    std::lock_guard<std::mutex> lock(mutex_);
    std::stable_sort(next_.decisions.begin(), next_.decisions.end(), byKey);
    next_.decisions.erase(std::unique(next_.decisions.begin(), next_.decisions.end(),
                                      [](const Decision& a, const Decision& b) { return a.key() == b.key(); }),
                          next_.decisions.end());
    std::sort(next_.tiles.begin(), next_.tiles.end());
    next_.tiles.erase(std::unique(next_.tiles.begin(), next_.tiles.end()), next_.tiles.end());
    previous_ = std::move(next_);
    next_ = {};
  }

  /// Drops what was recorded since the last advance() (a step that failed).
  void forgetRecorded() {
    std::lock_guard<std::mutex> lock(mutex_);
    next_ = {};
  }

  /// What the next step reads (for a checkpoint); restore() puts it back and forgets anything
  /// recorded since.
  const State& state() const { return previous_; }
  void restore(State s) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!std::is_sorted(s.decisions.begin(), s.decisions.end(), byKey) || !std::is_sorted(s.tiles.begin(), s.tiles.end()))
      throw std::invalid_argument("TileHistory::restore: the decisions and tiles must be sorted (as state() gives them)");
    previous_ = std::move(s);
    next_ = {};
  }

 private:
  static bool byKey(const Decision& a, const Decision& b) { return a.key() < b.key(); }

  mutable std::mutex mutex_;
  State previous_, next_;
};

}  // namespace reduced
}  // namespace stokes::solver
