#pragma once
// One-call entry point: build the chosen system on a StaggeredProblem, solve it with the chosen
// Krylov method and preconditioner, and write the new face velocities. The building blocks
// (PressureStressSystem, ViscositySystem, conjugateGradient, bicgstab) stay usable on their own.
#include <chrono>
#include <cmath>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>

#include "solver/krylov.h"
#include "solver/minres.h"
#include "solver/multigrid_preconditioners.h"
#include "solver/operator.h"
#include "solver/pressure_stress_system.h"
#include "solver/pressure_velocity_system.h"
#include "solver/viscosity_system.h"

namespace stokes::solver {

enum class SystemKind {
  UnifiedStokes,       ///< pressure + viscosity in one SPD pressure-stress solve (thesis 3.6)
  Viscosity,           ///< decoupled viscosity only (Batty & Bridson 2008; thesis Eq. 3.20)
  PressureProjection,  ///< inviscid pressure projection only (thesis Eq. 3.21-3.22)
  DecoupledStokes,     ///< viscosity, then a pressure projection (thesis 3.5)
};
enum class KrylovMethod { CG, BiCGSTAB, MINRES };
/// Which algebraic form unified Stokes is solved in.
enum class StokesForm {
  PressureStress,    ///< SPD, stresses kept, velocities eliminated (Eq. 4.20-4.25): CG
  PressureVelocity,  ///< symmetric indefinite, stresses eliminated (Eq. 4.19): BiCGSTAB
};
/// None: plain Krylov; Jacobi: the diagonal; Multigrid: the V-cycle preconditioners of
/// solver/multigrid_preconditioners.h (one per system and form).
enum class PreconditionerKind { None, Jacobi, Multigrid };

inline const char* toString(SystemKind k) {
  switch (k) {
    case SystemKind::UnifiedStokes: return "unified-stokes";
    case SystemKind::Viscosity: return "viscosity";
    case SystemKind::PressureProjection: return "pressure";
    case SystemKind::DecoupledStokes: return "decoupled";
  }
  return "?";
}

struct StepOptions {
  SystemKind system = SystemKind::UnifiedStokes;
  KrylovMethod method = KrylovMethod::CG;
  PreconditionerKind preconditioner = PreconditionerKind::Jacobi;
  SolveOptions krylov{};
  StokesForm form = StokesForm::PressureStress;  ///< unified Stokes only
  /// Reduced polynomial tiles (affine / quadratic model); empty: the uniform model.
  std::optional<ReducedOptions> reduced{};
};

/// What one solve did. For DecoupledStokes the two solves' iterations are added and the status is
/// the worse of the two.
struct StepReport {
  SolveResult solve;
  std::size_t unknowns = 0;  ///< rows with a non-zero diagonal, summed over the solves
  double setupSeconds = 0.0;  ///< system set-up, tiles included
  double tileSeconds = 0.0;   ///< of which: tiling, fits and factorisations of the tiles
  double solveSeconds = 0.0;
  double preconditionerSeconds = 0.0;  ///< of solveSeconds: building the multigrid hierarchy
  std::size_t multigridLevels = 0;
  std::size_t tiles = 0, reducedDofs = 0, cartesianDofs = 0;
  std::size_t fallbackTiles = 0;    ///< tiles returned to Cartesian (singular fit / B not SPD)
  std::size_t cacheHits = 0, cacheMisses = 0;  ///< tile library look-ups
  double reconstructionLinf = 0.0;  ///< max |C v* - u*| over tile faces
  double kineticEnergy = 0.0;       ///< sum of 1/2 rho W_m u^2 dV over Cartesian faces + tiles' 1/2 v^T M_R v dV
};

namespace detail {
inline double secondsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

/// Solves `sys` (any system with size/apply/rhs/diagonal/nullSpace/velocities) and writes u.
template <int Dim, class System>
StepReport solveSystem(const StaggeredProblem<Dim>& prob, const System& sys, const StepOptions& opt, double* u,
                       Vector* solution) {
  StepReport rep;
  rep.unknowns = sys.activeUnknowns();
  Vector x(sys.size(), 0.0);
  SolveOptions kopt = opt.krylov;
  kopt.nullSpace = sys.nullSpace();
  const auto t0 = std::chrono::steady_clock::now();
  auto run = [&](const auto& precond) {
    switch (opt.method) {
      case KrylovMethod::CG: return conjugateGradient(sys, sys.rhs().data(), x.data(), precond, kopt);
      case KrylovMethod::BiCGSTAB: return bicgstab(sys, sys.rhs().data(), x.data(), precond, kopt);
      default: return minres(sys, sys.rhs().data(), x.data(), precond, kopt);
    }
  };
  switch (opt.preconditioner) {
    case PreconditionerKind::Jacobi: rep.solve = run(JacobiPreconditioner(sys.diagonal())); break;
    case PreconditionerKind::Multigrid: {
      const auto tm = std::chrono::steady_clock::now();
      const BlockMultigridPreconditioner mg = makeMultigridPreconditioner(prob, sys);
      rep.preconditionerSeconds = secondsSince(tm);
      rep.multigridLevels = mg.levels();
      rep.solve = run(mg);
      break;
    }
    default: rep.solve = run(IdentityPreconditioner{sys.size()});
  }
  rep.solveSeconds = secondsSince(t0);
  sys.velocities(x.data(), u);
  if (solution) *solution = std::move(x);
  return rep;
}

/// Kinetic energy after the step: Cartesian faces with their mass weights, tiles through M_R.
template <int Dim, class System>
double stepKineticEnergy(const StaggeredProblem<Dim>& prob, const System& sys, const Vector& u,
                         const ReducedTiles<Dim>* tiles, const double* tileVelocities) {
  const double dV = std::pow(prob.layout->dx(), Dim);
  const auto& state = sys.faceStates();
  double e = 0.0;
  for (std::size_t i = 0; i < state.size(); ++i)
    if (state[i] == FaceState::Unknown) e += 0.5 * prob.rho * prob.fluidFaceWeight(i) * faceMassWeight(prob, i) * u[i] * u[i] * dV;
  if (tiles && tileVelocities) e += tiles->kineticEnergy(tileVelocities);
  return e;
}

inline void accumulate(StepReport& total, const StepReport& part) {
  total.solve.iterations += part.solve.iterations;
  total.solve.finalResidual = std::max(total.solve.finalResidual, part.solve.finalResidual);
  total.solve.relativeResidual = std::max(total.solve.relativeResidual, part.solve.relativeResidual);
  if (!part.solve.converged()) total.solve.status = part.solve.status;
  total.unknowns += part.unknowns;
  total.tiles += part.tiles;
  total.fallbackTiles += part.fallbackTiles;
  total.cacheHits += part.cacheHits;
  total.cacheMisses += part.cacheMisses;
  total.reducedDofs += part.reducedDofs;
  total.cartesianDofs += part.cartesianDofs;
  total.reconstructionLinf = std::max(total.reconstructionLinf, part.reconstructionLinf);
  total.kineticEnergy = part.kineticEnergy;
  total.tileSeconds += part.tileSeconds;
  total.setupSeconds += part.setupSeconds;
  total.solveSeconds += part.solveSeconds;
  total.preconditionerSeconds += part.preconditionerSeconds;
  total.multigridLevels = std::max(total.multigridLevels, part.multigridLevels);
}
}  // namespace detail

/// Solves one step of `opt.system` on `prob` and writes the face velocities into `u`
/// (Dim * numSlots values). `solution`, if given, receives the system's unknowns (for
/// PressureStressSystem [p | tau], for viscosity the face velocities).
/// Which Cartesian unknowns a system has, for coupling tiles into it.
inline CouplingKinds couplingKinds(SystemKind k) {
  switch (k) {
    case SystemKind::UnifiedStokes: return {true, true, true};
    case SystemKind::Viscosity: return {false, true, true};
    default: return {true, false, false};
  }
}

/// Solves one step of `opt.system` on `prob` and writes the face velocities into `u`
/// (Dim * numSlots values). `solution`, if given, receives the system's unknowns (for
/// PressureStressSystem [p | tau], for viscosity the face velocities then the tile DOFs).
template <int Dim>
StepReport solveStep(const StaggeredProblem<Dim>& prob, const StepOptions& opt, Vector& u,
                     Vector* solution = nullptr) {
  u.assign(Dim * prob.slots(), 0.0);
  if (opt.system == SystemKind::DecoupledStokes) {
    // viscosity (tiles of the requested family), then a projection (divergence-free tiles)
    StepOptions part = opt;
    part.system = SystemKind::Viscosity;
    StepReport total = solveStep(prob, part, u);
    StaggeredProblem<Dim> projected = prob;
    projected.uStar = u;
    part.system = SystemKind::PressureProjection;
    if (part.reduced) part.reduced->family = BasisFamily::DivergenceFree;
    detail::accumulate(total, solveStep(projected, part, u, solution));
    return total;
  }
  const auto t0 = std::chrono::steady_clock::now();
  std::unique_ptr<ReducedTiles<Dim>> tiles;
  if (opt.reduced) tiles = std::make_unique<ReducedTiles<Dim>>(prob, *opt.reduced, couplingKinds(opt.system));
  const double tileSeconds = detail::secondsSince(t0);
  auto finish = [&](StepReport rep, const auto& sys, const double* tileVelocities) {
    rep.setupSeconds = detail::secondsSince(t0) - rep.solveSeconds;
    rep.tileSeconds = tileSeconds;
    if (tiles) {
      rep.tiles = tiles->numTiles();
      rep.reducedDofs = tiles->totalDofs();
      rep.reconstructionLinf = tiles->reconstructionLinf();
      rep.fallbackTiles = tiles->fallbacks().size();
      rep.cacheHits = tiles->cacheHits();
      rep.cacheMisses = tiles->cacheMisses();
    }
    rep.cartesianDofs = rep.unknowns - rep.reducedDofs;
    rep.kineticEnergy = detail::stepKineticEnergy(prob, sys, u, tiles.get(), tileVelocities);
    return rep;
  };
  // Velocity forms keep x = [u_C | v_R | ...]: the tiles' generalised velocities follow the faces.
  auto solveVelocityForm = [&](const auto& sys, const StepOptions& o) {
    Vector x;
    StepReport rep = detail::solveSystem(prob, sys, o, u.data(), &x);
    rep = finish(rep, sys, tiles ? x.data() + Dim * prob.slots() : nullptr);
    if (solution) *solution = std::move(x);
    return rep;
  };
  if (opt.system == SystemKind::UnifiedStokes && opt.form == StokesForm::PressureVelocity) {
    const PressureVelocitySystem<Dim> sys(prob, tiles.get());
    StepOptions pv = opt;
    // The system is symmetric indefinite: CG does not apply. BiCGSTAB is the thesis' choice;
    // MINRES is the default here because BiCGSTAB stagnates on the reduced saddle point.
    if (pv.method == KrylovMethod::CG) pv.method = KrylovMethod::MINRES;
    return solveVelocityForm(sys, pv);
  }
  switch (opt.system) {
    case SystemKind::UnifiedStokes:
    case SystemKind::PressureProjection: {
      const PressureStressSystem<Dim> sys(prob, opt.system == SystemKind::UnifiedStokes, tiles.get());
      StepReport rep = detail::solveSystem(prob, sys, opt, u.data(), solution);
      rep.unknowns += tiles ? tiles->totalDofs() : 0;
      return finish(rep, sys, tiles ? sys.reducedVelocities().data() : nullptr);
    }
    case SystemKind::Viscosity: {
      const ViscositySystem<Dim> sys(prob, tiles.get());
      return solveVelocityForm(sys, opt);
    }
    default: break;
  }
  throw std::invalid_argument("solveStep: unknown system kind");
}

}  // namespace stokes::solver
