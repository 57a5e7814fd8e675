// Geometry for the 3D simulator: see geometry.h for the conventions and the maths of each part.
#include "sim/geometry/geometry.h"

#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/MeshToVolume.h>
#include <openvdb/tools/Prune.h>
#include <openvdb/tools/SignedFloodFill.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>
#include <stdexcept>
#include <string>

#include "sim/geometry/band_filter.h"
#include "sim/geometry/sphere_raster.h"

namespace stokes::sim {
inline namespace geometry {

namespace {

constexpr double kFar = std::numeric_limits<double>::max();

std::string shapeName(std::size_t index, const ShapeDesc& s) {
  return "shape " + std::to_string(index) + " (" + toString(s.kind) + ")";
}

openvdb::BBoxd emptyBBox() {
  return openvdb::BBoxd(Vec3d(kFar), Vec3d(-kFar));  // min > max: empty
}

bool isEmpty(const openvdb::BBoxd& b) {
  return b.min().x() > b.max().x() || b.min().y() > b.max().y() || b.min().z() > b.max().z();
}

openvdb::BBoxd intersect(const openvdb::BBoxd& a, const openvdb::BBoxd& b) {
  return openvdb::BBoxd(openvdb::math::maxComponent(a.min(), b.min()),
                        openvdb::math::minComponent(a.max(), b.max()));
}

void expandBy(openvdb::BBoxd& box, const Vec3d& p) {
  box.min() = openvdb::math::minComponent(box.min(), p);
  box.max() = openvdb::math::maxComponent(box.max(), p);
}

/// Bounding box of the half-space {(x - p).n <= 0} intersected with the box: the box corners on
/// the solid side plus the points where the plane crosses the box's 12 edges.
openvdb::BBoxd clippedHalfSpaceBBox(const Vec3d& p, const Vec3d& n, const openvdb::BBoxd& box) {
  std::array<Vec3d, 8> corner;
  std::array<double, 8> dist;
  for (int c = 0; c < 8; ++c) {
    corner[c] = Vec3d((c & 1) ? box.max().x() : box.min().x(), (c & 2) ? box.max().y() : box.min().y(),
                      (c & 4) ? box.max().z() : box.min().z());
    dist[c] = (corner[c] - p).dot(n);
  }
  openvdb::BBoxd out = emptyBBox();
  for (int c = 0; c < 8; ++c) {
    if (dist[c] <= 0.0) expandBy(out, corner[c]);
    for (int axisBit : {1, 2, 4}) {  // edge from c to c + axisBit
      if (c & axisBit) continue;
      const int d = c | axisBit;
      if ((dist[c] < 0.0) != (dist[d] < 0.0)) {
        const double t = dist[c] / (dist[c] - dist[d]);  // linear root along the edge
        expandBy(out, corner[c] + t * (corner[d] - corner[c]));
      }
    }
  }
  return out;
}

/// Rotation of p by `degrees` about coordinate axis `axis` (right-handed, column vectors):
/// e.g. about z, (x, y) -> (c x - s y, s x + c y).
Vec3d rotateAboutAxis(const Vec3d& p, int axis, double degrees) {
  const double rad = degrees * (openvdb::math::pi<double>() / 180.0);
  const double c = std::cos(rad), s = std::sin(rad);
  const int u = (axis + 1) % 3, v = (axis + 2) % 3;  // (y,z) for x, (z,x) for y, (x,y) for z
  Vec3d out = p;
  out[u] = c * p[u] - s * p[v];
  out[v] = s * p[u] + c * p[v];
  return out;
}

/// Trilinear sample of `grid` at a world position, through a per-call un-registered accessor.
double sampleWorld(const openvdb::FloatGrid& grid, const Vec3d& worldPos) {
  auto acc = grid.getConstUnsafeAccessor();
  const Vec3d ijk = grid.transform().worldToIndex(worldPos);
  return static_cast<double>(openvdb::tools::BoxSampler::sample(acc, ijk));
}

std::vector<const TriangleMesh*> meshPerShape(const std::vector<ShapeDesc>& shapes,
                                              const std::vector<const TriangleMesh*>& meshes) {
  std::size_t meshShapes = 0;
  for (const auto& s : shapes) meshShapes += s.kind == ShapeDesc::Kind::Mesh ? 1 : 0;
  std::vector<const TriangleMesh*> out(shapes.size(), nullptr);
  if (meshes.size() == shapes.size()) {
    for (std::size_t i = 0; i < shapes.size(); ++i)
      if (shapes[i].kind == ShapeDesc::Kind::Mesh) out[i] = meshes[i];
  } else if (meshes.size() == meshShapes) {
    std::size_t next = 0;
    for (std::size_t i = 0; i < shapes.size(); ++i)
      if (shapes[i].kind == ShapeDesc::Kind::Mesh) out[i] = meshes[next++];
  } else {
    throw std::invalid_argument("ShapeField: " + std::to_string(meshes.size()) +
                                " meshes given for " + std::to_string(meshShapes) +
                                " mesh shapes among " + std::to_string(shapes.size()) + " shapes");
  }
  return out;
}

}  // namespace

// ---- free functions ---------------------------------------------------------------------------

openvdb::math::Transform::Ptr cellCentredTransform(double dx) {
  if (!(dx > 0.0)) throw std::invalid_argument("cellCentredTransform: dx must be > 0");
  auto xform = openvdb::math::Transform::createLinearTransform(dx);
  xform->postTranslate(Vec3d(0.5 * dx));  // index (0,0,0) -> world (dx/2, dx/2, dx/2)
  return xform;
}

Vec3d applyPlacement(const Placement& placement, const Vec3d& p) {
  // R = Rz * Ry * Rx: rotate about x first, then y, then z.
  Vec3d q = placement.scale * p;
  for (int axis = 0; axis < 3; ++axis) q = rotateAboutAxis(q, axis, placement.rotationDegrees[axis]);
  return placement.translation + q;
}

double boxSignedDistance(const Vec3d& x, const Vec3d& lo, const Vec3d& hi) {
  // q = |x - c| - h per axis; outside: |max(q, 0)|, inside: max_a q_a (<= 0).
  const Vec3d c = 0.5 * (lo + hi), h = 0.5 * (hi - lo);
  Vec3d q;
  for (int a = 0; a < 3; ++a) q[a] = std::abs(x[a] - c[a]) - h[a];
  const Vec3d qPos(std::max(q.x(), 0.0), std::max(q.y(), 0.0), std::max(q.z(), 0.0));
  return qPos.length() + std::min(std::max({q.x(), q.y(), q.z()}), 0.0);
}

double domainWallPhi(const Vec3d& x, const Vec3d& lo, const Vec3d& hi) {
  return -boxSignedDistance(x, lo, hi);
}

openvdb::FloatGrid::Ptr meshLevelSet(const TriangleMesh& mesh, const Placement& placement,
                                     double dx, const MeshLevelSetOptions& options) {
  if (mesh.points.empty() || mesh.triangles.empty())
    throw std::invalid_argument("meshLevelSet: empty mesh (" + std::to_string(mesh.points.size()) +
                                " points, " + std::to_string(mesh.triangles.size()) + " triangles)");
  for (const auto& t : mesh.triangles)
    for (int v = 0; v < 3; ++v)
      if (t[v] >= mesh.points.size())
        throw std::invalid_argument("meshLevelSet: triangle vertex index " + std::to_string(t[v]) +
                                    " out of range (" + std::to_string(mesh.points.size()) +
                                    " points)");
  auto xform = cellCentredTransform(dx);
  std::vector<openvdb::Vec3s> placed(mesh.points.size());
  for (std::size_t i = 0; i < placed.size(); ++i)
    placed[i] = openvdb::Vec3s(applyPlacement(placement, Vec3d(mesh.points[i])));
  const float interior = options.interiorBandCells >= 1e6
                             ? std::numeric_limits<float>::max()
                             : static_cast<float>(options.interiorBandCells);
  auto grid = openvdb::tools::meshToSignedDistanceField<openvdb::FloatGrid>(
      *xform, placed, mesh.triangles, std::vector<openvdb::Vec4I>{},
      static_cast<float>(options.exteriorBandCells), interior);
  grid->setGridClass(openvdb::GRID_LEVEL_SET);
  return grid;
}

// ---- ShapeField -------------------------------------------------------------------------------

ShapeField::ShapeField(const std::vector<ShapeDesc>& shapes,
                       const std::vector<const TriangleMesh*>& meshesForMeshShapes, double dx,
                       const MeshLevelSetOptions& meshOptions)
    : shapes_(shapes), unitNormals_(shapes.size(), Vec3d(0.0)),
      meshGrids_(shapes.size()),
      meshBBoxes_(shapes.size(), emptyBBox()),
      dx_(dx) {
  if (!(dx > 0.0)) throw std::invalid_argument("ShapeField: dx must be > 0");
  const auto meshes = meshPerShape(shapes, meshesForMeshShapes);
  for (std::size_t i = 0; i < shapes_.size(); ++i) {
    const ShapeDesc& s = shapes_[i];
    switch (s.kind) {
      case ShapeDesc::Kind::Box:
        if (!(s.min.x() <= s.max.x() && s.min.y() <= s.max.y() && s.min.z() <= s.max.z()))
          throw std::invalid_argument("ShapeField: " + shapeName(i, s) + " has min > max");
        break;
      case ShapeDesc::Kind::Sphere:
        if (!(s.radius >= 0.0))
          throw std::invalid_argument("ShapeField: " + shapeName(i, s) + " has a negative radius");
        break;
      case ShapeDesc::Kind::Plane: {
        const double len = s.normal.length();
        if (!(len > 1e-12))
          throw std::invalid_argument("ShapeField: " + shapeName(i, s) + " has a zero normal");
        unitNormals_[i] = s.normal / len;
        break;
      }
      case ShapeDesc::Kind::Mesh:
        if (meshes[i] == nullptr)
          throw std::invalid_argument("ShapeField: " + shapeName(i, s) + " '" + s.meshPath +
                                      "' has no mesh");
        try {
          meshGrids_[i] = meshLevelSet(*meshes[i], s.placement, dx, meshOptions);
          meshBBoxes_[i] = emptyBBox();
          for (const auto& v : meshes[i]->points) expandBy(meshBBoxes_[i], applyPlacement(s.placement, Vec3d(v)));
        } catch (const std::invalid_argument& e) {
          throw std::invalid_argument("ShapeField: " + shapeName(i, s) + " '" + s.meshPath +
                                      "': " + e.what());
        }
        break;
    }
  }
}

double ShapeField::shapePhi(std::size_t i, const Vec3d& xWorld) const {
  const ShapeDesc& s = shapes_[i];
  const Vec3d x = xWorld - displacement(i);  // the shape's own frame: where it was at t = 0
  switch (s.kind) {
    case ShapeDesc::Kind::Box: return boxSignedDistance(x, s.min, s.max);
    case ShapeDesc::Kind::Sphere: return (x - s.center).length() - s.radius;
    case ShapeDesc::Kind::Plane: return (x - s.point).dot(unitNormals_[i]);
    case ShapeDesc::Kind::Mesh: return sampleWorld(*meshGrids_[i], x);
  }
  return kFar;
}

double ShapeField::phi(const Vec3d& x) const {
  double d = kFar;  // union = min over shapes
  for (std::size_t i = 0; i < shapes_.size(); ++i) d = std::min(d, shapePhi(i, x));
  return d;
}

bool ShapeField::moving() const {
  for (const ShapeDesc& s : shapes_)
    if (s.velocity != Vec3d(0.0)) return true;
  return false;
}

Vec3d ShapeField::velocityAt(const Vec3d& x) const {
  double d = kFar;
  Vec3d v(0.0);
  for (std::size_t i = 0; i < shapes_.size(); ++i) {
    const double di = shapePhi(i, x);
    if (di < d) {
      d = di;
      v = shapes_[i].velocity;
    }
  }
  return v;
}

Vec3d ShapeField::gradient(const Vec3d& x) const {
  const double h = 0.5 * dx_;
  Vec3d g;
  for (int a = 0; a < 3; ++a) {
    Vec3d e(0.0);
    e[a] = h;
    g[a] = (phi(x + e) - phi(x - e)) / (2.0 * h);
  }
  return g;
}

openvdb::FloatGrid::ConstPtr ShapeField::meshGrid(std::size_t index) const {
  return index < meshGrids_.size() ? meshGrids_[index] : nullptr;
}

openvdb::BBoxd ShapeField::worldBBox(const openvdb::BBoxd& domain) const {
  openvdb::BBoxd out = emptyBBox();
  for (std::size_t i = 0; i < shapes_.size(); ++i) {
    const ShapeDesc& s = shapes_[i];
    openvdb::BBoxd b;
    switch (s.kind) {
      case ShapeDesc::Kind::Box: b = openvdb::BBoxd(s.min, s.max); break;
      case ShapeDesc::Kind::Sphere:
        b = openvdb::BBoxd(s.center - Vec3d(s.radius), s.center + Vec3d(s.radius));
        break;
      case ShapeDesc::Kind::Plane:
        b = clippedHalfSpaceBBox(s.point + displacement(i), unitNormals_[i], domain);
        break;
      case ShapeDesc::Kind::Mesh: b = meshBBoxes_[i]; break;  // of the placed vertices
    }
    if (s.kind != ShapeDesc::Kind::Plane) b.translate(displacement(i));
    b = intersect(b, domain);
    if (isEmpty(b)) continue;
    expandBy(out, b.min());
    expandBy(out, b.max());
  }
  return out;
}

openvdb::CoordBBox ShapeField::indexBBox(const openvdb::BBoxd& domain) const {
  const openvdb::BBoxd w = worldBBox(domain);
  if (isEmpty(w)) return openvdb::CoordBBox();  // empty
  auto toCell = [this](double v) { return static_cast<openvdb::Int32>(std::floor(v / dx_)); };
  return openvdb::CoordBBox(openvdb::Coord(toCell(w.min().x()), toCell(w.min().y()), toCell(w.min().z())),
                            openvdb::Coord(toCell(w.max().x()), toCell(w.max().y()), toCell(w.max().z())));
}

openvdb::FloatGrid::Ptr ShapeField::toLevelSet(const openvdb::BBoxd& domain,
                                               double halfWidthInCells) const {
  const float background = static_cast<float>(halfWidthInCells * dx_);
  auto grid = openvdb::FloatGrid::create(background);
  grid->setTransform(cellCentredTransform(dx_));
  grid->setGridClass(openvdb::GRID_LEVEL_SET);
  openvdb::CoordBBox cells = indexBBox(domain);
  if (cells.empty()) return grid;
  cells.expand(static_cast<openvdb::Int32>(std::ceil(halfWidthInCells)) + 1);
  auto acc = grid->getAccessor();
  // Band |phi| < background: active values; deeper inside: inactive -background (then pruned to
  // tiles). Outside the band nothing is stored (reads +background).
  for (auto it = cells.begin(); it; ++it) {
    const openvdb::Coord& ijk = *it;
    const double d = phi(dx_ * (ijk.asVec3d() + Vec3d(0.5)));
    if (std::abs(d) < background) acc.setValueOn(ijk, static_cast<float>(d));
    else if (d < 0.0) acc.setValueOff(ijk, -background);
  }
  openvdb::tools::pruneLevelSet(grid->tree());
  return grid;
}

// ---- GridPhi ----------------------------------------------------------------------------------

namespace {
std::atomic<std::uint64_t> nextGridPhiId{1};

/// One thread's accessor into the tree of the GridPhi with id `id` (0: none yet). Un-registered,
/// so it never touches its tree again once replaced. `block` is the 8^3 block (a leaf's extent)
/// that the last sample's 2^3 corners all fell in: read straight from `leaf`, or, where the tree
/// holds no leaf there (a tile: one value), `tileValue`.
struct ThreadAccessor {
  std::uint64_t id = 0;
  std::optional<openvdb::FloatGrid::ConstUnsafeAccessor> accessor;
  bool hasBlock = false;
  openvdb::Coord block;
  const openvdb::FloatTree::LeafNodeType* leaf = nullptr;
  float tileValue = 0.0f;
};

/// True when the 2^3 voxels from `base` on lie in the 8^3 block at `origin`.
bool cornersInBlock(const openvdb::Coord& base, const openvdb::Coord& origin) {
  for (int a = 0; a < 3; ++a) {
    const int local = base[a] - origin[a];
    if (local < 0 || local > 6) return false;
  }
  return true;
}
}  // namespace

GridPhi::GridPhi(openvdb::FloatGrid::ConstPtr grid) : grid_(std::move(grid)), id_(nextGridPhiId++) {
  if (grid_ && !grid_->hasUniformVoxels())
    throw std::invalid_argument("GridPhi: grid '" + grid_->getName() + "' has non-uniform voxels");
}

double GridPhi::operator()(const Vec3d& worldPos) const {
  if (!grid_) return kFar;
  thread_local ThreadAccessor cache;
  if (cache.id != id_) {
    cache.accessor.emplace(grid_->getConstUnsafeAccessor());
    cache.hasBlock = false;
    cache.id = id_;
  }
  // openvdb::tools::BoxSampler::sample, bit for bit: the same corners and the same interpolation,
  // but when all eight lie in one 8^3 block (343 of 512 base voxels) they are read straight from
  // its leaf's buffer, or are all its tile's value, skipping eight accessor look-ups.
  const Vec3d ijk = grid_->transform().worldToIndex(worldPos);
  const openvdb::Coord base(int(std::floor(ijk[0])), int(std::floor(ijk[1])), int(std::floor(ijk[2])));
  const Vec3d uvw = ijk - base.asVec3d();
  float data[2][2][2];
  if (!cache.hasBlock || !cornersInBlock(base, cache.block)) {
    const openvdb::Coord block(base.x() & ~7, base.y() & ~7, base.z() & ~7);
    cache.hasBlock = cornersInBlock(base, block);
    if (cache.hasBlock) {
      cache.block = block;
      cache.leaf = cache.accessor->probeConstLeaf(base);
      if (!cache.leaf) cache.tileValue = cache.accessor->getValue(base);  // no leaf: one tile value
    }
  }
  if (!cache.hasBlock) {
    openvdb::tools::BoxSampler::getValues(data, *cache.accessor, base);
  } else if (cache.leaf) {
    const openvdb::Coord l = base - cache.block;
    const openvdb::Index o = openvdb::Index((l.x() << 6) | (l.y() << 3) | l.z());
    for (int i = 0; i < 2; ++i)
      for (int j = 0; j < 2; ++j)
        for (int k = 0; k < 2; ++k) data[i][j][k] = cache.leaf->getValue(o + openvdb::Index((i << 6) | (j << 3) | k));
  } else {
    return static_cast<double>(cache.tileValue);  // eight equal corners interpolate to their value
  }
  return static_cast<double>(openvdb::tools::BoxSampler::trilinearInterpolation(data, uvw));
}

// ---- liquid from particles --------------------------------------------------------------------

openvdb::FloatGrid::Ptr liquidLevelSetFromParticles(const std::vector<Vec3d>& positions, double dx,
                                                    double radiusInCells, double halfWidthInCells,
                                                    const ParticleSurfaceOptions& options) {
  if (!(dx > 0.0)) throw std::invalid_argument("liquidLevelSetFromParticles: dx must be > 0");
  if (!(radiusInCells > 0.0))
    throw std::invalid_argument("liquidLevelSetFromParticles: radiusInCells must be > 0");
  if (!(halfWidthInCells >= 1.0))
    throw std::invalid_argument("liquidLevelSetFromParticles: halfWidthInCells must be >= 1");
  if (!(radiusInCells + halfWidthInCells < 7.0))
    throw std::invalid_argument("liquidLevelSetFromParticles: radiusInCells + halfWidthInCells must be < 7");
  auto grid = openvdb::FloatGrid::create(static_cast<float>(halfWidthInCells * dx));
  grid->setTransform(cellCentredTransform(dx));
  grid->setGridClass(openvdb::GRID_LEVEL_SET);
  grid->setName("liquid");
  if (positions.empty()) return grid;

  const double radius = radiusInCells * dx;
  // openvdb::tools::ParticlesToLevelSet's sphere union, bit for bit, ~N x faster (sphere_raster.h).
  rasterizeSphereUnion(*grid, positions, radius, options.deepInteriorMargin);
  // The raster gives every voxel of its leaves its sign (untouched: outside; deep or inside:
  // -background); flood the sign into the missing leaves only (minLevel 1).
  openvdb::tools::signedFloodFill(grid->tree(), /*threaded=*/true, /*grainSize=*/1, /*minLevel=*/1);

  const double erosion =
      options.particleSpacingInCells > 0.0
          ? radius - 0.5 * options.particleSpacingInCells * dx + options.faceBulgeInCells * dx
          : 0.0;
  if (options.smoothingPasses > 0 || erosion != 0.0) {
    BandFilter filter(*grid);  // LevelSetFilter's steps and bits (band_filter.h)
    for (int pass = 0; pass < options.smoothingPasses; ++pass) filter.meanCurvature();
    if (erosion != 0.0) filter.offset(static_cast<float>(erosion));  // phi += erosion
  }
  openvdb::tools::pruneLevelSet(grid->tree());
  return grid;
}

// ---- volumes ----------------------------------------------------------------------------------

openvdb::BBoxd interiorWorldBBox(const openvdb::FloatGrid& grid) {
  openvdb::CoordBBox ijk;  // empty
  for (auto leaf = grid.tree().cbeginLeaf(); leaf; ++leaf) ijk.expand(leaf->getNodeBoundingBox());
  for (auto it = grid.tree().cbeginValueAll(); it; ++it)
    if (it.isTileValue() && *it < 0.0f) {
      openvdb::CoordBBox tile;
      it.getBoundingBox(tile);
      ijk.expand(tile);
    }
  if (ijk.empty()) return emptyBBox();
  // Voxel extents: index box [min - 1/2, max + 1/2] mapped to world (transform may be any affine).
  const openvdb::BBoxd indexBox(ijk.min().asVec3d() - Vec3d(0.5), ijk.max().asVec3d() + Vec3d(0.5));
  return grid.transform().indexToWorld(indexBox);
}

double levelSetVolume(const openvdb::FloatGrid& grid) {
  const Vec3d voxel = grid.voxelSize();
  const double dx = voxel.x();
  double insideVoxels = 0.0;
  for (auto it = grid.tree().cbeginValueAll(); it; ++it) {
    // Smoothed Heaviside of -phi: 1 deep inside, 0 outside, linear over one voxel.
    const double fraction = std::clamp(0.5 - static_cast<double>(*it) / dx, 0.0, 1.0);
    if (fraction > 0.0) insideVoxels += fraction * static_cast<double>(it.getVoxelCount());
  }
  return insideVoxels * voxel.x() * voxel.y() * voxel.z();
}

double levelSetVolumeClipped(const openvdb::FloatGrid& grid, const std::function<double(const Vec3d&)>& clip) {
  const Vec3d voxel = grid.voxelSize();
  const double dx = voxel.x();
  const openvdb::math::Transform& xform = grid.transform();
  auto fraction = [&](double phi, const openvdb::Coord& ijk) {
    phi = std::max(phi, clip(xform.indexToWorld(ijk)));
    return std::clamp(0.5 - phi / dx, 0.0, 1.0);
  };
  double insideVoxels = 0.0;
  for (auto it = grid.tree().cbeginValueAll(); it; ++it) {
    const double phi = static_cast<double>(*it);
    if (!(0.5 - phi / dx > 0.0)) continue;  // outside before clipping; clipping only raises phi
    if (it.isVoxelValue()) {
      insideVoxels += fraction(phi, it.getCoord());
      continue;
    }
    openvdb::CoordBBox tile;
    it.getBoundingBox(tile);
    for (auto ijk = tile.begin(); ijk; ++ijk) insideVoxels += fraction(phi, *ijk);
  }
  return insideVoxels * voxel.x() * voxel.y() * voxel.z();
}

ClippedVolumeTerms clippedVolumeTerms(const openvdb::FloatGrid& grid, const std::function<double(const Vec3d&)>& clip,
                                      double maxOffset, const std::function<bool(const openvdb::Coord&)>& counts) {
  const Vec3d voxel = grid.voxelSize();
  ClippedVolumeTerms t;
  t.dx = voxel.x();
  t.voxelVolume = voxel.x() * voxel.y() * voxel.z();
  t.maxOffset = maxOffset;
  const double dx = t.dx;
  const openvdb::math::Transform& xform = grid.transform();
  // Split sum over voxels of fraction(max(phi - c, clip)): voxels whose fraction cannot change for
  // |c| <= maxOffset are fixed (whole, or the clip's fraction); the others keep (phi, clip).
  auto add = [&](double phi, const openvdb::Coord& ijk) {
    if (phi - maxOffset >= 0.5 * dx) return;  // outside for every c
    if (counts && !counts(ijk)) return;
    const double b = clip(xform.indexToWorld(ijk));
    if (b >= 0.5 * dx) return;  // clipped away
    if (phi + maxOffset <= b || (phi + maxOffset <= -0.5 * dx && b <= -0.5 * dx)) {
      const double f = t.fraction(phi + maxOffset, b, 0.0);  // the clip or full inside decides
      if (f == 1.0) ++t.full;
      else t.partial.push_back(f);
      return;
    }
    t.variable.emplace_back(phi, b);
  };
  for (auto it = grid.tree().cbeginValueAll(); it; ++it) {
    const double phi = static_cast<double>(*it);
    if (phi - maxOffset >= 0.5 * dx) continue;
    if (it.isVoxelValue()) {
      add(phi, it.getCoord());
      continue;
    }
    openvdb::CoordBBox tile;
    it.getBoundingBox(tile);
    for (auto ijk = tile.begin(); ijk; ++ijk) add(phi, *ijk);
  }
  return t;
}

VolumeMatch matchVolume(openvdb::FloatGrid& grid, double target, double maxOffset,
                        const std::function<double(double)>& volumeAt) {
  const double dx = grid.voxelSize().x();
  const double background = static_cast<double>(grid.background());
  VolumeMatch m;
  double lo = -maxOffset, hi = maxOffset;
  if (volumeAt(lo) >= target) {
    m.offset = lo;
    m.bounded = maxOffset > 0.0;
  } else if (volumeAt(hi) <= target) {
    m.offset = hi;
    m.bounded = maxOffset > 0.0;
  } else {
    while (hi - lo > 1e-9 * dx) {  // volumeAt(lo) < target < volumeAt(hi)
      const double mid = 0.5 * (lo + hi);
      (volumeAt(mid) < target ? lo : hi) = mid;
    }
    m.offset = 0.5 * (lo + hi);
  }
  m.volume = volumeAt(m.offset);
  m.raw = volumeAt(0.0);
  if (m.offset != 0.0) {
    const float c = static_cast<float>(m.offset), bg = static_cast<float>(background);
    for (auto leaf = grid.tree().beginLeaf(); leaf; ++leaf)
      for (auto v = leaf->beginValueOn(); v; ++v) v.setValue(std::clamp(*v - c, -bg, bg));
  }
  return m;
}

VolumeMatch matchClippedVolume(openvdb::FloatGrid& grid, double target,
                               const std::function<double(const Vec3d&)>& clip, double maxOffset) {
  const double dx = grid.voxelSize().x();
  const double background = static_cast<double>(grid.background());
  if (!(maxOffset >= 0.0) || !(maxOffset < background - 0.5 * dx))
    throw std::invalid_argument("matchClippedVolume: maxOffset must lie in [0, background - dx/2)");
  if (!(target >= 0.0)) throw std::invalid_argument("matchClippedVolume: target must be >= 0");
  const ClippedVolumeTerms terms = clippedVolumeTerms(grid, clip, maxOffset);
  return matchVolume(grid, target, maxOffset, [&](double c) {
    double sum = double(terms.full);
    terms.forEachFraction(c, [&](double f) { sum += f; });
    return sum * terms.voxelVolume;
  });
}

double symmetricVolumeDifference(const openvdb::FloatGrid& a, const openvdb::FloatGrid& b) {
  openvdb::BBoxd box = interiorWorldBBox(a);
  const openvdb::BBoxd boxB = interiorWorldBBox(b);
  if (isEmpty(box) && isEmpty(boxB)) return 0.0;
  if (!isEmpty(boxB)) {
    if (isEmpty(box)) box = boxB;
    expandBy(box, boxB.min());
    expandBy(box, boxB.max());
  }
  const double h = std::min(a.voxelSize().x(), b.voxelSize().x());
  const Vec3d extent = box.extents();
  const std::int64_t nx = std::max<std::int64_t>(1, static_cast<std::int64_t>(std::ceil(extent.x() / h)));
  const std::int64_t ny = std::max<std::int64_t>(1, static_cast<std::int64_t>(std::ceil(extent.y() / h)));
  const std::int64_t nz = std::max<std::int64_t>(1, static_cast<std::int64_t>(std::ceil(extent.z() / h)));
  std::int64_t differing = 0;
#pragma omp parallel for schedule(dynamic, 1) reduction(+ : differing)
  for (std::int64_t i = 0; i < nx; ++i) {
    auto accA = a.getConstUnsafeAccessor();
    auto accB = b.getConstUnsafeAccessor();
    for (std::int64_t j = 0; j < ny; ++j)
      for (std::int64_t k = 0; k < nz; ++k) {
        const Vec3d x = box.min() + h * Vec3d(i + 0.5, j + 0.5, k + 0.5);
        const float pa = openvdb::tools::BoxSampler::sample(accA, a.transform().worldToIndex(x));
        const float pb = openvdb::tools::BoxSampler::sample(accB, b.transform().worldToIndex(x));
        differing += (pa < 0.0f) != (pb < 0.0f) ? 1 : 0;
      }
  }
  return static_cast<double>(differing) * h * h * h;
}

}  // namespace geometry
}  // namespace stokes::sim
