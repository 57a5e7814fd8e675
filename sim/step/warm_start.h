#pragma once
// Warm start of the SPD solves across time steps.
//
// The pressure-stress unknowns x = [p | tau] of unified Stokes (and p of the pressure projection)
// are the pressure and the viscous stress themselves (u = u* - dt (rho W_L^u)^-1 K x,
// pressure_stress_system.h), not impulses: in a viscous liquid they change little from one step to
// the next. The previous step's x, moved to the new step's cells, is the Krylov initial guess; the
// stopping rule stays ||r|| <= tol ||b||, so the answer meets the same tolerance and only the
// iterations change. Every step rebuilds its layout: values move by cell, block by block (both
// layouts cut the same 8^3-aligned blocks out of the domain), and cells new to the layout start at 0.
#include <cstddef>
#include <cstdint>
#include <memory>

#include "solver/krylov/aligned_vector.h"
#include "sparse_grid/block_layout.h"

namespace stokes::sim {
inline namespace step {

template <int Dim>
class WarmStart {
 public:
  using Layout = sparse_grid::BlockLayout<Dim>;

  /// Keeps one step's solution: `channels` blocks of layout->numSlots() values each (1 + the
  /// stress channels for unified Stokes, 1 for the projection).
  void keep(std::unique_ptr<Layout> layout, solver::Vector solution) {
    if (!layout || solution.empty() || solution.size() % layout->numSlots() != 0) {
      clear();
      return;
    }
    layout_ = std::move(layout);
    solution_ = std::move(solution);
  }

  void clear() {
    layout_.reset();
    solution_.clear();
  }

  /// What is kept, for a checkpoint (sim/run/checkpoint.h): the layout (null when nothing is kept)
  /// and its solution. keep(copy of the layout, solution) restores it bit for bit.
  const Layout* layout() const { return layout_.get(); }
  const solver::Vector& solution() const { return solution_; }

  /// The kept solution on `layout`'s slots, `channels` blocks; empty when nothing with that many
  /// channels is kept (the first step, or a solve of another kind).
  solver::Vector guessFor(const Layout& layout, std::size_t channels) const {
    if (!layout_ || solution_.size() != channels * layout_->numSlots()) return {};
    constexpr std::size_t kSlots = Layout::kSlots;
    const std::size_t n = layout.numSlots(), oldN = layout_->numSlots();
    solver::Vector guess(channels * n, 0.0);
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t b = 0; b < std::ptrdiff_t(layout.numBlocks()); ++b) {
      const std::int64_t oldSlot = layout_->slotOf(layout.blockOrigin(std::size_t(b)));
      if (oldSlot < 0) continue;
      for (std::size_t c = 0; c < channels; ++c) {
        const double* from = solution_.data() + c * oldN + std::size_t(oldSlot);
        double* to = guess.data() + c * n + std::size_t(b) * kSlots;
        for (std::size_t s = 0; s < kSlots; ++s) to[s] = from[s];
      }
    }
    return guess;
  }

 private:
  std::unique_ptr<Layout> layout_;
  solver::Vector solution_;
};

}  // namespace step
}  // namespace stokes::sim
