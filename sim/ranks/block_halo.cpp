// Halo values from their owners: see block_halo.h.
#include "sim/ranks/block_halo.h"

#include <algorithm>
#include <stdexcept>

#include "sim/ranks/rank_comm.h"

namespace stokes::sim {
inline namespace ranks {

namespace {

using Layout = sparse_grid::BlockLayout<3>;

/// The slots of block `k` (of `blocks`) that rank r reads: active cells within `depth` cells of a
/// block r owns. Both sides list them in slot order.
std::vector<std::size_t> slotsRead(const RankBlocks& blocks, std::size_t k, int r, int depth) {
  const Coord o = blocks.origins[k];
  std::vector<Coord> near;  // r's blocks around block k
  for (int dx = -1; dx <= 1; ++dx)
    for (int dy = -1; dy <= 1; ++dy)
      for (int dz = -1; dz <= 1; ++dz) {
        const Coord q = o + Coord(dx * Layout::kWidth, dy * Layout::kWidth, dz * Layout::kWidth);
        const std::int64_t b = blocks.blockOf(q);
        if (b >= 0 && blocks.owner[std::size_t(b)] == r) near.push_back(q);
      }
  std::vector<std::size_t> slots;
  for (std::size_t s = 0; s < Layout::kSlots; ++s) {
    if (!((blocks.cells[k][s / 64] >> (s % 64)) & 1u)) continue;
    const Coord c = o + Layout::localCoord(int(s));
    for (const Coord& q : near) {
      int d = 0;
      for (int a = 0; a < 3; ++a) d = std::max(d, std::max(q[a] - c[a], c[a] - (q[a] + Layout::kWidth - 1)));
      if (d <= depth) {
        slots.push_back(s);
        break;
      }
    }
  }
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
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dz = -1; dz <= 1; ++dz) {
          const std::int64_t q = blocks.blockOf(o + Coord(dx * Layout::kWidth, dy * Layout::kWidth, dz * Layout::kWidth));
          if (q < 0) continue;
          const int r = blocks.owner[std::size_t(q)];
          if (r == blocks.rank || sent[std::size_t(r)]) continue;
          sent[std::size_t(r)] = 1;
          Bytes& m = out[std::size_t(r)];
          m.put(o);
          for (std::size_t s : slotsRead(blocks, std::size_t(k), r, depth))
            for (double* channel : starts) m.put(channel[b * slots + s]);
        }
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
