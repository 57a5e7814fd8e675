#pragma once
// The grid side of one simulation step (thesis Algorithm 1 around Algorithm 2): from particles and
// the liquid level set to a StaggeredProblem, its Stokes solve, and the face velocity G2P reads.
//
// Grid of a step. The BlockLayout covers the cells that hold particles, dilated by `band` cells
// (the P2G kernel reaches 1.5 cells, the stresses one more, and the surface moves up to cfl cells a
// step), clipped to the domain box plus one layer of cells past each upper wall: cells 0..N_a
// along each axis (0..N_a-1 inside), cell i spanning [min + i dx, min + (i+1) dx].
//
// No slip where the wall or the solid is. A tangential face next to a wall sits half a
// cell from it, and the stress sample between that face and the one beyond the wall lies on the
// wall. With the face beyond the wall at the wall's velocity and the sample at full weight, the
// discrete shear (u_1 - u_w) / dx is that of a wall half a cell further out: a slip length of
// dx/2, and a film's flux (~ h^3 (1 + 3 slip / h)) 30% too large at 5 cells. The ghost-fluid
// value is (u_1 - u_w) / (theta dx), theta = the fraction of the face-to-face segment on the
// liquid's side. The variational form has exactly that factor already: a stress sample's
// coupling is mu W_L^tau / W_F^tau (compliance c mu^-1 W_F^tau W_L^tau in the SPD form), and W_F^tau
// is the fraction of its control volume outside the solid, = theta for a plane normal to the
// segment. So:
//  - W_F^tau is the plane-cut fraction of the region inside the box and outside the solids
//    (fillFluidStressWeights, sparse_grid::computePlaneCutFractions): 1/2 on a wall through the sample,
//    continuous as a solid's face moves between grid lines (27 sub-samples read 1/3 or 2/3 there).
//    It is stored without W_F^u for the walls of a scene without solids, and not at all when no
//    liquid stress sample is cut;
//  - W_L^tau must be 1 on the wall where the liquid touches it: the liquid weights see the liquid
//    continued one cell into the walls and solids it touches (extendIntoSolid), the sub-samples
//    on the wall itself included (the particles' spheres leave gaps on a flat wall, where a sample
//    on it lost a third of its weight);
//  - the stress samples on an upper wall belong to the cells past it (i_a = N_a), which the layout
//    therefore holds: before, where N_a was a multiple of 8 the block ended at the wall, those
//    samples were absent and the upper walls were free-slip;
//  - G2P and advection read the walls (BoxWalls in sim/particles/grid_velocity.h: the odd reflection across
//    each wall) and the solids (setSolidGhostVelocities: the face inside a solid takes the linear
//    extrapolation through its surface), so the velocity they interpolate is the wall's on it.
//
// Domain walls without W_F^u. The solver reads a face that is absent from the layout as velocity
// 0. The walls are made of such faces plus "closed" faces (StaggeredProblem::closedFace, Dirichlet 0):
//  - the lower wall normal to a: face a of the cells with i_a = 0 (it lies in their slot);
//  - the upper wall normal to a: face a of the cells with i_a = N_a -- closed;
//  - every face of a cell outside the domain box: closed, and its samples off the wall get no
//    liquid weight.
// With `open_top` the +y wall is not closed: cells above the domain are air (pressure 0).
// The tile bands treat the layout's edge as air (sparse_grid/tiling.h), so no tile reaches a wall
// as long as band_air >= 1 (the simulator raises 0 to 1).
//
// The liquid extension is for the weights only; the reported volume and the reseeding use the
// particle level set itself. W_F^u is built only when the scene has solids. Solids move rigidly
// at their `velocity` (ShapeField::setTime, set by the simulator to the step's start); u_solid is
// their velocity on the faces they cover. Liquid fractions follow the scene's liquid_weights
// (default sparse_grid::kLiquidFractionRule: plane cuts, the liquid and each wall or solid from
// its own plane, stokes_stage.cpp wetByPlanes; or 3^3 sub-samples of the extended liquid): both
// level sets are (close to) distances, so only samples near a surface are cut or sub-sampled.
#include "sparse_grid/vdb_trees.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "sim/geometry/geometry.h"
#include "sim/particles/grid_velocity.h"
#include "sim/particles/particles.h"
#include "sim/ranks/rank_blocks.h"
#include "sim/ranks/rank_comm.h"
#include "sim/scene/scene.h"
#include "sim/step/stages.h"
#include "sim/step/warm_start.h"
#include "solver/step/stokes_step.h"

namespace stokes::sim {
inline namespace step {

inline constexpr int kSimDim = 3;
using Layout3 = sparse_grid::BlockLayout<kSimDim>;
using Problem3 = solver::StaggeredProblem<kSimDim>;

/// The domain box in world units and in cells.
struct DomainBox {
  Vec3d min{0.0}, max{0.0};
  double dx = 1.0;
  openvdb::Coord cells{1, 1, 1};  ///< N_a cells per axis
  bool openTop = false;

  static DomainBox fromScene(const Scene& scene);
  openvdb::CoordBBox cellBBox() const { return {openvdb::Coord(0), cells - openvdb::Coord(1)}; }
  /// Signed distance to the box (negative inside); with openTop the box has no +y side.
  double phi(const Vec3d& x) const;
  /// The walls as G2P and advection see them (no slip on the wall itself).
  BoxWalls walls() const { return BoxWalls{cells, openTop}; }
};

/// The liquid region of the volume weights reaches this many cells into a solid it touches.
inline constexpr double kSolidExtensionCells = 1.0;

/// Liquid level set extended into the solid (thesis 3.6.4, Fig. 3.4c): the liquid domain Omega_L
/// continues into the solid, where it is not liquid but the constraint that enforces the solid
/// boundary: stress samples there have W_L^tau > 0 and W_F^tau = 0, i.e. zero compliance, so the
/// strain rate between the solid's velocity and the liquid's next to it vanishes (no slip and no
/// separation), and pressure cells in it close the flux through the solid's faces. Without it a
/// liquid touching a solid only at a face is held by shear alone and hinges about it (the beam
/// rotated as a rigid rod about its root, mean velocity 0.75 g t).
/// Region: L union (S_m intersect {phi_L < reach}), i.e. min(phi_L, max(phi_S - m, phi_L - reach)),
/// Lipschitz-1 like both inputs, so the volume fractions' distance shortcut stays valid. S_m is the
/// solid grown by the wetting margin m (kWettingMarginCells): a particle surface resting on a wall
/// leaves gaps between the particles' spheres, and a stress sample on the wall whose middle row of
/// sub-samples (on the wall, phi_S = 0) fell into one lost a third of its weight -- local slip
/// (noise of 15% of the velocity next to the floor in the Couette test at 16 cells across).
inline double extendIntoSolid(double phiLiquid, double phiSolid, double reach, double margin) {
  return std::min(phiLiquid, std::max(phiSolid - margin, phiLiquid - reach));
}

/// Wetting margin of extendIntoSolid, in cells: it takes the sub-samples exactly on a wall or a
/// solid face (phi_S = 0) into the extension, and nothing of the liquid's side. A margin of a
/// quarter cell was tried: it also took the sub-samples dx/6 off the floor into the liquid as soon
/// as a falling ball came within a cell of it, and the ball floated on that incompressible layer.
inline constexpr double kWettingMarginCells = 1e-3;

/// The plane-cut rule's wetting margin, in cells (wetByPlanes in stokes_stage.cpp): the wall's
/// and the solids' planes are moved this far into the liquid. The particle surface along a wall
/// wanders by about +-0.09 dx (the jitter of the particles next to it), and the liquid's plane cut
/// reads each dip as a gap the wall's cut must fill. 0.1 dx closes them: film on a wall 3.68% ->
/// 3.22% at 4 cells across, the off-grid lid 1.35% -> 0.46%. A plane cut
/// weighs a tenth of a cell by a tenth of its weight, where the sub-samples above took a whole row
/// in; the default scene's ball still falls through to the floor with it.
inline constexpr double kPlaneCutWettingMarginCells = 0.1;

/// Layout band in cells: the P2G kernel (1.5 cells) and the stresses reach 3 cells past the
/// particles' cells; the surface moves up to cfl cells in a step.
inline int layoutBand(const Scene& scene) { return 3 + std::max(0, int(std::ceil(scene.cfl)) - 1); }

/// Cells holding particles, dilated by `band` cells (face, edge and vertex neighbours), clipped to
/// the domain, with tiles voxelised (BlockLayout reads leaves).
openvdb::MaskTree particleBandMask(const std::vector<Vec3d>& positions, const DomainBox& domain, int band);

/// closedFace flags of the layout (see the header comment).
std::vector<std::uint8_t> closedWallFaces(const Layout3& layout, const DomainBox& domain);

/// Which solve a scene calls for (request.system: Scene::stepSystem) and with which options (the
/// scene's model and solver).
struct StokesPlan {
  solver::StepOptions options;  ///< what every step shares; the solver choice: optionsFor
  solver::SolveRequest request;  ///< what the scene asks of solver::planSolve (what it leaves open)
  bool viscous() const { return request.system != solver::SystemKind::PressureProjection; }
  /// `options` with form, method and preconditioner planned for a step of `liquidCells` liquid cells
  /// and viscous number mu dt / (rho dx^2) (an open preconditioner follows both:
  /// solver::kMultigridMinViscousNumber, solver::kMultigridMinLiquidCells,
  /// solver::kMultigridSmallStepMinViscousNumber).
  solver::StepOptions optionsFor(std::size_t liquidCells, double viscousNumber) const;
};
/// `library` and `history` are kept across steps by the caller (the tiles' factorisations and the
/// previous step's tiling; either may be null).
StokesPlan planStokes(const Scene& scene, std::shared_ptr<solver::TileLibrary> library,
                      std::shared_ptr<solver::TileHistory> history = nullptr);

/// Timings and counts of one grid step.
struct GridStepReport {
  StageTimes times;  ///< the grid stages' wall times
  int iterations = 0;
  std::size_t unknowns = 0;       ///< active rows over the solves
  std::size_t krylovRows = 0;     ///< length of the Krylov vectors (live rows, or padded blocks), summed
  std::size_t stencilSlots = 0;   ///< samples one operator apply visits (block slots or rows), summed
  double krylovSeconds = 0.0;     ///< Krylov solves alone (preconditioner set-up included), summed
  double setupSeconds = 0.0;      ///< of krylovSeconds: building the multigrid hierarchies, summed
  std::string solver;             ///< what ran, per solve ("system form: method + preconditioner", "; "-joined)
  std::size_t stressUnknowns = 0;  ///< stress samples with W_L^tau > 0 in a coupled solve, else 0
  std::size_t cells = 0;          ///< active cells of the layout
  std::size_t tiles = 0, fallbackTiles = 0;
  std::size_t partialTiles = 0;   ///< tiles that keep fewer modes than the basis
  std::size_t unpaidTiles = 0;    ///< tiles returned to Cartesian as not paying (solver/reduced/tile_cost.h)
  std::size_t keptTiles = 0;      ///< tiles the previous step also had (solver/reduced/tile_history.h)
  /// Bytes the ranks sent each other outside the Krylov solve (PETSc backend), all ranks together:
  /// the problems rank 0 sent, or in a step split over ranks the particles, ghosts, halo values and
  /// the warm start moved to new owners
  std::size_t sentBytes = 0;
  std::size_t tileDofs = 0;       ///< the modes the tiles keep (of `unknowns`)
  bool builtFluidWeights = false;  ///< W_F was built (the scene has solids)
  double relativeResidual = 0.0;
  std::vector<Stage> stages;  ///< grid stages that ran, in order
};

/// Error of a step, naming the stage (and the face or cell where known).
class SimulationError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// A step's solve stopped because a stop was requested (SolveOptions::stopRequested): not a
/// failure, so the step is not retried; Simulator::advanceFrame rolls it back and rethrows.
class StepInterrupted : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// The grid of one step and its face velocities.
class GridStep {
 public:
  /// Builds the layout and the volume weights. `liquid` is the step's liquid level set,
  /// `solids` the solid union (null: the scene has no solids, no W_F is built). With `part` (a
  /// step split over ranks, sim/ranks/) the layout holds this rank's blocks and their halo, as
  /// the whole layout has them, and the problem names the blocks' owners: the solve runs on every
  /// rank, and the halo's velocities come from their owners before the extrapolation.
  GridStep(const std::vector<Vec3d>& positions, const openvdb::FloatGrid& liquid, const ShapeField* solids,
           const DomainBox& domain, const Scene& scene, double dt, bool needStressWeights, int band,
           const RankBlocks* part = nullptr);

  /// An inflow: every face whose centre lies in {phi < 0} (`phi(Vec3d) -> double`, a signed
  /// distance) is prescribed at `velocity` in the solve (Dirichlet, W_F = 0, u_solid = velocity)
  /// and keeps it through the extrapolation and solid ghost values. An emitter is one: the liquid
  /// leaves it at its velocity, whatever pulls on it below (without, a falling rope drew 4-5x the
  /// nozzle's flux out of the coil's emitter). Call before solve().
  void setInflow(const std::function<double(const Vec3d&)>& phi, const Vec3d& velocity);

  /// The liquid cells' divergence target s (1/s) for the solve: div u = s instead of 0
  /// (StaggeredProblem::divergenceTarget; the simulator's volume control). Call before solve().
  void setDivergenceTarget(double s) { problem_.divergenceTarget = s; }

  /// P2G into u*, gravity if given, the solve(s) of `plan`, then velocity extrapolation beyond the
  /// liquid for G2P and advection. Throws SimulationError naming the stage and face on a
  /// non-finite velocity or a solve that did not converge. `warm`, if given, holds the previous
  /// step's unknowns: a solve of the same form starts from them (sim/step/warm_start.h).
  void solve(const ParticleSet<kSimDim>& particles, const Vec3d* gravity, const StokesPlan& plan,
             const WarmStart<kSimDim>* warm = nullptr);

  /// Instead of P2G: u* on every open face of an active cell is u(axis, the face's world position)
  /// (faces on the walls stay 0). Then solveFromStart. For a solve on the caller's own grids
  /// (sim/run/grid_solve.h).
  void setStartVelocity(const std::function<double(int, const Vec3d&)>& u);
  /// What solve() does after P2G: gravity, the solve(s) of `plan`, the extrapolation.
  void solveFromStart(const Vec3d* gravity, const StokesPlan& plan, const WarmStart<kSimDim>* warm = nullptr);
  /// The last solve's pressure per cell slot (Pa; the projection's after a decoupled step), or
  /// empty after a decoupled viscosity solve alone.
  solver::Vector pressure() const;

  const Layout3& layout() const { return *layout_; }
  const Problem3& problem() const { return problem_; }
  const solver::Vector& velocity() const { return velocity_; }
  const GridStepReport& report() const { return report_; }
  /// Hands the layout and the solve's unknowns (solution_) to the next step's warm start; the
  /// GridStep is spent afterwards.
  void passTo(WarmStart<kSimDim>& warm) { warm.keep(std::move(layout_), std::move(solution_)); }

 private:
  void fillWeights(const openvdb::FloatGrid& liquid, const ShapeField* solids, bool needStressWeights,
                   sparse_grid::FractionRule rule);
  void fillFluidStressWeights(const ShapeField* solids);
  void fillSolidVelocity(const ShapeField& solids);
  void runSolve(Stage stage, const solver::StepOptions& options, const WarmStart<kSimDim>* warm = nullptr);
  /// Split over ranks: the halo's liquid weights and u* from their owners (stokes_stage.cpp).
  void takeHaloWeightsFromOwners();
  /// Split over ranks with adaptive tiles: the whole problem gathered and solved on every rank
  /// (stokes_stage.cpp); `guess` holds `channels` channels on this rank's layout, or nothing.
  solver::StepReport solveWholeOnEveryRank(const solver::StepOptions& options, solver::Vector* solution,
                                           const solver::Vector& guess, std::size_t channels);
  /// Records stage `stage`, begun at t0, in the report.
  void finishStage(Stage stage, std::chrono::steady_clock::time_point t0);
  void extrapolate(int layers);
  void setSolidGhostVelocities(const ShapeField& solids);
  std::string faceName(std::size_t i) const;
  /// Whether `ok` holds on every rank of a step split over ranks (collective there), else `ok`: a
  /// check that fails on one rank fails the step on all, which then roll back together.
  bool everyRank(bool ok) const { return part_ ? allRanks(ok) : ok; }
  /// The liquid cell whose velocity breaks div u = s the most (for an unconverged solve's error);
  /// split over ranks, among this rank's blocks.
  std::string worstDivergenceCell() const;

  DomainBox domain_;
  const ShapeField* solids_ = nullptr;  ///< the scene's solids placed at the step's start, or null
  std::unique_ptr<Layout3> layout_;
  Problem3 problem_;
  solver::Vector faceMass_, velocity_;
  /// The solve's unknowns, channel-major over the slots: [p | tau] (pressure-stress form), [u | p]
  /// (pressure-velocity form), [p] (projection); empty after decoupled viscosity alone.
  solver::Vector solution_;
  std::size_t pressureOffset_ = 0;  ///< where the pressure channel starts in solution_
  std::vector<std::uint8_t> inflow_;  ///< faces an inflow prescribes (setInflow), or empty
  const RankBlocks* part_ = nullptr;  ///< this rank's part of a step split over ranks, or null
  int haloDepth_ = 0;  ///< cells past this rank's blocks whose velocities it reads after the solve
  /// Cells past this rank's blocks whose liquid weights and u* it takes from their owners before
  /// the solve: its stencils' reach, or the reduced tiles' (solver::distributedTileDepth)
  int weightsDepth_ = 0;
  GridStepReport report_;
};

}  // namespace step
}  // namespace stokes::sim
