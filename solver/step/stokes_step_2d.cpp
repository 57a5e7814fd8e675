// solveStep for Dim = 2, compiled once into the stokes_systems library (stokes_step.h).
#include "solver/step/stokes_step_impl.h"

namespace stokes::solver {
inline namespace step {

template StepReport solveStep<2>(const StaggeredProblem<2>&, const StepOptions&, Vector&, Vector*, const Vector*);

}  // namespace step
}  // namespace stokes::solver
