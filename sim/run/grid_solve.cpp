// One Stokes step on the caller's grids: see grid_solve.h.
#include "sim/run/grid_solve.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <vector>

#include "sim/geometry/geometry.h"
#include "sim/step/stokes_stage.h"

namespace stokes::sim {
inline namespace run {

namespace {

/// The liquid's cells (phi < 0) and their bounding box; throws where the grid cannot be used.
std::vector<openvdb::Coord> liquidCells(const GridSolveInput& in, double& dx) {
  if (!in.liquid) throw std::invalid_argument("solveOnGrids: no liquid level set");
  dx = in.liquid->voxelSize()[0];
  if (!(dx > 0.0) || in.liquid->transform() != *cellCentredTransform(dx))
    throw std::invalid_argument("solveOnGrids: the liquid's transform is not cellCentredTransform(dx): voxel (i, j, k) "
                                "must be centred at dx ((i, j, k) + 0.5)");
  if (in.velocity && in.velocity->transform() != in.liquid->transform())
    throw std::invalid_argument("solveOnGrids: the velocity grid's transform differs from the liquid's");
  if (!(in.dt > 0.0) || !std::isfinite(in.dt)) throw std::invalid_argument("solveOnGrids: dt must be positive");
  if (!(in.density > 0.0)) throw std::invalid_argument("solveOnGrids: density must be positive");
  if (!(in.viscosity >= 0.0)) throw std::invalid_argument("solveOnGrids: viscosity must be >= 0");
  std::vector<openvdb::Coord> cells;
  for (auto it = in.liquid->cbeginValueOn(); it; ++it)
    if (*it < 0.0f) {
      if (it.isVoxelValue()) {
        cells.push_back(it.getCoord());
      } else {
        const openvdb::CoordBBox tile = it.getBoundingBox();
        for (auto c = tile.begin(); c; ++c) cells.push_back(*c);
      }
    }
  if (cells.empty()) throw std::invalid_argument("solveOnGrids: the liquid level set has no cell with phi < 0");
  return cells;
}

}  // namespace

GridSolveResult solveOnGrids(const GridSolveInput& in) {
  double dx = 0.0;
  std::vector<openvdb::Coord> cells = liquidCells(in, dx);
  openvdb::CoordBBox walls;
  for (const openvdb::Coord& c : cells) walls.expand(c);
  walls.expand(kGridSolveWallPadding);
  if (in.walls) {  // the liquid inside them (a level set may continue past the walls)
    walls = *in.walls;
    std::erase_if(cells, [&walls](const openvdb::Coord& c) { return !walls.isInside(c); });
    if (cells.empty()) throw std::invalid_argument("solveOnGrids: no liquid cell lies inside the walls");
  }
  // the box: its cells are the caller's voxels shifted by walls.min()
  DomainBox domain;
  domain.dx = dx;
  domain.cells = walls.dim();
  for (int a = 0; a < 3; ++a) {
    domain.min[a] = dx * walls.min()[a];
    domain.max[a] = domain.min[a] + dx * domain.cells[a];
  }
  Scene scene;
  scene.name = "grids";
  scene.domainMin = domain.min;
  scene.domainMax = domain.max;
  scene.resolution = std::max({domain.cells.x(), domain.cells.y(), domain.cells.z()});
  scene.material = {in.density, in.viscosity};
  scene.gravity = in.gravity;
  scene.system = in.system;
  scene.solver.tolerance = in.tolerance;
  const StokesPlan plan = planStokes(scene, nullptr);

  std::vector<Vec3d> positions;
  positions.reserve(cells.size());
  for (const openvdb::Coord& c : cells) positions.push_back(in.liquid->indexToWorld(c));
  GridStep step(positions, *in.liquid, nullptr, domain, scene, in.dt, plan.viscous(), layoutBand(scene));
  if (in.velocity) {
    // face a of voxel (i, j, k) sits at dx i along a and at the cell centre across a
    // (read through the tree, not an accessor: the faces are filled by several threads)
    const openvdb::Vec3STree& tree = in.velocity->tree();
    step.setStartVelocity([&tree, dx](int a, const Vec3d& x) {
      openvdb::Coord c;
      for (int b = 0; b < 3; ++b) c[b] = int(b == a ? std::lround(x[b] / dx) : std::floor(x[b] / dx));
      return double(tree.getValue(c)[a]);
    });
  } else {
    step.setStartVelocity([](int, const Vec3d&) { return 0.0; });
  }
  step.solveFromStart(in.gravity ? &*in.gravity : nullptr, plan);

  GridSolveResult out;
  out.velocity = openvdb::Vec3SGrid::create(openvdb::Vec3f(0.0f));
  out.pressure = openvdb::FloatGrid::create(0.0f);
  for (auto* grid : {static_cast<openvdb::GridBase*>(out.velocity.get()), static_cast<openvdb::GridBase*>(out.pressure.get())})
    grid->setTransform(in.liquid->transform().copy());
  out.velocity->setName("vel");
  out.velocity->setGridClass(openvdb::GRID_STAGGERED);
  out.velocity->setVectorType(openvdb::VEC_CONTRAVARIANT_RELATIVE);
  out.pressure->setName("pressure");
  const Layout3& layout = step.layout();
  const std::size_t n = layout.numSlots();
  const solver::Vector& u = step.velocity();
  const solver::Vector p = step.pressure();
  openvdb::Vec3SGrid::Accessor vel = out.velocity->getAccessor();
  openvdb::FloatGrid::Accessor pressure = out.pressure->getAccessor();
  for (std::size_t s = 0; s < n; ++s) {
    if (!layout.isActiveCell(s)) continue;
    const openvdb::Coord c = layout.cellOf(s) + walls.min();
    vel.setValue(c, openvdb::Vec3f(float(u[s]), float(u[n + s]), float(u[2 * n + s])));
    if (!p.empty() && step.problem().liquidCell[s] > 0.0) pressure.setValue(c, float(p[s]));
  }
  out.iterations = step.report().iterations;
  out.relativeResidual = step.report().relativeResidual;
  out.solver = step.report().solver;
  return out;
}

}  // namespace run
}  // namespace stokes::sim
