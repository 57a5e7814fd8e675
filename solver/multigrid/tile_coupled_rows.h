#pragma once
// The finest level of the Galerkin velocity cycle with the tiles' couplings in factored form: the
// same matrix as VelocityBlockAssembly (velocity_block_matrix.h), applied without its dense rows.
//
// On x = [u_C | v_R], with w = J^T v the tiles' coupling-face velocities (w_p = C_p v_t for
// coupling face p of tile t; tile_coupled_rows gathers them once per apply),
//   y_C = A_CC u_C + A_Cw w                     sparse: a Cartesian row sees a coupling face as one
//                                               entry, not as dofsPerTile entries
//   y_t = C_t^T (A_wC u_C + A_ww' w) + A_tt v_t  per tile: the coupling faces' rows, then J
// where A_wC = A_Cw^T and A_ww' are the coupling faces' rows before J (d_sp Q_s e_s over the samples
// s holding face p; A_ww' only towards the faces of other tiles) and A_tt the tile's own block
// (ReducedTiles::viscosityTileBlocks). A_CC and A_tt are taken from the assembled block, A_Cw and
// A_ww' from the stencil (VelocityBlockStencil). Assembled, each Cartesian row next to a tile holds m = 26
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
#include <cstdint>
#include <memory>
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

  /// `rows`: the live velocity rows and `a` the velocity block assembled on them
  /// (VelocityBlockAssembly), whose face block and tile blocks are taken as they are: the face
  /// block is compacted in a's own arrays (no second copy at the set-up's peak); every tile DOF
  /// must be a row.
  TileCoupledRows(const PressureVelocitySystem<Dim>& sys, const RowSelection& rows, CsrMatrix&& a) {
    const VelocityBlockStencil<Dim> st(sys);
    if (!st.tiles() || st.tiles()->numTiles() == 0) throw std::invalid_argument("TileCoupledRows: no tiles");
    j_ = std::make_shared<const MonomialJ>(*st.tiles(), sys.layout().numSlots());
    const std::size_t m = std::size_t(j_->m), nt = st.tiles()->numTiles(), nw = j_->faceOffset.back();
    const std::vector<std::int32_t> compact = compactIndex(rows);
    const std::vector<std::uint32_t>& padded = rows.rows();
    nC_ = std::size_t(std::lower_bound(padded.begin(), padded.end(), std::uint32_t(st.faces())) - padded.begin());
    if (rows.size() != nC_ + nt * m || a.rows != rows.size())
      throw std::logic_error("TileCoupledRows: the tiles' DOFs are not all live rows");
    for (std::size_t i = 0; i < nt * m; ++i)
      if (compact[st.faces() + i] != std::int32_t(nC_ + i))
        throw std::logic_error("TileCoupledRows: the tiles' DOFs are not the last rows in tile order");
    // each tile's A_tt: a's diagonal tile blocks
    own_.assign(nt * m * m, 0.0);
    for (std::size_t t = 0; t < nt; ++t)
      for (std::size_t k = 0; k < m; ++k) {
        const std::size_t r = nC_ + t * m + k, first = nC_ + t * m;
        for (std::int64_t e = a.start[r]; e < a.start[r + 1]; ++e) {
          const std::size_t c = std::size_t(a.col[e]);
          if (c >= first && c < first + m) own_[(t * m + k) * m + (c - first)] = a.value[e];
        }
      }
    // the face rows that reach a tile: a row's columns increase, so its tile columns come last
    std::vector<std::uint8_t> reaches(nC_, 0);
    for (std::size_t r = 0; r < nC_; ++r)
      reaches[r] = a.start[r + 1] > a.start[r] && std::size_t(a.col[a.start[r + 1] - 1]) >= nC_ ? 1 : 0;
    cc_ = faceBlock(std::move(a), nC_);
    // Q = A_Cw, the face rows' couplings to the coupling faces, and A_ww' between the coupling
    // faces of different tiles (stress samples shared by two tiles), from the stencil
    const auto& offset = j_->faceOffset;
    q_ = buildCsrRows(nC_, nw, [&](std::size_t r, auto&& emit) {
      if (reaches[r])
        st.faceRow(padded[r], [](std::size_t, double) {}, [&](std::size_t t, std::size_t p, double v) { emit(offset[t] + p, v); });
    });
    auto tileOfFace = [&](std::size_t j) { return std::size_t(std::upper_bound(offset.begin(), offset.end(), j) - offset.begin()) - 1; };
    ww_ = buildCsrRows(nw, nw, [&](std::size_t j, auto&& emit) {
      const std::size_t t = tileOfFace(j);
      st.couplingFaceRow(st.tiles()->tile(t).coupling[j - offset[t]], [](std::size_t, double) {},
                         [&](std::size_t u, std::size_t p, double v) {
                           if (u != t) emit(offset[u] + p, v);
                         });
    });
    finish(nt);
  }

  std::size_t rows() const { return nC_ + nt_ * std::size_t(j_->m); }
  /// The rows from this one on are the tiles' DOFs, dofsPerTile per tile.
  std::size_t tileRows() const { return nC_; }
  std::size_t couplingFaces() const { return j_->faceOffset.back(); }
  /// Multiply-adds of one apply: the stored entries (Q twice), the monomials' count per coupling
  /// face for J and for J^T, and per chunk the monomial forms (2 Dim count m) and per tile A_tt
  /// (m^2).
  std::size_t work() const {
    const std::size_t m = std::size_t(j_->m), count = std::size_t(j_->count);
    return cc_.entries() + 2 * q_.entries() + ww_.entries() + 2 * count * couplingFaces() + chunks_.size() * 2 * Dim * count * m +
           nt_ * m * m;
  }
  std::size_t bytes() const {
    return cc_.bytes() + q_.bytes() + wc_.bytes() + ww_.bytes() + 8 * (own_.size() + w_.size() + partial_.size()) +
           4 * touched_.size();
  }
  const std::vector<std::size_t>& rowChunks() const { return rowChunks_; }

  /// The tiles' share of y = A x: w = C v, then the chunks' m-vectors C_t^T (A_wC u + A_ww' w).
  /// Must precede applyRows on the same x (the buffers make the operator non-re-entrant, as the
  /// cycle is).
  void prepare(const double* x) const {
    const std::size_t work = 2 * std::size_t(j_->count) * couplingFaces() + q_.entries();
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
        y[*it] += rowDot(q_, *it, w_.data());
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

  using Basis = kernels::PolynomialBasis<Dim>;
  static constexpr int kMono = Basis::kMaxMonomials;
  using RowMajor = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

  /// J of every tile in monomial form: per tile and axis a the (count x m)
  /// coefficients of C_a(x) T (ReducedTiles::basisRow), each coupling face's axis, and where each
  /// tile's coupling faces start in w.
  struct MonomialJ {
    const ReducedTiles<Dim>* tiles;
    int m, count;
    std::vector<std::size_t> faceOffset;
    Vector form;
    std::vector<std::uint8_t> axis;

    MonomialJ(const ReducedTiles<Dim>& t, std::size_t slots)
        : tiles(&t), m(t.dofsPerTile()), count(t.basis().monomialCount()), faceOffset(t.numTiles() + 1, 0) {
      const std::size_t nt = t.numTiles();
      for (std::size_t i = 0; i < nt; ++i) faceOffset[i + 1] = faceOffset[i] + t.tile(i).coupling.size();
      form.assign(nt * Dim * std::size_t(count * m), 0.0);
      std::vector<double> coeff(std::size_t(count * m));
      for (int a = 0; a < Dim; ++a) {
        t.basis().componentCoefficients(a, coeff.data());
        const Eigen::Map<const RowMajor> c(coeff.data(), count, m);
        for (std::size_t i = 0; i < nt; ++i) {
          Eigen::Map<RowMajor> out(form.data() + (i * Dim + std::size_t(a)) * std::size_t(count * m), count, m);
          const auto& modes = t.tile(i).modes;
          if (modes.size() == 0) out = c;
          else out = c * modes;
        }
      }
      axis.resize(faceOffset.back());
      for (std::size_t i = 0; i < nt; ++i)
        for (std::size_t p = 0; p < t.tile(i).coupling.size(); ++p)
          axis[faceOffset[i] + p] = std::uint8_t(std::size_t(t.tile(i).coupling[p]) / slots);
    }
    const double* matrix(std::size_t tile, int a) const {
      return form.data() + (tile * Dim + std::size_t(a)) * std::size_t(count * m);
    }
    const double* coords(std::size_t j, std::size_t tile) const {
      return tiles->tile(tile).couplingCoords.data() + (j - faceOffset[tile]) * Dim;
    }
  };

  // The rest from cc_, q_, ww_ and own_: Q's transpose and touched rows, the prepare passes' chunks
  // (each tile's coupling faces), the row pass's chunks, the buffers.
  void finish(std::size_t nt) {
    nt_ = nt;
    wc_ = transpose(q_);
    touched_.clear();
    for (std::size_t r = 0; r < q_.rows; ++r)
      if (q_.start[r + 1] > q_.start[r]) touched_.push_back(std::uint32_t(r));
    const auto& offset = j_->faceOffset;
    chunkOffset_.assign(1, 0);
    for (std::size_t t = 0; t < nt; ++t) {
      for (std::size_t b = offset[t]; b < offset[t + 1]; b += kFacesPerChunk)
        chunks_.push_back({t, b, std::min(offset[t + 1], b + kFacesPerChunk)});
      chunkOffset_.push_back(chunks_.size());
    }
    w_.assign(offset.back(), 0.0);
    partial_.assign(chunks_.size() * std::size_t(j_->m), 0.0);
    // the row pass: chunks of about 4,096 entries over the face rows, then one per tile
    rowChunks_ = balancedRowChunks(cc_);
    for (std::size_t t = 1; t <= nt; ++t) rowChunks_.push_back(nC_ + t * std::size_t(j_->m));
  }

  // The leading rows x columns block of `a` (its first `rows` rows, their columns below `rows`),
  // compacted in a's arrays: each row's entries move down to their new start, which never passes
  // their old one.
  static CsrMatrix faceBlock(CsrMatrix&& a, std::size_t rows) {
    std::int64_t out = 0;
    for (std::size_t r = 0; r < rows; ++r) {
      const std::int64_t begin = a.start[r], end = a.start[r + 1];
      a.start[r] = out;
      for (std::int64_t k = begin; k < end; ++k)
        if (std::size_t(a.col[k]) < rows) {
          a.col[out] = a.col[k];
          a.value[out] = a.value[k];
          ++out;
        }
    }
    a.start[rows] = out;
    a.start.resize(rows + 1);
    a.col.resize(std::size_t(out));
    a.value.resize(std::size_t(out));
    a.rows = a.cols = rows;
    return std::move(a);
  }

  static double rowDot(const CsrMatrix& m, std::size_t r, const double* x) {
    double sum = 0.0;
    for (std::int64_t k = m.start[r]; k < m.start[r + 1]; ++k) sum += m.value[k] * x[m.col[k]];
    return sum;
  }

  // w_p = C_p v_t on the chunk's faces, as monomial_m(x_p) (M_a v)_m with M_a the tile's
  // monomial form of axis a.
  void gatherChunk(const Chunk& c, const double* x) const {
    if (j_->count == kMono) gatherChunk<kMono>(c, x);
    else gatherChunk<1 + Dim>(c, x);
  }
  template <int Count>
  void gatherChunk(const Chunk& c, const double* x) const {
    const int m = j_->m;
    const std::size_t tile = c.tile;
    const double* v = x + nC_ + tile * std::size_t(m);
    double coef[Dim][Count], mono[kMono];
    for (int a = 0; a < Dim; ++a) {
      const double* M = j_->matrix(tile, a);
      for (int q = 0; q < Count; ++q) {
        double s = 0.0;
        for (int k = 0; k < m; ++k) s += M[q * m + k] * v[k];
        coef[a][q] = s;
      }
    }
    const double* xs = j_->coords(c.begin, tile);
    const std::uint8_t* axis = j_->axis.data();
    for (std::size_t j = c.begin; j < c.end; ++j, xs += Dim) {
      Basis::monomials(xs, Count, mono);
      const double* cf = coef[axis[j]];
      double s = 0.0;
      for (int q = 0; q < Count; ++q) s += cf[q] * mono[q];
      w_[j] = s;
    }
  }

  // partial = C^T z on the chunk's faces, z_p = A_wC,p u + A_ww',p w: the moments
  // mu_a = sum_{faces p of axis a} z_p monomials(x_p), then partial = sum_a M_a^T mu_a.
  void couplingChunk(std::size_t ci, const double* x) const {
    if (j_->count == kMono) couplingChunk<kMono>(ci, x);
    else couplingChunk<1 + Dim>(ci, x);
  }
  template <int Count>
  void couplingChunk(std::size_t ci, const double* x) const {
    const Chunk& c = chunks_[ci];
    const int m = j_->m;
    const std::size_t tile = c.tile;
    double mu[Dim][Count] = {}, mono[kMono];
    const double* xs = j_->coords(c.begin, tile);
    const std::uint8_t* axis = j_->axis.data();
    for (std::size_t j = c.begin; j < c.end; ++j, xs += Dim) {
      const double z = rowDot(wc_, j, x) + rowDot(ww_, j, w_.data());
      Basis::monomials(xs, Count, mono);
      double* mu_a = mu[axis[j]];
      for (int q = 0; q < Count; ++q) mu_a[q] += z * mono[q];
    }
    double* out = partial_.data() + ci * std::size_t(m);
    for (int k = 0; k < m; ++k) out[k] = 0.0;
    for (int a = 0; a < Dim; ++a) {
      const double* M = j_->matrix(tile, a);
      for (int q = 0; q < Count; ++q)
        for (int k = 0; k < m; ++k) out[k] += M[q * m + k] * mu[a][q];
    }
  }

  // Row k of tile i: its chunks' sums in chunk order, then A_tt v_t.
  double tileRow(std::size_t dof, const double* x) const {
    const std::size_t m = std::size_t(j_->m), i = dof / m, k = dof % m;
    double sum = 0.0;
    for (std::size_t c = chunkOffset_[i]; c < chunkOffset_[i + 1]; ++c) sum += partial_[c * m + k];
    const double* a = own_.data() + (i * m + k) * m;
    const double* v = x + nC_ + i * m;
    for (std::size_t l = 0; l < m; ++l) sum += a[l] * v[l];
    return sum;
  }

  std::shared_ptr<const MonomialJ> j_;
  std::size_t nC_ = 0, nt_ = 0;           // face rows, then m rows per tile
  CsrMatrix cc_, q_, wc_, ww_;            // A_CC; Q = A_Cw; Q^T; A_ww' (rows mostly empty)
  std::vector<std::uint32_t> touched_;    // the rows of Q that hold entries
  Vector own_;                            // A_tt row-major, tile after tile
  std::vector<Chunk> chunks_;
  std::vector<std::size_t> chunkOffset_;  // tile t's chunks are [chunkOffset_[t], chunkOffset_[t + 1])
  std::vector<std::size_t> rowChunks_;
  mutable Vector w_, partial_;
};

}  // namespace multigrid
}  // namespace stokes::solver
