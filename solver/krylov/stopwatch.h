#pragma once
// Wall time for the reports (set-up, solve, stage seconds).
#include <chrono>

namespace stokes::solver {
inline namespace krylov {

/// Seconds of std::chrono::steady_clock since t0.
inline double secondsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace krylov
}  // namespace stokes::solver
