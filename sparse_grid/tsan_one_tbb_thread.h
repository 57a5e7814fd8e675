#pragma once
// ThreadSanitizer builds only (-DSTOKES_SANITIZE_THREAD=ON, scripts/tsan.sh): oneTBB's scheduler
// (libtbb) is not instrumented, so every hand-over between the TBB workers of OpenVDB's tools
// and their caller reads as a data race. One TBB thread runs those tools on the calling thread,
// and TSan checks the project's own parallel code (OpenMP, whose synchronisation libomp's Archer
// tool reports) without false reports. Included by block_layout.h, so that every program of the
// project holds it; an inline variable is initialised once per program.
#ifdef STOKES_THREAD_SANITIZER
#include <tbb/global_control.h>

namespace stokes::grid {
inline const tbb::global_control kOneTbbThreadUnderTsan(tbb::global_control::max_allowed_parallelism, 1);
}  // namespace stokes::grid
#endif
