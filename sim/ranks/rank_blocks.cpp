// The step's blocks over the ranks: see rank_blocks.h.
#include "sim/ranks/rank_blocks.h"

#include <algorithm>
#include <bit>
#include <numeric>

#include "sim/ranks/rank_comm.h"
#include "sparse_grid/block_order.h"

namespace stokes::sim {
inline namespace ranks {

namespace {

bool coordLess(const Coord& a, const Coord& b) {
  for (int k = 0; k < 3; ++k)
    if (a[k] != b[k]) return a[k] < b[k];
  return false;
}

Coord blockOriginOf(const Coord& c) { return Coord(c.x() & ~7, c.y() & ~7, c.z() & ~7); }

}  // namespace

std::int64_t RankBlocks::blockOf(const Coord& c) const {
  const Coord o = blockOriginOf(c);
  const auto it = std::lower_bound(origins.begin(), origins.end(), o, coordLess);
  return it != origins.end() && *it == o ? std::int64_t(it - origins.begin()) : -1;
}

int RankBlocks::ownerOfCell(const Coord& c) const {
  const std::int64_t b = blockOf(c);
  return b < 0 ? -1 : owner[std::size_t(b)];
}

std::size_t RankBlocks::activeCells(std::size_t b) const {
  std::size_t n = 0;
  for (std::uint64_t w : cells[b]) n += std::size_t(std::popcount(w));
  return n;
}

std::vector<std::uint8_t> RankBlocks::ownedAndHalo(int depth) const {
  std::vector<std::uint8_t> keep =
      sparse_grid::haloBlocks<3>(origins, owner, rank, sparse_grid::BlockLayout<3>::kWidth, depth);
  for (std::size_t b = 0; b < size(); ++b)
    if (owner[b] == rank) keep[b] = 1;
  return keep;
}

openvdb::MaskTree RankBlocks::mask(const std::vector<std::uint8_t>& keep) const {
  openvdb::MaskTree tree;
  openvdb::tree::ValueAccessor<openvdb::MaskTree> acc(tree);
  for (std::size_t b = 0; b < size(); ++b) {
    if (!keep[b]) continue;
    auto* leaf = acc.touchLeaf(origins[b]);
    auto& m = leaf->getValueMask();
    for (int w = 0; w < kWords; ++w) m.template getWord<std::uint64_t>(w) = cells[b][std::size_t(w)];
  }
  return tree;
}

RankBlocks gatherRankBlocks(const openvdb::MaskTree& localCells) {
  Bytes mine;
  for (auto leaf = localCells.cbeginLeaf(); leaf; ++leaf) {
    const Coord o = leaf->origin();
    for (int k = 0; k < 3; ++k) mine.put(std::int32_t(o[k]));
    const auto& m = leaf->getValueMask();
    for (int w = 0; w < RankBlocks::kWords; ++w) mine.put(m.template getWord<std::uint64_t>(w));
  }
  std::vector<std::pair<Coord, RankBlocks::CellMask>> all;
  for (Bytes& b : allGather(mine))
    while (!b.done()) {
      Coord o;
      for (int k = 0; k < 3; ++k) o[k] = b.get<std::int32_t>();
      RankBlocks::CellMask m;
      for (auto& w : m) w = b.get<std::uint64_t>();
      all.emplace_back(o, m);
    }
  std::sort(all.begin(), all.end(), [](const auto& a, const auto& b) { return coordLess(a.first, b.first); });

  RankBlocks out;
  out.rank = thisRank();
  for (const auto& [o, m] : all) {  // the union: a block marked by several ranks once, its masks or-ed
    if (out.origins.empty() || out.origins.back() != o) {
      out.origins.push_back(o);
      out.cells.push_back(m);
      continue;
    }
    for (int w = 0; w < RankBlocks::kWords; ++w) out.cells.back()[std::size_t(w)] |= m[std::size_t(w)];
  }
  std::vector<std::size_t> weight(out.size());
  for (std::size_t b = 0; b < out.size(); ++b) weight[b] = out.activeCells(b);
  out.owner = sparse_grid::blockOwners<3>(out.origins, weight, rankCount());
  return out;
}

}  // namespace ranks
}  // namespace stokes::sim
