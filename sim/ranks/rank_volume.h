#pragma once
// The liquid level set of a simulation split over ranks (docs/petsc.md, "Particles by block"):
// each rank builds it from its particles and the ghosts within reach, which makes it exact on the
// rank's own blocks; the volumes count each voxel on the rank that owns its cell, in exact sums
// (ExactSum), so the volume match finds the same offset for any rank count; the frames stream the
// owned narrow bands onto rank 0, leaf by leaf.
#include "sparse_grid/vdb_trees.h"

#include <functional>

#include "sim/geometry/geometry.h"
#include "sim/ranks/particle_exchange.h"
#include "sim/ranks/rank_blocks.h"

namespace stokes::sim {
inline namespace ranks {

/// Whether a voxel of a level set with transform `xform` counts on this rank: the owner of the
/// cell its centre lies in.
std::function<bool(const openvdb::Coord&)> ownedVoxels(const openvdb::math::Transform& xform, const RankBlocks& blocks,
                                                       const CellIndex& cellOf);

/// matchClippedVolume over all ranks: each rank's share of the clipped volume is its owned voxels'
/// (clippedVolumeTerms), summed exactly over the ranks for every trial offset. Collective.
VolumeMatch matchClippedVolumeOnRanks(openvdb::FloatGrid& grid, double target,
                                      const std::function<double(const Vec3d&)>& clip, double maxOffset,
                                      const std::function<bool(const openvdb::Coord&)>& owned);

/// levelSetVolumeClipped over all ranks (no clip: levelSetVolume), exactly summed. Collective.
double clippedVolumeOnRanks(const openvdb::FloatGrid& grid, const std::function<double(const Vec3d&)>& clip,
                            const std::function<bool(const openvdb::Coord&)>& owned);

/// The owned narrow band of every rank's level set on rank 0, its interior flood-filled: the whole
/// liquid (null on the other ranks). Each rank sends its leaves with owned active voxels (origin,
/// voxel mask, values: 4 bytes a voxel and 76 a leaf), and rank 0 takes them one rank at a time
/// (streamToRoot): it holds the band it writes and one rank's leaves. Collective.
openvdb::FloatGrid::Ptr gatherLevelSet(const openvdb::FloatGrid& grid,
                                       const std::function<bool(const openvdb::Coord&)>& owned);

}  // namespace ranks
}  // namespace stokes::sim
