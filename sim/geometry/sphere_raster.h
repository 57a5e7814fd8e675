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
// each 8^3 leaf is filled in a dense buffer by one OpenMP thread: first the particles within a
// voxel of it set the 2^3 voxels around each, which bounds each 4^3 brick's values by M_b; a
// particle can then lower a voxel of brick b only within dx (M_b / dx + R) of it, and no farther
// voxel is visited (inside the liquid about a voxel instead of R + w = 4). Particles are sorted by
// voxel, so a leaf reads only those within reach. Measured (bench_stages, bench/results/stages.md):
// 1.5-1.8x OpenVDB's speed on the armadillo pile at res 256 and 3.4-3.6x on a ball at res 128,
// 2 threads (two passes).
#include <openvdb/openvdb.h>

#include <cstddef>
#include <vector>

namespace stokes::sim::inline geometry {

/// Rasterises spheres of `radius` (world units) around `positions` (world) into `grid`, which must
/// be empty, have uniform voxels and a background (the half width, world units) with
/// radius + background < 7 voxels. Throws std::invalid_argument otherwise.
void rasterizeSphereUnion(openvdb::FloatGrid& grid, const std::vector<openvdb::Vec3d>& positions, double radius);

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

}  // namespace stokes::sim::inline geometry
