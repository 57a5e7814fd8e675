// No slip where the wall or the solid is (thesis 3.6.3-3.6.4). Sheared layers whose
// one-step profile is known exactly are solved by the simulator's grid step (particles -> level
// set -> weights -> P2G -> unified Stokes solve), and the solved face velocities are compared with
// it at two or three resolutions: the error and its observed order. G2P is checked on the
// particles next to the wall.
//
// One implicit step from rest of a layer whose velocity u(s) depends on the wall-normal
// coordinate s alone is u - nu dt u'' = f dt (no pressure: the layer's free sides and ends carry
// no normal stress), so with k = 1/sqrt(nu dt):
//   Poiseuille between plates s = 0, W, gravity g along the plates:
//       u = g dt (1 - cosh(k (s - W/2)) / cosh(k W/2))
//   film on a vertical wall s = 0, free surface s = h (u'(h) = 0):
//       u = g dt (1 - cosh(k (s - h)) / cosh(k h))
//   Couette, wall s = 0 at rest, lid s = H moving at U, no gravity:
//       u = U sinh(k s) / sinh(k H)
#include <gtest/gtest.h>
#include "sparse_grid/vdb_trees.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "sim/scene/scene.h"
#include "sim/step/simulator.h"
#include "sim/step/stokes_stage.h"

namespace fs = std::filesystem;
using namespace stokes::sim;

namespace {

const fs::path kScenes = fs::path(STOKES_SOURCE_DIR) / "scenes";

class WallTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { openvdb::initialize(); }
};

constexpr double kRho = 1000.0, kMu = 1e4, kG = 9.81, kDt = 0.01;
const double kNuDt = kMu / kRho * kDt;  // 0.1 m^2

/// A sheared layer: its scene at a resolution, the velocity component and wall-normal axis of
/// its profile, the exact one-step profile u(s) with s the wall-normal world coordinate, and the
/// probe box (world coordinates) of faces compared: away from the layer's free ends and sides.
struct ShearLayer {
  std::function<std::string(int)> scene;
  int component = 1, normal = 0;
  std::function<double(double)> exact;
  std::function<double(const Vec3d&)> exact3;  ///< used instead of exact where set
  Vec3d probeMin, probeMax;
};

/// The layers' scenes keep the raw particle surface (keep_volume off) and an incompressible solve
/// (volume_control 0): these tests measure the walls' discretisation on a fixed geometry, and the
/// volume match moves every free surface by the offset the whole layer's volume asks for (at 4
/// cells across the film: 3.2% instead of 2.8%); the control's divergence would add its own flow.
/// The liquid weights are the engine's (sparse_grid::kLiquidFractionRule, plane cuts).
std::string sceneText(const std::string& domainMax, int resolution, const std::string& gravity,
                      const std::string& liquid, const std::string& solids) {
  return R"({"name": "walls", "keep_volume": false, "volume_control": 0, "domain": {"min": [0, 0, 0], "max": )" + domainMax + R"(},
    "resolution": )" + std::to_string(resolution) + R"(, "frames": 1, "fps": 24,
    "material": {"density": 1000, "viscosity": 10000}, "gravity": )" + gravity + R"(,
    "viscosity": "coupled", "solver": {"tolerance": 1e-12, "max_iterations": 100000},
    "liquid": [)" + liquid + R"(], "solids": )" + solids + R"(, "output": {"preview": false}})";
}

struct ProfileError {
  double relative = 0.0;  ///< max |u - exact| over the probed liquid faces / max |exact|
  int faces = 0;
};

/// One grid step of the layer's scene at `resolution`; the error of the solved face velocities.
ProfileError solvedProfileError(const ShearLayer& layer, int resolution) {
  const Scene scene = parseSceneText(layer.scene(resolution), "walls.json", kScenes.string());
  const Simulator sim(scene);
  const openvdb::FloatGrid::Ptr liquid = sim.liquidLevelSet();
  GridStep grid(sim.particles().x, *liquid, sim.solids(), sim.domain(), scene, kDt, true, layoutBand(scene));
  const Vec3d gravity = scene.gravity ? *scene.gravity : Vec3d(0.0);
  grid.solve(sim.particles(), &gravity, planStokes(scene, nullptr));
  const Layout3& L = grid.layout();
  const std::size_t n = L.numSlots();
  const int a = layer.component;
  ProfileError e;
  double peak = 0.0, worst = 0.0;
  for (std::size_t s = 0; s < n; ++s) {
    const Vec3d x = L.samplePosition(s, stokes::sparse_grid::faceMask(a));
    if (grid.problem().liquidFace[a * n + s] < 1.0) continue;
    bool inside = true;
    for (int b = 0; b < 3; ++b) inside = inside && x[b] >= layer.probeMin[b] && x[b] <= layer.probeMax[b];
    if (!inside) continue;
    const double exact = layer.exact3 ? layer.exact3(x) : layer.exact(x[layer.normal]);
    peak = std::max(peak, std::abs(exact));
    worst = std::max(worst, std::abs(grid.velocity()[a * n + s] - exact));
    ++e.faces;
  }
  e.relative = peak > 0.0 ? worst / peak : 0.0;
  return e;
}

/// Errors at the given resolutions, printed with the observed orders (log2 of successive ratios
/// when the resolution doubles).
std::vector<double> convergence(const char* name, const ShearLayer& layer, const std::vector<int>& resolutions) {
  std::vector<double> errors;
  for (int r : resolutions) {
    const ProfileError e = solvedProfileError(layer, r);
    EXPECT_GT(e.faces, 12) << name << " at resolution " << r;
    errors.push_back(e.relative);
    std::printf("[walls] %s res %d: relative error %.5f over %d faces", name, r, e.relative, e.faces);
    if (errors.size() > 1) std::printf(", order %.2f", std::log2(errors[errors.size() - 2] / e.relative));
    std::printf("\n");
  }
  return errors;
}

double order(const std::vector<double>& e, std::size_t i) { return std::log2(e[i - 1] / e[i]); }


/// Error at `cells` across the layer (the scene's resolution is cells * resolutionPerCell).
std::vector<double> convergenceInCells(const char* name, const ShearLayer& layer, const std::vector<int>& cells,
                                       int resolutionPerCell) {
  std::vector<int> resolutions;
  for (int c : cells) resolutions.push_back(c * resolutionPerCell);
  return convergence(name, layer, resolutions);
}

// ---- Couette: the floor (a domain wall) and a sliding solid lid ------------------------------

/// Plane Couette flow between the floor and a solid lid sliding at U = 0.1 m/s along x, its face at
/// y = H: a 0.3 x H x 0.05 m layer in a 0.4 x 0.1 x 0.1 m box, free at its ends and z sides, no
/// gravity. Resolution 8 per cell across H = 0.05.
ShearLayer couetteUnderSlidingLid(double H) {
  ShearLayer l;
  const double U = 0.1, k = 1.0 / std::sqrt(kNuDt);
  l.scene = [=](int res) {
    const std::string h = std::to_string(H);
    return sceneText("[0.4, 0.1, 0.1]", res, "[0, 0, 0]",
                     R"({"shape": "box", "min": [0.05, 0, 0.025], "max": [0.35, )" + h + R"(, 0.075]})",
                     R"([{"shape": "box", "min": [-1, )" + h + R"(, -1], "max": [1.4, 0.2, 1.1], "velocity": [0.1, 0, 0]}])");
  };
  l.component = 0;
  l.normal = 1;
  l.exact = [=](double y) { return U * std::sinh(k * y) / std::sinh(k * H); };
  l.probeMin = Vec3d(0.15, 0.0, 0.04);
  l.probeMax = Vec3d(0.25, H, 0.06);
  return l;
}

// The lid's face on a grid line (H = 4, 8, 16 cells): the wall and the solid each put the no-slip
// plane through a row of stress samples (W_F^tau = 1/2).
// Measured with plane cuts 0.541%, 0.172%, 0.071% (orders 1.65, 1.28; over both doublings
// 1.47). Sub-samples read 0.165%, 0.055%, 0.014%: they round the particles' surface at the lid
// (+-0.09 dx of jitter) to the grid line the lid lies on, where plane cuts read it as it is.
TEST_F(WallTest, CouetteUnderSlidingLidConverges) {
  const std::vector<double> e = convergenceInCells("couette", couetteUnderSlidingLid(0.05), {4, 8, 16}, 8);
  EXPECT_LT(e[1], 0.005);
  EXPECT_LT(e[2], 0.001);
  EXPECT_GT(order(e, 1), 1.5);
  EXPECT_GT(0.5 * std::log2(e[0] / e[2]), 1.4);
}

// The lid's face between grid lines (H = 0.0537 m: 4.3, 8.6, 17.2 cells): its stress samples
// have W_F^tau between 0 and 1, and the no-slip plane must still land on the face.
// Measured 0.63%, 0.80%, 0.053%: the error follows where the face cuts a cell, not dx. A
// face the solid cuts keeps its own fluid weight W_F^u in K^T S K, which weakens its coupling to
// the face beneath it: first order for solids off the grid lines.
TEST_F(WallTest, CouetteUnderOffGridLidStaysWithinOnePercent) {
  const std::vector<double> e = convergenceInCells("couette off-grid lid", couetteUnderSlidingLid(0.0537), {4, 8, 16}, 8);
  for (double err : e) EXPECT_LT(err, 0.01);
}

// G2P reads the wall's and the lid's velocity on their faces (BoxWalls reflection at the floor,
// ghost values through the solid in the lid): after a full step of the Couette layer at 8 cells,
// the particles' mean velocity in each half-cell slab across the layer matches the profile at
// their heights. Before, the slab on the floor read the first face's velocity (the ghost face
// outside the layout was skipped and the rest renormalised): 3.6x too fast.
TEST_F(WallTest, ParticlesNextToWallAndLidReadTheirVelocity) {
  const ShearLayer layer = couetteUnderSlidingLid(0.05);
  Simulator sim(parseSceneText(layer.scene(64), "walls.json", kScenes.string()));
  const double dx = sim.domain().dx, H = 0.05, U = 0.1;
  sim.step(kDt, 1);
  const int slabs = int(std::lround(2.0 * H / dx));
  std::vector<double> sum(slabs, 0.0);
  std::vector<int> count(slabs, 0);
  for (std::size_t p = 0; p < sim.particles().size(); ++p) {
    const Vec3d& x = sim.particles().x[p];
    if (x.x() < 0.15 || x.x() > 0.25 || std::abs(x.z() - 0.05) > 0.01 || x.y() >= H) continue;
    const int b = std::min(slabs - 1, int(x.y() / (0.5 * dx)));
    sum[b] += sim.particles().v[p].x() - layer.exact(x.y());
    ++count[b];
  }
  double worst = 0.0;
  for (int b = 0; b < slabs; ++b) {
    ASSERT_GT(count[b], 10) << "slab " << b;
    EXPECT_LT(std::abs(sum[b] / count[b]) / U, 0.005) << "slab " << b << " of " << slabs;
    worst = std::max(worst, std::abs(sum[b] / count[b]) / U);
  }
  std::printf("[walls] particles: largest slab error %.5f of U (slab 0: %.5f)\n", worst, sum[0] / count[0] / U);
}

// ---- Poiseuille: a column hanging between walls or solid plates --------------------------------

/// One implicit step from rest in a W x D duct (walls at 0 and W along x, 0 and D along z),
/// gravity g along it: v - nu dt lap v = g dt with v = 0 on the walls, as a double sine series.
double ductProfile(double x, double z, double W, double D) {
  const double pi = std::acos(-1.0);
  double sum = 0.0;
  for (int m = 1; m < 400; m += 2)
    for (int q = 1; q < 400; q += 2) {
      const double lambda = pi * pi * (m * m / (W * W) + q * q / (D * D));
      sum += 16.0 / (pi * pi * m * q) * std::sin(m * pi * x / W) * std::sin(q * pi * z / D) / (1.0 + kNuDt * lambda);
    }
  return kG * kDt * sum;
}

/// A 1 m column hanging in a 0.1 x 0.1 m duct whose four sides are the domain's walls (the lower
/// and the upper wall along x and z), free at its ends. Resolution 11 per cell across.
ShearLayer ductBetweenWalls() {
  ShearLayer l;
  const double W = 0.1;
  l.scene = [](int res) {
    return sceneText("[0.1, 1.1, 0.1]", res, "[0, -9.81, 0]",
                     R"({"shape": "box", "min": [0, 0.05, 0], "max": [0.1, 1.05, 0.1]})", "[]");
  };
  l.component = 1;
  l.normal = 0;
  l.exact3 = [=](const Vec3d& x) { return -ductProfile(x[0], x[2], W, W); };
  l.probeMin = Vec3d(0.0, 0.5, 0.0);
  l.probeMax = Vec3d(W, 0.6, W);
  return l;
}

// Measured 2.60% and 1.32% at 8 and 16 cells across; the scheme with exact reflection ghosts on
// the four walls (a 2D solve of the same one-step problem) gives 2.34% and 0.63%: the rest is the
// column's free ends. Before: the upper walls (x = W, z = D) were free-slip, 4x off.
TEST_F(WallTest, DuctBetweenDomainWallsHoldsAllFourWalls) {
  const std::vector<double> e = convergenceInCells("duct walls", ductBetweenWalls(), {8, 16}, 11);
  EXPECT_LT(e[0], 0.03);
  EXPECT_LT(e[1], 0.016);
}

/// Plane Poiseuille flow between two solid plates whose faces lie between grid lines (x = 0.0537
/// and 0.1537, gap W = 0.1 m): a 0.6 m column, 0.1 m deep, free at its ends and z sides, in a
/// 0.2 x 0.7 x 0.2 m box, probed in a band 0.05 m high in its middle. Resolution 7 per cell across
/// the gap.
///
/// The layer is long because its free ends are not part of the exact solution: the profile u(x)
/// leaves a shear traction mu u'(x) on them, and the ends' disturbance decays along the layer only
/// as exp(-pi d / W) (exp(-pi d / 2h) for the film). At d = 0.1 m, as in the first version of
/// these tests (0.3 m columns, 0.1 m band), that is 4%: the errors stalled at 4.2% (Poiseuille)
/// and 4.6% (film) whatever the resolution. At d = 0.28 m it is below 0.02%.
ShearLayer poiseuilleBetweenPlates() {
  ShearLayer l;
  const double lo = 0.0537, W = 0.1, k = 1.0 / std::sqrt(kNuDt);
  l.scene = [](int res) {
    return sceneText("[0.2, 0.7, 0.2]", res, "[0, -9.81, 0]",
                     R"({"shape": "box", "min": [0, 0.05, 0.05], "max": [0.2, 0.65, 0.15]})",
                     R"([{"shape": "box", "min": [-1, -1, -1], "max": [0.0537, 1, 1]},
                         {"shape": "box", "min": [0.1537, -1, -1], "max": [1, 1, 1]}])");
  };
  l.component = 1;
  l.normal = 0;
  l.exact = [=](double x) { return -kG * kDt * (1.0 - std::cosh(k * (x - lo - 0.5 * W)) / std::cosh(0.5 * k * W)); };
  l.probeMin = Vec3d(lo, 0.33, 0.09);
  l.probeMax = Vec3d(lo + W, 0.37, 0.11);
  return l;
}

// Measured 5.97% and 1.85% at 8 and 16 cells across (order 1.69; 19.5% and 4.4% before the wall
// fix, on the shorter column). The largest error is the face nearest a plate (0.2 dx from it at 8
// cells, 1.6x its exact speed): a cut face keeps its W_F^u in K^T S K and slips; the
// middle of the gap is 1.6% fast at 16 cells.
TEST_F(WallTest, PoiseuilleBetweenOffGridSolidPlates) {
  const std::vector<double> e = convergenceInCells("poiseuille plates", poiseuilleBetweenPlates(), {8, 16}, 7);
  EXPECT_LT(e[0], 0.065);
  EXPECT_LT(e[1], 0.02);
  EXPECT_GT(order(e, 1), 1.5);
}

/// A film draining down a vertical wall: a slab h thick (default 0.05 m) against the wall x = 0,
/// free at x = h, at its ends and z sides, 0.6 m long, in a 0.1 x 0.7 x 0.2 m box:
///     u = g dt (1 - cosh(k (x - h)) / cosh(k h)).  Resolution 14 per cell across 0.05 m.
ShearLayer filmOnVerticalWall(double h = 0.05) {
  ShearLayer l;
  const double k = 1.0 / std::sqrt(kNuDt);
  l.scene = [=](int res) {
    return sceneText("[0.1, 0.7, 0.2]", res, "[0, -9.81, 0]",
                     R"({"shape": "box", "min": [0, 0.05, 0.05], "max": [)" + std::to_string(h) + R"(, 0.65, 0.15]})",
                     "[]");
  };
  l.component = 1;
  l.normal = 0;
  l.exact = [=](double x) { return -kG * kDt * (1.0 - std::cosh(k * (x - h)) / std::cosh(k * h)); };
  l.probeMin = Vec3d(0.0, 0.33, 0.09);
  l.probeMax = Vec3d(h, 0.37, 0.11);
  return l;
}

// The film's surface on and off the grid lines, h = 0.05, 0.0535 and 0.055 m: 4, 4.28 and 4.4
// cells across, then 8, 8.56 and 8.8. Plane cuts converge wherever the surface sits. Measured
// 2.24% -> 0.71%, 1.55% -> 0.43%, 1.54% -> 0.60% (orders 1.65, 1.84, 1.37). What is left is
// mostly the particle surface's own noise: the surface the particles seeded next to the probe
// give sits 0.02-0.03 dx out after the seeding's mean bulge is taken off (seededFaceBulge;
// erosion by a further 0.035 dx gave 1.61% -> 0.39%). Sub-samples read the same films 1.39% ->
// 0.39%, 1.35% -> 2.16%, 1.62% -> 2.15%: right on a grid line, not converging off it. Before the
// touched air faces' clamped mass was lent by their liquid neighbours (faceMassWeights) the film
// was first order (2.84% -> 1.49% on the grid line).
TEST_F(WallTest, FilmDrainingDownVerticalWallConvergesWhereverItsSurfaceSits) {
  for (double h : {0.05, 0.0535, 0.055}) {
    const std::string name = "film on wall, h = " + std::to_string(h);
    const std::vector<double> e = convergenceInCells(name.c_str(), filmOnVerticalWall(h), {4, 8}, 14);
    EXPECT_LT(e[0], 0.025) << name;
    EXPECT_LT(e[1], 0.008) << name;
    EXPECT_GT(order(e, 1), 1.3) << name;
  }
}

}  // namespace
