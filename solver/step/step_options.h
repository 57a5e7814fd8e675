#pragma once
// What a step is asked to do (StepOptions: system, form, Krylov method, preconditioner, rows,
// tiles) and what it did (StepReport). planSolve (solve_plan.h) fills the solver choice.
#include <cstddef>
#include <map>
#include <optional>
#include <string>

#include "solver/krylov/krylov.h"
#include "solver/multigrid/multigrid.h"
#include "solver/reduced/reduced_tiles.h"
#include "solver/step/solve_plan.h"

namespace stokes::solver {
inline namespace step {

/// Measured (Jacobi CG, 1 thread, bench/results/compact_rows.md): the disk at N = 128 (1.18 padded
/// rows per live row) solves 1.58x slower compacted (the gather and scatter around each apply cost
/// more than the shorter vectors save); the 48^3 ball (3.25) 1.8x faster; the armadillos at
/// res 96 (~38) 3.7x faster.
inline constexpr double kCompactRowsMinPadding = 1.5;

/// The multigrid's option enums as a user writes them (command line, reports).
inline constexpr NamedValue<SchurApproximation> kSchurApproximationNames[] = {
    {SchurApproximation::Auto, "auto", "auto"},
    {SchurApproximation::Diagonal, "diagonal", "Schur diagonal"},
    {SchurApproximation::CahouetChabard, "cahouet-chabard", "Cahouet-Chabard"}};
inline constexpr NamedValue<FaceInterpolation> kFaceInterpolationNames[] = {
    {FaceInterpolation::Auto, "auto", "auto"},
    {FaceInterpolation::Constant, "constant", "constant"},
    {FaceInterpolation::Linear, "linear", "linear"}};
static_assert(listsEveryValueInOrder(kSchurApproximationNames, SchurApproximation::CahouetChabard));
static_assert(listsEveryValueInOrder(kFaceInterpolationNames, FaceInterpolation::Linear));
constexpr std::span<const NamedValue<SchurApproximation>> namesOf(SchurApproximation) {
  return kSchurApproximationNames;
}
constexpr std::span<const NamedValue<FaceInterpolation>> namesOf(FaceInterpolation) {
  return kFaceInterpolationNames;
}

struct StepOptions {
  SystemKind system = SystemKind::UnifiedStokes;
  /// Open (nullopt): the form's method (methodFor, solve_plan.h).
  std::optional<KrylovMethod> method;
  PreconditionerKind preconditioner = PreconditionerKind::Jacobi;
  SolveOptions krylov{};
  StokesForm form = StokesForm::PressureStress;  ///< unified Stokes only
  /// Reduced polynomial tiles (affine / quadratic model); empty: the uniform model.
  std::optional<ReducedOptions> reduced{};
  /// Where the Krylov vectors of the symmetric positive (semi-)definite systems live: on the live
  /// rows only (solver/krylov/compact_rows.h) or on the padded block layout.
  RowStorage rows = RowStorage::Auto;
  /// On compact rows, the pressure-stress system applies its stencils over the unknowns through a
  /// compact neighbour index (solver/systems/pressure_stress_rows.h) instead of sweeping the
  /// blocks that hold them; the same operator bit for bit.
  bool rowStencils = true;
  /// Smoother and coarse-solve settings of the multigrid preconditioner (preconditioner = Multigrid).
  MultigridOptions multigrid{};
  /// Petsc: the pressure-stress form (unified Stokes and the pressure projection) is solved by
  /// PETSc on every rank of PETSC_COMM_WORLD; method and preconditioner above are then unused.
  Backend backend = Backend::InHouse;
  /// OpenMP threads of an in-house solve (set-up, Krylov iterations, velocities); 0: the caller's.
  /// The result is the same bits for every count.
  int threads = 0;
};

/// A plan's solver choice (planSolve) into the options of a step.
inline void applyPlan(const SolvePlan& p, StepOptions& o) {
  o.form = p.form;
  o.method = p.method;
  o.preconditioner = p.preconditioner;
  o.backend = p.backend;
  o.threads = p.threads;
  if (o.reduced) o.reduced->rule = p.tileRule;
}

/// What one solve did. For DecoupledStokes the two solves' iterations are added and the status is
/// the worse of the two.
struct StepReport {
  SolveResult solve;
  std::size_t unknowns = 0;  ///< rows with a non-zero diagonal, summed over the solves
  std::size_t paddedRows = 0;  ///< rows of the padded block vectors, summed over the solves
  std::size_t krylovRows = 0;  ///< length of the vectors the Krylov method ran on, summed
  std::size_t stencilSlots = 0;  ///< samples one operator apply visits (block slots, or compact rows), summed
  double setupSeconds = 0.0;  ///< system set-up, tiles included
  double tileSeconds = 0.0;   ///< of which: tiling, fits and factorisations of the tiles
  double solveSeconds = 0.0;
  double preconditionerSeconds = 0.0;  ///< of solveSeconds: building the multigrid hierarchy
  std::size_t multigridLevels = 0;
  /// Pressure-velocity form with multigrid: the pressure block that ran ("diagonal" or
  /// "cahouet-chabard", see SchurApproximation); empty otherwise.
  std::string schurBlock;
  /// What ran, one "system form: method + preconditioner" per solve (decoupled: two, "; "-joined),
  /// e.g. "unified Stokes pressure-velocity: MINRES + multigrid".
  std::string solver;
  std::size_t tiles = 0, reducedDofs = 0, cartesianDofs = 0;
  std::size_t fallbackTiles = 0;    ///< tiles returned to Cartesian (no translations resolved / B not SPD)
  std::size_t partialTiles = 0;     ///< tiles that keep fewer modes than the basis (their faces resolve no more)
  std::size_t unpaidTiles = 0;      ///< tiles returned to Cartesian by TileRule::Paying (solver/reduced/tile_cost.h)
  std::size_t keptTiles = 0;        ///< tiles whose cells a tile of the previous step held (ReducedOptions::history)
  std::size_t sentBytes = 0;   ///< bytes a rank sent the others outside the Krylov solve (a split step's whole problem with tiles), else 0
  std::size_t reusedTileDecisions = 0;  ///< adaptive cubes that kept the previous step's decision
  std::string tileRule;             ///< the rule that kept the tiles (its key), empty without tiles
  double tileWorkSaved = 0.0, tileWorkOverhead = 0.0;  ///< tile_cost.h's estimate over the kept tiles
  std::map<int, std::size_t> tilesByEdge;  ///< tiles per edge of the cube they lie in (several with --tile-min)
  std::size_t cacheHits = 0, cacheMisses = 0;  ///< tile library look-ups
  double reconstructionLinf = 0.0;  ///< max |C v* - u*| over tile faces
  double kineticEnergy = 0.0;       ///< sum of 1/2 rho W_m u^2 dV over Cartesian faces + tiles' 1/2 v^T M_R v dV
  /// The same measure of the start state: u* on the Cartesian faces, the tiles' fits v*. With zero
  /// solid velocities the step minimises, so kineticEnergy <= initialKineticEnergy.
  double initialKineticEnergy = 0.0;
  /// One line per step: system, model, status, iterations, residual; on failure the first
  /// non-finite row named by its cell or tile; tiles that fell back to Cartesian, with why.
  std::string diagnostics;
};

}  // namespace step
}  // namespace stokes::solver
