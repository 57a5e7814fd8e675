// Convergence against the analytic solutions of thesis chapter 5 (docs/design.md §4), sized for CI.
#include <gtest/gtest.h>

#include <Eigen/Sparse>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <utility>
#include <vector>

#include "analytic/analytic_cases.h"
#include "analytic/disk_stokes_solution.h"
#include "analytic/surface_mode_solution.h"

namespace stokes {
namespace {

using analytic::AnalyticOptions;
using analytic::AnalyticResult;

double order(double coarse, double fine) { return std::log2(coarse / fine); }

AnalyticResult box(int dim, int n) {
  AnalyticOptions o;
  o.dim = dim;
  o.n = n;
  const AnalyticResult r = analytic::runBoxViscosity(o);
  EXPECT_EQ(r.status, "Converged");
  return r;
}

/// The 2D box-viscosity case (rho = mu = dt = 1 on [0, pi]^2, u = v = sin x sin y) assembled here
/// independently of the engine's stencils and solved directly (sparse LU): the textbook MAC form of
/// u - div(2 mu eps(u)) = u*, tau_xx = 2 (u_{i+1,j} - u_{i,j}) / dx on cells, tau_xy = (u_{i,j} -
/// u_{i,j-1} + v_{i,j} - v_{i-1,j}) / dx on nodes, every face on or beyond the walls (x or y = 0,
/// pi, and the ghost rows half a cell out) holding the exact velocity. Returns {L1, Linf} over the
/// unknown faces, L1 = sum |e| dx^2.
std::pair<double, double> directBoxViscosity2D(int N) {
  const double pi = std::numbers::pi, dx = pi / N;
  auto exact = [](double x, double y) { return std::sin(x) * std::sin(y); };
  auto uStar = [](double x, double y) { return 4.0 * std::sin(x) * std::sin(y) - std::cos(x) * std::cos(y); };
  // unknowns: u(i, j) at (i dx, (j + 1/2) dx), 1 <= i <= N - 1, 0 <= j <= N - 1; v the transpose
  const int nu = (N - 1) * N;
  auto uIndex = [&](int i, int j) { return (i >= 1 && i <= N - 1 && j >= 0 && j <= N - 1) ? (i - 1) * N + j : -1; };
  auto vIndex = [&](int i, int j) { return (j >= 1 && j <= N - 1 && i >= 0 && i <= N - 1) ? nu + (j - 1) * N + i : -1; };
  std::vector<Eigen::Triplet<double>> entries;
  Eigen::VectorXd b(2 * nu);
  const double c = 1.0 / (dx * dx);
  for (int a = 0; a < 2; ++a)
    for (int i = 0; i < N + (a == 0 ? 1 : 0); ++i)
      for (int j = 0; j < N + (a == 1 ? 1 : 0); ++j) {
        // channel a's face (i, j); in the transposed frame (x along a) v's equation reads as u's
        const auto along = [&](int ii, int jj) { return a == 0 ? uIndex(ii, jj) : vIndex(jj, ii); };
        const auto across = [&](int ii, int jj) { return a == 0 ? vIndex(ii, jj) : uIndex(jj, ii); };
        const auto pos = [&](bool alongFace, int ii, int jj) {  // (x, y) of a face in the real frame
          const double s = ii * dx, t = (jj + 0.5) * dx;  // along-face position in the transposed frame
          const double sx = (ii + 0.5) * dx, ty = jj * dx;  // across-face position
          const double x = alongFace ? s : sx, y = alongFace ? t : ty;
          return a == 0 ? std::make_pair(x, y) : std::make_pair(y, x);
        };
        const int ii = a == 0 ? i : j, jj = a == 0 ? j : i;
        const int row = along(ii, jj);
        if (row < 0) continue;
        const auto [x, y] = pos(true, ii, jj);
        b[row] = uStar(x, y);
        // coefficient (or known value) of a term  coef * w  with w an along- or across-face value
        auto add = [&](bool alongFace, int i2, int j2, double coef) {
          const int col = alongFace ? along(i2, j2) : across(i2, j2);
          if (col >= 0) entries.emplace_back(row, col, coef);
          else {
            const auto [x2, y2] = pos(alongFace, i2, j2);
            b[row] -= coef * exact(x2, y2);
          }
        };
        add(true, ii, jj, 1.0);
        // -(tau_xx(cell ii) - tau_xx(cell ii - 1)) / dx
        add(true, ii + 1, jj, -2.0 * c), add(true, ii, jj, 2.0 * c);
        add(true, ii, jj, 2.0 * c), add(true, ii - 1, jj, -2.0 * c);
        // -(tau_xy(node ii, jj + 1) - tau_xy(node ii, jj)) / dx
        add(true, ii, jj + 1, -c), add(true, ii, jj, c), add(false, ii, jj + 1, -c), add(false, ii - 1, jj + 1, c);
        add(true, ii, jj, c), add(true, ii, jj - 1, -c), add(false, ii, jj, c), add(false, ii - 1, jj, -c);
      }
  Eigen::SparseMatrix<double> A(2 * nu, 2 * nu);
  A.setFromTriplets(entries.begin(), entries.end());
  Eigen::SparseLU<Eigen::SparseMatrix<double>> lu(A);
  const Eigen::VectorXd w = lu.solve(b);
  double L1 = 0.0, Linf = 0.0;
  for (int i = 1; i <= N - 1; ++i)
    for (int j = 0; j <= N - 1; ++j) {
      // u(i, j) and, by the transposed layout, v(j, i) at the mirrored position
      const double e = std::abs(w[uIndex(i, j)] - exact(i * dx, (j + 0.5) * dx));
      const double f = std::abs(w[vIndex(j, i)] - exact((j + 0.5) * dx, i * dx));
      L1 += (e + f) * dx * dx;
      Linf = std::max({Linf, e, f});
    }
  return {L1, Linf};
}

// Uniform viscosity with exact Dirichlet ghosts is second order (thesis: 2.01). The engine's solve
// (Jacobi CG to 1e-10) is the scheme directBoxViscosity2D assembles independently: its L1 and Linf
// equal the direct solve's to 1e-6 relative at N = 16, 32, 64 (both: L1 = 0.020108, 0.0049256,
// 0.00121683; Linf = 0.00240782, 0.00060088, 0.000149955).
TEST(BoxViscosity, SecondOrderIn2D) {
  const AnalyticResult r16 = box(2, 16), r32 = box(2, 32), r64 = box(2, 64);
  for (const AnalyticResult* r : {&r16, &r32, &r64}) {
    const auto [L1, Linf] = directBoxViscosity2D(r->n);
    std::printf("[ measured ] N = %d: L1 %.6g (direct %.6g), Linf %.6g (direct %.6g)\n", r->n, r->L1, L1, r->Linf, Linf);
    EXPECT_NEAR(r->L1, L1, 1e-6 * L1) << "N = " << r->n;
    EXPECT_NEAR(r->Linf, Linf, 1e-6 * Linf) << "N = " << r->n;
  }
  EXPECT_NEAR(order(r16.L1, r32.L1), 2.0, 0.1);
  EXPECT_NEAR(order(r32.L1, r64.L1), 2.0, 0.1);
  EXPECT_NEAR(order(r32.Linf, r64.Linf), 2.0, 0.15);
}

TEST(BoxViscosity, SecondOrderIn3D) {
  const AnalyticResult r8 = box(3, 8), r16 = box(3, 16), r32 = box(3, 32);
  EXPECT_NEAR(order(r8.L1, r16.L1), 2.0, 0.2);
  EXPECT_NEAR(order(r16.L1, r32.L1), 2.0, 0.15);
}

// Free-surface Stokes disk: at or below 1.5x thesis Table F.1 (0.0226 at N = 32, 0.0110 at 64),
// and second order in both norms on the faces whose control volume holds liquid. Measured under
// the engine's plane cuts: L1 0.0933, 0.0200, 0.00454 (orders 2.22, 2.14), Linf 0.229, 0.0601,
// 0.0138 (1.93, 2.12).
TEST(DiskStokes, FreeSurfaceConvergesAtSecondOrder) {
  AnalyticOptions o;
  o.mu = 0.1;
  o.n = 16;
  const AnalyticResult r16 = analytic::runDiskStokes(o);
  o.n = 32;
  const AnalyticResult r32 = analytic::runDiskStokes(o);
  o.n = 64;
  const AnalyticResult r64 = analytic::runDiskStokes(o);
  for (const auto* r : {&r16, &r32, &r64}) EXPECT_EQ(r->status, "Converged");
  EXPECT_LE(r32.L1, 1.5 * 0.022576);
  EXPECT_LE(r64.L1, 1.5 * 0.010988);
  EXPECT_GE(order(r16.L1, r32.L1), 1.8);
  EXPECT_GE(order(r32.L1, r64.L1), 1.8);
  EXPECT_GE(order(r16.Linf, r32.Linf), 1.6);
  EXPECT_GE(order(r32.Linf, r64.Linf), 1.6);
  EXPECT_LT(r64.kineticEnergyAfter, r64.kineticEnergyBefore);
}

AnalyticResult reducedBox(const char* model, int n) {
  AnalyticOptions o;
  o.n = n;
  o.model = model;
  o.tileSize = 16;
  o.padding = 2;
  const AnalyticResult r = analytic::runBoxViscosity(o);
  EXPECT_EQ(r.status, "Converged");
  EXPECT_GT(r.tiles, 0u);
  return r;
}

// Reduced viscosity, 16/2 tiles, full bases: within 1.5x of thesis Table 5.1 / E.1, and the
// quadratic model converges clearly faster than second order (thesis: 2.66).
TEST(BoxViscosity, ReducedTilesMatchThesis) {
  const AnalyticResult a64 = reducedBox("affine", 64), q64 = reducedBox("quadratic", 64),
                       q128 = reducedBox("quadratic", 128);
  EXPECT_LT(a64.L1, 1.5 * 0.9869);
  EXPECT_GT(a64.L1, 0.9869 / 1.5);
  EXPECT_LT(q64.L1, 1.5 * 0.04906);
  EXPECT_LT(q128.L1, 1.5 * 0.005839);
  EXPECT_LT(q128.Linf, 1.5 * 0.001432);
  EXPECT_GT(order(q64.L1, q128.L1), 2.5);
}

// Reduced unified Stokes on the disk, 16/3 tiles. The L1 errors are fixed by the discretisation
// (the solve runs to 1e-10): measured affine 0.3217, quadratic 0.04309. Bounds at 1.25x those:
// a change of tiling, basis or fit that costs a quarter of the accuracy fails. Separately, both lie
// below thesis Table F.1 (affine 0.47645, quadratic 0.11502: the engine's plane-cut weights and
// all-face quadratic fit sit 1.5x and 2.7x below), and quadratic beats affine.
TEST(DiskStokes, ReducedTilesMatchThesis) {
  AnalyticOptions o;
  o.mu = 0.1;
  o.n = 64;
  o.tileSize = 16;
  o.padding = 3;
  o.model = "affine";
  const AnalyticResult a = analytic::runDiskStokes(o);
  o.model = "quadratic";
  const AnalyticResult q = analytic::runDiskStokes(o);
  EXPECT_EQ(a.status, "Converged");
  EXPECT_EQ(q.status, "Converged");
  EXPECT_GT(q.tiles, 10u);
  std::printf("[ measured ] disk 16/3 tiles: affine L1 %.5g, quadratic L1 %.5g\n", a.L1, q.L1);
  EXPECT_LT(a.L1, 1.25 * 0.3217);
  EXPECT_LT(q.L1, 1.25 * 0.04309);
  EXPECT_LT(a.L1, 0.47645);  // thesis Table F.1
  EXPECT_LT(q.L1, 0.11502);
  EXPECT_LT(q.L1, a.L1);
  EXPECT_LT(q.kineticEnergyAfter, q.kineticEnergyBefore);
  EXPECT_LT(q.maxDivergence, 1e-7);
}

// 3D free surface and solids together: a liquid ball on a floor around a solid sphere.
TEST(Ball, OnFloorWithSolidSphereStaysDivergenceFree) {
  AnalyticOptions o;
  o.n = 24;
  o.mu = 0.5;
  o.dt = 0.02;
  o.solids = true;
  o.tolerance = 1e-10;
  const AnalyticResult r = analytic::runBall(o);
  EXPECT_EQ(r.status, "Converged");
  EXPECT_LT(r.kineticEnergyAfter, r.kineticEnergyBefore);
  EXPECT_LT(r.maxDivergence, 1e-7);
}

// With plane-cut liquid weights, a small surface mode on a pool one wavelength deep (2D,
// a = lambda / 64, so k a = 0.1) decays at the linear theory's rate wherever the mean surface sits
// in its cell and whatever the mode's sign: within 0.3% at 64 cells per wavelength (measured
// 0.9983-0.9989; 0.9973-1.0012 at 32, 0.9985-0.9986 at 128, where the mode's own second-order term
// in k a holds it), a bump and a dimple within 0.01%. With the unit-box mass fractions it was
// 0.992-1.008 at 64 cells and 0.961-1.026 at 32; with sub-samples 0.93 to 1.02 here, and 0.80 to
// 1.07 at 32 cells.
TEST(SurfaceMode, DecaysAtTheLinearRateWhereverTheSurfaceSits) {
  const int n = 64;
  for (const double level : {0.0, 0.25, 0.5}) {
    double bump = 0.0;
    for (const double sign : {1.0, -1.0}) {
      AnalyticOptions o;
      o.n = n;
      o.amplitude = sign * n / 64.0;
      o.levelOffset = level;
      o.form = std::nullopt;  // MINRES + multigrid, the fastest
      o.preconditioner = std::nullopt;
      o.liquidWeights = sparse_grid::FractionRule::PlaneCut;
      const AnalyticResult r = analytic::runSurfaceMode(o);
      ASSERT_EQ(r.status, "Converged");
      const double ratio = r.rate / r.theoryRate;
      EXPECT_NEAR(ratio, 1.0, 0.003) << "level " << level << " sign " << sign;
      if (sign > 0.0) bump = ratio;
      else EXPECT_NEAR(ratio, bump, 1e-4) << "bump and dimple, level " << level;
    }
  }
}

// A flat surface's place in its cell. A mode of 1/8 cell (2D, plane cuts) at
// four levels of the mean surface: the rate must not jump with the level (a first-order error in
// dx would), and its worst error over the levels must fall at order 1.5 or better. Measured
// 0.9883 / 1.0086 / 0.9981 / 1.0003 at 32 cells per wavelength and levels 0 / 0.25 / 0.5 / 0.75,
// 0.9966 / 1.0027 / 0.9998 / 1.0003 at 64, 0.9991 / 1.0008 / 1.0000 / 1.0001 at 128: the worst
// error falls 3.4x and 3.8x (orders 1.8 and 1.9). With the faces' unit-box mass fractions the
// liquid's weight in a partly filled cell acted on the face whose box held the surface, up to half
// a cell off: 1.066 / 1.033 / 1.017 at 32 / 64 / 128 cells at level 0.5. Before the
// side walls were free-slip, their no-slip drag held every rate 0.2-0.3% off.
TEST(SurfaceMode, SmallModeRateDoesNotDependOnTheSurfacesPlaceInItsCell) {
  double worst[3] = {0.0, 0.0, 0.0};
  for (int level = 0; level < 3; ++level) {
    for (const double offset : {0.0, 0.25, 0.5, 0.75}) {
      AnalyticOptions o;
      o.n = 32 << level;
      o.amplitude = 0.125;
      o.levelOffset = offset;
      o.form = std::nullopt;
      o.preconditioner = std::nullopt;
      o.liquidWeights = sparse_grid::FractionRule::PlaneCut;
      const AnalyticResult r = analytic::runSurfaceMode(o);
      ASSERT_EQ(r.status, "Converged");
      worst[level] = std::max(worst[level], std::abs(r.rate / r.theoryRate - 1.0));
    }
  }
  EXPECT_LT(worst[0], 0.015);
  EXPECT_GE(order(worst[0], worst[1]), 1.5);
  EXPECT_GE(order(worst[1], worst[2]), 1.5);
}

// Surface features: a Gaussian bump and dimple, one and three cells tall, 8, 16 and 32 cells
// across their radius (2D, plane-cut weights, a box 8 units wide, the theory summing its modes).
// Measured ratios to the theory at R = 8 / 16 / 32 cells (n = 32 / 64 / 128):
//   bump 1: 0.9943 / 0.9986 / 0.9999;  dimple 1: 1.0081 / 1.0024 / 1.0005;
//   bump 3: 0.9649 / 0.9874 / 0.9966;  dimple 3: 1.0237 / 1.0089 / 1.0025.
// Their errors fall at orders 2.9, 2.0, 1.68 and 1.62 over the two halvings. A bump is slow and a
// dimple fast, growing with the height over the radius: the physics' own second-order term, which
// the linear theory leaves out (the three-cell bump's shape, refined at a fixed size, converges to
// 0.9671 at n = 256: at R = 8 its discretisation error is 0.26% of its 3.5%). A bump and a dimple of
// one size cancel that term: their mean is within 0.12% (one cell) and 0.57% (three cells) at R = 8.
TEST(SurfaceMode, GaussianBumpsAndDimplesConvergeForBothSigns) {
  for (const double height : {1.0, 3.0}) {
    double error[3][2], mean[3] = {0.0, 0.0, 0.0};
    for (int level = 0; level < 3; ++level) {
      for (int sign = 0; sign < 2; ++sign) {
        AnalyticOptions o;
        o.shape = "gaussian";  // in its default box, 8 units wide
        o.n = 32 << level;
        o.radius = 8.0 * (1 << level);
        o.amplitude = sign == 0 ? height : -height;
        o.form = std::nullopt;
        o.preconditioner = std::nullopt;
        o.liquidWeights = sparse_grid::FractionRule::PlaneCut;
        const AnalyticResult r = analytic::runSurfaceMode(o);
        ASSERT_EQ(r.status, "Converged");
        error[level][sign] = std::abs(r.rate / r.theoryRate - 1.0);
        mean[level] += 0.5 * r.rate / r.theoryRate;
      }
    }
    for (int sign = 0; sign < 2; ++sign) {
      const double amplitude = sign == 0 ? height : -height;
      EXPECT_LT(error[0][sign], height == 1.0 ? 0.01 : 0.037) << "amplitude " << amplitude << " cells, radius 8 cells";
      EXPECT_GE(order(error[0][sign], error[2][sign]) / 2.0, 1.5) << "amplitude " << amplitude << " cells, R 8 to 32";
    }
    EXPECT_NEAR(mean[0], 1.0, height == 1.0 ? 0.002 : 0.007) << "bump and dimple mean, " << height << " cells";
    EXPECT_NEAR(mean[1], 1.0, height == 1.0 ? 0.001 : 0.003) << "bump and dimple mean, " << height << " cells";
  }
}

// The theory's limits: a long step gives the quasi-static rate; a deep layer rho g / (2 mu K); a
// thin film the lubrication rate rho g K^2 H^3 / (3 mu).
TEST(SurfaceModeSolution, MatchesTheQuasiStaticDeepAndThinFilmLimits) {
  const double pi = 3.14159265358979323846, mu = 2.0, rho = 3.0, g = 9.81;
  const analytic::SurfaceModeSolution longStep(2.0 * pi, 1.0, mu, rho, g, 1e3);
  const double quasiStatic = analytic::SurfaceModeSolution::quasiStaticRate(2.0 * pi, 1.0, mu, rho, g);
  EXPECT_NEAR(longStep.rate() / quasiStatic, 1.0, 1e-4);
  EXPECT_NEAR(analytic::SurfaceModeSolution::quasiStaticRate(30.0, 1.0, mu, rho, g), rho * g / (2.0 * mu * 30.0), 1e-12);
  const double K = 0.01, H = 1.0;
  const double film = rho * g * K * K * H * H * H / (3.0 * mu);
  EXPECT_NEAR(analytic::SurfaceModeSolution::quasiStaticRate(K, H, mu, rho, g) / film, 1.0, 1e-3);
  EXPECT_NEAR(analytic::SurfaceModeSolution(K, H, mu, rho, g, 1e6).rate() / film, 1.0, 2e-3);
  // the profile: w vanishes on the no-slip floor and is the rate at the surface
  const analytic::SurfaceModeSolution unitStep(2.0 * pi, 1.0, mu, rho, g, 1.0);
  EXPECT_NEAR(unitStep.verticalProfile(-1.0) / unitStep.rate(), 0.0, 1e-10);
  EXPECT_DOUBLE_EQ(unitStep.verticalProfile(0.0), unitStep.rate());
}

// The manufactured disk solution itself: divergence-free, traction-free on r = 0.75, and
// u* - u = dt/rho (grad p - mu lap u) (checked against central differences).
TEST(DiskStokesSolution, IsDivergenceAndTractionFree) {
  const double mu = 0.1, h = 1e-5;
  const analytic::DiskStokesSolution s(mu);
  using V = openvdb::Vec3d;
  auto grad = [&](int comp, const V& x) {  // d u_comp / dx, d u_comp / dy
    return std::array<double, 2>{(s.velocity(x + V(h, 0, 0), comp) - s.velocity(x - V(h, 0, 0), comp)) / (2 * h),
                                 (s.velocity(x + V(0, h, 0), comp) - s.velocity(x - V(0, h, 0), comp)) / (2 * h)};
  };
  double maxTraction = 0.0, scale = 0.0;
  for (int k = 0; k < 64; ++k) {
    const double t = 2.0 * M_PI * (k + 0.3) / 64.0;
    const V n(std::cos(t), std::sin(t), 0.0);
    const V x = 0.75 * n;
    const auto gu = grad(0, x), gv = grad(1, x);
    EXPECT_NEAR(gu[0] + gv[1], 0.0, 1e-7);
    const double p = s.pressure(x);
    const double sxx = -p + 2 * mu * gu[0], syy = -p + 2 * mu * gv[1], sxy = mu * (gu[1] + gv[0]);
    maxTraction = std::max({maxTraction, std::abs(sxx * n[0] + sxy * n[1]), std::abs(sxy * n[0] + syy * n[1])});
    scale = std::max({scale, std::abs(p), std::abs(2 * mu * gu[0])});
  }
  EXPECT_GT(scale, 1e-2);
  EXPECT_LT(maxTraction, 1e-7 * std::max(1.0, scale) + 1e-8);

  const double hl = 2e-4, rho = 1.3, dt = 0.7;
  for (const V x : {V(0.3, 0.2, 0), V(-0.5, 0.1, 0), V(0.05, -0.6, 0)}) {
    for (int c = 0; c < 2; ++c) {
      const double lap = (s.velocity(x + V(hl, 0, 0), c) + s.velocity(x - V(hl, 0, 0), c) +
                          s.velocity(x + V(0, hl, 0), c) + s.velocity(x - V(0, hl, 0), c) - 4 * s.velocity(x, c)) /
                         (hl * hl);
      const V e = c == 0 ? V(h, 0, 0) : V(0, h, 0);
      const double dp = (s.pressure(x + e) - s.pressure(x - e)) / (2 * h);
      const double want = dt / rho * (dp - mu * lap);
      EXPECT_NEAR(s.startVelocity(x, c, rho, dt) - s.velocity(x, c), want, 1e-6 * std::max(1.0, std::abs(want)));
    }
  }
}

}  // namespace
}  // namespace stokes
