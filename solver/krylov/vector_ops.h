#pragma once
// OpenMP vector kernels for the Krylov solvers.
//
// Element-wise kernels are embarrassingly parallel and therefore deterministic.
// Reductions are made deterministic by a FIXED decomposition of [0, n) into
// chunks of kReductionChunk entries, independent of the thread count:
//   partial_c = sum_{i in chunk c} f(i)   (one chunk per task, fixed order inside, see laneSums)
//   result    = sum_c partial_c           (serial, in chunk order)
// The floating-point evaluation order is thus a function of n only, so every
// reduction -- and every solver built on them -- is bit-identical for any
// OMP_NUM_THREADS. Loops only fork threads when their work reaches the vector threshold of
// parallel/fork_policy.h; that choice never changes the arithmetic, and a reduction split over
// several threads counts itself there (parallel::Region::Reduction), so that a test can check that
// it ran the parallel path.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <functional>
#include <utility>
#include <vector>

#include "parallel/fork_policy.h"

namespace stokes::solver {
inline namespace krylov {

// Entries per reduction chunk (the unit of deterministic summation).
inline constexpr std::size_t kReductionChunk = 4096;

namespace detail {

inline std::ptrdiff_t signedSize(std::size_t n) noexcept { return static_cast<std::ptrdiff_t>(n); }

inline std::size_t chunkCount(std::size_t n) noexcept { return (n + kReductionChunk - 1) / kReductionChunk; }

// Applies body(i) for i in [0, n), statically partitioned over the threads when the loop's work
// (default: n entries; a sparse row weighs its stored entries) is worth a fork-join
// (parallel::forkVectorWork).
template <class Body>
void parallelFor(std::size_t n, Body body, std::size_t work) {
  const std::ptrdiff_t count = signedSize(n);
#pragma omp parallel if (parallel::forkVectorWork(work))
  {
    parallel::countTeam(parallel::Region::VectorLoop);
#pragma omp for schedule(static) nowait
    for (std::ptrdiff_t i = 0; i < count; ++i) body(i);
  }
}
template <class Body>
void parallelFor(std::size_t n, Body body) {
  parallelFor(n, body, n);
}

// Interleaved accumulators per chunk: entry i goes to lane (i - begin) % kReductionLanes
// (the tail of a short chunk to lane 0), lanes are combined pairwise at the end.
// This breaks the floating-point add latency chain and lets the compiler vectorise,
// while the summation order still depends on the chunk bounds only.
inline constexpr std::size_t kReductionLanes = 8;

// Returns (sum_{i in [begin,end)} term(i)[k])_k; term(i) may also update entry i.
template <std::size_t K, class Term>
std::array<double, K> laneSums(std::size_t begin, std::size_t end, Term term) {
  std::array<std::array<double, kReductionLanes>, K> acc{};
  std::size_t i = begin;
  for (; i + kReductionLanes <= end; i += kReductionLanes) {
    for (std::size_t l = 0; l < kReductionLanes; ++l) {
      const std::array<double, K> t = term(i + l);
      for (std::size_t k = 0; k < K; ++k) acc[k][l] += t[k];
    }
  }
  for (; i < end; ++i) {
    const std::array<double, K> t = term(i);
    for (std::size_t k = 0; k < K; ++k) acc[k][0] += t[k];
  }
  std::array<double, K> total{};
  for (std::size_t k = 0; k < K; ++k) {
    for (std::size_t width = kReductionLanes / 2; width > 0; width /= 2)
      for (std::size_t l = 0; l < width; ++l) acc[k][l] += acc[k][l + width];
    total[k] = acc[k][0];
  }
  return total;
}

// Deterministic K-fold reduction. chunkSum(begin, end) must return a
// std::array<double, K> accumulated in a fixed order over [begin, end); it may
// also update entries in that range (fused update + reduction). The chunk partials
// are then folded in chunk order with combine (a sum unless stated otherwise).
template <std::size_t K, class ChunkSum, class Combine = std::plus<>>
std::array<double, K> chunkedReduce(std::size_t n, ChunkSum chunkSum, Combine combine = {}) {
  const std::size_t chunks = chunkCount(n);
  std::vector<double> partials(chunks * K);
  const std::ptrdiff_t chunkTotal = signedSize(chunks);
#pragma omp parallel if (chunks > 1 && parallel::forkVectorWork(n))
  {
    parallel::countTeam(parallel::Region::Reduction);
#pragma omp for schedule(static) nowait
    for (std::ptrdiff_t c = 0; c < chunkTotal; ++c) {
      const std::size_t begin = static_cast<std::size_t>(c) * kReductionChunk;
      const std::size_t end = std::min(n, begin + kReductionChunk);
      const std::array<double, K> part = chunkSum(begin, end);
      std::copy(part.begin(), part.end(), partials.begin() + static_cast<std::ptrdiff_t>(K) * c);
    }
  }
  std::array<double, K> total{};
  for (std::size_t c = 0; c < chunks; ++c)
    for (std::size_t k = 0; k < K; ++k) total[k] = combine(total[k], partials[c * K + k]);
  return total;
}

// Deterministic sum over [0, n) of term(i) (a std::array<double, K>): fixed chunks, lanes inside.
template <std::size_t K, class Term>
std::array<double, K> chunkedSum(std::size_t n, Term term) {
  return chunkedReduce<K>(n, [&term](std::size_t begin, std::size_t end) { return laneSums<K>(begin, end, term); });
}

}  // namespace detail

// ---- reductions (deterministic) ----------------------------------------------------------

// a . b = sum_i a_i b_i
inline double dot(const double* a, const double* b, std::size_t n) {
  return detail::chunkedSum<1>(n, [=](std::size_t i) { return std::array<double, 1>{a[i] * b[i]}; })[0];
}

// (a . b, c . d) in a single pass over the data.
inline std::pair<double, double> dot2(const double* a, const double* b, const double* c, const double* d,
                                      std::size_t n) {
  const auto s =
      detail::chunkedSum<2>(n, [=](std::size_t i) { return std::array<double, 2>{a[i] * b[i], c[i] * d[i]}; });
  return {s[0], s[1]};
}

// ||a||_2 = sqrt(a . a)
inline double norm2(const double* a, std::size_t n) { return std::sqrt(dot(a, a, n)); }

// sum_i a_i
inline double sum(const double* a, std::size_t n) {
  return detail::chunkedSum<1>(n, [=](std::size_t i) { return std::array<double, 1>{a[i]}; })[0];
}

// max_i |a_i| (0 for n == 0). NaN entries are skipped; use allFinite to detect them.
inline double maxAbs(const double* a, std::size_t n) {
  const auto chunkMax = [=](std::size_t begin, std::size_t end) {
    double m = 0.0;
    for (std::size_t i = begin; i < end; ++i) m = std::max(m, std::abs(a[i]));
    return std::array<double, 1>{m};
  };
  return detail::chunkedReduce<1>(n, chunkMax, [](double x, double y) { return std::max(x, y); })[0];
}

// True iff no entry is NaN or +-Inf.
inline bool allFinite(const double* a, std::size_t n) {
  const std::ptrdiff_t count = detail::signedSize(n);
  bool finite = true;
#pragma omp parallel for schedule(static) reduction(&& : finite) if (parallel::forkVectorWork(n))
  for (std::ptrdiff_t i = 0; i < count; ++i) finite = finite && std::isfinite(a[i]);
  return finite;
}

// ---- element-wise updates ----------------------------------------------------------------

// y = x
inline void copy(const double* x, double* y, std::size_t n) {
  detail::parallelFor(n, [=](std::ptrdiff_t i) { y[i] = x[i]; });
}

// y = value
inline void fill(double* y, double value, std::size_t n) {
  detail::parallelFor(n, [=](std::ptrdiff_t i) { y[i] = value; });
}

// y = alpha x
inline void scaledCopy(double alpha, const double* x, double* y, std::size_t n) {
  detail::parallelFor(n, [=](std::ptrdiff_t i) { y[i] = alpha * x[i]; });
}

// y = alpha y
inline void scale(double alpha, double* y, std::size_t n) {
  detail::parallelFor(n, [=](std::ptrdiff_t i) { y[i] *= alpha; });
}

// y += alpha x
inline void axpy(double alpha, const double* x, double* y, std::size_t n) {
  detail::parallelFor(n, [=](std::ptrdiff_t i) { y[i] += alpha * x[i]; });
}

// y = x + beta y   (CG search direction p = z + beta p; residual r = b - Ap with beta = -1)
inline void xpby(const double* x, double beta, double* y, std::size_t n) {
  detail::parallelFor(n, [=](std::ptrdiff_t i) { y[i] = x[i] + beta * y[i]; });
}

// z += alpha x + beta y   (BiCGSTAB solution update x += alpha p^ + omega s^)
inline void axpby2(double alpha, const double* x, double beta, const double* y, double* z, std::size_t n) {
  detail::parallelFor(n, [=](std::ptrdiff_t i) { z[i] += alpha * x[i] + beta * y[i]; });
}

// p = r + beta (p - omega v)   (BiCGSTAB search direction)
inline void bicgstabDirection(const double* r, double beta, double omega, const double* v, double* p,
                              std::size_t n) {
  detail::parallelFor(n, [=](std::ptrdiff_t i) { p[i] = r[i] + beta * (p[i] - omega * v[i]); });
}

// MINRES' direction and solution update in one pass:
//   w = (v - oldeps w1 - delta w2) * invGamma;  x += phi w.
inline void minresDirectionUpdate(double invGamma, double oldeps, double delta, double phi, const double* v,
                                  const double* w1, const double* w2, double* w, double* x, std::size_t n) {
  detail::parallelFor(n, [=](std::ptrdiff_t i) {
    w[i] = (v[i] - oldeps * w1[i] - delta * w2[i]) * invGamma;
    x[i] += phi * w[i];
  });
}

// ---- fused update + reduction (deterministic) --------------------------------------------

// x += alpha p;  r -= alpha Ap;  returns r . r of the updated r (one pass, same chunking as dot).
inline double cgUpdate(double alpha, const double* p, const double* Ap, double* x, double* r, std::size_t n) {
  return detail::chunkedSum<1>(n, [=](std::size_t i) {
    x[i] += alpha * p[i];
    r[i] -= alpha * Ap[i];
    return std::array<double, 1>{r[i] * r[i]};
  })[0];
}

// The CG step with a diagonal preconditioner in one pass (Saad, Alg. 9.1, lines 4-6):
//   x += alpha p;  r -= alpha Ap;  z = dinv r;  returns (r . r, r . z) of the updated r.
// The sums follow the chunks and lanes of dot, so they are bit-identical to cgUpdate followed
// by z = dinv r and dot(r, z); one fork-join and one read of r instead of three.
inline std::pair<double, double> cgUpdateDiagonal(double alpha, const double* p, const double* Ap, double* x,
                                                  double* r, const double* dinv, double* z, std::size_t n) {
  const auto s = detail::chunkedSum<2>(n, [=](std::size_t i) {
    x[i] += alpha * p[i];
    r[i] -= alpha * Ap[i];
    z[i] = dinv[i] != 0.0 ? dinv[i] * r[i] : 0.0;
    return std::array<double, 2>{r[i] * r[i], r[i] * z[i]};
  });
  return {s[0], s[1]};
}

// w = y + alpha x;  returns w . w (one pass). w may alias y.
inline double waxpyNormSquared(double alpha, const double* x, const double* y, double* w, std::size_t n) {
  return detail::chunkedSum<1>(n, [=](std::size_t i) {
    w[i] = y[i] + alpha * x[i];
    return std::array<double, 1>{w[i] * w[i]};
  })[0];
}

// ---- block Gram-Schmidt (deterministic) ---------------------------------------------------

// out_i = w . v_i for i < k, and returns w . w, in one pass over w: each chunk of w stays in
// cache while the k basis chunks stream past it. Each out_i uses dot's chunks and lanes, so it is
// bit-identical to dot(w, v_i, n).
inline double multiDot(const double* w, const double* const* v, std::size_t k, double* out, std::size_t n) {
  const std::size_t chunks = detail::chunkCount(n);
  std::vector<double> partials(chunks * (k + 1));
  const std::ptrdiff_t chunkTotal = detail::signedSize(chunks);
#pragma omp parallel if (chunks > 1 && parallel::forkVectorWork(n * (k + 1)))
  {
    parallel::countTeam(parallel::Region::Reduction);
#pragma omp for schedule(static) nowait
    for (std::ptrdiff_t c = 0; c < chunkTotal; ++c) {
      const std::size_t begin = static_cast<std::size_t>(c) * kReductionChunk;
      const std::size_t end = std::min(n, begin + kReductionChunk);
      double* part = partials.data() + static_cast<std::size_t>(c) * (k + 1);
      for (std::size_t j = 0; j < k; ++j) {
        const double* vj = v[j];
        part[j] = detail::laneSums<1>(begin, end, [=](std::size_t i) { return std::array<double, 1>{w[i] * vj[i]}; })[0];
      }
      part[k] = detail::laneSums<1>(begin, end, [=](std::size_t i) { return std::array<double, 1>{w[i] * w[i]}; })[0];
    }
  }
  double wNormSquared = 0.0;
  std::fill(out, out + k, 0.0);
  for (std::size_t c = 0; c < chunks; ++c) {
    const double* part = partials.data() + c * (k + 1);
    for (std::size_t j = 0; j < k; ++j) out[j] += part[j];
    wNormSquared += part[k];
  }
  return wNormSquared;
}

// w -= sum_{i<k} h_i v_i;  returns w . w of the updated w (one pass over w, chunked as dot).
inline double subtractCombination(const double* h, const double* const* v, std::size_t k, double* w,
                                  std::size_t n) {
  return detail::chunkedReduce<1>(n, [=](std::size_t begin, std::size_t end) {
    for (std::size_t j = 0; j < k; ++j) {
      const double hj = h[j];
      const double* vj = v[j];
      for (std::size_t i = begin; i < end; ++i) w[i] -= hj * vj[i];
    }
    return detail::laneSums<1>(begin, end, [=](std::size_t i) { return std::array<double, 1>{w[i] * w[i]}; });
  })[0];
}

// v -= (u . v) u   -- removes the component along the unit vector u (null-space projection).
inline void projectOut(const double* u, double* v, std::size_t n) {
  const double coefficient = dot(u, v, n);
  axpy(-coefficient, u, v, n);
}

}  // namespace krylov
}  // namespace stokes::solver
