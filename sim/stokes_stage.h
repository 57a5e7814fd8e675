#pragma once
// The grid side of one simulation step (thesis Algorithm 1 around Algorithm 2): from particles and
// the liquid level set to a StaggeredProblem, its Stokes solve, and the face velocity G2P reads.
//
// Grid of a step. The BlockLayout covers the cells that hold particles, dilated by `band` cells
// (the P2G kernel reaches 1.5 cells, the stresses one more, and the surface moves up to cfl cells a
// step), clipped to the domain box: cells (0..N_a-1) along each axis, cell i spanning
// [min + i dx, min + (i+1) dx].
//
// Domain walls without W_F. The solver reads a face that is absent from the layout as velocity 0.
// The walls are made of such faces plus "closed" faces (StaggeredProblem::closedFace, Dirichlet 0):
//  - the lower wall normal to a: face a of the cells with i_a = 0 (it lies in their slot);
//  - the upper wall normal to a: face a of the cells with i_a = N_a, outside the domain: absent,
//    or present as padding of a block the domain ends inside -- closed;
//  - every face of a (padding) cell outside the domain box: closed, as absent ones would be.
// Tangential velocities next to a wall therefore see 0 beyond it (no-slip, as with solid W_F = 0).
// With `open_top` the +y wall is not closed: cells above the domain are air (pressure 0).
// The liquid weights come from the level set extended one cell into the walls it touches
// (extendIntoSolid with the outside of the box as the solid), as into solids: the samples on a
// wall carry their full weight, and no-slip holds there as at a solid.
// The tile bands treat the layout's edge as air (sparse_grid/tiling.h), so no tile reaches a wall
// as long as band_air >= 1 (the simulator raises 0 to 1).
//
// The liquid weights see the liquid extended kSolidExtensionCells into the solids it touches
// (extendIntoSolid); the reported volume and the reseeding use the particle level set itself.
// W_F is built only when the scene has solids: fraction of each control volume outside the solid
// union (phi_solid > 0). Solids move rigidly at their `velocity` (ShapeField::setTime, set by the
// simulator to the step's start); u_solid is their velocity on the faces they cover.
// Volume fractions use grid::computeVolumeFractionsOfDistance: both level sets are (close to)
// distances, so only samples within half a cell diagonal of a surface are sub-sampled.
#include <openvdb/openvdb.h>

#include <memory>
#include <string>
#include <vector>

#include "sim/geometry.h"
#include "sim/particles.h"
#include "sim/scene.h"
#include "solver/stokes_step.h"

namespace stokes::sim {

inline constexpr int kSimDim = 3;
using Layout3 = grid::BlockLayout<kSimDim>;
using Problem3 = solver::StaggeredProblem<kSimDim>;

/// The domain box in world units and in cells.
struct DomainBox {
  Vec3d min{0.0}, max{0.0};
  double dx = 1.0;
  openvdb::Coord cells{1, 1, 1};  ///< N_a cells per axis
  bool openTop = false;

  static DomainBox fromScene(const Scene& scene);
  openvdb::CoordBBox cellBBox() const { return {openvdb::Coord(0), cells - openvdb::Coord(1)}; }
  /// Signed distance to the box (negative inside); with openTop the box has no +y side.
  double phi(const Vec3d& x) const;
};

/// The liquid region of the volume weights reaches this many cells into a solid it touches.
inline constexpr double kSolidExtensionCells = 1.0;

/// Liquid level set extended into the solid (thesis 3.6.4, Fig. 3.4c): the liquid domain Omega_L
/// continues into the solid, where it is not liquid but the constraint that enforces the solid
/// boundary: stress samples there have W_L^tau > 0 and W_F^tau = 0, i.e. zero compliance, so the
/// strain rate between the solid's velocity and the liquid's next to it vanishes (no slip and no
/// separation), and pressure cells in it close the flux through the solid's faces. Without it a
/// liquid touching a solid only at a face is held by shear alone and hinges about it (the beam
/// rotated as a rigid rod about its root, mean velocity 0.75 g t).
/// Region: L union (S intersect {phi_L < reach}), i.e. min(phi_L, max(phi_S, phi_L - reach)),
/// Lipschitz-1 like both inputs, so the volume fractions' distance shortcut stays valid.
inline double extendIntoSolid(double phiLiquid, double phiSolid, double reach) {
  return std::min(phiLiquid, std::max(phiSolid, phiLiquid - reach));
}

/// Cells holding particles, dilated by `band` cells (face, edge and vertex neighbours), clipped to
/// the domain, with tiles voxelised (BlockLayout reads leaves).
openvdb::MaskTree particleBandMask(const std::vector<Vec3d>& positions, const DomainBox& domain, int band);

/// closedFace flags of the layout (see the header comment).
std::vector<std::uint8_t> closedWallFaces(const Layout3& layout, const DomainBox& domain);

/// Which solve a scene calls for and with which options (scene.viscosity, model, solver).
struct StokesPlan {
  enum class Kind { Coupled, Decoupled, Projection };
  Kind kind = Kind::Coupled;
  solver::StepOptions options;  ///< system = UnifiedStokes (coupled) or the first solve
  bool viscous() const { return kind != Kind::Projection; }
};
StokesPlan planStokes(const Scene& scene, std::shared_ptr<solver::TileLibrary> library);

/// Timings and counts of one grid step.
struct GridStepReport {
  double layoutSeconds = 0.0, weightSeconds = 0.0, p2gSeconds = 0.0, gravitySeconds = 0.0;
  double stokesSeconds = 0.0, viscositySeconds = 0.0, pressureSeconds = 0.0;  ///< by solve kind
  int iterations = 0;
  std::size_t unknowns = 0;       ///< active rows over the solves
  std::size_t stressUnknowns = 0;  ///< stress samples with W_L^tau > 0 in a coupled solve, else 0
  std::size_t cells = 0;          ///< active cells of the layout
  std::size_t tiles = 0, fallbackTiles = 0;
  bool builtFluidWeights = false;  ///< W_F was built (the scene has solids)
  double relativeResidual = 0.0;
  std::vector<std::string> stages;  ///< grid stages that ran, in order
};

/// Error of a step, naming the stage (and the face or cell where known).
class SimulationError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// The grid of one step and its face velocities.
class GridStep {
 public:
  /// Builds the layout and the volume weights. `liquid` is the step's liquid level set,
  /// `solids` the solid union (null: the scene has no solids, no W_F is built).
  GridStep(const std::vector<Vec3d>& positions, const openvdb::FloatGrid& liquid, const ShapeField* solids,
           const DomainBox& domain, const Scene& scene, double dt, bool needStressWeights, int band);

  /// P2G into u*, gravity if given, the solve(s) of `plan`, then velocity extrapolation beyond the
  /// liquid for G2P and advection. Throws SimulationError naming the stage and face on a
  /// non-finite velocity or a solve that did not converge.
  void solve(const ParticleSet<kSimDim>& particles, const Vec3d* gravity, const StokesPlan& plan);

  const Layout3& layout() const { return *layout_; }
  const Problem3& problem() const { return problem_; }
  const solver::Vector& velocity() const { return velocity_; }
  const GridStepReport& report() const { return report_; }

 private:
  void fillWeights(const openvdb::FloatGrid& liquid, const ShapeField* solids, bool needStressWeights);
  void fillSolidVelocity(const ShapeField& solids);
  void runSolve(const char* stage, const solver::StepOptions& options, double& seconds);
  void extrapolate(int layers);
  std::string faceName(std::size_t i) const;

  DomainBox domain_;
  std::unique_ptr<Layout3> layout_;
  Problem3 problem_;
  solver::Vector faceMass_, velocity_;
  GridStepReport report_;
};

}  // namespace stokes::sim
