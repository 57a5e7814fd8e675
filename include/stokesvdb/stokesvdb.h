#pragma once
// StokesVDB's public API in one include: scenes (sim/scene/scene.h), the simulator you advance by
// steps or frames (sim/step/simulator.h), whole runs with frames, statistics and checkpoints
// (sim/run/scene_runner.h, sim/run/checkpoint.h), one step on the caller's own grids
// (sim/run/grid_solve.h), and the frame files (sim/output/vdb_frame.h, sim/output/surface_mesh.h).
// Link the CMake target StokesVDB::stokesvdb.
//
//   #include <stokesvdb/stokesvdb.h>
//
//   using namespace stokes::sim;
//   const Scene scene = loadScene("scenes/default.json", SceneOverrides{24, 4});  // res 24, 4 frames
//   Simulator sim(scene);
//   std::atomic<bool> stop{false};  // set from a signal handler or another thread
//   for (int frame = 1; frame <= scene.frames; ++frame)
//     sim.advanceFrame(frame, [](const StepStats& s) { std::printf("t %g, %d iterations\n", s.t, s.grid.iterations); },
//                      [&] { return stop.load(); });  // polled between steps and once per Krylov iteration
//   openvdb::FloatGrid::Ptr surface = sim.liquidLevelSet();
//
// or the whole `stokesvdb run` loop: runScene(scene, RunOptions{.outDir = "out"}).
#include "sim/output/surface_mesh.h"
#include "sim/output/vdb_frame.h"
#include "sim/run/checkpoint.h"
#include "sim/run/grid_solve.h"
#include "sim/run/scene_runner.h"
#include "sim/scene/scene.h"
#include "sim/step/simulator.h"
