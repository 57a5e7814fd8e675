#pragma once
// What a thread-determinism test needs to know that it compared the parallel path with the serial
// one: below the fork thresholds (parallel/fork_policy.h) every loop runs on one thread whatever the
// thread count, so a small test problem would compare the serial path with itself. ForkTestSizes
// lowers both thresholds to test sizes (the arithmetic does not depend on them), and TeamCount
// reads how many regions of each kind ran on more than one thread meanwhile.
#include <omp.h>

#include <array>
#include <cstdint>
#include <type_traits>

#include "parallel/fork_policy.h"

namespace stokes::test {

/// The parallel regions (of each kind) that ran on more than one thread while the object lived.
class TeamCount {
 public:
  TeamCount() {
    for (int k = 0; k < parallel::kRegionKinds; ++k) start_[std::size_t(k)] = parallel::teamsRun(parallel::Region(k));
  }
  std::uint64_t operator()(parallel::Region kind) const { return parallel::teamsRun(kind) - start_[std::size_t(kind)]; }

 private:
  std::array<std::uint64_t, parallel::kRegionKinds> start_{};
};

/// While the object lives, a vector loop forks from 8,192 entries (a reduction of two chunks of
/// solver/krylov/vector_ops.h, the fewest that split) and a grid loop from 512 samples (one 3D
/// block, eight 2D ones). At 0 every coarse multigrid level's loops would fork too, loops that hold
/// no reduction, and the ball n = 96 padded-cycle test took 1.8x as long.
struct ForkTestSizes : parallel::ScopedForkThresholds {
  ForkTestSizes() : parallel::ScopedForkThresholds(8192, 512) {}
};

/// Runs f() on `threads` OpenMP threads, restoring the previous setting afterwards, and returns
/// what f returns.
template <class F>
auto withThreads(int threads, F f) {
  const int previous = omp_get_max_threads();
  omp_set_num_threads(threads);
  if constexpr (std::is_void_v<decltype(f())>) {
    f();
    omp_set_num_threads(previous);
  } else {
    auto value = f();
    omp_set_num_threads(previous);
    return value;
  }
}

}  // namespace stokes::test
