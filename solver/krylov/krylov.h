#pragma once
// Matrix-free Krylov solvers: preconditioned CG and right-preconditioned BiCGSTAB.
//
// The solvers only see y = A x and z = M^-1 r through the LinearOperator and
// Preconditioner concepts (solver/krylov/operator.h). All vector work goes through the
// fused, deterministic kernels of solver/krylov/vector_ops.h, so a solve is bit-identical
// for any OpenMP thread count as long as A and M are.
//
// Conventions shared by both solvers:
//   * x holds the initial guess on entry and the approximate solution on exit.
//   * Converged when ||r|| <= max(relativeTolerance * ||b||, absoluteTolerance),
//     measured on the (recursively updated) residual r = b - A x.
//   * Diverged when ||r|| > divergenceFactor * max(||r0||, ||b||).
//   * Optional null space (unit vector u): b, x0, every preconditioned vector and
//     the final x are projected, v -= (u . v) u, so iterates stay orthogonal to u.
//   * Non-finite data never propagates into x: the loop stops with NonFinite and
//     leaves x at the last finite iterate. Nothing inside the loop throws.
//   * The reported residuals are true residuals ||b - A x|| (b projected), the
//     final one recomputed after the loop.

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <functional>
#include <limits>
#include <stdexcept>
#include <tuple>
#include <vector>

#include "solver/krylov/aligned_vector.h"
#include "solver/krylov/operator.h"
#include "solver/krylov/vector_ops.h"

namespace stokes::solver {
inline namespace krylov {

/// Interrupted: SolveOptions::stopRequested said so between two iterations (x holds the last
/// iterate the method had formed).
enum class Status { Converged, MaxIterations, Breakdown, NonFinite, Diverged, Interrupted };

inline const char* toString(Status status) noexcept {
  switch (status) {
    case Status::Converged: return "Converged";
    case Status::MaxIterations: return "MaxIterations";
    case Status::Breakdown: return "Breakdown";
    case Status::NonFinite: return "NonFinite";
    case Status::Diverged: return "Diverged";
    case Status::Interrupted: return "Interrupted";
  }
  return "Unknown";
}

struct SolveOptions {
  double relativeTolerance = 1e-8;    // ||r|| <= relTol * ||b||  (or absoluteTolerance)
  double absoluteTolerance = 0.0;     // ||r|| <= absTol
  int maxIterations = 10000;          // main-loop passes (CG: one A and one M application each,
                                      // BiCGSTAB: at most two of each)
  double divergenceFactor = 1e6;      // Diverged if ||r|| > factor * max(||r0||, ||b||)
  const double* nullSpace = nullptr;  // optional unit vector u (length size()) spanning null(A)
  bool recordHistory = false;         // store the residual norm of every iteration
  // GMRES / FGMRES: Arnoldi steps m per cycle (m + 3 / 2 m + 2 vectors kept). 20: the
  // pressure-velocity steps took as many iterations as with 30 (beam 96: 46; armadillos 128,
  // 6 steps: 45-28 against 45-28; 15: 48, 50: 42), with a third fewer vectors.
  int restart = 20;
  // Asked once per iteration, on the calling thread, whether to stop (Ctrl-C in the command line,
  // KeyboardInterrupt in Python; the role of OpenVDB's util::NullInterrupter). Empty: never.
  std::function<bool()> stopRequested;
};

struct SolveResult {
  Status status = Status::MaxIterations;
  int iterations = 0;
  double initialResidual = 0.0;   // ||b - A x0||_2
  double finalResidual = 0.0;     // ||b - A x||_2, recomputed after the loop
  double relativeResidual = 0.0;  // finalResidual / ||b||  (0 if b == 0)
  int restarts = 0;               // BiCGSTAB restarts after (near-)breakdown
  std::vector<double> history;    // ||r0||, then the recursive residual norm per iteration

  bool converged() const noexcept { return status == Status::Converged; }
};

namespace detail {

// Stopping thresholds fixed at the start of a solve.
struct StoppingRule {
  double target = 0.0;      // converged when ||r|| <= target
  double divergence = 0.0;  // diverged when ||r|| > divergence

  bool converged(double rNorm) const noexcept { return rNorm <= target; }
  bool diverged(double rNorm) const noexcept { return rNorm > divergence; }
};

inline StoppingRule makeStoppingRule(const SolveOptions& opt, double bNorm, double r0Norm) {
  return {std::max(opt.relativeTolerance * bNorm, opt.absoluteTolerance),
          opt.divergenceFactor * std::max(r0Norm, bNorm)};
}

inline bool isFinite(double value) noexcept { return std::isfinite(value); }

// v -= (u . v) u when a null-space vector u is given.
inline void projectNullSpace(const SolveOptions& opt, double* v, std::size_t n) {
  if (opt.nullSpace != nullptr) projectOut(opt.nullSpace, v, n);
}

// r = b - A x
template <LinearOperator Op>
void residual(const Op& A, const double* b, const double* x, double* r, std::size_t n) {
  A.apply(x, r);
  xpby(b, -1.0, r, n);
}

// z = M^-1 r, projected orthogonal to the null space.
template <Preconditioner Pre>
void precondition(const Pre& M, const double* r, double* z, const SolveOptions& opt, std::size_t n) {
  M.apply(r, z);
  projectNullSpace(opt, z, n);
}

inline void recordResidual(const SolveOptions& opt, SolveResult& result, double rNorm) {
  if (opt.recordHistory) result.history.push_back(rNorm);
}

// True when the caller asked the solve to stop (SolveOptions::stopRequested).
inline bool interrupted(const SolveOptions& opt) { return opt.stopRequested && opt.stopRequested(); }

template <LinearOperator Op, Preconditioner Pre>
void checkSizes(const Op& A, const Pre& M) {
  if (static_cast<std::size_t>(M.size()) != static_cast<std::size_t>(A.size()))
    throw std::invalid_argument("Krylov solver: preconditioner size differs from operator size");
}

// Data shared by both solvers after the common prologue.
struct InitialState {
  Vector b;               // copy of the right-hand side, projected orthogonal to the null space
  Vector r;               // r0 = b - A x0
  double bNorm = 0.0;     // ||b||
  StoppingRule rule{};
  bool finished = false;  // the result is already final (see initialize)
};

inline void markNonFinite(SolveResult& result) {
  constexpr double nan = std::numeric_limits<double>::quiet_NaN();
  result.status = Status::NonFinite;
  result.initialResidual = result.finalResidual = result.relativeResidual = nan;
}

// Common prologue: validates the data, projects b and x0, computes r0 = b - A x0.
// Finishes early (state.finished) when
//   * b or x0 holds NaN/Inf, or r0 does        -> NonFinite, x untouched;
//   * ||b|| == 0                               -> Converged, x = 0 (the solution of A x = 0);
//   * x0 already satisfies the tolerance       -> Converged, 0 iterations.
template <LinearOperator Op>
InitialState initialize(const Op& A, const double* b, double* x, const SolveOptions& opt, SolveResult& result) {
  const std::size_t n = A.size();
  InitialState state;
  state.finished = true;
  state.b.assign(b, b + n);
  if (!allFinite(state.b.data(), n) || !allFinite(x, n)) {
    markNonFinite(result);
    return state;
  }
  projectNullSpace(opt, state.b.data(), n);
  state.bNorm = norm2(state.b.data(), n);
  if (state.bNorm == 0.0) {
    fill(x, 0.0, n);
    result.status = Status::Converged;
    return state;
  }
  projectNullSpace(opt, x, n);
  state.r.resize(n);
  residual(A, state.b.data(), x, state.r.data(), n);
  const double r0Norm = norm2(state.r.data(), n);
  if (!isFinite(r0Norm)) {
    markNonFinite(result);
    return state;
  }
  result.initialResidual = result.finalResidual = r0Norm;
  result.relativeResidual = r0Norm / state.bNorm;
  recordResidual(opt, result, r0Norm);
  state.rule = makeStoppingRule(opt, state.bNorm, r0Norm);
  state.finished = state.rule.converged(r0Norm);
  if (state.finished) result.status = Status::Converged;
  return state;
}

// Common epilogue: projects x and records the true residual ||b - A x||.
template <LinearOperator Op>
void finalize(const Op& A, InitialState& state, double* x, const SolveOptions& opt, SolveResult& result) {
  const std::size_t n = A.size();
  projectNullSpace(opt, x, n);
  residual(A, state.b.data(), x, state.r.data(), n);
  result.finalResidual = norm2(state.r.data(), n);
  result.relativeResidual = result.finalResidual / state.bNorm;
}

// ---- preconditioned conjugate gradients (Saad, Iterative Methods, Alg. 9.1) ----------------

template <LinearOperator Op, Preconditioner Pre>
Status runConjugateGradient(const Op& A, const Pre& M, const SolveOptions& opt, InitialState& state, double* x,
                            SolveResult& result) {
  const std::size_t n = A.size();
  Vector zStorage(n), pStorage(n), apStorage(n);
  double* r = state.r.data();
  double* z = zStorage.data();
  double* p = pStorage.data();
  double* Ap = apStorage.data();
  bool fused = false;
  if constexpr (DiagonalPreconditioner<Pre>) fused = opt.nullSpace == nullptr;

  precondition(M, r, z, opt, n);  // z0 = M^-1 r0
  copy(z, p, n);                  // p0 = z0
  double rz = dot(r, z, n);       // (r0, z0)
  if (!isFinite(rz)) return Status::NonFinite;
  if (rz <= 0.0) return Status::Breakdown;  // M not SPD on r0

  while (result.iterations < opt.maxIterations) {
    A.apply(p, Ap);                     // Ap = A p
    const double pAp = dot(p, Ap, n);   // (p, Ap)
    if (!isFinite(pAp)) return Status::NonFinite;
    if (pAp <= 0.0) return Status::Breakdown;  // A not SPD (or p = 0)
    const double alpha = rz / pAp;      // alpha = (r,z)/(p,Ap)
    if (!isFinite(alpha)) return Status::NonFinite;

    // x += alpha p; r -= alpha Ap; rr = (r,r). A diagonal preconditioner without a null space
    // is fused into the same pass (z = M^-1 r, (r,z)): two fork-joins fewer per iteration.
    double rr = 0.0, rzFused = 0.0;
    if constexpr (DiagonalPreconditioner<Pre>) {
      if (fused) std::tie(rr, rzFused) = cgUpdateDiagonal(alpha, p, Ap, x, r, M.inverseDiagonal().data(), z, n);
      else rr = cgUpdate(alpha, p, Ap, x, r, n);
    } else {
      rr = cgUpdate(alpha, p, Ap, x, r, n);
    }
    if (!isFinite(rr)) {
      axpy(-alpha, p, x, n);  // undo: keep the last finite iterate
      return Status::NonFinite;
    }
    ++result.iterations;
    const double rNorm = std::sqrt(rr);
    recordResidual(opt, result, rNorm);
    if (state.rule.converged(rNorm)) return Status::Converged;
    if (state.rule.diverged(rNorm)) return Status::Diverged;
    if (interrupted(opt)) return Status::Interrupted;

    if (!fused) precondition(M, r, z, opt, n);                // z = M^-1 r
    const double rzNew = fused ? rzFused : dot(r, z, n);      // (r_new, z_new)
    if (!isFinite(rzNew)) return Status::NonFinite;
    if (rzNew <= 0.0) return Status::Breakdown;  // M not SPD on r
    const double beta = rzNew / rz;        // beta = (r_new,z_new)/(r,z)
    rz = rzNew;
    xpby(z, beta, p, n);                   // p = z + beta p
  }
  return Status::MaxIterations;
}

// ---- right-preconditioned BiCGSTAB (van der Vorst 1992; Saad, Iterative Methods, Alg. 7.7) --
//
// Solves A M^-1 y = b, x = M^-1 y, so r is the true (unpreconditioned) residual:
//   rho_k   = (r0^, r_k)
//   beta    = (rho_k / rho_{k-1}) (alpha / omega)
//   p       = r + beta (p - omega v)
//   p^      = M^-1 p,          v = A p^
//   alpha   = rho_k / (r0^, v)
//   s       = r - alpha v
//   s^      = M^-1 s,          t = A s^
//   omega   = (t, s) / (t, t)
//   x      += alpha p^ + omega s^
//   r       = s - omega t
// (Near-)breakdown -- rho ~ 0, (r0^, v) ~ 0 or omega ~ 0 -- restarts from the true
// residual with r0^ = r. A solve gives up with Breakdown after kMaxStalledRestarts
// consecutive restarts that did not reduce ||b - A x||. Convergence of the
// recursive residual is confirmed on the true residual the same way. Every pass
// through the loop counts as one iteration, including one cut short by a breakdown.

// |(a, b)| <= tol ||a|| ||b||: a and b are numerically orthogonal (cosine below tol).
inline constexpr double kBreakdownCosine = 1e-12;
inline constexpr int kMaxStalledRestarts = 5;

inline bool nearlyOrthogonal(double ab, double aNorm, double bNorm) noexcept {
  return std::abs(ab) <= kBreakdownCosine * aNorm * bNorm;
}

template <LinearOperator Op, Preconditioner Pre>
class BiCgStab {
 public:
  BiCgStab(const Op& A, const Pre& M, const SolveOptions& opt, InitialState& state, double* x,
           SolveResult& result)
      : A_(A), M_(M), opt_(opt), state_(state), result_(result), n_(A.size()), x_(x),
        r0hat_(state.r), p_(n_), v_(n_), pHat_(n_), s_(n_), sHat_(n_), t_(n_),
        rNorm_(result.initialResidual), r0hatNorm_(rNorm_), bestRestartNorm_(rNorm_) {}

  Status run() {
    while (result_.iterations < opt_.maxIterations) {
      Step step = iterate();
      if (step == Step::Restart) step = restartFromTrueResidual();
      if (step == Step::Stop) return status_;
      if (interrupted(opt_)) return Status::Interrupted;
    }
    return Status::MaxIterations;
  }

 private:
  enum class Step { Continue, Restart, Stop };

  Step stop(Status status) {
    status_ = status;
    return Step::Stop;
  }

  // One pass of the recurrence above (two operator and two preconditioner applications).
  Step iterate() {
    double* r = state_.r.data();
    ++result_.iterations;
    const double rho = dot(r0hat_.data(), r, n_);  // rho_k = (r0^, r_k)
    if (!isFinite(rho)) return stop(Status::NonFinite);
    if (nearlyOrthogonal(rho, r0hatNorm_, rNorm_)) return Step::Restart;
    if (!updateDirection(rho, r)) return stop(Status::NonFinite);

    precondition(M_, p_.data(), pHat_.data(), opt_, n_);  // p^ = M^-1 p
    A_.apply(pHat_.data(), v_.data());                     // v = A p^
    const auto [r0v, vv] = dot2(r0hat_.data(), v_.data(), v_.data(), v_.data(), n_);
    if (!isFinite(r0v) || !isFinite(vv)) return stop(Status::NonFinite);
    if (nearlyOrthogonal(r0v, r0hatNorm_, std::sqrt(vv))) return Step::Restart;
    alpha_ = rho / r0v;  // alpha = rho / (r0^, v)
    if (!isFinite(alpha_)) return stop(Status::NonFinite);

    const double sNorm = std::sqrt(waxpyNormSquared(-alpha_, v_.data(), r, s_.data(), n_));  // s = r - alpha v
    if (!isFinite(sNorm)) return stop(Status::NonFinite);
    if (state_.rule.converged(sNorm)) return acceptHalfStep(sNorm);

    precondition(M_, s_.data(), sHat_.data(), opt_, n_);  // s^ = M^-1 s
    A_.apply(sHat_.data(), t_.data());                     // t = A s^
    const auto [ts, tt] = dot2(t_.data(), s_.data(), t_.data(), t_.data(), n_);
    if (!isFinite(ts) || !isFinite(tt)) return stop(Status::NonFinite);
    if (nearlyOrthogonal(ts, std::sqrt(tt), sNorm)) return acceptHalfStep(sNorm);
    omega_ = ts / tt;  // omega = (t,s)/(t,t)
    if (!isFinite(omega_)) return stop(Status::NonFinite);
    return fullStep(r);
  }

  // p = r after a (re)start, else p = r + beta (p - omega v). False if beta is not finite.
  bool updateDirection(double rho, const double* r) {
    if (freshStart_) {
      copy(r, p_.data(), n_);
    } else {
      const double beta = (rho / rhoPrevious_) * (alpha_ / omega_);  // beta = (rho_k/rho_{k-1}) (alpha/omega)
      if (!isFinite(beta)) return false;
      bicgstabDirection(r, beta, omega_, v_.data(), p_.data(), n_);
    }
    freshStart_ = false;
    rhoPrevious_ = rho;
    return true;
  }

  // x += alpha p^, r = s: used when s already converged or omega broke down. Either way the
  // recurrence restarts from the true residual, which also confirms convergence.
  Step acceptHalfStep(double sNorm) {
    axpy(alpha_, pHat_.data(), x_, n_);
    copy(s_.data(), state_.r.data(), n_);
    rNorm_ = sNorm;
    recordResidual(opt_, result_, rNorm_);
    return Step::Restart;
  }

  // x += alpha p^ + omega s^;  r = s - omega t.
  Step fullStep(double* r) {
    axpby2(alpha_, pHat_.data(), omega_, sHat_.data(), x_, n_);
    const double rr = waxpyNormSquared(-omega_, t_.data(), s_.data(), r, n_);
    if (!isFinite(rr)) {
      axpby2(-alpha_, pHat_.data(), -omega_, sHat_.data(), x_, n_);  // undo: keep the last finite iterate
      return stop(Status::NonFinite);
    }
    rNorm_ = std::sqrt(rr);
    recordResidual(opt_, result_, rNorm_);
    if (state_.rule.converged(rNorm_)) return Step::Restart;  // confirm on the true residual
    if (state_.rule.diverged(rNorm_)) return stop(Status::Diverged);
    return Step::Continue;
  }

  // r = b - A x; stop if converged, otherwise restart the recurrence with r0^ = r.
  Step restartFromTrueResidual() {
    double* r = state_.r.data();
    residual(A_, state_.b.data(), x_, r, n_);
    rNorm_ = norm2(r, n_);
    if (!isFinite(rNorm_)) return stop(Status::NonFinite);
    if (state_.rule.converged(rNorm_)) return stop(Status::Converged);
    ++result_.restarts;
    if (rNorm_ < bestRestartNorm_) {
      bestRestartNorm_ = rNorm_;
      stalledRestarts_ = 0;
    } else if (++stalledRestarts_ >= kMaxStalledRestarts) {
      return stop(Status::Breakdown);
    }
    copy(r, r0hat_.data(), n_);
    r0hatNorm_ = rNorm_;
    freshStart_ = true;
    return Step::Continue;
  }

  const Op& A_;
  const Pre& M_;
  const SolveOptions& opt_;
  InitialState& state_;
  SolveResult& result_;
  std::size_t n_;
  double* x_;
  Vector r0hat_, p_, v_, pHat_, s_, sHat_, t_;
  double rNorm_;             // ||r|| of the current residual
  double r0hatNorm_;         // ||r0^||
  double bestRestartNorm_;   // smallest true residual seen at a (re)start
  int stalledRestarts_ = 0;  // consecutive restarts without progress
  bool freshStart_ = true;   // next direction is p = r
  double rhoPrevious_ = 1.0, alpha_ = 1.0, omega_ = 1.0;
  Status status_ = Status::MaxIterations;
};

}  // namespace detail

// Preconditioned conjugate gradients for SPD A and SPD M (Saad, Iterative Methods, Alg. 9.1).
// One application of A and of M per iteration; Breakdown if (p, Ap) <= 0 or (r, z) <= 0.
template <LinearOperator Op, Preconditioner Pre>
SolveResult conjugateGradient(const Op& A, const double* b, double* x, const Pre& M, const SolveOptions& opt = {}) {
  detail::checkSizes(A, M);
  SolveResult result;
  detail::InitialState state = detail::initialize(A, b, x, opt, result);
  if (state.finished) return result;
  result.status = detail::runConjugateGradient(A, M, opt, state, x, result);
  detail::finalize(A, state, x, opt, result);
  // The recursive residual can drift from the true one over thousands of iterations: confirm
  // convergence on ||b - A x|| and restart from x (r = b - A x, fresh directions) if it missed.
  for (int restart = 0; restart < 3 && result.converged() && !state.rule.converged(result.finalResidual); ++restart) {
    ++result.restarts;
    result.status = detail::runConjugateGradient(A, M, opt, state, x, result);  // state.r holds b - A x
    detail::finalize(A, state, x, opt, result);
  }
  if (result.converged() && !state.rule.converged(result.finalResidual)) result.status = Status::MaxIterations;
  return result;
}

// Right-preconditioned BiCGSTAB for general nonsingular A (van der Vorst 1992), with
// restarts on breakdown. Two applications of A and of M per iteration.
template <LinearOperator Op, Preconditioner Pre>
SolveResult bicgstab(const Op& A, const double* b, double* x, const Pre& M, const SolveOptions& opt = {}) {
  detail::checkSizes(A, M);
  SolveResult result;
  detail::InitialState state = detail::initialize(A, b, x, opt, result);
  if (state.finished) return result;
  detail::BiCgStab<Op, Pre> solver(A, M, opt, state, x, result);
  result.status = solver.run();
  detail::finalize(A, state, x, opt, result);
  return result;
}

}  // namespace krylov
}  // namespace stokes::solver
