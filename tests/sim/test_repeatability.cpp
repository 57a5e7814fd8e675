// One answer on every run: a scene gives the same bits on every repeat and for any
// thread count, also while another process competes for the cores. A tiled scene step is the
// hardest case: before, the tile library kept the blocks of whichever tile of a shape finished
// first (computed from that tile's world coordinates, in its slot order), so the beam's first
// solve took 5,130 or 5,225 iterations depending on thread timing.
#include <gtest/gtest.h>
#include <omp.h>
#include "sparse_grid/vdb_trees.h"

#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include "sim/scene/scene.h"
#include "sim/step/simulator.h"
#include "tests/parallel_path.h"

namespace {

using namespace stokes::sim;
using Region = stokes::parallel::Region;

const std::filesystem::path kScenes = std::filesystem::path(STOKES_SOURCE_DIR) / "scenes";

/// A block of liquid falling onto a solid ledge in a closed box, quadratic tiles of 8 cells (many
/// cube tiles share one shape, so the library is hit from several threads at once), Jacobi CG.
Scene tiledScene() {
  const std::string text = R"({"name": "repeat", "domain": {"min": [0.013, 0, 0], "max": [0.223, 0.21, 0.21]},
    "resolution": 32, "frames": 1, "fps": 24,
    "material": {"density": 1000, "viscosity": 50}, "gravity": [0, -9.81, 0], "viscosity": "coupled",
    "model": {"type": "quadratic", "tile": 6, "padding": 2, "band_air": 2, "band_solid": 2, "min_region": 2},
    "solver": {"tolerance": 1e-6, "preconditioner": "jacobi"},
    "liquid": [{"shape": "box", "min": [0.013, 0.0, 0.0], "max": [0.223, 0.13, 0.21]}],
    "solids": [{"shape": "box", "min": [0.013, 0.0, 0.0], "max": [0.08, 0.041, 0.21]}],
    "output": {"preview": false}, "seed": 7})";
  return parseSceneText(text, "repeat.json", kScenes.string());
}

/// FNV-1a over bytes.
std::uint64_t fnv(const void* data, std::size_t bytes, std::uint64_t h = 1469598103934665603ull) {
  const auto* p = static_cast<const unsigned char*>(data);
  for (std::size_t i = 0; i < bytes; ++i) h = (h ^ p[i]) * 1099511628211ull;
  return h;
}

/// What a run must reproduce: per step the iterations, tiles, kinetic energy and volume, and at
/// the end every particle's x, v and c.
struct RunRecord {
  std::vector<int> iterations;
  std::vector<std::size_t> tiles;
  std::vector<double> kineticEnergy, liquidVolume;
  std::uint64_t particles = 0;
};

RunRecord runSteps(int threads, int steps) {
  omp_set_num_threads(threads);
  Simulator sim(tiledScene());
  RunRecord r;
  for (int i = 0; i < steps; ++i) {
    const StepStats s = sim.step(0.004, 1);
    r.iterations.push_back(s.grid.iterations);
    r.tiles.push_back(s.grid.tiles);
    r.kineticEnergy.push_back(s.kineticEnergy);
    r.liquidVolume.push_back(s.liquidVolume);
  }
  const auto& p = sim.particles();
  r.particles = fnv(p.x.data(), p.x.size() * sizeof(p.x[0]));
  r.particles = fnv(p.v.data(), p.v.size() * sizeof(p.v[0]), r.particles);
  r.particles = fnv(p.c.data(), p.c.size() * sizeof(p.c[0]), r.particles);
  return r;
}

void expectSameRun(const RunRecord& a, const RunRecord& b, const char* what) {
  EXPECT_EQ(a.iterations, b.iterations) << what;
  EXPECT_EQ(a.tiles, b.tiles) << what;
  ASSERT_EQ(a.kineticEnergy.size(), b.kineticEnergy.size());
  for (std::size_t i = 0; i < a.kineticEnergy.size(); ++i) {
    EXPECT_EQ(std::memcmp(&a.kineticEnergy[i], &b.kineticEnergy[i], sizeof(double)), 0)
        << what << ", step " << i << ": " << a.kineticEnergy[i] << " vs " << b.kineticEnergy[i];
    EXPECT_EQ(std::memcmp(&a.liquidVolume[i], &b.liquidVolume[i], sizeof(double)), 0) << what << ", step " << i;
  }
  EXPECT_EQ(a.particles, b.particles) << what << ": the particles differ";
}

/// Busy threads that take the cores in short bursts while they run, so that OpenMP threads are
/// descheduled at arbitrary points (the timing a shared machine gives).
class ConcurrentLoad {
 public:
  explicit ConcurrentLoad(int threads) {
    for (int t = 0; t < threads; ++t)
      workers_.emplace_back([this, t] {
        volatile double x = 1.0 + t;
        while (!stop_.load(std::memory_order_relaxed)) {
          for (int i = 0; i < 200000; ++i) x = x * 1.0000001 + 1e-9;
          std::this_thread::yield();
        }
      });
  }
  ~ConcurrentLoad() {
    stop_ = true;
    for (auto& w : workers_) w.join();
  }

 private:
  std::atomic<bool> stop_{false};
  std::vector<std::thread> workers_;
};

class Repeatability : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { openvdb::initialize(); }
  void TearDown() override { omp_set_num_threads(saved_); }
  int saved_ = omp_get_max_threads();
};

TEST_F(Repeatability, TiledSceneIsBitIdenticalAcrossRepeatsLoadAndThreads) {
  constexpr int kSteps = 3;
  const RunRecord one = runSteps(1, kSteps);
  ASSERT_GT(one.tiles.front(), 1u) << "the scene must have tiles";
  const stokes::test::TeamCount split;
  const RunRecord two = runSteps(2, kSteps);
  // the scene's own sizes take the parallel paths (the solve's ~20k liquid cells are above the
  // one-thread limit of small steps): reductions, stencils, tiles and P2G on two threads
  for (const auto kind : {Region::Reduction, Region::GridLoop, Region::Tiles, Region::ParticleScatter})
    EXPECT_GT(split(kind), 0u) << "region kind " << int(kind) << " never ran on two threads";
  expectSameRun(one, two, "2 threads against 1");
  const RunRecord again = runSteps(2, kSteps);
  expectSameRun(two, again, "2 threads, repeated");
  RunRecord loaded;
  {
    ConcurrentLoad load(2);
    loaded = runSteps(2, kSteps);
  }
  expectSameRun(two, loaded, "2 threads under a concurrent load");
  std::printf("[repeat] %zu tiles, iterations", one.tiles.front());
  for (int it : one.iterations) std::printf(" %d", it);
  std::printf(", particles %016llx on every run\n", static_cast<unsigned long long>(one.particles));
}

}  // namespace
