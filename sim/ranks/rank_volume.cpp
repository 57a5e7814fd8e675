// The level set over ranks: see rank_volume.h.
#include "sim/ranks/rank_volume.h"

#include <openvdb/tools/Prune.h>
#include <openvdb/tools/SignedFloodFill.h>

#include <limits>
#include <utility>

#include "sim/ranks/exact_sum.h"
#include "sim/ranks/rank_comm.h"

namespace stokes::sim {
inline namespace ranks {

namespace {

double clippedSum(const ClippedVolumeTerms& t, double c) {
  ExactSum sum;
  sum.addWhole(t.full);
  t.forEachFraction(c, [&](double f) { sum.add(f); });
  return sum.overRanks().value() * t.voxelVolume;
}

}  // namespace

std::function<bool(const openvdb::Coord&)> ownedVoxels(const openvdb::math::Transform& xform, const RankBlocks& blocks,
                                                       const CellIndex& cellOf) {
  return [xform = xform.copy(), &blocks, cellOf](const openvdb::Coord& ijk) {
    return blocks.ownerOfCell(cellOf(xform->indexToWorld(ijk))) == blocks.rank;
  };
}

VolumeMatch matchClippedVolumeOnRanks(openvdb::FloatGrid& grid, double target,
                                      const std::function<double(const Vec3d&)>& clip, double maxOffset,
                                      const std::function<bool(const openvdb::Coord&)>& owned) {
  const ClippedVolumeTerms terms = clippedVolumeTerms(grid, clip, maxOffset, owned);
  return matchVolume(grid, target, maxOffset, [&](double c) { return clippedSum(terms, c); });
}

double clippedVolumeOnRanks(const openvdb::FloatGrid& grid, const std::function<double(const Vec3d&)>& clip,
                            const std::function<bool(const openvdb::Coord&)>& owned) {
  const auto none = [](const Vec3d&) { return -std::numeric_limits<double>::infinity(); };
  return clippedSum(clippedVolumeTerms(grid, clip ? clip : none, 0.0, owned), 0.0);
}

openvdb::FloatGrid::Ptr gatherLevelSet(const openvdb::FloatGrid& grid,
                                       const std::function<bool(const openvdb::Coord&)>& owned) {
  // a record per leaf with owned active voxels: origin, the mask of those voxels, their values
  using Leaf = openvdb::FloatTree::LeafNodeType;
  constexpr std::size_t kWords = Leaf::SIZE / 64;
  Bytes mine;
  std::vector<float> values;
  for (auto leaf = grid.tree().cbeginLeaf(); leaf; ++leaf) {
    std::uint64_t mask[kWords] = {};
    values.clear();
    for (auto v = leaf->cbeginValueOn(); v; ++v)
      if (owned(v.getCoord())) {
        mask[v.pos() / 64] |= std::uint64_t(1) << (v.pos() % 64);
        values.push_back(*v);
      }
    if (values.empty()) continue;
    for (int k = 0; k < 3; ++k) mine.put(std::int32_t(leaf->origin()[k]));
    for (std::uint64_t w : mask) mine.put(w);
    for (float f : values) mine.put(f);
  }
  openvdb::FloatGrid::Ptr whole;
  if (thisRank() == 0) {
    whole = openvdb::FloatGrid::create(grid.background());
    whole->setTransform(grid.transform().copy());
    whole->setGridClass(grid.getGridClass());
    whole->setName(grid.getName());
  }
  streamToRoot(std::move(mine), [&](Bytes& b) {
    while (!b.done()) {
      openvdb::Coord origin;
      for (int k = 0; k < 3; ++k) origin[k] = b.get<std::int32_t>();
      std::uint64_t mask[kWords];
      for (std::uint64_t& w : mask) w = b.get<std::uint64_t>();
      Leaf* leaf = whole->tree().touchLeaf(origin);
      for (std::size_t i = 0; i < Leaf::SIZE; ++i)
        if (mask[i / 64] >> (i % 64) & 1) leaf->setValueOn(openvdb::Index(i), b.get<float>());
    }
  });
  if (!whole) return nullptr;
  openvdb::tools::signedFloodFill(whole->tree());
  openvdb::tools::pruneLevelSet(whole->tree());
  return whole;
}

}  // namespace ranks
}  // namespace stokes::sim
