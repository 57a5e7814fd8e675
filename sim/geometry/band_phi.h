#pragma once
// BandPhi: a level set sampled as GridPhi samples it (trilinear, openvdb::tools::BoxSampler's
// corners and interpolation, the same bits), with the voxels near a BlockLayout's cells copied
// once into a flat array per block, so that the many samples of the volume weights (10-27 per
// control volume) read eight floats from one small array instead of walking the tree.
//
// Block b of the layout, cells o .. o + 7 per axis, keeps the voxels o + s - 1 .. o + s + 8
// (10^3 floats), s the layout's origin in cells (the level set's voxel v is the layout's cell
// v - s; cellCentredTransform). A sample whose corners floor(ijk) .. floor(ijk) + 1 lie in that box
// of the block holding cell floor(ijk) - s + 1 reads them there; the others (outside the layout,
// or a layout origin that is not a whole number of cells) go to the GridPhi it holds. Built in
// parallel over blocks; reads are const and thread-safe.
#include "sparse_grid/vdb_trees.h"

#include <cstdint>
#include <vector>

#include "sim/geometry/geometry.h"
#include "sparse_grid/block_layout.h"

namespace stokes::sim {
inline namespace geometry {

class BandPhi {
 public:
  using Layout = sparse_grid::BlockLayout<3>;
  static constexpr int kSide = Layout::kWidth + 2;  ///< voxels kept per axis and block
  static constexpr int kBlockVoxels = kSide * kSide * kSide;

  /// `grid` must have the layout's voxel size and outlive nothing: the BandPhi holds it.
  BandPhi(openvdb::FloatGrid::ConstPtr grid, const Layout& layout);

  double operator()(const Vec3d& worldPos) const;

  /// Whether the per-block copies are used (false: every sample goes to GridPhi).
  bool cached() const { return !values_.empty(); }

 private:
  GridPhi gridPhi_;
  const Layout* layout_;
  openvdb::Coord shift_{0, 0, 0};  ///< the layout's origin in cells
  std::vector<float> values_;       ///< kBlockVoxels per block, x slowest
};

}  // namespace geometry
}  // namespace stokes::sim
