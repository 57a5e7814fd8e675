#pragma once
// Dot products over MPI ranks whose bits do not depend on the rank count, the partition or the
// order of the terms (docs/petsc.md, "Determinism across rank counts"). A floating-point sum of
// per-rank partial sums does: its rounding follows where the ranks' parts begin.
//
// Each product p_i = a_i b_i is scaled by 2^E, where E is the largest exponent with
// max|p_i| 2^E < 2^W, W = 52 - log2(N) (N the global length, the maximum over all ranks), and cut
// into kDotLevels integers of W bits each: v = w_0 + w_1 2^-W + w_2 2^-2W + (the rest, dropped).
// The integers of one level, N of them below 2^W, add up below 2^52: exactly, in a double, in any
// order and over any ranks (an MPI_SUM of such doubles is exact). The result is
// (s_0 + s_1 2^-W + s_2 2^-2W) 2^-E, evaluated in one order. Each term keeps 3W bits below the
// largest product's scale (84 at N = 2^24), more than a floating-point sum's 53. Cost: one more
// reduction (the maximum) and two vectorised passes: 1.2-1.5 ns an entry against a plain dot's
// 0.45-0.48 (bench/bench_exact_dot.cpp, one rank). PETSc's CG + Jacobi on the ball at n = 64
// takes 1.3-1.5x as long an iteration, and ends in 4,405 iterations instead of 4,447
// (bench/results/petsc.md).
#include <mpi.h>

#include <cstddef>
#include <cstdint>

namespace stokes::solver::petsc {

/// The integer levels each term is cut into.
inline constexpr int kDotLevels = 3;

/// sum_i a_i b_i over every rank's `n` local entries (`globalLength` entries in all). A non-finite
/// product gives a non-finite result. Collective on `comm`.
double exactDot(const double* a, const double* b, std::size_t n, std::int64_t globalLength, MPI_Comm comm);

}  // namespace stokes::solver::petsc
