#pragma once
// Preconditioned MINRES for symmetric (possibly indefinite) A with an SPD preconditioner M
// (Paige & Saunders 1975; the recurrences as in Choi, Paige & Saunders' MINRES-QLP paper, §2).
// It minimises ||b - A x||_{M^-1} over the Krylov space, so the residual never grows: the natural
// method for the saddle-point pressure-velocity form, where BiCGSTAB stagnates.
//
// Lanczos step (preconditioned):  beta_{k+1} v_{k+1} = A v_k - alpha_k v_k - beta_k v_{k-1}
// in the M-inner product, then one Givens rotation per step updates the QR factorisation of
// the tridiagonal T_k and x_k += phi_k w_k.  phibar is ||r_k||_{M^-1}; convergence is checked on
// it and confirmed on the true 2-norm residual (a confirmed miss restarts MINRES from x).
#include <algorithm>
#include <cmath>

#include "solver/krylov/krylov.h"

namespace stokes::solver {
inline namespace krylov {

namespace detail {

template <LinearOperator Op, Preconditioner Pre>
Status runMinres(const Op& A, const Pre& M, const SolveOptions& opt, InitialState& state, double* x,
                 SolveResult& result) {
  const std::size_t n = A.size();
  Vector r1(n), r2(n), y(n), v(n), w(n), w1(n), w2(n);
  for (int restart = 0; restart < 20; ++restart) {
    // r = b - A x,  y = M^-1 r,  beta1 = sqrt(r . y)
    residual(A, state.b.data(), x, r2.data(), n);
    copy(r2.data(), r1.data(), n);
    precondition(M, r2.data(), y.data(), opt, n);
    const double beta1 = std::sqrt(std::max(dot(r2.data(), y.data(), n), 0.0));
    if (!isFinite(beta1)) return Status::NonFinite;
    if (beta1 == 0.0) return Status::Converged;
    double oldb = 0.0, beta = beta1, dbar = 0.0, epsln = 0.0, phibar = beta1, cs = -1.0, sn = 0.0;
    fill(w.data(), 0.0, n);
    fill(w2.data(), 0.0, n);
    const double target = state.rule.target / std::max(norm2(r1.data(), n), 1e-300) * beta1;
    for (int k = 0; result.iterations < opt.maxIterations; ++k) {
      const double s = 1.0 / beta;
      scaledCopy(s, y.data(), v.data(), n);                // v_k = y / beta_k
      A.apply(v.data(), y.data());                         // y = A v_k
      if (k > 0) axpy(-beta / oldb, r1.data(), y.data(), n);
      const double alpha = dot(v.data(), y.data(), n);     // alpha_k = v_k . A v_k
      axpy(-alpha / beta, r2.data(), y.data(), n);
      std::swap(r1, r2);
      copy(y.data(), r2.data(), n);                        // r2 = unpreconditioned Lanczos vector
      precondition(M, r2.data(), y.data(), opt, n);        // y = M^-1 r2
      oldb = beta;
      const double bb = dot(r2.data(), y.data(), n);
      if (!isFinite(bb) || !isFinite(alpha)) return Status::NonFinite;
      if (bb < 0.0) return Status::Breakdown;              // M not SPD
      beta = std::sqrt(bb);
      // apply the previous rotation, then compute the new one
      const double oldeps = epsln;
      const double delta = cs * dbar + sn * alpha;
      const double gbar = sn * dbar - cs * alpha;
      epsln = sn * beta;
      dbar = -cs * beta;
      const double gamma = std::max(std::hypot(gbar, beta), 1e-300);
      cs = gbar / gamma;
      sn = beta / gamma;
      const double phi = cs * phibar;
      phibar = sn * phibar;
      // w_k = (v_k - oldeps w_{k-2} - delta w_{k-1}) / gamma;  x += phi w_k
      std::swap(w1, w2);
      std::swap(w2, w);
      minresDirectionUpdate(1.0 / gamma, oldeps, delta, phi, v.data(), w1.data(), w2.data(), w.data(), x, n);
      ++result.iterations;
      recordResidual(opt, result, phibar);
      if (phibar <= target || beta == 0.0) break;
      if (interrupted(opt)) return Status::Interrupted;
    }
    // confirm on the true residual
    residual(A, state.b.data(), x, r1.data(), n);
    const double rNorm = norm2(r1.data(), n);
    if (!isFinite(rNorm)) return Status::NonFinite;
    if (state.rule.converged(rNorm)) return Status::Converged;
    if (state.rule.diverged(rNorm)) return Status::Diverged;
    if (result.iterations >= opt.maxIterations) return Status::MaxIterations;
    ++result.restarts;
  }
  return Status::Breakdown;
}

}  // namespace detail

/// Preconditioned MINRES for symmetric A (SPD or indefinite) and SPD M. One application of A and
/// of M per iteration.
template <LinearOperator Op, Preconditioner Pre>
SolveResult minres(const Op& A, const double* b, double* x, const Pre& M, const SolveOptions& opt = {}) {
  detail::checkSizes(A, M);
  SolveResult result;
  detail::InitialState state = detail::initialize(A, b, x, opt, result);
  if (state.finished) return result;
  result.status = detail::runMinres(A, M, opt, state, x, result);
  detail::finalize(A, state, x, opt, result);
  return result;
}

}  // namespace krylov
}  // namespace stokes::solver
