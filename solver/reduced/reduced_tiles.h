#pragma once
// Reduced interior tiles (thesis 3.7, 4.1-4.3, 4.5; docs/design.md §3): inside each tile the velocity
// is a polynomial field u_R(x) = C(x) v_R, x~ = (x - x_COM) / h, coupled to the grid by
//   J f   = sum_{faces j of the tile} C_a(x_j)^T f_j      (face forces -> generalised forces)
//   J^T v = C_a(x_j) v on the tile's faces                 (generalised velocity -> faces)
//   M_R   = rho sum_j C_a(x_j)^T C_a(x_j)
//   K_R   = sum_{stress samples s inside the tile} Q_s (D J^T)_s^T (D J^T)_s,  Q = mu/c W_L^tau
//           (= 2 mu J D^T D J^T of Eq. 4.25 in this code's strain convention)
//   B     = M_R / dt + K_R
// All sums are per unit volume (dV cancels). A face is reduced if it touches a tile cell; a stress
// sample is "inside" if every face of its stencil is a face of the same tile (its stress is then
// 2 mu eps(u_R), folded into K_R); every other positive-weight sample stays a Cartesian unknown.
//
// Only "coupling" faces -- reduced faces that a Cartesian unknown's stencil touches -- carry non-zero
// forces during a solve, so the hot path gathers and scatters those alone:
//   coupleFaces(f):  for each tile  F = J f|coupling,  V = B^-1 F,  f|coupling = J^T V.
#include <Eigen/Dense>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <numeric>
#include <cstdio>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <vector>

#include "kernels/polynomial_basis.h"
#include "kernels/stencil_entries.h"
#include "solver/krylov/vector_ops.h"
#include "solver/problem/staggered_problem.h"
#include "solver/reduced/gram_accumulator.h"
#include "solver/reduced/tile_cost.h"
#include "solver/reduced/tile_history.h"
#include "solver/reduced/tile_library.h"
#include "sparse_grid/tiling.h"

namespace stokes::solver {
inline namespace reduced {

using kernels::BasisFamily;
using kernels::PolynomialBasis;
using kernels::PolynomialOrder;

struct ReducedOptions {
  PolynomialOrder order = PolynomialOrder::Quadratic;
  BasisFamily family = BasisFamily::DivergenceFree;
  sparse_grid::TilingOptions tiling{};
  /// With tiling.minTileSize: a cube splits while the least-squares fit of u* by the basis over its
  /// region misses by more than this fraction of the liquid's velocity variation (rms over faces
  /// of u* less its mean per axis); see ReducedTiles::fitMisfit. Must be > 0 exactly when
  /// tiling.minTileSize is set.
  double tileAccuracy = 0.0;
  bool fitAllFaces = false;  ///< least-squares fit of u* over all tile faces (else boundary faces)
  /// All: every tile the tiling makes; Paying: only those that tile_cost.h says pay (the others go
  /// back to Cartesian cells). solver::planSolve chooses it for a request that leaves it open.
  TileRule rule = TileRule::All;
  /// Under TileRule::Paying, the step without tiles for comparison: its live rows and the cost of
  /// its solve per row against the tiled solve's (1: the same solver). The tiles are all dropped
  /// when rows - saved + overhead >= uniformRowCost x rows (tile_cost.h). 0 rows: no comparison.
  std::size_t uniformRows = 0;
  double uniformRowCost = 1.0;
  TileCacheStrategy cache = TileCacheStrategy::Library;
  /// The shared cache (kept by the caller across steps); null: a private one for this build.
  std::shared_ptr<TileLibrary> library{};
  /// The previous step's tiling (tile_history.h), kept by the caller across steps: adaptive cubes
  /// whose region did not change keep its decision, and this build records its own. Null: every
  /// decision is taken afresh.
  std::shared_ptr<TileHistory> history{};
};

/// A rank of a problem distributed by blocks keeps the tiles with a cell within this many cells
/// of its blocks (Chebyshev distance): its rows' stencils (a cell's faces, a stress sample's faces
/// a cell away) and its blocks' faces (a tile's upper faces lie in the slots of the cells above
/// it) touch no other tile.
inline constexpr int kTileTouchCells = 2;

/// Cells around a rank's blocks (Chebyshev distance) within which a rank of a problem distributed
/// by blocks needs the whole problem's liquid weights and u* to build the tiles it keeps exactly as
/// the whole problem has them. A kept tile has a cell within kTileTouchCells of the blocks, and its
/// region lies in one cube of at most tileSize cells (sparse_grid/tiling.h: the slabs part the
/// cubes); the cube's labels read the air and solid bands around it (the dilation), and its
/// coupling faces the stencils' two cells beyond the tile plus the samples of those faces.
inline int distributedTileDepth(const sparse_grid::TilingOptions& t) {
  return kTileTouchCells + t.tileSize - 1 + std::max(t.bandAir, t.bandSolid) + 3;
}

/// Which Cartesian unknowns exist in the system the tiles are coupled into.
struct CouplingKinds {
  bool pressure = true;  ///< pressure unknowns on Cartesian cells
  bool stress = true;    ///< stress unknowns (SPD form) or viscous stencils (velocity forms)
  bool viscous = true;   ///< K_R in B (false: pressure projection, B = M_R / dt)
};

template <int Dim>
class ReducedTiles {
 public:
  using SC = StressChannels<Dim>;
  using Matrix = Eigen::MatrixXd;
  using RowMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  using VectorX = Eigen::VectorXd;
  static constexpr int kMax = PolynomialBasis<Dim>::kMaxSize;
  /// Stack storage for one basis row, padded to whole 512-bit packets.
  static constexpr int kRowStorage = 32;

  struct TileData {
    std::vector<std::int64_t> faces;     ///< all faces of the tile (global face index)
    std::vector<std::int64_t> coupling;  ///< faces touched by Cartesian unknowns
    std::vector<double> couplingCoords;  ///< Dim scaled coordinates per coupling face
    RowMatrix couplingRows;              ///< C_a(x_f) for each coupling face: the J of the hot path
    Matrix massR, viscR, inverseB;       ///< M_R, K_R, B^-1
    Matrix massHatInverse;               ///< M^-1 = Phi Phi^T (the fit E of fitFaceField)
    VectorX vStar;                       ///< least-squares fit of u*
    VectorX vFree;                       ///< B^-1 M_R v* / dt: the tile's velocity with no forces
    double reconstructionLinf = 0.0;     ///< max |C v* - u*| over the tile's faces
    Matrix modes;                        ///< T of TileShapeBlocks: empty when the tile keeps every mode
    int modeCount = 0;                   ///< the modes it keeps (its DOFs beyond are inert)
  };

  ReducedTiles(const StaggeredProblem<Dim>& prob, const ReducedOptions& opt, const CouplingKinds& kinds);

  const PolynomialBasis<Dim>& basis() const { return basis_; }
  int dofsPerTile() const { return basis_.size(); }
  std::size_t numTiles() const { return tiles_.size(); }
  /// Storage of the tiles' generalised velocities: dofsPerTile() per tile, tile-major.
  std::size_t totalDofs() const { return tiles_.size() * std::size_t(basis_.size()); }
  /// The counts below, the energy and the reconstruction error are over the tiles this process
  /// reports: all of them, or in a problem distributed by blocks (StaggeredProblem::blockOwner)
  /// those whose first cell (lowest coordinates) lies in one of the rank's blocks, so that summed
  /// over the ranks they are the whole problem's. Such a rank builds every tile near its blocks
  /// (kTileTouchCells), which a neighbour may build too: the same bits on both.
  std::size_t reportedTiles() const;
  bool reportsTile(std::size_t t) const { return reports_[t] != 0; }
  /// The modes the tiles keep (the unknowns they hold): totalDofs() less the inert DOFs of tiles
  /// that keep fewer modes than the basis has (of the reported tiles).
  std::size_t resolvedDofs() const;
  /// Tiles that keep fewer modes than the basis has (their region does not resolve the others).
  std::size_t partialTiles() const;
  const TileData& tile(std::size_t t) const { return tiles_[t]; }
  const sparse_grid::Tiling<Dim>& tiling() const { return tiling_; }
  double reconstructionLinf() const { return reconstructionLinf_; }
  /// Library look-ups of this build that found / did not find the tile's shape.
  std::size_t cacheHits() const { return cacheHits_; }
  std::size_t cacheMisses() const { return cacheMisses_; }
  /// Tiles of this build whose cells a tile of the previous step held (ReducedOptions::history).
  std::size_t keptTiles() const { return keptTiles_; }
  /// Octree decisions taken from the previous step rather than from a fit of u*.
  std::size_t reusedDecisions() const { return reusedDecisions_; }
  /// Tiles returned to Cartesian cells by TileRule::Paying (tile_cost.h).
  std::size_t unpaidTiles() const { return unpaidTiles_; }
  /// tile_cost.h's estimate summed over the kept tiles: rows saved and overhead, in row-equivalents
  /// of work per Krylov iteration.
  const TileWorkTotals& work() const { return work_; }
  /// Tiles returned to Cartesian cells because their fit was singular or B was not SPD, with why.
  const std::vector<std::string>& fallbacks() const { return fallbackMessages_; }

  /// Tile of face f (a * numSlots + slot), or -1.
  std::int32_t tileOfFace(std::size_t f) const { return tileOfFace_[f]; }
  bool isReducedCell(std::size_t slot) const { return tiling_.tileOfCell[slot] >= 0; }
  /// Stress sample (channel c, slot) folded into K_R.
  bool isInsideStress(int c, std::size_t slot) const { return insideStress_[c * n_ + slot] != 0; }

  /// f|coupling <- J^T B^-1 J f|coupling for every tile (other faces untouched).
  void coupleFaces(double* faces) const;

  /// The same on the listed tiles only (a rank of a distributed solve couples the tiles its rows
  /// touch).
  void coupleFaces(double* faces, const std::vector<std::int32_t>& tiles) const;

  /// F_t = J_t f over the coupling faces (F: totalDofs entries, tile-major).
  void gather(const double* faces, double* F) const;
  /// faces <- J^T V on coupling faces (couplingOnly) or on every tile face.
  void scatter(const double* V, double* faces, bool couplingOnly) const;

  /// V_t = B_t^-1 F_t for every tile (F, V: totalDofs entries, tile-major).
  void applyInverses(const double* F, double* V) const;

  /// Generalised velocities v_t = vFree_t - B_t^-1 J_t f (the force f on coupling faces).
  void solveVelocities(const double* faces, double* v) const;

  /// Kinetic energy of the (reported) tiles, sum_t 1/2 v_t^T M_R v_t dV.
  double kineticEnergy(const double* v) const;

  /// Exact contribution of the tile coupling to diag(K^T J^T B^-1 J K): for every Cartesian sample
  /// j touching a coupling face, k_j = sum_f K_fj C_f, diag_j += k_j^T B^-1 k_j. `pWeight` and
  /// `tauWeight` are the (effective) sample weights; `diag` is [p | tau] laid out as the
  /// pressure-stress system (tau may be absent).
  /// `inverses` (optional): per tile the inverse to use instead of B^-1.
  void addCouplingDiagonal(const double* pWeight, const double* tauWeight, double* diag,
                           const std::vector<Matrix>* inverses = nullptr) const;

  /// The tile blocks of the reduced viscosity system / of the velocity block of the PV form,
  ///   A_tt = B_t + (J V J^T)_tt = M_R/dt + K_R + sum_j Q_j d_j d_j^T,   d_j = (D J^T)_j,
  /// over the Cartesian stress samples j (q_j > 0) touching the tile's coupling faces: exact.
  std::vector<Matrix> viscosityTileBlocks(const double* q) const;

  /// diag(A_tt) of viscosityTileBlocks: the exact diagonal of the tile rows of the reduced
  /// viscosity system.
  void addViscosityTileDiagonal(const double* q, double* diagTiles) const;

  /// v = E u: per tile, the least-squares fit over all of its faces of a face field u,
  ///   v_t = M^_t^-1 sum_{faces j of t} C_j^T u_j,   M^_t = sum_j C_j^T C_j,
  /// i.e. the polynomial closest to u in the tile's face mass norm (the multigrid prolongation into
  /// the tiles, solver/multigrid/tile_face_transfer.h). u is read on tile faces only.
  void fitFaceField(const double* faces, double* v) const;
  /// u += E^T v: u_j += C_j M^_t^-1 v_t on every face j of every tile t (tiles share no face, so
  /// the writes are disjoint).
  void addFitTranspose(const double* v, double* faces) const;

  /// fn(f, C_f) for every face f of tile t, C_f the basis row of its component at the face.
  template <class Fn>
  void forEachTileFaceRow(std::size_t t, const Fn& fn) const {
    double row[kRowStorage], xs[3];
    const Eigen::Map<const VectorX> c(row, basis_.size());
    for (std::int64_t f : tiles_[t].faces) {
      scaledCoords(tiling_.tiles[t], f, xs);
      basisRow(tiles_[t], int(f / std::int64_t(n_)), xs, row);
      fn(f, c);
    }
  }

  /// Tile rows of the velocity forms: y_t = (M_R/dt + K_R) v_t + J_t f  (f: face forces).
  void applyTileRows(const double* faces, const double* v, double* y) const;
  /// Tile rows of the velocity forms' right-hand side: r_t = M_R v*_t / dt - J_t f.
  void tileRightHandSide(const double* faces, double* r) const;

 private:
  // Builds every tile in parallel; returns an error message per tile ("" when it succeeded).
  // Shape-only blocks come from the library, or are computed once per shape, from the first tile
  // of that shape, and inserted in tile order: which tile computes them and the library's
  // hit/miss counts do not depend on thread timing (and every tile of a shape gives the same bits
  // anyway, shapeOrder and scaledCoords).
  std::vector<std::string> buildAllTiles();

  // Returns the listed tiles' cells to Cartesian and renumbers the remaining tiles.
  void demoteTiles(const std::vector<std::size_t>& failed);

  // In a problem distributed by blocks, returns to Cartesian the tiles with no cell within
  // kTileTouchCells of the rank's blocks: its rows do not read them, and the edge of its halo may
  // cut them short.
  void keepTilesNearOwnedBlocks();

  // Whether this process reports the region (reportedTiles).
  bool reportsRegion(const sparse_grid::Tile& region) const;

  void buildTiling(const sparse_grid::TilingOptions& topt, double accuracy, TileHistory* history);

  // The octree's split test of a cube of `edge` cells holding `region`: the fit of u* misses by
  // more than `bound` (fitMisfit), or, where `history` saw this cube with the same cells, its
  // previous decision (counted in `reused`). The decision is recorded in `history`.
  bool splitsCube(const sparse_grid::Tile& region, int edge, double bound, TileHistory* history,
                  std::atomic<std::size_t>& reused) const;

  // Counts the tiles the previous step held (keptTiles_) and records this step's in `history`.
  void recordTiles(TileHistory& history);

  // Under TileRule::Paying, demotes the tiles whose estimated work (tile_cost.h) exceeds what they
  // save, and then every tile if the uniform step would cost less (ReducedOptions::uniformRows);
  // sums the kept tiles' estimate into work_.
  void applyTileRule(const ReducedOptions& opt);

  // The rms over the lower faces of the liquid cells of u* less its mean per axis: the scale of
  // the velocity that the tiles must represent (a uniform fall or translation does not count).
  double velocityVariation(const std::vector<std::uint8_t>& liquidFull) const;

  // The rms misfit of the least-squares fit of u* by the basis over the lower faces of the
  // region's cells: sqrt((|u|^2 - b^T v) / count), F v = b, F = sum C^T C, b = sum C^T u* (the
  // tiling's refinement test; the tile's own fit is buildTile's). A region too small to resolve
  // every mode is fitted in the modes it resolves (LDLT of the positive semi-definite F).
  double fitMisfit(const sparse_grid::Tile& region) const;

  // tileOfFace, insideStress.
  void labelFacesAndSamples();

  bool isCartesianPressure(std::size_t slot) const;
  bool isCartesianStress(int c, std::size_t slot) const;

  // x~ = (x_f - x_COM) / h of face f, from the face's integer offset to the tile's corner: the
  // same bits for every tile of one shape, wherever it sits.
  void scaledCoords(const sparse_grid::Tile& tile, std::int64_t f, double* xs) const;

  // The basis row C_a(x~) of tile td in the modes it keeps: (C T)_a = T^T C_a where the tile keeps
  // fewer modes than the basis has, else C_a itself.
  void basisRow(const TileData& td, int axis, const double* xs, double* row) const;

  // T = [T_kept | 0] for a singular fit matrix F = sum_{fit faces} C^T C: the basis fields the fit
  // faces resolve, by degree (each family orders its columns constants, linear, quadratic; the
  // first Dim are the translations). Each group's columns are made F-orthogonal to the modes kept
  // before it, W = E_g - T_r (T_r^T F T_r)^-1 T_r^T F E_g, and kept along the eigenvectors of
  // W^T F W whose eigenvalues exceed 1e-10 of F's largest (the QR's threshold). So a tile keeps
  // every affine mode wherever its faces resolve them, and only the quadratic fields its region
  // cannot see are dropped (p-adaptivity, the thesis' Chapter 6). Empty when the faces do not
  // resolve the translations.
  Matrix resolvedModes(const Matrix& F) const;

  // Positions in `faces` ordered by cell (z, y, x) and axis: an order fixed by the tile's shape
  // (slot order is not: it follows the 8^3 blocks the tile happens to overlap), for the shape-only
  // sums of the library.
  std::vector<std::size_t> shapeOrder(const std::vector<std::int64_t>& faces) const;

  // Shape key for the library, or "" when this tile is not to be cached under the strategy.
  std::string shapeKey(const sparse_grid::Tile& tile) const;

  // All faces of the tile (lower faces of its cells, plus upper faces leaving the tile), and
  // whether each lies on the tile boundary.
  void collectFaces(std::size_t t, TileData& td, std::vector<std::uint8_t>& boundary) const;

  // M^, K^, the fit QR and the generalised eigen-decomposition of (K^, M^) for one tile's shape.
  std::shared_ptr<TileShapeBlocks> computeShapeBlocks(std::size_t t, const TileData& td,
                                                      const std::vector<std::uint8_t>& boundary) const;

  // The per-step data of tile t (faces collected, shape-only blocks given).
  void buildTile(std::size_t t, const TileShapeBlocks& shape, const std::vector<std::uint8_t>& boundary);

  // K^ = sum over inside stress samples s of c_s^-1 d_s d_s^T, d_s = sum_{f in stencil(s)} D_sf C_f
  // (inside a tile every weight is 1; K_R = mu K^).
  Matrix viscousBlock(const sparse_grid::Tile& tile, std::size_t t) const;

  // A reduced face is a coupling face if a Cartesian unknown's stencil contains it.
  bool isCoupling(std::int64_t f) const;

  // f|coupling of tile t <- J_t^T B_t^-1 J_t f|coupling.
  void coupleTile(std::size_t t, double* faces) const;

  // F = J f = sum_{coupling faces} C_f^T f_f  (a gather, then a dense transposed mat-vec)
  void gatherTile(std::size_t t, const double* faces, double* F) const;
  void applyInverse(std::size_t t, const double* F, double* V) const;
  void scatterTile(std::size_t t, const double* V, double* faces, bool couplingOnly) const;

  const StaggeredProblem<Dim>* prob_;
  const BlockLayout<Dim>* layout_;
  PolynomialBasis<Dim> basis_;
  CouplingKinds kinds_;
  std::size_t n_;
  sparse_grid::Tiling<Dim> tiling_;
  std::vector<std::int32_t> tileOfFace_;
  std::vector<std::uint8_t> insideStress_;
  std::vector<TileData> tiles_;
  std::vector<std::uint8_t> reports_;  ///< per tile: reportsRegion
  std::vector<std::string> fallbackMessages_;
  bool parallelTiles_ = false;  ///< the per-iteration tile loops fork (set once the tiles are built)
  double reconstructionLinf_ = 0.0;
  TileCacheStrategy cache_ = TileCacheStrategy::Library;
  std::shared_ptr<TileLibrary> library_;
  bool fitAllFaces_ = false;
  std::size_t cacheHits_ = 0, cacheMisses_ = 0;
  std::size_t unpaidTiles_ = 0;
  std::size_t keptTiles_ = 0, reusedDecisions_ = 0;
  TileWorkTotals work_;
};

// Compiled once, in reduced_tiles.cpp.
extern template class ReducedTiles<2>;
extern template class ReducedTiles<3>;

}  // namespace reduced
}  // namespace stokes::solver
