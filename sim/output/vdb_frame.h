#pragma once
// Frames as OpenVDB files: the liquid level set (grid "surface"), the velocity (grid "vel") and
// optionally the particles (points grid "particles" with velocity "v"), each grid with the
// frame's metadata; and reading them back.
#include "sparse_grid/vdb_trees.h"

#include <cmath>
#include <string>
#include <vector>

#include "sim/output/surface_mesh.h"
#include "sim/scene/shapes.h"

namespace stokes::sim {
inline namespace output {

/// The metadata every grid of a frame carries (with the voxel size "dx" in metres, "up_axis" "y"
/// or "z" and "stokesvdb_version", which writeFrameVdb adds).
struct FrameInfo {
  double time = 0.0;  ///< simulated time, s ("time")
  int frame = 0;      ///< frame number ("frame")
  std::string scene;  ///< the scene's name ("scene")
};

/// What one frame file holds.
struct FrameGrids {
  openvdb::FloatGrid::Ptr surface;                ///< the liquid level set (required)
  const std::vector<Vec3d>* positions = nullptr;  ///< the particles, from which "vel" is splatted
  const std::vector<Vec3d>* velocities = nullptr;
  bool points = false;  ///< also write the particles as the points grid "particles"
  FrameInfo info{};
  UpAxis up = UpAxis::Y;
  /// "vel" already splatted (particleVelocityGrid, y-up), so that a frame splats it once; null:
  /// splatted here from the particles
  openvdb::Vec3SGrid::ConstPtr velocity;
};

/// Writes a frame: the level set as grid "surface" (a shallow copy is renamed; the caller's grid
/// is not touched); with particles and velocities the cell-centred velocity grid "vel"
/// (particleVelocityGrid); with `points` an OpenVDB points grid "particles" (positions, and the
/// Vec3f attribute "v"; voxel size = the surface's); on every grid the metadata of FrameInfo.
/// The names and the staggering follow Houdini's and Blender's conventions (an SDF "surface", a
/// cell-centred vector "vel"). The file is written atomically (sim/output/atomic_file.h).
/// Throws std::invalid_argument for a null grid or mismatched sizes, std::runtime_error naming the
/// path when writing fails. UpAxis::Z turns every grid's transform (and the velocities) from y-up
/// to z-up (sim/output/surface_mesh.h).
void writeFrameVdb(const std::string& path, const FrameGrids& frame);

/// The particles' velocities on the voxel centres of `surface`'s transform: sum_p w_p v_p / sum_p w_p
/// with trilinear weights, on the voxels within one voxel of the liquid (surface value below its
/// voxel size) that some particle reaches. A Vec3f grid named "vel", vector type
/// contravariant-relative, cell-centred (not staggered).
openvdb::Vec3SGrid::Ptr particleVelocityGrid(const std::vector<Vec3d>& positions, const std::vector<Vec3d>& velocities,
                                             const openvdb::FloatGrid& surface);

/// The eight voxels around the index-space point `u` with their trilinear weights: f(voxel, weight)
/// for each (weights that are 0 included).
template <class F>
void forEachTrilinearCorner(const openvdb::Vec3d& u, F f) {
  const openvdb::Coord base(int(std::floor(u[0])), int(std::floor(u[1])), int(std::floor(u[2])));
  const openvdb::Vec3d t = u - base.asVec3d();
  for (int corner = 0; corner < 8; ++corner) {
    double w = 1.0;
    for (int a = 0; a < 3; ++a) w *= (corner >> a) & 1 ? t[a] : 1.0 - t[a];
    f(base.offsetBy(corner & 1, (corner >> 1) & 1, (corner >> 2) & 1), w);
  }
}

/// Names of the grids in a .vdb file. Throws std::runtime_error naming the path.
std::vector<std::string> readVdbGridNames(const std::string& path);

/// The level set of a .vdb frame: its float grid "surface", or "liquid" in a file written before
/// that name. Throws std::runtime_error naming the path when the file cannot be read or has neither.
openvdb::FloatGrid::Ptr readLiquidGrid(const std::string& path);

}  // namespace output
}  // namespace stokes::sim
