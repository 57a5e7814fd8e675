// Hard cases stay numerically stable. Each named case runs one unified Stokes step for
// the uniform, affine and quadratic models and asserts what the mathematics fixes:
//   * the solve converges to its tolerance (or returns the status the case expects);
//   * every output velocity is finite;
//   * the kinetic energy does not grow: the step minimises
//       1/2 |u - u*|_M^2 + dt (dissipation >= 0)  subject to  K^T W_F u = C tau,
//     so u^T M u + dt tau^T C tau = u^T M u* and |u|_M <= |u*|_M (zero solid velocity); the tiles
//     enter with M_R and their fits v* (StepReport::initialKineticEnergy measures u* the same way);
//   * the discrete divergence W_L^p G^T (W_F u) after the step is at solver tolerance.
// Every case adds one line to the table printed at the end: case | model | iterations | final
// residual | energy change | result (docs/hard_cases.md records it).
#include <gtest/gtest.h>
#include <omp.h>

#include <cstdio>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "analytic/analytic_cases.h"
#include "hard_case_problems.h"
#include "tests/thread_determinism.h"
#include "mixed_problem.h"
#include "solver/step/stokes_step.h"
#include "solver/systems/pressure_stress_system.h"

namespace stokes {
namespace {

using solver::StepOptions;
using solver::StepReport;
using solver::Vector;
using test::HardProblem;
using test::HardProblemSpec;
using test::Vec3d;

// ---- the table --------------------------------------------------------------------------------

struct TableRow {
  std::string name, model;
  int iterations = 0;
  double residual = 0.0, energyChange = 0.0;
  std::string result;
};

std::vector<TableRow>& table() {
  static std::vector<TableRow> rows;
  return rows;
}

/// Prints every recorded case once, after the last test of this process.
class HardCaseTable : public ::testing::Environment {
 public:
  void TearDown() override {
    if (table().empty()) return;
    std::printf("\ncase | model | iterations | final residual | energy change | result\n");
    for (const TableRow& r : table())
      std::printf("%s | %s | %d | %.2e | %+.3e | %s\n", r.name.c_str(), r.model.c_str(), r.iterations, r.residual,
                  r.energyChange, r.result.c_str());
  }
};
[[maybe_unused]] ::testing::Environment* const kTable = ::testing::AddGlobalTestEnvironment(new HardCaseTable);

/// (E_after - E_before) / E_before, 0 when both vanish.
double relativeEnergyChange(const StepReport& rep) {
  if (rep.initialKineticEnergy == 0.0) return rep.kineticEnergy == 0.0 ? 0.0 : std::numeric_limits<double>::infinity();
  return (rep.kineticEnergy - rep.initialKineticEnergy) / rep.initialKineticEnergy;
}

void record(const std::string& name, const std::string& model, const StepReport& rep, const std::string& result) {
  table().push_back({name, model, rep.solve.iterations, rep.solve.relativeResidual, relativeEnergyChange(rep), result});
}

// ---- models and options -----------------------------------------------------------------------

enum class Model { Uniform, Affine, Quadratic };
constexpr Model kModels[] = {Model::Uniform, Model::Affine, Model::Quadratic};

const char* name(Model m) { return m == Model::Uniform ? "uniform" : m == Model::Affine ? "affine" : "quadratic"; }

/// Small tiles so that 2D N = 32..48 and 3D n = 16 hold several: 8 cells, padding 2, bands 2.
sparse_grid::TilingOptions smallTiles() {
  sparse_grid::TilingOptions t;
  t.tileSize = 8;
  t.padding = 2;
  t.bandAir = 2;
  t.bandSolid = 2;
  t.minRegion = 2;
  return t;
}

constexpr double kTolerance = 1e-10;

/// Unified Stokes, SPD pressure-stress form, Jacobi-CG at relative tolerance 1e-10; reduced models
/// use the divergence-free basis (affine fitted on the boundary faces, quadratic on all faces).
StepOptions stepOptions(Model m, const sparse_grid::TilingOptions& tiling = smallTiles()) {
  StepOptions o;
  o.krylov.relativeTolerance = kTolerance;
  o.krylov.maxIterations = 40000;
  if (m == Model::Uniform) return o;
  solver::ReducedOptions r;
  r.order = m == Model::Affine ? solver::PolynomialOrder::Affine : solver::PolynomialOrder::Quadratic;
  r.family = solver::BasisFamily::DivergenceFree;
  r.fitAllFaces = m == Model::Quadratic;
  r.tiling = tiling;
  o.reduced = r;
  return o;
}

// ---- the checks every case makes ---------------------------------------------------------------

/// Relative slack on the energy inequality: the Krylov solution satisfies the optimality
/// conditions to the solver tolerance only.
constexpr double kEnergySlack = 1e-8;
/// Divergence after the step, as a flux imbalance per cell (velocity units), relative to the
/// largest |u*|: the pressure rows of the residual are this divergence, at solver tolerance.
constexpr double kDivergenceTolerance = 1e-7;

double maxAbs(const Vector& v) { return solver::maxAbs(v.data(), v.size()); }

/// Index of the first non-finite entry, or -1.
std::ptrdiff_t firstNonFinite(const Vector& v) {
  for (std::size_t i = 0; i < v.size(); ++i)
    if (!std::isfinite(v[i])) return std::ptrdiff_t(i);
  return -1;
}

/// Runs one step and checks convergence, finiteness, energy and divergence; records the row.
template <int Dim>
StepReport expectStableStep(const std::string& caseName, Model model, const solver::StaggeredProblem<Dim>& prob,
                            const StepOptions& opt, Vector* velocities = nullptr) {
  Vector u;
  const StepReport rep = solver::solveStep(prob, opt, u);
  const std::string label = caseName + " / " + name(model) + ": " + rep.diagnostics;
  std::string result = solver::toString(rep.solve.status);
  if (rep.tiles + rep.fallbackTiles > 0)
    result += ", " + std::to_string(rep.tiles) + " tiles" +
              (rep.fallbackTiles ? " (" + std::to_string(rep.fallbackTiles) + " fell back)" : std::string());
  record(caseName, name(model), rep, result);
  EXPECT_EQ(rep.solve.status, solver::Status::Converged) << label;
  EXPECT_LE(rep.solve.relativeResidual, kTolerance) << label;
  EXPECT_EQ(u.size(), std::size_t(Dim) * prob.slots()) << label;
  EXPECT_EQ(firstNonFinite(u), -1) << label;
  EXPECT_TRUE(std::isfinite(rep.kineticEnergy)) << label;
  EXPECT_LE(rep.kineticEnergy, rep.initialKineticEnergy * (1.0 + kEnergySlack)) << label;
  if (opt.system != solver::SystemKind::Viscosity) {
    const double div = analytic::maxDivergence(prob, u);
    EXPECT_LE(div, kDivergenceTolerance * maxAbs(prob.uStar)) << label << " (divergence before "
                                                                    << analytic::maxDivergence(prob, prob.uStar) << ")";
  }
  if (velocities) *velocities = std::move(u);
  return rep;
}

// ---- level sets -------------------------------------------------------------------------------

/// A liquid pool [0.1, 0.9] x [.., 0.72] (x [0.1, 0.9]) on a solid floor y < 0.22: a free surface,
/// a fractional solid boundary, and room for several 8-cell tiles.
template <int Dim>
HardProblemSpec poolSpec(int n) {
  HardProblemSpec s;
  s.n = n;
  s.liquid = [](const Vec3d& x) {
    return test::boxLevelSet<Dim>(x, Vec3d(0.1, 0.1, 0.1), Vec3d(0.9, 0.72, 0.9));
  };
  s.solid = [](const Vec3d& x) { return x[1] - 0.22; };
  return s;
}

// ---- material and time step ranges -------------------------------------------------------------

TEST(HardCases, ViscosityFromOneThousandthToOneMillion) {
  for (double mu : {1e-3, 1e-1, 1e1, 1e3, 1e6}) {
    test::MixedBoundaryProblem<2> m(32);
    m.prob.rho = 1.0;
    m.prob.mu = mu;
    m.prob.dt = 0.1;
    char caseName[32];
    std::snprintf(caseName, sizeof caseName, "mu=%g", mu);
    for (Model model : kModels) expectStableStep(caseName, model, m.prob, stepOptions(model));
  }
}

TEST(HardCases, TimeStepFromOneTenThousandthToOne) {
  for (double dt : {1e-4, 1e-2, 1.0}) {
    HardProblemSpec spec = poolSpec<2>(32);
    spec.dt = dt;
    HardProblem<2> p(spec);
    char caseName[32];
    std::snprintf(caseName, sizeof caseName, "dt=%g", dt);
    for (Model model : kModels) expectStableStep(caseName, model, p.prob, stepOptions(model));
  }
}

TEST(HardCases, ViscosityOneMillionIn3D) {
  HardProblemSpec spec = poolSpec<3>(16);
  spec.mu = 1e6;
  HardProblem<3> p(spec);
  for (Model model : kModels) expectStableStep("3D mu=1e6", model, p.prob, stepOptions(model));
}

// ---- thin liquid and small weights -------------------------------------------------------------

/// The smallest non-zero weight of a channel (1 when none is below it).
template <class Weights>
double smallestWetWeight(const Weights& weights) {
  double smallest = 1.0;
  for (double w : weights)
    if (w > 0.0) smallest = std::min(smallest, w);
  return smallest;
}

/// The liquid box's lower corner sits dx/6 above a cell centre on every axis, so of the corner
/// cell's 3^3 sub-samples only the one at +dx/3 per axis is liquid: W_L^p = 1/27 exactly.
TEST(HardCases, VolumeFractionsDownToOneTwentySeventh) {
  const int n = 16;
  const double dx = 1.0 / n, lo = 2.5 * dx + dx / 6.0, hi = 1.0 - lo;
  HardProblemSpec spec;
  spec.n = n;
  spec.liquid = [=](const Vec3d& x) { return test::boxLevelSet<3>(x, Vec3d(lo), Vec3d(hi)); };
  spec.liquidRule = sparse_grid::FractionRule::SubSamples;
  HardProblem<3> p(spec);
  ASSERT_EQ(smallestWetWeight(p.prob.liquidCell), 1.0 / 27.0);
  for (Model model : kModels) expectStableStep("3D fraction 1/27", model, p.prob, stepOptions(model));
}

/// Plane cuts (the engine's rule) have no smallest weight: the liquid box's faces lie 1e-9 dx
/// past the centres of the cells outside them, so those cells' W_L^p is 1e-9 and the corners'
/// less. Their rows carry W^2 of their weight (the SPD form's coarse levels were
/// near-singular at such weights before their weight floor; docs/design.md §5.5).
TEST(HardCases, PlaneCutWeightsDownToOneBillionth) {
  const int n = 16;
  const double dx = 1.0 / n, lo = 3.0 * dx - 1e-9 * dx, hi = 1.0 - lo;
  HardProblemSpec spec;
  spec.n = n;
  spec.liquid = [=](const Vec3d& x) { return test::boxLevelSet<3>(x, Vec3d(lo), Vec3d(hi)); };
  spec.liquidRule = sparse_grid::FractionRule::PlaneCut;
  HardProblem<3> p(spec);
  ASSERT_LE(smallestWetWeight(p.prob.liquidCell), 2e-9);
  for (Model model : kModels) expectStableStep("3D plane-cut fraction 1e-9", model, p.prob, stepOptions(model));
}

/// Liquid boundaries exactly on cell faces (phi = 0 on sub-samples: ties count as air).
TEST(HardCases, LiquidExactlyOnCellFaces) {
  const int n = 32;
  const double dx = 1.0 / n;
  HardProblemSpec spec;
  spec.n = n;
  spec.liquid = [=](const Vec3d& x) { return test::boxLevelSet<2>(x, Vec3d(4 * dx), Vec3d(28 * dx, 22 * dx, 0.0)); };
  HardProblem<2> p(spec);
  for (Model model : kModels) expectStableStep("on cell faces", model, p.prob, stepOptions(model));
}

/// A liquid slab one cell thick (2D and 3D) and a thread one cell wide (3D): every liquid sample
/// is next to air, so no tile survives the air band; the reduced models must reduce to uniform.
TEST(HardCases, OneCellThickSheetAndOneCellWideThread) {
  {
    const double dx = 1.0 / 32;
    HardProblemSpec spec;
    spec.n = 32;
    spec.liquid = [=](const Vec3d& x) { return test::boxLevelSet<2>(x, Vec3d(0.1, 16 * dx, 0), Vec3d(0.9, 17 * dx, 0)); };
    HardProblem<2> p(spec);
    for (Model model : kModels) expectStableStep("sheet 2D", model, p.prob, stepOptions(model));
  }
  const double dx = 1.0 / 16;
  HardProblemSpec sheet;
  sheet.n = 16;
  sheet.liquid = [=](const Vec3d& x) { return test::boxLevelSet<3>(x, Vec3d(0.1, 8 * dx, 0.1), Vec3d(0.9, 9 * dx, 0.9)); };
  HardProblem<3> p3(sheet);
  HardProblemSpec thread = sheet;
  thread.liquid = [=](const Vec3d& x) { return test::boxLevelSet<3>(x, Vec3d(0.1, 8 * dx, 8 * dx), Vec3d(0.9, 9 * dx, 9 * dx)); };
  HardProblem<3> t3(thread);
  for (Model model : kModels) {
    const StepReport s = expectStableStep("sheet 3D", model, p3.prob, stepOptions(model));
    const StepReport t = expectStableStep("thread 3D", model, t3.prob, stepOptions(model));
    EXPECT_EQ(s.tiles, 0u);
    EXPECT_EQ(t.tiles, 0u);
  }
}

// ---- padding -----------------------------------------------------------------------------------

/// Padding 2 with 16-cell tiles, where the thesis reports convergence trouble.
TEST(HardCases, PaddingTwo) {
  HardProblem<2> p(poolSpec<2>(48));
  sparse_grid::TilingOptions t = smallTiles();
  t.tileSize = 16;
  for (Model model : {Model::Affine, Model::Quadratic}) {
    const StepReport rep = expectStableStep("padding 2, tile 16", model, p.prob, stepOptions(model, t));
    EXPECT_GT(rep.tiles, 0u);
  }
}

/// Padding 1 is refused for every system with viscosity (viscous stencils reach two cells, so
/// J^T B^-1 J would couple neighbouring tiles), with a message that says so; nothing is written.
/// The pressure projection has no viscous stencil and accepts it.
TEST(HardCases, PaddingOneIsRefusedWithViscosityAndAcceptedWithout) {
  HardProblem<2> p(poolSpec<2>(32));
  sparse_grid::TilingOptions t = smallTiles();
  t.padding = 1;
  const std::string expected =
      "reduced tiles: padding 1 is refused with viscosity: viscous stencils reach two cells, so --pad must be >= 2 "
      "(thesis 4.4)";
  for (Model model : {Model::Affine, Model::Quadratic})
    for (auto system : {solver::SystemKind::UnifiedStokes, solver::SystemKind::Viscosity,
                        solver::SystemKind::DecoupledStokes}) {
      StepOptions opt = stepOptions(model, t);
      opt.system = system;
      Vector u{42.0};
      try {
        solver::solveStep(p.prob, opt, u);
        ADD_FAILURE() << "padding 1 must be refused for " << solver::toString(system);
      } catch (const std::invalid_argument& e) {
        EXPECT_EQ(std::string(e.what()), expected);
      }
      EXPECT_EQ(u.size(), 1u);
      EXPECT_EQ(u[0], 42.0);
      table().push_back({std::string("padding 1 ") + solver::toString(system), name(model), 0, 0.0, 0.0,
                         "refused: " + expected});
    }
  for (Model model : {Model::Affine, Model::Quadratic}) {
    StepOptions opt = stepOptions(model, t);
    opt.system = solver::SystemKind::PressureProjection;
    const StepReport rep = expectStableStep("padding 1 pressure", model, p.prob, opt);
    EXPECT_GT(rep.tiles, 0u);
  }
}

// ---- irregular tiles ---------------------------------------------------------------------------

/// The tiling the step will use (tiles are rebuilt identically inside solveStep).
template <int Dim>
solver::ReducedTiles<Dim> tilesOf(const solver::StaggeredProblem<Dim>& prob, Model model,
                                  const sparse_grid::TilingOptions& tiling) {
  return solver::ReducedTiles<Dim>(prob, *stepOptions(model, tiling).reduced,
                                   solver::couplingKinds(solver::SystemKind::UnifiedStokes));
}

/// An L-shaped liquid (the unit box less its upper-right quarter) with 24-cell tiles: the tile
/// in the corner is L-shaped, i.e. non-convex.
TEST(HardCases, NonConvexTile) {
  HardProblemSpec spec;
  spec.n = 40;
  spec.liquid = [](const Vec3d& x) {
    return std::max(test::boxLevelSet<2>(x, Vec3d(0.05), Vec3d(0.95)), -test::boxLevelSet<2>(x, Vec3d(0.55), Vec3d(2.0)));
  };
  HardProblem<2> p(spec);
  sparse_grid::TilingOptions t = smallTiles();
  t.tileSize = 24;
  for (Model model : {Model::Affine, Model::Quadratic}) {
    const auto tiles = tilesOf(p.prob, model, t);
    int nonConvex = 0;
    for (const auto& tile : tiles.tiling().tiles) nonConvex += tile.isFullBox ? 0 : 1;
    EXPECT_GT(nonConvex, 0) << name(model);
    expectStableStep("non-convex tile", model, p.prob, stepOptions(model, t));
  }
}

/// A solid pillar inside a tile region: the solid band cuts a hole into the tile.
TEST(HardCases, TileWithAHole) {
  const int n = 40;
  const double dx = 1.0 / n;
  const Vec3d pillar(12.5 * dx, 12.5 * dx, 0.0);
  HardProblemSpec spec;
  spec.n = n;
  spec.liquid = [](const Vec3d& x) { return test::boxLevelSet<2>(x, Vec3d(0.05), Vec3d(0.95)); };
  spec.solid = [=](const Vec3d& x) { return test::distance<2>(x, pillar) - 1.2 * dx; };
  HardProblem<2> p(spec);
  sparse_grid::TilingOptions t = smallTiles();
  t.tileSize = 24;
  const std::size_t pillarSlot = std::size_t(p.layout.slotOf(sparse_grid::Coord(12, 12, 0)));
  for (Model model : {Model::Affine, Model::Quadratic}) {
    const auto tiles = tilesOf(p.prob, model, t);
    bool holed = false;  // a tile whose bounding box contains the pillar cell, which it excludes
    for (const auto& tile : tiles.tiling().tiles)
      holed = holed || (tile.bboxMin.x() < 12 && tile.bboxMax.x() > 12 && tile.bboxMin.y() < 12 && tile.bboxMax.y() > 12);
    EXPECT_TRUE(holed) << name(model);
    EXPECT_LT(tiles.tiling().tileOfCell[pillarSlot], 0);
    expectStableStep("tile with a hole", model, p.prob, stepOptions(model, t));
  }
}

/// Tile size 4 with padding 2 leaves regions of exactly 2 x 2 (x 2) cells: the smallest tile.
TEST(HardCases, SmallestTiles) {
  sparse_grid::TilingOptions t = smallTiles();
  t.tileSize = 4;
  HardProblem<2> p(poolSpec<2>(32));
  HardProblem<3> p3(poolSpec<3>(16));
  for (Model model : {Model::Affine, Model::Quadratic}) {
    const auto tiles = tilesOf(p.prob, model, t);
    ASSERT_GT(tiles.numTiles() + tiles.fallbacks().size(), 0u);
    for (const auto& tile : tiles.tiling().tiles) EXPECT_EQ(tile.cells.size(), 4u);
    expectStableStep("tile 2x2", model, p.prob, stepOptions(model, t));
    const auto tiles3 = tilesOf(p3.prob, model, t);
    for (const auto& tile : tiles3.tiling().tiles) EXPECT_EQ(tile.cells.size(), 8u);
    expectStableStep("tile 2x2x2", model, p3.prob, stepOptions(model, t));
  }
}

/// One large tile in a shallow pool: the solid band below and the air band above both clip it,
/// so it ends exactly bandSolid cells above the floor's partial cells and bandAir cells below the
/// surface's partial cells.
TEST(HardCases, TileClippedByAirAndSolidBands) {
  HardProblem<2> p(poolSpec<2>(32));
  sparse_grid::TilingOptions t = smallTiles();
  t.tileSize = 31;
  for (Model model : {Model::Affine, Model::Quadratic}) {
    const auto tiles = tilesOf(p.prob, model, t);
    ASSERT_EQ(tiles.numTiles(), 1u);
    const sparse_grid::Tile& tile = tiles.tiling().tiles[0];
    const int x = (tile.bboxMin.x() + tile.bboxMax.x()) / 2;
    const auto below = std::size_t(p.layout.slotOf(sparse_grid::Coord(x, tile.bboxMin.y() - t.bandSolid - 1, 0)));
    const auto above = std::size_t(p.layout.slotOf(sparse_grid::Coord(x, tile.bboxMax.y() + t.bandAir + 1, 0)));
    EXPECT_LT(p.prob.fluidStress[below], 1.0);  // channel 0: the cell centre
    EXPECT_LT(p.prob.liquidCell[above], 1.0);
    expectStableStep("tile clipped by both bands", model, p.prob, stepOptions(model, t));
  }
}

// ---- closed containers -------------------------------------------------------------------------

/// A box with walls 1.2 cells thick, point-sampled (binary W_F), full of liquid: constant pressure
/// is a null vector of the SPD operator and is handed to the solver.
HardProblemSpec closedBoxSpec(int n) {
  const double wall = 1.2 / n;
  HardProblemSpec s;
  s.n = n;
  s.liquid = [](const Vec3d&) { return -1.0; };
  s.solid = [=](const Vec3d& x) { return -test::boxLevelSet<2>(x, Vec3d(wall), Vec3d(1.0 - wall)); };
  s.solidSubsamples = 1;
  return s;
}

TEST(HardCases, ClosedContainerFullOfLiquid) {
  HardProblem<2> p(closedBoxSpec(32));
  ASSERT_NE(solver::PressureStressSystem<2>(p.prob, true).nullSpace(), nullptr);
  for (Model model : kModels) expectStableStep("closed, full", model, p.prob, stepOptions(model));
}

/// The same box with fractional walls (3 sub-samples, liquid = non-solid): W_L^p varies along the
/// walls, so the null vector is 1/W_L^p, not the constant the system tests for; b is still
/// orthogonal to it (zero net flux), so CG converges on the consistent singular system.
TEST(HardCases, ClosedContainerWithFractionalWalls) {
  HardProblemSpec spec = closedBoxSpec(32);
  spec.solidSubsamples = 3;
  const auto solid = spec.solid;
  spec.liquid = [=](const Vec3d& x) { return -solid(x); };
  HardProblem<2> p(spec);
  for (Model model : kModels) expectStableStep("closed, fractional walls", model, p.prob, stepOptions(model));
}

/// A tiny air pocket (radius 0.7 dx) in the full box pins the pressure: no null space.
TEST(HardCases, ClosedContainerWithTinyAirPocket) {
  HardProblemSpec spec = closedBoxSpec(32);
  const double dx = 1.0 / 32;
  const Vec3d centre(0.5 + 0.3 * dx, 0.5 + 0.2 * dx, 0.0);
  spec.liquid = [=](const Vec3d& x) { return 0.7 * dx - test::distance<2>(x, centre); };
  HardProblem<2> p(spec);
  ASSERT_EQ(solver::PressureStressSystem<2>(p.prob, true).nullSpace(), nullptr);
  for (Model model : kModels) expectStableStep("closed, tiny air pocket", model, p.prob, stepOptions(model));
}

// ---- right-hand sides --------------------------------------------------------------------------

/// u* = 0: b = 0, so the solver returns x = 0 without iterating and u = 0 exactly.
TEST(HardCases, ZeroRightHandSide) {
  HardProblem<2> p(poolSpec<2>(32));
  std::fill(p.prob.uStar.begin(), p.prob.uStar.end(), 0.0);
  for (Model model : kModels) {
    Vector u;
    const StepReport rep = solver::solveStep(p.prob, stepOptions(model), u);
    record("zero rhs", name(model), rep, solver::toString(rep.solve.status));
    EXPECT_EQ(rep.solve.status, solver::Status::Converged) << rep.diagnostics;
    EXPECT_EQ(rep.solve.iterations, 0);
    EXPECT_EQ(rep.kineticEnergy, 0.0);
    ASSERT_EQ(u.size(), 2 * p.prob.slots());
    for (double v : u) ASSERT_EQ(v, 0.0);
  }
}

/// A NaN in u* is refused before anything is written, naming the face and its cell.
TEST(HardCases, NanInRightHandSideIsNamedAndNothingIsWritten) {
  HardProblem<2> p(poolSpec<2>(32));
  const std::size_t slot = std::size_t(p.layout.slotOf(sparse_grid::Coord(16, 12, 0)));  // inside a tile region
  p.prob.uStar[1 * p.prob.slots() + slot] = std::numeric_limits<double>::quiet_NaN();
  const std::string expected = "StaggeredProblem: non-finite velocity on face axis 1 of cell (16,12,0)";
  for (Model model : kModels) {
    Vector u{42.0}, solution{7.0};
    try {
      solver::solveStep(p.prob, stepOptions(model), u, &solution);
      ADD_FAILURE() << "a NaN in u* must be refused";
    } catch (const std::invalid_argument& e) {
      EXPECT_EQ(std::string(e.what()), expected);
    }
    EXPECT_EQ(u, Vector{42.0});
    EXPECT_EQ(solution, Vector{7.0});
    table().push_back({"NaN in u*", name(model), 0, 0.0, 0.0, "refused: " + expected});
  }
}

// ---- singular tile fits ------------------------------------------------------------------------

/// A 2 x 2 tile has 8 boundary faces, fewer than the 9 columns of the 2D quadratic divergence-free
/// basis: its boundary fit is singular (rank 7). Such a tile keeps the 7 modes its faces resolve
/// -- every affine mode (5) and 2 quadratic ones -- instead of going back to Cartesian cells: the
/// step counts it as a tile that keeps fewer modes, holds 7 unknowns per tile, stays stable
/// (energy, divergence), and gives one answer in both Stokes forms. An affine divergence-free u*
/// lies in the kept modes, so the fit reproduces it to rounding.
TEST(HardCases, SingularQuadraticFitKeepsTheModesItResolves) {
  HardProblem<2> p(poolSpec<2>(32));
  const std::size_t n = p.prob.slots();
  for (std::size_t s = 0; s < n; ++s) {  // u* = (1 + x - 0.5 y, -2 - y): divergence free, affine
    const auto c = p.prob.layout->cellOf(s);
    const double dx = p.prob.layout->dx(), x = c.x() * dx, y = c.y() * dx;
    p.prob.uStar[s] = 1.0 + x - 0.5 * (y + 0.5 * dx);
    p.prob.uStar[n + s] = -2.0 - y;
  }
  sparse_grid::TilingOptions t = smallTiles();
  t.tileSize = 4;
  StepOptions opt = stepOptions(Model::Quadratic, t);
  opt.reduced->fitAllFaces = false;
  Vector spd, pv;
  const StepReport rep = expectStableStep("singular quadratic fit", Model::Quadratic, p.prob, opt, &spd);
  EXPECT_GT(rep.tiles, 0u);
  EXPECT_EQ(rep.fallbackTiles, 0u) << rep.diagnostics;
  EXPECT_EQ(rep.partialTiles, rep.tiles);
  EXPECT_EQ(rep.reducedDofs, 7 * rep.tiles);
  EXPECT_LT(rep.reconstructionLinf, 1e-12);
  StepOptions pvOpt = opt;
  pvOpt.form = solver::StokesForm::PressureVelocity;
  solver::solveStep(p.prob, pvOpt, pv);
  ASSERT_EQ(spd.size(), pv.size());
  const double scale = maxAbs(spd);
  for (std::size_t i = 0; i < spd.size(); ++i) ASSERT_NEAR(spd[i], pv[i], 1e-6 * scale) << "face " << i;
}

// ---- boundaries --------------------------------------------------------------------------------

/// Liquid fills every active cell: it touches the edge of the grid on all sides (2D N = 32, a
/// whole number of blocks, and N = 36, which leaves inactive slots in the edge blocks; 3D n = 12).
TEST(HardCases, LiquidTouchingTheDomainBoundaryOnAllSides) {
  for (int n : {32, 36}) {
    HardProblemSpec spec;
    spec.n = n;
    spec.liquid = [](const Vec3d&) { return -1.0; };
    HardProblem<2> p(spec);
    for (Model model : kModels) expectStableStep("fills domain 2D N=" + std::to_string(n), model, p.prob, stepOptions(model));
  }
  HardProblemSpec spec;
  spec.n = 12;
  spec.liquid = [](const Vec3d&) { return -1.0; };
  HardProblem<3> p3(spec);
  for (Model model : kModels) expectStableStep("fills domain 3D n=12", model, p3.prob, stepOptions(model));
}

/// Liquid around a solid sphere on a solid floor, fractional weights along both (tests/solver/mixed_problem.h).
TEST(HardCases, LiquidInContactWithASolidSphere) {
  test::MixedBoundaryProblem<2> m2(48);
  for (Model model : kModels) expectStableStep("solid sphere 2D", model, m2.prob, stepOptions(model));
  test::MixedBoundaryProblem<3> m3(16);
  for (Model model : kModels) expectStableStep("solid sphere 3D", model, m3.prob, stepOptions(model));
}

// ---- guards at the step level ------------------------------------------------------------------

/// The iteration cap ends the solve with MaxIterations (no exception); the velocities of the last
/// iterate are finite and written, and the diagnostics line says what happened.
TEST(StepGuards, IterationCapIsAStatus) {
  HardProblem<2> p(poolSpec<2>(32));
  StepOptions opt = stepOptions(Model::Quadratic);
  opt.krylov.maxIterations = 5;
  Vector u;
  const StepReport rep = solver::solveStep(p.prob, opt, u);
  record("iteration cap 5", "quadratic", rep, solver::toString(rep.solve.status));
  EXPECT_EQ(rep.solve.status, solver::Status::MaxIterations);
  EXPECT_EQ(rep.solve.iterations, 5);
  EXPECT_EQ(rep.diagnostics.rfind("unified-stokes quadratic: MaxIterations after 5 iterations, relative residual ", 0), 0u)
      << rep.diagnostics;
  ASSERT_EQ(u.size(), 2 * p.prob.slots());
  EXPECT_EQ(firstNonFinite(u), -1);
}

/// rho = 1e-300 and dt = 1e10 are each valid, but S = dt W_F / (rho W_m) overflows to infinity:
/// the operator's output is non-finite. The step stops with NonFinite, names the first non-finite
/// row by its cell, and writes nothing.
TEST(StepGuards, NonFiniteOperatorIsNamedAndNothingIsWritten) {
  HardProblemSpec spec = poolSpec<2>(32);
  spec.rho = 1e-300;
  spec.dt = 1e10;
  HardProblem<2> p(spec);
  for (Model model : {Model::Uniform, Model::Quadratic}) {
    Vector u{42.0};
    const StepReport rep = solver::solveStep(p.prob, stepOptions(model), u);
    record("S overflows (rho 1e-300, dt 1e10)", name(model), rep, solver::toString(rep.solve.status));
    EXPECT_EQ(rep.solve.status, solver::Status::NonFinite) << rep.diagnostics;
    EXPECT_NE(rep.diagnostics.find("non-finite operator output at the pressure row of cell ("), std::string::npos)
        << rep.diagnostics;
    EXPECT_EQ(u, Vector{42.0});
  }
}

// ---- determinism -------------------------------------------------------------------------------

/// The quadratic model's step (tile fits, J^T B^-1 J coupling, CG) is bit-identical for 1 and 2
/// threads (the uniform Jacobi and the multigrid steps are checked in test_systems / test_multigrid).
/// n = 128: the live rows fill several reduction chunks (at 32 one, where nothing split over the
/// threads; at 64 two, whose partial sums add up alike in either order).
TEST(Determinism, QuadraticStepIsBitIdenticalForOneAndTwoThreads) {
  test::MixedBoundaryProblem<2> m(128);
  const StepOptions opt = stepOptions(Model::Quadratic);
  const auto [r1, r2] = test::expectStepBitIdenticalForOneAndTwoThreads(m.prob, opt);
  ASSERT_GT(r1.tiles, 0u);
  EXPECT_EQ(std::memcmp(&r1.kineticEnergy, &r2.kineticEnergy, sizeof(double)), 0);
}

}  // namespace
}  // namespace stokes
