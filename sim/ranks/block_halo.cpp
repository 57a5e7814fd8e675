// Halo values from their owners: see block_halo.h.
#include "sim/ranks/block_halo.h"

#include <algorithm>
#include <array>
#include <stdexcept>

#include "sim/ranks/rank_comm.h"
#include "sparse_grid/block_order.h"

namespace stokes::sim {
inline namespace ranks {

namespace {

using Layout = sparse_grid::BlockLayout<3>;

/// fn(origin) over the origins of the blocks within `layers` blocks of the block at `o` (itself
/// included), whether or not they exist.
template <class Fn>
void forEachNearOrigin(const Coord& o, int layers, Fn&& fn) {
  for (int dx = -layers; dx <= layers; ++dx)
    for (int dy = -layers; dy <= layers; ++dy)
      for (int dz = -layers; dz <= layers; ++dz)
        fn(o + Coord(dx * Layout::kWidth, dy * Layout::kWidth, dz * Layout::kWidth));
}

/// The slots of block `k` (of `blocks`) that rank r reads: active cells within `depth` cells
/// (Chebyshev distance) of a block r owns. Both sides list them in slot order.
std::vector<std::size_t> slotsRead(const RankBlocks& blocks, std::size_t k, int r, int depth) {
  const Coord o = blocks.origins[k];
  std::array<std::uint8_t, Layout::kSlots> near{};
  forEachNearOrigin(o, sparse_grid::haloLayers(depth, Layout::kWidth), [&](const Coord& q) {
    const std::int64_t b = blocks.blockOf(q);
    if (b < 0 || blocks.owner[std::size_t(b)] != r) return;
    // the cells of block k within depth of block q's box, as local ranges per axis
    int lo[3], hi[3];
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::max(0, q[a] - depth - o[a]);
      hi[a] = std::min(Layout::kWidth - 1, q[a] + Layout::kWidth - 1 + depth - o[a]);
    }
    for (int x = lo[0]; x <= hi[0]; ++x)
      for (int y = lo[1]; y <= hi[1]; ++y)
        for (int z = lo[2]; z <= hi[2]; ++z) near[std::size_t(Layout::localSlot(x, y, z))] = 1;
  });
  std::vector<std::size_t> slots;
  for (std::size_t s = 0; s < Layout::kSlots; ++s)
    if (near[s] && ((blocks.cells[k][s / 64] >> (s % 64)) & 1u)) slots.push_back(s);
  return slots;
}

}  // namespace

std::size_t exchangeHaloValues(const sparse_grid::BlockLayout<3>& layout, const RankBlocks& blocks,
                               const std::vector<solver::Vector*>& arrays, int depth) {
  const std::size_t n = layout.numSlots(), slots = Layout::kSlots;
  // each array as its channels: the values of channel c of array k start at starts[j]
  std::vector<double*> starts;
  for (solver::Vector* v : arrays) {
    if (v->size() % n != 0) throw std::invalid_argument("exchangeHaloValues: values per slot");
    for (std::size_t c = 0; c < v->size() / n; ++c) starts.push_back(v->data() + c * n);
  }
  std::vector<Bytes> out(static_cast<std::size_t>(rankCount()));
  std::vector<std::uint8_t> sent(out.size());
  for (std::size_t b = 0; b < layout.numBlocks(); ++b) {
    const Coord o = layout.blockOrigin(b);
    const std::int64_t k = blocks.blockOf(o);
    if (k < 0 || blocks.owner[std::size_t(k)] != blocks.rank) continue;
    std::fill(sent.begin(), sent.end(), 0);
    forEachNearOrigin(o, sparse_grid::haloLayers(depth, Layout::kWidth), [&](const Coord& near) {
      const std::int64_t q = blocks.blockOf(near);
      if (q < 0) return;
      const int r = blocks.owner[std::size_t(q)];
      if (r == blocks.rank || sent[std::size_t(r)]) return;
      sent[std::size_t(r)] = 1;
      Bytes& m = out[std::size_t(r)];
      m.put(o);
      for (std::size_t s : slotsRead(blocks, std::size_t(k), r, depth))
        for (double* channel : starts) m.put(channel[b * slots + s]);
    });
  }
  std::size_t bytes = 0;
  for (const Bytes& m : out) bytes += m.bytes().size();
  for (Bytes& in : exchange(out))
    while (!in.done()) {
      const Coord o = in.get<Coord>();
      const std::int32_t b = layout.blockAt(o);
      if (b < 0) throw std::runtime_error("exchangeHaloValues: a halo block this rank does not hold");
      for (std::size_t s : slotsRead(blocks, std::size_t(blocks.blockOf(o)), blocks.rank, depth))
        for (double* channel : starts) channel[std::size_t(b) * slots + s] = in.get<double>();
    }
  return bytes;
}

}  // namespace ranks
}  // namespace stokes::sim
