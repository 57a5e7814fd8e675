#pragma once
// The pressure-stress system (pressure_stress_system.h; thesis Eq. 4.20-4.25) split over MPI ranks
// for the PETSc backend (petsc_krylov.h).
//
// Partition. The unknowns are the system's live rows (positive diagonal, as in the in-house
// compact solve). Every block of the layout has an owner rank, which owns every live row
// (pressure and all stress channels) of it. A problem distributed by blocks names the owners
// (StaggeredProblem::blockOwner: each rank holds its own blocks and a halo); for a whole problem
// held by every rank they are cut here by the same rule, equal runs of active cells in recursive
// coordinate bisection order (sparse_grid/block_order.h, blockOwners), so that both number the
// rows alike and give the same bits. The global numbering is rank-major, and within a rank block-major
// in the rank's block order, each block's rows channel by channel ([p | tau_0 | tau_1 | ...]) in
// slot order: a row's number is its block's first number plus its place among the block's live
// rows.
//
// Ghosts. A rank's rows read K x on the faces of their stencils (forEachPressureFace /
// forEachStressFace); K x on an unknown face reads the samples of that face's column
// (forEachSampleOfFace); on a tile's coupling face, the tile couples all of its coupling faces
// (J^T B^-1 J), so every sample of those faces is read too. The velocities of the owned blocks'
// faces read the same columns. Those samples are the ghost rows that the MatShell gathers before
// each apply; the apply then runs the compact neighbour-index stencils (pressure_stress_rows.h)
// over the rank's samples and those faces only. (The padded block kernels over the rank's
// blocks, PressureStressSystem::applyOnBlocks, give the same numbers bit for bit, tested, but
// sweep every slot of every block: 2.9x slower on the 64^3 ball.) A ghost's number comes from
// its block's owner: each rank asks the owners of the blocks its ghosts lie in for the block's
// first number and its live rows (a bitmap per channel), so that no rank needs the others' rows.
//
// Assembled part. K^T S K + C is assembled exactly from the stencil entries
// (kernels/stencil_entries.h) over the Cartesian unknown faces; the reduced tiles' coupling
// K^T J^T B^-1 J K, which is dense over each tile's coupling samples, enters only through its
// diagonal (the system's exact diagonal). Without tiles the assembled matrix is A itself.
#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <utility>
#include <vector>

#include "kernels/stencil_entries.h"
#include "solver/krylov/compact_rows.h"
#include "solver/petsc/petsc_krylov.h"
#include "solver/systems/pressure_stress_rows.h"
#include "solver/systems/pressure_stress_system.h"
#include "solver/krylov/stopwatch.h"
#include "sparse_grid/block_order.h"

namespace stokes::solver::petsc {

template <int Dim>
class PressureStressRanks {
 public:
  using SC = StressChannels<Dim>;
  static constexpr std::size_t kSlots = BlockLayout<Dim>::kSlots;
  static constexpr std::size_t kBitmapWords = (kSlots + 63) / 64;

  /// `rows`: the system's live rows; `owner`: the rank of each of the layout's blocks. sys, its
  /// tiles and rows must outlive this object. Collective.
  PressureStressRanks(const PressureStressSystem<Dim>& sys, const RowSelection& rows, std::vector<std::int32_t> owner,
                      int rank)
      : sys_(&sys), rows_(&rows), n_(sys.layout().numSlots()), rank_(rank), ownerOfBlock_(std::move(owner)) {
    if (ownerOfBlock_.size() != sys.layout().numBlocks())
      throw std::invalid_argument("PressureStressRanks: one owner per block");
    numberOwnedRows();
    collectStencilReach();
    numberGhostRows();
    buildDistributedSystem();
  }

  /// The owners of a whole problem's blocks on `ranks` ranks: equal runs of active cells
  /// (sparse_grid::blockOwners), as a problem set up per rank is cut.
  static std::vector<std::int32_t> owners(const BlockLayout<Dim>& layout, int ranks) {
    const std::vector<int> owner = sparse_grid::blockOwners<Dim>(layout, ranks);
    return std::vector<std::int32_t>(owner.begin(), owner.end());
  }

  DistributedSystem& system() { return dist_; }
  /// The live rows this rank owns (indices into the selection), in the global numbering's order.
  const std::vector<std::uint32_t>& ownedLive() const { return owned_; }
  std::size_t ownedBlocks() const { return rowBlocks_.size(); }
  std::size_t ghostRows() const { return dist_.ghostRows.size() - dist_.ownedRows; }

  /// Puts the rank's solution on the padded rows it reads: owned and ghost values (the
  /// ghostRows order), which give A x on its rows and the velocities of its blocks' faces.
  void scatterGhosts(const std::vector<double>& ghostValues, double* padded) const {
    for (std::size_t g = 0; g < ghostLive_.size(); ++g) padded[rows_->rows()[ghostLive_[g]]] = ghostValues[g];
  }

  /// Puts the global solution (rank-major, allGather's order) back on the padded rows. Only for a
  /// whole problem: every rank numbers every block (the owners' rule, applied locally).
  void scatterGlobal(const std::vector<double>& global, double* padded) const {
    const std::vector<RowSelection::Index>& live = rows_->rows();
    std::vector<std::vector<std::uint32_t>> rowsOfBlock(sys_->layout().numBlocks());
    for (std::size_t k = 0; k < live.size(); ++k) rowsOfBlock[blockOfSample(live[k])].push_back(std::uint32_t(k));
    std::size_t next = 0;
    const int ranks = 1 + *std::max_element(ownerOfBlock_.begin(), ownerOfBlock_.end());
    for (int r = 0; r < ranks; ++r)
      for (std::size_t b = 0; b < rowsOfBlock.size(); ++b)
        if (ownerOfBlock_[b] == r)
          for (std::uint32_t k : rowsOfBlock[b]) padded[live[k]] = global.at(next++);
    if (next != global.size()) throw std::logic_error("PressureStressRanks::scatterGlobal: the numbering is not the owners'");
  }

 private:
  std::size_t blockOfSample(std::size_t padded) const { return (padded % n_) / kSlots; }
  bool ownsBlock(std::size_t b) const { return ownerOfBlock_[b] == rank_; }
  int channels() const { return sys_->withStress() ? 1 + SC::kCount : 1; }

  // The rank's rows, block-major; their numbers start after the earlier ranks' rows.
  void numberOwnedRows() {
    const std::vector<RowSelection::Index>& live = rows_->rows();
    const std::size_t nb = sys_->layout().numBlocks();
    std::vector<std::vector<std::uint32_t>> rowsOfBlock(nb);
    for (std::size_t k = 0; k < live.size(); ++k)
      if (ownsBlock(blockOfSample(live[k]))) rowsOfBlock[blockOfSample(live[k])].push_back(std::uint32_t(k));
    globalOfLive_.assign(live.size(), -1);
    liveOfPadded_.assign(sys_->size(), -1);
    for (std::size_t k = 0; k < live.size(); ++k) liveOfPadded_[live[k]] = std::int64_t(k);
    std::size_t count = 0;
    for (const auto& r : rowsOfBlock) count += r.size();
    dist_.firstRow = std::int64_t(sumOverEarlierRanks(count));
    dist_.globalRows = std::int64_t(std::llround(sumOverRanks(double(count))));
    blockStart_.assign(nb, -1);
    for (std::size_t b = 0; b < nb; ++b) {
      if (!ownsBlock(b)) continue;
      blockStart_[b] = dist_.firstRow + std::int64_t(owned_.size());
      if (!rowsOfBlock[b].empty()) rowBlocks_.push_back(std::int32_t(b));
      for (std::uint32_t k : rowsOfBlock[b]) {
        globalOfLive_[k] = dist_.firstRow + std::int64_t(owned_.size());
        owned_.push_back(k);
      }
    }
  }

  // fn(faceIndex, coefficient) over the faces of K's column at padded sample `row`.
  template <class Fn>
  void forEachFaceOfRow(std::size_t row, Fn&& fn) const {
    if (row < n_) kernels::forEachPressureFace<Dim>(sys_->layout(), row, fn);
    else kernels::forEachStressFace<Dim>(sys_->layout(), int(row / n_) - 1, row % n_, fn);
  }
  // fn(paddedSample, coefficient) over the samples of K's row at face f (stresses only in the
  // unified system).
  template <class Fn>
  void forEachSampleOfFace(std::size_t f, Fn&& fn) const {
    kernels::forEachSampleOfFace<Dim>(
        sys_->layout(), int(f / n_), f % n_, [&](std::size_t s, double c) { fn(s, c); },
        [&](int ch, std::size_t s, double c) {
          if (sys_->withStress()) fn(n_ + std::size_t(ch) * n_ + s, c);
        });
  }
  // The same over the live ones.
  template <class Fn>
  void forEachLiveSampleOfFace(std::size_t f, Fn&& fn) const {
    forEachSampleOfFace(f, [&](std::size_t s, double c) {
      if (liveOfPadded_[s] >= 0) fn(s, c);
    });
  }

  // The faces the rank's rows and its blocks' velocities read, the tiles they touch, the blocks
  // to form K x on, the samples to gather (owned and ghost rows).
  void collectStencilReach() {
    const std::vector<RowSelection::Index>& live = rows_->rows();
    const std::vector<FaceState>& state = sys_->faceStates();
    const ReducedTiles<Dim>* tiles = sys_->tiles();
    std::vector<std::uint8_t> faceBlock(sys_->layout().numBlocks(), 0), tileTouched(tiles ? tiles->numTiles() : 0, 0);
    std::vector<std::int64_t> faces;
    auto reach = [&](std::int64_t f) {
      faceBlock[blockOfSample(std::size_t(f))] = 1;
      if (state[f] == FaceState::Unknown) faces.push_back(f);
      if (tiles && tiles->tileOfFace(std::size_t(f)) >= 0) tileTouched[tiles->tileOfFace(std::size_t(f))] = 1;
    };
    for (std::uint32_t k : owned_) forEachFaceOfRow(live[k], [&](std::int64_t f, double) { reach(f); });
    for (std::int32_t b : ownedBlockList())
      for (int a = 0; a < Dim; ++a)
        for (std::size_t s = std::size_t(b) * kSlots; s < std::size_t(b + 1) * kSlots; ++s)
          if (state[a * n_ + s] == FaceState::Unknown) reach(std::int64_t(a * n_ + s));
    for (std::size_t t = 0; t < tileTouched.size(); ++t) {
      if (!tileTouched[t]) continue;
      tiles_.push_back(std::int32_t(t));
      for (std::int64_t f : tiles->tile(t).coupling) {
        faceBlock[blockOfSample(std::size_t(f))] = 1;
        faces.push_back(f);
      }
    }
    for (std::size_t b = 0; b < faceBlock.size(); ++b)
      if (faceBlock[b]) faceBlocks_.push_back(std::int32_t(b));
    for (std::int64_t f : faces) faces_.push_back(RowSelection::Index(f));
    std::sort(faces_.begin(), faces_.end());
    faces_.erase(std::unique(faces_.begin(), faces_.end()), faces_.end());
    std::vector<std::uint8_t> needed(live.size(), 0);
    for (std::uint32_t k : owned_) needed[k] = 1;
    for (RowSelection::Index f : faces_)
      forEachLiveSampleOfFace(f, [&](std::size_t s, double) { needed[std::size_t(liveOfPadded_[s])] = 1; });
    for (std::size_t k = 0; k < live.size(); ++k)
      if (needed[k]) ghostLive_.push_back(std::uint32_t(k));
  }

  std::vector<std::int32_t> ownedBlockList() const {
    std::vector<std::int32_t> out;
    for (std::size_t b = 0; b < ownerOfBlock_.size(); ++b)
      if (ownsBlock(b)) out.push_back(std::int32_t(b));
    return out;
  }

  // Bit (channel c, slot s) of block b: whether that sample is a live row.
  void liveBitmap(std::size_t b, std::uint64_t* words) const {
    std::fill(words, words + channels() * kBitmapWords, std::uint64_t(0));
    for (int c = 0; c < channels(); ++c)
      for (std::size_t s = 0; s < kSlots; ++s)
        if (liveOfPadded_[std::size_t(c) * n_ + b * kSlots + s] >= 0)
          words[std::size_t(c) * kBitmapWords + s / 64] |= std::uint64_t(1) << (s % 64);
  }

  // Ghost numbers from their blocks' owners: each owner sends, per block asked for by its origin,
  // the block's first number and its live-row bitmaps; a ghost's number is its block's first
  // plus the live rows before it in the block's order (channel, then slot).
  void numberGhostRows() {
    const std::vector<RowSelection::Index>& live = rows_->rows();
    const BlockLayout<Dim>& L = sys_->layout();
    const int ranks = int(petsc::ranks());
    std::vector<std::vector<std::int32_t>> asks(ranks);
    std::vector<std::vector<std::int32_t>> askedBlocks(ranks);
    std::vector<std::uint8_t> asked(L.numBlocks(), 0);
    auto ask = [&](std::size_t b) {
      if (ownsBlock(b) || asked[b]) return;
      asked[b] = 1;
      const int r = ownerOfBlock_[b];
      if (r < 0 || r >= ranks) throw std::invalid_argument("PressureStressRanks: a block's owner is not a rank");
      for (int a = 0; a < 3; ++a) asks[r].push_back(L.blockOrigin(b)[a]);
      askedBlocks[r].push_back(std::int32_t(b));
    };
    for (RowSelection::Index f : faces_) forEachSampleOfFace(f, [&](std::size_t s, double) { ask(blockOfSample(s)); });
    const int words = 1 + channels() * int(kBitmapWords);
    const std::vector<std::vector<std::uint64_t>> replies =
        askRanks(asks, 3, words, [&](const std::int32_t* key, std::uint64_t* record) {
          const std::int32_t b = L.blockAt(sparse_grid::Coord(key[0], key[1], key[2]));
          if (b < 0 || !ownsBlock(std::size_t(b)))
            throw std::logic_error("PressureStressRanks: asked for the rows of a block this rank does not own");
          record[0] = std::uint64_t(blockStart_[std::size_t(b)]);
          liveBitmap(std::size_t(b), record + 1);
        });
    std::vector<const std::uint64_t*> recordOfBlock(L.numBlocks(), nullptr);
    for (int r = 0; r < ranks; ++r)
      for (std::size_t i = 0; i < askedBlocks[r].size(); ++i) recordOfBlock[std::size_t(askedBlocks[r][i])] = replies[r].data() + i * std::size_t(words);
    // the owner's bit of a sample in another rank's block; its number if live
    auto ownersBit = [&](std::size_t row, std::int64_t* number) {
      const std::size_t b = blockOfSample(row), c = row / n_, s = row % n_ - b * kSlots;
      const std::uint64_t* rec = recordOfBlock[b];
      const std::uint64_t* bits = rec + 1;
      const std::uint64_t word = bits[c * kBitmapWords + s / 64];
      if (number) {
        std::int64_t before = std::popcount(word & ((std::uint64_t(1) << (s % 64)) - 1));
        for (std::size_t w = 0; w < c * kBitmapWords + s / 64; ++w) before += std::popcount(bits[w]);
        *number = std::int64_t(rec[0]) + before;
      }
      return (word >> (s % 64) & 1) != 0;
    };
    // a halo's weights that differ from the owner's would silently change A: refuse them
    for (RowSelection::Index f : faces_)
      forEachSampleOfFace(f, [&](std::size_t s, double) {
        if (!ownsBlock(blockOfSample(s)) && ownersBit(s, nullptr) != (liveOfPadded_[s] >= 0))
          throw std::logic_error("PressureStressRanks: a halo sample that this rank's stencils read is " +
                                 std::string(liveOfPadded_[s] >= 0 ? "live here but not" : "not live here but") +
                                 " on its owner (the halo's weights differ from the owner's)");
      });
    for (std::uint32_t k : ghostLive_)
      if (!ownsBlock(blockOfSample(live[k]))) ownersBit(live[k], &globalOfLive_[k]);
    std::sort(ghostLive_.begin(), ghostLive_.end(),
              [&](std::uint32_t x, std::uint32_t y) { return globalOfLive_[x] < globalOfLive_[y]; });
  }

  // Row i of the assembled matrix: sum over unknown faces f of w_i K_fi S_f K_fj w_j, the exact
  // diagonal (compliance and tile coupling included) on i.
  void assembleRow(std::size_t row, std::vector<std::pair<std::int64_t, double>>& entries) const {
    const std::vector<FaceState>& state = sys_->faceStates();
    const std::size_t live = std::size_t(liveOfPadded_[row]);
    entries.clear();
    const double wi = weight(row);
    forEachFaceOfRow(row, [&](std::int64_t f, double ki) {
      if (state[f] != FaceState::Unknown) return;
      const double s = sys_->faceScale()[f];
      forEachLiveSampleOfFace(std::size_t(f), [&](std::size_t j, double kj) {
        if (j != row) entries.emplace_back(globalOfLive_[std::size_t(liveOfPadded_[j])], wi * ki * s * kj * weight(j));
      });
    });
    entries.emplace_back(globalOfLive_[live], sys_->diagonal()[row]);
    std::sort(entries.begin(), entries.end());
    std::size_t out = 0;
    for (std::size_t e = 0; e < entries.size(); ++e) {
      if (out > 0 && entries[out - 1].first == entries[e].first) entries[out - 1].second += entries[e].second;
      else entries[out++] = entries[e];
    }
    entries.resize(out);
  }
  double weight(std::size_t row) const {
    return row < n_ ? sys_->pressureWeights()[row] : sys_->stressWeights()[row - n_];
  }

  void buildDistributedSystem() {
    const std::vector<RowSelection::Index>& live = rows_->rows();
    dist_.ownedRows = owned_.size();
    for (std::uint32_t k : ghostLive_) dist_.ghostRows.push_back(globalOfLive_[k]);
    dist_.fieldNames = sys_->withStress() ? std::vector<std::string>{"pressure", "stress"}
                                          : std::vector<std::string>{"pressure"};
    const double* nullSpace = sys_->nullSpace();
    for (std::uint32_t k : owned_) {
      const std::size_t row = live[k];
      dist_.rhs.push_back(sys_->rhs()[row]);
      dist_.diagonal.push_back(sys_->diagonal()[row]);
      dist_.field.push_back(row < n_ ? 0 : 1);
      if (nullSpace) dist_.nullSpace.push_back(nullSpace[row]);
    }
    dist_.assemble = [this](std::vector<std::int64_t>& rowStart, std::vector<std::int64_t>& columns,
                            std::vector<double>& values) { assemble(rowStart, columns, values); };
    if (sys_->tiles() && sys_->tiles()->numTiles() > 0)
      dist_.assembledNote = "tile coupling K^T J^T B^-1 J K on the diagonal only";
    // the compact operator over the rank's samples (own and ghost rows, in padded order)
    std::vector<RowSelection::Index> read;
    for (std::uint32_t k : ghostLive_) read.push_back(live[k]);
    std::sort(read.begin(), read.end());
    readRows_ = std::make_unique<RowSelection>(read, sys_->size());
    operator_ = std::make_unique<PressureStressRows<Dim>>(*sys_, *readRows_, faces_, tiles_);
    std::vector<std::int64_t> compactOfPadded(sys_->size(), -1);
    for (std::size_t c = 0; c < read.size(); ++c) compactOfPadded[read[c]] = std::int64_t(c);
    for (std::uint32_t k : ghostLive_) ghostCompact_.push_back(RowSelection::Index(compactOfPadded[live[k]]));
    for (std::uint32_t k : owned_) ownedCompact_.push_back(RowSelection::Index(compactOfPadded[live[k]]));
    xCompact_.assign(read.size(), 0.0);
    yCompact_.assign(read.size(), 0.0);
    dist_.apply = [this](const double* ghosts, double* yOwned) { apply(ghosts, yOwned); };
  }

  // The owned rows of the assembled matrix, CSR with global columns.
  void assemble(std::vector<std::int64_t>& rowStart, std::vector<std::int64_t>& columns,
                std::vector<double>& values) const {
    std::vector<std::pair<std::int64_t, double>> entries;
    rowStart.assign(1, 0);
    for (std::uint32_t k : owned_) {
      assembleRow(rows_->rows()[k], entries);
      for (const auto& [c, v] : entries) {
        columns.push_back(c);
        values.push_back(v);
      }
      rowStart.push_back(std::int64_t(columns.size()));
    }
  }

  // y_owned = (A x)_owned from x on the ghost rows: the compact neighbour-index stencils
  // (pressure_stress_rows.h) over the rank's samples.
  void apply(const double* ghosts, double* yOwned) {
    for (std::size_t g = 0; g < ghostCompact_.size(); ++g) xCompact_[ghostCompact_[g]] = ghosts[g];
    operator_->apply(xCompact_.data(), yCompact_.data());
    for (std::size_t k = 0; k < ownedCompact_.size(); ++k) yOwned[k] = yCompact_[ownedCompact_[k]];
  }

 public:
  /// The same on the padded block kernels (PressureStressSystem::applyOnBlocks), for tests: the
  /// two must agree bit for bit.
  void applyOnBlocks(const double* ghosts, double* yOwned) const {
    const std::vector<RowSelection::Index>& live = rows_->rows();
    Vector x(sys_->size(), 0.0), y(sys_->size(), 0.0);
    for (std::size_t g = 0; g < ghostLive_.size(); ++g) x[live[ghostLive_[g]]] = ghosts[g];
    sys_->applyOnBlocks(x.data(), y.data(), faceBlocks_, rowBlocks_, tiles_);
    for (std::size_t k = 0; k < owned_.size(); ++k) yOwned[k] = y[live[owned_[k]]];
  }

 private:
  const PressureStressSystem<Dim>* sys_;
  const RowSelection* rows_;
  std::size_t n_;
  int rank_;
  std::vector<std::int32_t> ownerOfBlock_;
  std::vector<std::int64_t> blockStart_;  ///< first global number of each owned block's rows
  std::vector<std::int64_t> globalOfLive_, liveOfPadded_;  ///< -1 where this rank does not read
  std::vector<std::uint32_t> owned_, ghostLive_;
  kernels::BlockList rowBlocks_, faceBlocks_;
  std::vector<std::int32_t> tiles_;
  std::vector<RowSelection::Index> faces_;  ///< faces whose K x the rank's rows need
  std::unique_ptr<RowSelection> readRows_;  ///< the samples the rank reads, padded order
  std::unique_ptr<PressureStressRows<Dim>> operator_;
  std::vector<RowSelection::Index> ghostCompact_, ownedCompact_;  ///< positions in the compact vectors
  Vector xCompact_, yCompact_;
  DistributedSystem dist_;
};

}  // namespace stokes::solver::petsc

namespace stokes::solver::petsc {

/// Solves the pressure-stress system of `prob` on PETSC_COMM_WORLD. x: padded rows; the initial
/// guess on entry (live rows); on return the solution on every row of a whole problem, or, for a
/// problem distributed by blocks, on the rows of the rank's blocks and the halo rows their
/// stencils read. `liveRows` receives the unknowns (over all ranks).
template <int Dim>
PetscReport solvePressureStress(const StaggeredProblem<Dim>& prob, const PressureStressSystem<Dim>& sys,
                                const SolveOptions& opt, Vector& x, std::size_t* liveRows = nullptr) {
  const auto t0 = std::chrono::steady_clock::now();
  const RowSelection rows = RowSelection::positiveDiagonal(sys.diagonal());
  std::vector<std::int32_t> owner = prob.isDistributed()
                                        ? prob.blockOwner
                                        : PressureStressRanks<Dim>::owners(sys.layout(), ranks());
  PressureStressRanks<Dim> split(sys, rows, std::move(owner), rank());
  const DistributedSystem& d = split.system();
  std::vector<double> owned(d.ownedRows);
  for (std::size_t k = 0; k < d.ownedRows; ++k) owned[k] = x[rows.rows()[split.ownedLive()[k]]];
  const double partitionSeconds = secondsSince(t0);
  std::vector<double> ghosts;
  PetscReport rep = solveDistributed(d, opt, owned.data(), prob.isDistributed() ? &ghosts : nullptr);
  rep.setupSeconds += partitionSeconds;
  if (prob.isDistributed()) split.scatterGhosts(ghosts, x.data());
  else split.scatterGlobal(allGather(owned.data(), owned.size()), x.data());
  if (liveRows) *liveRows = std::size_t(d.globalRows);
  return rep;
}

}  // namespace stokes::solver::petsc
