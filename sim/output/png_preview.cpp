#include "sim/output/png_preview.h"

#include <openvdb/tools/RayIntersector.h>
#include <openvdb/tools/RayTracer.h>

#include <stb/stb_image_write.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>
#include <stdexcept>

#include "sim/output/atomic_file.h"

namespace stokes::sim {
inline namespace output {

PreviewCamera frameWorldBBox(const openvdb::BBoxd& box, double aspect, const Vec3d& viewDirection,
                             double fovDegrees, const Vec3d& up) {
  if (!(aspect > 0.0)) throw std::invalid_argument("frameWorldBBox: aspect must be > 0");
  if (!(fovDegrees > 0.0 && fovDegrees < 180.0))
    throw std::invalid_argument("frameWorldBBox: fovDegrees must be in (0, 180)");
  PreviewCamera cam;
  cam.fovDegrees = fovDegrees;
  cam.up = up;
  cam.target = box.getCenter();
  // Half-angle of the narrower field: tan(v/2) = tan(h/2) / aspect.
  const double tanHalfH = std::tan(0.5 * fovDegrees * openvdb::math::pi<double>() / 180.0);
  const double halfAngle = std::atan(std::min(tanHalfH, tanHalfH / aspect));
  const double radius = std::max(0.5 * box.extents().length(), 1e-6);
  // A sphere of radius r subtends half-angle asin(r / d) at distance d.
  const double distance = 1.05 * radius / std::sin(halfAngle);
  Vec3d dir = viewDirection;
  if (!(dir.length() > 0.0)) dir = Vec3d(0.0, 0.0, 1.0);
  dir.normalize();
  cam.eye = cam.target + distance * dir;
  return cam;
}

namespace {

using Intersector = openvdb::tools::LevelSetRayIntersector<openvdb::FloatGrid>;

struct Hit {
  double depth = std::numeric_limits<double>::infinity();
  Vec3d normal{0.0};
  Vec3d colour{0.0};
};

/// A level-set view of `grid` the intersector accepts (class LEVEL_SET), or nothing when the grid
/// has no active voxels. Shallow copy: shares the tree.
openvdb::FloatGrid::ConstPtr renderable(const openvdb::FloatGrid* grid) {
  if (grid == nullptr || grid->activeVoxelCount() == 0) return nullptr;
  // copyGrid() of a const grid is a const shallow copy; its metadata (the class) is its own.
  auto levelSet = std::const_pointer_cast<openvdb::FloatGrid>(
      openvdb::gridConstPtrCast<openvdb::FloatGrid>(grid->copyGrid()));
  levelSet->setGridClass(openvdb::GRID_LEVEL_SET);
  return levelSet;
}

/// Lambert shading: ambient + key light from above + headlight along the view ray, then an
/// approximate sRGB encoding (gamma 1/2.2).
std::array<std::uint8_t, 3> shade(const Hit& hit, const Vec3d& rayDir, const Vec3d& keyLight,
                                  const Vec3d& background) {
  Vec3d c = background;
  if (std::isfinite(hit.depth)) {
    Vec3d n = hit.normal;
    if (n.length() > 0.0) n.normalize();
    if (n.dot(rayDir) > 0.0) n = -n;  // face the camera
    const double light = 0.2 + 0.55 * std::max(0.0, n.dot(keyLight)) + 0.35 * std::max(0.0, -n.dot(rayDir));
    c = hit.colour * light;
  }
  std::array<std::uint8_t, 3> rgb;
  for (int a = 0; a < 3; ++a)
    rgb[a] = static_cast<std::uint8_t>(std::lround(255.0 * std::pow(std::clamp(c[a], 0.0, 1.0), 1.0 / 2.2)));
  return rgb;
}

}  // namespace

namespace {

/// The floor of `box` (its y = min face) where `ray` meets it before `nearest`: a checkered hit.
void hitFloor(const openvdb::math::Ray<double>& ray, const openvdb::BBoxd& box, const PreviewStyle& style,
              Hit& nearest) {
  const double dy = ray.dir().y();
  if (!(std::abs(dy) > 1e-12)) return;
  const double t = (box.min().y() - ray.eye().y()) / dy;
  if (!(t > 0.0)) return;
  const Vec3d x = ray.eye() + t * ray.dir();
  if (x.x() < box.min().x() || x.x() > box.max().x() || x.z() < box.min().z() || x.z() > box.max().z()) return;
  const double depth = (x - ray.eye()).length();
  if (depth >= nearest.depth) return;
  const double check = std::max(box.extents().x(), box.extents().z()) / 8.0;
  const long ix = std::lround(std::floor((x.x() - box.min().x()) / check));
  const long iz = std::lround(std::floor((x.z() - box.min().z()) / check));
  nearest = Hit{depth, Vec3d(0.0, 1.0, 0.0), (ix + iz) % 2 == 0 ? style.floorLight : style.floorDark};
}

/// Whether `ray` passes within `halfWidth(depth)` of an edge of `box` nearer than `depth`.
template <class HalfWidth>
bool onBoxEdge(const openvdb::math::Ray<double>& ray, const openvdb::BBoxd& box, double depth, HalfWidth halfWidth) {
  const Vec3d lo = box.min(), hi = box.max();
  for (int a = 0; a < 3; ++a)
    for (int k = 0; k < 4; ++k) {
      // the edge along axis a at the corner (b, c) = (k & 1, k >> 1) of the other two axes
      Vec3d p0 = lo;
      const int b = (a + 1) % 3, c = (a + 2) % 3;
      p0[b] = (k & 1) ? hi[b] : lo[b];
      p0[c] = (k >> 1) ? hi[c] : lo[c];
      Vec3d e(0.0);
      e[a] = hi[a] - lo[a];
      // closest points of the ray eye + t d (t >= 0) and the segment p0 + s e (0 <= s <= 1)
      const Vec3d d = ray.dir(), w = ray.eye() - p0;
      const double ee = e.dot(e), de = d.dot(e), dd = d.dot(d), dw = d.dot(w), ew = e.dot(w);
      const double denom = dd * ee - de * de;
      if (!(denom > 1e-18)) continue;
      const double s = std::clamp((dd * ew - de * dw) / denom, 0.0, 1.0);
      const double t = std::max((de * s - dw) / dd, 0.0);
      const Vec3d onRay = ray.eye() + t * d, onEdge = p0 + s * e;
      const double along = (onRay - ray.eye()).length();
      if (along < depth && (onRay - onEdge).length() < halfWidth(along)) return true;
    }
  return false;
}

}  // namespace

void renderPreviewPng(const std::string& path, const openvdb::FloatGrid& liquid,
                      const openvdb::FloatGrid* solid, const PreviewCamera& cam, int width,
                      int height, const PreviewStyle& style, const openvdb::BBoxd* domain) {
  if (width <= 0 || height <= 0)
    throw std::invalid_argument("renderPreviewPng: image size must be positive for '" + path + "'");
  if (!(cam.fovDegrees > 0.0 && cam.fovDegrees < 180.0))
    throw std::invalid_argument("renderPreviewPng: fovDegrees must be in (0, 180) for '" + path + "'");

  openvdb::tools::Film film(static_cast<size_t>(width), static_cast<size_t>(height));
  const double aperture = 41.2136;  // mm; only the ratio to the focal length matters
  openvdb::tools::PerspectiveCamera camera(
      film, Vec3d(0.0), cam.eye,
      openvdb::tools::PerspectiveCamera::fieldOfViewToFocalLength(cam.fovDegrees, aperture), aperture);
  camera.lookAt(cam.target, cam.up);

  // Grids to draw, each with its colour; intersectors are built once and copied per thread.
  const std::array<openvdb::FloatGrid::ConstPtr, 2> grids{renderable(&liquid), renderable(solid)};
  const std::array<Vec3d, 2> colours{style.liquid, style.solid};
  std::array<std::optional<Intersector>, 2> shared;
  try {
    for (int g = 0; g < 2; ++g)
      if (grids[g]) shared[g].emplace(*grids[g]);
  } catch (const openvdb::Exception& e) {
    throw std::runtime_error("renderPreviewPng: cannot ray-trace a grid for '" + path + "': " + e.what());
  }

  Vec3d keyLight = Vec3d(0.4, 1.0, 0.6);
  keyLight.normalize();
  // the angle one pixel spans (horizontal field over the width; rays are unit length)
  const double pixelAngle = 2.0 * std::tan(0.5 * cam.fovDegrees * openvdb::math::pi<double>() / 180.0) / width;
  std::vector<std::uint8_t> pixels(static_cast<std::size_t>(width) * height * 3);
#pragma omp parallel
  {
    std::array<std::optional<Intersector>, 2> local;
    for (int g = 0; g < 2; ++g)
      if (shared[g]) local[g].emplace(*shared[g]);
#pragma omp for schedule(dynamic, 4)
    for (int j = 0; j < height; ++j) {
      for (int i = 0; i < width; ++i) {
        const openvdb::math::Ray<double> ray = camera.getRay(i, j);
        Hit nearest;
        for (int g = 0; g < 2; ++g) {
          if (!local[g]) continue;
          Vec3d world, normal;
          if (!local[g]->intersectsWS(ray, world, normal)) continue;
          const double depth = (world - ray.eye()).length();
          if (depth < nearest.depth) nearest = Hit{depth, normal, colours[g]};
        }
        if (domain) hitFloor(ray, *domain, style, nearest);
        auto rgb = shade(nearest, ray.dir(), keyLight, style.background);
        if (domain && onBoxEdge(ray, *domain, nearest.depth, [&](double depth) { return 0.75 * pixelAngle * depth; }))
          rgb = shade(Hit{0.0, -ray.dir(), style.edges}, ray.dir(), keyLight, style.background);
        std::uint8_t* px = &pixels[(static_cast<std::size_t>(j) * width + i) * 3];
        px[0] = rgb[0], px[1] = rgb[1], px[2] = rgb[2];
      }
    }
  }
  writeFileAtomically(path, "renderPreviewPng", [&](const std::string& tmp) {
    if (stbi_write_png(tmp.c_str(), width, height, 3, pixels.data(), width * 3) == 0)
      throw std::runtime_error("stbi_write_png failed (disk full or not writable?)");
  });
}

}  // namespace output
}  // namespace stokes::sim
