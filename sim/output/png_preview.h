#pragma once
// Preview images of a frame: the liquid and the solids ray-cast from their level sets, written as PNG.
#include "sparse_grid/vdb_trees.h"

#include <string>

#include "sim/scene/shapes.h"

namespace stokes::sim {
inline namespace output {

/// A pinhole camera for previews. `fovDegrees` is the HORIZONTAL field of view (as in
/// openvdb::tools::PerspectiveCamera); the image's aspect ratio sets the vertical one.
struct PreviewCamera {
  Vec3d eye{0.0, 0.0, 5.0};
  Vec3d target{0.0};
  Vec3d up{0.0, 1.0, 0.0};
  double fovDegrees = 40.0;
};

/// A camera looking at the centre of `box` from direction `viewDirection` (from the target
/// towards the eye), far enough that the box's bounding sphere fits in the smaller of the
/// horizontal and vertical fields of view (aspect = width / height), with a 5% margin.
PreviewCamera frameWorldBBox(const openvdb::BBoxd& box, double aspect = 1.0,
                             const Vec3d& viewDirection = Vec3d(0.8, 0.6, 1.2),
                             double fovDegrees = 40.0, const Vec3d& up = Vec3d(0.0, 1.0, 0.0));

/// Colours (linear 0..1 RGB) used by renderPreviewPng.
struct PreviewStyle {
  Vec3d liquid{0.85, 0.55, 0.12};  ///< honey
  Vec3d solid{0.6, 0.6, 0.6};      ///< grey
  Vec3d background{0.12, 0.13, 0.16};
  Vec3d floorLight{0.42, 0.43, 0.46}, floorDark{0.30, 0.31, 0.34};  ///< the domain's floor, checkered
  Vec3d edges{0.75, 0.77, 0.82};                                    ///< the domain box's outline
};

/// Ray-casts the liquid level set and (optional) solid level set with
/// openvdb::tools::LevelSetRayIntersector through an openvdb::tools::PerspectiveCamera, one ray
/// per pixel; each pixel takes the nearer hit of the two grids (depth compositing) and is shaded
/// Lambertian (ambient + key light + headlight) from the level-set normal. Pixels that hit
/// nothing get the background colour; an empty (or non-level-set-class) grid is simply not drawn,
/// so an empty liquid gives a background image -- no slice fallback. Rows are rendered in
/// parallel (OpenMP, one intersector copy per thread). Written as 8-bit RGB PNG with
/// stbi_write_png. Throws std::invalid_argument for width/height <= 0 and std::runtime_error
/// naming the path when writing fails.
///
/// `domain` (optional): the box the liquid lives in, drawn for scale as a checkered floor
/// (its y = min face, 8 checks along its longer side; depth-composited with the grids) and the
/// outline of its 12 edges (lines about 1.5 pixels wide, hidden behind nearer liquid or solid).
void renderPreviewPng(const std::string& path, const openvdb::FloatGrid& liquid,
                      const openvdb::FloatGrid* solid, const PreviewCamera& cam, int width,
                      int height, const PreviewStyle& style = {}, const openvdb::BBoxd* domain = nullptr);

}  // namespace output
}  // namespace stokes::sim
