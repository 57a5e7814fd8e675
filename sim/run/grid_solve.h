#pragma once
// One Stokes step on the caller's own OpenVDB grids, without particles or a scene file: a liquid
// level set and a start velocity in, the new velocity and the pressure out (the role of OpenVDB's
// tools::poisson::solve for a viscous liquid).
//
//   using namespace stokes::sim;
//   GridSolveInput in;
//   in.liquid = liquidLevelSet;                  // FloatGrid, transform cellCentredTransform(dx)
//   in.velocity = macVelocity;                   // optional Vec3SGrid, staggered (see below)
//   in.walls = openvdb::CoordBBox({0, 0, 0}, {63, 63, 63});  // the box's cells; default: padded
//   in.density = 1000.0; in.viscosity = 10.0; in.dt = 0.01; in.gravity = Vec3d(0, -9.81, 0);
//   const GridSolveResult out = solveOnGrids(in);  // out.velocity (MAC), out.pressure (Pa)
//
// Index space: voxel (i, j, k) of every grid is the cell centred at dx ((i, j, k) + 0.5), the
// frame of the engine's own grids (sim/geometry/geometry.h cellCentredTransform); grids in another
// transform are refused. Velocities are staggered (MAC, as Houdini's and OpenVDB's staggered
// grids): component a of voxel (i, j, k) is the velocity normal to the cell's lower face along a.
// The domain is a box of solid, no-slip walls (the scene files' `domain`), `walls` its cells; the
// liquid is what lies inside it. A level set that continues past the walls (as the walls' own
// liquid extension reads it) is the better input: cut at the box, the liquid next to a wall reads
// air beyond it. The step is the scene runner's grid stage (sim/step/stokes_stage.h:
// volume weights, gravity, the solve planSolve picks, extrapolation of 3 face layers).
#include "sparse_grid/vdb_trees.h"

#include <optional>
#include <string>

#include "sim/scene/scene.h"
#include "solver/step/solve_plan.h"

namespace stokes::sim {
inline namespace run {

struct GridSolveInput {
  openvdb::FloatGrid::ConstPtr liquid;     ///< signed distance, negative in the liquid (required)
  openvdb::Vec3SGrid::ConstPtr velocity;   ///< u* before the step, staggered; null: at rest
  std::optional<openvdb::CoordBBox> walls;  ///< cells inside the box; default: the liquid's padded
  double density = 1000.0;                  ///< kg/m^3
  double viscosity = 0.0;                   ///< Pa s (0: inviscid, a pressure projection)
  double dt = 0.0;                          ///< s (required)
  std::optional<Vec3d> gravity;             ///< m/s^2, added to u* as g dt
  solver::SystemKind system = solver::SystemKind::UnifiedStokes;  ///< or DecoupledStokes
  double tolerance = 1e-6;                  ///< the Krylov solve's relative residual
};

struct GridSolveResult {
  openvdb::Vec3SGrid::Ptr velocity;  ///< staggered, on the liquid's faces and 3 layers beyond ("vel")
  openvdb::FloatGrid::Ptr pressure;  ///< Pa, on the liquid's cells ("pressure")
  int iterations = 0;
  double relativeResidual = 0.0;
  std::string solver;  ///< what ran, as stats.csv's `solver` column names it
};

/// The padding of the default walls around the liquid's cells, in cells.
inline constexpr int kGridSolveWallPadding = 4;

/// One step, see the top of this file. Throws std::invalid_argument naming what is wrong with the
/// input (no liquid inside the walls, another transform, dt <= 0, ...) and
/// SimulationError when the solve fails.
GridSolveResult solveOnGrids(const GridSolveInput& in);

}  // namespace run
}  // namespace stokes::sim
