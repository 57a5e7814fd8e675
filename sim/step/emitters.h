#pragma once
// Liquid sources of a scene: the initial liquid shapes and the emitters (a disc nozzle or a box)
// that keep their volume full of liquid moving at a fixed velocity (scenes/README.md).
#include <cstddef>
#include <cstdint>
#include <functional>
#include <vector>

#include "sim/geometry/geometry.h"
#include "sim/particles/particles.h"
#include "sim/scene/scene.h"
#include "sim/step/stokes_stage.h"
#include "sim/geometry/triangle_mesh.h"

namespace stokes::sim {
inline namespace step {

/// Signed distance to an emitter's volume (negative inside). Disc: the cylinder of `radius` around
/// the axis through `center` along `normal`, `thickness` long and centred on `center`:
/// max(r - radius, |s| - thickness / 2) with s the axial and r the radial coordinate (exact inside
/// and off the rims; a lower bound near the rims). Box: the exact box distance.
double emitterPhi(const EmitterDesc& emitter, const Vec3d& x);

/// Cells (domain cell indices) that can hold liquid of the region phi < 0 whose world bounding box
/// is [lo, hi], clipped to the domain.
openvdb::CoordBBox domainCellsOf(const DomainBox& domain, const Vec3d& lo, const Vec3d& hi);

/// Particles filling the initial liquid shapes: perAxis^3 jittered particles per cell where the
/// shape's signed distance is negative, with the shape's velocity. Mesh shapes read their OBJ.
/// Liquid is clipped to the domain box and, given `solids`, to the outside of the solids: the part
/// of a shape inside a solid (the beam's clamped end) is not liquid. Seeding it and pushing it out
/// afterwards would pile those particles onto the solid's face (several cells' worth in a tenth of
/// a cell), a layer reseeding thins out and the particle surface does not see. With `keepCell`
/// only the cells it accepts are seeded (a rank's share of a run split over ranks).
ParticleSet<kSimDim> seedInitialLiquid(const Scene& scene, const DomainBox& domain, const ShapeField* solids = nullptr,
                                       const std::function<bool(const openvdb::Coord&)>& keepCell = {});

/// How far the particle surface of a freshly seeded flat face lies beyond the seeded plane, in
/// cells (> 0: outside). A slab seeded as seedInitialLiquid seeds (perAxis^3 jittered particles
/// per cell, seeds 1 and 2, the plane at 0, 1/4, 1/2 and 3/4 of a cell) is turned into its level
/// set (liquidLevelSetFromParticles without this correction) and phi is averaged over the middle
/// of the face. The jitter makes it positive: the union of spheres is a maximum over the
/// particles. The simulator erodes its particle surface by it (ParticleSurfaceOptions::
/// faceBulgeInCells), so a resting face lies where its particles' volume ends. Deterministic;
/// measured once per perAxis and process.
double seededFaceBulge(int perAxis);

/// Keeps an active emitter's volume full of liquid moving at its velocity: particles inside it
/// take the velocity (and no affine part); with sinceLastEmit = 0 (the emitter's first step) its
/// whole volume is seeded, jittered as the initial liquid; afterwards only what entered through its
/// upstream side in the time sinceLastEmit (the region a velocity * sinceLastEmit shift moved into
/// the emitter), so the volume added is the emitter's flux. The solve prescribes the emitter's
/// velocity on its faces (GridStep::setInflow). An emitter must be at least |velocity| dt thick
/// (one cell at CFL 1 is). Returns the number of particles added. With `seeds` false it only sets
/// the velocities (the ranks of a split run but one: rank 0 seeds, every rank holds particles).
std::size_t applyEmitter(const EmitterDesc& emitter, const DomainBox& domain, int perAxis, std::uint64_t seed,
                         ParticleSet<kSimDim>& particles, double sinceLastEmit, bool seeds = true);

}  // namespace step
}  // namespace stokes::sim
