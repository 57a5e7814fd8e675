#pragma once
// Sums and maxima of a problem distributed by blocks (StaggeredProblem::blockOwner): each rank
// reduces over the samples it owns (StaggeredProblem::ownsSlot), then these combine the ranks'
// parts. A whole problem's value is returned as it is, so callers write one loop for both.
#include "solver/problem/staggered_problem.h"
#ifdef STOKES_HAVE_PETSC
#include "solver/petsc/petsc_krylov.h"
#endif

namespace stokes::solver {
inline namespace step {

template <int Dim>
double sumOverParts(const StaggeredProblem<Dim>& prob, double part) {
#ifdef STOKES_HAVE_PETSC
  if (prob.isDistributed()) return petsc::sumOverRanks(part);
#endif
  (void)prob;
  return part;
}

template <int Dim>
double maxOverParts(const StaggeredProblem<Dim>& prob, double part) {
#ifdef STOKES_HAVE_PETSC
  if (prob.isDistributed()) return petsc::maxOverRanks(part);
#endif
  (void)prob;
  return part;
}

}  // namespace step
}  // namespace stokes::solver
