// The assembled-free operators have the structure the maths promises: the pressure-stress form
// is symmetric positive semi-definite (positive on random vectors), the viscosity form is SPD,
// closed containers expose the constant-pressure null space, and solves are bit-identical for
// 1 and 2 threads.
#include <gtest/gtest.h>
#include <omp.h>

#include <cstdio>
#include <cstring>
#include <random>

#include "solver/step/stokes_step.h"
#include "solver/systems/pressure_stress_system.h"
#include "solver/systems/pressure_velocity_system.h"
#include "solver/systems/viscosity_system.h"
#include "sparse_grid/volume_weights.h"
#include "mixed_problem.h"
#include "tests/test_helpers.h"
#include "tests/thread_determinism.h"

namespace stokes {
namespace {

using sparse_grid::StressChannels;
using sparse_grid::Vec3d;
using solver::StaggeredProblem;
using solver::Vector;

template <class T>
class SystemTest : public ::testing::Test {};
using Dims = ::testing::Types<std::integral_constant<int, 2>, std::integral_constant<int, 3>>;
TYPED_TEST_SUITE(SystemTest, Dims);

TYPED_TEST(SystemTest, UnifiedStokesOperatorIsSymmetricPositive) {
  constexpr int Dim = TypeParam::value;
  test::MixedBoundaryProblem<Dim> m(Dim == 2 ? 40 : 20);
  const solver::PressureStressSystem<Dim> sys(m.prob, /*withStress=*/true);
  EXPECT_EQ(sys.nullSpace(), nullptr);  // free surface: no null space
  test::expectSymmetricPositive(sys, 5);
}

TYPED_TEST(SystemTest, PressureOperatorIsSymmetricPositive) {
  constexpr int Dim = TypeParam::value;
  test::MixedBoundaryProblem<Dim> m(Dim == 2 ? 40 : 20);
  const solver::PressureStressSystem<Dim> sys(m.prob, /*withStress=*/false);
  test::expectSymmetricPositive(sys, 6);
}

TYPED_TEST(SystemTest, ViscosityOperatorIsSymmetricPositive) {
  constexpr int Dim = TypeParam::value;
  test::MixedBoundaryProblem<Dim> m(Dim == 2 ? 40 : 20);
  const solver::ViscositySystem<Dim> sys(m.prob);
  test::expectSymmetricPositive(sys, 7);
}

/// The checks of PressureVelocityBlocksAreExact on one system.
template <int Dim>
void expectPressureVelocityBlocksExact(const solver::PressureVelocitySystem<Dim>& sys) {
  test::expectSymmetricPositive(sys, 8, /*positive=*/false, /*exactDiagonal=*/false);
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const auto& d = sys.diagonal();
  Vector x(sys.size(), 0.0), y(sys.size(), 1.0), yu(sys.velocityRows(), 1.0);
  for (std::size_t i = 0; i < sys.velocityRows(); ++i) x[i] = d[i] > 0.0 ? u(rng) : 0.0;
  sys.apply(x.data(), y.data());
  sys.applyVelocityBlock(x.data(), yu.data());
  EXPECT_EQ(std::memcmp(y.data(), yu.data(), yu.size() * sizeof(double)), 0);
  for (std::size_t i = sys.velocityRows(); i < sys.size(); ++i) x[i] = d[i] > 0.0 ? u(rng) : 0.0;
  sys.apply(x.data(), y.data());
  for (std::size_t i = 0; i < sys.size(); ++i) {
    if (!(d[i] > 0.0)) {
      ASSERT_EQ(y[i], 0.0) << "row " << i;
    }
  }
}

// The pressure-velocity operator skips the blocks without a pressure, stress or unknown face
// sample: it stays symmetric, its rows without a diagonal are zero, and the velocity block the
// multigrid applies on its own ([u_C | v_R], with quadratic tiles too) is the leading block of
// apply() with p = 0, bit for bit.
TYPED_TEST(SystemTest, PressureVelocityBlocksAreExact) {
  constexpr int Dim = TypeParam::value;
  test::MixedBoundaryProblem<Dim> m(Dim == 2 ? 64 : 40);
  const solver::PressureVelocitySystem<Dim> sys(m.prob);
  ASSERT_LT(sys.cellBlocks(), m.layout.numBlocks());  // some blocks are skipped
  ASSERT_LT(sys.faceBlocks(), m.layout.numBlocks());
  expectPressureVelocityBlocksExact(sys);
  solver::ReducedOptions r;
  r.order = solver::PolynomialOrder::Quadratic;
  r.fitAllFaces = true;
  r.tiling.tileSize = 8;
  r.tiling.padding = 2;
  const solver::ReducedTiles<Dim> tiles(m.prob, r, solver::couplingKinds(solver::SystemKind::UnifiedStokes));
  ASSERT_GT(tiles.numTiles(), 0u);
  const solver::PressureVelocitySystem<Dim> reduced(m.prob, &tiles);
  EXPECT_EQ(reduced.velocityRows(), reduced.faceRows() + tiles.totalDofs());
  expectPressureVelocityBlocksExact(reduced);
}

// One unified Stokes step is a constrained minimisation from u* with zero solid velocity: it can
// only lower the (weighted) kinetic energy, and it leaves the weighted divergence at solver
// tolerance.
TYPED_TEST(SystemTest, StokesStepLowersEnergyAndRemovesDivergence) {
  constexpr int Dim = TypeParam::value;
  test::MixedBoundaryProblem<Dim> m(Dim == 2 ? 48 : 20);
  solver::StepOptions opt;
  opt.krylov.relativeTolerance = 1e-12;
  Vector u;
  const auto rep = solver::solveStep(m.prob, opt, u);
  ASSERT_TRUE(rep.solve.converged()) << solver::toString(rep.solve.status);
  double before = 0.0, after = 0.0;
  for (std::size_t i = 0; i < u.size(); ++i) {
    const double w = m.prob.fluidFace[i] * std::max(m.prob.liquidFace[i], m.prob.minMassWeight);
    if (w <= 0.0) continue;
    before += w * m.prob.uStar[i] * m.prob.uStar[i];
    after += w * u[i] * u[i];
    ASSERT_TRUE(std::isfinite(u[i]));
  }
  EXPECT_LT(after, before);
  // Divergence: W_L^p G^T (W_F u), relative to the divergence of u*.
  const std::size_t n = m.layout.numSlots();
  Vector g(u.size()), gs(u.size()), div(n), divStar(n);
  for (std::size_t i = 0; i < u.size(); ++i) {
    g[i] = m.prob.fluidFace[i] * u[i];
    gs[i] = m.prob.fluidFace[i] * m.prob.uStar[i];
  }
  kernels::CellStressOutput out;
  out.pWeight = m.prob.liquidCell.data();
  out.p = div.data();
  kernels::cellsFromFaces<Dim>(m.layout, g.data(), out);
  out.p = divStar.data();
  kernels::cellsFromFaces<Dim>(m.layout, gs.data(), out);
  EXPECT_LT(std::sqrt(test::dotProduct(div, div)), 1e-8 * std::sqrt(test::dotProduct(divStar, divStar)));
}

// A closed container full of liquid (solid walls, no free surface): constant pressure is a null
// space, G 1_p = 0 because every face of the box's boundary is solid. The system detects it -- its
// unit vector is 1 / sqrt(cells) on the liquid cells, 0 on the stress rows, and A maps it to 0 --
// and the projection still converges to a divergence-free field: W_L^p G^T (W_F u + (1 - W_F)
// u_solid) = 0 to the solver tolerance against the random u*'s divergence (a divergence target is
// ignored there: the container's volume cannot change). Measured: A n = 0 exactly, and a
// divergence of 7.5e-11 to 9.9e-11 of u*'s in 2D and 3D (the 1e-10 residual tolerance); bound 1e-8.
TYPED_TEST(SystemTest, ClosedContainerHasPressureNullSpace) {
  constexpr int Dim = TypeParam::value;
  const int n = Dim == 2 ? 32 : 12;
  openvdb::MaskTree mask;
  sparse_grid::activateBox(mask, openvdb::Coord(-1), Dim == 3 ? openvdb::Coord(n) : openvdb::Coord(n, n, 0));
  const sparse_grid::BlockLayout<Dim> layout(mask, 1.0 / n);
  StaggeredProblem<Dim> prob;
  prob.layout = &layout;
  prob.allocate(true);
  std::fill(prob.liquidFace.begin(), prob.liquidFace.end(), 1.0);
  std::fill(prob.liquidCell.begin(), prob.liquidCell.end(), 1.0);
  std::fill(prob.liquidStress.begin(), prob.liquidStress.end(), 1.0);
  const std::size_t ns = layout.numSlots();
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> ud(-1.0, 1.0);
  for (int a = 0; a < Dim; ++a)
    for (std::size_t s = 0; s < ns; ++s) {
      const auto c = layout.cellOf(s);
      bool inside = true;  // faces strictly inside [0, n]: walls and beyond are solid
      for (int b = 0; b < Dim; ++b) inside = inside && (b == a ? (c[b] >= 1 && c[b] <= n - 1) : (c[b] >= 0 && c[b] <= n - 1));
      prob.fluidFace[a * ns + s] = inside ? 1.0 : 0.0;
      prob.uStar[a * ns + s] = ud(rng);
    }
  prob.divergenceTarget = 0.3;
  for (bool withStress : {false, true}) {
    const solver::PressureStressSystem<Dim> sys(prob, withStress);
    ASSERT_NE(sys.nullSpace(), nullptr) << "withStress " << withStress;
    // the null vector: constant on the liquid cells, zero on the stress rows, in the kernel of A
    std::size_t cells = 0;
    for (std::size_t s = 0; s < ns; ++s) cells += sys.diagonal()[s] > 0.0 ? 1 : 0;
    ASSERT_GT(cells, 0u);
    const double* null = sys.nullSpace();
    for (std::size_t i = 0; i < sys.size(); ++i) {
      const double expected = i < ns && sys.diagonal()[i] > 0.0 ? 1.0 / std::sqrt(double(cells)) : 0.0;
      ASSERT_NEAR(null[i], expected, 1e-15) << "row " << i << " withStress " << withStress;
    }
    Vector An(sys.size());
    sys.apply(null, An.data());
    const double maxDiag = *std::max_element(sys.diagonal().begin(), sys.diagonal().end());
    EXPECT_LT(std::sqrt(test::dotProduct(An, An)), 1e-12 * maxDiag) << "withStress " << withStress;
    solver::StepOptions opt;
    opt.system = withStress ? solver::SystemKind::UnifiedStokes : solver::SystemKind::PressureProjection;
    opt.krylov.relativeTolerance = 1e-10;
    Vector u;
    const auto rep = solver::solveStep(prob, opt, u);
    EXPECT_TRUE(rep.solve.converged()) << solver::toString(rep.solve.status);
    for (double v : u) ASSERT_TRUE(std::isfinite(v));
    // divergence after the step against u*'s (the walls carry u_solid = 0)
    Vector g(u.size()), gs(u.size()), div(ns), divStar(ns);
    for (std::size_t i = 0; i < u.size(); ++i) {
      g[i] = prob.fluidFace[i] * u[i] + (1.0 - prob.fluidFace[i]) * prob.solidVelocity(i);
      gs[i] = prob.fluidFace[i] * prob.uStar[i] + (1.0 - prob.fluidFace[i]) * prob.solidVelocity(i);
    }
    kernels::CellStressOutput out;
    out.pWeight = prob.liquidCell.data();
    out.p = div.data();
    kernels::cellsFromFaces<Dim>(layout, g.data(), out);
    out.p = divStar.data();
    kernels::cellsFromFaces<Dim>(layout, gs.data(), out);
    const double divNorm = std::sqrt(test::dotProduct(div, div)), starNorm = std::sqrt(test::dotProduct(divStar, divStar));
    std::printf("[ measured ] closed container, %dD withStress %d: |A n| %.2e of max diag, divergence %.2e of u*'s\n", Dim,
                int(withStress), std::sqrt(test::dotProduct(An, An)) / maxDiag, divNorm / starNorm);
    EXPECT_GT(starNorm, 0.0);
    EXPECT_LT(divNorm, 1e-8 * starNorm) << "withStress " << withStress;
  }
}

// A divergence target s (volume control) on a ball of liquid at rest, without gravity: the field
// that minimises the step's energy subject to div u = s is u = s (x - c) / Dim for every form --
// it is the potential flow grad phi with Delta phi = s and phi = 0 on the free surface, and its
// strain rate s/Dim I does no work against any divergence-free perturbation (eps(u) : eps(w) =
// s/Dim div w = 0). Checked: the weighted constraint W_L^p G^T u = -W_L^p s on every liquid cell
// to solver tolerance, and the velocities inside half the radius against s (x - c) / Dim.
TYPED_TEST(SystemTest, DivergenceTargetDilatesABallUniformly) {
  constexpr int Dim = TypeParam::value;
  const int n = Dim == 2 ? 64 : 24;
  const double dx = 1.0 / n, radius = 0.32, s = -0.4;
  const Vec3d c(0.5, 0.5, Dim == 3 ? 0.5 : 0.0);
  openvdb::MaskTree mask;
  sparse_grid::activateBox(mask, openvdb::Coord(0), Dim == 3 ? openvdb::Coord(n - 1) : openvdb::Coord(n - 1, n - 1, 0));
  const sparse_grid::BlockLayout<Dim> layout(mask, dx);
  StaggeredProblem<Dim> prob;
  prob.layout = &layout;
  prob.rho = 1.0;
  prob.mu = 5.0;
  prob.dt = 0.02;
  prob.allocate(/*withSolids=*/false);
  const auto offset = [&](const Vec3d& x) {
    Vec3d d = x - c;
    if (Dim == 2) d[2] = 0.0;
    return d;
  };
  solver::fillLiquidWeights(prob, [&](const Vec3d& x) { return offset(x).length() - radius; });
  prob.divergenceTarget = s;
  const std::size_t ns = layout.numSlots();

  struct Case { const char* name; solver::SystemKind system; solver::StokesForm form; solver::PreconditionerKind pc; };
  const Case cases[] = {
      {"unified pressure-stress, Jacobi CG", solver::SystemKind::UnifiedStokes, solver::StokesForm::PressureStress,
       solver::PreconditionerKind::Jacobi},
      {"unified pressure-velocity, MINRES + multigrid", solver::SystemKind::UnifiedStokes,
       solver::StokesForm::PressureVelocity, solver::PreconditionerKind::Multigrid},
      {"pressure projection", solver::SystemKind::PressureProjection, solver::StokesForm::PressureStress,
       solver::PreconditionerKind::Jacobi},
      {"decoupled", solver::SystemKind::DecoupledStokes, solver::StokesForm::PressureStress,
       solver::PreconditionerKind::Jacobi}};
  for (const Case& k : cases) {
    solver::StepOptions opt;
    opt.system = k.system;
    opt.form = k.form;
    opt.preconditioner = k.pc;
    opt.krylov.relativeTolerance = 1e-11;
    Vector u;
    const auto rep = solver::solveStep(prob, opt, u);
    ASSERT_TRUE(rep.solve.converged()) << k.name << ": " << solver::toString(rep.solve.status);
    Vector div(ns);
    kernels::CellStressOutput out;
    out.pWeight = prob.liquidCell.data();
    out.p = div.data();
    kernels::cellsFromFaces<Dim>(layout, u.data(), out);
    double constraint = 0.0;
    for (std::size_t i = 0; i < ns; ++i)
      if (prob.liquidCell[i] > 0.0) constraint = std::max(constraint, std::abs(div[i] + prob.liquidCell[i] * s));
    EXPECT_LT(constraint, 1e-7 * std::abs(s)) << k.name;
    double worst = 0.0;
    for (int a = 0; a < Dim; ++a)
      for (std::size_t i = 0; i < ns; ++i) {
        const Vec3d d = offset(layout.samplePosition(i, sparse_grid::faceMask(a)));
        if (d.length() < 0.5 * radius) worst = std::max(worst, std::abs(u[a * ns + i] - s * d[a] / Dim));
      }
    const double scale = std::abs(s) * radius / Dim;  // the exact speed at the surface
    EXPECT_LT(worst / scale, 0.005) << k.name;
    std::printf("  %s: constraint %.2e |s|, interior velocity error %.3f%% of |s| R / Dim\n", k.name,
                constraint / std::abs(s), 100.0 * worst / scale);
  }
}

// With solids, the liquid continues into them with zero-compliance stresses that hold its strain
// rate at zero, and a cell whose liquid only such pinned faces, solid faces and walls bound cannot
// change its volume: the divergence target skips the cells that reach no free surface through
// unpinned faces (solver/problem/divergence_target.h); with the source on every cell the system
// is inconsistent and CG diverges. The mixed-boundary blob (free surface, floor, sphere, random
// u*): both forms converge, with div u = s on the vented cells and div u = 0 on the others.
TYPED_TEST(SystemTest, DivergenceTargetSkipsCellsTheSolidsSeal) {
  constexpr int Dim = TypeParam::value;
  test::MixedBoundaryProblem<Dim> m(Dim == 2 ? 48 : 20);
  const double s = -0.5;
  m.prob.divergenceTarget = s;
  const std::size_t ns = m.layout.numSlots();
  const solver::PressureStressSystem<Dim> sys(m.prob, true);
  const std::vector<std::uint8_t> vented =
      solver::ventedCells(m.prob, sys.faceStates(), sys.pressureWeights().data(), sys.stressWeights().data());
  std::size_t sealed = 0, open = 0;
  for (std::size_t i = 0; i < ns; ++i)
    if (sys.diagonal()[i] > 0.0) (vented[i] ? open : sealed) += 1;
  EXPECT_GT(sealed, 0u);  // the case is there
  EXPECT_GT(open, 10 * sealed);
  for (auto form : {solver::StokesForm::PressureStress, solver::StokesForm::PressureVelocity}) {
    solver::StepOptions opt;
    opt.form = form;
    if (form == solver::StokesForm::PressureVelocity) opt.preconditioner = solver::PreconditionerKind::Multigrid;
    opt.krylov.relativeTolerance = 1e-11;
    Vector u;
    const auto rep = solver::solveStep(m.prob, opt, u);
    ASSERT_TRUE(rep.solve.converged()) << solver::toString(rep.solve.status);
    Vector g(u.size()), div(ns);
    for (std::size_t i = 0; i < u.size(); ++i)
      g[i] = m.prob.fluidFace[i] * u[i] + (1.0 - m.prob.fluidFace[i]) * m.prob.solidVelocity(i);
    kernels::CellStressOutput out;
    out.pWeight = m.prob.liquidCell.data();
    out.p = div.data();
    kernels::cellsFromFaces<Dim>(m.layout, g.data(), out);
    double worst = 0.0;
    for (std::size_t i = 0; i < ns; ++i)
      if (sys.diagonal()[i] > 0.0)
        worst = std::max(worst, std::abs(div[i] + (vented[i] ? m.prob.liquidCell[i] * s : 0.0)));
    EXPECT_LT(worst, 1e-6 * std::abs(s)) << int(form);
  }
}

TEST(Determinism, SolvesAreBitIdenticalForOneAndTwoThreads) {
  test::MixedBoundaryProblem<3> m(20);
  solver::StepOptions opt;
  opt.krylov.relativeTolerance = 1e-10;
  opt.rows = solver::RowStorage::Padded;  // the compact rows are checked in test_compact_rows
  test::expectStepBitIdenticalForOneAndTwoThreads(m.prob, opt);
}

TEST(ProblemValidation, NonFiniteVelocityIsNamed) {
  test::MixedBoundaryProblem<2> m(16);
  m.prob.uStar[5] = std::numeric_limits<double>::quiet_NaN();
  try {
    m.prob.validate();
    FAIL() << "expected an exception";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("non-finite velocity"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace stokes
