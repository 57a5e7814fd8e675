// Reduced polynomial tiles (thesis 3.7, 4.1-4.5): tiling rules, the coupled operators' structure,
// the defining properties of the affine and quadratic models, and agreement of the two forms.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <map>
#include <numbers>

#include "analytic/analytic_cases.h"
#include "kernels/staggered_stencils.h"
#include "solver/step/stokes_step.h"
#include "solver/systems/pressure_stress_system.h"
#include "solver/systems/pressure_velocity_system.h"
#include "solver/systems/viscosity_system.h"
#include "tests/test_helpers.h"

namespace stokes {
namespace {

using sparse_grid::StressChannels;
using sparse_grid::Vec3d;
using solver::StaggeredProblem;
using solver::Vector;

/// A fully liquid box of n^Dim cells (plus one ghost layer of air) with a random smooth u*.
template <int Dim>
struct LiquidBox {
  sparse_grid::BlockLayout<Dim> layout;
  StaggeredProblem<Dim> prob;
  LiquidBox(int n, double mu = 0.3) {
    openvdb::MaskTree mask;
    sparse_grid::activateBox(mask, openvdb::Coord(-1), Dim == 3 ? openvdb::Coord(n) : openvdb::Coord(n, n, 0));
    layout = sparse_grid::BlockLayout<Dim>(mask, 1.0 / n);
    prob.layout = &layout;
    prob.mu = mu;
    prob.rho = 1.5;
    prob.dt = 0.1;
    prob.allocate(false);
    const std::size_t ns = layout.numSlots();
    auto inside = [&](const Vec3d& x) {
      for (int a = 0; a < Dim; ++a)
        if (x[a] < 0.0 || x[a] > 1.0) return false;
      return true;
    };
    for (std::size_t s = 0; s < ns; ++s) {
      prob.liquidCell[s] = inside(layout.samplePosition(s, sparse_grid::kCellCentre)) ? 1.0 : 0.0;
      for (int a = 0; a < Dim; ++a) {
        const Vec3d x = layout.samplePosition(s, sparse_grid::faceMask(a));
        prob.liquidFace[a * ns + s] = inside(x) ? 1.0 : 0.0;
        prob.uStar[a * ns + s] = std::sin(3.0 * x[(a + 1) % Dim] + a) * std::cos(2.0 * x[a]);
      }
      for (int c = 0; c < StressChannels<Dim>::kCount; ++c)
        prob.liquidStress[c * ns + s] = inside(layout.samplePosition(s, StressChannels<Dim>::mask(c))) ? 1.0 : 0.0;
    }
  }
};

solver::ReducedOptions options(solver::PolynomialOrder order, solver::BasisFamily family, int tile, int pad) {
  solver::ReducedOptions r;
  r.order = order;
  r.family = family;
  r.tiling.tileSize = tile;
  r.tiling.padding = pad;
  return r;
}

template <class T>
class ReducedTest : public ::testing::Test {};
using Dims = ::testing::Types<std::integral_constant<int, 2>, std::integral_constant<int, 3>>;
TYPED_TEST_SUITE(ReducedTest, Dims);

TYPED_TEST(ReducedTest, CoupledOperatorsAreSymmetric) {
  constexpr int Dim = TypeParam::value;
  LiquidBox<Dim> box(Dim == 2 ? 40 : 24);
  for (auto order : {solver::PolynomialOrder::Affine, solver::PolynomialOrder::Quadratic}) {
    const auto ro = options(order, solver::BasisFamily::DivergenceFree, 8, 2);
    const solver::ReducedTiles<Dim> stokesTiles(box.prob, ro, solver::couplingKinds(solver::SystemKind::UnifiedStokes));
    ASSERT_GT(stokesTiles.numTiles(), 0u);
    const solver::PressureStressSystem<Dim> spd(box.prob, true, &stokesTiles);
    test::expectSymmetricPositive(spd, 21);
    const solver::PressureVelocitySystem<Dim> pv(box.prob, &stokesTiles);
    test::expectSymmetricPositive(pv, 22, /*positive=*/false, /*exactDiagonal=*/false);
    auto rv = options(order, solver::BasisFamily::Full, 8, 2);
    rv.fitAllFaces = true;
    const solver::ReducedTiles<Dim> viscTiles(box.prob, rv, solver::couplingKinds(solver::SystemKind::Viscosity));
    const solver::ViscositySystem<Dim> visc(box.prob, &viscTiles);
    test::expectSymmetricPositive(visc, 23);
  }
}

// Thesis 4.1: for an affine field D J^T v is constant, so the viscous force D^T Q D J^T v vanishes
// on faces strictly inside a tile -- no interior viscous dynamics. A quadratic field has them.
TYPED_TEST(ReducedTest, AffineTilesHaveNoInteriorViscousForce) {
  constexpr int Dim = TypeParam::value;
  LiquidBox<Dim> box(Dim == 2 ? 32 : 16);
  const std::size_t n = box.layout.numSlots();
  for (auto order : {solver::PolynomialOrder::Affine, solver::PolynomialOrder::Quadratic}) {
    auto ro = options(order, solver::BasisFamily::Full, 16, 2);
    ro.fitAllFaces = true;  // the full quadratic fit on boundary faces alone is singular (docs/design.md §4)
    const solver::ReducedTiles<Dim> tiles(box.prob, ro, solver::couplingKinds(solver::SystemKind::Viscosity));
    ASSERT_GT(tiles.numTiles(), 0u);
    std::mt19937_64 rng(5);
    std::uniform_real_distribution<double> ud(-1.0, 1.0);
    Vector v(tiles.totalDofs()), u(Dim * n, 0.0), tau(StressChannels<Dim>::kCount * n), f(Dim * n);
    for (auto& x : v) x = ud(rng);
    tiles.scatter(v.data(), u.data(), /*couplingOnly=*/false);
    kernels::CellStressOutput out;
    out.tau = tau.data();
    kernels::cellsFromFaces<Dim>(box.layout, u.data(), out);
    kernels::CellStressInput in;
    in.tau = tau.data();
    kernels::facesFromCells<Dim>(box.layout, in, nullptr, f.data());
    double maxInterior = 0.0, scale = 0.0;
    int interiorFaces = 0;
    for (std::size_t i = 0; i < Dim * n; ++i) {
      if (tiles.tileOfFace(i) < 0) continue;
      bool strictlyInside = true;  // every stress sample touching the face is inside the tile
      kernels::forEachSampleOfFace<Dim>(
          box.layout, int(i / n), i % n, [](std::size_t, double) {},
          [&](int c, std::size_t s, double) { strictlyInside = strictlyInside && tiles.isInsideStress(c, s); });
      if (!strictlyInside) continue;
      ++interiorFaces;
      maxInterior = std::max(maxInterior, std::abs(f[i]));
      scale = std::max(scale, std::abs(u[i]) / (box.layout.dx() * box.layout.dx()));
    }
    ASSERT_GT(interiorFaces, 10);
    if (order == solver::PolynomialOrder::Affine) EXPECT_LT(maxInterior, 1e-9 * scale);
    else EXPECT_GT(maxInterior, 1e-3 * scale);
  }
}

// A tile whose u* is exactly a divergence-free quadratic field is fitted exactly by the quadratic
// divergence-free basis (and not by the affine one).
TYPED_TEST(ReducedTest, QuadraticFieldIsFittedExactly) {
  constexpr int Dim = TypeParam::value;
  LiquidBox<Dim> box(Dim == 2 ? 32 : 16);
  const std::size_t n = box.layout.numSlots();
  // u = curl of a cubic potential: 2D psi = x^2 y - y^3/3 + x y^2 -> u = (psi_y, -psi_x);
  // 3D A = (y^2 z, x z^2, x^2 y) -> u = curl A.
  for (std::size_t s = 0; s < n; ++s)
    for (int a = 0; a < Dim; ++a) {
      const Vec3d p = box.layout.samplePosition(s, sparse_grid::faceMask(a));
      const double x = p[0], y = p[1], z = p[2];
      double v;
      if (Dim == 2) v = a == 0 ? (x * x - y * y + 2 * x * y) : -(2 * x * y + y * y);
      else v = a == 0 ? (x * x - 2 * x * z) : a == 1 ? (y * y - 2 * x * y) : (z * z - 2 * y * z);
      box.prob.uStar[a * n + s] = v;
    }
  const auto kinds = solver::couplingKinds(solver::SystemKind::UnifiedStokes);
  const solver::ReducedTiles<Dim> quad(box.prob, options(solver::PolynomialOrder::Quadratic, solver::BasisFamily::DivergenceFree, 16, 3), kinds);
  const solver::ReducedTiles<Dim> aff(box.prob, options(solver::PolynomialOrder::Affine, solver::BasisFamily::DivergenceFree, 16, 3), kinds);
  ASSERT_GT(quad.numTiles(), 0u);
  EXPECT_LT(quad.reconstructionLinf(), 1e-11);
  EXPECT_GT(aff.reconstructionLinf(), 1e-4);
}

// Reduced pressure projection (thesis Eq. 3.73): pressure only on Cartesian cells, B = M_R/dt.
// The projection lowers the kinetic energy, leaves the Cartesian divergence at solver tolerance,
// and its operator is symmetric positive.
TYPED_TEST(ReducedTest, PressureProjectionWithTiles) {
  constexpr int Dim = TypeParam::value;
  LiquidBox<Dim> box(Dim == 2 ? 48 : 20);
  solver::StepOptions opt;
  opt.system = solver::SystemKind::PressureProjection;
  opt.reduced = options(solver::PolynomialOrder::Quadratic, solver::BasisFamily::DivergenceFree, 10, 1);
  opt.reduced->fitAllFaces = true;
  opt.krylov.relativeTolerance = 1e-11;
  const solver::ReducedTiles<Dim> tiles(box.prob, *opt.reduced, solver::couplingKinds(opt.system));
  ASSERT_GT(tiles.numTiles(), 0u);
  const solver::PressureStressSystem<Dim> sys(box.prob, false, &tiles);
  test::expectSymmetricPositive(sys, 31);
  Vector u;
  const auto rep = solver::solveStep(box.prob, opt, u);
  ASSERT_TRUE(rep.solve.converged());
  double before = 0.0;
  for (std::size_t i = 0; i < u.size(); ++i) before += 0.5 * box.prob.rho * box.prob.liquidFace[i] * box.prob.uStar[i] * box.prob.uStar[i];
  before *= std::pow(box.layout.dx(), Dim);
  EXPECT_LT(rep.kineticEnergy, before);
  // divergence of the new field on every liquid cell (tile cells are divergence-free by the basis)
  const std::size_t n = box.layout.numSlots();
  Vector div(n);
  kernels::CellStressOutput out;
  out.p = div.data();
  out.pWeight = box.prob.liquidCell.data();
  kernels::cellsFromFaces<Dim>(box.layout, u.data(), out);
  double maxDiv = 0.0;
  for (double d : div) maxDiv = std::max(maxDiv, std::abs(d));
  EXPECT_LT(maxDiv * box.layout.dx(), 1e-8);
}

// Tiling (thesis 4.5): slabs use OR, regions are flood-filled, irregular shapes survive, small
// regions are culled, padding 1 is refused with viscosity.
// The shape-only blocks of a tile (M^, K^, and through them B^-1) are a function of its shape
// alone, bit for bit: computed in cell (z, y, x) order from integer offsets to the tile's corner,
// not in slot order from world coordinates. Tiles of 6 on a grid whose dx is not a power of two
// sit at every offset to the 8^3 blocks; factored each on its own (no library), every cube tile
// must give the first one's bits. (Before, they differed by rounding, and the library kept the
// blocks of whichever tile of a shape finished first: a tiled solve depended on thread timing.)
TYPED_TEST(ReducedTest, TilesOfOneShapeHaveBitIdenticalBlocks) {
  constexpr int Dim = TypeParam::value;
  LiquidBox<Dim> box(Dim == 2 ? 60 : 30);
  solver::ReducedOptions r = options(solver::PolynomialOrder::Quadratic, solver::BasisFamily::DivergenceFree, 6, 2);
  r.cache = solver::TileCacheStrategy::None;
  const solver::ReducedTiles<Dim> tiles(box.prob, r, solver::couplingKinds(solver::SystemKind::UnifiedStokes));
  const auto same = [](const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
    return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(double)) == 0;
  };
  std::size_t compared = 0, first = tiles.numTiles();
  for (std::size_t t = 0; t < tiles.numTiles(); ++t) {
    if (!tiles.tiling().tiles[t].isFullBox || tiles.tiling().tiles[t].cells.size() != std::size_t(std::pow(4, Dim)))
      continue;
    if (first == tiles.numTiles()) {
      first = t;
      continue;
    }
    EXPECT_TRUE(same(tiles.tile(t).massR, tiles.tile(first).massR)) << "tile " << t;
    EXPECT_TRUE(same(tiles.tile(t).viscR, tiles.tile(first).viscR)) << "tile " << t;
    EXPECT_TRUE(same(tiles.tile(t).inverseB, tiles.tile(first).inverseB)) << "tile " << t;
    ++compared;
  }
  EXPECT_GE(compared, Dim == 2 ? 20u : 40u);
}

TEST(Tiling, SlabsRegionsAndCulling) {
  // an L-shaped, holed 2D region: 48 x 48 minus a 20 x 20 corner, with a hole
  openvdb::MaskTree mask;
  for (int j = -1; j <= 48; ++j)
    for (int i = -1; i <= 48; ++i) mask.setValueOn(openvdb::Coord(i, j, 0));
  const sparse_grid::BlockLayout<2> layout(mask, 1.0);
  std::vector<std::uint8_t> liquid(layout.numSlots(), 0), fluid(layout.numSlots(), 1);
  for (std::size_t s = 0; s < layout.numSlots(); ++s) {
    const auto c = layout.cellOf(s);
    const bool inBox = c.x() >= 0 && c.x() < 48 && c.y() >= 0 && c.y() < 48;
    const bool corner = c.x() >= 28 && c.y() >= 28;
    const bool hole = c.x() >= 8 && c.x() < 10 && c.y() >= 8 && c.y() < 10;
    liquid[s] = layout.isActiveCell(s) && inBox && !corner && !hole;
  }
  sparse_grid::TilingOptions opt;
  opt.tileSize = 24;
  opt.padding = 2;
  opt.bandAir = 1;
  const auto tiling = sparse_grid::buildTiling<2>(layout, liquid, fluid, opt);
  // four tiles: three squares (one around the hole) and an L-shaped strip left by the corner
  ASSERT_EQ(tiling.tiles.size(), 4u);
  for (std::size_t s = 0; s < layout.numSlots(); ++s) {
    const auto c = layout.cellOf(s);
    if (tiling.tileOfCell[s] < 0) continue;
    EXPECT_TRUE(liquid[s]);
    EXPECT_GE(sparse_grid::detail::floorMod(c.x(), 24), 2);  // OR rule: slab along either axis
    EXPECT_GE(sparse_grid::detail::floorMod(c.y(), 24), 2);
  }
  // the tile around the hole and the L-shaped one are not full boxes (irregular tiles)
  int irregular = 0;
  for (const auto& t : tiling.tiles) irregular += t.isFullBox ? 0 : 1;
  EXPECT_EQ(irregular, 2);
  // culling: with min-region larger than any tile everything returns to Cartesian
  opt.minRegion = 40;
  const auto culled = sparse_grid::buildTiling<2>(layout, liquid, fluid, opt);
  EXPECT_EQ(culled.tiles.size(), 0u);
  EXPECT_EQ(culled.culledRegions, 4u);
}

// Octree tiles: the cube edges follow the refine predicate exactly. Always
// splitting gives the tiling of the smallest edge, never splitting that of the largest, bit for
// bit; splitting only the cubes that hold one cell refines a chain of cubes around it.
TEST(Tiling, OctreeEdgesFollowTheRefinePredicate) {
  openvdb::MaskTree mask;
  sparse_grid::activateBox(mask, openvdb::Coord(-1, -1, 0), openvdb::Coord(64, 64, 0));
  const sparse_grid::BlockLayout<2> layout(mask, 1.0);
  std::vector<std::uint8_t> liquid(layout.numSlots(), 0), fluid(layout.numSlots(), 1);
  for (std::size_t s = 0; s < layout.numSlots(); ++s) {
    const auto c = layout.cellOf(s);
    liquid[s] = c.x() >= 0 && c.x() < 64 && c.y() >= 0 && c.y() < 64;
  }
  sparse_grid::TilingOptions fixed;
  fixed.padding = 2;
  fixed.bandAir = 1;
  sparse_grid::TilingOptions octree = fixed;
  octree.tileSize = 32;
  octree.minTileSize = 8;
  auto same = [](const sparse_grid::Tiling<2>& a, const sparse_grid::Tiling<2>& b) {
    if (a.tileOfCell != b.tileOfCell || a.tiles.size() != b.tiles.size()) return false;
    for (std::size_t t = 0; t < a.tiles.size(); ++t)
      if (a.tiles[t].cells != b.tiles[t].cells || a.tiles[t].halfWidthInCells != b.tiles[t].halfWidthInCells) return false;
    return true;
  };
  const sparse_grid::RefineRegion always = [](const sparse_grid::Tile&, int) { return true; };
  const sparse_grid::RefineRegion never = [](const sparse_grid::Tile&, int) { return false; };
  fixed.tileSize = 8;
  EXPECT_TRUE(same(sparse_grid::buildTiling<2>(layout, liquid, fluid, octree, always),
                   sparse_grid::buildTiling<2>(layout, liquid, fluid, fixed)));
  fixed.tileSize = 32;
  EXPECT_TRUE(same(sparse_grid::buildTiling<2>(layout, liquid, fluid, octree, never),
                   sparse_grid::buildTiling<2>(layout, liquid, fluid, fixed)));
  // split the cubes holding cell (41, 41): [32, 64)^2, then [32, 48)^2, then 8 x 8 cubes
  const sparse_grid::Coord hot(41, 41, 0);
  const sparse_grid::RefineRegion aroundCell = [&](const sparse_grid::Tile& region, int edge) {
    for (int a = 0; a < 2; ++a)
      if (hot[a] / edge != region.bboxMin[a] / edge) return false;
    return true;
  };
  const auto tiling = sparse_grid::buildTiling<2>(layout, liquid, fluid, octree, aroundCell);
  std::map<int, int> byEdge;
  for (const auto& t : tiling.tiles) {
    ++byEdge[t.cubeEdge];
    for (std::size_t s : t.cells)
      for (int a = 0; a < 2; ++a) EXPECT_GE(sparse_grid::detail::floorMod(layout.cellOf(s)[a], t.cubeEdge), 2);
  }
  EXPECT_EQ(byEdge, (std::map<int, int>{{8, 4}, {16, 3}, {32, 3}}));
  // the edges must halve from --tile to --tile-min, above the padding
  octree.tileSize = 48;
  octree.minTileSize = 16;
  EXPECT_THROW(sparse_grid::buildTiling<2>(layout, liquid, fluid, octree, always), std::invalid_argument);
  octree.tileSize = 32;
  octree.minTileSize = 2;
  EXPECT_THROW(sparse_grid::buildTiling<2>(layout, liquid, fluid, octree, always), std::invalid_argument);
}

// Adaptive tiles from the fit (ReducedOptions::tileAccuracy): a field the quadratic basis holds
// exactly never splits a cube, however tight the target; a narrow bump added to it splits only the
// cubes around the bump.
TYPED_TEST(ReducedTest, AdaptiveTilesSplitOnlyWhereTheFitMisses) {
  constexpr int Dim = TypeParam::value;
  LiquidBox<Dim> box(Dim == 2 ? 64 : 32);
  const std::size_t n = box.layout.numSlots();
  const Vec3d bump(0.8, 0.8, 0.8);
  auto setField = [&](double amplitude) {
    for (std::size_t s = 0; s < n; ++s)
      for (int a = 0; a < Dim; ++a) {
        const Vec3d p = box.layout.samplePosition(s, sparse_grid::faceMask(a));
        const double x = p[0], y = p[1], z = p[2];
        double v;  // the divergence-free quadratic of QuadraticFieldIsFittedExactly
        if (Dim == 2) v = a == 0 ? (x * x - y * y + 2 * x * y) : -(2 * x * y + y * y);
        else v = a == 0 ? (x * x - 2 * x * z) : a == 1 ? (y * y - 2 * x * y) : (z * z - 2 * y * z);
        double r2 = 0.0;
        for (int d = 0; d < Dim; ++d) r2 += (p[d] - bump[d]) * (p[d] - bump[d]);
        box.prob.uStar[a * n + s] = v + (a == 0 ? amplitude * std::exp(-r2 / 0.003) : 0.0);
      }
  };
  const int big = Dim == 2 ? 32 : 16, small = big / 2;
  solver::ReducedOptions opt = options(solver::PolynomialOrder::Quadratic, solver::BasisFamily::DivergenceFree, big, 2);
  opt.tiling.minTileSize = small;
  opt.tileAccuracy = 1e-6;
  const auto kinds = solver::couplingKinds(solver::SystemKind::UnifiedStokes);
  setField(0.0);
  const solver::ReducedTiles<Dim> exact(box.prob, opt, kinds);
  ASSERT_GT(exact.numTiles(), 0u);
  for (const auto& t : exact.tiling().tiles) EXPECT_EQ(t.cubeEdge, big);
  setField(0.5);
  opt.tileAccuracy = 0.02;
  const solver::ReducedTiles<Dim> bumped(box.prob, opt, kinds);
  int split = 0;
  for (const auto& t : bumped.tiling().tiles) {
    if (t.cubeEdge == big) continue;
    EXPECT_EQ(t.cubeEdge, small);
    ++split;
    for (int a = 0; a < Dim; ++a) EXPECT_GE(t.bboxMin[a], big) << "a split cube away from the bump";
  }
  EXPECT_EQ(split, 1 << Dim);  // the cube holding the bump, in 2^Dim halves
  // the target must come with the smallest edge
  opt.tiling.minTileSize = 0;
  EXPECT_THROW(solver::ReducedTiles<Dim>(box.prob, opt, kinds), std::invalid_argument);
}

// The work estimate of solver/reduced/tile_cost.h on box-shaped tiles, whose counts are fixed by
// their widths w_a: cells = prod w_a, faces = Dim cells + sum_a cells / w_a (every cell's lower
// faces and the far side's), shell = 2 sum_a cells / w_a. The paying rule keeps exactly the tiles
// whose saved rows exceed their overhead: none of 6 cells (a cube pays from 12 cells in 2D, 13 in
// 3D), some of the wide ones.
TYPED_TEST(ReducedTest, TileWorkCountsBoxTilesAndThePayingRuleKeepsWhatPays) {
  constexpr int Dim = TypeParam::value;
  LiquidBox<Dim> box(Dim == 2 ? 64 : 32);
  const auto kinds = solver::couplingKinds(solver::SystemKind::UnifiedStokes);
  for (const int tile : {Dim == 2 ? 32 : 16, 8}) {
    solver::ReducedOptions opt = options(solver::PolynomialOrder::Quadratic, solver::BasisFamily::DivergenceFree, tile, 2);
    const solver::ReducedTiles<Dim> all(box.prob, opt, kinds);
    ASSERT_GT(all.numTiles(), 0u);
    std::size_t paying = 0;
    for (std::size_t t = 0; t < all.numTiles(); ++t) {
      const sparse_grid::Tile& region = all.tiling().tiles[t];
      ASSERT_TRUE(region.isFullBox);
      std::size_t cells = 1, across = 0;
      for (int a = 0; a < Dim; ++a) cells *= std::size_t(region.bboxMax[a] - region.bboxMin[a] + 1);
      for (int a = 0; a < Dim; ++a) across += cells / std::size_t(region.bboxMax[a] - region.bboxMin[a] + 1);
      const solver::TileWork w = solver::tileWork(box.layout, all.tiling(), t);
      EXPECT_EQ(w.cells, cells);
      EXPECT_EQ(w.faces, Dim * cells + across);
      EXPECT_EQ(w.shell, 2 * across);
      paying += w.pays() ? 1 : 0;
    }
    if (tile == 8) EXPECT_EQ(paying, 0u);
    else EXPECT_GT(paying, 0u);
    opt.rule = solver::TileRule::Paying;
    const solver::ReducedTiles<Dim> kept(box.prob, opt, kinds);
    EXPECT_EQ(kept.numTiles(), paying);
    EXPECT_EQ(kept.unpaidTiles(), all.numTiles() - paying);
    if (paying == 0) continue;
    // against a uniform step of R rows at c per row: the tiles stay while R - saved + overhead < c R
    opt.uniformRows = 4 * box.layout.numSlots();
    const double R = double(opt.uniformRows);
    const double threshold = (R - kept.work().saved + kept.work().overhead) / R;
    opt.uniformRowCost = threshold + 1e-9;
    EXPECT_EQ(solver::ReducedTiles<Dim>(box.prob, opt, kinds).numTiles(), paying);
    opt.uniformRowCost = threshold - 1e-9;
    const solver::ReducedTiles<Dim> none(box.prob, opt, kinds);
    EXPECT_EQ(none.numTiles(), 0u);
    EXPECT_EQ(none.unpaidTiles(), all.numTiles());
  }
}

// The disk under the pressure-velocity multigrid with the default quadratic tiles (16 / 3): none
// pays against the uniform padded cycle (solver/step/stokes_step_impl.h, payingRuleOptions), so
// the step is the uniform one, bit for bit; told to keep every tile, it has tiles and other bits.
TEST(PayingTiles, DiskWhoseTilesDoNotPayIsTheUniformStep) {
  analytic::AnalyticOptions o;
  o.n = 128;
  o.mu = 0.1;
  o.form = std::nullopt;
  o.preconditioner = std::nullopt;  // planSolve's: MINRES + multigrid on the pressure-velocity form
  o.keepVelocities = true;
  const analytic::AnalyticResult uniform = analytic::runDiskStokes(o);
  o.model = "quadratic";
  const analytic::AnalyticResult paying = analytic::runDiskStokes(o);
  EXPECT_EQ(paying.tileRule, "paying");
  EXPECT_EQ(paying.tiles, 0u);
  EXPECT_GT(paying.unpaidTiles, 0u);
  ASSERT_EQ(paying.velocities.size(), uniform.velocities.size());
  EXPECT_EQ(std::memcmp(paying.velocities.data(), uniform.velocities.data(), uniform.velocities.size() * sizeof(double)), 0);
  o.tileRule = solver::TileRule::All;
  const analytic::AnalyticResult all = analytic::runDiskStokes(o);
  EXPECT_EQ(all.tiles, paying.unpaidTiles);
  EXPECT_NE(all.L1, uniform.L1);
}

// Temporally consistent tiles (solver/reduced/tile_history.h): a cube whose region the previous
// build saw keeps that build's decision, whatever the new velocity, and every tile is the one the
// previous build had; a history of other regions is not used, and the fit decides again.
TYPED_TEST(ReducedTest, AdaptiveCubesKeepThePreviousDecisionWhereTheirRegionDidNotChange) {
  constexpr int Dim = TypeParam::value;
  LiquidBox<Dim> box(Dim == 2 ? 64 : 32);
  const std::size_t n = box.layout.numSlots();
  auto setField = [&](double amplitude) {  // a linear shear, plus a narrow bump near (0.8, 0.8, 0.8)
    for (std::size_t s = 0; s < n; ++s)
      for (int a = 0; a < Dim; ++a) {
        const Vec3d p = box.layout.samplePosition(s, sparse_grid::faceMask(a));
        double r2 = 0.0;
        for (int d = 0; d < Dim; ++d) r2 += (p[d] - 0.8) * (p[d] - 0.8);
        box.prob.uStar[a * n + s] = a == 0 ? p[1] + amplitude * std::exp(-r2 / 0.003) : 0.0;
      }
  };
  const int big = Dim == 2 ? 32 : 16;
  solver::ReducedOptions opt = options(solver::PolynomialOrder::Quadratic, solver::BasisFamily::DivergenceFree, big, 2);
  opt.tiling.minTileSize = big / 2;
  opt.tileAccuracy = 0.02;
  const auto kinds = solver::couplingKinds(solver::SystemKind::UnifiedStokes);
  auto edges = [](const solver::ReducedTiles<Dim>& r) {
    std::vector<int> e;
    for (const auto& t : r.tiling().tiles) e.push_back(t.cubeEdge);
    return e;
  };
  opt.history = std::make_shared<solver::TileHistory>();
  setField(0.5);
  const solver::ReducedTiles<Dim> bumped(box.prob, opt, kinds);
  EXPECT_EQ(bumped.reusedDecisions(), 0u);
  EXPECT_EQ(bumped.keptTiles(), 0u);
  opt.history->advance();
  const solver::TileHistory::State seen = opt.history->state();
  ASSERT_FALSE(seen.decisions.empty());

  setField(0.0);  // the shear alone: no cube splits when decided afresh
  const std::vector<int> fresh = [&] {
    solver::ReducedOptions o = opt;
    o.history = nullptr;
    return edges(solver::ReducedTiles<Dim>(box.prob, o, kinds));
  }();
  EXPECT_EQ(std::count(fresh.begin(), fresh.end(), big / 2), 0);
  const solver::ReducedTiles<Dim> kept(box.prob, opt, kinds);
  const std::vector<int> keptEdges = edges(kept);
  EXPECT_EQ(keptEdges, edges(bumped));
  EXPECT_EQ(kept.keptTiles(), bumped.numTiles());
  EXPECT_GT(kept.reusedDecisions(), 0u);
  EXPECT_EQ(std::count(keptEdges.begin(), keptEdges.end(), big / 2), 1 << Dim);

  solver::TileHistory::State other = seen;  // the same cubes, other regions
  for (auto& d : other.decisions) d.region += 1;
  opt.history->restore(other);
  const solver::ReducedTiles<Dim> decidedAgain(box.prob, opt, kinds);
  EXPECT_EQ(decidedAgain.reusedDecisions(), 0u);
  EXPECT_EQ(edges(decidedAgain), fresh);
}

TEST(Tiling, PaddingOneIsRefusedWithViscosity) {
  LiquidBox<2> box(32);
  try {
    solver::ReducedTiles<2> tiles(box.prob, options(solver::PolynomialOrder::Quadratic, solver::BasisFamily::DivergenceFree, 16, 1),
                                  solver::couplingKinds(solver::SystemKind::UnifiedStokes));
    FAIL() << "padding 1 must be refused";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("padding 1"), std::string::npos) << e.what();
  }
}

// Both forms of reduced Stokes give the same face velocities at tolerance 1e-10 (the
// pressure-velocity form is solved with MINRES; CG on the SPD form): on every face of the layout,
// the ones outside the liquid's control volumes (which the disk's L1 error and kinetic energy do
// not weigh) included, to 1e-8 of the largest (measured 1.4e-11, 5.5e-11, 3.9e-11 for the uniform,
// affine and quadratic models: the residual tolerance, with room for the conditioning); L1 and
// kinetic energy to 1e-6.
TEST(Forms, PressureStressAndPressureVelocityAgree) {
  for (const char* model : {"uniform", "affine", "quadratic"}) {
    analytic::AnalyticOptions o;
    o.n = 32;
    o.mu = 0.1;
    o.model = model;
    o.tolerance = 1e-10;
    o.keepVelocities = true;
    o.form = solver::StokesForm::PressureStress;
    const auto spd = analytic::runDiskStokes(o);
    o.form = solver::StokesForm::PressureVelocity;
    const auto pv = analytic::runDiskStokes(o);
    EXPECT_EQ(spd.status, "Converged") << model;
    EXPECT_EQ(pv.status, "Converged") << model;
    ASSERT_EQ(spd.velocities.size(), pv.velocities.size()) << model;
    ASSERT_FALSE(spd.velocities.empty()) << model;
    double scale = 0.0, worst = 0.0;
    std::size_t worstFace = 0;
    for (std::size_t i = 0; i < spd.velocities.size(); ++i) {
      scale = std::max(scale, std::abs(spd.velocities[i]));
      const double d = std::abs(spd.velocities[i] - pv.velocities[i]);
      if (d > worst) worst = d, worstFace = i;
    }
    std::printf("[ measured ] %s: largest face velocity difference %.2e of the largest speed %.3e\n", model,
                worst / scale, scale);
    EXPECT_GT(scale, 0.0) << model;
    EXPECT_LT(worst, 1e-8 * scale) << model << ": face " << worstFace;
    EXPECT_NEAR(spd.L1, pv.L1, 1e-6 * spd.L1) << model;
    EXPECT_NEAR(spd.kineticEnergyAfter, pv.kineticEnergyAfter, 1e-6 * spd.kineticEnergyAfter) << model;
  }
}

}  // namespace
}  // namespace stokes
