#pragma once
// Per-slot values of whole blocks moved between ranks (docs/petsc.md, "Particles by block"):
//  - to the blocks' owners: the warm start of a run split over ranks. A rank holds the previous
//    step's solution exactly on the blocks it owned; when the owners change, the new owner of a
//    block receives it, so that every rank starts its part of the solve where one rank would;
//  - to every rank: the whole problem of a step with adaptive tiles.
#include <memory>
#include <vector>

#include "sim/ranks/rank_blocks.h"
#include "solver/krylov/aligned_vector.h"
#include "sparse_grid/block_layout.h"

namespace stokes::sim {
inline namespace ranks {

/// Values over the blocks of a layout (channel-major, channels x layout->numSlots()).
struct BlockValues {
  std::unique_ptr<sparse_grid::BlockLayout<3>> layout;
  solver::Vector values;
};

/// The blocks of `layout` (null: none) marked in `mine`, with their `values`, sent to their owners
/// in `now` (dropped where `now` has no such block): returns the blocks this rank owns in `now`
/// that some rank sent, on a layout of just those blocks with spacing dx and origin `origin` (null
/// when none). Collective. `sentBytes`, if given, receives what this rank sent the others.
BlockValues moveToOwners(const sparse_grid::BlockLayout<3>* layout, const solver::Vector& values,
                         const std::vector<std::uint8_t>& mine, const RankBlocks& now, double dx,
                         const openvdb::Vec3d& origin, std::size_t* sentBytes = nullptr);

/// The values of the blocks each rank owns (`local`, channel-major on layout `localLayout`),
/// gathered on every rank into `whole` on `wholeLayout`, a layout of all the step's blocks (a
/// step with adaptive tiles, whose split test reads the whole liquid, solves the whole problem on
/// every rank).
/// Every rank must hold the same number of channels. Collective. Returns the bytes this rank sent.
std::size_t gatherWholeValues(const sparse_grid::BlockLayout<3>& localLayout, const solver::Vector& local,
                              const RankBlocks& blocks, const sparse_grid::BlockLayout<3>& wholeLayout,
                              solver::Vector& whole);

}  // namespace ranks
}  // namespace stokes::sim
