#pragma once
// Surface meshes of the liquid for renderers (Blender, Houdini): the zero isosurface of a frame's
// level set (openvdb::tools::volumeToMesh, quads split into triangles), written as binary PLY,
// which both import without plug-ins. Triangles are wound counter-clockwise seen from outside
// (normals point out of the liquid), which enclosedVolume() checks: > 0.
//
// Up axis: the simulator's world is y-up; Blender's is z-up. UpAxis::Z maps (x, y, z) to
// (x, -z, y), a +90 degree turn about x (what Blender's own importers do to y-up files), for the
// mesh, the .vdb grids' transforms and the particles' velocities alike (sim/output/vdb_frame.h).
#include "sparse_grid/vdb_trees.h"

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace stokes::sim {
inline namespace output {

enum class UpAxis { Y, Z };

struct SurfaceMesh {
  std::vector<openvdb::Vec3f> points;
  std::vector<std::array<std::uint32_t, 3>> triangles;
  std::vector<openvdb::Vec3f> velocities;  ///< per point (m/s), or empty: no velocity
};

/// The world position `x` (y-up) in the output frame of `up`.
openvdb::Vec3d toUpAxis(const openvdb::Vec3d& x, UpAxis up);

/// The zero isosurface of a level set, in world coordinates (y-up); empty for an empty grid. Its
/// vertices lie on the zero of the level set's quadratic interpolant; each of `subdivisions` splits
/// every triangle into four (edge midpoints projected onto the surface), which quarters the
/// volume the flat facets cut off.
SurfaceMesh meshLevelSet(const openvdb::FloatGrid& levelSet, int subdivisions = 1);

/// Sets mesh.velocities from a cell-centred velocity grid (a frame's "vel", vdb_frame.h) with the
/// points in the grid's world frame: at each point the trilinear weights of the eight voxel centres
/// around it, over the active ones only and normalised by their sum, so a field the active voxels
/// sample linearly comes back exactly; zero where none of the eight is active.
void sampleVertexVelocities(SurfaceMesh& mesh, const openvdb::Vec3SGrid& velocity);

/// Maps every point and velocity to the output frame of `up` (a rotation: volume and winding are
/// kept).
void applyUpAxis(SurfaceMesh& mesh, UpAxis up);

/// Writes binary little-endian PLY (float x, y, z, then float vx, vy, vz where the mesh has
/// velocities, as Houdini names a point velocity; uchar-counted int vertex indices) to path.tmp,
/// then renames it onto `path`. Throws std::runtime_error naming the path.
void writePly(const std::string& path, const SurfaceMesh& mesh);

/// Reads what writePly writes (velocities where the file has vx, vy, vz). Throws std::runtime_error naming the path and the problem.
SurfaceMesh readPly(const std::string& path);

/// Signed enclosed volume by the divergence theorem, sum over triangles of p0 . (p1 x p2) / 6.
double enclosedVolume(const SurfaceMesh& mesh);

/// Edges not shared by exactly one triangle in each direction (0: closed and consistently wound).
std::size_t openOrMisorientedEdges(const SurfaceMesh& mesh);

}  // namespace output
}  // namespace stokes::sim
