#pragma once
// One-call entry point of a step's linear solve: solveStep builds the system the options ask for on
// a StaggeredProblem, solves it with the planned Krylov method and preconditioner (solve_plan.h)
// and writes the new face velocities. Its definitions (stokes_step_impl.h) are compiled once, for
// Dim = 2 and 3, into the stokes_systems library (stokes_step_2d.cpp, stokes_step_3d.cpp); callers
// compile against these declarations. The building blocks (PressureStressSystem,
// ViscositySystem, conjugateGradient, minres) stay usable on their own.
#include <stdexcept>

#include "solver/problem/staggered_problem.h"
#include "sparse_grid/stagger.h"
#include "solver/step/step_options.h"

namespace stokes::solver {
inline namespace step {

/// Which Cartesian unknowns a system has, for coupling tiles into it.
inline CouplingKinds couplingKinds(SystemKind k) {
  switch (k) {
    case SystemKind::UnifiedStokes: return {true, true, true};
    case SystemKind::Viscosity: return {false, true, true};
    case SystemKind::PressureProjection: return {true, false, false};
    case SystemKind::DecoupledStokes: break;  // two systems: each solve asks for its own
  }
  throw std::invalid_argument("couplingKinds: the decoupled step couples its tiles per solve");
}

/// Values per slot of solveStep's `solution` (and of its `guess`) for the systems that carry a
/// warm start from step to step: the pressure-stress form [p | tau], the pressure-velocity form
/// [u | p | l] (l the rigid multipliers on their stress samples, 0 elsewhere), the projection [p].
/// The counts differ, so a guess of another form or system is told apart by its size.
template <int Dim>
constexpr std::size_t solutionChannels(SystemKind k, StokesForm form) {
  constexpr std::size_t stress = sparse_grid::StressChannels<Dim>::kCount;
  if (k == SystemKind::UnifiedStokes) return form == StokesForm::PressureVelocity ? Dim + 1 + stress : 1 + stress;
  return 1;
}

/// Solves one step of `opt.system` on `prob` and writes the face velocities into `u`
/// (Dim * numSlots values). `solution`, if given, receives the system's unknowns (for
/// PressureStressSystem [p | tau], for viscosity the face velocities then the tile DOFs, for the
/// pressure-velocity form [u | p | l] per slot, l the rigid multipliers on their stress samples).
/// A non-finite u* or solid velocity throws std::invalid_argument naming its face and cell before
/// anything is written. A step that ends NonFinite (or with a non-finite velocity) writes neither
/// `u` nor `solution`; report.diagnostics names the first non-finite row (cell or tile).
/// `guess`, if given, is the Krylov initial guess in the layout of `solution` (a warm start, e.g.
/// the previous time step's pressure and stresses); its values on inactive rows are ignored. The
/// pressure-velocity form fits its tiles' DOFs to the guess' u (DecoupledStokes takes one for its
/// projection). The tolerance stays relative to ||b||, so
/// a good guess saves iterations.
template <int Dim>
StepReport solveStep(const StaggeredProblem<Dim>& prob, const StepOptions& opt, Vector& u,
                     Vector* solution = nullptr, const Vector* guess = nullptr);

extern template StepReport solveStep<2>(const StaggeredProblem<2>&, const StepOptions&, Vector&, Vector*,
                                        const Vector*);
extern template StepReport solveStep<3>(const StaggeredProblem<3>&, const StepOptions&, Vector&, Vector*,
                                        const Vector*);

}  // namespace step
}  // namespace stokes::solver
