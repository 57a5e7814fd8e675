#pragma once
// Per-slot values of whole blocks moved to the blocks' owners (docs/petsc.md, "Particles by
// block"): the warm start of a run split over ranks. A rank holds the previous step's solution
// exactly on the blocks it owned; when the owners change, the new owner of a block receives it, so
// that every rank starts its part of the solve from the values one rank would start from.
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

/// The blocks of `from` marked in `mine` (per block of from.layout), sent to their owners in `now`
/// (dropped where `now` has no such block): returns the blocks this rank owns in `now` that some
/// rank sent, on a layout of just those blocks with spacing dx and origin `origin` (null when
/// none). Collective. `sentBytes`, if given, receives what this rank sent the others.
BlockValues moveToOwners(const BlockValues& from, const std::vector<std::uint8_t>& mine, const RankBlocks& now,
                         double dx, const openvdb::Vec3d& origin, std::size_t* sentBytes = nullptr);

}  // namespace ranks
}  // namespace stokes::sim
