#pragma once
// The order in which a distributed solve cuts a layout's blocks into one contiguous run per rank
// (docs/petsc.md, "Partition"): recursive coordinate bisection by active cells. A run of the
// order is then a compact box of blocks whose halo grows with its surface. Measured on the ball
// (bench/results/petsc.md; bisection by live rows), the halo rows summed over 4 / 8 / 16 ranks at
// n = 128 were 109 k / 170 k / 297 k, against 161 k / 332 k / 420 k for runs of the layout's own order (OpenVDB leaves, slabs
// across the liquid) and 159 k / 231 k / 345 k along a Morton curve (whose cuts fall inside its
// octants: 79 k against 55 k on 2 ranks).
#include <algorithm>
#include <array>
#include <cstdint>
#include <numeric>
#include <set>
#include <stdexcept>
#include <vector>

#include "sparse_grid/block_layout.h"

namespace stokes::sparse_grid {

/// Block indices ordered by recursive coordinate bisection of their work (`weight[b]`, active
/// cells): the blocks are split across the longest extent of their origins at the
/// weight's median, and each half is ordered the same way before the other, down to single blocks.
/// Any 2^k equal-weight runs of this order are the 2^k parts of the bisection, compact boxes whose
/// halo grows with their surface. Ties along the axis are broken by the other coordinates, so the
/// order is a function of the blocks and weights alone (whatever order they are listed in).
template <int Dim>
std::vector<std::size_t> bisectionBlockOrder(const std::vector<Coord>& origins, const std::vector<std::size_t>& weight) {
  const std::size_t nb = origins.size();
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
    Coord lo = origins[order[r.begin]], hi = lo;
    std::size_t total = 0;
    for (std::size_t i = r.begin; i < r.end; ++i) {
      lo = Coord::minComponent(lo, origins[order[i]]);
      hi = Coord::maxComponent(hi, origins[order[i]]);
      total += weight[order[i]];
    }
    int axis = 0;
    for (int a = 1; a < Dim; ++a)
      if (hi[a] - lo[a] > hi[axis] - lo[axis]) axis = a;
    const auto begin = order.begin() + std::ptrdiff_t(r.begin), end = order.begin() + std::ptrdiff_t(r.end);
    std::sort(begin, end, [&](std::size_t a, std::size_t b) {
      const Coord &p = origins[a], &q = origins[b];
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

/// The same over a layout's blocks.
template <int Dim>
std::vector<std::size_t> bisectionBlockOrder(const BlockLayout<Dim>& layout, const std::vector<std::size_t>& weight) {
  std::vector<Coord> origins(layout.numBlocks());
  for (std::size_t b = 0; b < origins.size(); ++b) origins[b] = layout.blockOrigin(b);
  return bisectionBlockOrder<Dim>(origins, weight);
}

/// The rank that owns each block: the bisection order cut into `ranks` contiguous runs of about
/// equal weight (active cells, the one measure every rank can count before it builds anything) (block b goes to the rank whose share [r W / R, (r + 1) W / R) of the total weight
/// W holds the weight before it). The one partition rule of the distributed solve.
template <int Dim>
std::vector<int> blockOwners(const std::vector<Coord>& origins, const std::vector<std::size_t>& weight, int ranks) {
  if (ranks < 1) throw std::invalid_argument("blockOwners: at least one rank");
  std::size_t total = 0;
  for (std::size_t w : weight) total += w;
  std::vector<int> owner(origins.size(), 0);
  std::size_t seen = 0;
  for (std::size_t b : bisectionBlockOrder<Dim>(origins, weight)) {
    owner[b] = int(std::min<std::size_t>(std::size_t(ranks) - 1, seen * std::size_t(ranks) / std::max<std::size_t>(1, total)));
    seen += weight[b];
  }
  return owner;
}

/// The owners of a layout's blocks, cut by active cells: the rule a problem set up per rank
/// follows before any system exists (it counts the cells it would activate), so that a whole
/// problem held by every rank is split the same way.
template <int Dim>
std::vector<int> blockOwners(const BlockLayout<Dim>& layout, int ranks) {
  std::vector<Coord> origins(layout.numBlocks());
  std::vector<std::size_t> cells(layout.numBlocks(), 0);
  for (std::size_t b = 0; b < origins.size(); ++b) {
    origins[b] = layout.blockOrigin(b);
    for (std::size_t s = b * BlockLayout<Dim>::kSlots; s < (b + 1) * BlockLayout<Dim>::kSlots; ++s)
      cells[b] += layout.isActiveCell(s) ? 1 : 0;
  }
  return blockOwners<Dim>(origins, cells, ranks);
}

/// Layers of blocks `width` cells wide that hold every cell within `depth` cells of a block.
inline int haloLayers(int depth, int width) { return std::max(1, (depth + width - 1) / width); }

/// Blocks a rank keeps besides its own: every block among `origins` that holds a cell within
/// `depth` cells of a block with owner `rank`, whole blocks (the (2 L + 1)^Dim neighbourhood,
/// L = haloLayers); `width` is the blocks' width in cells (the step between neighbouring origins).
/// One cell holds every sample a stencil of its rows reads; reduced tiles reach further
/// (solver::distributedTileDepth).
template <int Dim>
std::vector<std::uint8_t> haloBlocks(const std::vector<Coord>& origins, const std::vector<int>& owner, int rank,
                                     int width, int depth = 1) {
  const int layers = haloLayers(depth, width);
  std::set<std::array<int, 3>> own;
  for (std::size_t b = 0; b < origins.size(); ++b)
    if (owner[b] == rank) own.insert({origins[b][0], origins[b][1], origins[b][2]});
  const int side = 2 * layers + 1, codes = Dim == 3 ? side * side * side : side * side;
  std::vector<std::uint8_t> halo(origins.size(), 0);
  for (std::size_t b = 0; b < origins.size(); ++b) {
    if (owner[b] == rank) continue;
    for (int code = 0; code < codes && !halo[b]; ++code) {
      std::array<int, 3> o{origins[b][0], origins[b][1], origins[b][2]};
      int rest = code;
      for (int a = 0; a < Dim; ++a, rest /= side) o[a] += (rest % side - layers) * width;
      if (own.count(o)) halo[b] = 1;
    }
  }
  return halo;
}

}  // namespace stokes::sparse_grid
