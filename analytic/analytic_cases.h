#pragma once
// The analytic verification cases of thesis chapter 5 (docs/design.md §4), set up on a BlockLayout,
// solved with the engine's systems and compared against the exact answer.
//
//   box-viscosity  [0,pi]^Dim, rho = mu = dt = 1, exact u_a = prod_c sin x_c for every a; walls and
//                  outside faces carry the exact velocity (Dirichlet); all weights 1. Decoupled
//                  viscosity solve (thesis 5.3). L1 = sum_faces |e| dx^Dim, Linf = max |e|.
//   disk-stokes    2D free-surface Stokes disk (thesis 5.4), unified Stokes, errors on the faces whose
//                  control volume holds liquid (the same faces under either liquid-weight rule).
//   ball           3D liquid ball (radius 0.35 in the unit box) falling under gravity: a
//                  performance case, with a solid sphere and a floor when `solids` is set.
//   surface-mode   a small disturbance of a viscous pool's free surface, 2D or 3D: a
//                  Fourier mode or a Gaussian bump / dimple; one unified Stokes step from rest, its
//                  vertical velocity below the surface against linear theory (surface_mode_solution.h).
#include <algorithm>
#include <cmath>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "kernels/staggered_stencils.h"
#include "solver/step/rank_sums.h"
#include "solver/step/stokes_step.h"
#include "sparse_grid/volume_weights.h"

namespace stokes::analytic {

struct AnalyticOptions {
  int dim = 2;
  int n = 32;            ///< cells across the box (box-viscosity) or per unit length (disk, ball)
  double mu = 1.0;
  double rho = 1.0;
  double dt = 1.0;
  double tolerance = 1e-10;  ///< relative residual of the Krylov solve
  int maxIterations = 200000;
  std::string model = "uniform";  ///< uniform | affine | quadratic
  int tileSize = 16, padding = 3, bandAir = 2, bandSolid = 2, minRegion = 2;
  int minTileSize = 0;        ///< 0: every tile cube has edge tileSize; else octree edges down to this
  double tileAccuracy = 0.0;  ///< with minTileSize: ReducedOptions::tileAccuracy
  /// Which tiles are kept (ReducedOptions::rule); open: solver::planSolve's (paying tiles under the
  /// pressure-velocity multigrid, else all)
  std::optional<solver::TileRule> tileRule;
  std::string family = "auto";  ///< auto | divfree | full  (auto: full for viscosity, divfree otherwise)
  std::string fit = "auto";     ///< auto | boundary | all  (auto: all faces for quadratic, boundary for affine)
  /// The solver: what is open (nullopt) solver::planSolve chooses (solver/step/solve_plan.h).
  std::optional<solver::StokesForm> form = solver::StokesForm::PressureStress;
  std::optional<solver::KrylovMethod> method;  ///< open: CG on the SPD form, MINRES on the PV form
  std::optional<solver::PreconditionerKind> preconditioner = solver::PreconditionerKind::Jacobi;
  std::string tileCache = "library";  ///< none | library | shapes
  /// disk / ball: unified Stokes, or the comparisons decoupled (viscosity then projection) and
  /// pressure (projection only)
  solver::SystemKind system = solver::SystemKind::UnifiedStokes;
  bool solids = false;  ///< ball: add a solid floor and a solid sphere
  solver::RowStorage rows = solver::RowStorage::Auto;  ///< Krylov vectors on live rows or padded blocks
  bool rowStencils = true;  ///< on live rows: stencils over a neighbour index (false: sweep the blocks)
  int multigridDegree = solver::MultigridOptions{}.smootherDegree;  ///< Chebyshev degree per smoothing
  double multigridRange = solver::MultigridOptions{}.smootherRange;  ///< smoothed eigenvalue range
  /// --form pv with multigrid: the pressure block (auto: by the viscous number mu dt / (rho dx^2))
  solver::SchurApproximation multigridSchur = solver::SchurApproximation::Auto;
  solver::FaceInterpolation multigridInterpolation = solver::FaceInterpolation::Auto;
  /// in-house, or PETSc over the MPI ranks (SPD form; PETSc's options database picks the solver)
  solver::Backend backend = solver::Backend::InHouse;
  /// PETSc backend (ball, disk), uniform model: each rank builds its own blocks and a halo ("own"),
  /// or every rank the whole problem ("whole", as with reduced tiles)
  std::string rankSetup = "own";
  bool keepVelocities = false;  ///< return the step's face velocities in AnalyticResult::velocities
  /// ball, reduced model: also solve the uniform model and report AnalyticResult::versusUniform
  bool versusUniform = false;
  /// ball: write the liquid's face velocities to this file (one rank), or compare them with such
  /// a file (AnalyticResult::facesDifference; any number of ranks, each its own faces)
  std::string facesOut, facesCompare;
  /// surface-mode: the disturbance. `mode`: eta = a prod cos(2 pi (x - c)) over a box of
  /// `width` wavelengths, n cells per wavelength; `gaussian`: eta = a exp(-|x - c|^2 / (2 s^2)),
  /// s = radius / 2, n cells per unit length, a box `width` units wide. The pool is 1 unit deep.
  std::string shape = "mode";
  double amplitude = 1.0;    ///< a in cells: > 0 a crest (bump) at the centre c, < 0 a trough (dimple)
  double radius = 8.0;       ///< gaussian: the feature's radius (two standard deviations), in cells
  double crestOffset = 0.0;  ///< c less the box's centre, in cells along every horizontal axis
  double levelOffset = 0.0;  ///< the mean surface's height above the grid line at depth 1, in cells
  std::optional<int> width;  ///< box width in wavelengths (mode) or units (gaussian); open: 4 or 8
  double gravity = 9.81;
  /// How the liquid weights W_L are measured; open: the engine's rule
  /// (sparse_grid::kLiquidFractionRule, as the scenes)
  std::optional<sparse_grid::FractionRule> liquidWeights;
};

struct AnalyticResult {
  std::string test, model, status;
  /// Whether the solve left a velocity to measure (detail::fillReport); if not, the errors and
  /// rates below are unset and `status` says why.
  bool measured = false;
  int dim = 2, n = 0;
  double mu = 0.0, rho = 0.0, dt = 0.0;
  double L1 = 0.0, Linf = 0.0;
  int iterations = 0;
  std::size_t unknowns = 0;
  std::size_t paddedRows = 0, krylovRows = 0;  ///< padded block rows; rows the Krylov vectors held
  double relativeResidual = 0.0;
  double setupSeconds = 0.0, solveSeconds = 0.0, totalSeconds = 0.0;
  double preconditionerSeconds = 0.0;  ///< of solveSeconds: multigrid set-up
  std::size_t multigridLevels = 0;
  std::string schurBlock;  ///< the PV multigrid's pressure block, or empty
  std::string solver;      ///< what ran: system and form, Krylov method, preconditioner
  std::size_t tiles = 0, reducedDofs = 0, cartesianDofs = 0, fallbackTiles = 0, cacheHits = 0, cacheMisses = 0;
  std::size_t partialTiles = 0;  ///< tiles that keep fewer modes than the basis
  std::size_t unpaidTiles = 0;   ///< tiles returned to Cartesian by the paying-tiles rule
  std::string tileRule;          ///< the rule that kept the tiles (solver::TileRule's key)
  double tileWorkSaved = 0.0, tileWorkOverhead = 0.0;  ///< solver/reduced/tile_cost.h's estimate, kept tiles
  std::map<int, std::size_t> tilesByEdge;  ///< tiles per cube edge (several with --tile-min)
  double reconstructionLinf = 0.0, tileSeconds = 0.0;
  double kineticEnergyBefore = 0.0, kineticEnergyAfter = 0.0;  ///< sum rho W_L u^2 dV / 2
  double maxDivergence = 0.0;  ///< max |W_L^p G^T (W_F u + (1 - W_F) u_s)| after the step (unified Stokes)
  std::vector<double> velocities;  ///< every face's velocity after the step (keepVelocities), padded layout
  /// With AnalyticOptions::versusUniform: the rms over the faces of the difference from the uniform
  /// model's velocities, over the rms of the uniform velocities less their mean per axis; else -1.
  double versusUniform = -1.0;
  /// With AnalyticOptions::facesCompare: max |u - u_file| / max |u_file| over the file's faces,
  /// and how many faces the ranks compared (all of the file's, or the layouts differ).
  double facesDifference = -1.0;
  std::size_t facesCompared = 0;
  /// surface-mode: the decay rate -w / eta fitted below the surface (least squares of the step's
  /// vertical velocities on one face row against the linear theory's shape), the theory's rate of
  /// the step, and the quasi-static rate (dt -> infinity); 0 for the other cases.
  double rate = 0.0, theoryRate = 0.0, quasiStaticRate = 0.0;
};

/// max_j |W_L^p G^T (W_F u + (1 - W_F) u_s)|_j * dx: the discrete volume flux imbalance per cell
/// (over every rank's cells in a distributed problem).
template <int Dim>
double maxDivergence(const solver::StaggeredProblem<Dim>& prob, const solver::Vector& u) {
  const std::size_t n = prob.slots();
  solver::Vector g(u.size()), div(n);
  for (std::size_t i = 0; i < u.size(); ++i) {
    const double wf = prob.fluidFaceWeight(i);
    g[i] = wf * u[i] + (1.0 - wf) * prob.solidVelocity(i);
  }
  kernels::CellStressOutput out;
  out.p = div.data();
  out.pWeight = prob.liquidCell.data();
  kernels::cellsFromFaces<Dim>(*prob.layout, g.data(), out);
  double m = 0.0;
  for (std::size_t s = 0; s < n; ++s)
    if (prob.ownsSlot(s)) m = std::max(m, std::abs(div[s]));
  return solver::maxOverParts(prob, m * prob.layout->dx());
}

/// The ball case's step before its solve (what `runBall` solves), for tools that measure its
/// system: the layout, the problem with its weights and u*, the solver options `opt` asks for.
struct BallStep {
  std::unique_ptr<sparse_grid::BlockLayout<3>> layout;  ///< prob.layout points here
  solver::StaggeredProblem<3> prob;
  solver::StepOptions options;
};
BallStep ballStep(const AnalyticOptions& opt);

AnalyticResult runBoxViscosity(const AnalyticOptions& opt);
AnalyticResult runDiskStokes(const AnalyticOptions& opt);
AnalyticResult runBall(const AnalyticOptions& opt);
AnalyticResult runSurfaceMode(const AnalyticOptions& opt);

}  // namespace stokes::analytic
