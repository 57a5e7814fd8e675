// Rank-count-free dot products: see exact_dot.h.
#include "solver/petsc/exact_dot.h"

#include <algorithm>
#include <cmath>

namespace stokes::solver::petsc {

namespace {

static_assert(kDotLevels == 3, "cutAndSum writes three levels");

/// The three levels' integer sums of v_i = a_i b_i s1 s2 (sum[k] += w_k, see exact_dot.h). The
/// sums are exact whatever their order, so the vectorised reduction (reassociated) changes no bit.
void cutAndSum(const double* a, const double* b, std::size_t n, double s1, double s2, double level, double* sum) {
  double l0 = 0.0, l1 = 0.0, l2 = 0.0;
#pragma omp simd reduction(+ : l0, l1, l2)
  for (std::size_t i = 0; i < n; ++i) {
    double v = (a[i] * b[i]) * s1 * s2;
    const double w0 = __builtin_trunc(v);
    l0 += w0;
    v = (v - w0) * level;  // |v - w0| < 1: an exact difference, exactly scaled
    const double w1 = __builtin_trunc(v);
    l1 += w1;
    l2 += __builtin_trunc((v - w1) * level);
  }
  sum[0] = l0;
  sum[1] = l1;
  sum[2] = l2;
}

/// max |a_i b_i|, or a non-finite value where a product is not finite.
double largestProduct(const double* a, const double* b, std::size_t n) {
  double largest = 0.0, finite = 0.0;  // finite: 0, or NaN once a product is NaN or infinite
#pragma omp simd reduction(max : largest) reduction(+ : finite)
  for (std::size_t i = 0; i < n; ++i) {
    const double p = std::abs(a[i] * b[i]);
    largest = p > largest ? p : largest;
    finite += p * 0.0;
  }
  return largest + finite;
}

}  // namespace

double exactDot(const double* a, const double* b, std::size_t n, std::int64_t globalLength, MPI_Comm comm) {
  double largest = largestProduct(a, b, n);
  double globalLargest = 0.0;
  MPI_Allreduce(&largest, &globalLargest, 1, MPI_DOUBLE, MPI_MAX, comm);
  if (!std::isfinite(globalLargest)) return globalLargest;
  if (globalLargest == 0.0) return 0.0;
  // Each level keeps W = 52 - log2(N) bits of every term as an integer below 2^W, so that N of
  // them add up exactly in a double (below 2^52) in any order, on any rank.
  int lengthBits = 0;
  while ((std::int64_t(1) << lengthBits) < std::max<std::int64_t>(globalLength, 1)) ++lengthBits;
  const int W = 52 - lengthBits;
  const int E = W - (std::ilogb(globalLargest) + 1);  // |p| 2^E < 2^W
  // 2^E as two factors (E may pass 1023 for tiny products); scaling by a power of 2 is exact
  const double s1 = std::ldexp(1.0, E / 2), s2 = std::ldexp(1.0, E - E / 2), level = std::ldexp(1.0, W);
  double sum[kDotLevels] = {};
  cutAndSum(a, b, n, s1, s2, level, sum);
  double total[kDotLevels] = {};
  MPI_Allreduce(sum, total, kDotLevels, MPI_DOUBLE, MPI_SUM, comm);  // integers below 2^52: exact
  double result = 0.0;
  for (int k = kDotLevels - 1; k >= 0; --k) result = result / level + total[k];
  return std::ldexp(std::ldexp(result, -(E / 2)), -(E - E / 2));
}

}  // namespace stokes::solver::petsc
