#pragma once
// The finest level of the Galerkin velocity cycle with the tiles' couplings in factored form: the
// same matrix as VelocityBlockAssembly (velocity_block_matrix.h), applied without its dense rows.
//
// On x = [u_C | v_R], with w = J^T v the tiles' coupling-face velocities (w_p = C_p v_t for
// coupling face p of tile t; tile_coupled_rows gathers them once per apply),
//   y_C = A_CC u_C + A_Cw w                     sparse: a Cartesian row sees a coupling face as one
//                                               entry, not as dofsPerTile entries
//   y_t = C_t^T (A_wC u_C + A_ww' w) + A_tt v_t  per tile: the coupling faces' rows, then J
// where A_wC, A_ww' are the coupling faces' rows before J (d_sp Q_s e_s over the samples s holding
// face p; A_ww' only towards the faces of other tiles) and A_tt the tile's own block
// (ReducedTiles::viscosityTileBlocks). Assembled, each Cartesian row next to a tile holds m = 26
// entries per tile it touches and each tile row one per Cartesian face its coupling faces reach.
// Here C_p v is the polynomial itself, evaluated in monomial form: per chunk the tile's field is
// turned into monomial coefficients per axis, c_a = M_a v (M_a = the basis' componentCoefficients
// times the tile's kept modes T), and w_p = sum_m monomial_m(x_p) c_{a,m}; J^T z the same way
// backwards, moments mu_a = sum_p z_p monomials(x_p) and J z = sum_a M_a^T mu_a. A coupling face
// then costs 2 x 10 multiply-adds (quadratic, 3D) for J and J^T and reads only its coordinates,
// where the assembled rows hold 2 x 26 entries for each Cartesian face next to a tile.
//
// One apply is three passes: w = J^T v (prepare), the coupling faces' rows and J by chunks of
// faces into per-chunk m-vectors (prepare), then the rows of y (applyRows): the Cartesian rows,
// and each tile row as the sum of its chunks in chunk order plus A_tt v_t. The chunks are fixed by
// the tiles, so the bits do not depend on the thread count.
#include <algorithm>
#include <atomic>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include <Eigen/Dense>

#include "kernels/polynomial_basis.h"
#include "solver/krylov/csr_matrix.h"
#include "solver/multigrid/multigrid.h"
#include "solver/multigrid/velocity_block_matrix.h"

namespace stokes::solver {
inline namespace multigrid {

template <int Dim>
class TileCoupledRows {
 public:
  /// Coupling faces per chunk of the prepare passes (about 50 k multiply-adds at m = 26).
  static constexpr std::size_t kFacesPerChunk = 512;

  /// `rows`: the live velocity rows (as VelocityBlockAssembly's); every tile DOF must be one.
  TileCoupledRows(const PressureVelocitySystem<Dim>& sys, const RowSelection& rows)
      : st_(sys), tiles_(sys.tiles()), m_(st_.dofsPerTile()) {
    if (!tiles_ || tiles_->numTiles() == 0) throw std::invalid_argument("TileCoupledRows: no tiles");
    const std::vector<std::int32_t> compact = compactIndex(rows);
    const std::vector<std::uint32_t>& padded = rows.rows();
    nC_ = std::size_t(std::lower_bound(padded.begin(), padded.end(), std::uint32_t(st_.faces())) - padded.begin());
    nt_ = tiles_->numTiles();
    if (rows.size() != nC_ + nt_ * std::size_t(m_))
      throw std::logic_error("TileCoupledRows: the tiles' DOFs are not all live rows");
    for (std::size_t i = 0; i < nt_ * std::size_t(m_); ++i)
      if (compact[st_.faces() + i] != std::int32_t(nC_ + i))
        throw std::logic_error("TileCoupledRows: the tiles' DOFs are not the last rows in tile order");
    faceOffset_.assign(nt_ + 1, 0);
    for (std::size_t t = 0; t < nt_; ++t) faceOffset_[t + 1] = faceOffset_[t] + tiles_->tile(t).coupling.size();
    const std::size_t nw = faceOffset_.back();
    // flagged, not thrown, inside the parallel builds (as VelocityBlockAssembly::column)
    std::atomic<bool> missing{false};
    auto cartesianColumn = [&](std::size_t f) {
      const std::int32_t c = compact[f];
      if (c >= 0) return std::size_t(c);
      missing.store(true, std::memory_order_relaxed);
      return std::size_t(0);
    };
    // the Cartesian rows: A_CC, then A_Cw on the rows that touch a coupling face
    cc_ = buildCsrRows(nC_, nC_, [&](std::size_t r, auto&& emit) {
      st_.faceRow(padded[r], [&](std::size_t f, double v) { emit(cartesianColumn(f), v); }, [](std::size_t, std::size_t, double) {});
    });
    const CsrMatrix cw = buildCsrRows(nC_, nw, [&](std::size_t r, auto&& emit) {
      st_.faceRow(padded[r], [](std::size_t, double) {}, [&](std::size_t t, std::size_t p, double v) { emit(faceOffset_[t] + p, v); });
    });
    cw_ = compressRows(cw, touched_);
    // the coupling faces' rows before J
    auto tileOfRow = [&](std::size_t j) {
      return std::size_t(std::upper_bound(faceOffset_.begin(), faceOffset_.end(), j) - faceOffset_.begin()) - 1;
    };
    wc_ = buildCsrRows(nw, nC_, [&](std::size_t j, auto&& emit) {
      const std::size_t t = tileOfRow(j);
      st_.couplingFaceRow(tiles_->tile(t).coupling[j - faceOffset_[t]], [&](std::size_t f, double v) { emit(cartesianColumn(f), v); },
                          [](std::size_t, std::size_t, double) {});
    });
    const CsrMatrix ww = buildCsrRows(nw, nw, [&](std::size_t j, auto&& emit) {
      const std::size_t t = tileOfRow(j);
      st_.couplingFaceRow(tiles_->tile(t).coupling[j - faceOffset_[t]], [](std::size_t, double) {},
                          [&](std::size_t u, std::size_t p, double v) {
                            if (u != t) emit(faceOffset_[u] + p, v);
                          });
    });
    ww_ = compressRows(ww, wwTouched_);
    if (missing.load()) throw std::logic_error("TileCoupledRows: a stencil reaches a face that is not a live row");
    // J in monomial form: per tile and axis a, (count x m) coefficients of C_a(x) T (basisRow)
    const auto& basis = tiles_->basis();
    count_ = basis.monomialCount();
    monomialForm_.assign(nt_ * Dim * std::size_t(count_ * m_), 0.0);
    std::vector<double> coeff(std::size_t(count_ * m_));
    for (int a = 0; a < Dim; ++a) {
      basis.componentCoefficients(a, coeff.data());
      const Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> c(coeff.data(), count_, m_);
      for (std::size_t t = 0; t < nt_; ++t) {
        Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> out(monomialMatrix(t, a), count_, m_);
        const auto& modes = tiles_->tile(t).modes;
        if (modes.size() == 0) out = c;
        else out = c * modes;
      }
    }
    axis_.resize(nw);
    const std::size_t slots = sys.layout().numSlots();
    for (std::size_t t = 0; t < nt_; ++t)
      for (std::size_t p = 0; p < tiles_->tile(t).coupling.size(); ++p)
        axis_[faceOffset_[t] + p] = std::uint8_t(std::size_t(tiles_->tile(t).coupling[p]) / slots);
    // the tiles' own blocks, row-major, and the chunks of the prepare passes
    const std::vector<Eigen::MatrixXd> own = tiles_->viscosityTileBlocks(st_.stressCoefficients());
    own_.resize(nt_ * std::size_t(m_ * m_));
    for (std::size_t t = 0; t < nt_; ++t)
      for (int k = 0; k < m_; ++k)
        for (int l = 0; l < m_; ++l) own_[(t * m_ + k) * m_ + l] = own[t](k, l);
    chunkOffset_.assign(1, 0);
    for (std::size_t t = 0; t < nt_; ++t) {
      for (std::size_t b = faceOffset_[t]; b < faceOffset_[t + 1]; b += kFacesPerChunk)
        chunks_.push_back({t, b, std::min(faceOffset_[t + 1], b + kFacesPerChunk)});
      chunkOffset_.push_back(chunks_.size());
    }
    w_.assign(nw, 0.0);
    partial_.assign(chunks_.size() * std::size_t(m_), 0.0);
    // the row pass: chunks of about 4,096 entries over the Cartesian rows, then one per tile
    rowChunks_ = balancedRowChunks(cc_);
    for (std::size_t t = 1; t <= nt_; ++t) rowChunks_.push_back(nC_ + t * std::size_t(m_));
  }

  std::size_t rows() const { return nC_ + nt_ * std::size_t(m_); }
  /// The rows from this one on are the tiles' DOFs, dofsPerTile() per tile.
  std::size_t tileRows() const { return nC_; }
  std::size_t couplingFaces() const { return w_.size(); }
  /// Multiply-adds of one apply: the stored entries, the monomials' count per coupling face for J
  /// and for J^T, and per chunk the monomial forms (2 Dim count m) and per tile A_tt (m^2).
  std::size_t work() const {
    return cc_.entries() + cw_.entries() + wc_.entries() + ww_.entries() + 2 * std::size_t(count_) * w_.size() +
           chunks_.size() * 2 * Dim * std::size_t(count_ * m_) + nt_ * std::size_t(m_ * m_);
  }
  std::size_t bytes() const {
    return cc_.bytes() + cw_.bytes() + wc_.bytes() + ww_.bytes() + w_.size() +
           8 * (own_.size() + w_.size() + partial_.size() + monomialForm_.size()) + 4 * (touched_.size() + wwTouched_.size());
  }
  const std::vector<std::size_t>& rowChunks() const { return rowChunks_; }

  /// The tiles' share of y = A x: w = C v, then the chunks' m-vectors C_t^T (A_wC u + A_ww' w).
  /// Must precede applyRows on the same x (the buffers make the operator non-re-entrant, as the
  /// cycle is).
  void prepare(const double* x) const {
    const std::size_t work = 2 * std::size_t(m_) * w_.size() + wc_.entries();
    detail::parallelFor(chunks_.size(), [&](std::ptrdiff_t c) { gatherChunk(chunks_[std::size_t(c)], x); }, work);
    detail::parallelFor(chunks_.size(), [&](std::ptrdiff_t c) { couplingChunk(std::size_t(c), x); }, work);
  }

  /// Rows [begin, end) of y = A x (after prepare(x)).
  void applyRows(const double* x, double* y, std::size_t begin, std::size_t end) const {
    const std::size_t split = std::min(end, nC_);
    if (begin < split) {
      cc_.applyRows(x, y, begin, split);
      auto it = std::lower_bound(touched_.begin(), touched_.end(), std::uint32_t(begin));
      for (; it != touched_.end() && *it < split; ++it) {
        const std::size_t k = std::size_t(it - touched_.begin());
        y[*it] += rowDot(cw_, k, w_.data());
      }
    }
    for (std::size_t r = std::max(begin, nC_); r < end; ++r) y[r] = tileRow(r - nC_, x);
  }

  /// y = A x.
  void apply(const double* x, double* y) const {
    prepare(x);
    detail::parallelFor(
        rowChunks_.size() - 1, [&](std::ptrdiff_t c) { applyRows(x, y, rowChunks_[std::size_t(c)], rowChunks_[std::size_t(c) + 1]); },
        work());
  }

 private:
  struct Chunk {
    std::size_t tile, begin, end;  // coupling faces [begin, end) of w, all of one tile
  };

  // Keeps the rows of `m` that hold entries (their indices into `rows`, increasing).
  static CsrMatrix compressRows(const CsrMatrix& m, std::vector<std::uint32_t>& rows) {
    CsrMatrix c;
    c.cols = m.cols;
    rows.clear();
    for (std::size_t r = 0; r < m.rows; ++r) {
      if (m.start[r + 1] == m.start[r]) continue;
      rows.push_back(std::uint32_t(r));
      c.col.insert(c.col.end(), m.col.begin() + m.start[r], m.col.begin() + m.start[r + 1]);
      c.value.insert(c.value.end(), m.value.begin() + m.start[r], m.value.begin() + m.start[r + 1]);
      c.start.push_back(std::int64_t(c.col.size()));
    }
    c.rows = rows.size();
    return c;
  }

  static double rowDot(const CsrMatrix& m, std::size_t r, const double* x) {
    double sum = 0.0;
    for (std::int64_t k = m.start[r]; k < m.start[r + 1]; ++k) sum += m.value[k] * x[m.col[k]];
    return sum;
  }

  using Basis = kernels::PolynomialBasis<Dim>;
  static constexpr int kMono = Basis::kMaxMonomials;

  double* monomialMatrix(std::size_t t, int a) const {
    return const_cast<double*>(monomialForm_.data()) + (t * Dim + std::size_t(a)) * std::size_t(count_ * m_);
  }
  const double* coords(std::size_t j, std::size_t tile) const {
    return tiles_->tile(tile).couplingCoords.data() + (j - faceOffset_[tile]) * Dim;
  }

  // w_p = C_p v_t on the chunk's faces, as monomial_m(x_p) (M_a v)_m with M_a the tile's
  // monomial form of axis a.
  void gatherChunk(const Chunk& c, const double* x) const {
    if (count_ == kMono) gatherChunk<kMono>(c, x);
    else gatherChunk<1 + Dim>(c, x);
  }
  template <int Count>
  void gatherChunk(const Chunk& c, const double* x) const {
    const double* v = x + nC_ + c.tile * std::size_t(m_);
    double coef[Dim][Count], mono[kMono];
    for (int a = 0; a < Dim; ++a) {
      const double* M = monomialMatrix(c.tile, a);
      for (int q = 0; q < Count; ++q) {
        double s = 0.0;
        for (int k = 0; k < m_; ++k) s += M[q * m_ + k] * v[k];
        coef[a][q] = s;
      }
    }
    const double* xs = coords(c.begin, c.tile);
    for (std::size_t j = c.begin; j < c.end; ++j, xs += Dim) {
      Basis::monomials(xs, Count, mono);
      const double* cf = coef[axis_[j]];
      double s = 0.0;
      for (int q = 0; q < Count; ++q) s += cf[q] * mono[q];
      w_[j] = s;
    }
  }

  // partial = C^T z on the chunk's faces, z_p = A_wC,p u + A_ww',p w: the moments
  // mu_a = sum_{faces p of axis a} z_p monomials(x_p), then partial = sum_a M_a^T mu_a.
  void couplingChunk(std::size_t ci, const double* x) const {
    if (count_ == kMono) couplingChunk<kMono>(ci, x);
    else couplingChunk<1 + Dim>(ci, x);
  }
  template <int Count>
  void couplingChunk(std::size_t ci, const double* x) const {
    const Chunk& c = chunks_[ci];
    double mu[Dim][Count] = {}, mono[kMono];
    auto it = std::lower_bound(wwTouched_.begin(), wwTouched_.end(), std::uint32_t(c.begin));
    const double* xs = coords(c.begin, c.tile);
    for (std::size_t j = c.begin; j < c.end; ++j, xs += Dim) {
      double z = rowDot(wc_, j, x);
      if (it != wwTouched_.end() && *it == j) {
        z += rowDot(ww_, std::size_t(it - wwTouched_.begin()), w_.data());
        ++it;
      }
      Basis::monomials(xs, Count, mono);
      double* m = mu[axis_[j]];
      for (int q = 0; q < Count; ++q) m[q] += z * mono[q];
    }
    double* out = partial_.data() + ci * std::size_t(m_);
    for (int k = 0; k < m_; ++k) out[k] = 0.0;
    for (int a = 0; a < Dim; ++a) {
      const double* M = monomialMatrix(c.tile, a);
      for (int q = 0; q < Count; ++q)
        for (int k = 0; k < m_; ++k) out[k] += M[q * m_ + k] * mu[a][q];
    }
  }

  // Row k of tile t: its chunks' sums in chunk order, then A_tt v_t.
  double tileRow(std::size_t dof, const double* x) const {
    const std::size_t t = dof / std::size_t(m_), k = dof % std::size_t(m_);
    double sum = 0.0;
    for (std::size_t c = chunkOffset_[t]; c < chunkOffset_[t + 1]; ++c) sum += partial_[c * std::size_t(m_) + k];
    const double* a = own_.data() + (t * m_ + k) * m_;
    const double* v = x + nC_ + t * std::size_t(m_);
    for (int l = 0; l < m_; ++l) sum += a[l] * v[l];
    return sum;
  }

  VelocityBlockStencil<Dim> st_;
  const ReducedTiles<Dim>* tiles_;
  int m_;
  std::size_t nC_ = 0, nt_ = 0;
  std::vector<std::size_t> faceOffset_;  // tile t's coupling faces are w[faceOffset_[t], faceOffset_[t + 1])
  CsrMatrix cc_, cw_, wc_, ww_;          // A_CC; A_Cw on touched_ rows; A_wC; A_ww' on wwTouched_ rows
  std::vector<std::uint32_t> touched_, wwTouched_;
  Vector own_;                           // A_tt row-major, tile after tile
  std::vector<Chunk> chunks_;
  std::vector<std::size_t> chunkOffset_;  // tile t's chunks are [chunkOffset_[t], chunkOffset_[t + 1])
  std::vector<std::size_t> rowChunks_;
  int count_ = 0;                         // monomials of the basis
  Vector monomialForm_;                   // per tile and axis: count_ x m, row-major
  std::vector<std::uint8_t> axis_;        // axis of each coupling face
  mutable Vector w_, partial_;
};

}  // namespace multigrid
}  // namespace stokes::solver
