#pragma once
// Compact rows: a Krylov solve over only the rows of an operator that are unknowns.
//
// A system stored on a padded layout has N rows, of which only the set R (|R| = m) are unknowns;
// the others are identically zero rows and columns (padding slots, dry samples). With the N x m
// selection matrix P (P x puts x_k at row R_k and zero elsewhere) the compact operator is
//
//   A_R = P^T A P,   b_R = P^T b,   M_R^-1 = P^T M^-1 P,   x = P x_R,
//
// which has the same non-zero spectrum as A on span(P), so a Krylov method on A_R takes the same
// steps as on A (up to rounding) while every vector operation streams m entries instead of N.
// The wrapped operator still applies on padded vectors; if it offers applyOnRows(x, y) (writes
// y = A x on the rows R and may skip the rest), that cheaper apply is used.
//
// The Krylov layer knows nothing of grids: R is any sorted list of row indices.

#include <cstdint>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "solver/krylov/aligned_vector.h"
#include "solver/krylov/operator.h"
#include "solver/krylov/vector_ops.h"

namespace stokes::solver {
inline namespace krylov {

/// The rows R of a padded vector of length fullSize that carry unknowns (strictly increasing).
class RowSelection {
 public:
  using Index = std::uint32_t;

  RowSelection(std::vector<Index> rows, std::size_t fullSize) : rows_(std::move(rows)), fullSize_(fullSize) {
    if (fullSize_ > std::size_t(UINT32_MAX))
      throw std::invalid_argument("RowSelection: " + std::to_string(fullSize_) + " padded rows exceed 32-bit indices");
    for (std::size_t k = 0; k < rows_.size(); ++k)
      if (rows_[k] >= fullSize_ || (k > 0 && rows_[k] <= rows_[k - 1]))
        throw std::invalid_argument("RowSelection: rows must be increasing and below " + std::to_string(fullSize_));
  }

  /// The rows whose diagonal entry is positive: for a symmetric positive semi-definite A a zero
  /// diagonal entry means a zero row and column, so these are exactly the live rows.
  static RowSelection positiveDiagonal(std::span<const double> diagonal) {
    std::vector<Index> rows;
    for (std::size_t i = 0; i < diagonal.size(); ++i)
      if (diagonal[i] > 0.0) rows.push_back(Index(i));
    return RowSelection(std::move(rows), diagonal.size());
  }

  std::size_t size() const noexcept { return rows_.size(); }
  std::size_t fullSize() const noexcept { return fullSize_; }
  const std::vector<Index>& rows() const noexcept { return rows_; }

  /// compact_k = full[R_k]  (P^T full).
  void gather(const double* full, double* compact) const {
    const Index* r = rows_.data();
    forRows([=](std::ptrdiff_t k) { compact[k] = full[r[k]]; });
  }
  /// full[R_k] = compact_k; the other entries of full are left as they are.
  void scatter(const double* compact, double* full) const {
    const Index* r = rows_.data();
    forRows([=](std::ptrdiff_t k) { full[r[k]] = compact[k]; });
  }
  Vector gathered(std::span<const double> full) const {
    Vector c(size());
    gather(full.data(), c.data());
    return c;
  }
  /// P x: a padded vector, zero off R.
  Vector expanded(const double* compact) const {
    Vector full(fullSize_, 0.0);
    scatter(compact, full.data());
    return full;
  }

 private:
  /// A gather or scatter moves 20 bytes per row; below kSerialRows rows one thread does it faster
  /// than a fork-join costs (passive wait policy: tens of us per region; default scene, 19,000
  /// rows, 2 threads: see bench/results/compact_rows.md).
  static constexpr std::size_t kSerialRows = 1 << 16;
  template <class Body>
  void forRows(Body body) const {
    if (size() < kSerialRows) {
      for (std::size_t k = 0; k < size(); ++k) body(std::ptrdiff_t(k));
    } else {
      detail::parallelFor(size(), body);
    }
  }

  std::vector<Index> rows_;
  std::size_t fullSize_;
};

/// An operator that can apply itself on its live rows only (y is only defined on those rows).
template <class A>
concept RowRestrictedOperator = LinearOperator<A> && requires(const A& op, const double* x, double* y) {
  op.applyOnRows(x, y);
};

/// A_R = P^T A P for an operator A on padded vectors (or M_R^-1 = P^T M^-1 P for a preconditioner).
/// A and the selection must outlive it.
template <LinearOperator Op>
class CompactOperator {
 public:
  CompactOperator(const Op& op, const RowSelection& rows)
      : op_(&op), rows_(&rows), xFull_(op.size(), 0.0), yFull_(op.size(), 0.0) {
    if (rows.fullSize() != op.size())
      throw std::invalid_argument("CompactOperator: selection of " + std::to_string(rows.fullSize()) +
                                  " rows for an operator of size " + std::to_string(op.size()));
  }

  std::size_t size() const noexcept { return rows_->size(); }

  /// y = P^T A P x. xFull_ is zero off R from construction on, and only R is ever written.
  void apply(const double* x, double* y) const {
    rows_->scatter(x, xFull_.data());
    if constexpr (RowRestrictedOperator<Op>) op_->applyOnRows(xFull_.data(), yFull_.data());
    else op_->apply(xFull_.data(), yFull_.data());
    rows_->gather(yFull_.data(), y);
  }

 private:
  const Op* op_;
  const RowSelection* rows_;
  mutable Vector xFull_, yFull_;
};

/// M_R^-1 = P^T M^-1 P for a preconditioner on padded vectors (for instance a multigrid cycle):
/// the same restriction, as a preconditioner has the operator's interface.
template <Preconditioner Pre>
using CompactPreconditioner = CompactOperator<Pre>;

}  // namespace krylov
}  // namespace stokes::solver
