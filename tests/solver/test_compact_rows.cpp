// Compact rows (solver/krylov/compact_rows.h): the compact operator is exactly the
// padded operator restricted to its live rows (bit for bit), applyOnRows skips only blocks whose
// rows are dead, and a solve on the live rows gives the padded solve's velocities to the solver
// tolerance -- with Jacobi and with the multigrid cycle, for unified Stokes, the projection, the
// viscosity solve and reduced tiles -- bit-identically for 1 and 2 threads. The pressure-stress
// system's compact neighbour-index stencils (pressure_stress_rows.h) give the same bits as the
// block sweep.
#include <gtest/gtest.h>
#include <omp.h>

#include <cstring>
#include <random>

#include "analytic/analytic_cases.h"
#include "mixed_problem.h"
#include "tests/test_helpers.h"
#include "tests/thread_determinism.h"
#include "solver/step/stokes_step.h"
#include "solver/krylov/compact_rows.h"
#include "solver/systems/pressure_stress_rows.h"
#include "solver/systems/pressure_stress_system.h"
#include "solver/systems/pressure_velocity_rows.h"
#include "solver/systems/pressure_velocity_system.h"
#include "solver/systems/viscosity_system.h"

namespace stokes {
namespace {

using solver::RowSelection;
using solver::RowStorage;
using solver::Vector;

template <class T>
class CompactRowsTest : public ::testing::Test {};
using Dims = ::testing::Types<std::integral_constant<int, 2>, std::integral_constant<int, 3>>;
TYPED_TEST_SUITE(CompactRowsTest, Dims);

/// A random compact vector x_R, its padded image P x_R, and the checks
///   CompactOperator(x_R) == P^T A P x_R    and    applyOnRows(P x_R) == A P x_R on R,
/// both bit for bit.
template <class System>
void expectCompactIsRestriction(const System& sys, unsigned seed) {
  const RowSelection rows = RowSelection::positiveDiagonal(sys.diagonal());
  ASSERT_GT(rows.size(), 0u);
  ASSERT_LT(rows.size(), sys.size());  // the fixture has padding and dry rows
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Vector xr(rows.size());
  for (double& v : xr) v = u(rng);
  const Vector x = rows.expanded(xr.data());
  Vector yFull(sys.size());
  sys.apply(x.data(), yFull.data());
  const Vector expected = rows.gathered(yFull);
  const solver::CompactOperator<System> A(sys, rows);
  Vector yr(rows.size());
  A.apply(xr.data(), yr.data());
  EXPECT_EQ(0, std::memcmp(yr.data(), expected.data(), yr.size() * sizeof(double)));
  if constexpr (requires { sys.compliance(); }) {  // the compact neighbour-index stencils
    const solver::PressureStressRows<System::kDim> R(sys, rows);
    Vector yi(rows.size());
    R.apply(xr.data(), yi.data());
    EXPECT_EQ(0, std::memcmp(yi.data(), expected.data(), yi.size() * sizeof(double)));
  }
  // A's rows off R are zero: nothing is lost by dropping them.
  double offRows = 0.0;
  std::size_t k = 0;
  for (std::size_t i = 0; i < yFull.size(); ++i) {
    if (k < rows.size() && rows.rows()[k] == i) { ++k; continue; }
    offRows = std::max(offRows, std::abs(yFull[i]));
  }
  EXPECT_EQ(offRows, 0.0);
}

TYPED_TEST(CompactRowsTest, CompactOperatorIsTheRestrictionOfThePaddedOne) {
  constexpr int Dim = TypeParam::value;
  test::MixedBoundaryProblem<Dim> m(Dim == 2 ? 40 : 20);
  const solver::PressureStressSystem<Dim> stokes(m.prob, /*withStress=*/true);
  const solver::PressureStressSystem<Dim> projection(m.prob, /*withStress=*/false);
  const solver::ViscositySystem<Dim> viscosity(m.prob);
  expectCompactIsRestriction(stokes, 1);
  expectCompactIsRestriction(projection, 2);
  expectCompactIsRestriction(viscosity, 3);
  EXPECT_LT(stokes.rowBlocks(), m.layout.numBlocks());  // the blob leaves blocks without rows
}

/// Quadratic divergence-free tiles of 8 cells with 2 cells of padding.
solver::ReducedOptions quadraticTiles() {
  solver::ReducedOptions r;
  r.order = solver::PolynomialOrder::Quadratic;
  r.family = solver::BasisFamily::DivergenceFree;
  r.tiling.tileSize = 8;
  r.tiling.padding = 2;
  return r;
}

// The compact neighbour-index stencils with reduced tiles coupled in (J^T B^-1 J on tile faces):
// still P^T A P bit for bit.
TYPED_TEST(CompactRowsTest, RowStencilsWithTilesAreTheRestrictionOfThePaddedOperator) {
  constexpr int Dim = TypeParam::value;
  test::MixedBoundaryProblem<Dim> m(Dim == 2 ? 64 : 28);
  const solver::ReducedTiles<Dim> tiles(m.prob, quadraticTiles(), solver::couplingKinds(solver::SystemKind::UnifiedStokes));
  ASSERT_GT(tiles.numTiles(), 0u);
  const solver::PressureStressSystem<Dim> stokes(m.prob, /*withStress=*/true, &tiles);
  expectCompactIsRestriction(stokes, 4);
}

// The pressure-velocity form on its live rows through the compact neighbour index
// (pressure_velocity_rows.h) is P^T A P of the padded matrix-free apply, to rounding, with solids
// (rigid multiplier rows), a free surface and reduced tiles.
TYPED_TEST(CompactRowsTest, PressureVelocityRowsAreTheRestrictionOfThePaddedOperator) {
  constexpr int Dim = TypeParam::value;
  test::MixedBoundaryProblem<Dim> m(Dim == 2 ? 64 : 28);
  const solver::ReducedTiles<Dim> tiles(m.prob, quadraticTiles(), solver::couplingKinds(solver::SystemKind::UnifiedStokes));
  ASSERT_GT(tiles.numTiles(), 0u);
  for (const bool withTiles : {false, true}) {
    const solver::PressureVelocitySystem<Dim> sys(m.prob, withTiles ? &tiles : nullptr);
    const solver::RowSelection rows = solver::RowSelection::positiveDiagonal(sys.diagonal());
    const solver::PressureVelocityRows<Dim> op(sys, rows);
    const solver::CompactOperator<solver::PressureVelocitySystem<Dim>> ref(sys, rows);
    ASSERT_EQ(op.size(), rows.size());
    std::mt19937_64 rng(17);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    Vector x(rows.size()), y(rows.size()), yRef(rows.size());
    for (double& v : x) v = u(rng);
    op.apply(x.data(), y.data());
    ref.apply(x.data(), yRef.data());
    EXPECT_LT(test::relativeMaxDifference(y, yRef), 1e-12) << (withTiles ? "tiles" : "uniform");
    EXPECT_GT(sys.rigidRows(), 0u);  // the floor and the sphere hold rigid stress samples
  }
}

/// Face velocities of one step with the Krylov vectors on live rows and on padded blocks.
template <int Dim>
void expectSameVelocities(const solver::StaggeredProblem<Dim>& prob, solver::StepOptions opt, double tolerance) {
  opt.krylov.relativeTolerance = 1e-12;
  Vector uc, up;
  opt.rows = RowStorage::Compact;
  const auto rc = solver::solveStep(prob, opt, uc);
  opt.rows = RowStorage::Padded;
  const auto rp = solver::solveStep(prob, opt, up);
  ASSERT_TRUE(rc.solve.converged()) << solver::toString(rc.solve.status);
  ASSERT_TRUE(rp.solve.converged()) << solver::toString(rp.solve.status);
  EXPECT_LT(rc.krylovRows, rp.krylovRows);
  EXPECT_EQ(rc.unknowns, rp.unknowns);
  double diff = 0.0, scale = 0.0;
  for (std::size_t i = 0; i < uc.size(); ++i) {
    diff = std::max(diff, std::abs(uc[i] - up[i]));
    scale = std::max(scale, std::abs(up[i]));
  }
  EXPECT_LT(diff, tolerance * scale) << solver::toString(opt.system) << ", iterations " << rc.solve.iterations
                                     << " compact against " << rp.solve.iterations << " padded";
}

TYPED_TEST(CompactRowsTest, CompactAndPaddedSolvesAgree) {
  constexpr int Dim = TypeParam::value;
  test::MixedBoundaryProblem<Dim> m(Dim == 2 ? 40 : 16);
  for (auto system : {solver::SystemKind::UnifiedStokes, solver::SystemKind::PressureProjection,
                      solver::SystemKind::DecoupledStokes}) {
    solver::StepOptions opt;
    opt.system = system;
    expectSameVelocities(m.prob, opt, 1e-8);
  }
  solver::StepOptions mg;  // the padded multigrid cycle wrapped onto the live rows
  mg.system = solver::SystemKind::PressureProjection;
  mg.preconditioner = solver::PreconditionerKind::Multigrid;
  expectSameVelocities(m.prob, mg, 1e-8);
}

TEST(CompactRows, ReducedTilesGiveThePaddedAnswer) {
  analytic::AnalyticOptions o;
  o.n = 32;
  o.mu = 0.1;
  o.model = "quadratic";
  o.tolerance = 1e-12;
  o.rows = RowStorage::Compact;
  const auto compact = analytic::runDiskStokes(o);
  o.rows = RowStorage::Padded;
  const auto padded = analytic::runDiskStokes(o);
  ASSERT_EQ(compact.status, "Converged");
  ASSERT_EQ(padded.status, "Converged");
  ASSERT_GT(compact.tiles, 0u);
  EXPECT_LT(compact.krylovRows, padded.krylovRows);
  EXPECT_NEAR(compact.L1, padded.L1, 1e-8 * padded.L1);
  EXPECT_NEAR(compact.Linf, padded.Linf, 1e-8 * padded.Linf);
}

// Where nothing but a free surface bounds the liquid and the blocks are nearly full (the disk: 1.04
// padded rows per live row), the default runs the pressure-velocity form on the padded
// re-discretised cycle; with tiles it keeps the Galerkin cycle on live rows. Either cycle solves
// the same system: the same errors against the exact disk to the solver's tolerance.
TEST(CompactRows, FreeSurfaceDiskRunsThePaddedCycleWithTheGalerkinAnswer) {
  analytic::AnalyticOptions o;
  o.n = 128;
  o.mu = 0.1;
  o.form = solver::StokesForm::PressureVelocity;
  o.preconditioner = solver::PreconditionerKind::Multigrid;
  o.tolerance = 1e-12;
  const auto automatic = analytic::runDiskStokes(o);
  o.rows = RowStorage::Compact;
  const auto galerkin = analytic::runDiskStokes(o);
  ASSERT_EQ(automatic.status, "Converged");
  ASSERT_EQ(galerkin.status, "Converged");
  EXPECT_EQ(automatic.krylovRows, automatic.paddedRows);
  EXPECT_LT(galerkin.krylovRows, galerkin.paddedRows);
  EXPECT_NEAR(automatic.L1, galerkin.L1, 1e-8 * galerkin.L1);
  EXPECT_NEAR(automatic.Linf, galerkin.Linf, 1e-8 * galerkin.Linf);
  o.rows = RowStorage::Auto;
  o.model = "quadratic";
  o.tileRule = solver::TileRule::All;  // the paying rule would drop these tiles for the padded cycle
  const auto reduced = analytic::runDiskStokes(o);
  ASSERT_GT(reduced.tiles, 0u);
  EXPECT_LT(reduced.krylovRows, reduced.paddedRows);
}

// The ball at n = 96 (1.87 padded rows per live row, a free surface alone) runs the padded
// velocity cycle by default, with the same bits on 1 and 2 threads.
TEST(CompactRows, PaddedVelocityCycleIsBitIdenticalForOneAndTwoThreads) {
  analytic::AnalyticOptions o;
  o.n = 96;
  o.form = solver::StokesForm::PressureVelocity;
  o.preconditioner = solver::PreconditionerKind::Multigrid;
  o.tolerance = 1e-6;
  const analytic::BallStep step = analytic::ballStep(o);
  const auto [r1, r2] = test::expectStepBitIdenticalForOneAndTwoThreads(step.prob, step.options);
  EXPECT_EQ(r1.krylovRows, r1.paddedRows);
  EXPECT_TRUE(r1.solve.converged()) << solver::toString(r1.solve.status);
}

TEST(CompactRows, SolveIsBitIdenticalForOneAndTwoThreads) {
  test::MixedBoundaryProblem<3> m(20);
  solver::StepOptions opt;
  opt.rows = RowStorage::Compact;
  opt.krylov.relativeTolerance = 1e-10;
  for (bool rowStencils : {true, false}) {
    opt.rowStencils = rowStencils;
    const auto [r1, r2] = test::expectStepBitIdenticalForOneAndTwoThreads(m.prob, opt);
    EXPECT_LT(r1.krylovRows, r1.paddedRows);
  }
}

// The neighbour-index stencils and the block sweep are the same operator bit for bit, so CG takes
// the same steps: same iterations, same velocities to the last bit.
TEST(CompactRows, RowStencilsAndBlockSweepGiveTheSameSolve) {
  test::MixedBoundaryProblem<3> m(20);
  solver::StepOptions opt;
  opt.rows = RowStorage::Compact;
  opt.krylov.relativeTolerance = 1e-10;
  Vector ui, ub;
  opt.rowStencils = true;
  const auto ri = solver::solveStep(m.prob, opt, ui);
  opt.rowStencils = false;
  const auto rb = solver::solveStep(m.prob, opt, ub);
  ASSERT_TRUE(ri.solve.converged());
  EXPECT_EQ(ri.solve.iterations, rb.solve.iterations);
  ASSERT_EQ(ui.size(), ub.size());
  EXPECT_EQ(0, std::memcmp(ui.data(), ub.data(), ui.size() * sizeof(double)));
}

// A step on an empty layout (no blocks) has nothing to solve, whatever the row storage.
TEST(CompactRows, EmptyLayoutSolvesToNothing) {
  const sparse_grid::BlockLayout<3> layout(openvdb::MaskTree(), 0.1);
  solver::StaggeredProblem<3> prob;
  prob.layout = &layout;
  prob.rho = 1.0;
  prob.mu = 1.0;
  prob.dt = 0.1;
  prob.allocate(/*withSolids=*/false);
  for (RowStorage rows : {RowStorage::Auto, RowStorage::Compact, RowStorage::Padded}) {
    solver::StepOptions opt;
    opt.rows = rows;
    Vector u;
    const auto rep = solver::solveStep(prob, opt, u);
    EXPECT_TRUE(rep.solve.converged()) << solver::toString(rep.solve.status);
    EXPECT_EQ(rep.solve.iterations, 0);
    EXPECT_EQ(u.size(), 0u);
  }
}

TEST(CompactRows, SelectionRejectsUnsortedRows) {
  EXPECT_THROW(RowSelection({3, 2}, 5), std::invalid_argument);
  EXPECT_THROW(RowSelection({1, 5}, 5), std::invalid_argument);
  try {
    RowSelection({0, 0}, 4);
    FAIL() << "expected an exception";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("increasing"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace stokes
