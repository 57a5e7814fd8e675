// One answer whichever form solves a step: the pressure-velocity form (MINRES) is the
// exact elimination of the pressure-stress form's compliant stresses, its rigid stress samples kept
// as multipliers (solver/systems/pressure_velocity_system.h). So both give the same face
// velocities to the solver tolerance in every case family -- free surface, solids, tiles, domain
// walls, inflow, a divergence target -- at two resolutions each.
//
// Tolerance 1e-12 on ||b - A x|| / ||b|| for both; bound 1e-8 of max |u|. Before the rigid
// samples became multipliers (the PV form clamped W_F^tau to 1/27, a 27x viscosity), the ball on
// solids differed by 7.8% (n = 16) and 1.9% (n = 32) in kinetic energy.
#include <gtest/gtest.h>
#include "sparse_grid/vdb_trees.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "analytic/analytic_cases.h"
#include "sim/scene/scene.h"
#include "sim/step/simulator.h"
#include "tests/test_helpers.h"

namespace stokes {
namespace {

using test::relativeMaxDifference;

constexpr double kTolerance = 1e-12;
constexpr double kAgreement = 1e-8;

/// max_i |a_i - b_i| / max_i |b_i|
using Runner = analytic::AnalyticResult (*)(const analytic::AnalyticOptions&);

/// The case solved on the SPD form (CG + Jacobi) and on the PV form (MINRES and GMRES + `pvPreconditioner`);
/// expects the same face velocities. Both keep every tile (the paying rule follows the solver).
void expectFormsAgree(const char* what, analytic::AnalyticOptions o, Runner run,
                      solver::PreconditionerKind pvPreconditioner, bool needsTiles = false) {
  o.keepVelocities = true;
  o.tileRule = solver::TileRule::All;
  o.tolerance = kTolerance;
  o.form = solver::StokesForm::PressureStress;
  o.method = solver::KrylovMethod::CG;
  o.preconditioner = solver::PreconditionerKind::Jacobi;
  const analytic::AnalyticResult spd = run(o);
  ASSERT_EQ(spd.status, "Converged") << what;
  o.form = solver::StokesForm::PressureVelocity;
  o.preconditioner = pvPreconditioner;
  // MINRES with the block-diagonal preconditioner; with the multigrid also GMRES with the block
  // upper-triangular one
  const bool multigrid = pvPreconditioner == solver::PreconditionerKind::Multigrid;
  for (solver::KrylovMethod method : {solver::KrylovMethod::MINRES, solver::KrylovMethod::GMRES}) {
    if (method == solver::KrylovMethod::GMRES && !multigrid) continue;
    o.method = method;
    const analytic::AnalyticResult pv = run(o);
    ASSERT_EQ(pv.status, "Converged") << what << ": " << pv.solver;
    if (needsTiles) {
      ASSERT_GT(spd.tiles, 0u) << what << " at n = " << o.n << " has no tile";
      ASSERT_EQ(spd.tiles, pv.tiles);
    }
    const double d = relativeMaxDifference(pv.velocities, spd.velocities);
    std::printf("[forms] %s n=%d: max |u_pv - u_spd| / max |u| = %.2e; kinetic energy %.10g / %.10g; iterations "
                "%d (SPD) / %d (PV, %s); %zu tiles\n",
                what, o.n, d, spd.kineticEnergyAfter, pv.kineticEnergyAfter, spd.iterations, pv.iterations,
                pv.solver.c_str(), spd.tiles);
    EXPECT_LE(d, kAgreement) << what << " at n = " << o.n << ", " << pv.solver;
  }
}

analytic::AnalyticOptions ballOptions(int n, bool solids) {
  analytic::AnalyticOptions o;
  o.dim = 3;
  o.n = n;
  o.solids = solids;
  return o;
}

TEST(OneAnswer, BallWithoutSolids) {
  for (int n : {16, 24})
    expectFormsAgree("ball", ballOptions(n, false), analytic::runBall, solver::PreconditionerKind::Jacobi);
}

TEST(OneAnswer, BallOnSolids) {
  for (int n : {16, 24})
    expectFormsAgree("ball on solids", ballOptions(n, true), analytic::runBall, solver::PreconditionerKind::Multigrid);
}

TEST(OneAnswer, Disk) {
  for (int n : {32, 64}) {
    analytic::AnalyticOptions o;
    o.n = n;
    o.mu = 0.1;
    expectFormsAgree("disk", o, analytic::runDiskStokes, solver::PreconditionerKind::Multigrid);
  }
}

// Tiles of 8 with a 1-cell band next to the solids: 1 tile at n = 24, 4 at n = 32.
TEST(OneAnswer, QuadraticTilesOnSolids) {
  for (int n : {24, 32}) {
    analytic::AnalyticOptions o = ballOptions(n, true);
    o.model = "quadratic";
    o.tileSize = 8;
    o.padding = 2;
    o.bandSolid = 1;
    expectFormsAgree("quadratic tiles, ball on solids", o, analytic::runBall, solver::PreconditionerKind::Multigrid,
                     /*needsTiles=*/true);
  }
}

// ---- scene steps: domain walls, solids, an emitter, the volume control's divergence target ----

const std::filesystem::path kScenes = std::filesystem::path(STOKES_SOURCE_DIR) / "scenes";

/// A liquid slab on the floor of the closed domain box, touching its four side walls, with a ball
/// dropped into it (domain walls; the volume control's divergence target after the first step).
std::string wallsScene(int resolution, const char* preconditioner) {
  return R"({"name": "walls", "domain": {"min": [0, 0, 0], "max": [0.2, 0.2, 0.2]},
    "resolution": )" + std::to_string(resolution) + R"(, "frames": 1, "fps": 24,
    "material": {"density": 1000, "viscosity": 20}, "gravity": [0, -9.81, 0], "viscosity": "coupled",
    "solver": {"tolerance": 1e-12, "max_iterations": 200000, "preconditioner": ")" + preconditioner + R"("},
    "liquid": [{"shape": "box", "min": [0, 0, 0], "max": [0.2, 0.06, 0.2]},
               {"shape": "sphere", "center": [0.1, 0.12, 0.1], "radius": 0.04, "velocity": [0.1, -0.3, 0.05]}],
    "output": {"preview": false}, "seed": 3})";
}

/// A nozzle pouring onto a tilted block (an emitter's inflow, a solid cut between grid lines, and
/// the liquid's extension into it: rigid stress samples).
std::string emitterScene(int resolution, const char* preconditioner) {
  return R"({"name": "emitter", "domain": {"min": [0, 0, 0], "max": [0.2, 0.2, 0.2]},
    "resolution": )" + std::to_string(resolution) + R"(, "frames": 1, "fps": 24,
    "material": {"density": 1000, "viscosity": 20}, "gravity": [0, -9.81, 0], "viscosity": "coupled",
    "solver": {"tolerance": 1e-12, "max_iterations": 200000, "preconditioner": ")" + preconditioner + R"("},
    "liquid": [{"shape": "box", "min": [0.06, 0.061, 0.06], "max": [0.14, 0.1, 0.14]}],
    "solids": [{"shape": "box", "min": [0.03, 0.0, 0.03], "max": [0.17, 0.0613, 0.17]}],
    "emitters": [{"shape": "disc", "center": [0.1, 0.16, 0.1], "radius": 0.02, "normal": [0, -1, 0],
                  "velocity": [0, -0.4, 0]}],
    "output": {"preview": false}, "seed": 5})";
}

/// Two steps of the scene with Jacobi CG on the SPD form and with GMRES + multigrid (block
/// upper-triangular) on the PV form; the particle velocities after each (G2P of the solved face velocities) must agree.
void expectSceneFormsAgree(const char* what, std::string (*text)(int, const char*), int resolution) {
  sim::Simulator spd(sim::parseSceneText(text(resolution, "jacobi"), "forms.json", kScenes.string()));
  sim::Simulator pv(sim::parseSceneText(text(resolution, "multigrid"), "forms.json", kScenes.string()));
  for (int step = 0; step < 2; ++step) {
    const sim::StepStats a = spd.step(0.005, 1), b = pv.step(0.005, 1);
    ASSERT_EQ(spd.particles().size(), pv.particles().size()) << what;
    std::vector<double> va, vb;
    for (std::size_t p = 0; p < spd.particles().size(); ++p)
      for (int k = 0; k < 3; ++k) {
        va.push_back(spd.particles().v[p][k]);
        vb.push_back(pv.particles().v[p][k]);
      }
    const double d = relativeMaxDifference(vb, va);
    std::printf("[forms] %s res %d step %d: max |v_pv - v_spd| / max |v| = %.2e; iterations %d (SPD) / %d (PV), %s\n",
                what, resolution, step, d, a.grid.iterations, b.grid.iterations, b.grid.solver.c_str());
    EXPECT_NE(b.grid.solver.find("pressure-velocity"), std::string::npos) << b.grid.solver;
    EXPECT_LE(d, kAgreement) << what << " at resolution " << resolution << ", step " << step;
  }
}

class OneAnswerScene : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { openvdb::initialize(); }
};

TEST_F(OneAnswerScene, DomainWallsAndDivergenceTarget) {
  for (int res : {16, 24}) expectSceneFormsAgree("slab on the domain walls", wallsScene, res);
}

TEST_F(OneAnswerScene, EmitterOverASolid) {
  for (int res : {16, 24}) expectSceneFormsAgree("nozzle over a block", emitterScene, res);
}

}  // namespace
}  // namespace stokes
