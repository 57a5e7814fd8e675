// A viscous film spreading on a no-slip floor against the axisymmetric viscous gravity current of
// Huppert (1982, J. Fluid Mech. 121, "The propagation of two-dimensional and axisymmetric viscous
// gravity currents over a rigid horizontal surface"): a fixed volume V of liquid of kinematic
// viscosity nu spreads as
//     r_N(t) = 0.894 (g V^3 t / (3 nu))^(1/8)
// once the film is thin (lubrication) and the release has been forgotten. The scene is
// scenes/film_spreading.json; the footprint radius is that of the area the liquid level set covers
// half a cell above the floor, sampled at dx/4: r = sqrt(A / pi).
//
//   film_spreading [--res N] [--viscosity coupled|decoupled] [--t-end T] [--fit-from T0] [--csv FILE]
//
// Prints, per frame: t, r, r_N, r / r_N, the liquid volume relative to its start, steps and
// seconds; then the mean and range of r / r_N over [fit-from, t-end] and the growth exponent
// (least squares of log r on log t there; the theory's is 1/8).
#include "sparse_grid/vdb_trees.h"
#include <openvdb/tools/Interpolation.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "sim/scene/scene.h"
#include "sim/step/simulator.h"
#include "solver/krylov/stopwatch.h"

using namespace stokes::sim;

namespace {

/// Area the level set covers on the plane y = height (phi < 0), sampled on a square lattice of
/// spacing h over the domain's x-z extent.
double footprintArea(const openvdb::FloatGrid& liquid, const DomainBox& domain, double height, double h) {
  const openvdb::tools::GridSampler<openvdb::FloatGrid, openvdb::tools::BoxSampler> sampler(liquid);
  const int nx = int((domain.max[0] - domain.min[0]) / h), nz = int((domain.max[2] - domain.min[2]) / h);
  long inside = 0;
#pragma omp parallel for reduction(+ : inside) schedule(static)
  for (int i = 0; i < nx; ++i)
    for (int k = 0; k < nz; ++k) {
      const openvdb::Vec3d x(domain.min[0] + (i + 0.5) * h, height, domain.min[2] + (k + 0.5) * h);
      inside += sampler.wsSample(x) < 0.0f ? 1 : 0;
    }
  return double(inside) * h * h;
}

struct Options {
  int resolution = 64;
  std::string viscosity = "coupled";
  double tEnd = 6.0, fitFrom = 2.4;
  std::string csv;
};

Options parse(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) throw std::invalid_argument("film_spreading: " + a + " needs a value");
      return argv[++i];
    };
    if (a == "--res") o.resolution = std::stoi(value());
    else if (a == "--viscosity") o.viscosity = value();
    else if (a == "--t-end") o.tEnd = std::stod(value());
    else if (a == "--fit-from") o.fitFrom = std::stod(value());
    else if (a == "--csv") o.csv = value();
    else throw std::invalid_argument("film_spreading: unknown option " + a);
  }
  if (o.viscosity != "coupled" && o.viscosity != "decoupled")
    throw std::invalid_argument("film_spreading: --viscosity must be coupled or decoupled, not " + o.viscosity);
  return o;
}

}  // namespace

int main(int argc, char** argv) try {
  openvdb::initialize();
  const Options o = parse(argc, argv);
  SceneOverrides over;
  over.resolution = o.resolution;
  Scene scene = loadScene(std::string(STOKES_SOURCE_DIR) + "/scenes/film_spreading.json", over);
  scene.system = parseViscosityMode(o.viscosity);
  const int frames = int(std::lround(o.tEnd * scene.fps));
  Simulator sim(scene);
  const double dx = sim.domain().dx, g = 9.81, nu = scene.material.viscosity / scene.material.density;
  double volume0 = 0.0;
  for (const ShapeDesc& s : scene.liquid) volume0 += 4.0 / 3.0 * std::acos(-1.0) * std::pow(s.radius, 3);
  const double v0 = sim.liquidVolume(*sim.liquidLevelSet());
  std::FILE* csv = o.csv.empty() ? nullptr : std::fopen(o.csv.c_str(), "w");
  if (!o.csv.empty() && !csv) throw std::runtime_error("film_spreading: cannot write " + o.csv);
  const char* header = "t,radius,huppert,ratio,volume_ratio,steps,seconds\n";
  std::printf("# %s, resolution %d (dx = %.4g m), nu = %.4g m^2/s, V = %.5g m^3\n%s", o.viscosity.c_str(),
              o.resolution, dx, nu, volume0, header);
  if (csv) std::fputs(header, csv);
  std::vector<double> logT, logR, ratios;
  const auto start = std::chrono::steady_clock::now();
  for (int f = 1; f <= frames; ++f) {
    sim.advanceFrame(f);
    const openvdb::FloatGrid::Ptr liquid = sim.liquidLevelSet();
    const double t = sim.time(), r = std::sqrt(footprintArea(*liquid, sim.domain(), 0.5 * dx, 0.25 * dx) / std::acos(-1.0));
    const double rN = 0.894 * std::pow(g * volume0 * volume0 * volume0 * t / (3.0 * nu), 0.125);
    const double seconds = stokes::solver::secondsSince(start);
    char line[256];
    std::snprintf(line, sizeof line, "%.4f,%.5f,%.5f,%.4f,%.4f,%d,%.1f\n", t, r, rN, r / rN,
                  sim.liquidVolume(*liquid) / v0, sim.stepsTaken(), seconds);
    std::fputs(line, stdout);
    std::fflush(stdout);
    if (csv) std::fputs(line, csv);
    if (t >= o.fitFrom - 1e-9) {
      logT.push_back(std::log(t));
      logR.push_back(std::log(r));
      ratios.push_back(r / rN);
    }
  }
  if (csv) std::fclose(csv);
  if (logT.size() >= 2) {
    double mt = 0, mr = 0;
    for (std::size_t i = 0; i < logT.size(); ++i) mt += logT[i], mr += logR[i];
    mt /= logT.size();
    mr /= logT.size();
    double stt = 0, str = 0, lo = 1e9, hi = -1e9, mean = 0;
    for (std::size_t i = 0; i < logT.size(); ++i) {
      stt += (logT[i] - mt) * (logT[i] - mt);
      str += (logT[i] - mt) * (logR[i] - mr);
      lo = std::min(lo, ratios[i]);
      hi = std::max(hi, ratios[i]);
      mean += ratios[i] / ratios.size();
    }
    std::printf("# r / r_N over t in [%.2f, %.2f]: mean %.4f, from %.4f to %.4f; growth exponent %.4f (theory 0.125)\n",
                o.fitFrom, o.tEnd, mean, lo, hi, str / stt);
  }
  return 0;
} catch (const std::exception& e) {
  std::fprintf(stderr, "%s\n", e.what());
  return 1;
}
