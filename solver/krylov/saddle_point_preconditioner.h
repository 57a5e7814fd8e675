#pragma once
// Block preconditioners of a saddle point K = [A  B^T; B  0] whose leading `split` rows are the
// primal block A (velocities) and whose trailing rows are the constraints B (pressures,
// multipliers), built from approximations A_hat^-1 (the leading rows of M) and S_hat^-1 (its
// trailing rows) of A^-1 and of the Schur complement S = B A^-1 B^T (Elman, Silvester & Wathen,
// "Finite Elements and Fast Iterative Solvers", 2nd ed. 2014, ch. 9; Cai, Nonaka, Bell, Griffith &
// Donev 2014, "Efficient variable-coefficient finite-volume Stokes solvers"):
//
//   Diagonal         P = diag(A_hat, S_hat):   z = [A_hat^-1 r_u ; S_hat^-1 r_c]. SPD if both
//                    parts are: the preconditioner MINRES needs. With exact blocks P^-1 K has the
//                    eigenvalues 1 and (1 +- sqrt(5)) / 2 (Murphy, Golub & Wathen 2000), and with
//                    S_hat of condition kappa the two intervals [-1, -1/kappa-ish] u [1, 2] cost
//                    MINRES about as much as CG costs on a condition number of ~4 kappa.
//   UpperTriangular  P = [A_hat  B^T; 0  -S_hat], applied on the right:
//                        z_c = -S_hat^-1 r_c,   z_u = A_hat^-1 (r_u - B^T z_c).
//                    K P^-1 = [A A_hat^-1, (I - A A_hat^-1) B^T S_hat^-1; B A_hat^-1, S S_hat^-1]:
//                    with A_hat = A its eigenvalues are 1 and those of S S_hat^-1, so GMRES
//                    converges as CG would on S_hat^-1 S (one extra step for the unit block).
//                    Nonsymmetric: a flexible or right-preconditioned GMRES (fgmres.h).
//
// B^T z_c is taken from K itself, K [0; z_c] = [B^T z_c; 0] (the constraint block is zero), so
// the triangular form costs one more apply of K per preconditioning and needs nothing of K's
// structure beyond the split. M must apply its two parts separately: `applyRows(r, z, begin, end)`
// writes z on rows [begin, end) from r on those rows only (M block diagonal across the split).
#include <concepts>
#include <cstddef>
#include <stdexcept>

#include "solver/krylov/operator.h"

namespace stokes::solver {
inline namespace krylov {

enum class SaddlePointBlocks { Diagonal, UpperTriangular };

/// A preconditioner that is block diagonal across a split of its rows and applies each part alone.
template <class M>
concept SplitPreconditioner = Preconditioner<M> && requires(const M& m, const double* r, double* z, std::size_t i) {
  m.applyRows(r, z, i, i);
};

template <LinearOperator Op, SplitPreconditioner M>
class SaddlePointPreconditioner {
 public:
  /// K the whole operator, m the block-diagonal approximation diag(A_hat, S_hat), split the first
  /// constraint row. K and m are referenced, not copied.
  SaddlePointPreconditioner(const Op& K, const M& m, std::size_t split, SaddlePointBlocks blocks)
      : K_(K), m_(m), split_(split), blocks_(blocks) {
    if (K.size() != m.size() || split > K.size())
      throw std::invalid_argument("SaddlePointPreconditioner: operator, preconditioner and split disagree");
    if (blocks == SaddlePointBlocks::UpperTriangular) {
      lifted_.assign(K.size(), 0.0);
      image_.resize(K.size());
    }
  }

  std::size_t size() const { return K_.size(); }
  SaddlePointBlocks blocks() const { return blocks_; }

  void apply(const double* r, double* z) const {
    if (blocks_ == SaddlePointBlocks::Diagonal) {
      m_.apply(r, z);
      return;
    }
    const std::size_t n = size();
    // z_c = -S_hat^-1 r_c, kept in lifted_ = [0 ; z_c] for B^T z_c = (K lifted_)_u
    m_.applyRows(r, lifted_.data(), split_, n);
    double* lifted = lifted_.data() + split_;
    double* zc = z + split_;
    detail::parallelFor(n - split_, [=](std::ptrdiff_t i) {
      lifted[i] = -lifted[i];
      zc[i] = lifted[i];
    });
    K_.apply(lifted_.data(), image_.data());
    // image_u <- r_u - B^T z_c, then z_u = A_hat^-1 image_u
    double* w = image_.data();
    detail::parallelFor(split_, [=](std::ptrdiff_t i) { w[i] = r[i] - w[i]; });
    m_.applyRows(image_.data(), z, 0, split_);
  }

 private:
  const Op& K_;
  const M& m_;
  std::size_t split_;
  SaddlePointBlocks blocks_;
  mutable Vector lifted_, image_;  // work vectors of the triangular apply (apply is not re-entrant)
};

}  // namespace krylov
}  // namespace stokes::solver
