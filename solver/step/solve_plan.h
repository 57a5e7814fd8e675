#pragma once
// The solve plan: which system form, Krylov method and preconditioner a step runs, decided in one
// function (planSolve) from what the caller asks. The command line (`stokesvdb analytic`,
// `stokesvdb study`), the scene files (sim/step/stokes_stage.h, planStokes) and the solver
// (solveStep, for a method left open) all go through it, and every name of these options comes
// from the tables below (names.h).
//
// The rules, measured (bench/results/preconditioners.md, reduced_multigrid.md; docs/design.md §5):
//  - the block multigrid pays on the pressure-velocity form of unified Stokes (GMRES with its block
//    upper-triangular preconditioner, 2-6x faster than Jacobi CG on the SPD form on viscous steps);
//    on the SPD pressure-stress form it saves only 2-3x, so a multigrid unified solve runs on the
//    pressure-velocity form unless a form is asked for. GMRES with the triangular form took a third
//    of MINRES' iterations with the block diagonal (beam 96, frames 1-2: 38 against 115 per step;
//    armadillos 128: 37 against 94; film spreading 64: 27 against 75) at about the same cost each;
//  - but not on steps whose viscous number mu dt / (rho dx^2) is below kMultigridMinViscousNumber:
//    mass-dominated, the SPD form is well conditioned and Jacobi CG needs few iterations, and the
//    multigrid would need its Cahouet-Chabard pressure cycle (below kCahouetChabardMaxViscousNumber
//    = 10). Armadillos res 128, frames 1-12, the same 123 steps on both sides, multigrid / Jacobi
//    Krylov time: 2.2-2.4x at nu 6-9, 0.63-0.81x at 10-20, 0.46-0.49x at 40-60
//    (bench/results/multigrid_scenes.md);
//  - nor on small steps, below kMultigridMinLiquidCells liquid cells, unless their viscous number
//    reaches kMultigridSmallStepMinViscousNumber: there the cycle's set-up and its per-iteration
//    cost outweigh its fewer iterations (armadillos res 64, ~10k unknowns, nu 11-33: 1.3-1.9x
//    slower), except on stiff bodies, where Jacobi CG's iterations grow with the viscous number
//    (beam res 32, nu 1,600, 5.6k unknowns: 1,570 against 26 iterations, 2.2x faster; beam res 64,
//    3.3k liquid cells: 3.6x);
//  - small steps also run their solve on one thread: below kParallelSolveMinLiquidCells liquid
//    cells a second thread's fork-joins cost more than it saves (2 threads against 1, first
//    frame: Jacobi CG on the default scene 1.6-1.8x and on the beam at res 64 1.3-1.4x slower; the
//    multigrid on the armadillos at res 128, 7k cells, a tie; film spreading and beam 96, 10-12k
//    cells, 1.1-1.2x faster). The answer does not depend on it: reductions
//    are bit-identical for every thread count;
//  - reduced tiles outside unified Stokes sit beside the cycle as Jacobi rows: there Jacobi is the
//    faster preconditioner (box-viscosity quadratic N = 64: 107 against 147 iterations, at several
//    times the cost of an iteration);
//  - the pressure-velocity form is symmetric indefinite: MINRES (BiCGSTAB, the thesis' choice,
//    stagnates on the reduced saddle point), never CG;
//  - the PETSc backend solves the pressure-velocity form (its distributed velocity multigrid,
//    solver/petsc/face_levels.h) where it or the multigrid is asked for, and, with the
//    preconditioner open, on a scene's step without tiles where the in-house rule takes the
//    multigrid and the viscous number is at least kPetscMultigridMinViscousNumber; else the SPD
//    pressure-stress form. First frames on 2 ranks, uniform model, against CG + Jacobi on the SPD
//    form: the beam at res 96 (viscous number 14,400) ~3x faster (6 steps, 3.3-3.9 against 11.2 s),
//    the armadillos at res 192 (150) 1.2x slower (3 steps, 3.7 against 3.1 s). Its options
//    database picks the method and the preconditioner;
//  - reduced tiles under the pressure-velocity multigrid are kept only where they pay
//    (TileRule::Paying, solver/reduced/tile_cost.h, whose work estimate was fitted to that solver);
//    elsewhere every tile the tiling makes is kept.
#include <cstddef>
#include <limits>
#include <optional>
#include <stdexcept>
#include <string>

#include "solver/krylov/saddle_point_preconditioner.h"
#include "solver/reduced/tile_cost.h"
#include "solver/step/names.h"

namespace stokes::solver {
inline namespace step {

enum class SystemKind {
  UnifiedStokes,       ///< pressure + viscosity in one solve (thesis 3.6)
  Viscosity,           ///< decoupled viscosity only (Batty & Bridson 2008; thesis Eq. 3.20)
  PressureProjection,  ///< inviscid pressure projection only (thesis Eq. 3.21-3.22)
  DecoupledStokes,     ///< viscosity, then a pressure projection (thesis 3.5)
};
/// GMRES and FGMRES: restarted, right-preconditioned (solver/krylov/gmres.h); FGMRES keeps the
/// preconditioned basis, for a preconditioner that varies between applies.
enum class KrylovMethod { CG, BiCGSTAB, MINRES, GMRES, FGMRES };
/// Which algebraic form unified Stokes is solved in.
enum class StokesForm {
  PressureStress,    ///< SPD, stresses kept, velocities eliminated (Eq. 4.20-4.25): CG
  PressureVelocity,  ///< symmetric indefinite, stresses eliminated (Eq. 4.19): MINRES
};
/// None: plain Krylov; Jacobi: the diagonal; Multigrid: the V-cycle preconditioners of
/// solver/multigrid/multigrid_preconditioners.h (one per system and form).
enum class PreconditionerKind { None, Jacobi, Multigrid };
/// Who runs the Krylov solve: the engine's own solvers, or PETSc over MPI ranks (solver/petsc/).
enum class Backend { InHouse, Petsc };
/// Compact: Krylov vectors hold the live rows only; Padded: every slot of every block; Auto:
/// compact for the pressure-stress and pressure-velocity forms, otherwise when the padded layout
/// has at least kCompactRowsMinPadding rows per live row (solveSystem in stokes_step.h).
enum class RowStorage { Auto, Compact, Padded };
/// How the pressure-stress form's stencils run on live rows: over the compact neighbour index of
/// the unknowns (Rows), or sweeping the blocks that hold them (Blocks); the same operator bit for
/// bit (StepOptions::rowStencils).
enum class StencilSweep { Rows, Blocks };

inline constexpr NamedValue<SystemKind> kSystemNames[] = {
    {SystemKind::UnifiedStokes, "unified", "unified-stokes"},
    {SystemKind::Viscosity, "viscosity", "viscosity"},
    {SystemKind::PressureProjection, "pressure", "pressure"},
    {SystemKind::DecoupledStokes, "decoupled", "decoupled"}};
inline constexpr NamedValue<KrylovMethod> kKrylovMethodNames[] = {
    {KrylovMethod::CG, "cg", "CG"},
    {KrylovMethod::BiCGSTAB, "bicgstab", "BiCGSTAB"},
    {KrylovMethod::MINRES, "minres", "MINRES"},
    {KrylovMethod::GMRES, "gmres", "GMRES"},
    {KrylovMethod::FGMRES, "fgmres", "FGMRES"}};
inline constexpr NamedValue<StokesForm> kFormNames[] = {{StokesForm::PressureStress, "spd", "pressure-stress"},
                                                        {StokesForm::PressureVelocity, "pv", "pressure-velocity"}};
inline constexpr NamedValue<PreconditionerKind> kPreconditionerNames[] = {
    {PreconditionerKind::None, "none", "none"},
    {PreconditionerKind::Jacobi, "jacobi", "Jacobi"},
    {PreconditionerKind::Multigrid, "multigrid", "multigrid"}};
inline constexpr NamedValue<Backend> kBackendNames[] = {{Backend::InHouse, "in-house", "in-house"},
                                                        {Backend::Petsc, "petsc", "petsc"}};
inline constexpr NamedValue<RowStorage> kRowStorageNames[] = {
    {RowStorage::Auto, "auto", "auto"}, {RowStorage::Compact, "compact", "compact"}, {RowStorage::Padded, "padded", "padded"}};

inline constexpr NamedValue<StencilSweep> kStencilSweepNames[] = {
    {StencilSweep::Rows, "rows", "neighbour-index stencils"}, {StencilSweep::Blocks, "blocks", "block stencils"}};

inline constexpr NamedValue<TileRule> kTileRuleNames[] = {{TileRule::All, "all", "all tiles"},
                                                          {TileRule::Paying, "paying", "paying tiles"}};

static_assert(listsEveryValueInOrder(kTileRuleNames, TileRule::Paying));
static_assert(listsEveryValueInOrder(kStencilSweepNames, StencilSweep::Blocks));
static_assert(listsEveryValueInOrder(kSystemNames, SystemKind::DecoupledStokes));
static_assert(listsEveryValueInOrder(kKrylovMethodNames, KrylovMethod::FGMRES));
static_assert(listsEveryValueInOrder(kFormNames, StokesForm::PressureVelocity));
static_assert(listsEveryValueInOrder(kPreconditionerNames, PreconditionerKind::Multigrid));
static_assert(listsEveryValueInOrder(kBackendNames, Backend::Petsc));
static_assert(listsEveryValueInOrder(kRowStorageNames, RowStorage::Padded));

constexpr std::span<const NamedValue<SystemKind>> namesOf(SystemKind) { return kSystemNames; }
constexpr std::span<const NamedValue<KrylovMethod>> namesOf(KrylovMethod) { return kKrylovMethodNames; }
constexpr std::span<const NamedValue<StokesForm>> namesOf(StokesForm) { return kFormNames; }
constexpr std::span<const NamedValue<PreconditionerKind>> namesOf(PreconditionerKind) { return kPreconditionerNames; }
constexpr std::span<const NamedValue<Backend>> namesOf(Backend) { return kBackendNames; }
constexpr std::span<const NamedValue<RowStorage>> namesOf(RowStorage) { return kRowStorageNames; }
constexpr std::span<const NamedValue<TileRule>> namesOf(TileRule) { return kTileRuleNames; }
constexpr std::span<const NamedValue<StencilSweep>> namesOf(StencilSweep) { return kStencilSweepNames; }

/// Unified solves with fewer liquid cells than this run Jacobi CG when the preconditioner is left
/// open, unless their viscous number reaches kMultigridSmallStepMinViscousNumber (see the file
/// comment).
inline constexpr std::size_t kMultigridMinLiquidCells = 5000;
/// Unified solves whose viscous number mu dt / (rho dx^2) is below this run Jacobi CG when the
/// preconditioner is left open (see the file comment).
inline constexpr double kMultigridMinViscousNumber = 10.0;
/// Small unified solves (below kMultigridMinLiquidCells) run the multigrid from this viscous number
/// on when the preconditioner is left open (see the file comment).
inline constexpr double kMultigridSmallStepMinViscousNumber = 1000.0;
/// On the PETSc backend a scene's unified step with the preconditioner open takes the
/// pressure-velocity form only from this viscous number on (see the file comment): between the
/// armadillos' 150 and the beam's 14,400, where the velocity multigrid's interpolation turns linear.
inline constexpr double kPetscMultigridMinViscousNumber = 1000.0;
/// Steps with fewer liquid cells than this solve on one thread (see the file comment).
inline constexpr std::size_t kParallelSolveMinLiquidCells = 5000;

/// What a caller asks for; what it leaves open (nullopt) the plan chooses.
struct SolveRequest {
  SystemKind system = SystemKind::UnifiedStokes;
  bool reducedTiles = false;  ///< the velocity model has polynomial tiles
  std::optional<PreconditionerKind> preconditioner;  ///< open: the fastest measured
  /// The step's liquid cells (W_L^p > 0), where known (a scene's step): an open preconditioner
  /// follows the size (kMultigridMinLiquidCells); unknown (the analytic cases), it is the one for
  /// large problems.
  std::optional<std::size_t> liquidCells;
  /// The step's viscous number mu dt / (rho dx^2), where known: an open preconditioner is Jacobi
  /// below kMultigridMinViscousNumber.
  std::optional<double> viscousNumber;
  std::optional<StokesForm> form;                    ///< open: the form the preconditioner pays on
  std::optional<KrylovMethod> method;                ///< open: the form's method
  /// The method of a step planned on the pressure-velocity form, where `method` is open (a scene's
  /// `solver.multigrid_method`: its Jacobi steps keep CG on the SPD form).
  std::optional<KrylovMethod> pressureVelocityMethod;
  std::optional<TileRule> tileRule;                  ///< open: Paying under the PV multigrid, else All
  Backend backend = Backend::InHouse;
};

/// What a step runs.
struct SolvePlan {
  StokesForm form = StokesForm::PressureStress;
  KrylovMethod method = KrylovMethod::CG;
  PreconditionerKind preconditioner = PreconditionerKind::Jacobi;
  TileRule tileRule = TileRule::All;  ///< which reduced tiles are kept (ReducedOptions::rule)
  Backend backend = Backend::InHouse;
  int threads = 0;  ///< OpenMP threads of the solve; 0: the caller's
};

/// The Krylov method of `form` under `preconditioner`: `asked` if it applies, else CG on the SPD
/// form; on the pressure-velocity form GMRES with the multigrid (its block upper-triangular
/// preconditioner, saddlePointBlocksFor) and MINRES with the others (GMRES(30) with Jacobi took
/// 89,043 iterations on the ball at n = 24 where MINRES took 761). Throws std::invalid_argument for
/// CG on the indefinite form.
inline KrylovMethod methodFor(StokesForm form, std::optional<KrylovMethod> asked,
                              PreconditionerKind preconditioner = PreconditionerKind::Multigrid) {
  if (form == StokesForm::PressureStress) return asked.value_or(KrylovMethod::CG);
  if (asked == KrylovMethod::CG)
    throw std::invalid_argument("the pressure-velocity form is symmetric indefinite: CG does not apply (use gmres, "
                                "minres, fgmres or bicgstab, or leave the method open)");
  return asked.value_or(preconditioner == PreconditionerKind::Multigrid ? KrylovMethod::GMRES : KrylovMethod::MINRES);
}

/// The block structure of the pressure-velocity form's preconditioner under `method`
/// (solver/krylov/saddle_point_preconditioner.h): MINRES needs an SPD preconditioner, the block
/// diagonal; GMRES and FGMRES take the block upper-triangular one, whose iterations with exact blocks
/// are those of CG on the Schur complement rather than MINRES' on the two intervals of the diagonal
/// form. BiCGSTAB keeps the diagonal form it was measured with.
inline SaddlePointBlocks saddlePointBlocksFor(KrylovMethod method) {
  const bool gmres = method == KrylovMethod::GMRES || method == KrylovMethod::FGMRES;
  return gmres ? SaddlePointBlocks::UpperTriangular : SaddlePointBlocks::Diagonal;
}

/// The preconditioner of a request that leaves it open: the fastest measured (file comment).
inline PreconditionerKind openPreconditioner(const SolveRequest& r) {
  const bool unified = r.system == SystemKind::UnifiedStokes;
  if (r.reducedTiles && !unified) return PreconditionerKind::Jacobi;
  if (r.liquidCells) {
    // a scene's step: the multigrid where viscosity matters (kMultigridMinViscousNumber), from
    // kMultigridMinLiquidCells on or on stiff small steps (kMultigridSmallStepMinViscousNumber), for
    // unified Stokes only (the decoupled and projection solves of the scenes were measured with
    // Jacobi CG alone)
    const double nu = r.viscousNumber.value_or(std::numeric_limits<double>::infinity());
    const bool large = *r.liquidCells >= kMultigridMinLiquidCells || nu >= kMultigridSmallStepMinViscousNumber;
    return unified && nu >= kMultigridMinViscousNumber && large ? PreconditionerKind::Multigrid
                                                                : PreconditionerKind::Jacobi;
  }
  return PreconditionerKind::Multigrid;
}

/// Throws std::invalid_argument, naming the conflict, for a request no plan can serve (the PETSc
/// backend asked for a form or system it does not solve, CG asked for on the indefinite form).
/// planSolve checks again; a scene, whose request names no method (so that no step's size can make
/// its plan invalid), checks once before its first step.
inline void checkRequest(const SolveRequest& r) {
  if (r.backend == Backend::Petsc) {
    if (r.system == SystemKind::Viscosity || r.system == SystemKind::DecoupledStokes)
      throw std::invalid_argument("the PETSc backend solves unified Stokes or the pressure projection; the "
                                  "decoupled viscosity solve runs in-house only");
    return;
  }
  if (r.form) (void)methodFor(*r.form, r.method);
  (void)methodFor(StokesForm::PressureVelocity, r.pressureVelocityMethod);
}

/// The one decision (see the file comment).
inline SolvePlan planSolve(const SolveRequest& r) {
  checkRequest(r);
  SolvePlan p;
  p.backend = r.backend;
  if (r.backend == Backend::Petsc) {
    // the pressure-velocity form (PETSc's field split with the distributed velocity multigrid) for a
    // unified step without tiles where it is asked for, by name or as the multigrid, or where the
    // preconditioner is open, the in-house rule takes the multigrid and the step's viscous number
    // is at least kPetscMultigridMinViscousNumber; else the pressure-stress form
    // (PETSc's field split was measured on steps from kMultigridMinLiquidCells liquid cells only)
    const bool viscous = r.viscousNumber && *r.viscousNumber >= kPetscMultigridMinViscousNumber &&
                         (!r.liquidCells || *r.liquidCells >= kMultigridMinLiquidCells);
    const bool multigrid =
        !r.reducedTiles && (r.preconditioner ? *r.preconditioner == PreconditionerKind::Multigrid
                                             : viscous && openPreconditioner(r) == PreconditionerKind::Multigrid);
    p.form = r.system == SystemKind::UnifiedStokes
                 ? r.form.value_or(multigrid ? StokesForm::PressureVelocity : StokesForm::PressureStress)
                 : StokesForm::PressureStress;
    p.preconditioner = r.preconditioner.value_or(PreconditionerKind::Jacobi);
    p.method = r.method.value_or(methodFor(p.form, std::nullopt, p.preconditioner));  // unused: PETSc's options database decides
    p.tileRule = r.tileRule.value_or(TileRule::All);
    return p;
  }
  p.preconditioner = r.preconditioner.value_or(openPreconditioner(r));
  if (r.liquidCells && *r.liquidCells < kParallelSolveMinLiquidCells) p.threads = 1;
  const bool multigridUnified =
      p.preconditioner == PreconditionerKind::Multigrid && r.system == SystemKind::UnifiedStokes;
  p.form = r.form.value_or(multigridUnified ? StokesForm::PressureVelocity : StokesForm::PressureStress);
  p.method = methodFor(p.form, p.form == StokesForm::PressureVelocity && !r.method ? r.pressureVelocityMethod : r.method,
                       p.preconditioner);
  const bool pvMultigrid = multigridUnified && p.form == StokesForm::PressureVelocity;
  p.tileRule = r.tileRule.value_or(pvMultigrid ? TileRule::Paying : TileRule::All);
  return p;
}

}  // namespace step
}  // namespace stokes::solver
