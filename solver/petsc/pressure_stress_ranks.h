#pragma once
// The pressure-stress system (pressure_stress_system.h; thesis Eq. 4.20-4.25) split over MPI ranks
// for the PETSc backend (petsc_krylov.h).
//
// Partition. The unknowns are the system's live rows (positive diagonal, as in the in-house
// compact solve). The layout's blocks, along a Morton curve (sparse_grid/block_order.h), are cut
// into one contiguous run per rank with about the same number of live rows each; a rank owns every
// live row (pressure and all stress channels) of its blocks. The global numbering is rank-major: rank 0's
// rows, then rank 1's, ..., each rank's in the padded order [p | tau_0 | tau_1 | ...].
//
// Ghosts. A rank's rows read K x on the faces of their stencils (forEachPressureFace /
// forEachStressFace); K x on an unknown face reads the samples of that face's column
// (forEachSampleOfFace); on a tile's coupling face, the tile couples all of its coupling faces
// (J^T B^-1 J), so every sample of those faces is read too. Those samples are the ghost rows that
// the MatShell gathers before each apply; the apply then runs the compact neighbour-index
// stencils (pressure_stress_rows.h) over the rank's samples and those faces only. (The padded
// block kernels over the rank's blocks, PressureStressSystem::applyOnBlocks, give the same numbers
// bit for bit, tested, but sweep every slot of every block: 2.9x slower on the 64^3 ball.)
//
// Assembled part. K^T S K + C is assembled exactly from the stencil entries
// (kernels/stencil_entries.h) over the Cartesian unknown faces; the reduced tiles' coupling
// K^T J^T B^-1 J K, which is dense over each tile's coupling samples, enters only through its
// diagonal (the system's exact diagonal). Without tiles the assembled matrix is A itself.
//
// First version: every rank holds the whole problem and the system (the scene stays on rank 0 and
// is sent to the others, or every rank builds the same analytic problem); the Krylov vectors,
// the stencil applies and the preconditioner are distributed.
#include <algorithm>
#include <chrono>
#include <cstdint>
#include <memory>
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

  /// `rows`: the system's live rows. sys, its tiles and rows must outlive this object.
  PressureStressRanks(const PressureStressSystem<Dim>& sys, const RowSelection& rows, int rank, int ranks)
      : sys_(&sys), rows_(&rows), n_(sys.layout().numSlots()), rank_(rank) {
    partition(ranks);
    collectStencilReach();
    buildDistributedSystem();
  }

  DistributedSystem& system() { return dist_; }
  /// Row k of the global numbering is live row liveOfGlobal()[k] of the selection.
  const std::vector<std::uint32_t>& liveOfGlobal() const { return liveOfGlobal_; }
  std::size_t ownedBlocks() const { return rowBlocks_.size(); }
  std::size_t ghostRows() const { return dist_.ghostRows.size() - dist_.ownedRows; }

  /// Puts the global solution (rank-major, allGather's order) back on the padded rows.
  void scatterGlobal(const std::vector<double>& global, double* padded) const {
    for (std::size_t k = 0; k < global.size(); ++k) padded[rows_->rows()[liveOfGlobal_[k]]] = global[k];
  }

 private:
  std::size_t blockOfSample(std::size_t padded) const { return (padded % n_) / kSlots; }

  // Contiguous runs of blocks along the Morton curve, ~equal live rows per rank; the rank-major
  // global numbering.
  void partition(int ranks) {
    const std::vector<RowSelection::Index>& live = rows_->rows();
    const std::size_t nb = sys_->layout().numBlocks();
    std::vector<std::size_t> rowsInBlock(nb, 0);
    for (RowSelection::Index r : live) ++rowsInBlock[blockOfSample(r)];
    ownerOfBlock_.assign(nb, 0);
    std::size_t seen = 0;
    const std::vector<std::size_t> order = sparse_grid::bisectionBlockOrder(sys_->layout(), rowsInBlock);
    for (std::size_t b : order) {
      // block b goes to the rank whose share [r N / R, (r + 1) N / R) holds its first row
      ownerOfBlock_[b] = int(std::min<std::size_t>(std::size_t(ranks) - 1, seen * std::size_t(ranks) / std::max<std::size_t>(1, live.size())));
      seen += rowsInBlock[b];
    }
    std::vector<std::vector<std::uint32_t>> perRank(ranks);
    for (std::size_t k = 0; k < live.size(); ++k) perRank[ownerOfBlock_[blockOfSample(live[k])]].push_back(std::uint32_t(k));
    globalOfLive_.assign(live.size(), 0);
    for (int r = 0; r < ranks; ++r) {
      if (r == rank_) dist_.firstRow = std::int64_t(liveOfGlobal_.size());
      for (std::uint32_t k : perRank[r]) {
        globalOfLive_[k] = std::int64_t(liveOfGlobal_.size());
        liveOfGlobal_.push_back(k);
      }
    }
    owned_ = std::move(perRank[rank_]);
    liveOfPadded_.assign(sys_->size(), -1);
    for (std::size_t k = 0; k < live.size(); ++k) liveOfPadded_[live[k]] = std::int64_t(k);
    for (std::size_t b = 0; b < nb; ++b)
      if (ownerOfBlock_[b] == rank_ && rowsInBlock[b] > 0) rowBlocks_.push_back(std::int32_t(b));
  }

  // fn(faceIndex, coefficient) over the faces of K's column at padded sample `row`.
  template <class Fn>
  void forEachFaceOfRow(std::size_t row, Fn&& fn) const {
    if (row < n_) kernels::forEachPressureFace<Dim>(sys_->layout(), row, fn);
    else kernels::forEachStressFace<Dim>(sys_->layout(), int(row / n_) - 1, row % n_, fn);
  }
  // fn(paddedSample, coefficient) over the live samples of K's row at face f.
  template <class Fn>
  void forEachLiveSampleOfFace(std::size_t f, Fn&& fn) const {
    const std::size_t slot = f % n_;
    const int a = int(f / n_);
    kernels::forEachSampleOfFace<Dim>(
        sys_->layout(), a, slot,
        [&](std::size_t s, double c) {
          if (liveOfPadded_[s] >= 0) fn(s, c);
        },
        [&](int ch, std::size_t s, double c) {
          const std::size_t p = n_ + std::size_t(ch) * n_ + s;
          if (sys_->withStress() && liveOfPadded_[p] >= 0) fn(p, c);
        });
  }

  // The faces the rank's rows read, the tiles they touch, the blocks to form K x on, the ghosts.
  void collectStencilReach() {
    const std::vector<RowSelection::Index>& live = rows_->rows();
    const std::vector<FaceState>& state = sys_->faceStates();
    const ReducedTiles<Dim>* tiles = sys_->tiles();
    std::vector<std::uint8_t> faceBlock(sys_->layout().numBlocks(), 0), tileTouched(tiles ? tiles->numTiles() : 0, 0);
    std::vector<std::int64_t> faces;
    for (std::uint32_t k : owned_)
      forEachFaceOfRow(live[k], [&](std::int64_t f, double) {
        faceBlock[blockOfSample(std::size_t(f))] = 1;
        if (state[f] == FaceState::Unknown) faces.push_back(f);
        if (tiles && tiles->tileOfFace(std::size_t(f)) >= 0) tileTouched[tiles->tileOfFace(std::size_t(f))] = 1;
      });
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
    dist_.globalRows = std::int64_t(live.size());
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
  std::vector<int> ownerOfBlock_;
  std::vector<std::int64_t> globalOfLive_, liveOfPadded_;
  std::vector<std::uint32_t> liveOfGlobal_, owned_, ghostLive_;
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

/// Solves the pressure-stress system on PETSC_COMM_WORLD. x: padded rows; the initial guess on
/// entry (live rows), the solution on every rank on return. `liveRows` receives the unknowns.
template <int Dim>
PetscReport solvePressureStress(const PressureStressSystem<Dim>& sys, const SolveOptions& opt, Vector& x,
                                std::size_t* liveRows = nullptr) {
  const auto t0 = std::chrono::steady_clock::now();
  const RowSelection rows = RowSelection::positiveDiagonal(sys.diagonal());
  PressureStressRanks<Dim> split(sys, rows, rank(), ranks());
  const DistributedSystem& d = split.system();
  std::vector<double> owned(d.ownedRows);
  for (std::size_t k = 0; k < d.ownedRows; ++k)
    owned[k] = x[rows.rows()[split.liveOfGlobal()[std::size_t(d.firstRow) + k]]];
  const double partitionSeconds = secondsSince(t0);
  PetscReport rep = solveDistributed(d, opt, owned.data());
  rep.setupSeconds += partitionSeconds;
  split.scatterGlobal(allGather(owned.data(), owned.size()), x.data());
  if (liveRows) *liveRows = rows.size();
  return rep;
}

}  // namespace stokes::solver::petsc
