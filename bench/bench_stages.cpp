// The non-solver stages of a simulation step, each on its own, on the particles
// of a real scene at its first step:
//   BM_LevelSet      liquid level set from the particles (sim::liquidLevelSetFromParticles)
//   BM_ParticleSurface  its level set alone (sim::liquidLevelSetFromParticles, no volume match), third
//                    argument the deep interior margin: -1 = the whole union of spheres, 3 = the default
//   BM_SphereRaster  its first part, the union of the particles' spheres (sim/geometry/sphere_raster.h),
//                    third argument the deep margin as above (-1: OpenVDB's bits);
//   BM_OpenVdbParticleRaster  the same bits from openvdb::tools::ParticlesToLevelSet
//   BM_LiquidVolume  the clipped and unclipped volumes of that level set (the step's report)
//   BM_GridWeights   the step's layout and volume weights (sim::GridStep's constructor)
//   BM_PhiSamples    27 trilinear samples of the level set around every particle (the weights'
//                    sub-sample pattern): third argument 0 = openvdb::tools::BoxSampler through one
//                    accessor per thread, 1 = sim::GridPhi (the same bits)
//   BM_P2G           APIC particle-to-grid (sim::particlesToGrid on the active cells, as a step runs it)
//   BM_G2P           APIC grid-to-particle (sim::gridToParticles), on the P2G velocities
//   BM_Advect        RK2 advection of the particles through those velocities (positions restored)
// Cases (first argument): 0 = the armadillos (scenes/armadillos.json), 1 = a ball of radius
// 0.3 in the unit box (uniform liquid); second argument: the resolution. Counters: particles,
// cells (active cells of the layout), slots (cells of its 8^3 blocks), ns_per_particle and ns_per_cell (wall time of one call over
// each). Threads: OMP_NUM_THREADS (OpenVDB's own TBB tools take every core regardless).
#include <benchmark/benchmark.h>
#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/ParticlesToLevelSet.h>

#include <chrono>
#include <map>
#include <memory>
#include <string>
#include <utility>

#include "sim/particles/advection.h"
#include "sim/particles/apic_transfer.h"
#include "sim/step/simulator.h"
#include "sim/geometry/sphere_raster.h"
#include "sim/step/stokes_stage.h"
#include "solver/krylov/stopwatch.h"

namespace stokes::bench {
namespace {

using sim::kSimDim;

/// The scene's particles at its start, its first step's level set and grid.
struct StageCase {
  sim::Scene scene;
  std::unique_ptr<sim::Simulator> simulator;
  openvdb::FloatGrid::Ptr liquid;
  std::unique_ptr<sim::GridStep> grid;
  double dt = 0.0;

  StageCase(int which, int resolution) {
    if (which == 0) {
      scene = sim::loadScene(std::string(STOKES_SOURCE_DIR) + "/scenes/armadillos.json",
                             sim::SceneOverrides{resolution, 1});
    } else {
      scene = sim::parseSceneText(
          R"({"name": "ball", "domain": {"min": [0, 0, 0], "max": [1, 1, 1]}, "resolution": )" +
              std::to_string(resolution) +
              R"(, "frames": 1, "material": {"density": 1000, "viscosity": 10},
                 "liquid": [{"shape": "sphere", "center": [0.5, 0.5, 0.5], "radius": 0.3}]})",
          "ball.json", ".");
    }
    simulator = std::make_unique<sim::Simulator>(scene);
    liquid = simulator->liquidLevelSet();
    dt = 0.5 * scene.dx();  // 0.5 cell per step at 1 m/s
    grid = std::make_unique<sim::GridStep>(simulator->particles().x, *liquid, nullptr, simulator->domain(), scene, dt,
                                           true, sim::layoutBand(scene));
  }
  const sim::ParticleSet<kSimDim>& particles() const { return simulator->particles(); }
  double cells() const { return double(grid->report().cells); }
};

class CaseLibrary {
 public:
  StageCase& get(int which, int resolution) {
    auto& slot = cases_[{which, resolution}];
    if (!slot) slot = std::make_unique<StageCase>(which, resolution);
    return *slot;
  }

 private:
  std::map<std::pair<int, int>, std::unique_ptr<StageCase>> cases_;
};

CaseLibrary& library() {
  static CaseLibrary cases;
  return cases;
}

/// Runs `body` once per benchmark iteration, timing it by hand (set-up inside the loop excluded).
/// `prepare` runs before each timed call, untimed.
template <class Prepare, class Body>
void timedLoop(benchmark::State& state, const StageCase& c, Prepare&& prepare, Body&& body) {
  double seconds = 0.0;
  for (auto _ : state) {
    prepare();
    const auto t0 = std::chrono::steady_clock::now();
    body();
    const double t = solver::secondsSince(t0);
    state.SetIterationTime(t);
    seconds += t;
  }
  const double perCall = 1e9 * seconds / double(state.iterations());
  state.counters["particles"] = double(c.particles().size());
  state.counters["cells"] = c.cells();
  state.counters["slots"] = double(c.grid->layout().numSlots());
  state.counters["ns_per_particle"] = perCall / double(c.particles().size());
  state.counters["ns_per_cell"] = perCall / c.cells();
}

template <class Body>
void timedLoop(benchmark::State& state, const StageCase& c, Body&& body) {
  timedLoop(state, c, [] {}, std::forward<Body>(body));
}

void BM_LevelSet(benchmark::State& state) {
  StageCase& c = library().get(int(state.range(0)), int(state.range(1)));
  timedLoop(state, c, [&] { benchmark::DoNotOptimize(c.simulator->liquidLevelSet()); });
}

/// The level set from the particles with the simulator's settings, whole union (deep = -1) or with
/// the deep interior left out (the default, 3): the raster and the filters' share of BM_LevelSet.
void BM_ParticleSurface(benchmark::State& state) {
  StageCase& c = library().get(int(state.range(0)), int(state.range(1)));
  sim::ParticleSurfaceOptions surface;
  surface.particleSpacingInCells = 1.0 / c.scene.particlesPerCellAxis;
  surface.deepInteriorMargin = int(state.range(2));
  timedLoop(state, c, [&] {
    benchmark::DoNotOptimize(sim::liquidLevelSetFromParticles(c.particles().x, c.scene.dx(), 1.0, 3.0, surface));
  });
}

/// An empty level set with the liquid's voxels and half width (3 cells), for the rasters.
openvdb::FloatGrid::Ptr emptyLiquidGrid(double dx) {
  auto grid = openvdb::FloatGrid::create(float(3.0 * dx));
  grid->setTransform(sim::cellCentredTransform(dx));
  return grid;
}

/// The sphere-union raster alone, ours (sim/geometry/sphere_raster.h) and OpenVDB's ParticlesToLevelSet,
/// which writes the same bits (radius 1 cell, half width 3, as liquidLevelSetFromParticles).
void BM_SphereRaster(benchmark::State& state) {
  StageCase& c = library().get(int(state.range(0)), int(state.range(1)));
  timedLoop(state, c, [&] {
    auto grid = emptyLiquidGrid(c.scene.dx());
    sim::rasterizeSphereUnion(*grid, c.particles().x, c.scene.dx(), int(state.range(2)));
    benchmark::DoNotOptimize(grid);
  });
}

void BM_OpenVdbParticleRaster(benchmark::State& state) {
  StageCase& c = library().get(int(state.range(0)), int(state.range(1)));
  const double dx = c.scene.dx();
  timedLoop(state, c, [&] {
    auto grid = emptyLiquidGrid(dx);
    openvdb::tools::ParticlesToLevelSet<openvdb::FloatGrid> raster(*grid);
    raster.setRmin(0.0);
    raster.rasterizeSpheres(sim::ParticlePositionList(c.particles().x), dx);
    raster.finalize(/*prune=*/true);
    benchmark::DoNotOptimize(grid);
  });
}

void BM_LiquidVolume(benchmark::State& state) {
  StageCase& c = library().get(int(state.range(0)), int(state.range(1)));
  timedLoop(state, c, [&] {
    benchmark::DoNotOptimize(c.simulator->liquidVolume(*c.liquid));
    benchmark::DoNotOptimize(sim::levelSetVolume(*c.liquid));
  });
}

void BM_GridWeights(benchmark::State& state) {
  StageCase& c = library().get(int(state.range(0)), int(state.range(1)));
  timedLoop(state, c, [&] {
    benchmark::DoNotOptimize(sim::GridStep(c.particles().x, *c.liquid, nullptr, c.simulator->domain(), c.scene, c.dt,
                                           true, sim::layoutBand(c.scene)));
  });
}

void BM_PhiSamples(benchmark::State& state) {
  StageCase& c = library().get(int(state.range(0)), int(state.range(1)));
  const bool gridPhi = state.range(2) == 1;
  const sim::GridPhi phi(c.liquid);
  const auto& x = c.particles().x;
  const double h = c.scene.dx() / 3.0;
  timedLoop(state, c, [&] {
    double sum = 0.0;
#pragma omp parallel reduction(+ : sum)
    {
      auto acc = c.liquid->getConstUnsafeAccessor();
      const auto& xform = c.liquid->transform();
#pragma omp for schedule(static)
      for (std::ptrdiff_t i = 0; i < std::ptrdiff_t(x.size()); ++i)
        for (int k = 0; k < 27; ++k) {
          const sim::Vec3d p = x[std::size_t(i)] + h * sim::Vec3d(k % 3 - 1, (k / 3) % 3 - 1, k / 9 - 1);
          sum += gridPhi ? phi(p) : double(openvdb::tools::BoxSampler::sample(acc, xform.worldToIndex(p)));
        }
    }
    benchmark::DoNotOptimize(sum);
  });
}

void BM_P2G(benchmark::State& state) {
  StageCase& c = library().get(int(state.range(0)), int(state.range(1)));
  solver::Vector u, mass;
  timedLoop(state, c, [&] {
    sim::particlesToGrid<kSimDim>(c.grid->layout(), c.particles(), u, mass, sparse_grid::SlotsToFill::ActiveCells);
  });
}

/// The P2G velocities of a case and a copy of its particles, for the stages after the solve.
struct AfterSolve {
  solver::Vector u, mass;
  sim::ParticleSet<kSimDim> particles;
  sim::BoxWalls walls;
  explicit AfterSolve(const StageCase& c) : particles(c.particles()), walls(c.simulator->domain().walls()) {
    sim::particlesToGrid<kSimDim>(c.grid->layout(), c.particles(), u, mass);
  }
};

void BM_G2P(benchmark::State& state) {
  StageCase& c = library().get(int(state.range(0)), int(state.range(1)));
  AfterSolve s(c);
  timedLoop(state, c, [&] { sim::gridToParticles<kSimDim>(c.grid->layout(), s.u, s.particles, &s.walls); });
}

void BM_Advect(benchmark::State& state) {
  StageCase& c = library().get(int(state.range(0)), int(state.range(1)));
  AfterSolve s(c);
  timedLoop(
      state, c, [&] { s.particles.x = c.particles().x; },
      [&] { sim::advectRK2<kSimDim>(c.grid->layout(), s.u, s.particles, c.dt, &s.walls); });
}

void stageArgs(benchmark::internal::Benchmark* b) {
  b->ArgNames({"case", "res"})->Args({0, 128})->Args({0, 256})->Args({1, 64})->Args({1, 128});
  b->Unit(benchmark::kMillisecond)->UseManualTime()->MinTime(1.0);
}

// The ball at res 256 too (15.2 M particles, 4.1 GB peak with the smaller cases): the level set's cost per
// particle as the liquid gets bulkier.
BENCHMARK(BM_LevelSet)->Apply(stageArgs)->Args({1, 256});
void deepArgs(benchmark::internal::Benchmark* b) {
  b->ArgNames({"case", "res", "deep"})->ArgsProduct({{0}, {128, 256}, {-1, 3}})->ArgsProduct({{1}, {64, 128, 256}, {-1, 3}});
  b->Unit(benchmark::kMillisecond)->UseManualTime()->MinTime(1.0);
}
BENCHMARK(BM_ParticleSurface)->Apply(deepArgs);
BENCHMARK(BM_SphereRaster)->Apply(deepArgs);
BENCHMARK(BM_OpenVdbParticleRaster)->Apply(stageArgs);
BENCHMARK(BM_LiquidVolume)->Apply(stageArgs);
BENCHMARK(BM_GridWeights)->Apply(stageArgs);
BENCHMARK(BM_PhiSamples)->ArgNames({"case", "res", "gridphi"})->ArgsProduct({{0}, {128, 256}, {0, 1}})->Unit(benchmark::kMillisecond)->UseManualTime()->MinTime(0.5);
BENCHMARK(BM_P2G)->Apply(stageArgs);
BENCHMARK(BM_G2P)->Apply(stageArgs);
BENCHMARK(BM_Advect)->Apply(stageArgs);

}  // namespace
}  // namespace stokes::bench

BENCHMARK_MAIN();
