#pragma once
// A triangle mesh as read from an OBJ file (sim/geometry/obj_mesh.h) and turned into a level set
// (sim/geometry/geometry.h). Quads and polygons are fanned into triangles by the reader.
#include "sparse_grid/vdb_trees.h"

#include <vector>

namespace stokes::sim {
inline namespace geometry {

struct TriangleMesh {
  std::vector<openvdb::Vec3s> points;
  std::vector<openvdb::Vec3I> triangles;  ///< 0-based vertex indices
};

}  // namespace geometry
}  // namespace stokes::sim
