#pragma once
// The union of particle spheres as a narrow-band level set: the raster behind the liquid surface
// (sim/geometry/geometry.h, liquidLevelSetFromParticles), built leaf by leaf with OpenMP.
//
// It writes what openvdb::tools::ParticlesToLevelSet::rasterizeSpheres(particles, radius) and
// finalize(/*prune=*/true) write into an empty level-set grid -- the same active voxels and the
// same values, bit for bit (tested against it in tests/sim/test_geometry.cpp). In index space, with
// P the particle's position, R = radius / dx and w = background / dx the half width, every voxel
// c with |c - P|^2 < (R + w)^2 for some particle takes
//     phi(c) = min over those particles of float(dx (|c - P| - R))
// and is active where that is below the background (a particle exactly on a voxel centre with
// R <= w marks it inside instead, as OpenVDB does). OpenVDB visits (2 (R + w) + 1)^3 voxels per
// particle through an accessor, on TBB's threads with a grid per task joined by CSG union. Here
// each 8^3 leaf is filled in a dense buffer by one OpenMP thread, and each voxel searches for its
// nearest particle instead: the value is a monotone function of the smallest squared distance
// alone, so that search gives the same bits. Particles are sorted by voxel (a parallel counting
// sort, O(particles), the order of a stable sort at any thread count); per leaf a table holds
// each nearby cell's particle range and a bit mask per column of cells. The 8 voxels of a z-row
// search together, each particle met updating all 8 (vectorised): the row starts from the previous
// row's nearest particles (upper bounds, usually exact) and reads only the columns, nearest first,
// and the cells along each whose gap could still beat some voxel's bound; rows with no particle
// within R + w skip at once. The work follows the particles near the surface, not the
// (2 (R + w) + 1)^3 box. Measured (bench_stages, bench/results/stages.md, 2 threads): 9.7x
// OpenVDB's speed on the armadillos at res 256 and 35x on a ball at res 128. With a deep margin
// (below) the deep interior is not rasterised at all.
#include "sparse_grid/vdb_trees.h"

#include <cstddef>
#include <vector>

namespace stokes::sim {
inline namespace geometry {

/// The largest deep margin rasterizeSphereUnion accepts, in voxels.
inline constexpr int kMaxDeepMargin = 6;

/// Rasterises spheres of `radius` (world units) around `positions` (world) into `grid`, which must
/// be empty, have uniform voxels and a background (the half width, world units) with
/// radius + background < 7 voxels. Throws std::invalid_argument otherwise.
///
/// deepMargin < 0 (the default) writes ParticlesToLevelSet's raster bit for bit. deepMargin = K in
/// [0, kMaxDeepMargin] leaves the deep interior out: a voxel c whose cells c + o, o in
/// [-1 - K, K]^3 (every cell within K whole voxels of c along each axis), all hold particles is
/// left inactive at -background, unrasterised, so the work follows the surface and the level-set
/// filters after it run on the band only (whole deep leaves prune to an inside tile). Every
/// inactive voxel of the grid then already has its sign: the caller must not flood the leaves
/// (openvdb::tools::signedFloodFill with minLevel 1 fills the missing leaves only).
void rasterizeSphereUnion(openvdb::FloatGrid& grid, const std::vector<openvdb::Vec3d>& positions, double radius,
                          int deepMargin = -1);

/// The particle list openvdb::tools::ParticlesToLevelSet reads (positions only): the reference
/// rasterizeSphereUnion is tested and benchmarked against.
class ParticlePositionList {
 public:
  using PosType = openvdb::Vec3R;
  explicit ParticlePositionList(const std::vector<openvdb::Vec3d>& x) : x_(&x) {}
  std::size_t size() const { return x_->size(); }
  void getPos(std::size_t n, openvdb::Vec3R& xyz) const { xyz = (*x_)[n]; }

 private:
  const std::vector<openvdb::Vec3d>* x_;
};

}  // namespace geometry
}  // namespace stokes::sim
