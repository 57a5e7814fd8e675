#pragma once
// The one place where a step's preconditioner is made and its Krylov method run with it. Adding a
// preconditioner: an enumerator and its names in solve_plan.h, its rule in planSolve if it is to be
// chosen automatically, and a case in solvePreconditioned below (-Wswitch names a missing one).
#include <chrono>
#include <stdexcept>

#include "solver/krylov/gmres.h"
#include "solver/krylov/krylov.h"
#include "solver/krylov/minres.h"
#include "solver/krylov/stopwatch.h"
#include "solver/multigrid/multigrid_preconditioners.h"
#include "solver/step/step_options.h"

namespace stokes::solver {
inline namespace step {

template <LinearOperator Op, Preconditioner Pre>
SolveResult runKrylov(KrylovMethod method, const Op& A, const double* b, double* x, const Pre& M,
                      const SolveOptions& opt) {
  switch (method) {
    case KrylovMethod::CG: return conjugateGradient(A, b, x, M, opt);
    case KrylovMethod::BiCGSTAB: return bicgstab(A, b, x, M, opt);
    case KrylovMethod::MINRES: return minres(A, b, x, M, opt);
    case KrylovMethod::GMRES: return gmres(A, b, x, M, opt);
    case KrylovMethod::FGMRES: return fgmres(A, b, x, M, opt);
  }
  throw std::invalid_argument("runKrylov: not a Krylov method");
}

/// Solves A x = b with opt.method (resolved) and opt.preconditioner: `jacobi()` makes the diagonal
/// preconditioner of A's rows, `multigrid()` the padded cycle and `wrap(cycle)` adapts it to A's
/// rows. Fills the report's solve fields.
template <class Op, class MakeJacobi, class MakeMultigrid, class Wrap>
void solvePreconditioned(const StepOptions& opt, const Op& A, const double* b, double* x, const SolveOptions& kopt,
                         const MakeJacobi& jacobi, const MakeMultigrid& multigrid, const Wrap& wrap,
                         StepReport& rep) {
  const KrylovMethod method = opt.method.value();  // resolved by solveStep (methodFor)
  switch (opt.preconditioner) {
    case PreconditionerKind::None:
      rep.solve = runKrylov(method, A, b, x, IdentityPreconditioner{A.size()}, kopt);
      return;
    case PreconditionerKind::Jacobi:
      rep.solve = runKrylov(method, A, b, x, jacobi(), kopt);
      return;
    case PreconditionerKind::Multigrid: {
      const auto tm = std::chrono::steady_clock::now();
      const BlockMultigridPreconditioner mg = multigrid();
      rep.preconditionerSeconds = secondsSince(tm);
      rep.multigridLevels = mg.levels();
      if (kopt.stopRequested && kopt.stopRequested()) {  // asked during the set-up: before any iteration
        rep.solve.status = Status::Interrupted;
        return;
      }
      rep.solve = runKrylov(method, A, b, x, wrap(mg), kopt);
      return;
    }
  }
  throw std::invalid_argument("solvePreconditioned: not a preconditioner");
}

}  // namespace step
}  // namespace stokes::solver
