#pragma once
// Shape descriptions shared by scenes (sim/scene/scene.h), solids and initial liquid (sim/geometry/geometry.h):
// what a scene file says about a box, sphere, plane or mesh, before any grid exists.
#include "sparse_grid/vdb_trees.h"

#include <string>

namespace stokes::sim {
inline namespace scene {

using openvdb::Vec3d;

/// Placement of a mesh: p_world = translation + R(rotationDegrees) * (scale * p_file), with R the
/// rotation about x, then y, then z (degrees, extrinsic).
struct Placement {
  Vec3d translation{0.0};
  Vec3d rotationDegrees{0.0};
  double scale = 1.0;
};

struct ShapeDesc {
  enum class Kind { Box, Sphere, Plane, Mesh };
  Kind kind = Kind::Box;
  Vec3d min{0.0}, max{0.0};     ///< Box: corners
  Vec3d center{0.0};            ///< Sphere
  double radius = 0.0;          ///< Sphere
  Vec3d point{0.0};             ///< Plane: a point on it
  Vec3d normal{0.0, 1.0, 0.0};  ///< Plane: outward normal (the solid/liquid side is -normal)
  std::string meshPath;         ///< Mesh: OBJ file (absolute, or resolved against the scene file)
  Placement placement;          ///< Mesh
  Vec3d velocity{0.0};          ///< initial liquid velocity (liquid shapes); solid velocity (solids)
};

inline const char* toString(ShapeDesc::Kind k) {
  switch (k) {
    case ShapeDesc::Kind::Box: return "box";
    case ShapeDesc::Kind::Sphere: return "sphere";
    case ShapeDesc::Kind::Plane: return "plane";
    case ShapeDesc::Kind::Mesh: return "mesh";
  }
  return "?";
}

}  // namespace scene
}  // namespace stokes::sim
