// Warm start of the solves (solver/step/stokes_step.h `guess`, sim/step/warm_start.h): a solve that
// starts from its own solution has nothing left to do (0 iterations, the same velocities bit for
// bit); one that starts from a neighbouring problem's solution meets the same tolerance as a cold
// start; the previous step's unknowns move to a new layout by cell, exactly; and the guesses the
// solver cannot use are refused with a message.
#include <gtest/gtest.h>

#include <cstring>
#include <stdexcept>
#include <string>
#include <vector>

#include "mixed_problem.h"
#include "sim/step/warm_start.h"
#include "solver/step/stokes_step.h"

namespace stokes {
namespace {

using solver::RowStorage;
using solver::StepOptions;
using solver::SystemKind;
using solver::Vector;

double maxAbsDifference(const Vector& a, const Vector& b) {
  double d = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) d = std::max(d, std::abs(a[i] - b[i]));
  return d;
}

double maxAbs(const Vector& a) {
  double m = 0.0;
  for (double v : a) m = std::max(m, std::abs(v));
  return m;
}

// x0 = x* makes r0 = b - A x* meet the stopping rule at once: 0 iterations, and the velocities
// are the same function of the same x, bit for bit. The pressure-stress form and the projection
// on live and padded rows; the pressure-velocity form ([u | p | l], solutionChannels, with the
// multipliers of the solids' rigid samples) under Jacobi MINRES and multigrid GMRES.
TEST(WarmStart, SolveFromItsOwnSolutionTakesNoIterations) {
  test::MixedBoundaryProblem<3> m(16);
  std::vector<StepOptions> cases;
  for (SystemKind system : {SystemKind::UnifiedStokes, SystemKind::PressureProjection})
    for (RowStorage rows : {RowStorage::Compact, RowStorage::Padded}) {
      StepOptions opt;
      opt.system = system;
      opt.rows = rows;
      cases.push_back(opt);
    }
  for (solver::PreconditionerKind pre : {solver::PreconditionerKind::Jacobi, solver::PreconditionerKind::Multigrid}) {
    StepOptions opt;
    opt.form = solver::StokesForm::PressureVelocity;
    opt.preconditioner = pre;
    cases.push_back(opt);
  }
  for (StepOptions& opt : cases) {
    opt.krylov.relativeTolerance = 1e-10;
    const std::string name = std::string(solver::toString(opt.system)) + ", " + solver::toString(opt.form) + ", " +
                             solver::toString(opt.preconditioner);
    Vector cold, x, warm;
    const auto first = solver::solveStep(m.prob, opt, cold, &x);
    ASSERT_TRUE(first.solve.converged()) << name;
    ASSERT_GT(first.solve.iterations, 10) << name;
    ASSERT_EQ(x.size(), solver::solutionChannels<3>(opt.system, opt.form) * m.prob.slots()) << name;
    const auto again = solver::solveStep(m.prob, opt, warm, nullptr, &x);
    ASSERT_TRUE(again.solve.converged()) << name;
    EXPECT_EQ(again.solve.iterations, 0) << name;
    ASSERT_EQ(cold.size(), warm.size());
    EXPECT_EQ(0, std::memcmp(cold.data(), warm.data(), cold.size() * sizeof(double))) << name;
  }
}

// Started from a neighbouring problem's solution (u* changed by 5%), the solve meets the same
// tolerance as from zero: the velocities agree to the tolerance's level. The pressure-stress form
// under CG and the pressure-velocity form ([u | p | l]) under the multigrid GMRES.
TEST(WarmStart, NeighbouringSolutionReachesTheColdAnswer) {
  for (solver::StokesForm form : {solver::StokesForm::PressureStress, solver::StokesForm::PressureVelocity}) {
    test::MixedBoundaryProblem<3> m(16);
    StepOptions opt;
    opt.form = form;
    if (form == solver::StokesForm::PressureVelocity) opt.preconditioner = solver::PreconditionerKind::Multigrid;
    opt.krylov.relativeTolerance = 1e-12;
    Vector u0, x0;
    ASSERT_TRUE(solver::solveStep(m.prob, opt, u0, &x0).solve.converged());
    for (std::size_t i = 0; i < m.prob.uStar.size(); ++i) m.prob.uStar[i] *= 1.0 + 0.05 * std::sin(double(i));
    Vector cold, warm;
    const auto c = solver::solveStep(m.prob, opt, cold);
    const auto w = solver::solveStep(m.prob, opt, warm, nullptr, &x0);
    ASSERT_TRUE(c.solve.converged());
    ASSERT_TRUE(w.solve.converged());
    EXPECT_LE(maxAbsDifference(cold, warm), 1e-8 * maxAbs(cold)) << solver::toString(form);
  }
}

// With reduced tiles the guess' u on a tile's faces is the tile's polynomial, whose fit gives the
// DOFs back to round-off: still no iterations, and the velocities to round-off.
TEST(WarmStart, PressureVelocityWithTilesRecoversTheirDofsFromTheFaces) {
  test::MixedBoundaryProblem<3> m(28);
  StepOptions opt;
  opt.form = solver::StokesForm::PressureVelocity;
  opt.preconditioner = solver::PreconditionerKind::Multigrid;
  opt.krylov.relativeTolerance = 1e-10;
  solver::ReducedOptions r;
  r.order = solver::PolynomialOrder::Quadratic;
  r.family = solver::BasisFamily::DivergenceFree;
  r.tiling.tileSize = 8;
  r.tiling.padding = 2;
  opt.reduced = r;
  Vector cold, x, warm;
  const auto first = solver::solveStep(m.prob, opt, cold, &x);
  ASSERT_TRUE(first.solve.converged());
  ASSERT_GT(first.tiles, 0u);
  const auto again = solver::solveStep(m.prob, opt, warm, nullptr, &x);
  ASSERT_TRUE(again.solve.converged());
  EXPECT_EQ(again.solve.iterations, 0);
  EXPECT_LE(maxAbsDifference(cold, warm), 1e-12 * maxAbs(cold));
}

TEST(WarmStart, RefusesAGuessOfTheWrongSize) {
  test::MixedBoundaryProblem<2> m(24);
  StepOptions opt;
  Vector u;
  const Vector tooShort(5, 0.0);
  EXPECT_THROW(solver::solveStep(m.prob, opt, u, nullptr, &tooShort), std::invalid_argument);
  opt.form = solver::StokesForm::PressureVelocity;
  const Vector pressureStress(solver::solutionChannels<2>(opt.system, solver::StokesForm::PressureStress) * m.prob.slots(), 0.0);
  try {
    solver::solveStep(m.prob, opt, u, nullptr, &pressureStress);
    FAIL() << "the pressure-velocity form took the pressure-stress form's guess";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("[u | p | l]"), std::string::npos) << e.what();
  }
}

// Two layouts over overlapping boxes (blocks in a different order): every cell of the new layout
// that the old one held gets its value in every channel, the others 0.
TEST(WarmStart, MovesValuesByCellBetweenLayouts) {
  using Layout = sparse_grid::BlockLayout<3>;
  auto layoutOver = [](openvdb::Coord lo, openvdb::Coord hi) {
    openvdb::MaskTree mask;
    sparse_grid::activateBox(mask, lo, hi);
    return std::make_unique<Layout>(mask, 0.1);
  };
  auto value = [](const openvdb::Coord& c, std::size_t channel) {
    return 1.0 + c.x() + 100.0 * c.y() + 10000.0 * c.z() + 1e6 * double(channel);
  };
  constexpr std::size_t kChannels = 3;
  auto before = layoutOver(openvdb::Coord(0), openvdb::Coord(20, 11, 9));
  const auto after = layoutOver(openvdb::Coord(-8, 4, 0), openvdb::Coord(15, 30, 9));
  const std::size_t n0 = before->numSlots(), n1 = after->numSlots();
  Vector x(kChannels * n0);
  for (std::size_t c = 0; c < kChannels; ++c)
    for (std::size_t s = 0; s < n0; ++s) x[c * n0 + s] = value(before->cellOf(s), c);
  const Layout* old = before.get();
  std::vector<std::int64_t> oldSlot(n1);
  for (std::size_t s = 0; s < n1; ++s) oldSlot[s] = old->slotOf(after->cellOf(s));
  sim::WarmStart<3> warm;
  EXPECT_TRUE(warm.guessFor(*after, kChannels).empty());  // nothing kept yet
  warm.keep(std::move(before), std::move(x));
  EXPECT_TRUE(warm.guessFor(*after, 1).empty());  // another kind of solve
  const Vector guess = warm.guessFor(*after, kChannels);
  ASSERT_EQ(guess.size(), kChannels * n1);
  std::size_t carried = 0;
  for (std::size_t c = 0; c < kChannels; ++c)
    for (std::size_t s = 0; s < n1; ++s) {
      const double expected = oldSlot[s] >= 0 ? value(after->cellOf(s), c) : 0.0;
      ASSERT_EQ(guess[c * n1 + s], expected) << "channel " << c << " slot " << s;
      carried += oldSlot[s] >= 0 ? 1 : 0;
    }
  EXPECT_GT(carried, 0u);
  EXPECT_LT(carried, kChannels * n1);
}

}  // namespace
}  // namespace stokes
