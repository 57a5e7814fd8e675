#pragma once
// Manual wall-clock timing shared by the Google Benchmark programs: a thread count scoped to one
// benchmark run, and the mean seconds per call of an operation timed call by call.
#include <benchmark/benchmark.h>
#include <omp.h>

#include <chrono>

#include "solver/krylov/stopwatch.h"

namespace stokes::bench {

/// Sets the OpenMP thread count for one benchmark run and restores it afterwards.
class ThreadScope {
 public:
  explicit ThreadScope(int threads) : previous_(omp_get_max_threads()) { omp_set_num_threads(threads); }
  ~ThreadScope() { omp_set_num_threads(previous_); }
  ThreadScope(const ThreadScope&) = delete;
  ThreadScope& operator=(const ThreadScope&) = delete;

 private:
  int previous_;
};

/// Runs `apply` once untimed (warm-up), then once per benchmark iteration, timing each call with
/// the wall clock (manual time). Returns the mean seconds per call.
template <class Apply>
double timeApplies(benchmark::State& state, Apply&& apply) {
  apply();
  double total = 0.0;
  for (auto _ : state) {
    const auto t0 = std::chrono::steady_clock::now();
    apply();
    const double s = solver::secondsSince(t0);
    state.SetIterationTime(s);
    total += s;
  }
  return state.iterations() > 0 ? total / double(state.iterations()) : 0.0;
}

}  // namespace stokes::bench
