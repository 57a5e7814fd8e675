#pragma once
// The blocks of a step split over the ranks, known to every rank without any rank holding the
// step's particles or grid (docs/petsc.md, "Particles by block").
//
// Each rank marks the cells of its particles, dilated by the layout's band (the band mask a
// whole run builds from all particles), and sends the mask's 8^3 blocks -- origin and a 512-bit
// cell mask, 76 bytes a block -- to every rank. Their union is the whole layout's set of cells,
// so the owners (sparse_grid::blockOwners: recursive coordinate bisection by active cells) are
// the whole problem's partition, and each rank can build the layout of its own blocks and their
// halo bit for bit as the whole layout has them.
#include "sparse_grid/vdb_trees.h"

#include <array>
#include <cstdint>
#include <vector>

#include "sparse_grid/block_layout.h"

namespace stokes::sim {
inline namespace ranks {

using openvdb::Coord;

struct RankBlocks {
  static constexpr int kWords = 8;  ///< 64-bit words of a block's cell mask (8^3 cells)
  using CellMask = std::array<std::uint64_t, kWords>;

  std::vector<Coord> origins;      ///< every block of the step, sorted (x, then y, then z)
  std::vector<CellMask> cells;     ///< the active cells of each block (openvdb's leaf mask order)
  std::vector<int> owner;          ///< the rank that owns each block
  int rank = 0;                    ///< this rank

  std::size_t size() const { return origins.size(); }
  /// The block holding cell c, or -1 when no block does.
  std::int64_t blockOf(const Coord& c) const;
  /// The owner of the block holding cell c, or -1.
  int ownerOfCell(const Coord& c) const;
  /// Active cells of block b.
  std::size_t activeCells(std::size_t b) const;
  /// The blocks this rank owns and the blocks holding a cell within `depth` cells of them
  /// (sparse_grid::haloBlocks): the cells whose weights, u* and velocities the rank's part of the
  /// step needs.
  std::vector<std::uint8_t> ownedAndHalo(int depth = 1) const;
  /// The active cells of the blocks marked in `keep`, as a mask tree (BlockLayout's input).
  openvdb::MaskTree mask(const std::vector<std::uint8_t>& keep) const;
};

/// Gathers every rank's band of cells (`localCells`: this rank's particles' cells, dilated and
/// clipped as the whole layout's) and cuts the union among the ranks. Collective.
RankBlocks gatherRankBlocks(const openvdb::MaskTree& localCells);

}  // namespace ranks
}  // namespace stokes::sim
