// Liquid sources: see emitters.h.
#include "sim/step/emitters.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <mutex>
#include <stdexcept>
#include <string>
#include <vector>

#include "sim/geometry/geometry.h"
#include "sim/geometry/obj_mesh.h"
#include "sim/particles/reseed.h"

namespace stokes::sim {
inline namespace step {

double emitterPhi(const EmitterDesc& e, const Vec3d& x) {
  if (e.kind == EmitterDesc::Kind::Box) return boxSignedDistance(x, e.min, e.max);
  const Vec3d d = x - e.center;
  const double s = d.dot(e.normal);
  const double r = (d - s * e.normal).length();
  return std::max(r - e.radius, std::abs(s) - 0.5 * e.thickness);
}

openvdb::CoordBBox domainCellsOf(const DomainBox& domain, const Vec3d& lo, const Vec3d& hi) {
  openvdb::Coord a, b;
  for (int k = 0; k < 3; ++k) {
    a[k] = std::max(0, int(std::floor((lo[k] - domain.min[k]) / domain.dx)));
    b[k] = std::min(domain.cells[k] - 1, int(std::floor((hi[k] - domain.min[k]) / domain.dx)));
  }
  return {a, b};
}

namespace {

/// World bounding box of an emitter: a box, or the disc's centre +- (radius + thickness/2).
void emitterBounds(const EmitterDesc& e, Vec3d& lo, Vec3d& hi) {
  if (e.kind == EmitterDesc::Kind::Box) {
    lo = e.min;
    hi = e.max;
    return;
  }
  const double r = e.radius + 0.5 * e.thickness;
  lo = e.center - Vec3d(r);
  hi = e.center + Vec3d(r);
}

CellBox cellBox(const DomainBox& domain, const openvdb::CoordBBox& cells) { return CellBox{cells, domain.dx, domain.min}; }

}  // namespace

ParticleSet<kSimDim> seedInitialLiquid(const Scene& scene, const DomainBox& domain, const ShapeField* solids,
                                       const std::function<bool(const openvdb::Coord&)>& keepCell) {
  ParticleSet<kSimDim> particles;
  const openvdb::BBoxd domainBox(domain.min, domain.max);
  // Shapes are sampled at the particle spacing (a mesh a few cells across keeps its limbs), and
  // each OBJ file is read once however many shapes use it.
  const double spacing = domain.dx / scene.particlesPerCellAxis;
  std::map<std::string, TriangleMesh> meshes;
  std::vector<ShapeField> fields;
  fields.reserve(scene.liquid.size());
  for (const ShapeDesc& shape : scene.liquid) {
    std::vector<const TriangleMesh*> meshOfShape;
    if (shape.kind == ShapeDesc::Kind::Mesh) {
      auto it = meshes.find(shape.meshPath);
      if (it == meshes.end()) it = meshes.emplace(shape.meshPath, loadObj(shape.meshPath)).first;
      meshOfShape.push_back(&it->second);
    }
    fields.emplace_back(std::vector<ShapeDesc>{shape}, meshOfShape, spacing);
  }
  // The liquid is the union of the shapes: shape i seeds only where no earlier shape lies, so an
  // overlap is seeded once (by the first shape that holds it, with that shape's velocity) and the
  // particles carry the union's volume.
  for (std::size_t i = 0; i < fields.size(); ++i) {
    const openvdb::BBoxd box = fields[i].worldBBox(domainBox);
    if (box.min().x() > box.max().x()) continue;  // nothing inside the domain
    const openvdb::CoordBBox cells = domainCellsOf(domain, box.min(), box.max());
    // the domain box, the solids and the earlier shapes clip the shape:
    // max(phi_i, phi_box, -phi_solids, -phi_j for j < i)
    auto phi = [&](const Vec3d& x) {
      double v = std::max(fields[i].phi(x), domain.phi(x));
      if (solids) v = std::max(v, -solids->phi(x));
      for (std::size_t j = 0; j < i && v < 0.0; ++j) v = std::max(v, -fields[j].phi(x));
      return v;
    };
    particles.append(seedParticles<kSimDim>(cellBox(domain, cells), phi, scene.particlesPerCellAxis,
                                            scene.seed + 0x1000 * (i + 1), scene.liquid[i].velocity, keepCell));
  }
  return particles;
}

namespace {
/// seededFaceBulge's measurement (a few ms).
double measureSeededFaceBulge(int perAxis) {
  constexpr int kSide = 20, kDepth = 6, kInset = 5;  // slab cells; the face's middle is read
  const double dx = 1.0;
  ParticleSurfaceOptions surface;
  surface.particleSpacingInCells = 1.0 / perAxis;
  double sum = 0.0;
  int count = 0;
  for (std::uint64_t seed : {1u, 2u})
    for (double planeInCell : {0.0, 0.25, 0.5, 0.75}) {
      const double top = kDepth - 1 + planeInCell;  // the slab is 0 <= z < top
      const CellBox box{openvdb::CoordBBox(openvdb::Coord(0), openvdb::Coord(kSide - 1, kSide - 1, kDepth - 1)),
                        dx, Vec3d(0.0)};
      const auto particles = seedParticles<kSimDim>(box, [&](const Vec3d& x) { return x[2] - top; }, perAxis, seed);
      const GridPhi phi(liquidLevelSetFromParticles(particles.x, dx, 1.0, 3.0, surface));
      for (double x = kInset + 0.125; x < kSide - kInset; x += 0.25)
        for (double y = kInset + 0.125; y < kSide - kInset; y += 0.25) {
          sum += phi(Vec3d(x, y, top));
          ++count;
        }
    }
  return -sum / count / dx;
}
}  // namespace

double seededFaceBulge(int perAxis) {
  if (perAxis < 1) throw std::invalid_argument("seededFaceBulge: perAxis must be >= 1");
  // Measured once per seeding density and process: every Simulator (a resume included) asks.
  static std::mutex mutex;
  static std::map<int, double> measured;
  {
    const std::lock_guard<std::mutex> lock(mutex);
    if (const auto it = measured.find(perAxis); it != measured.end()) return it->second;
  }
  const double bulge = measureSeededFaceBulge(perAxis);  // deterministic: a race only repeats it
  const std::lock_guard<std::mutex> lock(mutex);
  return measured.emplace(perAxis, bulge).first->second;
}

std::size_t applyEmitter(const EmitterDesc& e, const DomainBox& domain, int perAxis, std::uint64_t seed,
                         ParticleSet<kSimDim>& particles, double sinceLastEmit, bool seeds) {
  Vec3d lo, hi;
  emitterBounds(e, lo, hi);
  const openvdb::CoordBBox cells = domainCellsOf(domain, lo, hi);
  if (cells.empty()) return 0;
  auto inEmitter = [&](const Vec3d& x) { return std::max(emitterPhi(e, x), domain.phi(x)); };
  for (std::size_t p = 0; p < particles.size(); ++p)
    if (inEmitter(particles.x[p]) < 0.0) {
      particles.v[p] = e.velocity;
      particles.c[p] = ParticleSet<kSimDim>::zeroAffine();
    }
  if (!seeds) return 0;
  // What entered since the last emission: the points of the emitter that lay outside it, upstream,
  // sinceLastEmit ago. The particles inside moved by exactly velocity * sinceLastEmit (the solve
  // prescribes it there), so that region is what they vacated; seeding it at the initial density
  // adds the emitter's flux, |velocity| dt times its cross-section, in expectation. (Refilling
  // cells or sub-cells that ran short overfilled the emitter 1.2-1.5x: jittered particles leave a
  // cell one by one, and a refill never takes back the cell's surplus.)
  const Vec3d shift = e.velocity * sinceLastEmit;
  auto entered = [&](const Vec3d& x) { return std::max(inEmitter(x), -emitterPhi(e, x - shift)); };
  const ParticleSet<kSimDim> fresh =
      sinceLastEmit > 0.0 ? seedParticles<kSimDim>(cellBox(domain, cells), entered, perAxis, seed, e.velocity)
                          : seedParticles<kSimDim>(cellBox(domain, cells), inEmitter, perAxis, seed, e.velocity);
  particles.append(fresh);
  return fresh.size();
}

}  // namespace step
}  // namespace stokes::sim
