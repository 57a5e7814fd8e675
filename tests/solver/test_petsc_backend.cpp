// The PETSc backend (solver/petsc/): run by ctest on 1 and on 2 MPI ranks (mpirun -np R). Every
// rank builds the same problem; the PETSc solve must give the in-house solve's face velocities to
// the solver tolerance, and its pieces (the row partition, the ghost exchange, the assembled
// matrix) must be exact.
#include <gtest/gtest.h>
#include <mpi.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <random>
#include <string>

#include "analytic/analytic_cases.h"
#include "solver/petsc/face_levels.h"
#include "solver/petsc/pressure_stress_ranks.h"
#include "solver/step/stokes_step.h"
#include "solver/systems/pressure_stress_system.h"
#include "tests/test_helpers.h"

namespace stokes {
namespace {

using test::relativeMaxDifference;

namespace mpi = solver::petsc;
using solver::Vector;

/// max_i |a_i - b_i| / max_i |b_i|
/// The same analytic case solved in-house (Jacobi CG on the pressure-stress form), by PETSc (CG +
/// Jacobi unless the options database says otherwise), and -- for unified Stokes -- in-house on the
/// pressure-velocity form (MINRES + multigrid), all to relative residual `tol`.
struct Pair {
  analytic::AnalyticResult inHouse, petsc, pressureVelocity;
};
Pair solveBoth(analytic::AnalyticOptions o, analytic::AnalyticResult (*run)(const analytic::AnalyticOptions&)) {
  o.keepVelocities = true;
  o.form = solver::StokesForm::PressureStress;
  o.method = solver::KrylovMethod::CG;
  o.preconditioner = solver::PreconditionerKind::Jacobi;
  Pair p;
  p.inHouse = run(o);
  if (o.system == solver::SystemKind::UnifiedStokes) {
    analytic::AnalyticOptions pv = o;
    pv.form = solver::StokesForm::PressureVelocity;
    pv.method = solver::KrylovMethod::MINRES;
    pv.preconditioner = solver::PreconditionerKind::Multigrid;
    pv.tileRule = solver::TileRule::All;  // the tiles of the SPD solves (the paying rule follows the solver)
    p.pressureVelocity = run(pv);
  }
  o.backend = solver::Backend::Petsc;
  o.rankSetup = "whole";  // every rank's velocities on the whole layout, as the in-house solve's
  p.petsc = run(o);
  return p;
}

// Tolerance 1e-12 on ||b - A x|| / ||b||: measured, the face velocities then agree to 2.9e-12 of
// their largest value or better on every case below (1 and 2 ranks); the bound leaves 30x.
constexpr double kTol = 1e-12;
constexpr double kVelocityAgreement = 1e-10;
constexpr double kFormAgreement = 1e-8;  // MINRES stops on its own (preconditioned) residual norm

void expectSameVelocities(const Pair& p, const char* what) {
  ASSERT_EQ(p.inHouse.status, "Converged") << what;
  ASSERT_EQ(p.petsc.status, "Converged") << what << ": " << p.petsc.solver;
  EXPECT_LE(p.petsc.relativeResidual, 2.0 * kTol) << what;  // true vs recursive residual: rounding
  EXPECT_NE(p.petsc.solver.find("PETSc"), std::string::npos) << p.petsc.solver;
  EXPECT_NE(p.petsc.solver.find("on " + std::to_string(mpi::ranks()) + " rank"), std::string::npos) << p.petsc.solver;
  const double d = relativeMaxDifference(p.petsc.velocities, p.inHouse.velocities);
  EXPECT_LE(d, kVelocityAgreement) << what << " on " << mpi::ranks() << " rank(s)";
  if (mpi::rank() == 0)
    std::printf("[ petsc ] %s on %d rank(s): max |u_petsc - u_in-house| / max |u| = %.2e; iterations %d (PETSc) / %d "
              "(in-house)\n",
              what, mpi::ranks(), d, p.petsc.iterations, p.inHouse.iterations);
  // one answer: the pressure-velocity form agrees with both (tests/sim/test_forms.cpp)
  if (!p.pressureVelocity.velocities.empty()) {
    ASSERT_EQ(p.pressureVelocity.status, "Converged") << what << ": " << p.pressureVelocity.solver;
    const double dpv = relativeMaxDifference(p.petsc.velocities, p.pressureVelocity.velocities);
    EXPECT_LE(dpv, kFormAgreement) << what << ": PETSc against the pressure-velocity form";
    if (mpi::rank() == 0)
      std::printf("[ petsc ] %s on %d rank(s): max |u_petsc - u_pv| / max |u| = %.2e\n", what, mpi::ranks(), dpv);
  }
  EXPECT_EQ(p.petsc.Linf == 0.0, p.inHouse.Linf == 0.0);
}

analytic::AnalyticOptions caseOptions(int n, double mu) {
  analytic::AnalyticOptions o;
  o.n = n;
  o.mu = mu;
  o.tolerance = kTol;
  return o;
}

TEST(PetscBackend, DiskGivesTheInHouseVelocities) {
  expectSameVelocities(solveBoth(caseOptions(48, 0.1), analytic::runDiskStokes), "disk N = 48");
}

TEST(PetscBackend, BallGivesTheInHouseVelocities) {
  analytic::AnalyticOptions o = caseOptions(16, 1.0);
  o.dim = 3;
  expectSameVelocities(solveBoth(o, analytic::runBall), "ball 16^3");
}

TEST(PetscBackend, BallOnSolidsGivesTheInHouseVelocities) {
  analytic::AnalyticOptions o = caseOptions(16, 1.0);
  o.dim = 3;
  o.solids = true;
  expectSameVelocities(solveBoth(o, analytic::runBall), "ball 16^3 on solids");
}

// Reduced tiles: the tiles' J^T B^-1 J runs inside the MatShell on the rank whose rows touch them.
TEST(PetscBackend, ReducedTilesGiveTheInHouseVelocities) {
  analytic::AnalyticOptions o = caseOptions(64, 0.1);
  o.model = "quadratic";
  o.tileSize = 8;
  o.padding = 3;
  const Pair p = solveBoth(o, analytic::runDiskStokes);
  ASSERT_GT(p.petsc.tiles, 0u);
  EXPECT_EQ(p.petsc.tiles, p.inHouse.tiles);
  expectSameVelocities(p, "quadratic disk N = 64, tiles 8/3");
}

// Adaptive tiles: every rank builds the same octree from the same options and problem (the
// tiling's accuracy included), so the tiles and velocities agree.
TEST(PetscBackend, AdaptiveTilesGiveTheInHouseVelocities) {
  analytic::AnalyticOptions o = caseOptions(64, 0.1);
  o.model = "quadratic";
  o.tileSize = 32;
  o.minTileSize = 8;
  o.tileAccuracy = 0.1;
  o.padding = 3;
  const Pair p = solveBoth(o, analytic::runDiskStokes);
  ASSERT_GT(p.inHouse.tilesByEdge.size(), 1u) << "the case must mix cube edges";
  EXPECT_EQ(p.petsc.tilesByEdge, p.inHouse.tilesByEdge);
  expectSameVelocities(p, "quadratic disk N = 64, adaptive tiles 32 -> 8");
}

// A preconditioner from the options database that needs entries (GAMG on the assembled AIJ
// matrix), and the field split (pressure | stresses) with a Schur complement: the same velocities.
// The disk's weights by sub-samples: with the engine's plane cuts the disk has weights down to
// round-off (1e-13; W^2 of them on a row's diagonal), and the Schur field split with GAMG on 2 ranks
// ends "NonFinite" (1 rank, and GAMG alone, converge). PETSc's GAMG builds
// its own coarse levels, which meet the near-null rows the in-house multigrid floors
// (kCoarseLiquidWeightFloor); the scenes drop such weights.
TEST(PetscBackend, OptionsDatabaseChoosesAssembledPreconditioners) {
  for (const char* options : {"-pc_type gamg", "-pc_type fieldsplit -pc_fieldsplit_type schur "
                                               "-pc_fieldsplit_schur_fact_type full -fieldsplit_0_pc_type gamg "
                                               "-fieldsplit_1_pc_type jacobi -ksp_type fgmres"}) {
    mpi::Session::initialise({options});
    analytic::AnalyticOptions o = caseOptions(32, 0.1);
    o.liquidWeights = sparse_grid::FractionRule::SubSamples;
    const Pair p = solveBoth(o, analytic::runDiskStokes);
    mpi::Session::clearOptions();
    const std::string want = std::string(options).find("fieldsplit") != std::string::npos ? "fieldsplit" : "gamg";
    EXPECT_NE(p.petsc.solver.find(want), std::string::npos) << p.petsc.solver;
    expectSameVelocities(p, options);
  }
}

// The partition covers every live row once, the ghost exchange feeds the matrix-free apply the
// right values, and without tiles the assembled AIJ rows are A: (A x)_owned from the MatShell's
// callback equals the CSR rows times x, on every rank.
TEST(PetscBackend, PartitionGhostsAndAssemblyAreExact) {
  test::WalledLayerProblem<3> w(16);
  const solver::PressureStressSystem<3> sys(w.prob, true);
  const solver::RowSelection rows = solver::RowSelection::positiveDiagonal(sys.diagonal());
  mpi::PressureStressRanks<3> split(
      sys, rows, mpi::PressureStressRanks<3>::owners(w.layout, mpi::ranks()), mpi::rank());
  const mpi::DistributedSystem& d = split.system();
  EXPECT_EQ(mpi::sumOverRanks(double(d.ownedRows)), double(rows.size()));
  EXPECT_GT(d.ownedRows, 0u);
  if (mpi::ranks() > 1) {
    EXPECT_GT(split.ghostRows(), 0u);
  }
  std::mt19937_64 rng(11);  // the same x on every rank
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<double> x(rows.size());
  for (double& v : x) v = u(rng);
  std::vector<std::int64_t> rowStart, columns;
  std::vector<double> values;
  d.assemble(rowStart, columns, values);
  std::vector<double> ghosts, yShell(d.ownedRows);
  for (std::int64_t g : d.ghostRows) ghosts.push_back(x[std::size_t(g)]);
  d.apply(ghosts.data(), yShell.data());
  double worst = 0.0, scale = 0.0;
  for (std::size_t k = 0; k < d.ownedRows; ++k) {
    double y = 0.0;
    for (std::int64_t e = rowStart[k]; e < rowStart[k + 1]; ++e) y += values[e] * x[std::size_t(columns[e])];
    worst = std::max(worst, std::abs(y - yShell[k]));
    scale = std::max(scale, std::abs(yShell[k]));
  }
  EXPECT_LE(worst, 1e-12 * scale);
  // and the shell apply is the padded system's apply on the rank's rows
  Vector xPadded(sys.size(), 0.0), yPadded(sys.size(), 0.0);
  split.numbering().scatterWhole(x, rows.rows(), xPadded.data());
  sys.apply(xPadded.data(), yPadded.data());
  double shellVsSystem = 0.0;
  for (std::size_t k = 0; k < d.ownedRows; ++k)
    shellVsSystem = std::max(shellVsSystem, std::abs(yShell[k] - yPadded[rows.rows()[split.numbering().owned()[k]]]));
  EXPECT_EQ(shellVsSystem, 0.0);  // the same stencil terms in the same order: bit for bit
  std::vector<double> yBlocks(d.ownedRows);
  split.applyOnBlocks(ghosts.data(), yBlocks.data());
  EXPECT_EQ(yBlocks, yShell);  // the padded block kernels on the rank's blocks, bit for bit
}

/// The case on PETSc's default solve of the SPD form (CG + Jacobi).
analytic::AnalyticOptions petscJacobiCg(analytic::AnalyticOptions o) {
  o.form = solver::StokesForm::PressureStress;
  o.method = solver::KrylovMethod::CG;
  o.preconditioner = solver::PreconditionerKind::Jacobi;
  o.backend = solver::Backend::Petsc;
  return o;
}

double maxAbs(const Vector& v) {
  double m = 0.0;
  for (double x : v) m = std::max(m, std::abs(x));
  return m;
}

/// max |u_part - u_whole| over the faces of the blocks each rank owns in `part` (a ball set up per
/// rank), against the same faces of `whole`, over all ranks; infinity if a face is missing there.
double ownedFaceDifference(const analytic::BallStep& part, const analytic::BallStep& whole, const Vector& uPart,
                           const Vector& uWhole) {
  double worst = 0.0;
  const std::size_t nPart = part.layout->numSlots(), nWhole = whole.layout->numSlots();
  for (std::size_t s = 0; s < nPart; ++s) {
    if (!part.prob.ownsSlot(s)) continue;
    const std::int64_t w = whole.layout->slotOf(part.layout->cellOf(s));
    if (w < 0) return mpi::maxOverRanks(std::numeric_limits<double>::infinity());
    for (int a = 0; a < 3; ++a)
      worst = std::max(worst, std::abs(uPart[a * nPart + s] - uWhole[a * nWhole + std::size_t(w)]));
  }
  return mpi::maxOverRanks(worst);
}

// Per-rank set-up (StaggeredProblem::blockOwner): each rank builds the ball's weights and u* on
// its own blocks and a halo only. The step must give the whole problem's velocities on every face
// it owns, the owned blocks must tile the whole layout once, and on more than one rank no rank may
// hold the whole layout. Both are cut by the same rule and number their rows alike (rank by rank,
// block by block), and each row's stencil sums its terms in the same order: the same bits,
// iterations and velocities. With reduced tiles each rank builds the tiles near its blocks
// (ReducedTiles::keepTilesNearOwnedBlocks) on a halo as deep as they reach
// (solver::distributedTileDepth); a tile may lie on several ranks, and each must build it as the
// whole problem does.
void expectPerRankSetUpGivesTheWholeProblem(analytic::AnalyticOptions o, const char* label) {
  o.dim = 3;
  o.rankSetup = "whole";
  const analytic::BallStep whole = analytic::ballStep(o);
  o.rankSetup = "own";
  const analytic::BallStep part = analytic::ballStep(o);
  ASSERT_FALSE(whole.prob.isDistributed());
  ASSERT_TRUE(part.prob.isDistributed());
  std::size_t ownedBlocks = 0;
  for (std::int32_t r : part.prob.blockOwner) ownedBlocks += r == mpi::rank() ? 1 : 0;
  EXPECT_EQ(mpi::sumOverRanks(double(ownedBlocks)), double(whole.layout->numBlocks()));
  if (mpi::ranks() > 1) {
    EXPECT_LT(part.layout->numBlocks(), whole.layout->numBlocks());
  }

  Vector uWhole, uPart;
  const solver::StepReport repWhole = solver::solveStep(whole.prob, whole.options, uWhole);
  const solver::StepReport repPart = solver::solveStep(part.prob, part.options, uPart);
  ASSERT_TRUE(repWhole.solve.converged()) << repWhole.diagnostics;
  ASSERT_TRUE(repPart.solve.converged()) << repPart.diagnostics;
  EXPECT_EQ(repPart.krylovRows, repWhole.krylovRows);
  EXPECT_EQ(repPart.unknowns, repWhole.unknowns);
  EXPECT_EQ(repPart.tiles, repWhole.tiles);
  EXPECT_EQ(repPart.reducedDofs, repWhole.reducedDofs);
  EXPECT_EQ(repPart.solve.iterations, repWhole.solve.iterations);
  EXPECT_NEAR(repPart.kineticEnergy, repWhole.kineticEnergy, 1e-12 * repWhole.kineticEnergy);

  const double largest = maxAbs(uWhole), worst = ownedFaceDifference(part, whole, uPart, uWhole);
  EXPECT_EQ(worst, 0.0);
  if (mpi::rank() == 0)
    std::printf("[ petsc ] %s set up per rank on %d rank(s): %zu of %zu blocks held, %zu tiles; max |u_own - "
                "u_whole| / max |u| = %.2e; iterations %d against %d\n",
                label, mpi::ranks(), part.layout->numBlocks(), whole.layout->numBlocks(), repPart.tiles,
                worst / largest, repPart.solve.iterations, repWhole.solve.iterations);
}

TEST(PetscBackend, PerRankSetUpGivesTheWholeProblemsVelocities) {
  expectPerRankSetUpGivesTheWholeProblem(petscJacobiCg(caseOptions(40, 1.0)), "ball 40^3");
}

TEST(PetscBackend, PerRankSetUpWithTilesGivesTheWholeProblemsVelocities) {
  analytic::AnalyticOptions o = petscJacobiCg(caseOptions(64, 0.1));
  o.model = "quadratic";
  o.tileSize = 10;  // cubes across the 8^3 blocks, as the armadillos' (a halo of 2 blocks)
  o.padding = 3;
  expectPerRankSetUpGivesTheWholeProblem(o, "quadratic-tile ball 64^3");
}

// The same in 2D: the disk set up per rank gives the whole problem's iterations and errors
// (L1 summed over the ranks' owned faces: equal to rounding; Linf, a maximum: equal), without
// tiles and with quadratic tiles built per rank.
void expectPerRankDiskGivesTheWholeProblem(analytic::AnalyticOptions o) {
  o.rankSetup = "whole";
  const analytic::AnalyticResult whole = analytic::runDiskStokes(o);
  o.rankSetup = "own";
  const analytic::AnalyticResult part = analytic::runDiskStokes(o);
  ASSERT_EQ(whole.status, "Converged") << whole.solver;
  ASSERT_EQ(part.status, "Converged") << part.solver;
  if (mpi::ranks() > 1) {
    EXPECT_NE(part.solver.find("each holding its blocks and a halo"), std::string::npos) << part.solver;
  }
  EXPECT_EQ(part.iterations, whole.iterations);
  EXPECT_EQ(part.tiles, whole.tiles);
  EXPECT_EQ(part.Linf, whole.Linf);
  EXPECT_NEAR(part.L1, whole.L1, 1e-12 * whole.L1);
  EXPECT_NEAR(part.kineticEnergyAfter, whole.kineticEnergyAfter, 1e-12 * whole.kineticEnergyAfter);
}

TEST(PetscBackend, PerRankSetUpOfTheDiskGivesTheWholeProblemsErrors) {
  expectPerRankDiskGivesTheWholeProblem(petscJacobiCg(caseOptions(64, 0.1)));
  analytic::AnalyticOptions tiled = petscJacobiCg(caseOptions(64, 0.1));
  tiled.model = "quadratic";
  tiled.tileSize = 12;
  tiled.padding = 3;
  expectPerRankDiskGivesTheWholeProblem(tiled);
}

// A case with adaptive tiles keeps the whole problem on every rank, whatever the rank set-up asks
// (the octree's split test reads the whole liquid's velocity variation): it is solved, with its
// tiles, not refused.
TEST(PetscBackend, AdaptiveTilesKeepTheWholeProblem) {
  analytic::AnalyticOptions o = petscJacobiCg(caseOptions(64, 0.1));
  o.model = "quadratic";
  o.tileSize = 16;
  o.minTileSize = 8;
  o.tileAccuracy = 0.1;
  o.padding = 3;
  o.rankSetup = "own";
  const analytic::AnalyticResult r = analytic::runDiskStokes(o);
  ASSERT_EQ(r.status, "Converged") << r.solver;
  EXPECT_GT(r.tiles, 0u);
  EXPECT_EQ(r.solver.find("each holding"), std::string::npos) << r.solver;
}

// A closed container: constant pressure is A's null space; PETSc gets it through MatSetNullSpace
// and must still give the in-house velocities.
TEST(PetscBackend, ClosedContainerNullSpace) {
  test::WalledLayerProblem<2> w(32, /*level=*/2.0);
  ASSERT_NE(solver::PressureStressSystem<2>(w.prob, true).nullSpace(), nullptr);
  solver::StepOptions opt;
  opt.krylov.relativeTolerance = kTol;
  Vector uInHouse, uPetsc;
  ASSERT_TRUE(solver::solveStep(w.prob, opt, uInHouse).solve.converged());
  opt.backend = solver::Backend::Petsc;
  const solver::StepReport rep = solver::solveStep(w.prob, opt, uPetsc);
  ASSERT_TRUE(rep.solve.converged()) << rep.diagnostics;
  EXPECT_LE(relativeMaxDifference(uPetsc, uInHouse),
            kVelocityAgreement);
}

// The pressure-velocity form on PETSc (pressure_velocity_ranks.h: MINRES with PCMG on the face
// levels of face_levels.h for the velocity block and Jacobi on the Schur diagonal estimate) gives
// the in-house pressure-velocity solve's velocities: the 2D disk held whole by every rank, and the
// ball on solids (rigid multipliers) and without, each rank building its blocks and a halo. Both
// solve to relative residual 1e-12 (PETSc's MINRES continued to the true residual). Measured on 1
// and 2 ranks: the balls' faces agree to 1.1e-13 and 6.7e-15 of the largest; the bound is the
// forms' agreement used above (kFormAgreement, 1e-8).
// The disk's PETSc solve takes 50 MINRES iterations on 1 and on 2 ranks (PETSc 3.18; the in-house
// cycle 59). Its bound, kDiskPvIterations = 100, is twice that: room for another PETSc release's
// MINRES and PCMG details, while the velocity block without its multigrid fails it (Jacobi in
// place of PCMG, -fieldsplit_0_pc_type jacobi: 425; PCMG with constant interpolation across the
// face normals takes 65 and passes, VelocityMultigridInterpolationReproducesLinearFields catches it).
TEST(PetscBackend, PressureVelocityFormGivesTheInHouseVelocities) {
  auto pvOptions = [](analytic::AnalyticOptions o) {
    o.form = solver::StokesForm::PressureVelocity;
    o.method = solver::KrylovMethod::MINRES;
    o.preconditioner = solver::PreconditionerKind::Multigrid;
    o.keepVelocities = true;
    return o;
  };
  {
    const analytic::AnalyticOptions o = pvOptions(caseOptions(32, 0.1));
    analytic::AnalyticOptions petsc = o;
    petsc.backend = solver::Backend::Petsc;
    petsc.rankSetup = "whole";  // every rank's velocities on the whole layout, as the in-house solve's
    const analytic::AnalyticResult inHouse = analytic::runDiskStokes(o), onPetsc = analytic::runDiskStokes(petsc);
    ASSERT_EQ(onPetsc.status, "Converged") << onPetsc.solver;
    EXPECT_NE(onPetsc.solver.find("PETSc minres + fieldsplit"), std::string::npos) << onPetsc.solver;
    EXPECT_LE(relativeMaxDifference(onPetsc.velocities, inHouse.velocities), kFormAgreement);
    constexpr int kDiskPvIterations = 100;
    EXPECT_LE(onPetsc.iterations, kDiskPvIterations) << onPetsc.solver;
    if (mpi::rank() == 0)
      std::printf("[ petsc ] pressure-velocity form, disk N = 32 on %d rank(s): %d MINRES iterations (in-house %d)\n",
                  mpi::ranks(), onPetsc.iterations, inHouse.iterations);
  }
  for (bool solids : {false, true}) {
    analytic::AnalyticOptions o = pvOptions(caseOptions(24, 1.0));
    o.dim = 3;
    o.solids = solids;
    const analytic::BallStep whole = analytic::ballStep(o);
    o.backend = solver::Backend::Petsc;
    const analytic::BallStep part = analytic::ballStep(o);
    ASSERT_TRUE(part.prob.isDistributed());
    Vector uWhole, uPart;
    ASSERT_TRUE(solver::solveStep(whole.prob, whole.options, uWhole).solve.converged());
    const solver::StepReport rep = solver::solveStep(part.prob, part.options, uPart);
    ASSERT_TRUE(rep.solve.converged()) << rep.diagnostics;
    const double largest = maxAbs(uWhole), worst = ownedFaceDifference(part, whole, uPart, uWhole);
    EXPECT_LE(worst, kFormAgreement * largest) << (solids ? "ball on solids" : "ball");
    if (mpi::rank() == 0)
      std::printf("[ petsc ] pressure-velocity form, ball 24^3%s on %d rank(s): max |u_petsc - u_in-house| / max |u| = "
                  "%.2e, %d MINRES iterations\n",
                  solids ? " on solids" : "", mpi::ranks(), worst / largest, rep.solve.iterations);
  }
}

// The velocity multigrid's levels over ranks (face_levels.h) are a function of the fine faces
// alone: built from a ball's faces split by blocks over the ranks, and from all of them on rank 0,
// every level holds the same faces and every P_l the same (fine face, coarse face, weight) terms,
// bit for bit. Each P_l row keeps its axis and sums to 1 (the staggered prolongation carries a
// constant field exactly: its weights are dyadic, so the sums are exact).
template <int Dim>
std::vector<solver::petsc::FaceSample> ballFaces(int radius) {
  std::vector<solver::petsc::FaceSample> faces;
  const int zMax = Dim == 3 ? radius : 0;
  for (int x = -radius; x <= radius; ++x)
    for (int y = -radius; y <= radius; ++y)
      for (int z = -zMax; z <= zMax; ++z)
        if (x * x + y * y + z * z <= radius * radius)
          for (int a = 0; a < Dim; ++a) faces.push_back({a, sparse_grid::Coord(x, y, z)});
  return faces;
}

// Every rank's (fine face, coarse face, weight) terms of P_l, in one sorted list on every rank.
using Term = std::array<double, 9>;
template <int Dim>
std::vector<Term> allTerms(solver::petsc::FaceLevels<Dim>& levels, const std::vector<solver::petsc::FaceSample>& fine,
                           std::size_t l) {
  auto flat = [](const std::vector<solver::petsc::FaceSample>& faces) {
    std::vector<double> v;
    for (const auto& f : faces) v.insert(v.end(), {double(f.axis), double(f.cell[0]), double(f.cell[1]), double(f.cell[2])});
    return v;
  };
  const std::vector<double> coarse = flat(levels.coarseRows(l));
  const std::vector<double> all = mpi::allGather(coarse.data(), coarse.size());  // by number
  const std::vector<solver::petsc::FaceSample>& rows = l == 0 ? fine : levels.coarseRows(l - 1);
  const solver::petsc::Interpolation& p = levels.transfers()[l];
  std::vector<double> mine;
  for (std::size_t i = 0; i < rows.size(); ++i) {
    double sum = 0.0;
    for (std::int64_t k = p.rowStart[i]; k < p.rowStart[i + 1]; ++k) {
      const double* c = all.data() + 4 * p.columns[std::size_t(k)];
      EXPECT_EQ(int(c[0]), rows[i].axis) << "P mixes the face axes";
      mine.insert(mine.end(), {double(rows[i].axis), double(rows[i].cell[0]), double(rows[i].cell[1]),
                               double(rows[i].cell[2]), c[0], c[1], c[2], c[3], p.values[std::size_t(k)]});
      sum += p.values[std::size_t(k)];
    }
    EXPECT_EQ(sum, 1.0) << "row " << i << " of P_" << l;
  }
  const std::vector<double> gathered = mpi::allGather(mine.data(), mine.size());
  std::vector<Term> terms(gathered.size() / 9);
  for (std::size_t t = 0; t < terms.size(); ++t) std::copy_n(gathered.begin() + std::ptrdiff_t(9 * t), 9, terms[t].begin());
  std::sort(terms.begin(), terms.end());
  return terms;
}

template <int Dim>
void expectLevelsIndependentOfTheSplit(sparse_grid::CellAxes finest, sparse_grid::CellAxes coarser) {
  const std::vector<solver::petsc::FaceSample> all = ballFaces<Dim>(Dim == 3 ? 13 : 40);
  std::vector<solver::petsc::FaceSample> mine;  // split by blocks of 8 cells along x
  for (const auto& f : all)
    if (((f.cell[0] >> 3) % mpi::ranks() + mpi::ranks()) % mpi::ranks() == mpi::rank()) mine.push_back(f);
  const std::vector<solver::petsc::FaceSample> onRankZero = mpi::rank() == 0 ? all : std::vector<solver::petsc::FaceSample>{};
  solver::petsc::FaceLevels<Dim> split(mine, finest, coarser, 40, 12), whole(onRankZero, finest, coarser, 40, 12);
  ASSERT_EQ(split.transfers().size(), whole.transfers().size());
  ASSERT_GE(split.transfers().size(), 2u);
  for (std::size_t l = 0; l < split.transfers().size(); ++l) {
    const std::vector<Term> a = allTerms(split, mine, l), b = allTerms(whole, onRankZero, l);
    EXPECT_EQ(a.size(), b.size()) << "level " << l;
    EXPECT_TRUE(a == b) << "P_" << l << " differs between the splits";
  }
}

TEST(PetscBackend, VelocityMultigridLevelsAreIndependentOfTheSplit) {
  using sparse_grid::CellAxes;
  expectLevelsIndependentOfTheSplit<3>(CellAxes::Constant, CellAxes::Linear);  // the default
  expectLevelsIndependentOfTheSplit<3>(CellAxes::Linear, CellAxes::Linear);
  expectLevelsIndependentOfTheSplit<3>(CellAxes::Constant, CellAxes::Constant);
  expectLevelsIndependentOfTheSplit<2>(CellAxes::Linear, CellAxes::Linear);
}

// The fields each P_l carries exactly. On level l (cells of edge h_l = 2^l, global cell
// coordinates) the face of axis a of cell c sits at x_a = c_a h_l and x_b = (c_b + 1/2) h_l across
// its normal (b != a). Along the normal P_l is linear interpolation between the coarse faces 2C and
// 2C + 2 (weights 1, or 1/2 and 1/2), exact for any u linear in x_a. Across it, CellAxes::Linear
// takes 3/4 of the parent cell's centre and 1/4 of its nearer neighbour's, at h_l/2 and 3 h_l/2
// from the fine face: exact for any u linear in x_b. CellAxes::Constant takes the parent's value
// alone, whose centre lies h_l/2 from every fine face, so u = x_b comes back off by exactly
// h_l/2 on every row (signs alternating with c_b's parity). With u_l, u_{l+1} the samples of one
// field on the two levels, P_l u_{l+1} - u_l on every row of level l is then
//   0 (round-off)      for u_a = alpha_a + beta_a x_a, on every level;
//   0 (round-off)      for any affine u_a = alpha_a + sum_b beta_ab x_b, where P_l is Linear across;
//   +-h_l/2 (exactly)  for u_a = x_(a+1 mod Dim), where P_l is Constant across (dyadic values).
// In 3D PressureVelocityRanks::faceLevels keeps P_0 Constant and makes the coarser P_l Linear where
// viscosity dominates the step (else Constant); in 2D all are Linear. The round-off bound: each
// row sums at most 2^Dim products of values below `scale` (largest |u_l|); measured, the errors
// stay below 3e-16 * scale (1 and 2 ranks), and 1e-14 * scale leaves 30x.
using Affine = std::array<std::array<double, 4>, 3>;  // u_a = [a][0] + sum_b [a][1 + b] x_b

template <int Dim>
double faceValue(const Affine& u, int axis, const double* cell, std::size_t level) {
  const double h = std::ldexp(1.0, int(level));
  double v = u[std::size_t(axis)][0];
  for (int b = 0; b < Dim; ++b) v += u[std::size_t(axis)][std::size_t(1 + b)] * (cell[b] + (b == axis ? 0.0 : 0.5)) * h;
  return v;
}

/// P_l u_{l+1} - u_l on this rank's rows of level l, and max |u_l| over all ranks' rows (`scale`).
template <int Dim>
std::vector<double> interpolationErrors(solver::petsc::FaceLevels<Dim>& levels,
                                        const std::vector<solver::petsc::FaceSample>& fine, std::size_t l,
                                        const Affine& u, double& scale) {
  std::vector<double> coarse;  // level l + 1's faces by number: axis, cell
  for (const auto& f : levels.coarseRows(l))
    coarse.insert(coarse.end(), {double(f.axis), double(f.cell[0]), double(f.cell[1]), double(f.cell[2])});
  const std::vector<double> all = mpi::allGather(coarse.data(), coarse.size());
  const std::vector<solver::petsc::FaceSample>& rows = l == 0 ? fine : levels.coarseRows(l - 1);
  const solver::petsc::Interpolation& p = levels.transfers()[l];
  std::vector<double> errors;
  scale = 0.0;
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const double cell[3] = {double(rows[i].cell[0]), double(rows[i].cell[1]), double(rows[i].cell[2])};
    const double exact = faceValue<Dim>(u, rows[i].axis, cell, l);
    double interpolated = 0.0;
    for (std::int64_t k = p.rowStart[i]; k < p.rowStart[i + 1]; ++k) {
      const double* c = all.data() + 4 * p.columns[std::size_t(k)];
      interpolated += p.values[std::size_t(k)] * faceValue<Dim>(u, int(c[0]), c + 1, l + 1);
    }
    errors.push_back(interpolated - exact);
    scale = std::max(scale, std::abs(exact));
  }
  scale = mpi::maxOverRanks(scale);
  return errors;
}

template <int Dim>
void expectLinearFieldsReproduced(sparse_grid::CellAxes finest, sparse_grid::CellAxes coarser) {
  const std::vector<solver::petsc::FaceSample> all = ballFaces<Dim>(Dim == 3 ? 13 : 40);
  std::vector<solver::petsc::FaceSample> mine;  // split by blocks of 8 cells along x, as above
  for (const auto& f : all)
    if (((f.cell[0] >> 3) % mpi::ranks() + mpi::ranks()) % mpi::ranks() == mpi::rank()) mine.push_back(f);
  solver::petsc::FaceLevels<Dim> levels(mine, finest, coarser, 40, 12);
  ASSERT_GE(levels.transfers().size(), 2u);
  Affine alongNormal{}, affine{}, acrossNormal{};
  const double alpha[3] = {0.3, -1.1, 0.7}, beta[3][3] = {{0.37, -0.61, 0.23}, {0.19, -0.53, 0.41}, {-0.29, 0.13, 0.47}};
  for (int a = 0; a < Dim; ++a) {
    alongNormal[a][0] = affine[a][0] = alpha[a];
    alongNormal[a][1 + a] = beta[a][a];
    for (int b = 0; b < Dim; ++b) affine[a][1 + b] = beta[a][b];
    acrossNormal[a][1 + (a + 1) % Dim] = 1.0;
  }
  auto worstOf = [](const std::vector<double>& e) {
    double m = 0.0;
    for (double v : e) m = std::max(m, std::abs(v));
    return mpi::maxOverRanks(m);
  };
  for (std::size_t l = 0; l < levels.transfers().size(); ++l) {
    const bool linearAcross = (l == 0 ? finest : coarser) == sparse_grid::CellAxes::Linear;
    double scale = 0.0;
    const double along = worstOf(interpolationErrors(levels, mine, l, alongNormal, scale));
    EXPECT_LE(along, 1e-14 * scale) << "P_" << l << " on u_a = alpha_a + beta_a x_a";
    const double general = worstOf(interpolationErrors(levels, mine, l, affine, scale));
    if (linearAcross) {
      EXPECT_LE(general, 1e-14 * scale) << "P_" << l << " (linear across) on an affine field";
    } else {
      const std::vector<double> e = interpolationErrors(levels, mine, l, acrossNormal, scale);
      double smallest = std::numeric_limits<double>::infinity();
      for (double v : e) smallest = std::min(smallest, std::abs(v));
      const double halfCell = std::ldexp(0.5, int(l));
      EXPECT_EQ(worstOf(e), halfCell) << "P_" << l << " (constant across) on u_a = x_(a+1)";
      EXPECT_EQ(-mpi::maxOverRanks(-smallest), halfCell) << "P_" << l << " (constant across) on u_a = x_(a+1)";
    }
    if (mpi::rank() == 0)
      std::printf("[ petsc ] %dD P_%zu (%s across) on %d rank(s): max error %.1e (along the normal), %.1e (affine), "
                  "largest value %.1f\n",
                  Dim, l, linearAcross ? "linear" : "constant", mpi::ranks(), along, general, scale);
  }
}

TEST(PetscBackend, VelocityMultigridInterpolationReproducesLinearFields) {
  using sparse_grid::CellAxes;
  expectLinearFieldsReproduced<3>(CellAxes::Constant, CellAxes::Linear);  // the default where viscosity dominates
  expectLinearFieldsReproduced<3>(CellAxes::Linear, CellAxes::Linear);
  expectLinearFieldsReproduced<3>(CellAxes::Constant, CellAxes::Constant);
  expectLinearFieldsReproduced<2>(CellAxes::Linear, CellAxes::Linear);
}

// What the backend does not solve is refused with a clear error, not a wrong answer: the
// pressure-velocity form with reduced tiles (their coupling is not split over ranks in that form),
// and the decoupled viscosity solve.
TEST(PetscBackend, OtherSystemsAreRefused) {
  analytic::AnalyticOptions o = caseOptions(64, 0.1);
  o.backend = solver::Backend::Petsc;
  o.form = solver::StokesForm::PressureVelocity;
  o.method = solver::KrylovMethod::MINRES;
  o.model = "quadratic";
  o.tileSize = 8;
  o.tileRule = solver::TileRule::All;
  try {
    analytic::runDiskStokes(o);
    FAIL() << "the pressure-velocity form with tiles ran on PETSc";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("without reduced tiles"), std::string::npos) << e.what();
  }
  o = caseOptions(16, 0.1);
  o.backend = solver::Backend::Petsc;
  o.system = solver::SystemKind::DecoupledStokes;
  try {
    analytic::runDiskStokes(o);
    FAIL() << "the decoupled step ran on PETSc";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("runs in-house only"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace stokes

// PETSc (and MPI) live for the whole test program.
int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  stokes::solver::petsc::Session session;
  stokes::solver::petsc::Session::initialise({});
  // only rank 0 reports; every rank runs every test (the solves are collective)
  if (stokes::solver::petsc::rank() != 0) {
    ::testing::TestEventListeners& listeners = ::testing::UnitTest::GetInstance()->listeners();
    delete listeners.Release(listeners.default_result_printer());
  }
  int failed = RUN_ALL_TESTS();
  // a failure on any rank fails the program on rank 0
  int anyFailed = 0;
  MPI_Allreduce(&failed, &anyFailed, 1, MPI_INT, MPI_MAX, MPI_COMM_WORLD);
  return anyFailed;
}
