// ThreadSanitizer builds only (-DSTOKES_SANITIZE_THREAD=ON, scripts/tsan.sh): compiled into every
// target of the project. oneTBB's scheduler (libtbb) is not instrumented, so every hand-over
// between the TBB workers of OpenVDB's tools and their caller reads as a data race. One TBB thread
// runs those tools on the calling thread, and TSan checks the project's own parallel code
// (OpenMP, whose synchronisation libomp's Archer tool reports) without false reports.
#include <tbb/global_control.h>

namespace {
const tbb::global_control kOneTbbThreadUnderTsan(tbb::global_control::max_allowed_parallelism, 1);
}  // namespace
