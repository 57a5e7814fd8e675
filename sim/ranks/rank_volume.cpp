// The level set over ranks: see rank_volume.h.
#include "sim/ranks/rank_volume.h"

#include <openvdb/tools/Prune.h>
#include <openvdb/tools/SignedFloodFill.h>

#include <limits>

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
  Bytes mine;
  for (auto leaf = grid.tree().cbeginLeaf(); leaf; ++leaf)
    for (auto v = leaf->cbeginValueOn(); v; ++v)
      if (owned(v.getCoord())) {
        const openvdb::Coord c = v.getCoord();
        for (int k = 0; k < 3; ++k) mine.put(std::int32_t(c[k]));
        mine.put(float(*v));
      }
  std::vector<Bytes> all = gatherOnRoot(mine);
  if (thisRank() != 0) return nullptr;
  openvdb::FloatGrid::Ptr whole = openvdb::FloatGrid::create(grid.background());
  whole->setTransform(grid.transform().copy());
  whole->setGridClass(grid.getGridClass());
  whole->setName(grid.getName());
  openvdb::tree::ValueAccessor<openvdb::FloatTree> acc(whole->tree());
  for (Bytes& b : all)
    while (!b.done()) {
      openvdb::Coord c;
      for (int k = 0; k < 3; ++k) c[k] = b.get<std::int32_t>();
      acc.setValueOn(c, b.get<float>());
    }
  openvdb::tools::signedFloodFill(whole->tree());
  openvdb::tools::pruneLevelSet(whole->tree());
  return whole;
}

}  // namespace ranks
}  // namespace stokes::sim
