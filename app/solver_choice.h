#pragma once
// The solver an analytic case gets when none is asked for: the fastest one measured
// (bench/results/reduced_multigrid.md, preconditioners.md). Shared by `stokesvdb analytic ...`
// (--precond auto, --form auto) and `stokesvdb study accuracy-time`.
#include <string>

#include "solver/stokes_step.h"

namespace stokes::app {

struct SolverChoice {
  std::string form;  ///< spd (pressure-stress, CG) | pv (pressure-velocity, MINRES)
  solver::PreconditionerKind preconditioner = solver::PreconditionerKind::Jacobi;
};

/// The form a preconditioner runs on: block multigrid on the pressure-velocity form (MINRES) for
/// the unified solve, the SPD pressure-stress form (CG) otherwise.
inline std::string formFor(solver::PreconditionerKind preconditioner, solver::SystemKind system) {
  return preconditioner == solver::PreconditionerKind::Multigrid && system == solver::SystemKind::UnifiedStokes ? "pv"
                                                                                                               : "spd";
}

/// Multigrid, except where reduced tiles sit beside the cycle as Jacobi rows (a viscosity-only
/// test, decoupled viscosity and projection): there Jacobi (box-viscosity quadratic N = 64: 107
/// against 147 iterations, at several times the cost of an iteration). The unified solve under
/// multigrid runs on the pressure-velocity form (block-multigrid MINRES, 3-8x faster than Jacobi
/// CG on the SPD form); everything else on the SPD form.
inline SolverChoice strongestSolver(const std::string& model, bool viscosityTest, solver::SystemKind system) {
  const bool tilesBesideCycle = model != "uniform" && (viscosityTest || system != solver::SystemKind::UnifiedStokes);
  SolverChoice c;
  c.preconditioner = tilesBesideCycle ? solver::PreconditionerKind::Jacobi : solver::PreconditionerKind::Multigrid;
  c.form = formFor(c.preconditioner, system);
  return c;
}

}  // namespace stokes::app
