#pragma once
// Multigrid preconditioners for each system of the engine, built from the generic
// V-cycle (multigrid.h) over re-discretised coarse problems (multigrid_hierarchy.h):
//
//   ViscositySystem         V-cycle on the face block (coarse levels: ViscositySystem);
//                           tile DOFs, if any, Jacobi.
//   pressure projection     V-cycle on the pressure Poisson operator.
//   unified Stokes, SPD     V-cycle on [p | tau] (coarse levels: PressureStressSystem).
//   unified Stokes, PV      block-diagonal (Elman, Silvester & Wathen, "Finite Elements and Fast
//                           Iterative Solvers", ch. 9; Cahouet & Chabard 1988):
//                             z_u = V-cycle of the velocity block  (rho/dt) W_m + D^T Q D,
//                             z_p = L^-1 r_p + s^-1 r_p  (Cahouet-Chabard), or z_p = s^-1 r_p,
//                           where L = dt Wp G^T W_F (rho W_m)^-1 G Wp is the pressure Schur
//                           complement for mu -> 0 (a V-cycle of the pressure projection), and s
//                           the diagonal estimate of the Schur complement Wp G^T W_F diag(V)^-1
//                           W_F G Wp, which is ~ Wp^2 / (2 mu) in the viscous limit (G^T (2 mu
//                           D^T D)^-1 G = 1/(2 mu) on gradients) but also right at the free
//                           surface and at solids. (The plain 2 mu / Wp^2 of Cahouet-Chabard
//                           needed 113 / 163 MINRES iterations on the disk at N = 64 / 128, the
//                           diagonal estimate 46 / 71.) The L^-1 term pays only where inertia
//                           dominates (SchurApproximation, multigrid.h): the diagonal alone breaks
//                           even near mu dt / (rho dx^2) = 16 (1.5x the iterations at 1.5-1.8x less
//                           time each) and from ~160 on takes as few iterations or fewer
//                           (bench/results/schur_block.md). Tile DOFs are rows of the velocity
//                           cycle's finest level (tile_face_transfer.h). The result is SPD, as
//                           MINRES needs.
#include <memory>
#include <span>
#include <stdexcept>
#include <vector>

#include "solver/multigrid/galerkin_cycle.h"
#include "solver/multigrid/multigrid_hierarchy.h"
#include "solver/multigrid/tile_face_transfer.h"
#include "solver/krylov/compact_rows.h"
#include "solver/krylov/operator.h"
#include "solver/systems/pressure_stress_system.h"
#include "solver/systems/pressure_velocity_system.h"
#include "solver/systems/viscosity_system.h"

namespace stokes::solver {
inline namespace multigrid {

/// z = B r over a system's whole unknown vector: V-cycles on some blocks, Jacobi on every other row.
/// A block may carry a row mask (rows outside it get zero from the V-cycle) and an added diagonal
/// term z += extra ⊙ r.
class BlockMultigridPreconditioner {
 public:
  struct Block {
    std::size_t offset = 0;
    std::shared_ptr<Multigrid> cycle;
    Vector mask;   ///< empty: all rows of the block
    Vector extra;  ///< empty: none
    /// Empty: the block is the cycle's rows [offset, offset + cycle size). Else the block is
    /// rows.size() rows from offset, row k being row rows[k] of the cycle (a cycle on padded rows
    /// under a compact solve); mask and extra are then indexed by k.
    std::vector<std::uint32_t> rows;
  };

  explicit BlockMultigridPreconditioner(std::span<const double> diagonal) : jacobi_(diagonal) {}

  void addBlock(Block b) { blocks_.push_back(std::move(b)); }
  /// Keeps the objects the cycles reference (the problem hierarchy, fine systems) alive.
  void keepAlive(std::shared_ptr<const void> p) { owned_.push_back(std::move(p)); }

  std::size_t size() const { return jacobi_.size(); }
  const std::vector<Block>& blocks() const { return blocks_; }

  void apply(const double* r, double* z) const { applyRows(r, z, 0, size()); }

  /// z = B r on the rows [begin, end) alone, from r on those rows (the two parts of a saddle-point
  /// preconditioner, solver/krylov/saddle_point_preconditioner.h). A block must lie inside the
  /// range or outside it.
  void applyRows(const double* r, double* z, std::size_t begin, std::size_t end) const {
    jacobi_.applyRows(r, z, begin, end);
    for (const Block& b : blocks_) {
      const std::size_t n = b.rows.empty() ? b.cycle->size() : b.rows.size();
      if (b.offset >= end || b.offset + n <= begin) continue;
      if (b.offset < begin || b.offset + n > end)
        throw std::logic_error("BlockMultigridPreconditioner::applyRows: a block straddles the range");
      double* zb = z + b.offset;
      const double* rb = r + b.offset;
      if (b.rows.empty()) {
        b.cycle->apply(rb, zb);
      } else {  // scatter into the cycle's rows, cycle, gather
        rowsIn_.assign(b.cycle->size(), 0.0);
        rowsOut_.resize(b.cycle->size());
        const std::uint32_t* idx = b.rows.data();
        double* in = rowsIn_.data();
        detail::parallelFor(n, [=](std::ptrdiff_t k) { in[idx[k]] = rb[k]; });
        b.cycle->apply(rowsIn_.data(), rowsOut_.data());
        const double* out = rowsOut_.data();
        detail::parallelFor(n, [=](std::ptrdiff_t k) { zb[k] = out[idx[k]]; });
      }
      const double* mask = b.mask.empty() ? nullptr : b.mask.data();
      const double* extra = b.extra.empty() ? nullptr : b.extra.data();
      if (mask || extra)
        detail::parallelFor(n, [=](std::ptrdiff_t i) {
          double v = mask ? mask[i] * zb[i] : zb[i];
          zb[i] = extra ? v + extra[i] * rb[i] : v;
        });
    }
  }

  std::size_t levels() const { return blocks_.empty() ? 0 : blocks_.front().cycle->numLevels(); }

 private:
  std::vector<std::shared_ptr<const void>> owned_;  // destroyed after the blocks that use it
  JacobiPreconditioner jacobi_;
  std::vector<Block> blocks_;
  mutable Vector rowsIn_, rowsOut_;  // work arrays of blocks with rows (apply is not re-entrant)
};

namespace detail {
/// A shared_ptr that does not own (for the fine system, which the caller keeps alive).
template <class T>
std::shared_ptr<const T> borrow(const T& t) {
  return std::shared_ptr<const T>(&t, [](const T*) {});
}
}  // namespace detail

/// Decoupled viscosity: V-cycle on the faces, Jacobi on tile DOFs.
template <int Dim>
BlockMultigridPreconditioner makeMultigridPreconditioner(const StaggeredProblem<Dim>& prob,
                                                         const ViscositySystem<Dim>& sys,
                                                         const MultigridOptions& opt = {}) {
  auto h = std::make_shared<ProblemHierarchy<Dim>>(prob);
  const std::size_t nFaces = Dim * prob.slots();
  auto make = [](const StaggeredProblem<Dim>& p) { return std::make_shared<const ViscositySystem<Dim>>(p); };
  BlockMultigridPreconditioner pre(sys.diagonal());
  pre.addBlock({0, buildMultigrid(*h, faceChannels<Dim>(), leadingBlockLevel(detail::borrow(sys), nFaces), make, opt), {}, {}, {}});
  pre.keepAlive(h);
  return pre;
}

/// Pressure projection (withStress = false) or unified Stokes in the SPD form: V-cycle on all rows.
template <int Dim>
BlockMultigridPreconditioner makeMultigridPreconditioner(const StaggeredProblem<Dim>& prob,
                                                         const PressureStressSystem<Dim>& sys,
                                                         const MultigridOptions& opt = {}) {
  auto h = std::make_shared<ProblemHierarchy<Dim>>(prob);
  const bool withStress = sys.withStress();
  auto make = [withStress](const StaggeredProblem<Dim>& p) {
    return std::make_shared<const PressureStressSystem<Dim>>(p, withStress);
  };
  BlockMultigridPreconditioner pre(sys.diagonal());
  pre.addBlock({0, buildMultigrid(*h, pressureStressChannels<Dim>(withStress), leadingBlockLevel(detail::borrow(sys), sys.size()), make, opt), {}, {}, {}});
  pre.keepAlive(h);
  return pre;
}

/// The tile DOF rows of the velocity block [u_C | v_R] with their exact blocks A_tt^-1 (the
/// smoother's block Jacobi, MultigridLevel::DiagonalBlocks).
template <int Dim>
MultigridLevel::DiagonalBlocks tileDiagonalBlocks(const PressureVelocitySystem<Dim>& pv) {
  MultigridLevel::DiagonalBlocks b;
  const auto& inverses = pv.tileBlockInverses();
  if (inverses.empty()) return b;
  const std::size_t m = std::size_t(pv.tiles()->dofsPerTile());
  std::vector<std::uint32_t> rows(m);
  for (std::size_t t = 0; t < inverses.size(); ++t) {
    for (std::size_t i = 0; i < m; ++i) rows[i] = std::uint32_t(pv.faceRows() + t * m + i);
    const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> inv = inverses[t];
    b.append(rows.data(), m, inv.data());
  }
  return b;
}

/// The V-cycle of the pressure-velocity system's velocity block: on level 0 the rows [u_C | v_R]
/// (U = (rho/dt) W_F W_m + W_F V W_F on the Cartesian faces, the tiles coupled in), on the coarse
/// levels uniform PV systems on the coarsened problems, where the tiles' cells are plain liquid.
/// With tiles, level 0 reaches level 1 through TileFaceTransfer (the fit of the prolonged faces).
template <int Dim>
std::shared_ptr<Multigrid> velocityBlockCycle(const ProblemHierarchy<Dim>& h, std::shared_ptr<const PressureVelocitySystem<Dim>> pv,
                                              const MultigridOptions& opt) {
  auto makePV = [](const StaggeredProblem<Dim>& p) { return std::make_shared<const PressureVelocitySystem<Dim>>(p); };
  const ReducedTiles<Dim>* tiles = pv->tiles();
  std::vector<MultigridLevel> levels = hierarchyLevels(h, faceChannels<Dim>(), leadingBlockLevel(pv, pv->velocityRows()), makePV);
  for (std::size_t l = 0; l + 1 < levels.size(); ++l) {
    if (l == 0 && tiles && tiles->numTiles() > 0) attachTileFaceTransfer(levels, h, *tiles);
    else attachGridTransfer(levels, h, faceChannels<Dim>(), l);
  }
  if (tiles && tiles->numTiles() > 0) levels[0].blocks = tileDiagonalBlocks(*pv);
  return std::make_shared<Multigrid>(std::move(levels), opt);
}

/// The Cahouet-Chabard block for the pressure Schur complement Wp G^T W_F U^-1 W_F G Wp:
/// z_p = mask (L^-1 r_p) + s^-1 r_p, L the pressure projection (V-cycle), s the diagonal estimate
/// `schurDiagonal` (the PV system's pressure rows). Offset 0: the caller sets it.
template <int Dim>
BlockMultigridPreconditioner::Block pressureSchurBlock(const ProblemHierarchy<Dim>& h, const double* schurDiagonal,
                                                       const MultigridOptions& opt) {
  const std::size_t n = h.problem(0).slots();
  auto makeL = [](const StaggeredProblem<Dim>& p) { return std::make_shared<const PressureStressSystem<Dim>>(p, false); };
  Vector mask(n, 0.0), extra(n, 0.0);
  for (std::size_t s = 0; s < n; ++s) {
    if (!(schurDiagonal[s] > 0.0)) continue;
    mask[s] = 1.0;
    extra[s] = 1.0 / schurDiagonal[s];
  }
  auto cycle = buildMultigrid(h, pressureStressChannels<Dim>(false), leadingBlockLevel(makeL(h.problem(0)), n), makeL, opt);
  return {0, std::move(cycle), std::move(mask), std::move(extra), {}};
}

/// Whether the pressure-velocity preconditioner adds the V-cycle of the projection operator L to
/// its pressure block (Cahouet-Chabard) for this problem; see SchurApproximation.
template <int Dim>
bool usesPressureCycle(const StaggeredProblem<Dim>& prob, SchurApproximation a) {
  if (a == SchurApproximation::Auto) return prob.viscousNumber() < kCahouetChabardMaxViscousNumber;
  return a == SchurApproximation::CahouetChabard;
}

/// Unified Stokes in the pressure-velocity form: the block-diagonal preconditioner above. Without
/// the pressure cycle the pressure rows are the Jacobi rows of the Schur diagonal (sys.diagonal()).
template <int Dim>
BlockMultigridPreconditioner makeMultigridPreconditioner(const StaggeredProblem<Dim>& prob,
                                                         const PressureVelocitySystem<Dim>& sys,
                                                         const MultigridOptions& opt = {}) {
  auto h = std::make_shared<ProblemHierarchy<Dim>>(prob);
  const std::size_t p0 = sys.pressureOffset();
  MultigridOptions blockOpt = opt;
  if (blockOpt.smootherDegree == 0) blockOpt.smootherDegree = kPressureVelocitySmootherDegree;
  BlockMultigridPreconditioner pre(sys.diagonal());
  pre.addBlock({0, velocityBlockCycle(*h, detail::borrow(sys), blockOpt), {}, {}, {}});
  if (usesPressureCycle(prob, opt.pressureSchur)) {
    auto pressure = pressureSchurBlock(*h, sys.diagonal().data() + p0, blockOpt);
    pressure.offset = p0;
    pre.addBlock(std::move(pressure));
  }
  pre.keepAlive(h);
  return pre;
}

/// The system's diagonal() with the pressure rows' Schur estimate taken through the exact blocks of
/// the strongly coupled face groups that the velocity cycle's smoother solves (level 0's blocks
/// below its tile rows): where A has a near-null pair, 1 / A_ff underestimates A^-1 and with it
/// the Schur complement (armadillos res 128, first step: s^-1 S in [0.53, 8.5], with the groups
/// [0.53, 2.9]; bench/results/schur_spectrum.md).
template <int Dim>
Vector schurDiagonalWithFaceGroups(const PressureVelocitySystem<Dim>& sys, const RowSelection& velocityRows,
                                   const AssembledLevel& level0) {
  Vector diagonal = sys.diagonal();
  const MultigridLevel::DiagonalBlocks& b = level0.blocks;
  std::vector<std::uint32_t> faces;
  for (std::size_t k = 0; k < b.count(); ++k) {
    const std::size_t m = b.blockSize(k);
    if (b.rows[b.offsets[k]] >= level0.tileRows) continue;  // a tile's block: already in the estimate
    faces.resize(m);
    for (std::size_t q = 0; q < m; ++q) faces[q] = std::uint32_t(velocityRows.rows()[b.rows[b.offsets[k] + q]]);
    sys.addFaceBlockToSchurDiagonal(faces.data(), m, b.inverses.data() + b.inverseOffsets[k],
                                    diagonal.data() + sys.pressureOffset());
  }
  return diagonal;
}

/// Unified Stokes in the pressure-velocity form on the live rows `rows` of the system (the compact
/// Krylov solve): the velocity rows lead the selection, and their block is the Galerkin
/// cycle on live rows (galerkin_cycle.h); the pressure block as in the padded preconditioner above,
/// its cycle (if any) on the padded pressure rows.
template <int Dim>
BlockMultigridPreconditioner makeMultigridPreconditioner(const StaggeredProblem<Dim>& prob,
                                                         const PressureVelocitySystem<Dim>& sys, const RowSelection& rows,
                                                         const MultigridOptions& opt = {}) {
  const std::size_t p0 = sys.pressureOffset();
  std::vector<RowSelection::Index> velocity, pressure;
  for (RowSelection::Index i : rows.rows()) {
    if (i < p0) velocity.push_back(i);
    else if (i < sys.rigidOffset()) pressure.push_back(i - RowSelection::Index(p0));
  }
  MultigridOptions blockOpt = opt;
  if (blockOpt.smootherDegree == 0) blockOpt.smootherDegree = kPressureVelocitySmootherDegree;
  const RowSelection velocityRows(std::move(velocity), sys.velocityRows());
  auto hierarchy = std::make_shared<GalerkinVelocityHierarchy<Dim>>(sys, velocityRows, blockOpt);
  const Vector diagonal = schurDiagonalWithFaceGroups(sys, velocityRows, hierarchy->levels()->front());
  BlockMultigridPreconditioner pre(rows.gathered(diagonal));
  pre.addBlock({0, assembledMultigrid(hierarchy->levels(), blockOpt), {}, {}, {}});
  pre.keepAlive(hierarchy);
  if (usesPressureCycle(prob, opt.pressureSchur)) {
    auto h = std::make_shared<ProblemHierarchy<Dim>>(prob);
    auto block = pressureSchurBlock(*h, diagonal.data() + p0, blockOpt);
    block.offset = velocityRows.size();
    Vector mask(pressure.size()), extra(pressure.size());
    for (std::size_t k = 0; k < pressure.size(); ++k) {
      mask[k] = block.mask[pressure[k]];
      extra[k] = block.extra[pressure[k]];
    }
    block.mask = std::move(mask);
    block.extra = std::move(extra);
    block.rows = std::move(pressure);
    pre.addBlock(std::move(block));
    pre.keepAlive(h);
  }
  return pre;
}

}  // namespace multigrid
}  // namespace stokes::solver
