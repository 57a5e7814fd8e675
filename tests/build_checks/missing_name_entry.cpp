// A name table (solver/step/names.h) that misses an enumerator must not build: every table in
// the project sits next to `static_assert(listsEveryValueInOrder(table, LastValue))`, as this
// one does. tests/CMakeLists.txt builds this file as written (it must compile) and with
// STOKES_BUILD_CHECK_BREAK, where the table lacks its last entry (it must fail at the assert).
#include "solver/step/names.h"

namespace stokes::solver {

enum class Smoother { Jacobi, Chebyshev, GaussSeidel };

inline constexpr NamedValue<Smoother> kSmootherNames[] = {
    {Smoother::Jacobi, "jacobi", "Jacobi"},
    {Smoother::Chebyshev, "chebyshev", "Chebyshev"},
#ifndef STOKES_BUILD_CHECK_BREAK
    {Smoother::GaussSeidel, "gauss-seidel", "Gauss-Seidel"},
#endif
};
static_assert(listsEveryValueInOrder(kSmootherNames, Smoother::GaussSeidel));

}  // namespace stokes::solver
