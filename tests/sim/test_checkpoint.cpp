// Runs that survive faults (sim/run/checkpoint.h, sim/run/scene_runner.h, Simulator::advanceFrame):
// checkpoint files that round-trip every bit and refuse damaged copies, a resumed run whose
// frames and particles are bit for bit those of an uninterrupted one (in-process stop, SIGTERM
// and SIGKILL of the real `stokesvdb run`), and failed steps retried at smaller dt.
#include <gtest/gtest.h>
#include "sparse_grid/vdb_trees.h"
#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "sim/run/checkpoint.h"
#include "sim/output/stats_csv.h"
#include "sim/output/vdb_frame.h"
#include "sim/scene/scene.h"
#include "sim/run/scene_runner.h"
#include "sim/step/simulator.h"

extern char** environ;

namespace fs = std::filesystem;
using namespace stokes::sim;

namespace {

class CheckpointTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { openvdb::initialize(); }
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("stokes_ckpt_" + std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

/// A viscous ball falling onto the floor of a 20 cm box at 16 cells: a few steps per frame, a
/// warm-started solve, reseeding and the volume control all carry state from step to step.
std::string ballSceneText(int frames, int maxIterations = 2000, int retries = 3, double mu = 10.0,
                          const std::string& preconditioner = "auto") {
  return R"({"name": "ckpt", "domain": {"min": [0, 0, 0], "max": [0.2, 0.2, 0.2]},
    "resolution": 16, "frames": )" + std::to_string(frames) + R"(, "fps": 24,
    "material": {"density": 1000, "viscosity": )" + std::to_string(mu) + R"(},
    "gravity": [0, -9.81, 0], "viscosity": "coupled",
    "solver": {"max_iterations": )" + std::to_string(maxIterations) + R"(, "retries": )" + std::to_string(retries) +
         R"(, "preconditioner": ")" + preconditioner + R"("},
    "liquid": [{"shape": "sphere", "center": [0.1, 0.07, 0.1], "radius": 0.05}],
    "output": {"preview": false, "particles": true}})";
}

Scene ballScene(int frames, int maxIterations = 2000, int retries = 3, double mu = 10.0,
                const std::string& preconditioner = "auto") {
  return parseSceneText(ballSceneText(frames, maxIterations, retries, mu, preconditioner), "ckpt.json", ".");
}

template <class V>
bool sameBits(const V& a, const V& b) {
  return a.size() == b.size() &&
         (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(typename V::value_type)) == 0);
}

bool sameParticles(const ParticleSet<3>& a, const ParticleSet<3>& b) {
  return sameBits(a.x, b.x) && sameBits(a.v, b.v) && sameBits(a.c, b.c);
}

/// The coil measure's carried state, field by field, bit for bit (NaN before the first contact).
bool sameCoil(const CoilMeasure::State& a, const CoilMeasure::State& b) {
  return std::memcmp(&a.swept, &b.swept, sizeof a.swept) == 0 &&
         std::memcmp(&a.lastAngle, &b.lastAngle, sizeof a.lastAngle) == 0 &&
         std::memcmp(&a.radius, &b.radius, sizeof a.radius) == 0 && a.contact == b.contact;
}

/// Every voxel and tile of two liquid level sets: active state and value bits.
::testing::AssertionResult sameLevelSet(const fs::path& a, const fs::path& b) {
  const openvdb::FloatGrid::Ptr ga = readLiquidGrid(a.string()), gb = readLiquidGrid(b.string());
  if (ga->activeVoxelCount() != gb->activeVoxelCount() || !ga->tree().hasSameTopology(gb->tree()))
    return ::testing::AssertionFailure() << a << " and " << b << " differ in topology";
  auto acc = gb->getConstAccessor();
  for (auto it = ga->tree().cbeginValueAll(); it; ++it) {
    const float va = *it, vb = acc.getValue(it.getCoord());
    if (std::memcmp(&va, &vb, sizeof va) != 0 || it.isValueOn() != acc.isValueOn(it.getCoord()))
      return ::testing::AssertionFailure() << a << " and " << b << " differ at " << it.getCoord();
  }
  return ::testing::AssertionSuccess();
}

/// stats.csv without its wall-time columns (*_s), one string per row.
std::vector<std::string> statsWithoutTimes(const fs::path& dir) {
  std::ifstream in(dir / "stats.csv");
  std::string line;
  std::getline(in, line);
  std::vector<bool> timing;
  std::stringstream header(line);
  for (std::string name; std::getline(header, name, ',');)
    timing.push_back(name.size() > 2 && name.compare(name.size() - 2, 2, "_s") == 0);
  std::vector<std::string> rows;
  while (std::getline(in, line)) {
    std::string kept, field;
    std::stringstream fields(line);
    for (std::size_t c = 0; std::getline(fields, field, ','); ++c)
      if (c >= timing.size() || !timing[c]) kept += field + ",";
    rows.push_back(kept);
  }
  return rows;
}

void expectSameRun(const fs::path& a, const fs::path& b, int frames) {
  for (int f = 0; f <= frames; ++f) {
    char name[32];
    std::snprintf(name, sizeof name, "frame_%04d.vdb", f);
    EXPECT_TRUE(sameLevelSet(a / name, b / name)) << name;
  }
  EXPECT_EQ(statsWithoutTimes(a), statsWithoutTimes(b));
  const auto ca = findNewestCheckpoint(a.string()), cb = findNewestCheckpoint(b.string());
  ASSERT_TRUE(ca && cb);
  EXPECT_EQ(ca->second.state.steps, cb->second.state.steps);
  EXPECT_TRUE(sameParticles(ca->second.state.particles, cb->second.state.particles));
}

}  // namespace

// Every field of a checkpoint comes back bit for bit, including NaN payloads and the warm start.
TEST_F(CheckpointTest, FileRoundTripsEveryBit) {
  RunCheckpoint c;
  c.signature = std::string("scene text\nwith \0 a nul", 24);
  c.progress = {7, 0.125, 321};
  std::mt19937_64 rng(3);
  std::normal_distribution<double> n(0.0, 1.0);
  c.state.time = 0.291666;
  c.state.lastDt = 1.0 / 3.0;
  c.state.volumeTarget = 5.2e-4;
  c.state.steps = 57;
  c.state.frame = 8;
  c.state.frameSubsteps = 2;
  c.state.retryDtLimit = 0.004;
  for (int p = 0; p < 1000; ++p) {
    ParticleSet<3>::Affine a;
    for (auto& v : a) v = Vec3d(n(rng), n(rng), n(rng));
    c.state.particles.push_back(Vec3d(n(rng), n(rng), n(rng)), Vec3d(n(rng), n(rng), n(rng)), a);
  }
  c.state.particles.v[3] = Vec3d(std::nan("7"), 0.0, -0.0);
  WarmStartState w;
  w.dx = 0.0125;
  w.origin = Vec3d(0.1, 0.2, 0.3);
  w.blockOrigins = {Coord(0, 0, 0), Coord(8, 0, -8)};
  w.activeSlots.assign(2 * 512, 0);
  w.activeSlots[17] = w.activeSlots[600] = 1;
  w.solution.assign(7 * 2 * 512, 0.0);
  for (double& v : w.solution) v = n(rng);
  c.state.warm = w;
  c.state.coil = CoilMeasure::State{-5874.0, 12.5, 0.015, 42};
  c.state.tileHistory.decisions = {{{-8, 0, 16}, 16, 0xfedcba9876543210ull, true}, {{0, 8, 8}, 8, 7, false}};
  c.state.tileHistory.tiles = {3, 0x8000000000000001ull};

  const std::string path = writeCheckpoint(dir_.string(), c);
  EXPECT_FALSE(fs::exists(path + ".tmp"));
  const RunCheckpoint r = readCheckpoint(path);
  EXPECT_EQ(r.signature, c.signature);
  EXPECT_EQ(r.progress.framesWritten, 7);
  EXPECT_EQ(r.progress.initialVolume, 0.125);
  EXPECT_EQ(r.progress.maxIterations, 321);
  EXPECT_EQ(r.state.time, c.state.time);
  EXPECT_EQ(r.state.lastDt, c.state.lastDt);
  EXPECT_EQ(r.state.volumeTarget, c.state.volumeTarget);
  EXPECT_EQ(r.state.steps, 57);
  EXPECT_EQ(r.state.frame, 8);
  EXPECT_EQ(r.state.frameSubsteps, 2);
  EXPECT_EQ(r.state.retryDtLimit, 0.004);
  EXPECT_TRUE(sameParticles(r.state.particles, c.state.particles));
  ASSERT_TRUE(r.state.warm);
  EXPECT_EQ(r.state.warm->dx, w.dx);
  EXPECT_EQ(r.state.warm->origin, w.origin);
  EXPECT_EQ(r.state.warm->blockOrigins, w.blockOrigins);
  EXPECT_EQ(r.state.warm->activeSlots, w.activeSlots);
  EXPECT_TRUE(sameBits(r.state.warm->solution, w.solution));
  ASSERT_TRUE(r.state.coil);
  EXPECT_TRUE(sameCoil(*r.state.coil, *c.state.coil));  // every field the next update reads, bit for bit
  EXPECT_EQ(r.state.coil->swept, -5874.0);
  EXPECT_EQ(r.state.coil->lastAngle, 12.5);
  EXPECT_EQ(r.state.coil->radius, 0.015);
  EXPECT_EQ(r.state.coil->contact, 42u);
  ASSERT_EQ(r.state.tileHistory.decisions.size(), 2u);
  for (std::size_t i = 0; i < 2; ++i) {
    const auto &a = r.state.tileHistory.decisions[i], &b = c.state.tileHistory.decisions[i];
    EXPECT_EQ(a.key(), b.key());
    EXPECT_EQ(a.split, b.split);
  }
  EXPECT_EQ(r.state.tileHistory.tiles, c.state.tileHistory.tiles);
}

// A truncated or altered file is refused with its path and reason; the newest intact one is
// found past it, and only the newest two are kept.
TEST_F(CheckpointTest, DamagedFilesAreRefusedAndSkipped) {
  RunCheckpoint c;
  c.signature = "run";
  c.state.particles.push_back(Vec3d(1.0), Vec3d(2.0));
  for (int step : {10, 20, 30}) {
    c.state.steps = step;
    writeCheckpoint(dir_.string(), c);
  }
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(checkpointFolder(dir_.string()))) files.push_back(e.path());
  ASSERT_EQ(files.size(), 2u);  // step 10 removed
  const fs::path newest = fs::path(checkpointFolder(dir_.string())) / "step_000000030.ckpt";
  ASSERT_TRUE(fs::exists(newest));

  fs::resize_file(newest, fs::file_size(newest) - 5);  // a torn write
  try {
    readCheckpoint(newest.string());
    FAIL() << "expected an error";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("step_000000030.ckpt"), std::string::npos) << e.what();
  }
  std::vector<std::string> notes;
  const auto found = findNewestCheckpoint(dir_.string(), &notes);
  ASSERT_TRUE(found);
  EXPECT_EQ(found->second.state.steps, 20);
  ASSERT_EQ(notes.size(), 1u);

  {  // one flipped byte in the particles
    const fs::path second = found->first;
    std::fstream f(second, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(40);
    char byte = 0;
    f.read(&byte, 1);
    f.seekp(40);
    byte ^= 0x10;
    f.write(&byte, 1);
  }
  EXPECT_FALSE(findNewestCheckpoint(dir_.string()));
  std::ofstream(dir_ / "not_a_checkpoint.ckpt") << "hello";
  EXPECT_THROW(readCheckpoint((dir_ / "not_a_checkpoint.ckpt").string()), std::runtime_error);
}

// stats.csv of a resumed run keeps the rows before the checkpoint's step and appends after them.
TEST_F(CheckpointTest, StatsCsvResumeKeepsRowsBeforeTheStep) {
  const std::string path = (dir_ / "stats.csv").string();
  {
    StatsCsv csv(path, {"frame", "step", "solver", "x"});
    for (int s = 0; s < 6; ++s) csv.row({{"frame", 1.0}, {"step", double(s)}, {"x", 0.5 * s}}, {{"solver", "CG, a"}});
  }
  std::ofstream(path, std::ios::app) << "2,1";  // a row cut short by a kill: step 1 of 12 written
  {
    StatsCsv csv = StatsCsv::resume(path, {"frame", "step", "solver", "x"}, "step", 4.0);
    EXPECT_EQ(csv.rowsWritten(), 4u);
    csv.row({{"frame", 2.0}, {"step", 4.0}, {"x", 9.0}});
  }
  std::ifstream in(path);
  std::vector<std::string> lines;
  for (std::string l; std::getline(in, l);) lines.push_back(l);
  ASSERT_EQ(lines.size(), 6u);
  EXPECT_EQ(lines[4], "1,3,\"CG, a\",1.5");
  EXPECT_EQ(lines[5], "2,4,,9");
  EXPECT_THROW(StatsCsv::resume(path, {"frame", "step", "other"}, "step", 1.0), std::runtime_error);
}

// A run stopped mid-frame (as SIGINT / SIGTERM do) and resumed gives the uninterrupted run's frames,
// statistics and particles bit for bit; so does extending a finished run with more frames.
TEST_F(CheckpointTest, StoppedAndResumedRunIsBitIdentical) {
  const int frames = 5;
  RunOptions whole;
  whole.outDir = (dir_ / "whole").string();
  const RunSummary a = runScene(ballScene(frames), whole);
  ASSERT_EQ(a.frames, frames);
  ASSERT_GE(a.steps, 8);

  RunOptions part;
  part.outDir = (dir_ / "part").string();
  int steps = 0;
  part.onStep = [&](const StepStats&) { ++steps; };
  part.stopRequested = [&] { return steps == a.steps / 2 + 1; };  // a step inside a frame
  const RunSummary stopped = runScene(ballScene(frames), part);
  ASSERT_TRUE(stopped.stopped);
  const auto mid = findNewestCheckpoint(part.outDir);
  ASSERT_TRUE(mid);
  EXPECT_GT(mid->second.state.frameSubsteps, 0);  // the stop fell inside a frame
  part.resume = true;
  part.stopRequested = {};
  const RunSummary resumed = runScene(ballScene(frames), part);
  EXPECT_FALSE(resumed.stopped);
  EXPECT_EQ(resumed.resumedFromStep, stopped.steps);
  EXPECT_EQ(stopped.steps + resumed.steps, a.steps);
  expectSameRun(whole.outDir, part.outDir, frames);

  // extend: 3 frames, then --resume to 5
  RunOptions ext;
  ext.outDir = (dir_ / "extended").string();
  runScene(ballScene(3), ext);
  ext.resume = true;
  runScene(ballScene(frames), ext);
  expectSameRun(whole.outDir, ext.outDir, frames);

  // another scene's checkpoint is refused, naming what differs
  RunOptions other = part;
  other.signature = "res=32";
  EXPECT_THROW(runScene(ballScene(frames), other), ResumeError);
  RunOptions none;
  none.outDir = (dir_ / "empty").string();
  none.resume = true;
  EXPECT_THROW(runScene(ballScene(frames), none), ResumeError);
}

// A stop requested inside a Krylov solve (SolveOptions::stopRequested, polled once per iteration):
// the step is rolled back, not retried and not counted; the checkpoint holds the step before, and
// the resumed run is the uninterrupted one, bit for bit.
TEST_F(CheckpointTest, StopInsideASolveRollsTheStepBackAndResumesBitIdentical) {
  const int frames = 4;
  RunOptions whole;
  whole.outDir = (dir_ / "whole").string();
  const RunSummary a = runScene(ballScene(frames), whole);
  ASSERT_GE(a.steps, 6);

  RunOptions part;
  part.outDir = (dir_ / "part").string();
  int steps = 0, pollsAfter = 0;
  part.onStep = [&](const StepStats& s) {
    ++steps;
    ASSERT_GE(s.grid.iterations, 3);  // so that the third poll after a step falls inside the next solve
  };
  // after step a.steps / 2: one poll between steps (advanceFrame's, or the run's after a frame),
  // then the next solve's first two iterations; the second of those stops it
  part.stopRequested = [&] { return steps == a.steps / 2 && ++pollsAfter == 3; };
  const RunSummary stopped = runScene(ballScene(frames), part);
  ASSERT_TRUE(stopped.stopped);
  EXPECT_EQ(pollsAfter, 3);
  EXPECT_EQ(stopped.steps, a.steps / 2);  // the interrupted step is not counted
  const auto mid = findNewestCheckpoint(part.outDir);
  ASSERT_TRUE(mid);
  EXPECT_EQ(mid->second.state.steps, a.steps / 2);
  part.resume = true;
  part.stopRequested = {};
  const RunSummary resumed = runScene(ballScene(frames), part);
  EXPECT_FALSE(resumed.stopped);
  EXPECT_EQ(stopped.steps + resumed.steps, a.steps);
  expectSameRun(whole.outDir, part.outDir, frames);
}

/// The value of one stats.csv column, per row.
std::vector<double> statsColumn(const fs::path& dir, const std::string& column) {
  std::ifstream in(dir / "stats.csv");
  std::string line, name;
  std::getline(in, line);
  std::stringstream header(line);
  std::size_t index = 0;
  while (std::getline(header, name, ',') && name != column) ++index;
  std::vector<double> values;
  while (std::getline(in, line)) {
    std::stringstream fields(line);
    std::string field;
    for (std::size_t c = 0; c <= index; ++c) std::getline(fields, field, ',');
    values.push_back(std::stod(field));
  }
  return values;
}

// A pool at rest with adaptive quadratic tiles: each step's cubes see the regions of the step
// before, keep their decisions and their tiles (solver/reduced/tile_history.h). A run stopped and
// resumed restores that history from its checkpoint: frames, statistics (the kept tiles among
// them) and particles are the uninterrupted run's, bit for bit.
TEST_F(CheckpointTest, ResumedRunKeepsTheTileHistory) {
  const auto scene = [](int frames) {
    return parseSceneText(R"({"name": "pool", "domain": {"min": [0, 0, 0], "max": [0.2, 0.2, 0.2]},
      "resolution": 24, "frames": )" + std::to_string(frames) + R"(, "fps": 24,
      "material": {"density": 1000, "viscosity": 10}, "gravity": [0, -9.81, 0], "viscosity": "coupled",
      "model": {"type": "quadratic", "tile": 8, "tile_min": 4, "padding": 2, "tile_accuracy": 0.05,
                "tile_rule": "all"},
      "liquid": [{"shape": "box", "min": [0, 0, 0], "max": [0.2, 0.1, 0.2]}],
      "output": {"preview": false, "particles": true}})",
                          "pool.json", ".");
  };
  const int frames = 4;
  RunOptions whole;
  whole.outDir = (dir_ / "whole").string();
  const RunSummary a = runScene(scene(frames), whole);
  ASSERT_GE(a.steps, 4);
  const std::vector<double> tiles = statsColumn(whole.outDir, "tiles"), kept = statsColumn(whole.outDir, "kept_tiles");
  ASSERT_EQ(kept.size(), std::size_t(a.steps));
  EXPECT_GT(tiles.front(), 0.0);
  EXPECT_EQ(kept.front(), 0.0);  // the first step has no previous one
  EXPECT_GT(kept.back(), 0.0);

  RunOptions part;
  part.outDir = (dir_ / "part").string();
  int steps = 0;
  part.onStep = [&](const StepStats&) { ++steps; };
  part.stopRequested = [&] { return steps == a.steps / 2; };
  ASSERT_TRUE(runScene(scene(frames), part).stopped);
  const auto mid = findNewestCheckpoint(part.outDir);
  ASSERT_TRUE(mid);
  EXPECT_FALSE(mid->second.state.tileHistory.tiles.empty());
  part.resume = true;
  part.stopRequested = {};
  runScene(scene(frames), part);
  expectSameRun(whole.outDir, part.outDir, frames);
}

/// A tilted nozzle pouring onto the floor of a 20 cm box at 16 cells (a disc emitter: the
/// simulator keeps a coil measure, sim/step/coil_measure.h).
std::string nozzleSceneText(int frames) {
  return R"({"name": "nozzle", "domain": {"min": [0, 0, 0], "max": [0.2, 0.2, 0.2]},
    "resolution": 16, "frames": )" + std::to_string(frames) + R"(, "fps": 24,
    "material": {"density": 1000, "viscosity": 10}, "gravity": [0, -9.81, 0], "viscosity": "coupled",
    "emitters": [{"shape": "disc", "center": [0.06, 0.08, 0.1], "radius": 0.015, "normal": [0, -1, 0],
                  "velocity": [0.3, -0.3, 0]}],
    "output": {"preview": false, "particles": true}, "seed": 7})";
}

// A run with an emitter carries the coil measure from step to step: its unwrapped angle adds each
// step's increment against the previous step's angle (lastAngle). The nozzle's velocity sets the
// measure's axis at 45 degrees from the vertical; gravity bends the stream below that line, and
// from about 0.1 s (step 7 of 11) its lowest falling particles lie off the axis by more than the
// measure's minimum radius (dx/2), so each step sweeps an angle. A run stopped after the first step
// that swept one (mid-frame: its checkpoint holds a finite lastAngle and a swept angle) and resumed
// gives the uninterrupted run's frames, statistics (coil_angle_deg and coil_radius among them),
// particles and coil state bit for bit.
TEST_F(CheckpointTest, ResumedEmitterRunKeepsTheCoilMeasure) {
  const auto scene = [](int frames) { return parseSceneText(nozzleSceneText(frames), "nozzle.json", "."); };
  const int frames = 3;
  RunOptions whole;
  whole.outDir = (dir_ / "whole").string();
  const RunSummary a = runScene(scene(frames), whole);
  ASSERT_EQ(a.frames, frames);
  ASSERT_GE(a.steps, 4);

  RunOptions part;
  part.outDir = (dir_ / "part").string();
  double swept = 0.0;
  part.onStep = [&](const StepStats& s) { swept = s.coilDegrees.value_or(0.0); };
  part.stopRequested = [&] { return swept != 0.0; };
  const RunSummary stopped = runScene(scene(frames), part);
  ASSERT_TRUE(stopped.stopped);
  const auto mid = findNewestCheckpoint(part.outDir);
  ASSERT_TRUE(mid);
  EXPECT_GT(mid->second.state.frameSubsteps, 0);  // the stop fell inside a frame
  ASSERT_TRUE(mid->second.state.coil);
  EXPECT_TRUE(std::isfinite(mid->second.state.coil->lastAngle));  // the measure has its angle before the stop
  EXPECT_EQ(mid->second.state.coil->swept, swept);
  part.resume = true;
  part.stopRequested = {};
  const RunSummary resumed = runScene(scene(frames), part);
  EXPECT_GE(resumed.steps, 2);  // steps that add to the angle after the resume
  EXPECT_EQ(stopped.steps + resumed.steps, a.steps);
  expectSameRun(whole.outDir, part.outDir, frames);
  const auto ca = findNewestCheckpoint(whole.outDir), cb = findNewestCheckpoint(part.outDir);
  ASSERT_TRUE(ca && cb && ca->second.state.coil && cb->second.state.coil);
  EXPECT_TRUE(sameCoil(*ca->second.state.coil, *cb->second.state.coil))
      << "swept " << ca->second.state.coil->swept << " against " << cb->second.state.coil->swept;
}

// A step whose solve fails is rolled back and taken again as two of dt/2 (down to
// solver.retries halvings). A very viscous ball (mu = 1e4 Pa s: mu dt / (rho dx^2) ~ 1,300 at the
// CFL step) solved by Jacobi CG (named: the default would take the multigrid there) needs
// 1,200-1,600 iterations per step (700-1,100 with sub-sample weights);
// capped at 1,000, many full steps fail and pass at dt/2 .. dt/16, where the mass term makes the
// system better conditioned. The run
// completes; every step stays under the cap; a split step's halves have equal dt; the steps add
// up to the frames. With no retries the same run fails, naming frame, step, stage and the cell
// whose divergence the unconverged solve left largest, and keeps a
// checkpoint of the last good state and its particles in failed_step_*.vdb.
TEST_F(CheckpointTest, FailedStepsAreRetriedWithSmallerSteps) {
  const int frames = 3, cap = 1000;
  const double mu = 1e4;
  RunOptions options;
  options.outDir = (dir_ / "retry").string();
  std::vector<StepStats> steps;
  options.onStep = [&](const StepStats& s) { steps.push_back(s); };
  const RunSummary summary = runScene(ballScene(frames, cap, 4, mu, "jacobi"), options);
  EXPECT_EQ(summary.frames, frames);
  EXPECT_GT(summary.retriedSteps, 0);
  double t = 0.0;
  int retried = 0;
  for (const StepStats& s : steps) {
    EXPECT_LE(s.grid.iterations, cap);
    if (s.retryLevel > 0) ++retried;
    if (!s.failedAttempts.empty()) {
      EXPECT_GT(s.retryLevel, 0);
      EXPECT_NE(s.failedAttempts.front().find("did not converge"), std::string::npos);
    }
    t += s.dt;
  }
  EXPECT_EQ(retried, summary.retriedSteps);
  EXPECT_NEAR(t, frames / 24.0, 1e-12);
  // The first half of a split step is followed by its twin, or by the twin's own halves when it
  // failed too: the steps after it add up to its dt exactly (halves of a double are exact).
  for (std::size_t i = 0; i + 1 < steps.size(); ++i)
    if (!steps[i].failedAttempts.empty()) {
      double twin = 0.0;
      for (std::size_t j = i + 1; j < steps.size() && twin < steps[i].dt; ++j) twin += steps[j].dt;
      EXPECT_EQ(twin, steps[i].dt) << "step " << i;
    }

  RunOptions strict;
  strict.outDir = (dir_ / "strict").string();
  try {
    runScene(ballScene(frames, cap, 0, mu, "jacobi"), strict);
    FAIL() << "expected a SimulationError";
  } catch (const SimulationError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("frame 1, step 0"), std::string::npos) << msg;
    EXPECT_NE(msg.find("stage stokes"), std::string::npos) << msg;
    EXPECT_NE(msg.find("did not converge"), std::string::npos) << msg;
    EXPECT_NE(msg.find("largest divergence left at cell ("), std::string::npos) << msg;
    EXPECT_NE(msg.find("failed_step_000000000.vdb"), std::string::npos) << msg;
  }
  const auto kept = findNewestCheckpoint(strict.outDir);
  ASSERT_TRUE(kept);
  EXPECT_EQ(kept->second.state.steps, 0);  // the last good state: the start
  EXPECT_EQ(readVdbGridNames((fs::path(strict.outDir) / "failed_step_000000000.vdb").string()),
            (std::vector<std::string>{"particles", "surface", "vel"}));
}

#ifdef STOKESVDB_BINARY
namespace {

/// Starts `stokesvdb run SCENE --out DIR [--resume]` with 2 threads; returns its pid.
pid_t startRun(const fs::path& scene, const fs::path& out, bool resume) {
  std::vector<std::string> args = {STOKESVDB_BINARY, "run", scene.string(), "--out", out.string(), "--threads", "2"};
  if (resume) args.push_back("--resume");
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  const std::string log = (out.string() + (resume ? ".resume.log" : ".log"));
  posix_spawn_file_actions_addopen(&actions, 2, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  pid_t pid = -1;
  const int rc = posix_spawn(&pid, STOKESVDB_BINARY, &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  return rc == 0 ? pid : -1;
}

int waitFor(pid_t pid) {
  int status = 0;
  waitpid(pid, &status, 0);
  return status;
}

/// Waits (up to a minute) until DIR holds a checkpoint of at least `step`.
bool waitForCheckpoint(const fs::path& out, std::int64_t step) {
  for (int i = 0; i < 6000; ++i) {
    std::error_code ec;
    for (const auto& e : fs::directory_iterator(checkpointFolder(out.string()), ec)) {
      const std::string name = e.path().filename().string();
      if (e.path().extension() == ".ckpt" && std::stoll(name.substr(5, 9)) >= step) return true;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return false;
}

}  // namespace

// The real command, killed: SIGKILL after a checkpoint (whatever it was doing), then --resume;
// SIGTERM finishes its step, checkpoints and exits 143, then --resume. Both give the frames,
// statistics and particles of an uninterrupted run bit for bit.
TEST_F(CheckpointTest, KilledCommandResumesBitIdentical) {
  const int frames = 10;
  const fs::path scene = dir_ / "ball.json";
  std::ofstream(scene) << ballSceneText(frames);
  const fs::path whole = dir_ / "whole", killed = dir_ / "killed", termed = dir_ / "termed";
  ASSERT_EQ(waitFor(startRun(scene, whole, false)), 0);

  const pid_t k = startRun(scene, killed, false);
  ASSERT_GT(k, 0);
  ASSERT_TRUE(waitForCheckpoint(killed, 5));
  kill(k, SIGKILL);
  const int ks = waitFor(k);
  ASSERT_TRUE(WIFSIGNALED(ks) && WTERMSIG(ks) == SIGKILL);  // killed mid-run, not finished
  EXPECT_EQ(waitFor(startRun(scene, killed, true)), 0);
  expectSameRun(whole, killed, frames);

  const pid_t t = startRun(scene, termed, false);
  ASSERT_GT(t, 0);
  ASSERT_TRUE(waitForCheckpoint(termed, 3));
  kill(t, SIGTERM);
  const int ts = waitFor(t);
  ASSERT_TRUE(WIFEXITED(ts) && WEXITSTATUS(ts) == 143);  // stopped by the signal, after a checkpoint
  std::ifstream log(termed.string() + ".log");
  const std::string text((std::istreambuf_iterator<char>(log)), std::istreambuf_iterator<char>());
  EXPECT_NE(text.find("stopped by signal 15"), std::string::npos) << text;
  EXPECT_EQ(waitFor(startRun(scene, termed, true)), 0);
  expectSameRun(whole, termed, frames);
}
#endif
