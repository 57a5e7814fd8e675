// The clamped viscous beam (scenes/beam.json, uniform model) against beam theory under grid
// refinement. From rest the beam's bending mode reaches steady creeping flow in
// rho A L^4 / (3 mu I 12.36) = 0.034 s; by t = 0.16 s the mean vertical speed of its particles is
// the viscous cantilever's: Euler-Bernoulli with E = 3 mu plus Timoshenko shear with G = mu,
// kappa = 5/6, under its weight q = rho g A,
//     mean deflection rate  q L^4 / (20 E I) + q L^2 / (3 kappa G A).
// (tests/sim/test_simulator.cpp checks res 32 within 15%.) Runs each resolution, prints the ratio to
// the theory, and from three successive resolutions the observed order of the discretisation
// error and the Richardson limit, which shows how much of the gap is the grid's and how much the
// theory's (a short, thick beam: L / h = 3.6).
//
//   cantilever [--res 32,64,96] [--steps 8] [--dt 0.02] [--form spd|pv] [--tol 1e-6]
//              [--liquid-weights plane-cut|subsample]   (default: the engine's rule, plane cuts)
#include "sparse_grid/vdb_trees.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "sim/scene/scene.h"
#include "sim/step/simulator.h"
#include "solver/krylov/stopwatch.h"

using namespace stokes::sim;

namespace {

struct Options {
  std::vector<int> resolutions{32, 64, 96};  // the beam's faces lie on grid lines
  int steps = 8;
  double dt = 0.02;
  std::string form = "spd";
  double tolerance = 0.0;  ///< 0: the scene's
  stokes::sparse_grid::FractionRule liquidWeights = stokes::sparse_grid::kLiquidFractionRule;
};

Options parse(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) throw std::invalid_argument("cantilever: " + a + " needs a value");
      return argv[++i];
    };
    if (a == "--res") {
      o.resolutions.clear();
      std::stringstream list(value());
      for (std::string r; std::getline(list, r, ',');) o.resolutions.push_back(std::stoi(r));
    } else if (a == "--steps") o.steps = std::stoi(value());
    else if (a == "--dt") o.dt = std::stod(value());
    else if (a == "--form") o.form = value();
    else if (a == "--tol") o.tolerance = std::stod(value());
    else if (a == "--liquid-weights") {
      const std::string name = value();
      const auto rule = stokes::sparse_grid::fractionRuleNamed(name);
      if (!rule) throw std::invalid_argument("cantilever: --liquid-weights must be subsample or plane-cut, not " + name);
      o.liquidWeights = *rule;
    }
    else throw std::invalid_argument("cantilever: unknown option " + a);
  }
  if (o.form != "spd" && o.form != "pv") throw std::invalid_argument("cantilever: --form must be spd or pv, not " + o.form);
  if (o.resolutions.empty()) throw std::invalid_argument("cantilever: --res needs at least one resolution");
  return o;
}

}  // namespace

int main(int argc, char** argv) try {
  openvdb::initialize();
  const Options o = parse(argc, argv);
  std::printf("res,dx,cells_thick,mean_vy,theory,ratio,iterations_last_step,seconds\n");
  std::vector<double> speeds, spacings;
  double expected = 0.0;
  for (int res : o.resolutions) {
    SceneOverrides over;
    over.resolution = res;
    Scene scene = loadScene(std::string(STOKES_SOURCE_DIR) + "/scenes/beam.json", over);
    scene.model.type = ModelType::Uniform;
    scene.solver.preconditioner = o.form == "pv" ? stokes::solver::PreconditionerKind::Multigrid : stokes::solver::PreconditionerKind::Jacobi;
    if (o.tolerance > 0.0) scene.solver.tolerance = o.tolerance;
    scene.liquidWeights = o.liquidWeights;
    scene.solver.maxIterations = 200000;
    const double mu = scene.material.viscosity, rho = scene.material.density, g = 9.81;
    const double L = 1.2 - 0.3, h = 0.25, A = h * h, I = h * h * h * h / 12.0, q = rho * g * A;
    expected = q * std::pow(L, 4) / (20.0 * 3.0 * mu * I) + q * L * L / (3.0 * (5.0 / 6.0) * mu * A);
    const auto t0 = std::chrono::steady_clock::now();
    Simulator sim(scene);
    StepStats s;
    for (int i = 0; i < o.steps; ++i) s = sim.step(o.dt, 1);
    const double seconds = stokes::solver::secondsSince(t0);
    const double v = -s.meanVelocity[1], dx = sim.domain().dx;
    std::printf("%d,%.5f,%.2f,%.5f,%.5f,%.4f,%d,%.1f\n", res, dx, h / dx, v, expected, v / expected, s.grid.iterations,
                seconds);
    std::fflush(stdout);
    speeds.push_back(v);
    spacings.push_back(dx);
  }
  for (std::size_t i = 2; i < speeds.size(); ++i) {
    // v(dx) = v* + C dx^p through three points (the spacings need not be in a fixed ratio):
    // solve (v1 - v2) / (v2 - v3) = (dx1^p - dx2^p) / (dx2^p - dx3^p) for p by bisection.
    const double d12 = speeds[i - 2] - speeds[i - 1], d23 = speeds[i - 1] - speeds[i];
    const double h1 = spacings[i - 2], h2 = spacings[i - 1], h3 = spacings[i];
    auto f = [&](double p) {
      return (std::pow(h1, p) - std::pow(h2, p)) / (std::pow(h2, p) - std::pow(h3, p)) - d12 / d23;
    };
    if (!(d12 / d23 > 0.0)) {
      std::printf("# res %.0f..%.0f: not monotone (differences %.3g, %.3g): no order\n", 0.0 + o.resolutions[i - 2],
                  0.0 + o.resolutions[i], d12, d23);
      continue;
    }
    double lo = 0.05, hi = 6.0;
    if (f(lo) * f(hi) > 0.0) {
      std::printf("# res %d..%d: order outside [0.05, 6]\n", o.resolutions[i - 2], o.resolutions[i]);
      continue;
    }
    for (int k = 0; k < 100; ++k) {
      const double mid = 0.5 * (lo + hi);
      (f(lo) * f(mid) <= 0.0 ? hi : lo) = mid;
    }
    const double p = 0.5 * (lo + hi);
    const double c = d23 / (std::pow(h2, p) - std::pow(h3, p));
    const double limit = speeds[i] - c * std::pow(h3, p);
    std::printf("# res %d..%d: observed order %.2f, Richardson limit %.5f m/s = %.4f of the theory\n",
                o.resolutions[i - 2], o.resolutions[i], p, limit, limit / expected);
  }
  return 0;
} catch (const std::exception& e) {
  std::fprintf(stderr, "%s\n", e.what());
  return 1;
}
