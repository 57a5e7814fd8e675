#pragma once
// Bit-identity of a solve for 1 and 2 OpenMP threads (the reductions of solver/krylov/vector_ops.h
// have a fixed order, so every solve must reproduce itself exactly whatever the thread count).
#include <gtest/gtest.h>
#include <omp.h>

#include <cstring>
#include <utility>

#include "solver/step/stokes_step.h"

namespace stokes::test {

/// Solves one step with 1, then 2 threads, expects the same iteration count and bit-identical face
/// velocities, and returns both reports for further checks.
template <int Dim>
std::pair<solver::StepReport, solver::StepReport> expectStepBitIdenticalForOneAndTwoThreads(
    const solver::StaggeredProblem<Dim>& prob, const solver::StepOptions& opt) {
  solver::Vector u1, u2;
  const int saved = omp_get_max_threads();
  omp_set_num_threads(1);
  solver::StepReport r1 = solver::solveStep(prob, opt, u1);
  omp_set_num_threads(2);
  solver::StepReport r2 = solver::solveStep(prob, opt, u2);
  omp_set_num_threads(saved);
  EXPECT_EQ(r1.solve.iterations, r2.solve.iterations);
  EXPECT_EQ(u1.size(), u2.size());
  if (u1.size() == u2.size()) {
    EXPECT_EQ(0, std::memcmp(u1.data(), u2.data(), u1.size() * sizeof(double)));
  }
  return {std::move(r1), std::move(r2)};
}

}  // namespace stokes::test
