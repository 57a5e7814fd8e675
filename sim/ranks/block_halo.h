#pragma once
// Per-slot values of a rank's halo blocks from their owners (docs/petsc.md, "Particles by
// block"): after the solve a rank holds the velocities of its own blocks; G2P, the extrapolation
// and advection near its edge read the halo's too.
#include <vector>

#include "solver/krylov/aligned_vector.h"
#include "sim/ranks/rank_blocks.h"
#include "sparse_grid/block_layout.h"

namespace stokes::sim {
inline namespace ranks {

/// Overwrites the halo's values of each of `arrays` (channel-major, a whole number of channels of
/// layout.numSlots() each) with their owners': those of the active cells within `depth` cells
/// (along each axis) of this rank's blocks, the ones its stencils, tiles or later stages read.
/// `layout` holds this rank's blocks and their halo (RankBlocks::ownedAndHalo) to at least
/// `depth`. One message per rank for all the arrays. Collective. Returns the bytes
/// this rank sent.
std::size_t exchangeHaloValues(const sparse_grid::BlockLayout<3>& layout, const RankBlocks& blocks,
                               const std::vector<solver::Vector*>& arrays, int depth);

}  // namespace ranks
}  // namespace stokes::sim
