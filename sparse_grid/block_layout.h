#pragma once
// BlockLayout: the sparse topology every solver vector is laid out on.
//
// OpenVDB supplies the topology: a MaskTree of active cells (the z = 0 layer in 2D). Each of its
// leaf nodes (8^3 voxels) becomes a block of 8^Dim cells. Solver vectors are flat, 64-byte-aligned
// arrays numbered block by block ("leaf order"): slot = block * 8^Dim + local, with
// local = z + 8 y + 64 x in 3D and y + 8 x in 2D (the last axis contiguous, see localSlot). A cell's staggered samples (its lower faces, its centre, its lower
// edges/node) share the cell's slot, one array (channel) per sample kind.
//
// Inside the Krylov loop no ValueAccessor is used: stencils reach neighbouring blocks through the
// precomputed neighbour-block table (see halo.h). slotOf() reads a dense table of block indices
// over the blocks' bounding box (O(1): the particle stages call it per particle), or, where that box
// would hold more than kMaxDenseBlockIndex entries, the block-index tree.
#include "sparse_grid/vdb_trees.h"

#include <algorithm>
#include <array>
#include <cstdint>
#include <memory>
#include <vector>

#include "parallel/fork_policy.h"
#include "sparse_grid/stagger.h"

namespace stokes::sparse_grid {

using openvdb::Coord;
using openvdb::Vec3d;

/// Which slots a per-slot routine fills (volume fractions, P2G). ActiveCells: only the slots of
/// active cells, the rest are set to 0 without being computed -- exact when nothing reaches the
/// inactive ones, and on a sparse layout most slots are inactive padding.
enum class SlotsToFill { All, ActiveCells };

template <int Dim>
class BlockLayout {
 public:
  static_assert(Dim == 2 || Dim == 3, "StokesVDB supports 2D and 3D");
  static constexpr int kLog2Width = 3;
  static constexpr int kWidth = 1 << kLog2Width;            // 8 cells per block axis
  static constexpr int kSlots = 1 << (kLog2Width * Dim);     // 64 (2D) or 512 (3D)
  static constexpr int kNeighbourCodes = Dim == 2 ? 9 : 27;  // 3^Dim offsets in {-1,0,1}^Dim
  static constexpr int kSelfCode = Dim == 2 ? 4 : 13;

  BlockLayout() = default;

  /// Builds blocks covering every active voxel of `cells`. `dx` is the cell size and `origin` the
  /// world position of the lower corner of cell (0,0,0). In 2D only voxels with z = 0 are used.
  BlockLayout(const openvdb::MaskTree& cells, double dx, const Vec3d& origin = Vec3d(0.0))
      : dx_(dx), origin_(origin) {
    for (auto leaf = cells.cbeginLeaf(); leaf; ++leaf) {
      if (leaf->isEmpty()) continue;
      Coord o = leaf->origin();
      if (Dim == 2 && o.z() != 0) continue;
      blockOrigins_.push_back(o);
    }
    auto index = std::make_shared<openvdb::Int32Tree>(-1);
    for (std::size_t b = 0; b < blockOrigins_.size(); ++b)
      index->setValueOn(blockOrigins_[b], static_cast<std::int32_t>(b));
    blockIndex_ = std::move(index);
    buildDenseBlockIndex();
    buildNeighbourTable();
    buildActiveMask(cells);
  }

  double dx() const { return dx_; }
  const Vec3d& origin() const { return origin_; }
  std::size_t numBlocks() const { return blockOrigins_.size(); }
  std::size_t numSlots() const { return blockOrigins_.size() * kSlots; }
  const Coord& blockOrigin(std::size_t b) const { return blockOrigins_[b]; }
  /// Index of the block whose origin is `origin` (a multiple of kWidth per axis), or -1.
  std::int32_t blockAt(const Coord& origin) const { return blockIndexOf(origin); }

  /// Block index of the neighbour of block b at offset code (sum_a (d_a + 1) 3^a), or -1.
  std::int32_t neighbourBlock(std::size_t b, int code) const {
    return neighbours_[b * kNeighbourCodes + code];
  }
  const std::int32_t* neighbourTable() const { return neighbours_.data(); }

  /// True for cells that were active in the mask the layout was built from (the rest of a block is
  /// padding that carries zero weights).
  bool isActiveCell(std::size_t slot) const { return activeMask_[slot] != 0; }

  /// Block-local numbering with the LAST axis contiguous (z in 3D, y in 2D): OpenVDB orders its
  /// leaves with that axis fastest too, so the neighbour block along it is usually the adjacent
  /// one in memory (cache-hot) -- and that is the axis whose halo layer is strided.
  static constexpr int localSlot(int x, int y, int z = 0) {
    return Dim == 3 ? z + (y << kLog2Width) + (x << (2 * kLog2Width)) : y + (x << kLog2Width);
  }
  static Coord localCoord(int s) {
    const int m = kWidth - 1;
    if (Dim == 3) return Coord((s >> (2 * kLog2Width)) & m, (s >> kLog2Width) & m, s & m);
    return Coord((s >> kLog2Width) & m, s & m, 0);
  }
  Coord cellOf(std::size_t slot) const {
    return blockOrigins_[slot / kSlots] + localCoord(int(slot % kSlots));
  }

  /// Slot of cell c, or -1 if c is outside every block. Thread-safe.
  std::int64_t slotOf(const Coord& c) const {
    if (Dim == 2 && c.z() != 0) return -1;
    const Coord o = blockOriginOf(c);
    const std::int32_t b = blockIndexOf(o);
    if (b < 0) return -1;
    const Coord l = c - o;
    return std::int64_t(b) * kSlots + localSlot(l.x(), l.y(), l.z());
  }

  /// Slot of the cell one step from `slot` along `axis` (dir = +1 or -1), or -1. O(1), no accessor.
  std::int64_t neighbourSlot(std::size_t slot, int axis, int dir) const {
    const std::size_t b = slot / kSlots;
    Coord l = localCoord(int(slot % kSlots));
    l[axis] += dir;
    int code = 0, pow3 = 1;
    for (int a = 0; a < Dim; ++a, pow3 *= 3) {
      int off = 0;
      if (l[a] < 0) { off = -1; l[a] += kWidth; }
      else if (l[a] >= kWidth) { off = 1; l[a] -= kWidth; }
      code += (off + 1) * pow3;
    }
    const std::int32_t nb = neighbourBlock(b, code);
    if (nb < 0) return -1;
    return std::int64_t(nb) * kSlots + localSlot(l.x(), l.y(), l.z());
  }

  /// World position of the sample of kind `mask` belonging to cell `c`: the cell centre shifted by
  /// -dx/2 along every axis in the mask.
  Vec3d samplePosition(const Coord& c, StaggerMask mask) const {
    Vec3d p(0.0);
    for (int a = 0; a < Dim; ++a)
      p[a] = origin_[a] + dx_ * (double(c[a]) + ((mask >> a) & 1u ? 0.0 : 0.5));
    return p;
  }
  Vec3d samplePosition(std::size_t slot, StaggerMask mask) const {
    return samplePosition(cellOf(slot), mask);
  }

  static Coord blockOriginOf(const Coord& c) {
    const int m = ~(kWidth - 1);
    return Coord(c.x() & m, c.y() & m, Dim == 3 ? (c.z() & m) : 0);
  }

 private:
  /// Entries of the dense block index at most (4 bytes each): beyond, slotOf walks the tree.
  static constexpr std::size_t kMaxDenseBlockIndex = std::size_t(1) << 24;

  /// Index of the block at origin o (a multiple of kWidth per axis), or -1.
  std::int32_t blockIndexOf(const Coord& o) const {
    if (denseIndex_.empty()) return blockIndex_ ? blockIndex_->getValue(o) : -1;
    std::size_t k = 0;
    for (int a = 0; a < Dim; ++a) {
      const int i = (o[a] - denseLo_[a]) >> kLog2Width;
      if (i < 0 || i >= denseExtent_[a]) return -1;
      k = k * std::size_t(denseExtent_[a]) + std::size_t(i);
    }
    return denseIndex_[k];
  }
  void buildDenseBlockIndex() {
    if (blockOrigins_.empty()) return;
    Coord lo = blockOrigins_.front(), hi = lo;
    for (const Coord& o : blockOrigins_)
      for (int a = 0; a < Dim; ++a) lo[a] = std::min(lo[a], o[a]), hi[a] = std::max(hi[a], o[a]);
    std::size_t total = 1;
    for (int a = 0; a < Dim; ++a) {
      denseExtent_[a] = ((hi[a] - lo[a]) >> kLog2Width) + 1;
      total *= std::size_t(denseExtent_[a]);
    }
    if (total > kMaxDenseBlockIndex) return;
    denseLo_ = lo;
    denseIndex_.assign(total, -1);
    for (std::size_t b = 0; b < blockOrigins_.size(); ++b) {
      std::size_t k = 0;
      for (int a = 0; a < Dim; ++a)
        k = k * std::size_t(denseExtent_[a]) + std::size_t((blockOrigins_[b][a] - lo[a]) >> kLog2Width);
      denseIndex_[k] = std::int32_t(b);
    }
  }
  void buildNeighbourTable() {
    neighbours_.assign(numBlocks() * kNeighbourCodes, -1);
    openvdb::tree::ValueAccessor<const openvdb::Int32Tree> acc(*blockIndex_);
    for (std::size_t b = 0; b < numBlocks(); ++b) {
      for (int code = 0; code < kNeighbourCodes; ++code) {
        Coord o = blockOrigins_[b];
        int rest = code;
        for (int a = 0; a < Dim; ++a) {
          o[a] += (rest % 3 - 1) * kWidth;
          rest /= 3;
        }
        neighbours_[b * kNeighbourCodes + code] = acc.getValue(o);
      }
    }
  }
  void buildActiveMask(const openvdb::MaskTree& cells) {
    activeMask_.assign(numSlots(), 0);
    openvdb::tree::ValueAccessor<const openvdb::MaskTree> acc(cells);
    for (std::size_t s = 0; s < numSlots(); ++s) activeMask_[s] = acc.isValueOn(cellOf(s)) ? 1 : 0;
  }

  double dx_ = 1.0;
  Vec3d origin_{0.0};
  std::vector<Coord> blockOrigins_;
  std::shared_ptr<const openvdb::Int32Tree> blockIndex_;  // block origin -> block index
  std::vector<std::int32_t> denseIndex_;  // the same over the blocks' bounding box, first axis slowest
  Coord denseLo_{0, 0, 0};
  std::array<int, 3> denseExtent_{1, 1, 1};
  std::vector<std::int32_t> neighbours_;
  std::vector<std::uint8_t> activeMask_;
};

/// Adds every cell of the index box [lo, hi] (inclusive) to a mask tree (2D: use lo.z = hi.z = 0).
inline void activateBox(openvdb::MaskTree& tree, const Coord& lo, const Coord& hi) {
  tree.sparseFill(openvdb::CoordBBox(lo, hi), true, true);
  tree.voxelizeActiveTiles();
}

}  // namespace stokes::sparse_grid
