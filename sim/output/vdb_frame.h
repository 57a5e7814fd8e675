#pragma once
// Frames as OpenVDB files: the liquid level set (grid "liquid") and optionally the particles
// (points grid "particles" with velocity "v"); and reading them back.
#include "sparse_grid/vdb_trees.h"

#include <string>
#include <vector>

#include "sim/output/surface_mesh.h"
#include "sim/scene/shapes.h"

namespace stokes::sim {
inline namespace output {

/// Writes `liquid` as a grid named "liquid" (a shallow copy is renamed; the caller's grid is not
/// touched) and, when `particles` is given, an OpenVDB points grid named "particles" (positions,
/// plus a Vec3f attribute "v" when `velocities` is given; voxel size = the liquid's). The file is
/// written atomically (sim/output/atomic_file.h).
/// Throws std::invalid_argument for a null grid or mismatched sizes, std::runtime_error naming the
/// path when writing fails.
/// `up`: UpAxis::Z turns every grid's transform (and the velocities) from y-up to z-up
/// (sim/output/surface_mesh.h).
void writeFrameVdb(const std::string& path, openvdb::FloatGrid::Ptr liquid,
                   const std::vector<Vec3d>* particles = nullptr,
                   const std::vector<Vec3d>* velocities = nullptr, UpAxis up = UpAxis::Y);

/// Names of the grids in a .vdb file. Throws std::runtime_error naming the path.
std::vector<std::string> readVdbGridNames(const std::string& path);

/// The float grid named "liquid" of a .vdb file. Throws std::runtime_error naming the path when
/// the file cannot be read or has no float grid of that name.
openvdb::FloatGrid::Ptr readLiquidGrid(const std::string& path);

}  // namespace output
}  // namespace stokes::sim
