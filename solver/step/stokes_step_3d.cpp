// solveStep for Dim = 3, compiled once into the stokes_systems library (stokes_step.h).
#include "solver/step/stokes_step_impl.h"

namespace stokes::solver {
inline namespace step {

template StepReport solveStep<3>(const StaggeredProblem<3>&, const StepOptions&, Vector&, Vector*, const Vector*);

}  // namespace step
}  // namespace stokes::solver
