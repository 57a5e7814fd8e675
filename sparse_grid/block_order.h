#pragma once
// The order in which a distributed solve cuts a layout's blocks into one contiguous run per rank
// (docs/petsc.md, "Partition"): recursive coordinate bisection by live rows. A run of the order is
// then a compact box of blocks whose halo grows with its surface. Measured on the ball (bench/
// results/petsc.md), the halo rows summed over 4 / 8 / 16 ranks at n = 128 were 109 k / 170 k /
// 297 k, against 161 k / 332 k / 420 k for runs of the layout's own order (OpenVDB leaves, slabs
// across the liquid) and 159 k / 231 k / 345 k along a Morton curve (whose cuts fall inside its
// octants: 79 k against 55 k on 2 ranks).
#include <algorithm>
#include <cstdint>
#include <numeric>
#include <stdexcept>
#include <vector>

#include "sparse_grid/block_layout.h"

namespace stokes::sparse_grid {

/// The layout's block indices ordered by recursive coordinate bisection of their live rows
/// (`weight[b]`): the blocks are split across the longest extent of their origins at the weight's
/// median, and each half is ordered the same way before the other, down to single blocks. Any
/// 2^k equal-weight runs of this order are the 2^k parts of the bisection, compact boxes whose
/// halo grows with their surface. Ties along the axis are broken by the other coordinates, so the
/// order is a function of the blocks and weights alone.
template <int Dim>
std::vector<std::size_t> bisectionBlockOrder(const BlockLayout<Dim>& layout, const std::vector<std::size_t>& weight) {
  const std::size_t nb = layout.numBlocks();
  if (weight.size() != nb) throw std::invalid_argument("bisectionBlockOrder: one weight per block");
  std::vector<std::size_t> order(nb);
  std::iota(order.begin(), order.end(), std::size_t(0));
  struct Range {
    std::size_t begin, end;
  };
  std::vector<Range> pending{{0, nb}};
  while (!pending.empty()) {
    const Range r = pending.back();
    pending.pop_back();
    if (r.end - r.begin < 2) continue;
    Coord lo = layout.blockOrigin(order[r.begin]), hi = lo;
    std::size_t total = 0;
    for (std::size_t i = r.begin; i < r.end; ++i) {
      lo = Coord::minComponent(lo, layout.blockOrigin(order[i]));
      hi = Coord::maxComponent(hi, layout.blockOrigin(order[i]));
      total += weight[order[i]];
    }
    int axis = 0;
    for (int a = 1; a < Dim; ++a)
      if (hi[a] - lo[a] > hi[axis] - lo[axis]) axis = a;
    const auto begin = order.begin() + std::ptrdiff_t(r.begin), end = order.begin() + std::ptrdiff_t(r.end);
    std::sort(begin, end, [&](std::size_t a, std::size_t b) {
      const Coord &p = layout.blockOrigin(a), &q = layout.blockOrigin(b);
      for (int k = 0; k < 3; ++k) {
        const int c = (axis + k) % 3;
        if (p[c] != q[c]) return p[c] < q[c];
      }
      return false;
    });
    // the first block whose cumulative weight reaches half the range's (at least one block a side)
    std::size_t split = r.begin + 1, seen = weight[order[r.begin]];
    while (split + 1 < r.end && 2 * seen < total) seen += weight[order[split++]];
    pending.push_back({split, r.end});
    pending.push_back({r.begin, split});
  }
  return order;
}

}  // namespace stokes::sparse_grid
