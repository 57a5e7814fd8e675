#pragma once
// The coarse levels of a geometric multigrid on the velocity faces, built over MPI ranks for
// PETSc's PCMG (DistributedSystem::fieldZeroLevels): the distributed counterpart of the in-house
// Galerkin velocity cycle (solver/multigrid/galerkin_cycle.h), with the same transfers.
//
// Level 0 is each rank's owned face rows, (axis a, cell c) in the order of its rows. Level l + 1
// holds every coarse face that P_l reaches from any rank's rows of level l, where P_l is the
// staggered prolongation of sparse_grid/grid_transfer.h (forEachProlongationTerm) on global cell
// coordinates: no rank needs a coarse layout, and no coarse face is unreached (an unreached one
// would be a zero row of P_l^T A_l P_l). Coarse blocks (8^Dim coarse cells) get owners by the one
// partition rule (sparse_grid::blockOwners, weighted by the faces the ranks reach there), and an
// owner numbers the faces reached in its blocks (block order, then axis, then slot), as BlockRows
// numbers the fine rows. Per level: one gather of the reached blocks' origins and counts, the
// reached faces to their owners (a bitmap per block), each block's first number and merged
// bitmap back. The coarse operators A_{l+1} = P_l^T A_l P_l are PETSc's (PCMG's Galerkin option).
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <unordered_map>
#include <utility>
#include <vector>

#include "solver/petsc/block_rows.h"
#include "solver/petsc/petsc_krylov.h"
#include "sparse_grid/block_layout.h"
#include "sparse_grid/block_order.h"
#include "sparse_grid/grid_transfer.h"

namespace stokes::solver::petsc {

/// A face sample on global cell coordinates of its level: the face of axis `axis` of `cell`.
struct FaceSample {
  int axis = 0;
  sparse_grid::Coord cell;
};

template <int Dim>
class FaceLevels {
 public:
  using Layout = sparse_grid::BlockLayout<Dim>;
  static constexpr int kWidth = Layout::kWidth;
  static constexpr std::size_t kSlots = Layout::kSlots;
  static constexpr std::size_t kWords = (kSlots + 63) / 64;  // a bitmap of one axis in one block
  static constexpr std::size_t kBitmapWords = Dim * kWords;

  /// Coarsens `fine` (this rank's owned face rows, in its row order) until a level has at most
  /// `coarsestRows` rows over all ranks, shrinks by less than a quarter, or `maxLevels` levels
  /// exist; P_0 interpolates across the face normals by `finest`, the coarser transfers by
  /// `coarser`. Collective.
  FaceLevels(std::vector<FaceSample> fine, sparse_grid::CellAxes finest, sparse_grid::CellAxes coarser,
             std::int64_t coarsestRows, int maxLevels) {
    std::vector<FaceSample> rows = std::move(fine);
    std::int64_t globalRows = std::llround(sumOverRanks(double(rows.size())));
    while (int(transfers_.size()) + 1 < maxLevels && globalRows > coarsestRows) {
      std::vector<FaceSample> coarse;
      Interpolation p = coarsen(rows, transfers_.empty() ? finest : coarser, coarse);
      const std::int64_t coarseRows = std::llround(sumOverRanks(double(coarse.size())));
      if (4 * coarseRows > 3 * globalRows) break;
      transfers_.push_back(std::move(p));
      coarseRows_.push_back(coarse);
      rows = std::move(coarse);
      globalRows = coarseRows;
    }
  }

  /// P_0, P_1, ...: finest first.
  std::vector<Interpolation>& transfers() { return transfers_; }
  /// The rows of level l + 1 this rank owns, in their numbers' order (P_l's columns from
  /// transfers()[l].coarseFirst on).
  const std::vector<FaceSample>& coarseRows(std::size_t l) const { return coarseRows_[l]; }

 private:
  // A block origin (multiples of kWidth) packed into one word, 21 bits an axis.
  static std::uint64_t pack(const sparse_grid::Coord& o) {
    std::uint64_t key = 0;
    for (int a = 0; a < 3; ++a) key = key << 21 | (std::uint64_t(std::int64_t(o[a] / kWidth) + (1 << 20)) & 0x1FFFFF);
    return key;
  }
  static sparse_grid::Coord originOf(const sparse_grid::Coord& c) {
    sparse_grid::Coord o(0, 0, 0);
    for (int a = 0; a < Dim; ++a) o[a] = c[a] & ~(kWidth - 1);  // floors negatives
    return o;
  }
  static int slotIn(const sparse_grid::Coord& c, const sparse_grid::Coord& origin) {
    return Layout::localSlot(c[0] - origin[0], c[1] - origin[1], Dim == 3 ? c[2] - origin[2] : 0);
  }

  // The blocks this rank's rows reach on the coarse level, and the faces they reach there.
  struct Reached {
    std::vector<sparse_grid::Coord> origin;
    std::vector<std::uint64_t> bitmap;  // kBitmapWords per block: axis-major, slot bits
    std::unordered_map<std::uint64_t, std::uint32_t> index;
    std::uint32_t blockOf(const sparse_grid::Coord& o) {
      const auto [it, inserted] = index.emplace(pack(o), std::uint32_t(origin.size()));
      if (inserted) {
        origin.push_back(o);
        bitmap.resize(bitmap.size() + kBitmapWords, 0);
      }
      return it->second;
    }
  };

  // P from the next coarser level onto `rows`, and that level's rows owned here (`coarse`).
  Interpolation coarsen(const std::vector<FaceSample>& rows, sparse_grid::CellAxes across,
                        std::vector<FaceSample>& coarse) const {
    // P's terms, each (reached block, axis * kSlots + slot, weight)
    Reached reached;
    std::vector<std::uint32_t> termBlock, termSample;
    Interpolation p;
    for (const FaceSample& f : rows) {
      sparse_grid::forEachProlongationTerm<Dim>(
          f.cell, sparse_grid::faceMask(f.axis), across, [&](const sparse_grid::Coord& c, double w) {
            const sparse_grid::Coord o = originOf(c);
            const std::uint32_t b = reached.blockOf(o);
            const std::uint32_t sample = std::uint32_t(f.axis) * kSlots + std::uint32_t(slotIn(c, o));
            reached.bitmap[b * kBitmapWords + sample / 64] |= std::uint64_t(1) << (sample % 64);
            termBlock.push_back(b), termSample.push_back(sample), p.values.push_back(w);
          });
      p.rowStart.push_back(std::int64_t(p.values.size()));
    }

    // every reached block and its owner (the same list and rule on every rank)
    std::vector<sparse_grid::Coord> origins;
    std::vector<std::size_t> weights;
    allReachedBlocks(reached, origins, weights);
    const std::vector<int> owner = sparse_grid::blockOwners<Dim>(origins, weights, ranks());
    auto globalBlock = [&](const sparse_grid::Coord& o) {
      const auto it = std::lower_bound(origins.begin(), origins.end(), o);
      if (it == origins.end() || *it != o) throw std::logic_error("FaceLevels: a block no rank reached");
      return std::size_t(it - origins.begin());
    };
    std::vector<int> ownerOfReached(reached.origin.size());
    for (std::size_t t = 0; t < reached.origin.size(); ++t) ownerOfReached[t] = owner[globalBlock(reached.origin[t])];

    // the reached faces to the blocks' owners, merged there
    const int me = rank();
    std::vector<std::size_t> mine;  // blocks owned here, in the list's order
    for (std::size_t b = 0; b < origins.size(); ++b)
      if (owner[b] == me) mine.push_back(b);
    std::vector<std::uint64_t> merged(mine.size() * kBitmapWords, 0);
    auto mineOf = [&](std::size_t b) {
      return std::size_t(std::lower_bound(mine.begin(), mine.end(), b) - mine.begin());
    };
    constexpr int kKeyWords = 3 + 2 * int(kBitmapWords);
    std::vector<std::vector<std::int32_t>> asks(static_cast<std::size_t>(ranks()));
    for (std::size_t t = 0; t < reached.origin.size(); ++t) {
      std::vector<std::int32_t>& a = asks[std::size_t(ownerOfReached[t])];
      for (int k = 0; k < 3; ++k) a.push_back(reached.origin[t][k]);
      for (std::size_t w = 0; w < kBitmapWords; ++w) {
        const std::uint64_t word = reached.bitmap[t * kBitmapWords + w];
        a.push_back(std::int32_t(std::uint32_t(word))), a.push_back(std::int32_t(std::uint32_t(word >> 32)));
      }
    }
    askRanks(asks, kKeyWords, 0, [&](const std::int32_t* key, std::uint64_t*) {
      std::uint64_t* bits = merged.data() + mineOf(globalBlock(sparse_grid::Coord(key[0], key[1], key[2]))) * kBitmapWords;
      for (std::size_t w = 0; w < kBitmapWords; ++w)
        bits[w] |= std::uint64_t(std::uint32_t(key[3 + 2 * w])) | std::uint64_t(std::uint32_t(key[4 + 2 * w])) << 32;
    });

    // the owner numbers its blocks' faces: block, axis, slot
    std::size_t count = 0;
    for (std::uint64_t w : merged) count += std::size_t(std::popcount(w));
    p.coarseOwned = count;
    p.coarseFirst = std::int64_t(sumOverEarlierRanks(count));
    std::vector<std::int64_t> firstOfMine(mine.size());
    std::int64_t next = p.coarseFirst;
    for (std::size_t m = 0; m < mine.size(); ++m) {
      firstOfMine[m] = next;
      for (std::size_t s = 0; s < kBitmapWords * 64; ++s) {
        if (!(merged[m * kBitmapWords + s / 64] >> (s % 64) & 1)) continue;
        ++next;
        const sparse_grid::Coord local = Layout::localCoord(int(s % kSlots));
        coarse.push_back({int(s / kSlots), origins[mine[m]] + local});
      }
    }

    // each reached block's first number and merged bitmap, from its owner
    std::vector<std::vector<std::int32_t>> query(static_cast<std::size_t>(ranks()));
    std::vector<std::vector<std::uint32_t>> asked(static_cast<std::size_t>(ranks()));
    for (std::size_t t = 0; t < reached.origin.size(); ++t) {
      const int r = ownerOfReached[t];
      for (int k = 0; k < 3; ++k) query[std::size_t(r)].push_back(reached.origin[t][k]);
      asked[std::size_t(r)].push_back(std::uint32_t(t));
    }
    const std::vector<std::vector<std::uint64_t>> replies =
        askRanks(query, 3, 1 + int(kBitmapWords), [&](const std::int32_t* key, std::uint64_t* record) {
          const std::size_t m = mineOf(globalBlock(sparse_grid::Coord(key[0], key[1], key[2])));
          record[0] = std::uint64_t(firstOfMine[m]);
          std::copy_n(merged.begin() + std::ptrdiff_t(m * kBitmapWords), kBitmapWords, record + 1);
        });
    std::vector<const std::uint64_t*> recordOf(reached.origin.size());
    for (std::size_t r = 0; r < asked.size(); ++r)
      for (std::size_t i = 0; i < asked[r].size(); ++i)
        recordOf[asked[r][i]] = replies[r].data() + i * (1 + kBitmapWords);

    // P's columns: a block's first number plus the reached faces before the term's
    p.columns.resize(termBlock.size());
    for (std::size_t k = 0; k < termBlock.size(); ++k) {
      const std::uint64_t* record = recordOf[termBlock[k]];
      p.columns[k] = std::int64_t(record[0]) + setBitsBefore(record + 1, termSample[k]);
    }
    return p;
  }

  // Every rank's reached blocks, merged: origins in coordinate order, the faces reached there
  // summed over the ranks (faces reached from two ranks count twice: only a weight for the cut).
  static void allReachedBlocks(const Reached& reached, std::vector<sparse_grid::Coord>& origins,
                               std::vector<std::size_t>& weights) {
    std::vector<double> mine;
    for (std::size_t t = 0; t < reached.origin.size(); ++t) {
      std::size_t faces = 0;
      for (std::size_t w = 0; w < kBitmapWords; ++w) faces += std::size_t(std::popcount(reached.bitmap[t * kBitmapWords + w]));
      for (int a = 0; a < 3; ++a) mine.push_back(double(reached.origin[t][a]));
      mine.push_back(double(faces));
    }
    const std::vector<double> all = allGather(mine.data(), mine.size());
    std::vector<std::pair<sparse_grid::Coord, std::size_t>> blocks;
    for (std::size_t k = 0; k + 3 < all.size(); k += 4)
      blocks.push_back({sparse_grid::Coord(int(all[k]), int(all[k + 1]), int(all[k + 2])), std::size_t(all[k + 3])});
    std::sort(blocks.begin(), blocks.end(), [](const auto& x, const auto& y) { return x.first < y.first; });
    for (const auto& [o, faces] : blocks) {
      if (!origins.empty() && origins.back() == o) weights.back() += faces;
      else origins.push_back(o), weights.push_back(faces);
    }
  }

  std::vector<Interpolation> transfers_;
  std::vector<std::vector<FaceSample>> coarseRows_;
};

}  // namespace stokes::solver::petsc
