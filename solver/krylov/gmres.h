#pragma once
// Restarted GMRES with right preconditioning (Saad & Schultz 1986; Saad, Iterative Methods for
// Sparse Linear Systems, 2nd ed. 2003, Alg. 9.5) and its flexible variant (Saad 1993, "A flexible
// inner-outer preconditioned GMRES algorithm"; Alg. 9.6), for any nonsingular A and a
// nonsymmetric preconditioner (the block-triangular preconditioner of a saddle point,
// saddle_point_preconditioner.h).
//
// One cycle of m steps builds the Arnoldi basis of A M^-1, v_0 = r / beta, ...:
//     z_j = M^-1 v_j;  w = A z_j;  h_:j = V_j^T w, w -= V_j h_:j (classical Gram-Schmidt, refined
//     once where it cancels, see orthogonalize);
//     h_{j+1,j} = ||w||;  v_{j+1} = w / h_{j+1,j}.
// Givens rotations reduce the Hessenberg matrix H_j to upper-triangular form, and the rotated
// right-hand side g = Q^T (beta e_1) gives ||b - A x_j||_2 = |g_{j+1}| without forming x_j: the
// unpreconditioned residual that the other methods report, so the stopping rule is theirs. At the
// end of a cycle, with R y = g:
//   gmres   x += M^-1 (V y): one more apply of M per cycle, and M must be the same linear map at
//           every apply (a fixed multigrid cycle is); memory m + 3 vectors;
//   fgmres  x += Z y from the z_j kept: M may change between applies (an inner Krylov solve);
//           memory 2 m + 2 vectors.
// The true residual then confirms convergence or starts the next cycle from x. Every inner
// product is a fixed-chunk reduction, so a solve is bit-identical for any thread count
// (SolveOptions::restart = m).
#include <algorithm>
#include <cmath>
#include <vector>

#include "solver/krylov/krylov.h"

namespace stokes::solver {
inline namespace krylov {

namespace detail {

/// One FGMRES cycle's small dense part: the rotated Hessenberg columns R (column j holds rows
/// 0..j), the rotations and the rotated right-hand side g.
struct HessenbergQR {
  explicit HessenbergQR(int m, double beta)
      : r(std::size_t(m) * std::size_t(m + 1), 0.0), cs(std::size_t(m), 0.0), sn(std::size_t(m), 0.0),
        g(std::size_t(m + 1), 0.0), m_(m) {
    g[0] = beta;
  }
  double& at(int i, int j) { return r[std::size_t(j) * std::size_t(m_ + 1) + std::size_t(i)]; }

  /// Column j (h_0j .. h_{j+1,j}) enters: the earlier rotations, then a new one that zeroes
  /// h_{j+1,j}. Returns |g_{j+1}| = ||b - A x_j||_2.
  double addColumn(int j, const std::vector<double>& h) {
    for (int i = 0; i <= j + 1; ++i) at(i, j) = h[std::size_t(i)];
    for (int i = 0; i < j; ++i) {
      const double a = at(i, j), b = at(i + 1, j);
      at(i, j) = cs[std::size_t(i)] * a + sn[std::size_t(i)] * b;
      at(i + 1, j) = -sn[std::size_t(i)] * a + cs[std::size_t(i)] * b;
    }
    const double a = at(j, j), b = at(j + 1, j);
    const double rho = std::hypot(a, b);
    cs[std::size_t(j)] = rho > 0.0 ? a / rho : 1.0;
    sn[std::size_t(j)] = rho > 0.0 ? b / rho : 0.0;
    at(j, j) = rho;
    at(j + 1, j) = 0.0;
    g[std::size_t(j) + 1] = -sn[std::size_t(j)] * g[std::size_t(j)];
    g[std::size_t(j)] = cs[std::size_t(j)] * g[std::size_t(j)];
    return std::abs(g[std::size_t(j) + 1]);
  }

  /// y with R y = g over the first k columns (back substitution; a zero pivot gives y_i = 0).
  std::vector<double> solve(int k) {
    std::vector<double> y(std::size_t(k), 0.0);
    for (int i = k - 1; i >= 0; --i) {
      double s = g[std::size_t(i)];
      for (int l = i + 1; l < k; ++l) s -= at(i, l) * y[std::size_t(l)];
      y[std::size_t(i)] = at(i, i) != 0.0 ? s / at(i, i) : 0.0;
    }
    return y;
  }

  std::vector<double> r, cs, sn, g;

 private:
  int m_;
};

/// Classical Gram-Schmidt with selective reorthogonalisation (Daniel, Gragg, Kaufman & Stewart
/// 1976): h = V^T w, w -= V h in one pass each over w and the k basis vectors; where that removed
/// more than half of ||w||^2 (||w'|| < ||w|| / sqrt 2, cancellation that costs orthogonality) the
/// pass runs once more and its coefficients add to h. Returns ||w'||. Modified Gram-Schmidt reads
/// and writes w 3k times; this reads it about twice.
inline double orthogonalize(const std::vector<const double*>& basis, std::size_t k, double* w, double* h,
                            std::size_t n) {
  const double before = multiDot(w, basis.data(), k, h, n);
  double after = subtractCombination(h, basis.data(), k, w, n);
  if (after < 0.5 * before) {
    std::vector<double> correction(k);
    multiDot(w, basis.data(), k, correction.data(), n);
    after = subtractCombination(correction.data(), basis.data(), k, w, n);
    for (std::size_t i = 0; i < k; ++i) h[i] += correction[i];
  }
  return std::sqrt(after);
}

/// The restarted cycles of GMRES (Flexible: of FGMRES), see the file comment.
template <bool Flexible, LinearOperator Op, Preconditioner Pre>
Status runGmres(const Op& A, const Pre& M, const SolveOptions& opt, InitialState& state, double* x,
                SolveResult& result) {
  const std::size_t n = A.size();
  const int m = std::max(opt.restart, 1);
  const std::size_t basis = static_cast<std::size_t>(m);
  std::vector<Vector> v(basis + 1, Vector(n)), z(Flexible ? basis : 1, Vector(n));
  auto zOf = [&](int j) -> Vector& { return z[Flexible ? std::size_t(j) : 0]; };
  Vector w(n);
  std::vector<double> h(std::size_t(m) + 1);
  std::vector<const double*> basisRows(basis + 1);
  for (std::size_t i = 0; i <= basis; ++i) basisRows[i] = v[i].data();
  copy(state.r.data(), v[0].data(), n);  // r0 = b - A x0 (initialize)
  for (;;) {
    const double beta = norm2(v[0].data(), n);
    if (!isFinite(beta)) return Status::NonFinite;
    if (state.rule.converged(beta)) return Status::Converged;
    scale(1.0 / beta, v[0].data(), n);
    HessenbergQR qr(m, beta);
    int k = 0;  // columns in this cycle
    bool stop = false;
    while (k < m && result.iterations < opt.maxIterations && !stop) {
      const int j = k;
      precondition(M, v[std::size_t(j)].data(), zOf(j).data(), opt, n);
      A.apply(zOf(j).data(), w.data());
      h[std::size_t(j) + 1] = orthogonalize(basisRows, std::size_t(j) + 1, w.data(), h.data(), n);
      for (int i = 0; i <= j + 1; ++i)
        if (!isFinite(h[std::size_t(i)])) return Status::NonFinite;  // x keeps the last cycle's iterate
      const double estimate = qr.addColumn(j, h);
      ++k;
      ++result.iterations;
      recordResidual(opt, result, estimate);
      // converged by the estimate, or the space is invariant (h_{j+1,j} = 0: x_j is exact)
      stop = state.rule.converged(estimate) || h[std::size_t(j) + 1] == 0.0;
      if (!stop && interrupted(opt)) return Status::Interrupted;  // x keeps the last cycle's iterate
      if (!stop) scaledCopy(1.0 / h[std::size_t(j) + 1], w.data(), v[std::size_t(j) + 1].data(), n);
    }
    const std::vector<double> y = qr.solve(k);
    if constexpr (Flexible) {  // x += Z y
      for (int i = 0; i < k; ++i) axpy(y[std::size_t(i)], z[std::size_t(i)].data(), x, n);
    } else if (k > 0) {  // x += M^-1 (V y)
      scaledCopy(y[0], v[0].data(), w.data(), n);
      for (int i = 1; i < k; ++i) axpy(y[std::size_t(i)], v[std::size_t(i)].data(), w.data(), n);
      precondition(M, w.data(), z[0].data(), opt, n);
      axpy(1.0, z[0].data(), x, n);
    }
    projectNullSpace(opt, x, n);
    residual(A, state.b.data(), x, v[0].data(), n);  // the true residual starts the next cycle
    const double rNorm = norm2(v[0].data(), n);
    if (!isFinite(rNorm)) return Status::NonFinite;
    if (state.rule.converged(rNorm)) return Status::Converged;
    if (state.rule.diverged(rNorm)) return Status::Diverged;
    if (result.iterations >= opt.maxIterations) return Status::MaxIterations;
    if (stop && k == 1 && h[0] == 0.0) return Status::Breakdown;  // A M^-1 v_0 = 0: no progress
    ++result.restarts;
  }
}

/// One GMRES (Flexible: FGMRES) solve from x: the set-up and wrap-up every method shares.
template <bool Flexible, LinearOperator Op, Preconditioner Pre>
SolveResult solveGmres(const Op& A, const double* b, double* x, const Pre& M, const SolveOptions& opt) {
  checkSizes(A, M);
  SolveResult result;
  InitialState state = initialize(A, b, x, opt, result);
  if (state.finished) return result;
  result.status = runGmres<Flexible>(A, M, opt, state, x, result);
  finalize(A, state, x, opt, result);
  return result;
}

}  // namespace detail

/// Restarted GMRES with right preconditioning (see the file comment): A any nonsingular operator,
/// M a fixed linear preconditioner. One application of A and of M per iteration, and one more of M
/// per cycle; result.restarts counts the cycles after the first.
template <LinearOperator Op, Preconditioner Pre>
SolveResult gmres(const Op& A, const double* b, double* x, const Pre& M, const SolveOptions& opt = {}) {
  return detail::solveGmres<false>(A, b, x, M, opt);
}

/// Restarted flexible GMRES with right preconditioning (see the file comment): as gmres, but M may
/// vary between applies, at twice the memory.
template <LinearOperator Op, Preconditioner Pre>
SolveResult fgmres(const Op& A, const double* b, double* x, const Pre& M, const SolveOptions& opt = {}) {
  return detail::solveGmres<true>(A, b, x, M, opt);
}

}  // namespace krylov
}  // namespace stokes::solver
