#pragma once
// The pressure-velocity system (pressure_velocity_system.h; thesis Eq. 4.19) split over MPI ranks
// for the PETSc backend (petsc_krylov.h), without reduced tiles.
//
// Rows. The live rows (positive diagonal) of x = [u | p | l_r], each a sample of the layout: face
// axis a (channel a), the cell's pressure (channel Dim), a rigid stress multiplier (channel
// Dim + 1 + its stress channel). They are numbered by their blocks' owners (block_rows.h), as the
// pressure-stress split numbers its rows.
//
// Ghosts: the columns of the rank's rows. A face row reads the faces of its velocity block row
// (mass and W_F D^T Q D W_F: the faces of every stress sample that holds it, VelocityBlockStencil),
// the pressures beside it and the multipliers of its stress samples; a pressure row its cell's
// faces; a multiplier row its sample's faces.
//
// Apply. The rank's padded system on its own part of the problem (its blocks and a halo, or the
// whole problem) applied to x with the rank's own and ghost values and zeros elsewhere: exact on
// the owned rows, whose columns are all there. On a problem set up per rank the padded sweep
// covers the rank's blocks and its halo; on a whole problem held by every rank it covers all of
// it, which is correct but does not divide the work.
//
// Preconditioner matrix. P = blockdiag(A_uu, S_d): the velocity block assembled exactly from its
// stencil (VelocityBlockStencil) and, on the pressure and multiplier rows, the system's Schur
// complement diagonal estimate -- the in-house block-diagonal preconditioner's blocks, both
// symmetric positive definite, so MINRES can use any symmetric preconditioner built on them. The
// default is a field split, additive (block Jacobi over the two fields): on the velocity block a
// geometric multigrid over the ranks (PCMG on the levels of faceLevels(), face_levels.h), on S_d
// Jacobi. Ball n = 192, 1 / 2 ranks: 75 / 75 MINRES iterations, where GAMG (PETSc's algebraic
// multigrid, translations as its near-null space, graph threshold 0.01; still the option
// `-fieldsplit_0_pc_type gamg`) took 156 / 153; ball 64 and 128: 85 and 90 on 1 to 16
// ranks. With the velocity block solved exactly 22 (n = 32): the Schur diagonal is not the weak
// part. PETSc's Schur-complement factorisation is not used: its "diag" variant negates S, which
// MINRES cannot take (docs/petsc.md).
#include <algorithm>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "kernels/stencil_entries.h"
#include "solver/krylov/compact_rows.h"
#include "solver/multigrid/galerkin_cycle.h"
#include "solver/multigrid/velocity_block_matrix.h"
#include "solver/petsc/block_rows.h"
#include "solver/petsc/face_levels.h"
#include "solver/petsc/petsc_krylov.h"
#include "solver/systems/pressure_velocity_system.h"
#include "sparse_grid/block_order.h"

namespace stokes::solver::petsc {

template <int Dim>
class PressureVelocityRanks {
 public:
  using SC = StressChannels<Dim>;
  static constexpr int kChannels = Dim + 1 + SC::kCount;

  /// `rows`: the system's live rows; `owner`: the rank of each of the layout's blocks. sys and rows
  /// must outlive this object. Collective.
  /// `interpolation`: the velocity multigrid's across the face normals (faceLevels()).
  PressureVelocityRanks(const PressureVelocitySystem<Dim>& sys, const RowSelection& rows,
                        std::vector<std::int32_t> owner, int rank,
                        FaceInterpolation interpolation = FaceInterpolation::Auto)
      : sys_(&sys), rows_(&rows), n_(sys.layout().numSlots()), interpolation_(interpolation), stencil_(sys),
        numbering_(sys.layout(), std::move(owner), rank, kChannels, keysOf(sys, rows)) {
    numbering_.numberGhosts(columnsOfOwnedRows());
    buildDistributedSystem();
  }

  DistributedSystem& system() { return dist_; }
  /// The rows' numbering over the ranks (block_rows.h).
  const BlockRows<Dim>& numbering() const { return numbering_; }

 private:
  // The sample key of padded row i (see the file comment).
  static std::vector<std::uint64_t> keysOf(const PressureVelocitySystem<Dim>& sys, const RowSelection& rows) {
    if (sys.tiles()) throw std::invalid_argument("the PETSc backend solves the pressure-velocity form without reduced tiles");
    const std::size_t n = sys.layout().numSlots();
    std::vector<std::uint64_t> keys;
    keys.reserve(rows.size());
    for (RowSelection::Index i : rows.rows()) {
      if (i < sys.rigidOffset()) keys.push_back(i);  // u, then p at Dim n + slot
      else keys.push_back((Dim + 1) * n + sys.rigidSample(i - sys.rigidOffset()));
    }
    return keys;
  }

  // fn(key) over the columns of live row k (its key).
  template <class Fn>
  void forEachColumn(std::uint64_t key, Fn&& fn) const {
    const BlockLayout<Dim>& L = sys_->layout();
    fn(key);
    if (key < Dim * n_) {
      stencil_.faceRow(std::size_t(key), [&](std::size_t f, double) { fn(f); }, [](std::size_t, std::size_t, double) {});
      kernels::forEachSampleOfFace<Dim>(
          L, int(key / n_), key % n_, [&](std::size_t s, double) { fn(Dim * n_ + s); },
          [&](int c, std::size_t s, double) { fn((Dim + 1) * n_ + std::size_t(c) * n_ + s); });
    } else if (key < (Dim + 1) * n_) {
      kernels::forEachPressureFace<Dim>(L, key - Dim * n_, [&](std::int64_t f, double) { fn(std::uint64_t(f)); });
    } else {
      const std::size_t sample = key - (Dim + 1) * n_;
      kernels::forEachStressFace<Dim>(L, int(sample / n_), sample % n_, [&](std::int64_t f, double) { fn(std::uint64_t(f)); });
    }
  }
  std::vector<std::uint64_t> columnsOfOwnedRows() const {
    std::vector<std::uint64_t> keys;
    for (std::uint32_t k : numbering_.owned()) forEachColumn(numbering_.key(k), [&](std::uint64_t c) { keys.push_back(c); });
    std::sort(keys.begin(), keys.end());
    keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
    return keys;
  }

  void buildDistributedSystem() {
    const std::vector<std::uint32_t>& owned = numbering_.owned();
    dist_.globalRows = numbering_.globalRows();
    dist_.firstRow = numbering_.firstRow();
    dist_.ownedRows = owned.size();
    for (std::uint32_t k : numbering_.read()) dist_.ghostRows.push_back(numbering_.globalOf(k));
    dist_.fieldNames = {"velocity", "pressure and rigid multipliers"};
    const double* nullSpace = sys_->nullSpace();
    for (std::uint32_t k : owned) {
      const std::size_t row = rows_->rows()[k];
      dist_.rhs.push_back(sys_->rhs()[row]);
      dist_.diagonal.push_back(sys_->diagonal()[row]);
      dist_.field.push_back(row < sys_->velocityRows() ? 0 : 1);
      if (nullSpace) dist_.nullSpace.push_back(nullSpace[row]);
    }
    dist_.assemble = [this](std::vector<std::int64_t>& rowStart, std::vector<std::int64_t>& columns,
                            std::vector<double>& values) { assemble(rowStart, columns, values); };
    dist_.assembledNote = "velocity block and the Schur diagonal estimate (block diagonal)";
    dist_.defaultOptions = {"-ksp_type", "minres", "-pc_type", "fieldsplit", "-pc_fieldsplit_type", "additive",
                            "-fieldsplit_0_pc_type", "mg",
                            "-fieldsplit_0_pc_gamg_threshold", "0.01", "-fieldsplit_1_pc_type", "jacobi"};
    // On several ranks PETSc's Galerkin products by its low-memory algorithm (the coarse operators
    // of PCMG or GAMG; on one rank there is only the sequential one): see kProductAlgorithm.
    if (petsc::ranks() > 1) dist_.defaultOptions.insert(dist_.defaultOptions.end(), {"-matptap_via", kProductAlgorithm});
    dist_.fieldZeroLevels = [this] { return faceLevels(); };
    dist_.fieldZeroSmoother = [this] { return strongPairSmoother(); };
    dist_.nearNullSpace = [this] { return translations(); };
    dist_.assembledHasNullSpace = false;  // P is definite; only A has the closed container's null space
    x_.assign(sys_->size(), 0.0);
    y_.assign(sys_->size(), 0.0);
    dist_.apply = [this](const double* ghosts, double* yOwned) { apply(ghosts, yOwned); };
  }

  // The velocity block's geometric levels (face_levels.h) from the owned face rows. Across the face
  // normals the in-house Galerkin cycle's rule (GalerkinVelocityHierarchy::cellAxes: linear in 2D
  // and where viscosity dominates the step, else constant), except that in 3D P_0 stays constant
  // where the rule is left open: PETSc's P^T A P with a linear P_0 costs more set-up than its fewer
  // iterations save. Ball n = 128, 2 ranks (stopping on MINRES' own norm): linear P_0 54 MINRES iterations, set-up 9.5 s, 12.9 s in all, 864 MB
  // on the largest rank; constant P_0 and linear below 100, 3.1 s, 8.0 s, 711 MB; constant
  // throughout 193, 1.9 s, 9.2 s, 685 MB; linear P_0 and constant below 110, 6.9 s, 14.1 s.
  std::vector<Interpolation> faceLevels() const {
    std::vector<FaceSample> faces;
    for (std::uint32_t k : numbering_.owned()) {
      const std::uint64_t key = numbering_.key(k);
      if (key < Dim * n_) faces.push_back({int(key / n_), sys_->layout().cellOf(key % n_)});
    }
    const sparse_grid::CellAxes coarser = GalerkinVelocityHierarchy<Dim>::cellAxes(sys_->viscousNumber(), interpolation_);
    const sparse_grid::CellAxes finest =
        Dim == 3 && interpolation_ == FaceInterpolation::Auto ? sparse_grid::CellAxes::Constant : coarser;
    FaceLevels<Dim> levels(std::move(faces), finest, coarser, kCoarsestFaceRows, kMaxFaceLevels);
    return std::move(levels.transfers());
  }
  // The finest level's smoother preconditioner: Jacobi, with the groups of strongly coupled face
  // rows (appendStrongPairBlocks, galerkin_cycle.h) among the rank's own rows inverted whole, as
  // the in-house cycle's smoother does. Only the rows of strong pairs are assembled (the whole
  // block's copy raised the ball's peak by 69 MB). First frame on 2 ranks: armadillos res 128 148 /
  // 171 MINRES iterations a step, 0.57 / 0.60 s, against 179 / 181, 0.64-0.69 s with Jacobi; beam
  // res 96 239 against 463 on its first step. The balls have no strong pairs.
  std::function<void(const double*, double*)> strongPairSmoother() const {
    std::vector<std::uint32_t> faces;  // field 0's rows: the owned face rows in order
    std::vector<std::int32_t> local(rows_->size(), -1);  // field 0's place of an owned face row
    for (std::uint32_t k : numbering_.owned())
      if (numbering_.key(k) < Dim * n_) local[k] = std::int32_t(faces.size()), faces.push_back(k);
    // the system's diagonal on the face rows is the velocity block's (to rounding)
    Vector diagonal(faces.size());
    for (std::size_t i = 0; i < faces.size(); ++i) diagonal[i] = sys_->diagonal()[rows_->rows()[faces[i]]];
    std::vector<std::pair<CsrMatrix::Index, double>> row;
    auto rowTerms = [&](std::size_t i) {  // row i's (field 0 column, value) terms among the owned faces
      row.clear();
      stencil_.faceRow(
          std::size_t(numbering_.key(faces[i])),
          [&](std::size_t f, double v) {
            const std::int32_t live = numbering_.liveOfKey(f);
            if (live >= 0 && local[std::size_t(live)] >= 0) row.emplace_back(local[std::size_t(live)], v);
          },
          [](std::size_t, std::size_t, double) {});
    };
    std::vector<std::uint8_t> strong(faces.size(), 0);
    for (std::size_t i = 0; i < faces.size(); ++i) {
      rowTerms(i);
      mergeRowTerms(row);
      for (const auto& [j, v] : row)
        if (std::size_t(j) != i && diagonal[i] > 0.0 && diagonal[std::size_t(j)] > 0.0 &&
            std::abs(v) > kStrongPairCoupling * std::sqrt(diagonal[i] * diagonal[std::size_t(j)]))
          strong[i] = strong[std::size_t(j)] = 1;
    }
    CsrMatrix a;  // the rows of strong pairs only
    a.rows = a.cols = faces.size();
    for (std::size_t i = 0; i < faces.size(); ++i) {
      if (strong[i]) rowTerms(i);
      else row.clear();
      appendCsrRow(row, a.start, a.col, a.value);
    }
    MultigridLevel::DiagonalBlocks blocks;
    appendStrongPairBlocks(a, a.rows, blocks);
    for (double& d : diagonal) d = d > 0.0 ? 1.0 / d : 0.0;
    Vector work(blocks.rows.size());  // the block rows' values, in blocks.rows' order
    return [inverseDiagonal = std::move(diagonal), blocks = std::move(blocks), work = std::move(work)](
               const double* r, double* z) mutable {
      for (std::size_t i = 0; i < inverseDiagonal.size(); ++i) z[i] = inverseDiagonal[i] * r[i];
      blocks.scale(r, work.data());
      for (std::size_t q = 0; q < work.size(); ++q) z[blocks.rows[q]] = work[q];
    };
  }

  // PCMG's coarsest level is factored on every rank (PETSc's default coarse solve in parallel:
  // redundant LU).
  static constexpr std::int64_t kCoarsestFaceRows = 1000;
  static constexpr int kMaxFaceLevels = 12;
  // PETSc's parallel P^T A P "allatonce" forms each coarse row without storing A P: ball n = 192 on
  // 2 ranks, largest rank 2,029 against 2,502 MB with the default "scalable" (one rank: 3,568 MB),
  // set-up 11.0 against 8.8 s, the same MINRES iterations.
  static constexpr const char* kProductAlgorithm = "allatonce";

  // The near-null space handed to GAMG on the owned face rows: the translations along each axis
  // (1 on the faces of that axis). They carry no strain rate, so the viscous part of the velocity
  // block (D^T Q D) does not see them, and its mass term is small. The rotations (omega x (x - c),
  // one centre for all ranks) are near-null too and cut the iterations further, but GAMG's coarse
  // levels then hold 6 instead of 3 modes per aggregate. Ball n = 96 on 2 ranks: translations 141
  // MINRES iterations, 5.6 s, 601 MB on the largest rank; with the rotations 66, 12.8 s, 1,274 MB;
  // none 371 iterations already at n = 32 (45 with the rotations).
  std::vector<std::vector<double>> translations() const {
    std::vector<std::vector<double>> modes(Dim);
    for (std::uint32_t k : numbering_.owned()) {
      const std::uint64_t key = numbering_.key(k);
      if (key >= Dim * n_) continue;
      for (int a = 0; a < Dim; ++a) modes[a].push_back(int(key / n_) == a ? 1.0 : 0.0);
    }
    return modes;
  }

  // P's owned rows: the velocity block's row from its stencil, or the Schur diagonal estimate.
  void assemble(std::vector<std::int64_t>& rowStart, std::vector<std::int64_t>& columns,
                std::vector<double>& values) const {
    std::vector<std::pair<std::int64_t, double>> entries;
    rowStart.assign(1, 0);
    for (std::uint32_t k : numbering_.owned()) {
      const std::uint64_t key = numbering_.key(k);
      entries.clear();
      if (key < Dim * n_) {
        stencil_.faceRow(
            std::size_t(key),
            [&](std::size_t f, double v) {
              const std::int32_t live = numbering_.liveOfKey(f);
              if (live < 0 || numbering_.globalOf(std::size_t(live)) < 0)
                throw std::logic_error("PressureVelocityRanks: a velocity block entry outside the rank's rows");
              entries.emplace_back(numbering_.globalOf(std::size_t(live)), v);
            },
            [](std::size_t, std::size_t, double) {});
      } else {
        entries.emplace_back(numbering_.globalOf(k), sys_->diagonal()[rows_->rows()[k]]);
      }
      appendCsrRow(entries, rowStart, columns, values);
    }
  }

  // y_owned = (A x)_owned: the padded system on x with the rank's own and ghost values.
  void apply(const double* ghosts, double* yOwned) {
    const std::vector<std::uint32_t>& read = numbering_.read();
    for (std::size_t g = 0; g < read.size(); ++g) x_[rows_->rows()[read[g]]] = ghosts[g];
    sys_->apply(x_.data(), y_.data());
    const std::vector<std::uint32_t>& owned = numbering_.owned();
    for (std::size_t k = 0; k < owned.size(); ++k) yOwned[k] = y_[rows_->rows()[owned[k]]];
  }

  const PressureVelocitySystem<Dim>* sys_;
  const RowSelection* rows_;
  std::size_t n_;
  FaceInterpolation interpolation_;
  VelocityBlockStencil<Dim> stencil_;
  BlockRows<Dim> numbering_;
  Vector x_, y_;
  DistributedSystem dist_;
};

}  // namespace stokes::solver::petsc
