#pragma once
// When a loop forks an OpenMP team, decided in one place, and what a test can see of it.
//
// Two thresholds, measured on the 2-core machine (2 threads) under the passive wait policy that
// stokesvdb runs with, where a fork-join costs ~22 us (a barrier inside a region 11 us; 3.3 us
// spinning):
//  - vector work (solver/krylov/vector_ops.h: element-wise passes, the fixed-chunk reductions, the
//    reduced tiles' loops): a serial y += a x over 65,536 entries takes 9 us and over 262,144 entries
//    55 us (forked: 32 and 62 us), so below ~2^17 entries of work (a sparse row weighs its stored
//    entries) a split costs more than it saves: kDefaultVectorForkMinWork;
//  - grid loops (stencils, grid transfers, the systems' element-wise loops, the particle
//    transfers): below 8,192 samples a multigrid cycle's ~100 loops on its small coarse levels lose
//    more to the fork-joins than they gain (bench/results/multigrid_cycles.md):
//    kDefaultGridForkMinSamples.
// Neither changes the arithmetic: reductions sum over fixed chunks in chunk order and the other
// loops write disjoint entries (docs/design.md §5.3), so a thread count or a threshold changes
// which path runs, never the bits.
//
// Tests lower the thresholds (ScopedForkThresholds) so that their small problems take the
// parallel path, and read the team counters (teamsRun) to check that they did: every region
// that can run on several threads calls countTeam(kind) inside it, which counts the regions whose
// team had more than one thread. The thresholds and counters are process-wide atomics (relaxed:
// a test sets them between solves, never during one); a count costs one branch per thread per
// region. A region split as `omp parallel { countTeam(...); omp for nowait ... }` keeps the one
// barrier of `omp parallel for` (without nowait the loop's own barrier would come on top).
#include <omp.h>

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>

namespace stokes::parallel {

inline constexpr std::size_t kDefaultVectorForkMinWork = std::size_t(1) << 17;
inline constexpr std::size_t kDefaultGridForkMinSamples = 8192;

/// The kinds of parallel region a test can ask about.
enum class Region : int {
  Reduction,        ///< a fixed-chunk reduction split over threads (solver/krylov/vector_ops.h)
  VectorLoop,       ///< an element-wise vector or sparse-row loop (vector_ops.h: parallelFor)
  GridLoop,         ///< a stencil or grid-transfer loop over blocks
  ParticleScatter,  ///< one colour of P2G's blocks (sim/particles/apic_transfer.h)
  ParticleGather,   ///< G2P over particles
  ParticleSort,     ///< the counting sort's chunks (sparse_grid/bucket_sort.h)
  Tiles,            ///< the reduced tiles' loops (solver/reduced/reduced_tiles.cpp; the last kind)
};
inline constexpr int kRegionKinds = int(Region::Tiles) + 1;

namespace detail {
inline std::atomic<std::size_t> vectorForkMinWork{kDefaultVectorForkMinWork};
inline std::atomic<std::size_t> gridForkMinSamples{kDefaultGridForkMinSamples};
inline std::array<std::atomic<std::uint64_t>, kRegionKinds> teams{};
}  // namespace detail

/// A vector loop or reduction over `work` entries forks a team.
inline bool forkVectorWork(std::size_t work) noexcept {
  return work >= detail::vectorForkMinWork.load(std::memory_order_relaxed);
}
/// A grid loop over `samples` samples forks a team.
inline bool forkGridLoop(std::size_t samples) noexcept {
  return samples >= detail::gridForkMinSamples.load(std::memory_order_relaxed);
}

/// Called by every thread inside a parallel region of kind `kind`: counts the region once when its
/// team has more than one thread.
inline void countTeam(Region kind) noexcept {
  if (omp_get_thread_num() == 0 && omp_get_num_threads() > 1)
    detail::teams[std::size_t(kind)].fetch_add(1, std::memory_order_relaxed);
}

/// Regions of kind `kind` that ran on more than one thread since the program started.
inline std::uint64_t teamsRun(Region kind) noexcept {
  return detail::teams[std::size_t(kind)].load(std::memory_order_relaxed);
}

/// Test setting: both thresholds lowered (or raised) for the object's lifetime, then restored.
class ScopedForkThresholds {
 public:
  ScopedForkThresholds(std::size_t vectorWork, std::size_t gridSamples)
      : vector_(detail::vectorForkMinWork.exchange(vectorWork)),
        grid_(detail::gridForkMinSamples.exchange(gridSamples)) {}
  ~ScopedForkThresholds() {
    detail::vectorForkMinWork.store(vector_);
    detail::gridForkMinSamples.store(grid_);
  }
  ScopedForkThresholds(const ScopedForkThresholds&) = delete;
  ScopedForkThresholds& operator=(const ScopedForkThresholds&) = delete;

 private:
  std::size_t vector_, grid_;
};

}  // namespace stokes::parallel
