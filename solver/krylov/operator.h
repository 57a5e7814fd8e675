#pragma once
// Operator and preconditioner concepts for the matrix-free Krylov layer.
//
// The solvers see a linear map only through y = A x on raw, contiguous arrays of
// length size(); they know nothing about grids or storage formats.

#include <cmath>
#include <concepts>
#include <cstddef>
#include <limits>
#include <span>

#include "solver/krylov/aligned_vector.h"
#include "solver/krylov/vector_ops.h"

namespace stokes::solver {
inline namespace krylov {

// y = A x for x, y of length A.size(); x and y never alias.
template <class A>
concept LinearOperator = requires(const A& op, const double* x, double* y) {
  { op.size() } -> std::convertible_to<std::size_t>;
  op.apply(x, y);
};

// z = M^-1 r, an approximate inverse of the operator; same interface as LinearOperator.
template <class M>
concept Preconditioner = requires(const M& pre, const double* r, double* z) {
  { pre.size() } -> std::convertible_to<std::size_t>;
  pre.apply(r, z);
};

// z = r  (M = I: no preconditioning).
struct IdentityPreconditioner {
  std::size_t n = 0;

  std::size_t size() const noexcept { return n; }
  void apply(const double* r, double* z) const { copy(r, z, n); }
};

// Diagonal (Jacobi) preconditioner, M = D = diag(A):
//   z = D^-1 r,  i.e.  z_i = r_i / d_i   if |d_i| > tiny,
//                      z_i = 0           otherwise.
// A (numerically) zero diagonal entry marks an inactive DOF whose row of A is
// identically zero; mapping it to zero keeps such DOFs out of the Krylov space.
class JacobiPreconditioner {
 public:
  // Default threshold: the smallest normal double, so any genuine diagonal is kept.
  static constexpr double kDefaultTiny = std::numeric_limits<double>::min();

  // Accepts a Vector, a std::vector<double> or any contiguous range of doubles.
  explicit JacobiPreconditioner(std::span<const double> diagonal, double tiny = kDefaultTiny)
      : inverseDiagonal_(diagonal.size()) {
    for (std::size_t i = 0; i < diagonal.size(); ++i) inverseDiagonal_[i] = invertEntry(diagonal[i], tiny);
  }

  std::size_t size() const noexcept { return inverseDiagonal_.size(); }

  // z = D^-1 r; inactive rows (stored 1/d = 0) give exactly z_i = +0, whatever r_i holds.
  void apply(const double* r, double* z) const { applyRows(r, z, 0, size()); }
  // The same on rows [begin, end) only (a block of a block-diagonal preconditioner).
  void applyRows(const double* r, double* z, std::size_t begin, std::size_t end) const {
    const double* inv = inverseDiagonal_.data() + begin;
    r += begin;
    z += begin;
    detail::parallelFor(end - begin, [=](std::ptrdiff_t i) { z[i] = inv[i] != 0.0 ? inv[i] * r[i] : 0.0; });
  }

  const Vector& inverseDiagonal() const noexcept { return inverseDiagonal_; }

 private:
  // 1/d for an active diagonal entry, 0 for an inactive (zero or non-finite) one.
  static double invertEntry(double d, double tiny) noexcept {
    const bool active = std::abs(d) > tiny && std::isfinite(d);
    return active ? 1.0 / d : 0.0;
  }

  Vector inverseDiagonal_;
};

// A preconditioner that is a diagonal, z = dinv r: the Krylov loops may fuse it into their
// vector updates (cgUpdateDiagonal). dinv_i = 0 marks an inactive row.
template <class M>
concept DiagonalPreconditioner = Preconditioner<M> && requires(const M& pre) {
  { pre.inverseDiagonal().data() } -> std::convertible_to<const double*>;
};

static_assert(Preconditioner<IdentityPreconditioner>);
static_assert(DiagonalPreconditioner<JacobiPreconditioner>);
static_assert(Preconditioner<JacobiPreconditioner>);

}  // namespace krylov
}  // namespace stokes::solver
