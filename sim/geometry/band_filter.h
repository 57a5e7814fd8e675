#pragma once
// BandFilter: OpenVDB's narrow-band level-set filters (openvdb::tools::LevelSetFilter's
// meanCurvature() and offset(), each followed by LevelSetTracker::track()) with the same arithmetic
// in the same order, so the same bits, but with every stencil read from a padded copy of its leaf
// instead of a tree accessor per sample.
//
// The steps, phi the float values of the active voxels, dx the voxel size (all in float unless
// stated, as OpenVDB computes them):
//   mean curvature  phi += dx^2/3 kappa |grad phi|, the 19-point central differences of
//                   openvdb::math::CurvatureStencil::meanCurvatureNormGrad (in double), then track;
//   offset(d)       in steps of at most dx/2: phi += step, then track;
//   track           dilate the active voxels by one face neighbour, three Euler steps of the
//                   reinitialisation phi -= 0.3 dx S(phi) (|grad phi| - 1), S(phi) = phi / (sqrt(phi^2
//                   + |grad phi|^2 dx^2) + eps) and |grad phi|^2 the Godunov upwind norm of HJ-WENO5
//                   differences (openvdb::math::ISGradientNormSqrd<HJWENO5_BIAS>), then switch off
//                   the voxels at or beyond the half width (+-background) and prune.
// Each Euler step reads the previous values only (Jacobi), so the result does not depend on the
// thread count. The per-voxel formulas are OpenVDB's own functions (WENO5, GodunovsNormSqrd) or
// copies of its inline code in the same operation order; the project compiles without contraction
// (-ffp-contract=off), as Debian's libopenvdb is built without FMA, so the bits agree (tested
// against LevelSetFilter in tests/sim/test_geometry.cpp).
//
// Why: LevelSetFilter moves a 19-point stencil through a tree accessor voxel by voxel (about 60 ms
// per track on the armadillos at res 256, 2 threads); here each leaf gathers its 14^3 padded
// neighbourhood (its own 8^3 voxels and three layers from each face neighbour, one from each edge
// neighbour) once per sweep from raw leaf buffers.
#include "sparse_grid/vdb_trees.h"

#include <array>
#include <vector>

namespace stokes::sim {
inline namespace geometry {

class BandFilter {
 public:
  /// The grid must be a level set (GRID_LEVEL_SET) with uniform voxels; throws
  /// std::invalid_argument otherwise. The filter holds a reference: the grid must outlive it.
  explicit BandFilter(openvdb::FloatGrid& grid);

  /// One explicit step of mean-curvature flow, then track() (LevelSetFilter::meanCurvature()).
  void meanCurvature();
  /// Moves the surface by `distance` (world units; > 0 erodes: phi += distance) in steps of at most
  /// dx/2, each followed by track() (LevelSetFilter::offset()).
  void offset(float distance);
  /// Rebuilds the band after a change (LevelSetTracker::track()).
  void track();

 private:
  using Leaf = openvdb::FloatTree::LeafNodeType;
  /// The 3^3 leaves around a leaf (index (ox + 1) 9 + (oy + 1) 3 + (oz + 1)): a buffer, or the
  /// uniform value of a region without a leaf (a tile or the background).
  struct Neighbourhood {
    std::array<const float*, 27> data;
    std::array<float, 27> value;
  };

  void collectLeaves();   ///< leaves_: the tree's leaves
  void linkNeighbours();  ///< around_ of leaves_, and next_ sized for them
  template <class VoxelUpdate>
  void sweep(int layers, bool edges, const VoxelUpdate& update);
  void renormalise();
  void trimAndPrune();

  openvdb::FloatGrid& grid_;
  float dx_;
  std::vector<Leaf*> leaves_;
  std::vector<Neighbourhood> around_;
  std::vector<float> next_;  ///< 512 new values per leaf, written for its active voxels
};

}  // namespace geometry
}  // namespace stokes::sim
