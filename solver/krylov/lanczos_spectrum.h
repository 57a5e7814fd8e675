#pragma once
// Extreme eigenvalues of M^-1 A for symmetric A (definite or not) and SPD M, by the preconditioned
// Lanczos process (Golub & Van Loan, "Matrix Computations", 4th ed., §10.1; the same recurrence
// as MINRES, minres.h):
//
//   z_1 = M^-1 r_1 / beta_1,  beta_1 = sqrt(r_1 . M^-1 r_1)
//   beta_{k+1} r_{k+1} = A v_k - alpha_k r_k - beta_k r_{k-1}   (v_k = M^-1 r_k, M-orthonormal)
//   alpha_k = v_k . A v_k
//
// The eigenvalues of the tridiagonal T_k (alpha on the diagonal, beta off it) are the Ritz values
// of M^-1 A on the Krylov space; its extreme ones converge first, from inside the spectrum, so
// the condition number of T_k is a lower bound that rises to the true one. Without
// re-orthogonalisation converged Ritz values repeat ("ghosts"), which leaves the extremes right but
// can take more steps than the dimension where the spectrum clusters at an end.
// Counting eigenvalues of T_k below x (Sturm sequence of the LDL^T pivots) gives lambda_min,
// lambda_max and the smallest |lambda| by bisection, so no dense eigen-solver is needed.
//
// A null vector (e.g. constant pressure in a closed box) is projected out of the start vector and
// of every M^-1 r (M-orthogonally), so that the process sees the operator on its complement.
// Used to attribute Krylov iterations to the preconditioner: condition numbers of the
// preconditioned Schur complement and of the whole preconditioned system (docs/design.md §5.5).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include "solver/krylov/krylov.h"

namespace stokes::solver {
inline namespace krylov {

/// Ritz estimates of the spectrum of M^-1 A after `steps` Lanczos steps.
struct SpectrumEstimate {
  double lambdaMin = 0.0;     ///< smallest eigenvalue
  double lambdaMax = 0.0;     ///< largest eigenvalue
  double smallestAbs = 0.0;   ///< smallest |eigenvalue| (see lanczosMagnitudes where A is indefinite)
  double largestAbs = 0.0;    ///< largest |eigenvalue|
  int steps = 0;              ///< Lanczos steps taken (fewer than asked: the space was exhausted)
  int nullRitz = 0;           ///< Ritz values taken for a null space (tridiagonalSpectrum's nullCut)
  /// max |lambda| / min |lambda|.
  double condition() const { return largestAbs / std::max(smallestAbs, 1e-300); }
};

namespace detail {

/// Eigenvalues of the symmetric tridiagonal (a: diagonal, b: off-diagonal, b.size() = a.size() - 1)
/// that are < x: the negative pivots of T - x I = L D L^T.
inline int countBelow(const std::vector<double>& a, const std::vector<double>& b, double x) {
  int count = 0;
  double d = 1.0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    const double off = i ? b[i - 1] * b[i - 1] : 0.0;
    d = a[i] - x - (i ? off / d : 0.0);
    if (d == 0.0) d = -1e-300;  // a pivot exactly zero: perturb to the negative side
    if (d < 0.0) ++count;
  }
  return count;
}

/// The k-th smallest eigenvalue (k = 0, 1, ...) of the tridiagonal, by bisection on [lo, hi].
inline double kthEigenvalue(const std::vector<double>& a, const std::vector<double>& b, int k, double lo,
                            double hi) {
  for (int it = 0; it < 200 && hi - lo > 1e-15 * std::max(std::abs(lo), std::abs(hi)); ++it) {
    const double mid = 0.5 * (lo + hi);
    if (countBelow(a, b, mid) > k) hi = mid;
    else lo = mid;
  }
  return 0.5 * (lo + hi);
}

}  // namespace detail

/// Extreme eigenvalues of the tridiagonal T (a, b): Gershgorin bounds, then bisection. Ritz values
/// with |lambda| <= nullCut max |lambda| count as a null space (a consistent singular operator, e.g.
/// dependent constraint rows): they are counted in `nullRitz` and skipped for smallestAbs.
inline SpectrumEstimate tridiagonalSpectrum(const std::vector<double>& a, const std::vector<double>& b,
                                            double nullCut = 0.0) {
  SpectrumEstimate s;
  s.steps = int(a.size());
  if (a.empty()) return s;
  double lo = a[0], hi = a[0];
  for (std::size_t i = 0; i < a.size(); ++i) {
    const double r = (i ? std::abs(b[i - 1]) : 0.0) + (i + 1 < a.size() ? std::abs(b[i]) : 0.0);
    lo = std::min(lo, a[i] - r);
    hi = std::max(hi, a[i] + r);
  }
  const int n = int(a.size());
  s.lambdaMin = detail::kthEigenvalue(a, b, 0, lo, hi);
  s.lambdaMax = detail::kthEigenvalue(a, b, n - 1, lo, hi);
  s.largestAbs = std::max(std::abs(s.lambdaMin), std::abs(s.lambdaMax));
  // smallest |lambda| outside [-cut, cut]: the eigenvalues just below -cut and at/above cut
  const double cut = nullCut * s.largestAbs;
  const int below = detail::countBelow(a, b, -cut), upTo = detail::countBelow(a, b, cut);
  s.nullRitz = upTo - below;
  double best = std::numeric_limits<double>::infinity();
  if (below > 0) best = std::abs(detail::kthEigenvalue(a, b, below - 1, lo, -cut));
  if (upTo < n) best = std::min(best, std::abs(detail::kthEigenvalue(a, b, upTo, cut, hi)));
  s.smallestAbs = best;
  return s;
}

/// `steps` preconditioned Lanczos steps on M^-1 A from a pseudo-random start (a fixed seed: the
/// same estimate on every run), then the spectrum of T. `nullVector` (optional, size A.size()):
/// a vector of A's null space to project out; `nullCut`: see tridiagonalSpectrum. Stops early when beta falls to rounding level (the
/// Krylov space is exhausted: the Ritz values are then exact).
template <LinearOperator Op, Preconditioner Pre>
SpectrumEstimate lanczosSpectrum(const Op& A, const Pre& M, int steps, const double* nullVector = nullptr,
                                 double nullCut = 0.0) {
  const std::size_t n = A.size();
  Vector r(n), rOld(n, 0.0), v(n), w(n), Mnull;
  // With A z0 = 0, z0 . A v = 0 for every v: the residuals r stay orthogonal to z0 (projected
  // again against rounding), and the process sees M^-1 A on {v : z0 . M v = 0}, without z0.
  double nullNorm2 = 0.0;
  if (nullVector) nullNorm2 = dot(nullVector, nullVector, n);
  auto project = [&](double* x) {
    if (!nullVector || nullNorm2 == 0.0) return;
    axpy(-dot(nullVector, x, n) / nullNorm2, nullVector, x, n);
  };
  std::uint64_t seed = 0x9E3779B97F4A7C15ull;
  for (std::size_t i = 0; i < n; ++i) {
    seed ^= seed << 13, seed ^= seed >> 7, seed ^= seed << 17;
    r[i] = double(seed >> 11) * 0x1.0p-53 - 0.5;
  }
  project(r.data());
  M.apply(r.data(), v.data());
  double beta = std::sqrt(std::max(dot(r.data(), v.data(), n), 0.0));
  const double beta1 = beta;
  std::vector<double> alphas, betas;
  for (int k = 0; k < steps && beta > 1e-14 * beta1; ++k) {
    scale(1.0 / beta, r.data(), n);
    scale(1.0 / beta, v.data(), n);
    A.apply(v.data(), w.data());  // w = A v_k
    if (k > 0) axpy(-betas.back(), rOld.data(), w.data(), n);
    const double alpha = dot(v.data(), w.data(), n);
    axpy(-alpha, r.data(), w.data(), n);
    alphas.push_back(alpha);
    project(w.data());
    std::swap(rOld, r);
    std::swap(r, w);  // r = r_{k+1} beta_{k+1}
    M.apply(r.data(), v.data());
    beta = std::sqrt(std::max(dot(r.data(), v.data(), n), 0.0));
    if (!std::isfinite(alpha) || !std::isfinite(beta)) break;
    betas.push_back(beta);
  }
  if (!betas.empty() && betas.size() == alphas.size()) betas.pop_back();
  return tridiagonalSpectrum(alphas, betas, nullCut);
}

/// |eigenvalues| of M^-1 A for indefinite A: Ritz values of an indefinite operator can fall into
/// the gap around 0 (they are not bounded by the spectrum's inner ends), so the smallest |lambda|
/// is read from the square instead: M^-1 (A M^-1 A) = (M^-1 A)^2 is definite, and its Ritz values
/// converge to min lambda^2 from above. Two applies of A per step; lambdaMin and lambdaMax are
/// left 0.
template <LinearOperator Op, Preconditioner Pre>
SpectrumEstimate lanczosMagnitudes(const Op& A, const Pre& M, int steps, const double* nullVector = nullptr,
                                   double nullCut = 0.0) {
  struct Squared {
    const Op& a;
    const Pre& m;
    mutable Vector t, u;
    std::size_t size() const { return a.size(); }
    void apply(const double* x, double* y) const {
      t.resize(a.size());
      u.resize(a.size());
      a.apply(x, t.data());
      m.apply(t.data(), u.data());
      a.apply(u.data(), y);
    }
  };
  const SpectrumEstimate sq = lanczosSpectrum(Squared{A, M, {}, {}}, M, steps, nullVector, nullCut * nullCut);
  SpectrumEstimate s;
  s.steps = sq.steps;
  s.nullRitz = sq.nullRitz;
  s.smallestAbs = std::sqrt(std::max(sq.smallestAbs, 0.0));
  s.largestAbs = std::sqrt(std::max(sq.lambdaMax, 0.0));
  return s;
}

}  // namespace krylov
}  // namespace stokes::solver
