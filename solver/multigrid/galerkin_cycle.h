#pragma once
// The velocity V-cycle of the pressure-velocity form on live rows with Galerkin coarse operators
// (issue 32, items 1-3). Every level stores only its unknowns, in compressed rows:
//
//   level 0      A_0 = the velocity block [u_C | v_R] assembled on its live rows
//                (velocity_block_matrix.h);
//   level l + 1  A_{l+1} = P_l^T A_l P_l  on the coarse samples P_l reaches,
//
// P_l the staggered face prolongation of sparse_grid/grid_transfer.h between the layouts of
// levels l and l + 1 (parent cells, dx doubled), restricted to the live rows of level l and to the
// coarse samples it uses; into the tiles (level 0 only) P = E P_g, the least-squares fit of the
// prolonged faces (tile_face_transfer.h), so a coarse level holds no tile interiors. R = P^T.
//
// Why Galerkin: next to solids and walls the re-discretised coarse operator of
// multigrid_hierarchy.h does not represent the fine one (a two-level cycle with R A P took the
// velocity PCG from 23 to 11 iterations with solids, docs/NOTES.md §4), and P^T A P is right by
// construction wherever the fine level is, with no rule for walls, air or tiles on coarse levels.
// The cycle stays symmetric positive definite (R = P^T, the same Chebyshev smoother before and
// after), as MINRES needs, and bit-identical for any thread count (csr_matrix.h).
#include <algorithm>
#include <cstdint>
#include <memory>
#include <unordered_map>
#include <vector>

#include "solver/krylov/compact_rows.h"
#include "solver/multigrid/csr_matrix.h"
#include "solver/multigrid/multigrid.h"
#include "solver/multigrid/multigrid_hierarchy.h"
#include "solver/multigrid/velocity_block_matrix.h"
#include "sparse_grid/grid_transfer.h"

namespace stokes::solver::inline multigrid {

/// One level of an assembled hierarchy: A on its rows, the padded sample of each row (level 0:
/// velocity rows [faces | tile DOFs]; coarse levels: face samples of their layout), and the
/// prolongation from the next coarser level (empty on the coarsest) with its transpose.
struct AssembledLevel {
  CsrMatrix a, p, pt;
  std::vector<std::uint32_t> padded;
};

/// The V-cycle's view of an assembled hierarchy (R = P^T, so A_{l+1} = R A_l P is Galerkin).
inline std::shared_ptr<Multigrid> assembledMultigrid(std::shared_ptr<const std::vector<AssembledLevel>> h,
                                                     const MultigridOptions& opt) {
  std::vector<MultigridLevel> levels;
  for (std::size_t l = 0; l < h->size(); ++l) {
    const AssembledLevel* L = &(*h)[l];
    MultigridLevel level;
    level.size = L->a.rows;
    level.diagonal = L->a.diagonal();
    level.apply = [h, L](const double* x, double* y) { L->a.apply(x, y); };
    if (l + 1 < h->size()) {
      level.restrictToCoarse = [h, L](const double* f, double* c) { L->pt.apply(f, c); };
      level.prolongToFine = [h, L](const double* c, double* f) { L->p.apply(c, f); };
    }
    levels.push_back(std::move(level));
  }
  return std::make_shared<Multigrid>(std::move(levels), opt);
}

/// Builds the Galerkin velocity hierarchy of `sys` on its live velocity rows `rows`.
template <int Dim>
class GalerkinVelocityHierarchy {
 public:
  /// Coarsens until a level has at most kCoarsestRows rows, stops shrinking, or has 12 levels.
  /// (The coarsest level is a dense pseudo-inverse: with 800 rows its mat-vec would cost more than
  /// the fine level's on a small scene.)
  static constexpr std::size_t kCoarsestRows = 256;
  GalerkinVelocityHierarchy(const PressureVelocitySystem<Dim>& sys, const RowSelection& rows, const MultigridOptions& opt)
      : tiles_(sys.tiles()), nFaces0_(Dim * sys.layout().numSlots()) {
    auto levels = std::make_shared<std::vector<AssembledLevel>>();
    levels->push_back({VelocityBlockAssembly<Dim>(sys, rows).release(), {}, {}, rows.rows()});
    const sparse_grid::BlockLayout<Dim>* fine = &sys.layout();
    while (levels->back().a.rows > std::min(kCoarsestRows, opt.maxCoarseRows) && levels->size() < 12) {
      auto coarse = std::make_unique<sparse_grid::BlockLayout<Dim>>(sparse_grid::coarsenLayout(*fine));
      AssembledLevel& f = levels->back();
      AssembledLevel next;
      f.p = prolongation(*fine, *coarse, f.padded, levels->size() == 1, next.padded);
      f.pt = transpose(f.p);
      next.a = galerkinProduct(f.pt, f.a, f.p);
      if (next.a.rows == 0 || next.a.rows >= f.a.rows) {  // no coarsening left: this level is the coarsest
        f.p = {};
        f.pt = {};
        break;
      }
      levels->push_back(std::move(next));
      layouts_.push_back(std::move(coarse));
      fine = layouts_.back().get();
    }
    levels_ = std::move(levels);
  }

  std::shared_ptr<const std::vector<AssembledLevel>> levels() const { return levels_; }

  /// Stored bytes of all levels' operators and transfers.
  std::size_t bytes() const {
    std::size_t b = 0;
    for (const AssembledLevel& l : *levels_) b += l.a.bytes() + l.p.bytes() + l.pt.bytes() + 4 * l.padded.size();
    return b;
  }

 private:
  // P from `coarse` to `fine` on the fine rows `finePadded` (their padded samples); fills the
  // coarse level's padded samples (the coarse samples P uses, increasing).
  CsrMatrix prolongation(const sparse_grid::BlockLayout<Dim>& fine, const sparse_grid::BlockLayout<Dim>& coarse,
                         const std::vector<std::uint32_t>& finePadded, bool withTiles,
                         std::vector<std::uint32_t>& coarsePadded) const {
    const std::size_t nFine = Dim * fine.numSlots();
    const bool tiles = withTiles && tiles_ && tiles_->numTiles() > 0;
    std::vector<std::uint8_t> activeFine(nFine, 0);
    for (std::uint32_t i : finePadded)
      if (i < nFine) activeFine[i] = 1;
    if (tiles)
      for (std::size_t f = 0; f < nFine; ++f)
        if (tiles_->tileOfFace(f) >= 0) activeFine[f] = 1;
    const sparse_grid::GridTransfer<Dim> gt(fine, coarse, faceChannels<Dim>(), {}, activeFine, {});
    const sparse_grid::SparseRows& pg = gt.prolongation();
    // the coarse samples in use, numbered in increasing order
    std::vector<std::int32_t> coarseIndex(gt.coarseSize(), -1);
    for (std::size_t f = 0; f < nFine; ++f)
      if (activeFine[f])
        for (std::int64_t k = pg.start[f]; k < pg.start[f + 1]; ++k) coarseIndex[std::size_t(pg.col[k])] = 0;
    coarsePadded.clear();
    for (std::size_t c = 0; c < coarseIndex.size(); ++c)
      if (coarseIndex[c] == 0) {
        coarseIndex[c] = std::int32_t(coarsePadded.size());
        coarsePadded.push_back(std::uint32_t(c));
      }
    std::vector<TileProlongation> tileRows;
    if (tiles) tileRows = tileProlongations(pg, coarseIndex);
    const int m = tiles ? tiles_->dofsPerTile() : 0;
    return buildCsrRows(finePadded.size(), coarsePadded.size(), [&](std::size_t r, auto&& emit) {
      const std::size_t i = finePadded[r];
      if (i < nFine) {
        for (std::int64_t k = pg.start[i]; k < pg.start[i + 1]; ++k)
          emit(std::size_t(coarseIndex[std::size_t(pg.col[k])]), pg.weight[k]);
        return;
      }
      const std::size_t dof = i - nFaces0_;
      const TileProlongation& tp = tileRows[dof / m];
      for (std::size_t j = 0; j < tp.columns.size(); ++j) emit(tp.columns[j], tp.values(Eigen::Index(dof % m), Eigen::Index(j)));
    });
  }

  struct TileProlongation {
    std::vector<std::size_t> columns;
    Eigen::MatrixXd values;  // dofs x columns
  };

  // Rows of E P_g per tile: M^_t^-1 sum_{faces j of t} C_j^T (P_g)_j.
  std::vector<TileProlongation> tileProlongations(const sparse_grid::SparseRows& pg, const std::vector<std::int32_t>& coarseIndex) const {
    const std::size_t nt = tiles_->numTiles();
    const int m = tiles_->dofsPerTile();
    std::vector<TileProlongation> out(nt);
#pragma omp parallel for schedule(dynamic, 1)
    for (std::ptrdiff_t ti = 0; ti < std::ptrdiff_t(nt); ++ti) {
      std::unordered_map<std::size_t, std::size_t> position;
      std::vector<std::size_t> columns;
      std::vector<Eigen::VectorXd> acc;
      tiles_->forEachTileFaceRow(std::size_t(ti), [&](std::int64_t f, const Eigen::Map<const Eigen::VectorXd>& c) {
        for (std::int64_t k = pg.start[f]; k < pg.start[f + 1]; ++k) {
          const std::size_t col = std::size_t(coarseIndex[std::size_t(pg.col[k])]);
          const auto [it, fresh] = position.emplace(col, columns.size());
          if (fresh) {
            columns.push_back(col);
            acc.push_back(pg.weight[k] * c);
          } else {
            acc[it->second] += pg.weight[k] * c;
          }
        }
      });
      Eigen::MatrixXd F(m, Eigen::Index(columns.size()));
      for (std::size_t j = 0; j < columns.size(); ++j) F.col(Eigen::Index(j)) = acc[j];
      out[ti].columns = std::move(columns);
      out[ti].values = tiles_->tile(std::size_t(ti)).massHatInverse * F;
    }
    return out;
  }

  const ReducedTiles<Dim>* tiles_;
  std::size_t nFaces0_;
  std::vector<std::unique_ptr<sparse_grid::BlockLayout<Dim>>> layouts_;
  std::shared_ptr<const std::vector<AssembledLevel>> levels_;
};

}  // namespace stokes::solver::inline multigrid
