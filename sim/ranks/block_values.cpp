// Block values to their owners: see block_values.h.
#include "sim/ranks/block_values.h"

#include <algorithm>
#include <cstring>
#include <stdexcept>

#include "sim/ranks/rank_comm.h"

namespace stokes::sim {
inline namespace ranks {

BlockValues moveToOwners(const sparse_grid::BlockLayout<3>* layout, const solver::Vector& values,
                         const std::vector<std::uint8_t>& mine, const RankBlocks& now, double dx,
                         const openvdb::Vec3d& origin, std::size_t* sentBytes) {
  using Layout = sparse_grid::BlockLayout<3>;
  constexpr std::size_t kSlots = Layout::kSlots;
  std::vector<Bytes> out(static_cast<std::size_t>(rankCount()));
  if (layout) {
    const Layout& L = *layout;
    const std::size_t n = L.numSlots();
    if (n == 0 || values.size() % n != 0 || mine.size() != L.numBlocks())
      throw std::invalid_argument("moveToOwners: values per slot and a mark per block");
    const std::size_t channels = values.size() / n;
    for (std::size_t b = 0; b < L.numBlocks(); ++b) {
      if (!mine[b]) continue;
      const std::int64_t k = now.blockOf(L.blockOrigin(b));
      if (k < 0) continue;
      Bytes& m = out[std::size_t(now.owner[std::size_t(k)])];
      m.put(L.blockOrigin(b));
      m.put(std::uint32_t(channels));
      for (std::size_t c = 0; c < channels; ++c)
        for (std::size_t s = 0; s < kSlots; ++s) m.put(values[c * n + b * kSlots + s]);
    }
  }
  if (sentBytes) {
    *sentBytes = 0;
    for (std::size_t r = 0; r < out.size(); ++r)
      if (int(r) != now.rank) *sentBytes += out[r].bytes().size();
  }
  // the blocks received, all cells on (the values travel whole blocks)
  std::vector<std::pair<Coord, std::vector<double>>> blocks;
  std::size_t channels = 0;
  for (Bytes& in : exchange(out))
    while (!in.done()) {
      const Coord o = in.get<Coord>();
      channels = in.get<std::uint32_t>();
      std::vector<double> v(channels * kSlots);
      for (double& x : v) x = in.get<double>();
      blocks.emplace_back(o, std::move(v));
    }
  BlockValues to;
  if (blocks.empty()) return to;
  openvdb::MaskTree cells;
  for (const auto& [o, v] : blocks) cells.touchLeaf(o)->setValuesOn();
  to.layout = std::make_unique<Layout>(cells, dx, origin);
  const std::size_t n = to.layout->numSlots();
  to.values.assign(channels * n, 0.0);
  for (const auto& [o, v] : blocks) {
    const std::int32_t b = to.layout->blockAt(o);
    for (std::size_t c = 0; c < channels; ++c)
      for (std::size_t s = 0; s < kSlots; ++s) to.values[c * n + std::size_t(b) * kSlots + s] = v[c * kSlots + s];
  }
  return to;
}

std::size_t gatherWholeValues(const sparse_grid::BlockLayout<3>& localLayout, const solver::Vector& local,
                              const RankBlocks& blocks, const sparse_grid::BlockLayout<3>& wholeLayout,
                              solver::Vector& whole) {
  using Layout = sparse_grid::BlockLayout<3>;
  constexpr std::size_t kSlots = Layout::kSlots;
  const std::size_t n = localLayout.numSlots(), N = wholeLayout.numSlots();
  if (n == 0 || local.size() % n != 0) throw std::invalid_argument("gatherWholeValues: values per slot");
  const std::size_t channels = local.size() / n;
  // Sparse: per block and channel, the background (0 or 1, whichever most slots hold), a bitmap
  // of the slots that differ from it, and their values (weights are mostly 0 or 1; the whole
  // problem of the armadillos at res 192 with tiles went from 46-59 to 13-16 MB a step on 2 ranks).
  constexpr std::size_t kWords = kSlots / 64;
  Bytes mine;
  for (std::size_t b = 0; b < localLayout.numBlocks(); ++b) {
    const Coord o = localLayout.blockOrigin(b);
    if (blocks.ownerOfCell(o) != blocks.rank) continue;
    mine.put(o);
    for (std::size_t c = 0; c < channels; ++c) {
      const double* v = local.data() + c * n + b * kSlots;
      std::size_t ones = 0, zeros = 0;
      for (std::size_t s = 0; s < kSlots; ++s) {
        ones += v[s] == 1.0 ? 1 : 0;
        zeros += v[s] == 0.0 ? 1 : 0;
      }
      const double background = ones > zeros ? 1.0 : 0.0;
      std::uint64_t differs[kWords] = {};
      for (std::size_t s = 0; s < kSlots; ++s)
        if (std::memcmp(&v[s], &background, sizeof(double)) != 0) differs[s / 64] |= std::uint64_t(1) << (s % 64);
      mine.put(background);
      for (std::uint64_t w : differs) mine.put(w);
      for (std::size_t s = 0; s < kSlots; ++s)
        if (differs[s / 64] >> (s % 64) & 1u) mine.put(v[s]);
    }
  }
  whole.assign(channels * N, 0.0);
  for (Bytes& in : allGather(mine))
    while (!in.done()) {
      const std::int32_t b = wholeLayout.blockAt(in.get<Coord>());
      if (b < 0) throw std::runtime_error("gatherWholeValues: a block not in the step's layout");
      for (std::size_t c = 0; c < channels; ++c) {
        const double background = in.get<double>();
        std::uint64_t differs[kWords];
        for (std::uint64_t& w : differs) w = in.get<std::uint64_t>();
        double* v = whole.data() + c * N + std::size_t(b) * kSlots;
        for (std::size_t s = 0; s < kSlots; ++s) v[s] = differs[s / 64] >> (s % 64) & 1u ? in.get<double>() : background;
      }
    }
  return mine.bytes().size() * std::size_t(std::max(0, rankCount() - 1));
}

}  // namespace ranks
}  // namespace stokes::sim
