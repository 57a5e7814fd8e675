#pragma once
// Bit-identity of a solve for 1 and 2 OpenMP threads (the reductions of solver/krylov/vector_ops.h
// have a fixed order, so every solve must reproduce itself exactly whatever the thread count).
//
// Loops of test size fork for the comparison, and the team counters show that the 2-thread run
// split its reductions and grid loops over threads (tests/parallel_path.h).
#include <gtest/gtest.h>
#include <omp.h>

#include <cstring>
#include <utility>

#include "solver/step/stokes_step.h"
#include "tests/parallel_path.h"

namespace stokes::test {

/// Solves one step with 1, then 2 threads, loops of test size forking, expects the same iteration count,
/// bit-identical face velocities, and reductions and grid loops split over the 2 threads of the
/// second run, and returns both reports for further checks.
template <int Dim>
std::pair<solver::StepReport, solver::StepReport> expectStepBitIdenticalForOneAndTwoThreads(
    const solver::StaggeredProblem<Dim>& prob, const solver::StepOptions& opt) {
  const ForkTestSizes forkTestSizes;
  solver::Vector u1, u2;
  solver::StepReport r1 = withThreads(1, [&] { return solver::solveStep(prob, opt, u1); });
  const TeamCount split;
  solver::StepReport r2 = withThreads(2, [&] { return solver::solveStep(prob, opt, u2); });
  // the 2-thread run took the parallel path, on at least three reduction chunks: one chunk does
  // not split, and two partial sums add up to the same bits in either order, so a problem of
  // 8,192 Krylov rows or fewer cannot tell a thread-dependent summation order
  EXPECT_GT(r1.krylovRows, 2 * solver::kReductionChunk) << "too few rows to test the summation order";
  EXPECT_GT(split(parallel::Region::Reduction), 0u) << "no reduction was split over threads";
  EXPECT_GT(split(parallel::Region::GridLoop), 0u) << "no stencil loop ran on two threads";
  EXPECT_EQ(r1.solve.iterations, r2.solve.iterations);
  EXPECT_EQ(u1.size(), u2.size());
  if (u1.size() == u2.size()) {
    EXPECT_EQ(0, std::memcmp(u1.data(), u2.data(), u1.size() * sizeof(double)));
  }
  return {std::move(r1), std::move(r2)};
}

}  // namespace stokes::test
