#pragma once
// One-call entry point: build the chosen system on a StaggeredProblem, solve it with the chosen
// Krylov method and preconditioner, and write the new face velocities. The building blocks
// (PressureStressSystem, ViscositySystem, conjugateGradient, bicgstab) stay usable on their own.
#include <chrono>
#include <stdexcept>
#include <string>

#include "solver/krylov.h"
#include "solver/operator.h"
#include "solver/pressure_stress_system.h"
#include "solver/viscosity_system.h"

namespace stokes::solver {

enum class SystemKind {
  UnifiedStokes,       ///< pressure + viscosity in one SPD pressure-stress solve (thesis 3.6)
  Viscosity,           ///< decoupled viscosity only (Batty & Bridson 2008; thesis Eq. 3.20)
  PressureProjection,  ///< inviscid pressure projection only (thesis Eq. 3.21-3.22)
  DecoupledStokes,     ///< viscosity, then a pressure projection (thesis 3.5)
};
enum class KrylovMethod { CG, BiCGSTAB };
enum class PreconditionerKind { None, Jacobi };

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
};

/// What one solve did. For DecoupledStokes the two solves' iterations are added and the status is
/// the worse of the two.
struct StepReport {
  SolveResult solve;
  std::size_t unknowns = 0;  ///< rows with a non-zero diagonal, summed over the solves
  double setupSeconds = 0.0;
  double solveSeconds = 0.0;
};

namespace detail {
inline double secondsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

/// Solves `sys` (any system with size/apply/rhs/diagonal/nullSpace/velocities) and writes u.
template <class System>
StepReport solveSystem(const System& sys, const StepOptions& opt, double* u, Vector* solution) {
  StepReport rep;
  rep.unknowns = sys.activeUnknowns();
  Vector x(sys.size(), 0.0);
  SolveOptions kopt = opt.krylov;
  kopt.nullSpace = sys.nullSpace();
  const auto t0 = std::chrono::steady_clock::now();
  auto run = [&](const auto& precond) {
    return opt.method == KrylovMethod::CG ? conjugateGradient(sys, sys.rhs().data(), x.data(), precond, kopt)
                                          : bicgstab(sys, sys.rhs().data(), x.data(), precond, kopt);
  };
  if (opt.preconditioner == PreconditionerKind::Jacobi) rep.solve = run(JacobiPreconditioner(sys.diagonal()));
  else rep.solve = run(IdentityPreconditioner{sys.size()});
  rep.solveSeconds = secondsSince(t0);
  sys.velocities(x.data(), u);
  if (solution) *solution = std::move(x);
  return rep;
}

inline void accumulate(StepReport& total, const StepReport& part) {
  total.solve.iterations += part.solve.iterations;
  total.solve.finalResidual = std::max(total.solve.finalResidual, part.solve.finalResidual);
  total.solve.relativeResidual = std::max(total.solve.relativeResidual, part.solve.relativeResidual);
  if (!part.solve.converged()) total.solve.status = part.solve.status;
  total.unknowns += part.unknowns;
  total.setupSeconds += part.setupSeconds;
  total.solveSeconds += part.solveSeconds;
}
}  // namespace detail

/// Solves one step of `opt.system` on `prob` and writes the face velocities into `u`
/// (Dim * numSlots values). `solution`, if given, receives the system's unknowns (for
/// PressureStressSystem [p | tau], for viscosity the face velocities).
template <int Dim>
StepReport solveStep(const StaggeredProblem<Dim>& prob, const StepOptions& opt, Vector& u,
                     Vector* solution = nullptr) {
  u.assign(Dim * prob.slots(), 0.0);
  const auto t0 = std::chrono::steady_clock::now();
  switch (opt.system) {
    case SystemKind::UnifiedStokes:
    case SystemKind::PressureProjection: {
      const PressureStressSystem<Dim> sys(prob, opt.system == SystemKind::UnifiedStokes);
      const double setup = detail::secondsSince(t0);
      StepReport rep = detail::solveSystem(sys, opt, u.data(), solution);
      rep.setupSeconds = setup;
      return rep;
    }
    case SystemKind::Viscosity: {
      const ViscositySystem<Dim> sys(prob);
      const double setup = detail::secondsSince(t0);
      StepReport rep = detail::solveSystem(sys, opt, u.data(), solution);
      rep.setupSeconds = setup;
      return rep;
    }
    case SystemKind::DecoupledStokes: {
      StepOptions part = opt;
      part.system = SystemKind::Viscosity;
      StepReport total = solveStep(prob, part, u);
      StaggeredProblem<Dim> projected = prob;
      projected.uStar = u;
      part.system = SystemKind::PressureProjection;
      detail::accumulate(total, solveStep(projected, part, u, solution));
      return total;
    }
  }
  throw std::invalid_argument("solveStep: unknown system kind");
}

}  // namespace stokes::solver
