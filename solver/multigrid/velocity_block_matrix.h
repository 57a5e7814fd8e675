#pragma once
// The velocity block of the pressure-velocity form assembled on its live rows, the
// finest level of the Galerkin velocity cycle (galerkin_cycle.h). The Krylov solve keeps applying
// the system matrix-free; only the preconditioner holds entries.
//
// On x = [u_C | v_R] (pressure_velocity_system.h)
//   A_vv = Mass (+) B  +  E^T D^T Q D E,
// with Mass = (rho/dt) W_F W_m on the Cartesian faces, B_t = M_R/dt + K_R per tile, and E the map
// from the unknowns to the face field w that the stresses see: w_f = W_F u_f on a Cartesian unknown
// face, w_f = C_f v_t on a coupling face of tile t (J^T), 0 elsewhere. A stress sample s with Q_s > 0
// contributes Q_s e_s e_s^T, e_s = E^T d_s, d_s its row of D (kernels/stencil_entries.h). Each tile's
// own block B_t + (J V J^T)_tt is taken whole from ReducedTiles::viscosityTileBlocks; the sample
// loops add the Cartesian-Cartesian, Cartesian-tile and tile-tile (two tiles) couplings.
//
// Row by row: the row of face f sums, over the samples s whose stencil holds f, W_F,f d_sf Q_s e_s;
// the rows of tile t sum C_j^T d_sj Q_s e_s over its coupling faces j. Tested against
// applyVelocityBlock (tests/solver/test_multigrid.cpp). VelocityBlockStencil walks these rows for
// this assembly and for the factored couplings of tile_coupled_rows.h.
#include <atomic>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <vector>

#include <Eigen/Dense>

#include "kernels/stencil_entries.h"
#include "solver/krylov/compact_rows.h"
#include "solver/krylov/csr_matrix.h"
#include "solver/systems/pressure_velocity_system.h"

namespace stokes::solver {
inline namespace multigrid {

/// compact[i] = position of padded row i in `rows`, or -1.
inline std::vector<std::int32_t> compactIndex(const RowSelection& rows) {
  std::vector<std::int32_t> compact(rows.fullSize(), -1);
  for (std::size_t k = 0; k < rows.size(); ++k) compact[rows.rows()[k]] = std::int32_t(k);
  return compact;
}

/// Dense columns of a sparse matrix block (a tile's rows): values(:, j) is column columns[j].
struct ColumnBlock {
  std::vector<std::size_t> columns;
  Eigen::MatrixXd values;
};

/// An m x k matrix built column by column: add(col, v) sums the m-vector v into column `col`;
/// columns are kept in order of first appearance (a fixed order: the sums are deterministic).
struct DenseColumns {
  std::unordered_map<std::size_t, std::size_t> position;
  std::vector<std::size_t> columns;
  std::vector<Eigen::VectorXd> sums;

  template <class V>
  void add(std::size_t col, const V& v) {
    const auto [it, fresh] = position.emplace(col, columns.size());
    if (fresh) {
      columns.push_back(col);
      sums.emplace_back(v);
    } else {
      sums[it->second] += v;
    }
  }
  /// The sums as an m x columns.size() block.
  ColumnBlock block(int m) const {
    ColumnBlock out{columns, Eigen::MatrixXd(m, Eigen::Index(columns.size()))};
    for (std::size_t j = 0; j < columns.size(); ++j) out.values.col(Eigen::Index(j)) = sums[j];
    return out;
  }
};

/// The velocity block's stencil row by row on the system's arrays, shared by the assembled matrix
/// (VelocityBlockAssembly) and the tile-coupled rows (tile_coupled_rows.h). Each traversal reports
/// a Cartesian unknown face f as cartesian(f, value) and coupling face p of tile t as
/// tileFace(t, p, value): the assembled matrix expands the latter through C_p (J^T), the
/// tile-coupled rows keep it as a face.
template <int Dim>
class VelocityBlockStencil {
 public:
  explicit VelocityBlockStencil(const PressureVelocitySystem<Dim>& sys)
      : L_(&sys.layout()), tiles_(sys.tiles()), n_(L_->numSlots()), nFaces_(Dim * n_),
        m_(tiles_ ? tiles_->dofsPerTile() : 0), q_(sys.stressCoefficients().data()),
        wf_(sys.unknownFaceWeights().data()), mass_(sys.faceMass().data()) {
    if (!tiles_) return;
    couplingRow_.assign(nFaces_, -1);
    for (std::size_t t = 0; t < tiles_->numTiles(); ++t) {
      const auto& coupling = tiles_->tile(t).coupling;
      for (std::size_t p = 0; p < coupling.size(); ++p) couplingRow_[coupling[p]] = std::int32_t(p);
    }
  }

  const ReducedTiles<Dim>* tiles() const { return tiles_; }
  std::size_t faces() const { return nFaces_; }
  int dofsPerTile() const { return m_; }
  const double* stressCoefficients() const { return q_; }

  /// e_s = E^T d_s of stress sample (channel c, slot), scaled by w, face by face.
  template <class Cartesian, class TileFace>
  void forEachElementFace(int c, std::size_t slot, double w, const Cartesian& cartesian, const TileFace& tileFace) const {
    kernels::forEachStressFace<Dim>(*L_, c, slot, [&](std::int64_t f, double coef) {
      if (wf_[f] > 0.0) {
        cartesian(std::size_t(f), w * coef * wf_[f]);
        return;
      }
      if (!tiles_) return;
      const std::int32_t t = tiles_->tileOfFace(std::size_t(f));
      if (t < 0 || couplingRow_[f] < 0) return;
      tileFace(std::size_t(t), std::size_t(couplingRow_[f]), w * coef);
    });
  }

  /// Row of Cartesian face f: its mass, then W_F,f d_sf Q_s e_s over the samples s holding f.
  template <class Cartesian, class TileFace>
  void faceRow(std::size_t f, const Cartesian& cartesian, const TileFace& tileFace) const {
    cartesian(f, mass_[f]);
    forEachSampleTerm(f, wf_[f], cartesian, tileFace);
  }

  /// Row of coupling face f before J: d_sf Q_s e_s over the samples s holding f.
  template <class Cartesian, class TileFace>
  void couplingFaceRow(std::int64_t f, const Cartesian& cartesian, const TileFace& tileFace) const {
    forEachSampleTerm(std::size_t(f), 1.0, cartesian, tileFace);
  }

 private:
  template <class Cartesian, class TileFace>
  void forEachSampleTerm(std::size_t f, double scale, const Cartesian& cartesian, const TileFace& tileFace) const {
    kernels::forEachSampleOfFace<Dim>(*L_, int(f / n_), f % n_, [](std::size_t, double) {}, [&](int c, std::size_t s, double coef) {
      const double q = q_[c * n_ + s];
      if (q > 0.0) forEachElementFace(c, s, scale * coef * q, cartesian, tileFace);
    });
  }

  const sparse_grid::BlockLayout<Dim>* L_;
  const ReducedTiles<Dim>* tiles_;
  std::size_t n_, nFaces_;
  int m_;
  const double *q_, *wf_, *mass_;
  std::vector<std::int32_t> couplingRow_;  // position of a coupling face in its tile's list, or -1
};

template <int Dim>
class VelocityBlockAssembly {
 public:
  /// `rows`: the live rows of the velocity block (positive diagonal), as padded velocity rows.
  VelocityBlockAssembly(const PressureVelocitySystem<Dim>& sys, const RowSelection& rows)
      : st_(sys), tiles_(sys.tiles()), nFaces_(st_.faces()), m_(st_.dofsPerTile()), compact_(compactIndex(rows)) {
    if (rows.fullSize() != sys.velocityRows())
      throw std::invalid_argument("VelocityBlockAssembly: a selection of " + std::to_string(rows.fullSize()) +
                                  " rows for a velocity block of " + std::to_string(sys.velocityRows()));
    if (tiles_) buildColumnBlock();
    const std::vector<std::uint32_t>& padded = rows.rows();
    matrix_ = buildCsrRows(rows.size(), rows.size(), [&](std::size_t r, auto&& emit) {
      const std::size_t i = padded[r];
      if (i < nFaces_) st_.faceRow(i, [&](std::size_t f, double v) { emit(column(f), v); }, expandTileFace(emit));
      else tileRow(i - nFaces_, emit);
    });
    if (missing_.load())
      throw std::logic_error("VelocityBlockAssembly: a velocity row with entries has a zero diagonal");
  }

  const CsrMatrix& matrix() const { return matrix_; }
  CsrMatrix release() { return std::move(matrix_); }

 private:
  // tileFace(t, p, v) of VelocityBlockStencil as entries v C_p of the DOF columns of tile t.
  template <class Emit>
  auto expandTileFace(const Emit& emit) const {
    return [this, &emit](std::size_t t, std::size_t p, double v) {
      const auto row = tiles_->tile(t).couplingRows.row(Eigen::Index(p));
      for (int k = 0; k < m_; ++k) emit(column(nFaces_ + t * m_ + k), v * row[k]);
    };
  }

  // Row k of tile t: the precomputed couplings (buildColumnBlock), then the tile's own block.
  template <class Emit>
  void tileRow(std::size_t dof, const Emit& emit) const {
    const std::size_t t = dof / m_;
    const int k = int(dof % m_);
    const ColumnBlock& tr = tileRows_[t];
    for (std::size_t j = 0; j < tr.columns.size(); ++j) emit(tr.columns[j], tr.values(k, Eigen::Index(j)));
    for (int l = 0; l < m_; ++l) emit(column(nFaces_ + t * m_ + l), ownBlocks_[t](k, l));
  }

  // Per tile: sum over its coupling faces j and the samples s holding j of C_j^T d_sj Q_s e_s,
  // without the entries of its own DOFs (those are in viscosityTileBlocks).
  void buildColumnBlock() {
    const std::size_t nt = tiles_->numTiles();
    ownBlocks_ = tiles_->viscosityTileBlocks(st_.stressCoefficients());
    tileRows_.resize(nt);
#pragma omp parallel for schedule(dynamic, 1)
    for (std::ptrdiff_t ti = 0; ti < std::ptrdiff_t(nt); ++ti) {
      const std::size_t t = std::size_t(ti);
      const auto& td = tiles_->tile(t);
      DenseColumns acc;
      for (std::size_t p = 0; p < td.coupling.size(); ++p) {
        const Eigen::VectorXd cj = td.couplingRows.row(Eigen::Index(p)).transpose();
        const auto add = [&](std::size_t col, double v) { acc.add(col, v * cj); };
        st_.couplingFaceRow(td.coupling[p], [&](std::size_t f, double v) { add(column(f), v); },
                            [&](std::size_t u, std::size_t q, double v) {
                              if (u != t) expandTileFace(add)(u, q, v);
                            });
      }
      tileRows_[t] = acc.block(m_);
    }
  }

  // The compact column of a padded velocity row. A row with entries but a zero diagonal cannot
  // occur (every unknown face has mass, every tile block is SPD); it is flagged, not thrown,
  // because this runs inside parallel loops, and reported after them.
  std::size_t column(std::size_t padded) const {
    const std::int32_t c = compact_[padded];
    if (c >= 0) return std::size_t(c);
    missing_.store(true, std::memory_order_relaxed);
    return 0;
  }

  VelocityBlockStencil<Dim> st_;
  const ReducedTiles<Dim>* tiles_;
  std::size_t nFaces_;
  int m_;
  std::vector<std::int32_t> compact_;
  std::vector<Eigen::MatrixXd> ownBlocks_;
  std::vector<ColumnBlock> tileRows_;
  CsrMatrix matrix_;
  mutable std::atomic<bool> missing_{false};
};

}  // namespace multigrid
}  // namespace stokes::solver
