// A switch over one of the project's enums that leaves an enumerator out must not build: the
// build flags make -Wswitch an error (-Werror=switch, CMakeLists.txt), and no switch over the
// project's enums has a `default:` that would hide the missing case. tests/CMakeLists.txt builds
// this file as written (it must compile) and with STOKES_BUILD_CHECK_BREAK (it must fail, naming
// the enumerator).
#include "solver/step/solve_plan.h"

namespace stokes::solver {

int costRank(PreconditionerKind kind) {
  switch (kind) {
    case PreconditionerKind::None: return 0;
    case PreconditionerKind::Jacobi: return 1;
#ifndef STOKES_BUILD_CHECK_BREAK
    case PreconditionerKind::Multigrid: return 2;
#endif
  }
  return -1;
}

}  // namespace stokes::solver
