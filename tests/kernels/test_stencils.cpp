// The separately written stencils are adjoint, with the weights the systems use:
//   <G (wp p), f> = <p, wp G^T f> = -<p, wp div f>     and     <D^T (wt tau), f> = <tau, wt D f>.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "kernels/staggered_stencils.h"
#include "sparse_grid/block_order.h"
#include "sparse_grid/volume_weights.h"
#include "tests/test_helpers.h"

namespace stokes {
namespace {

using sparse_grid::StressChannels;

template <class T>
class StencilTest : public ::testing::Test {};
using Dims = ::testing::Types<std::integral_constant<int, 2>, std::integral_constant<int, 3>>;
TYPED_TEST_SUITE(StencilTest, Dims);

/// Which cell-sample family K = [G Wp, D^T Wt] is tested on: pressure (1 channel) or stress.
enum class Family { Pressure, Stress };

/// <K (w x), f> = <x, w K^T f> for random cell values x, weights w in [0, 1] and face values f on
/// an irregular layout of cell size dx: the fused kernels facesFromCells and
/// cellsFromFaces are adjoint for the family's weights.
template <int Dim>
void expectKernelsAdjoint(Family family, double dx, unsigned seed) {
  const auto layout = test::irregularLayout<Dim>(Dim == 2 ? 40 : 20, dx);
  std::mt19937_64 rng(seed);
  const std::size_t n = layout.numSlots();
  const int channels = family == Family::Pressure ? 1 : sparse_grid::StressChannels<Dim>::kCount;
  const solver::Vector x = test::randomChannels<Dim>(layout, channels, rng);
  const solver::Vector w = test::randomChannels<Dim>(layout, channels, rng, 0.0, 1.0);
  const solver::Vector f = test::randomChannels<Dim>(layout, Dim, rng);
  solver::Vector Kx(Dim * n), KTf(channels * n);
  kernels::CellStressInput in;
  kernels::CellStressOutput out;
  if (family == Family::Pressure) {
    in.p = x.data(), in.pWeight = w.data();
    out.p = KTf.data(), out.pWeight = w.data();
  } else {
    in.tau = x.data(), in.tauWeight = w.data();
    out.tau = KTf.data(), out.tauWeight = w.data();
  }
  kernels::facesFromCells<Dim>(layout, in, nullptr, Kx.data());
  kernels::cellsFromFaces<Dim>(layout, f.data(), out);
  const double lhs = test::dotProduct(Kx, f), rhs = test::dotProduct(x, KTf);
  EXPECT_NEAR(lhs, rhs, 1e-12 * std::abs(lhs));
  EXPECT_GT(std::abs(lhs), 1.0);
}

// <G (wp p), f> = <p, wp G^T f>.
TYPED_TEST(StencilTest, GradientIsMinusDivergenceAdjoint) {
  expectKernelsAdjoint<TypeParam::value>(Family::Pressure, 0.37, 11);
}

// <D^T (wt tau), u> = <tau, wt D u>.
TYPED_TEST(StencilTest, StrainIsMinusStressDivergenceAdjoint) {
  expectKernelsAdjoint<TypeParam::value>(Family::Stress, 0.21, 12);
}

// A linear velocity field u_a = sum_b A_ab x_b has exact discrete strain rates and divergence.
TYPED_TEST(StencilTest, LinearFieldGivesExactStrainAndDivergence) {
  constexpr int Dim = TypeParam::value;
  using SC = StressChannels<Dim>;
  openvdb::MaskTree mask;
  sparse_grid::activateBox(mask, openvdb::Coord(0), Dim == 3 ? openvdb::Coord(15) : openvdb::Coord(15, 15, 0));
  const sparse_grid::BlockLayout<Dim> layout(mask, 0.1);
  const std::size_t n = layout.numSlots();
  const double A[3][3] = {{0.3, -1.2, 0.7}, {2.0, 0.5, -0.4}, {0.9, 1.1, -0.8}};
  solver::Vector u(Dim * n), strain(SC::kCount * n), div(n);
  for (std::size_t s = 0; s < n; ++s)
    for (int a = 0; a < Dim; ++a) {
      const auto x = layout.samplePosition(s, sparse_grid::faceMask(a));
      double v = 0.0;
      for (int b = 0; b < Dim; ++b) v += A[a][b] * x[b];
      u[a * n + s] = v;
    }
  kernels::CellStressOutput out;
  out.p = div.data();
  out.tau = strain.data();
  kernels::cellsFromFaces<Dim>(layout, u.data(), out);
  double trace = 0.0;
  for (int a = 0; a < Dim; ++a) trace += A[a][a];
  // Interior cells only (index 1..14): the outermost ring reads missing neighbours as zero.
  for (std::size_t s = 0; s < n; ++s) {
    const auto c = layout.cellOf(s);
    bool interior = true;
    for (int a = 0; a < Dim; ++a) interior = interior && c[a] >= 1 && c[a] <= 14;
    if (!interior) continue;
    EXPECT_NEAR(-div[s], trace, 1e-10);  // G^T u = -div u
    for (int ch = 0; ch < SC::kCount; ++ch) {
      double want;
      if (SC::isDiagonal(ch)) want = A[ch][ch];
      else {
        const auto pr = SC::pairs()[ch - SC::kDiagonal];
        want = A[pr.first][pr.second] + A[pr.second][pr.first];  // gamma_ab
      }
      EXPECT_NEAR(strain[ch * n + s], want, 1e-10);
    }
  }
}

// For a true signed distance the shortcut (0 or 1 beyond half a cell diagonal) changes nothing:
// both functions give the same fraction on every sample kind, and the sphere's cut samples are
// fractional.
TYPED_TEST(StencilTest, DistanceShortcutGivesTheSubsampledFractions) {
  constexpr int Dim = TypeParam::value;
  const auto layout = test::irregularLayout<Dim>(Dim == 2 ? 40 : 20, 0.05);
  const sparse_grid::Vec3d c(0.52, 0.47, Dim == 3 ? 0.5 : 0.0);
  auto sphere = [&](const sparse_grid::Vec3d& x) {
    sparse_grid::Vec3d d = x - c;
    if (Dim == 2) d[2] = 0.0;
    return d.length() - 0.31;
  };
  const std::size_t n = layout.numSlots();
  int fractional = 0;
  for (int a = 0; a <= Dim; ++a) {
    const sparse_grid::StaggerMask mask = a < Dim ? sparse_grid::faceMask(a) : sparse_grid::kCellCentre;
    solver::Vector full(n), fast(n);
    sparse_grid::computeVolumeFractions<Dim>(layout, mask, sphere, full.data());
    sparse_grid::computeVolumeFractionsOfDistance<Dim>(layout, mask, sphere, fast.data());
    for (std::size_t s = 0; s < n; ++s) {
      ASSERT_EQ(full[s], fast[s]) << "slot " << s;
      fractional += full[s] > 0.0 && full[s] < 1.0 ? 1 : 0;
    }
  }
  EXPECT_GT(fractional, 20);
}

// The plane-cut fractions (the liquid and solid weights): for a plane normal to an axis, the exact
// share of the control volume below it; for a plane of any normal, a region and its complement
// add to 1 on every sample kind.
TYPED_TEST(StencilTest, PlaneCutFractionsAreExactForAxisPlanesAndComplementary) {
  constexpr int Dim = TypeParam::value;
  const auto layout = test::irregularLayout<Dim>(Dim == 2 ? 24 : 12, 1.0);
  const double dx = layout.dx();
  const std::size_t n = layout.numSlots();
  sparse_grid::Vec3d normal(0.37, -0.81, Dim == 3 ? 0.45 : 0.0);
  normal.normalize();
  for (int a = 0; a <= Dim; ++a) {
    const sparse_grid::StaggerMask mask = a < Dim ? sparse_grid::faceMask(a) : sparse_grid::kCellCentre;
    solver::Vector level(n), below(n), above(n);
    const double height = 0.4637;  // a plane y = height, off the grid lines
    sparse_grid::computePlaneCutFractions<Dim>(layout, mask, [&](const sparse_grid::Vec3d& x) { return x[1] - height; },
                                               level.data());
    const sparse_grid::Vec3d origin(0.43, 0.51, 0.47);
    auto tilted = [&](const sparse_grid::Vec3d& x) { return normal.dot(x - origin); };
    sparse_grid::computePlaneCutFractions<Dim>(layout, mask, tilted, below.data());
    sparse_grid::computePlaneCutFractions<Dim>(layout, mask, [&](const sparse_grid::Vec3d& x) { return -tilted(x); },
                                               above.data());
    for (std::size_t s = 0; s < n; ++s) {
      const sparse_grid::Vec3d c = layout.samplePosition(s, mask);
      ASSERT_NEAR(level[s], std::clamp((height - (c[1] - 0.5 * dx)) / dx, 0.0, 1.0), 1e-12) << "slot " << s;
      ASSERT_NEAR(below[s] + above[s], 1.0, 1e-12) << "slot " << s;
    }
  }
}

// A plane that only touches a control volume gives it exactly 0 (or 1), even where round-off in
// the coordinates (dx = 1/12) leaves 1/2 - d at +-1e-15: the corner cell outside a box whose
// walls lie on grid lines holds no fluid (sparse_grid::CutRoundOff::Snap, the walls' and solids').
TEST(PlaneCutFractions, ATouchingPlaneGivesExactlyZero) {
  const int n = 12;
  const double dx = 1.0 / n, width = 4.0;
  openvdb::MaskTree mask;
  sparse_grid::activateBox(mask, openvdb::Coord(-1, -1, 0), openvdb::Coord(4 * n, 4, 0));
  const sparse_grid::BlockLayout<2> layout(mask, dx);
  auto outsideBox = [&](const sparse_grid::Vec3d& x) { return -std::min({x[1], x[0], width - x[0]}); };
  solver::Vector f(layout.numSlots());
  sparse_grid::computePlaneCutFractions<2>(layout, sparse_grid::kCellCentre, outsideBox, f.data());
  for (const openvdb::Coord corner : {openvdb::Coord(-1, -1, 0), openvdb::Coord(4 * n, -1, 0)})
    EXPECT_EQ(f[std::size_t(layout.slotOf(corner))], 0.0) << corner;
  EXPECT_EQ(f[std::size_t(layout.slotOf(openvdb::Coord(4 * n - 1, 0, 0)))], 1.0);
}

TYPED_TEST(StencilTest, NeighbourSlotsMatchCoordinates) {
  constexpr int Dim = TypeParam::value;
  const auto layout = test::irregularLayout<Dim>(Dim == 2 ? 30 : 14, 1.0);
  for (std::size_t s = 0; s < layout.numSlots(); ++s) {
    const auto c = layout.cellOf(s);
    ASSERT_EQ(layout.slotOf(c), std::int64_t(s));
    for (int a = 0; a < Dim; ++a)
      for (int dir : {-1, 1}) {
        auto d = c;
        d[a] += dir;
        ASSERT_EQ(layout.neighbourSlot(s, a, dir), layout.slotOf(d));
      }
  }
}

}  // namespace
}  // namespace stokes

namespace stokes {
namespace {

// Recursive coordinate bisection of a layout's blocks (sparse_grid/block_order.h): the order is a
// permutation, and on a box of 2 x 4 x 4 equally weighted blocks every 2^k equal run of it is a
// box of blocks whose longest edge is at most twice its shortest (the layout's own order cuts
// lines of 1 x 1 x 4 blocks there).
TEST(BlockOrder, BisectionRunsAreCompactBoxesOfBlocks) {
  openvdb::MaskTree mask;
  sparse_grid::activateBox(mask, openvdb::Coord(0), openvdb::Coord(15, 31, 31));
  const sparse_grid::BlockLayout<3> layout(mask, 1.0);
  ASSERT_EQ(layout.numBlocks(), 32u);
  const std::vector<std::size_t> order = sparse_grid::bisectionBlockOrder(layout, std::vector<std::size_t>(32, 1));
  std::vector<std::size_t> sorted = order;
  std::sort(sorted.begin(), sorted.end());
  for (std::size_t i = 0; i < sorted.size(); ++i) EXPECT_EQ(sorted[i], i);
  for (std::size_t run = 1; run <= 32; run *= 2)
    for (std::size_t start = 0; start < 32; start += run) {
      openvdb::Coord lo = layout.blockOrigin(order[start]), hi = lo;
      for (std::size_t i = start; i < start + run; ++i) {
        lo = openvdb::Coord::minComponent(lo, layout.blockOrigin(order[i]));
        hi = openvdb::Coord::maxComponent(hi, layout.blockOrigin(order[i]));
      }
      std::size_t volume = 1, shortest = 64, longest = 0;
      for (int a = 0; a < 3; ++a) {
        const std::size_t edge = std::size_t((hi[a] - lo[a]) / 8 + 1);
        volume *= edge;
        shortest = std::min(shortest, edge);
        longest = std::max(longest, edge);
      }
      EXPECT_EQ(volume, run) << "run of " << run << " from " << start;
      EXPECT_LE(longest, 2 * shortest) << "run of " << run << " from " << start;
    }
}

}  // namespace
}  // namespace stokes
