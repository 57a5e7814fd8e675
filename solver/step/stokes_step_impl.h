#pragma once
// The definitions behind stokes_step.h: build the chosen system on a StaggeredProblem, solve it
// with the chosen Krylov method and preconditioner (solve_plan.h decides them,
// preconditioner_factory.h makes the preconditioner), and write the new face velocities.
// Included only by the translation units that instantiate solveStep for Dim = 2 and 3
// (stokes_step_2d.cpp, stokes_step_3d.cpp); every other file compiles against the declarations.
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <type_traits>

#include "solver/krylov/compact_rows.h"
#include "solver/krylov/operator.h"
#include "solver/krylov/stopwatch.h"
#include "solver/step/rank_sums.h"
#include "solver/step/preconditioner_factory.h"
#include "solver/step/step_diagnostics.h"
#include "solver/step/step_options.h"
#include "solver/step/stokes_step.h"
#include "solver/systems/pressure_stress_rows.h"
#include "solver/systems/pressure_stress_system.h"
#include "solver/systems/pressure_velocity_rows.h"
#include "solver/systems/pressure_velocity_system.h"
#include "solver/systems/viscosity_system.h"
#ifdef STOKES_HAVE_PETSC
#include "solver/petsc/solve_on_ranks.h"
#endif

namespace stokes::solver {
inline namespace step {

namespace detail {

/// The OpenMP thread count of one solve (StepOptions::threads; 0 leaves the caller's), restored
/// when it goes out of scope.
class SolveThreads {
 public:
  explicit SolveThreads(int threads) : saved_(omp_get_max_threads()) {
    if (threads > 0) omp_set_num_threads(threads);
  }
  ~SolveThreads() { omp_set_num_threads(saved_); }
  SolveThreads(const SolveThreads&) = delete;
  SolveThreads& operator=(const SolveThreads&) = delete;

 private:
  int saved_;
};
/// x0 of a warm-started SPD solve: `guess` on the active rows (positive diagonal), 0 on the rest,
/// which the compact and padded operators both require.
inline void startFromGuess(const Vector& guess, const Vector& diagonal, Vector& x) {
  if (guess.size() != x.size())
    throw std::invalid_argument("solveStep: the initial guess has " + std::to_string(guess.size()) +
                                " values, the system " + std::to_string(x.size()));
  for (std::size_t i = 0; i < x.size(); ++i) x[i] = diagonal[i] > 0.0 ? guess[i] : 0.0;
}

/// The PETSc backend's solve of `sys` (the pressure-stress form, or the pressure-velocity form
/// without tiles) on x (padded; guess in, solution out on every rank: all of it, or a distributed
/// problem's part, solveOnRanks).
template <int Dim, class System>
void solveOnPetsc(const StaggeredProblem<Dim>& prob, const System& sys, const SolveOptions& kopt,
                  FaceInterpolation interpolation, Vector& x, StepReport& rep) {
#ifdef STOKES_HAVE_PETSC
  constexpr bool stress = std::is_same_v<System, PressureStressSystem<Dim>>;
  constexpr bool velocity = std::is_same_v<System, PressureVelocitySystem<Dim>>;
  if constexpr (stress || velocity) {
    const petsc::PetscReport pr = [&] {
      if constexpr (stress) return petsc::solveOnRanks<petsc::PressureStressRanks>(prob, sys, kopt, x, &rep.krylovRows);
      else return petsc::solveOnRanks<petsc::PressureVelocityRanks>(prob, sys, kopt, x, &rep.krylovRows, interpolation);
    }();
    if (prob.isDistributed()) rep.unknowns = rep.krylovRows;  // every rank's, not this rank's and its halo
    rep.solve = pr.solve;
    if (!pr.solve.converged()) rep.diagnostics = "PETSc: " + pr.reason;
    rep.preconditionerSeconds = pr.setupSeconds;
    rep.stencilSlots = rep.krylovRows;
    rep.solver = std::string(systemName<Dim, System>(sys)) + ": PETSc " + pr.kspType + " + " + pr.pcType + " on " +
                 std::to_string(pr.ranks) + (pr.ranks == 1 ? " rank" : " ranks") +
                 (prob.isDistributed() && pr.ranks > 1 ? ", each holding its blocks and a halo" : "") +
                 (pr.normType == "UNPRECONDITIONED" ? "" : " (stopping on its " + pr.normType + " residual norm" +
                  (pr.restarts > 0 ? ", continued " + std::to_string(pr.restarts) + "x to the true residual" : "") + ")") +
                 (pr.assembledNote.empty() ? "" : "; its AIJ matrix has the " + pr.assembledNote) +
                 (pr.ranks == 1 ? ""
                                : "; rows per rank " + std::to_string(pr.rowsMin) + "-" + std::to_string(pr.rowsMax) +
                                      ", halo rows per apply " + std::to_string(pr.haloMax) + " on the largest rank, " +
                                      std::to_string(pr.haloSum) + " in all");
    return;
  } else {
    throw std::invalid_argument(std::string("the PETSc backend solves unified Stokes or the pressure projection, not "
                                            "the ") +
                                systemName<Dim, System>(sys) + " system");
  }
#else
  (void)prob, (void)sys, (void)kopt, (void)x, (void)rep;
  throw std::invalid_argument("this build has no PETSc backend: install PETSc (scripts/install_deps.sh) and "
                              "configure with -DSTOKES_WITH_PETSC=ON");
#endif
}

template <int Dim, class System>
inline constexpr bool kIsPressureVelocity = std::is_same_v<System, PressureVelocitySystem<Dim>>;

template <int Dim>
constexpr std::size_t kPressureVelocityChannels = solutionChannels<Dim>(SystemKind::UnifiedStokes, StokesForm::PressureVelocity);

/// x0 of a warm-started pressure-velocity solve from `guess` = [u | p | l] per slot
/// (solutionChannels): u on the
/// unknown faces, the tiles' DOFs from the fit of u over their faces (ReducedTiles::fitFaceField),
/// p on the live pressure rows, l on this step's rigid samples.
template <int Dim>
void startPressureVelocityFromGuess(const PressureVelocitySystem<Dim>& sys, const ReducedTiles<Dim>* tiles,
                                    const Vector& guess, std::size_t slots, Vector& x) {
  if (guess.size() != kPressureVelocityChannels<Dim> * slots)
    throw std::invalid_argument("solveStep: the pressure-velocity initial guess has " + std::to_string(guess.size()) +
                                " values, [u | p | l] on " + std::to_string(slots) + " cells needs " +
                                std::to_string(kPressureVelocityChannels<Dim> * slots));
  const Vector& diagonal = sys.diagonal();
  for (std::size_t i = 0; i < Dim * slots; ++i) x[i] = diagonal[i] > 0.0 ? guess[i] : 0.0;
  if (tiles && tiles->numTiles() > 0) tiles->fitFaceField(guess.data(), x.data() + Dim * slots);
  const std::size_t p0 = sys.pressureOffset(), l0 = (Dim + 1) * slots;
  for (std::size_t s = 0; s < slots; ++s) x[p0 + s] = diagonal[p0 + s] > 0.0 ? guess[Dim * slots + s] : 0.0;
  for (std::size_t k = 0; k < sys.rigidRows(); ++k) x[sys.rigidOffset() + k] = guess[l0 + sys.rigidSample(k)];
}

/// The pressure-velocity form's `solution` [u | p | l] (above): the face velocities the step
/// wrote, the pressure rows of x, the multipliers on their samples.
template <int Dim>
Vector pressureVelocitySolution(const PressureVelocitySystem<Dim>& sys, const double* u, const Vector& x,
                                std::size_t slots) {
  Vector s(kPressureVelocityChannels<Dim> * slots, 0.0);
  std::copy(u, u + Dim * slots, s.begin());
  std::copy_n(x.begin() + std::ptrdiff_t(sys.pressureOffset()), slots, s.begin() + std::ptrdiff_t(Dim * slots));
  const std::size_t l0 = (Dim + 1) * slots;
  for (std::size_t k = 0; k < sys.rigidRows(); ++k) s[l0 + sys.rigidSample(k)] = x[sys.rigidOffset() + k];
  return s;
}

/// Whether the pressure-velocity multigrid runs the re-discretised padded cycle rather than the
/// Galerkin cycle on live rows: only where nothing but a free surface bounds the liquid (no solid,
/// no closed wall, no tile: there the Galerkin cycle's coarse levels pay, 3-5x fewer iterations
/// around solids; design.md §5.5) and the padded blocks hold fewer than kPaddedCycleMaxPadding rows
/// per live row. Ball 128^3 (1.67 padded rows per live row): 62 against 78 iterations, 5.0-6.9
/// against 10.0-11.4 s, 727 against 1,152 MB; per live row and iteration 100 against 106 ns, so the
/// padded cycle wins by its iterations and by the Galerkin products it does not build. Disk N = 512
/// (1.04): 63 against 62 iterations, 5.1-5.4 against 6.0-8.8 s, 593 against 961 MB. The falling
/// armadillo pile, 10.7 padded rows per live row: 28 against 5.7 ms per iteration.
inline constexpr double kPaddedCycleMaxPadding = 2.0;

/// The uniform padded-cycle solve's time against the Galerkin cycle's on the same live rows (the
/// comparison the paying-tiles rule makes, ReducedOptions::uniformRowCost): ball 128^3 6.93
/// against 11.43 s (0.61: 62 against 78 iterations at 100 against 106 ns per live row per
/// iteration), disk N = 512 5.37 against 6.01 s (0.89: the Galerkin products' set-up); their mean.
inline constexpr double kPaddedCycleSolveCost = 0.75;

/// The rows of the step's solve without tiles: faces with liquid weight, not closed, and cells
/// with liquid (the pressure-velocity form's live rows, less the odd row a weight floor removes).
template <int Dim>
std::size_t uniformRowEstimate(const StaggeredProblem<Dim>& prob) {
  const std::size_t n = prob.slots();
  std::size_t rows = 0;
#pragma omp parallel for reduction(+ : rows) schedule(static)
  for (std::ptrdiff_t s = 0; s < std::ptrdiff_t(n); ++s) {
    rows += prob.liquidCell[s] > 0.0 ? 1 : 0;
    for (int a = 0; a < Dim; ++a) {
      const std::size_t f = a * n + std::size_t(s);
      rows += prob.liquidFace[f] > 0.0 && !prob.isClosedFace(f) ? 1 : 0;
    }
  }
  return rows;
}

/// The problem side of runsPaddedVelocityCycle: only a free surface bounds the liquid (no solid,
/// no closed wall) and the padded rows are fewer than kPaddedCycleMaxPadding per live row.
template <int Dim>
bool paddedCycleSuits(const StaggeredProblem<Dim>& prob, std::size_t paddedRows, std::size_t liveRows) {
  if (prob.hasSolids()) return false;
  if (std::any_of(prob.closedFace.begin(), prob.closedFace.end(), [](std::uint8_t c) { return c != 0; })) return false;
  return double(paddedRows) < kPaddedCycleMaxPadding * double(liveRows);
}

template <int Dim>
bool runsPaddedVelocityCycle(const StaggeredProblem<Dim>& prob, const PressureVelocitySystem<Dim>& sys,
                             const StepOptions& opt, const RowSelection& rows) {
  return opt.preconditioner == PreconditionerKind::Multigrid && !sys.tiles() &&
         paddedCycleSuits(prob, sys.size(), rows.size());
}

/// The reduced options of a step under the paying rule: the uniform step to compare with, which
/// runs the padded cycle (kPaddedCycleSolveCost) where runsPaddedVelocityCycle would pick it
/// without tiles (the PV system without tiles has Dim + 1 padded rows per slot).
template <int Dim>
ReducedOptions payingRuleOptions(const StaggeredProblem<Dim>& prob, const StepOptions& opt) {
  ReducedOptions r = *opt.reduced;
  const bool pvMultigrid = opt.system == SystemKind::UnifiedStokes && opt.form == StokesForm::PressureVelocity &&
                           opt.preconditioner == PreconditionerKind::Multigrid;
  if (r.rule != TileRule::Paying || !pvMultigrid) return r;
  r.uniformRows = uniformRowEstimate(prob);
  const bool paddedCycle =
      opt.rows == RowStorage::Auto && paddedCycleSuits(prob, std::size_t(Dim + 1) * prob.slots(), r.uniformRows);
  r.uniformRowCost = paddedCycle ? kPaddedCycleSolveCost : 1.0;
  return r;
}

/// Whether a solve of `sys` keeps its Krylov vectors on the live rows `rows` (RowStorage::Auto:
/// the pressure-stress stencils on a neighbour index beat the padded sweep even on the dense disk,
/// 1.18 padded rows per live row; the pressure-velocity form compacts, its Galerkin multigrid on
/// live rows, unless runsPaddedVelocityCycle; the viscosity and projection systems compact from
/// kCompactRowsMinPadding padded rows per live row on).
template <int Dim, class System>
bool keepsLiveRowsOnly(const StaggeredProblem<Dim>& prob, const System& sys, const StepOptions& opt, const RowSelection& rows) {
  if (opt.rows != RowStorage::Auto) return opt.rows == RowStorage::Compact;
  constexpr bool kRowStencils = std::is_same_v<System, PressureStressSystem<Dim>>;
  if constexpr (kIsPressureVelocity<Dim, System>) return !runsPaddedVelocityCycle(prob, sys, opt, rows);
  return (kRowStencils && opt.rowStencils) || double(sys.size()) >= kCompactRowsMinPadding * double(rows.size());
}

/// Calls solve(A) with the operator of `sys` on the live rows `rows`: the pressure-velocity or
/// pressure-stress stencils on a compact neighbour index (StepOptions::rowStencils), else the
/// padded operator wrapped by the row selection. Sets rep.stencilSlots to what one apply visits.
template <int Dim, class System, class Solve>
void withLiveRowOperator(const StaggeredProblem<Dim>& prob, const System& sys, const StepOptions& opt,
                         const RowSelection& rows, StepReport& rep, const Solve& solve) {
  if constexpr (kIsPressureVelocity<Dim, System>) {
    if (opt.rowStencils) {
      solve(PressureVelocityRows<Dim>(sys, rows));
      rep.stencilSlots = rows.size();
      return;
    }
  } else if constexpr (std::is_same_v<System, PressureStressSystem<Dim>>) {
    if (opt.rowStencils) {
      solve(PressureStressRows<Dim>(sys, rows));
      rep.stencilSlots = rows.size();
    } else {
      solve(CompactOperator<System>(sys, rows));
      rep.stencilSlots = sys.rowBlocks() * sparse_grid::BlockLayout<Dim>::kSlots;
    }
    return;
  }
  solve(CompactOperator<System>(sys, rows));
  rep.stencilSlots = prob.slots();
}

/// The Krylov solve of A on the live rows `rows` (x padded: guess in, solution out). The
/// pressure-velocity form builds its multigrid on those rows (the Galerkin velocity cycle); the
/// SPD forms wrap the padded cycle to them.
template <int Dim, class System, class Op>
void solveOnLiveRows(const StaggeredProblem<Dim>& prob, const System& sys, const StepOptions& opt, const Op& A,
                     const RowSelection& rows, SolveOptions kopt, Vector& x, StepReport& rep) {
  const Vector b = rows.gathered(sys.rhs());
  Vector nullSpace;
  if (sys.nullSpace()) nullSpace = rows.gathered({sys.nullSpace(), sys.size()});
  kopt.nullSpace = nullSpace.empty() ? nullptr : nullSpace.data();
  Vector xr = rows.gathered(x);
  rep.krylovRows = rows.size();
  auto jacobi = [&] { return JacobiPreconditioner(rows.gathered(sys.diagonal())); };
  if constexpr (kIsPressureVelocity<Dim, System>) {
    const std::size_t split = std::size_t(std::lower_bound(rows.rows().begin(), rows.rows().end(),
                                                           RowSelection::Index(sys.pressureOffset())) -
                                          rows.rows().begin());
    solvePreconditioned(
        opt, A, b.data(), xr.data(), kopt, jacobi,
        [&] { return makeMultigridPreconditioner(prob, sys, rows, opt.multigrid); },
        [&](const auto& mg) { return SaddlePointPreconditioner(A, mg, split, saddlePointBlocksFor(*opt.method)); }, rep);
  } else
    solvePreconditioned(
        opt, A, b.data(), xr.data(), kopt, jacobi, [&] { return makeMultigridPreconditioner(prob, sys, opt.multigrid); },
        [&](const auto& mg) { return CompactPreconditioner<std::decay_t<decltype(mg)>>(mg, rows); }, rep);
  rows.scatter(xr.data(), x.data());
}

/// The Krylov solve of `sys` on its padded block layout (the re-discretised multigrid cycle).
template <int Dim, class System>
void solveOnPaddedRows(const StaggeredProblem<Dim>& prob, const System& sys, const StepOptions& opt,
                       SolveOptions kopt, Vector& x, StepReport& rep) {
  rep.stencilSlots = prob.slots();
  kopt.nullSpace = sys.nullSpace();
  rep.krylovRows = sys.size();
  auto wrap = [&](const auto& mg) -> decltype(auto) {
    if constexpr (kIsPressureVelocity<Dim, System>)
      return SaddlePointPreconditioner(sys, mg, sys.pressureOffset(), saddlePointBlocksFor(*opt.method));
    else
      return (mg);
  };
  solvePreconditioned(
      opt, sys, sys.rhs().data(), x.data(), kopt, [&] { return JacobiPreconditioner(sys.diagonal()); },
      [&] { return makeMultigridPreconditioner(prob, sys, opt.multigrid); }, wrap, rep);
}

/// Solves `sys` (any system with size/apply/rhs/diagonal/nullSpace/velocities) and writes u.
/// Every system runs on its live rows unless opt.rows says padded: the positive diagonal picks
/// them (for the semi-definite forms a zero diagonal is a zero row and column; in the
/// pressure-velocity form a velocity row with a zero diagonal is empty, and a constraint row
/// whose Schur estimate is zero touches no unknown face, so the same holds).
template <int Dim, class System>
StepReport solveSystem(const StaggeredProblem<Dim>& prob, const System& sys, const StepOptions& opt, double* u,
                       Vector* solution, const ReducedTiles<Dim>* tiles = nullptr, const Vector* guess = nullptr) {
  StepReport rep;
  rep.unknowns = sys.activeUnknowns();
  rep.paddedRows = sys.size();
  Vector x(sys.size(), 0.0);
  if (guess) {
    if constexpr (kIsPressureVelocity<Dim, System>) startPressureVelocityFromGuess(sys, tiles, *guess, prob.slots(), x);
    else startFromGuess(*guess, sys.diagonal(), x);
  }
  const auto t0 = std::chrono::steady_clock::now();
  const RowSelection rows = opt.rows != RowStorage::Padded ? RowSelection::positiveDiagonal(sys.diagonal())
                                                           : RowSelection({}, 0);
  if (opt.backend == Backend::Petsc)
    solveOnPetsc<Dim>(prob, sys, opt.krylov, opt.multigrid.interpolation, x, rep);
  else if (keepsLiveRowsOnly<Dim>(prob, sys, opt, rows))
    withLiveRowOperator(prob, sys, opt, rows, rep,
                        [&](const auto& A) { solveOnLiveRows(prob, sys, opt, A, rows, opt.krylov, x, rep); });
  else
    solveOnPaddedRows(prob, sys, opt, opt.krylov, x, rep);
  rep.solveSeconds = secondsSince(t0);
  if constexpr (kIsPressureVelocity<Dim, System>)
    if (opt.preconditioner == PreconditionerKind::Multigrid)
      rep.schurBlock = usesPressureCycle(prob, opt.multigrid.pressureSchur) ? "cahouet-chabard" : "diagonal";
  if (rep.solver.empty())
    rep.solver = std::string(systemName<Dim, System>(sys)) + ": " + toString(*opt.method) + " + " + toString(opt.preconditioner);
  if (rep.solve.status == Status::NonFinite) rep.diagnostics = locateNonFinite(prob, sys, tiles, x);
  sys.velocities(x.data(), u);
  if (solution) *solution = std::move(x);
  return rep;
}

/// Kinetic energy sum 1/2 rho W_F W_m |u|^2 dV over the unknown Cartesian faces (of all ranks'
/// blocks in a distributed problem), with the solve's
/// mass weights W_m (faceMassWeights, computed once by the caller for both energies of a step),
/// plus the tiles' 1/2 v^T M_R v.
template <int Dim>
double stepKineticEnergy(const StaggeredProblem<Dim>& prob, const std::vector<FaceState>& state,
                         const std::vector<double>& massWeight, const Vector& u, const ReducedTiles<Dim>* tiles,
                         const double* tileVelocities) {
  const double dV = std::pow(prob.layout->dx(), Dim);
  const std::size_t n = prob.slots();
  double e = 0.0;
  for (std::size_t i = 0; i < state.size(); ++i)
    if (state[i] == FaceState::Unknown && prob.ownsSlot(i % n))
      e += 0.5 * prob.rho * prob.fluidFaceWeight(i) * massWeight[i] * u[i] * u[i] * dV;
  if (tiles && tileVelocities) e += tiles->kineticEnergy(tileVelocities);
  return sumOverParts(prob, e);
}

inline void accumulate(StepReport& total, const StepReport& part) {
  total.solve.iterations += part.solve.iterations;
  total.solve.finalResidual = std::max(total.solve.finalResidual, part.solve.finalResidual);
  total.solve.relativeResidual = std::max(total.solve.relativeResidual, part.solve.relativeResidual);
  if (!part.solve.converged()) total.solve.status = part.solve.status;
  total.unknowns += part.unknowns;
  total.paddedRows += part.paddedRows;
  total.krylovRows += part.krylovRows;
  total.stencilSlots += part.stencilSlots;
  total.tiles += part.tiles;
  total.fallbackTiles += part.fallbackTiles;
  total.partialTiles += part.partialTiles;
  total.unpaidTiles += part.unpaidTiles;
  total.keptTiles += part.keptTiles;
  total.reusedTileDecisions += part.reusedTileDecisions;
  total.tileWorkSaved += part.tileWorkSaved;
  total.tileWorkOverhead += part.tileWorkOverhead;
  if (!part.tileRule.empty()) total.tileRule = part.tileRule;
  for (const auto& [edge, count] : part.tilesByEdge) total.tilesByEdge[edge] += count;
  total.cacheHits += part.cacheHits;
  total.cacheMisses += part.cacheMisses;
  total.reducedDofs += part.reducedDofs;
  total.cartesianDofs += part.cartesianDofs;
  total.reconstructionLinf = std::max(total.reconstructionLinf, part.reconstructionLinf);
  total.kineticEnergy = part.kineticEnergy;  // the start energy stays the first solve's
  if (!part.diagnostics.empty()) total.diagnostics += (total.diagnostics.empty() ? "" : "; ") + part.diagnostics;
  total.tileSeconds += part.tileSeconds;
  total.setupSeconds += part.setupSeconds;
  total.solveSeconds += part.solveSeconds;
  total.preconditionerSeconds += part.preconditionerSeconds;
  total.multigridLevels = std::max(total.multigridLevels, part.multigridLevels);
  if (!part.schurBlock.empty()) total.schurBlock = part.schurBlock;
  if (!part.solver.empty()) total.solver += (total.solver.empty() ? "" : "; ") + part.solver;
}

/// The tile counts of a problem distributed by blocks, each rank's over the tiles it reports
/// (ReducedTiles::reportedTiles), summed over the ranks (integers: exact in any order), and the
/// reconstruction error their maximum. Such a problem has no adaptive tiles: every cube has the
/// edge `tileSize`. The unknowns hold every rank's Krylov rows (solveOnPetsc) and this rank's
/// tile modes, which become every rank's.
template <int Dim>
void sumTileCountsOverParts(const StaggeredProblem<Dim>& prob, int tileSize, StepReport& rep) {
  rep.unknowns -= rep.reducedDofs;
  for (std::size_t* count : {&rep.tiles, &rep.reducedDofs, &rep.partialTiles, &rep.unpaidTiles, &rep.keptTiles,
                             &rep.fallbackTiles, &rep.cacheHits, &rep.cacheMisses})
    *count = std::size_t(sumOverParts(prob, double(*count)));
  rep.unknowns += rep.reducedDofs;
  rep.tilesByEdge.clear();
  if (rep.tiles > 0) rep.tilesByEdge[tileSize] = rep.tiles;
  rep.reconstructionLinf = maxOverParts(prob, rep.reconstructionLinf);
}

/// One system (not DecoupledStokes) on a validated problem; writes every face of `u`.
template <int Dim>
StepReport solveOneSystem(const StaggeredProblem<Dim>& prob, const StepOptions& opt, Vector& u, Vector* solution,
                          const Vector* guess) {
  u.assign(Dim * prob.slots(), 0.0);
  if (prob.isDistributed() && opt.backend != Backend::Petsc)
    throw std::invalid_argument("solveStep: a problem distributed by blocks is solved by the PETSc backend");
  if (prob.isDistributed() && opt.reduced && opt.system == SystemKind::UnifiedStokes &&
      opt.form == StokesForm::PressureVelocity)
    throw std::invalid_argument("solveStep: the PETSc backend solves reduced tiles in the pressure-stress form");
  const auto t0 = std::chrono::steady_clock::now();
  std::unique_ptr<ReducedTiles<Dim>> tiles;
  std::size_t unpaidTiles = 0;
  if (opt.reduced) {
    tiles = std::make_unique<ReducedTiles<Dim>>(prob, payingRuleOptions(prob, opt), couplingKinds(opt.system));
    if (tiles->numTiles() == 0 && tiles->unpaidTiles() > 0) {  // none pays: the step is the uniform one
      unpaidTiles = tiles->unpaidTiles();
      tiles.reset();
    }
  }
  const double tileSeconds = secondsSince(t0);
  auto finish = [&](StepReport rep, const auto& sys, const double* tileVelocities) {
    rep.setupSeconds = secondsSince(t0) - rep.solveSeconds;
    rep.tileSeconds = tileSeconds;
    rep.unpaidTiles = unpaidTiles;
    if (opt.reduced) rep.tileRule = keyOf(opt.reduced->rule);
    if (tiles) {
      rep.tiles = tiles->reportedTiles();
      rep.reducedDofs = tiles->resolvedDofs();
      rep.partialTiles = tiles->partialTiles();
      rep.unpaidTiles = tiles->unpaidTiles();
      rep.keptTiles = tiles->keptTiles();
      rep.reusedTileDecisions = tiles->reusedDecisions();
      rep.tileWorkSaved = tiles->work().saved;
      rep.tileWorkOverhead = tiles->work().overhead;
      for (std::size_t t = 0; t < tiles->numTiles(); ++t)
        if (tiles->reportsTile(t)) ++rep.tilesByEdge[tiles->tiling().tiles[t].cubeEdge];
      rep.reconstructionLinf = tiles->reconstructionLinf();
      rep.fallbackTiles = tiles->fallbacks().size();
      rep.cacheHits = tiles->cacheHits();
      rep.cacheMisses = tiles->cacheMisses();
    }
    if (prob.isDistributed() && opt.reduced) detail::sumTileCountsOverParts(prob, opt.reduced->tiling.tileSize, rep);
    rep.cartesianDofs = rep.unknowns - rep.reducedDofs;
    const std::vector<FaceState>& state = sys.faceStates();
    const std::vector<double> massWeight = faceMassWeights(prob, state);
    rep.kineticEnergy = detail::stepKineticEnergy(prob, state, massWeight, u, tiles.get(), tileVelocities);
    Vector vStar;  // the tiles' fits of u*, tile-major
    if (tiles)
      for (std::size_t t = 0; t < tiles->numTiles(); ++t)
        vStar.insert(vStar.end(), tiles->tile(t).vStar.data(), tiles->tile(t).vStar.data() + tiles->dofsPerTile());
    rep.initialKineticEnergy =
        detail::stepKineticEnergy(prob, state, massWeight, prob.uStar, tiles.get(), vStar.data());
    if (tiles && !tiles->fallbacks().empty())
      rep.diagnostics += (rep.diagnostics.empty() ? "" : "; ") + std::to_string(tiles->fallbacks().size()) +
                         " tile(s) fell back to Cartesian cells, first: " + tiles->fallbacks().front();
    return rep;
  };
  // Velocity forms keep x = [u_C | v_R | ...]: the tiles' generalised velocities follow the faces.
  auto solveVelocityForm = [&](const auto& sys, const StepOptions& o) {
    Vector x;
    StepReport rep = detail::solveSystem(prob, sys, o, u.data(), &x, tiles.get(), guess);
    if (tiles) rep.unknowns -= tiles->totalDofs() - tiles->resolvedDofs();  // the dropped modes' inert rows
    rep = finish(rep, sys, tiles ? x.data() + Dim * prob.slots() : nullptr);
    if (!solution) return rep;
    if constexpr (std::is_same_v<std::decay_t<decltype(sys)>, PressureVelocitySystem<Dim>>)
      *solution = detail::pressureVelocitySolution(sys, u.data(), x, prob.slots());
    else
      *solution = std::move(x);
    return rep;
  };
  if (opt.system == SystemKind::UnifiedStokes && opt.form == StokesForm::PressureVelocity) {
    const PressureVelocitySystem<Dim> sys(prob, tiles.get());
    return solveVelocityForm(sys, opt);
  }
  switch (opt.system) {
    case SystemKind::UnifiedStokes:
    case SystemKind::PressureProjection: {
      const PressureStressSystem<Dim> sys(prob, opt.system == SystemKind::UnifiedStokes, tiles.get());
      StepReport rep = detail::solveSystem(prob, sys, opt, u.data(), solution, tiles.get(), guess);
      rep.unknowns += tiles ? tiles->resolvedDofs() : 0;
      return finish(rep, sys, tiles ? sys.reducedVelocities().data() : nullptr);
    }
    case SystemKind::Viscosity: {
      const ViscositySystem<Dim> sys(prob, tiles.get());
      return solveVelocityForm(sys, opt);
    }
    case SystemKind::DecoupledStokes: break;  // solveStep splits it into two systems
  }
  throw std::invalid_argument("solveOneSystem: the decoupled step is two solves (solveStep)");
}
}  // namespace detail

template <int Dim>
StepReport solveStep(const StaggeredProblem<Dim>& prob, const StepOptions& opt, Vector& u, Vector* solution,
                     const Vector* guess) {
  prob.validate();
  const detail::SolveThreads threads(opt.backend == Backend::InHouse ? opt.threads : 0);
  if (opt.system == SystemKind::DecoupledStokes) {
    // viscosity (tiles of the requested family), then a projection (divergence-free tiles)
    StepOptions part = opt;
    part.system = SystemKind::Viscosity;
    StaggeredProblem<Dim> projected = prob;
    StepReport total = solveStep(prob, part, projected.uStar);
    if (total.solve.status == Status::NonFinite || total.solve.status == Status::Interrupted) return total;
    part.system = SystemKind::PressureProjection;
    if (part.reduced) part.reduced->family = BasisFamily::DivergenceFree;
    detail::accumulate(total, solveStep(projected, part, u, solution, guess));
    return total;
  }
  // a method left open is the form's (solve_plan.h)
  StepOptions resolved = opt;
  resolved.method =
      methodFor(opt.system == SystemKind::UnifiedStokes ? opt.form : StokesForm::PressureStress, opt.method,
                opt.preconditioner);
  Vector out, x;
  StepReport rep = detail::solveOneSystem(prob, resolved, out, solution ? &x : nullptr, guess);
  detail::checkFiniteVelocities(prob, out, rep);
  rep.diagnostics = detail::stepSummary(opt, rep) + (rep.diagnostics.empty() ? "" : "; " + rep.diagnostics);
  if (rep.solve.status == Status::NonFinite) return rep;
  u = std::move(out);
  if (solution) *solution = std::move(x);
  return rep;
}

}  // namespace step
}  // namespace stokes::solver
