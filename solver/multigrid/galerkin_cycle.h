#pragma once
// The velocity V-cycle of the pressure-velocity form on live rows with Galerkin coarse operators.
// Every level stores only its unknowns, in compressed rows:
//
//   level 0      A_0 = the velocity block [u_C | v_R] assembled on its live rows
//                (velocity_block_matrix.h), applied with the tiles' couplings in factored form
//                (tile_coupled_rows.h) once the coarse levels are formed from it;
//   level l + 1  A_{l+1} = P_l^T A_l P_l  on the coarse samples P_l reaches,
//
// P_l the staggered face prolongation of sparse_grid/grid_transfer.h between the layouts of
// levels l and l + 1 (parent cells, dx doubled), restricted to the live rows of level l and to the
// coarse samples it uses; into the tiles (level 0 only) P = E P_g, the least-squares fit of the
// prolonged faces (tile_face_transfer.h), so a coarse level holds no tile interiors. R = P^T.
//
// Why Galerkin: next to solids and walls the re-discretised coarse operator of
// multigrid_hierarchy.h does not represent the fine one (a two-level cycle with R A P took the
// velocity PCG from 23 to 11 iterations with solids), and P^T A P is right by
// construction wherever the fine level is, with no rule for walls, air or tiles on coarse levels.
// The cycle stays symmetric positive definite (R = P^T, the same Chebyshev smoother before and
// after), as MINRES needs, and bit-identical for any thread count (csr_matrix.h).
#include <algorithm>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <vector>

#include "solver/krylov/compact_rows.h"
#include "solver/krylov/csr_matrix.h"
#include "solver/multigrid/multigrid.h"
#include "solver/multigrid/multigrid_hierarchy.h"
#include "solver/multigrid/tile_coupled_rows.h"
#include "solver/multigrid/velocity_block_matrix.h"
#include "sparse_grid/grid_transfer.h"

namespace stokes::solver {
inline namespace multigrid {

/// One level of an assembled hierarchy: A on its rows, the padded sample of each row (level 0:
/// velocity rows [faces | tile DOFs]; coarse levels: face samples of their layout), and the
/// prolongation from the next coarser level (empty on the coarsest) with its transpose.
struct AssembledLevel {
  /// A, empty on a level applied in factored form (`factored`) once the coarser level is formed.
  CsrMatrix a, p, pt;
  std::vector<std::uint32_t> padded;
  Vector diagonal{};  ///< A's diagonal where `a` is released (factored level 0)
  /// The rows from tileRows on are tile DOFs, dofsPerTile consecutive rows per tile (0: none).
  std::size_t tileRows = 0;
  int dofsPerTile = 0;
  /// The smoother's blocks: strongly coupled face groups (appendStrongPairBlocks), then the tiles.
  MultigridLevel::DiagonalBlocks blocks{};
  /// Level 0 with tiles: A's rows with the tiles' couplings in factored form (tile_coupled_rows.h).
  MultigridLevel::RowMap factored{};
  std::size_t factoredBytes = 0;
  std::size_t rows() const { return a.rows > 0 ? a.rows : diagonal.size(); }
};

/// Appends to `b` the inverses of the dense diagonal blocks of `a` over the rows [begin, a.rows),
/// `size` rows each (the smoother's block Jacobi on a tile's DOFs, MultigridLevel::DiagonalBlocks).
inline void appendDiagonalBlockInverses(const CsrMatrix& a, std::size_t begin, int size, MultigridLevel::DiagonalBlocks& b) {
  if (size <= 0 || begin >= a.rows) return;
  const std::size_t m = std::size_t(size), count = (a.rows - begin) / m;
  if (begin + count * m != a.rows) throw std::logic_error("appendDiagonalBlockInverses: the rows do not split into blocks");
  Vector inverses(count * m * m, 0.0);
  std::vector<std::string> failures(count);
#pragma omp parallel for schedule(dynamic, 4)
  for (std::ptrdiff_t k = 0; k < std::ptrdiff_t(count); ++k) {
    const std::size_t first = begin + std::size_t(k) * m;
    Eigen::MatrixXd h = Eigen::MatrixXd::Zero(size, size);
    for (std::size_t i = 0; i < m; ++i)
      for (std::int64_t e = a.start[first + i]; e < a.start[first + i + 1]; ++e) {
        const std::size_t c = std::size_t(a.col[e]);
        if (c >= first && c < first + m) h(Eigen::Index(i), Eigen::Index(c - first)) += a.value[e];
      }
    const Eigen::LLT<Eigen::MatrixXd> llt(h);
    if (llt.info() != Eigen::Success) {
      failures[std::size_t(k)] = "appendDiagonalBlockInverses: block " + std::to_string(k) + " is not positive definite";
      continue;
    }
    const Eigen::MatrixXd inv = llt.solve(Eigen::MatrixXd::Identity(size, size));
    for (std::size_t i = 0; i < m; ++i)
      for (std::size_t j = 0; j < m; ++j) inverses[(std::size_t(k) * m + i) * m + j] = inv(Eigen::Index(i), Eigen::Index(j));
  }
  for (const std::string& f : failures)
    if (!f.empty()) throw std::runtime_error(f);
  std::vector<std::uint32_t> rows(m);
  for (std::size_t k = 0; k < count; ++k) {
    for (std::size_t i = 0; i < m; ++i) rows[i] = std::uint32_t(begin + k * m + i);
    b.append(rows.data(), m, inverses.data() + k * m * m);
  }
}

/// A pair of rows i, j is strongly coupled where |a_ij| > kStrongPairCoupling sqrt(a_ii a_jj): the
/// 2 x 2 block's scaled eigenvalues are 1 -+ |a_ij| / sqrt(a_ii a_jj), and the small one lies
/// below the smoother's interval. On plane-cut weights such pairs are the velocity components of
/// a corner face pair where one shear sample dominates both rows (a liquid sliver: tiny mass, one
/// stress weight); they are near-null modes of A that no coarse level represents.
/// Measured (bench/results/schur_spectrum.md): C^-1 A's smallest eigenvalues were these pairs.
/// 0.6 against 0.8 (armadillos res 128, first step): C^-1 A kappa 40 against 74, MINRES 94 against
/// 109 iterations per step over the first 2 frames; 0.5: 37, 94.
inline constexpr double kStrongPairCoupling = 0.6;
/// A weak row (diagonal below kWeakRowFraction of the median) joins a group already where
/// |a_ij| > kWeakRowCoupling sqrt(a_ii a_jj). Where the free surface meets a wall the cut cells
/// leave clusters of 20-70 such rows (0.1-1.4% of the median diagonal) whose slow mode point
/// smoothing misses (pile at rest, res 448: C^-1 A kappa 180, the cycle's slowest mode on the
/// wall x = max); grouped, the GMRES iterations per step fall from 59-166 to 38-65 there (res 640:
/// 151-205 to 75-96), and elsewhere nothing changes (armadillos 128, beam 96: the same iterations).
/// A lower pair cut for all rows instead (0.2-0.3) grouped too much: fewer iterations, but each
/// 1.7x dearer and a set-up 2-3x longer (bench/results/saddle_point.md).
inline constexpr double kWeakRowFraction = 0.1;
inline constexpr double kWeakRowCoupling = 0.2;
/// The smallest eigenvalue of a group's block, relative to its largest, that the smoother inverts:
/// a group singular in A itself keeps a bounded, positive step. 1e-3 under-corrected groups with
/// a near-null mode (beam 96: 36-46 GMRES iterations per step against 26-32 with 1e-6).
inline constexpr double kStrongBlockFloor = 1e-6;
/// The largest group: a pair whose groups together would exceed it is not merged.
inline constexpr std::size_t kMaxStrongGroupRows = 16;

/// Appends to `b` the groups of rows below `end` linked by strongly coupled pairs (above) with the
/// inverses of their diagonal blocks: the smoother then solves each group exactly. Pairs merge
/// strongest first (ties by row), and a merge that would pass kMaxStrongGroupRows is skipped, so
/// a long chain splits into groups rather than falling back to point Jacobi.
inline void appendStrongPairBlocks(const CsrMatrix& a, std::size_t end, MultigridLevel::DiagonalBlocks& b) {
  const Vector d = a.diagonal();
  std::vector<std::size_t> parent(end);
  for (std::size_t i = 0; i < end; ++i) parent[i] = i;
  auto root = [&](std::size_t i) {
    while (parent[i] != i) i = parent[i] = parent[parent[i]];
    return i;
  };
  double weakBelow = 0.0;  // kWeakRowFraction of the median positive diagonal
  {
    std::vector<double> positive;
    for (std::size_t i = 0; i < end; ++i)
      if (d[i] > 0.0) positive.push_back(d[i]);
    if (!positive.empty()) {
      std::nth_element(positive.begin(), positive.begin() + std::ptrdiff_t(positive.size() / 2), positive.end());
      weakBelow = kWeakRowFraction * positive[positive.size() / 2];
    }
  }
  struct Pair {
    double coupling;
    std::uint32_t i, j;
  };
  std::vector<Pair> pairs;
  for (std::size_t i = 0; i < end; ++i)
    for (std::int64_t k = a.start[i]; k < a.start[i + 1]; ++k) {
      const std::size_t j = std::size_t(a.col[k]);
      if (j <= i || j >= end || !(d[i] > 0.0 && d[j] > 0.0)) continue;
      const double c = std::abs(a.value[k]) / std::sqrt(d[i] * d[j]);
      const bool weak = d[i] < weakBelow || d[j] < weakBelow;
      if (c > kStrongPairCoupling || (weak && c > kWeakRowCoupling)) pairs.push_back({c, std::uint32_t(i), std::uint32_t(j)});
    }
  if (pairs.empty()) return;
  std::sort(pairs.begin(), pairs.end(), [](const Pair& x, const Pair& y) {
    return x.coupling != y.coupling ? x.coupling > y.coupling : x.i != y.i ? x.i < y.i : x.j < y.j;
  });
  std::vector<std::uint32_t> size(end, 1);
  for (const Pair& q : pairs) {
    const std::size_t ri = root(q.i), rj = root(q.j);
    if (ri == rj || size[ri] + size[rj] > kMaxStrongGroupRows) continue;
    parent[rj] = ri;
    size[ri] += size[rj];
  }
  // groups in order of their first row (deterministic), rows increasing within a group
  std::vector<std::int32_t> groupOf(end, -1);  // a root's group, numbered by its first row
  std::vector<std::vector<std::uint32_t>> groups;
  for (std::size_t i = 0; i < end; ++i) {
    const std::size_t r = root(i);
    if (size[r] < 2) continue;
    if (groupOf[r] < 0) {
      groupOf[r] = std::int32_t(groups.size());
      groups.emplace_back();
    }
    groups[std::size_t(groupOf[r])].push_back(std::uint32_t(i));
  }
  // each group's inverse in parallel, appended in group order (the same bits for any thread count)
  using RowMajor = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  std::vector<RowMajor> inverses(groups.size());
#pragma omp parallel for schedule(dynamic, 16)
  for (std::ptrdiff_t gi = 0; gi < std::ptrdiff_t(groups.size()); ++gi) {
    const std::vector<std::uint32_t>& g = groups[std::size_t(gi)];
    const Eigen::Index m = Eigen::Index(g.size());
    Eigen::MatrixXd h = Eigen::MatrixXd::Zero(m, m);
    for (Eigen::Index p = 0; p < m; ++p)
      for (std::int64_t k = a.start[g[std::size_t(p)]]; k < a.start[g[std::size_t(p)] + 1]; ++k) {
        const auto it = std::lower_bound(g.begin(), g.end(), std::uint32_t(a.col[k]));
        if (it != g.end() && *it == std::uint32_t(a.col[k])) h(p, Eigen::Index(it - g.begin())) += a.value[k];
      }
    // H^-1 with H's eigenvalues raised to at least kStrongBlockFloor of its largest
    const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(h);
    const double lo = kStrongBlockFloor * es.eigenvalues().maxCoeff();
    if (!(lo > 0.0)) continue;  // an empty inverse: the group keeps point Jacobi
    const Eigen::VectorXd invLambda = es.eigenvalues().cwiseMax(lo).cwiseInverse();
    inverses[std::size_t(gi)] = es.eigenvectors() * invLambda.asDiagonal() * es.eigenvectors().transpose();
  }
  for (std::size_t gi = 0; gi < groups.size(); ++gi)
    if (inverses[gi].size() > 0) b.append(groups[gi].data(), groups[gi].size(), inverses[gi].data());
}

/// The fused passes' view of one matrix of the hierarchy h (kept alive by the kernel).
inline MultigridLevel::RowMap rowMap(std::shared_ptr<const std::vector<AssembledLevel>> h, const CsrMatrix& m) {
  return {[h, &m](const double* x, double* y, std::size_t b, std::size_t e) { m.applyRows(x, y, b, e); },
          balancedRowChunks(m), m.entries() + m.rows};
}

/// The V-cycle's view of an assembled hierarchy (R = P^T, so A_{l+1} = R A_l P is Galerkin), with
/// the row kernels that fuse the cycle's passes.
inline std::vector<MultigridLevel> assembledLevels(std::shared_ptr<const std::vector<AssembledLevel>> h) {
  std::vector<MultigridLevel> levels;
  for (std::size_t l = 0; l < h->size(); ++l) {
    const AssembledLevel* L = &(*h)[l];
    MultigridLevel level;
    level.size = L->rows();
    level.diagonal = L->a.rows > 0 ? L->a.diagonal() : L->diagonal;
    level.blocks = L->blocks;
    if (L->factored.rows) {
      level.apply = [h, L](const double* x, double* y) { applyRowMap(L->factored, x, y, [](std::ptrdiff_t) {}); };
      level.applyRows = L->factored;
    } else {
      level.apply = [h, L](const double* x, double* y) { L->a.apply(x, y); };
      level.applyRows = rowMap(h, L->a);
    }
    if (l + 1 < h->size()) {
      level.restrictToCoarse = [r = rowMap(h, L->pt)](const double* f, double* c) {
        applyRowMap(r, f, c, [](std::ptrdiff_t) {});
      };
      level.prolongToFine = [h, L](const double* c, double* f) { L->p.apply(c, f); };
      level.prolongRows = rowMap(h, L->p);
    }
    levels.push_back(std::move(level));
  }
  return levels;
}

inline std::shared_ptr<Multigrid> assembledMultigrid(std::shared_ptr<const std::vector<AssembledLevel>> h,
                                                     const MultigridOptions& opt) {
  return std::make_shared<Multigrid>(assembledLevels(std::move(h)), opt);
}

/// Builds the Galerkin velocity hierarchy of `sys` on its live velocity rows `rows`.
///
/// Tiles on coarse levels: a tile's DOFs stay rows of the coarse levels (P is the identity on them)
/// while the tile spans more than kFoldTileWidth coarse cells; then they are folded into the coarse
/// faces by the fit, P_t = E_t P_g(0<-1) ... P_g(l<-l+1), the polynomial closest to the prolonged
/// face field over the tile's level-0 faces. Folding at level 1 (tile_face_transfer.h's choice)
/// couples every coarse face of a tile to every other through the tile's 26 DOFs: on the beam
/// (res 64, tiles of 8) level 1 held 255 entries per row against 108 without tiles, and the cycle
/// cost 2.6x its fine level there.
template <int Dim>
class GalerkinVelocityHierarchy {
 public:
  /// Coarsens until a level has at most kCoarsestRows rows, stops shrinking, or has 12 levels.
  /// (The coarsest level is solved densely: with 800 rows its solve would cost more than
  /// the fine level's on a small scene.)
  static constexpr std::size_t kCoarsestRows = 256;
  /// Interpolation across the face normals (sparse_grid::CellAxes). 2D: linear, whose coarse
  /// stencils stay small there. 3D: linear where viscosity dominates the step, mu dt / (rho dx^2) at
  /// least kLinearMinViscousNumber, else constant. Constant P cannot carry a rotation or a bending
  /// mode (u_x linear across x's cell axes), which costs a thin viscous body (beam res 64 / 96, first
  /// step: C^-1 A kappa 139 / 191 constant, 16 / 27 linear; MINRES, beam 96: 255 against 104
  /// iterations, Krylov 1.07-1.52 against 0.97-1.29 s; beam 128: 269 against 106-133, 2.6-3.9
  /// against 2.2-2.6 s), while linear P's denser coarse levels cost the inertia-dominated armadillos
  /// (res 128, nu 114: 110 against 72-91 iterations, 0.33-0.43 against 0.56-0.77 s; 5.4 stored
  /// entries over the levels per fine-level entry against 1.4).
  static constexpr double kLinearMinViscousNumber = 1000.0;
  static sparse_grid::CellAxes cellAxes(double viscousNumber, FaceInterpolation choice = FaceInterpolation::Auto) {
    const bool linear = Dim == 2 || choice == FaceInterpolation::Linear ||
                        (choice == FaceInterpolation::Auto && viscousNumber >= kLinearMinViscousNumber);
    return linear ? sparse_grid::CellAxes::Linear : sparse_grid::CellAxes::Constant;
  }
  /// A tile folds into the faces of the first coarse level on which it spans at most this many cells.
  static constexpr double kFoldTileWidth = 2.0;

  /// How level 0 applies the tiles' couplings: Factored (tile_coupled_rows.h, the default) or as
  /// the assembled matrix's dense rows (kept for comparison: bench_velocity_cycle). Measured
  /// (bench/results/reduced_tiles.md, ball n = 96, 2 threads): level 0 0.66-1.0x the assembled
  /// time, MINRES 0.89-0.91x.
  enum class TileCouplings { Assembled, Factored };

  GalerkinVelocityHierarchy(const PressureVelocitySystem<Dim>& sys, const RowSelection& rows, const MultigridOptions& opt,
                            TileCouplings couplings = TileCouplings::Factored);

  std::shared_ptr<const std::vector<AssembledLevel>> levels() const { return levels_; }

  /// Stored bytes of all levels' operators and transfers.
  std::size_t bytes() const;

 private:
  // A level's rows are its face samples (padded index below faceSamples), then the kept tiles' DOFs;
  // marks where the tiles start and builds the smoother's blocks (AssembledLevel::blocks).
  void markRowsAndBlocks(AssembledLevel& level, std::size_t faceSamples) const;

  // Level 0 with tiles, unless it is the coarsest, applies their couplings in factored form
  // (tile_coupled_rows.h) in place of its assembled A. The coarse levels keep theirs: in factored
  // form each would evaluate J on the fine coupling faces, which cost more than their assembled
  // tile rows (ball n = 96, tiles 16 / 3: one V-cycle 20.9 against 19.5 ms).
  void factorTileCouplings(const PressureVelocitySystem<Dim>& sys, const RowSelection& rows, std::vector<AssembledLevel>& levels) const;

  // A tile's fit as a dense m x columns matrix over the samples `columns` (padded, one level).
  using TileFit = ColumnBlock;

  // Level l's rows are its face samples (padded index < Dim * slots, increasing), then the DOFs of
  // the kept tiles (Dim * slots + t m + k). Builds P from level l + 1 to level l, the coarse rows
  // (`coarsePadded`), the kept tiles' fits one level down and which tiles fold now.
  CsrMatrix transfer(int l, const sparse_grid::BlockLayout<Dim>& fine, const sparse_grid::BlockLayout<Dim>& coarse,
                     const std::vector<std::uint32_t>& finePadded, const std::vector<std::uint8_t>& kept,
                     const std::vector<TileFit>& fit, std::vector<std::uint32_t>& coarsePadded,
                     std::vector<TileFit>& coarseFit, std::vector<std::uint8_t>& fold) const;

  // E_t P_g: M^_t^-1 sum_{faces j of t} C_j^T (P_g)_j, over the coarse samples.
  TileFit fitOfFaces(std::size_t t, const sparse_grid::SparseRows& pg) const;

  // F P_g for a fit F over the fine samples.
  TileFit throughProlongation(const TileFit& f, const sparse_grid::SparseRows& pg) const;

  const ReducedTiles<Dim>* tiles_;
  std::size_t nt_;
  int m_;
  sparse_grid::CellAxes cellAxes_;
  std::vector<std::unique_ptr<sparse_grid::BlockLayout<Dim>>> layouts_;
  std::shared_ptr<const std::vector<AssembledLevel>> levels_;
};

// Compiled once, in galerkin_cycle.cpp.
extern template class GalerkinVelocityHierarchy<2>;
extern template class GalerkinVelocityHierarchy<3>;

}  // namespace multigrid
}  // namespace stokes::solver
