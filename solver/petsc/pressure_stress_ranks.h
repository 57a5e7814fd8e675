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
// rows alike and give the same bits. The numbering and the ghosts' numbers: block_rows.h.
//
// Ghosts. A rank's rows read K x on the faces of their stencils (forEachPressureFace /
// forEachStressFace); K x on an unknown face reads the samples of that face's column
// (forEachSampleOfFace); on a tile's coupling face, the tile couples all of its coupling faces
// (J^T B^-1 J), so every sample of those faces is read too. The velocities of the owned blocks'
// faces read the same columns. Those samples are the ghost rows that the MatShell gathers before
// each apply; the apply then runs the compact neighbour-index stencils (pressure_stress_rows.h)
// over the rank's samples and those faces only. (The padded block kernels over the rank's
// blocks, PressureStressSystem::applyOnBlocks, give the same numbers bit for bit, tested, but
// sweep every slot of every block: 2.9x slower on the 64^3 ball.)
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
#include "solver/petsc/block_rows.h"
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

  /// `rows`: the system's live rows; `owner`: the rank of each of the layout's blocks. sys, its
  /// tiles and rows must outlive this object. Collective.
  PressureStressRanks(const PressureStressSystem<Dim>& sys, const RowSelection& rows, std::vector<std::int32_t> owner,
                      int rank)
      : sys_(&sys), rows_(&rows), n_(sys.layout().numSlots()),
        numbering_(sys.layout(), std::move(owner), rank, sys.withStress() ? 1 + SC::kCount : 1,
                   std::vector<std::uint64_t>(rows.rows().begin(), rows.rows().end())) {
    numbering_.numberGhosts(collectStencilReach());
    buildDistributedSystem();
  }

  /// The owners of a whole problem's blocks on `ranks` ranks: equal runs of active cells
  /// (sparse_grid::blockOwners), as a problem set up per rank is cut.
  static std::vector<std::int32_t> owners(const BlockLayout<Dim>& layout, int ranks) {
    const std::vector<int> owner = sparse_grid::blockOwners<Dim>(layout, ranks);
    return std::vector<std::int32_t>(owner.begin(), owner.end());
  }

  DistributedSystem& system() { return dist_; }
  /// The rows' numbering over the ranks: the rank's own live rows (indices into the selection) in
  /// order, the rows it reads, the scatters of a solution back on the padded rows.
  const BlockRows<Dim>& numbering() const { return numbering_; }
  std::size_t ghostRows() const { return dist_.ghostRows.size() - dist_.ownedRows; }

 private:
  std::size_t blockOfSample(std::size_t padded) const { return (padded % n_) / kSlots; }
  bool live(std::size_t padded) const { return numbering_.liveOfKey(padded) >= 0; }

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
      if (live(s)) fn(s, c);
    });
  }

  // The faces the rank's rows and its blocks' velocities read, the tiles they touch, the blocks
  // to form K x on; returns the samples they read.
  std::vector<std::uint64_t> collectStencilReach() {
    const std::vector<RowSelection::Index>& liveRows = rows_->rows();
    const std::vector<FaceState>& state = sys_->faceStates();
    const ReducedTiles<Dim>* tiles = sys_->tiles();
    std::vector<std::uint8_t> faceBlock(sys_->layout().numBlocks(), 0), tileTouched(tiles ? tiles->numTiles() : 0, 0);
    std::vector<std::int64_t> faces;
    auto reach = [&](std::int64_t f) {
      faceBlock[blockOfSample(std::size_t(f))] = 1;
      if (state[f] == FaceState::Unknown) faces.push_back(f);
      if (tiles && tiles->tileOfFace(std::size_t(f)) >= 0) tileTouched[tiles->tileOfFace(std::size_t(f))] = 1;
    };
    for (std::uint32_t k : numbering_.owned()) forEachFaceOfRow(liveRows[k], [&](std::int64_t f, double) { reach(f); });
    for (std::size_t b = 0; b < sys_->layout().numBlocks(); ++b)
      if (numbering_.ownsBlock(b))
        for (int a = 0; a < Dim; ++a)
          for (std::size_t s = b * kSlots; s < (b + 1) * kSlots; ++s)
            if (state[a * n_ + s] == FaceState::Unknown) reach(std::int64_t(a * n_ + s));
    // the blocks of the owned rows (block-major: each block's rows are consecutive)
    for (std::uint32_t k : numbering_.owned())
      if (rowBlocks_.empty() || rowBlocks_.back() != std::int32_t(blockOfSample(liveRows[k])))
        rowBlocks_.push_back(std::int32_t(blockOfSample(liveRows[k])));
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
    std::vector<std::uint64_t> read;
    for (RowSelection::Index f : faces_) forEachSampleOfFace(f, [&](std::size_t s, double) { read.push_back(s); });
    return read;
  }

  // The terms of row i of the assembled matrix: w_i K_fi S_f K_fj w_j over the unknown faces f,
  // and the exact diagonal (compliance and tile coupling included) on i.
  void rowTerms(std::size_t row, std::vector<std::pair<std::int64_t, double>>& entries) const {
    const std::vector<FaceState>& state = sys_->faceStates();
    entries.clear();
    const double wi = weight(row);
    forEachFaceOfRow(row, [&](std::int64_t f, double ki) {
      if (state[f] != FaceState::Unknown) return;
      const double s = sys_->faceScale()[f];
      forEachLiveSampleOfFace(std::size_t(f), [&](std::size_t j, double kj) {
        if (j != row) entries.emplace_back(globalOfSample(j), wi * ki * s * kj * weight(j));
      });
    });
    entries.emplace_back(globalOfSample(row), sys_->diagonal()[row]);
  }
  std::int64_t globalOfSample(std::size_t padded) const {
    return numbering_.globalOf(std::size_t(numbering_.liveOfKey(padded)));
  }
  double weight(std::size_t row) const {
    return row < n_ ? sys_->pressureWeights()[row] : sys_->stressWeights()[row - n_];
  }

  void buildDistributedSystem() {
    const std::vector<RowSelection::Index>& liveRows = rows_->rows();
    const std::vector<std::uint32_t>& owned = numbering_.owned();
    dist_.globalRows = numbering_.globalRows();
    dist_.firstRow = numbering_.firstRow();
    dist_.ownedRows = owned.size();
    for (std::uint32_t k : numbering_.read()) dist_.ghostRows.push_back(numbering_.globalOf(k));
    dist_.fieldNames = sys_->withStress() ? std::vector<std::string>{"pressure", "stress"}
                                          : std::vector<std::string>{"pressure"};
    const double* nullSpace = sys_->nullSpace();
    for (std::uint32_t k : owned) {
      const std::size_t row = liveRows[k];
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
    for (std::uint32_t k : numbering_.read()) read.push_back(liveRows[k]);
    std::sort(read.begin(), read.end());
    readRows_ = std::make_unique<RowSelection>(read, sys_->size());
    operator_ = std::make_unique<PressureStressRows<Dim>>(*sys_, *readRows_, faces_, tiles_);
    std::vector<std::int64_t> compactOfPadded(sys_->size(), -1);
    for (std::size_t c = 0; c < read.size(); ++c) compactOfPadded[read[c]] = std::int64_t(c);
    for (std::uint32_t k : numbering_.read()) ghostCompact_.push_back(RowSelection::Index(compactOfPadded[liveRows[k]]));
    for (std::uint32_t k : owned) ownedCompact_.push_back(RowSelection::Index(compactOfPadded[liveRows[k]]));
    xCompact_.assign(read.size(), 0.0);
    yCompact_.assign(read.size(), 0.0);
    dist_.apply = [this](const double* ghosts, double* yOwned) { apply(ghosts, yOwned); };
  }

  // The owned rows of the assembled matrix, CSR with global columns.
  void assemble(std::vector<std::int64_t>& rowStart, std::vector<std::int64_t>& columns,
                std::vector<double>& values) const {
    std::vector<std::pair<std::int64_t, double>> entries;
    rowStart.assign(1, 0);
    for (std::uint32_t k : numbering_.owned()) {
      rowTerms(rows_->rows()[k], entries);
      appendCsrRow(entries, rowStart, columns, values);
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
    const std::vector<RowSelection::Index>& liveRows = rows_->rows();
    const std::vector<std::uint32_t>& read = numbering_.read();
    Vector x(sys_->size(), 0.0), y(sys_->size(), 0.0);
    for (std::size_t g = 0; g < read.size(); ++g) x[liveRows[read[g]]] = ghosts[g];
    sys_->applyOnBlocks(x.data(), y.data(), faceBlocks_, rowBlocks_, tiles_);
    const std::vector<std::uint32_t>& owned = numbering_.owned();
    for (std::size_t k = 0; k < owned.size(); ++k) yOwned[k] = y[liveRows[owned[k]]];
  }

 private:
  const PressureStressSystem<Dim>* sys_;
  const RowSelection* rows_;
  std::size_t n_;
  BlockRows<Dim> numbering_;
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
