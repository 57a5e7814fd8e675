// `stokesvdb run`: see run_command.h.
#include "app/run_command.h"

#include <CLI/CLI.hpp>
#include <fmt/core.h>
#include <omp.h>

#include <iostream>

#include "sim/scene_runner.h"

namespace stokes::app {

CLI::App* addRunCommand(CLI::App& app, RunArgs& args) {
  CLI::App* cmd = app.add_subcommand("run", "simulate a scene file (scenes/*.json) into --out DIR");
  cmd->add_option("scene", args.scene, "scene file (JSON, schema in scenes/README.md)")->required();
  cmd->add_option("--out", args.outDir, "output folder: frame_NNNN.vdb / .png, stats.csv")->required();
  cmd->add_option("--frames", args.frames, "number of frames (overrides the scene's)");
  cmd->add_option("--res", args.resolution, "cells along the longest domain axis (overrides the scene's)");
  cmd->add_option("--threads", args.threads, "OpenMP threads (0: all cores)")->check(CLI::NonNegativeNumber);
  return cmd;
}

int runRunCommand(const RunArgs& args) {
  sim::Scene scene;
  try {
    scene = sim::loadScene(args.scene, sim::SceneOverrides{args.resolution, args.frames});
  } catch (const sim::SceneError& e) {
    fmt::print(stderr, "stokesvdb run: {}\n", e.what());
    return 2;
  }
  if (args.threads > 0) omp_set_num_threads(args.threads);
  sim::RunOptions options;
  options.outDir = args.outDir;
  options.progress = &std::cerr;
  try {
    const sim::RunSummary s = sim::runScene(scene, options);
    fmt::print(stderr,
               "stokesvdb run: {} frames, {} steps in {:.1f} s ({:.2f} s per frame); liquid volume {:.6g} -> {:.6g} "
               "m^3 ({:+.2f}%); at most {} iterations per step; output in {}\n",
               s.frames, s.steps, s.wallSeconds, s.wallSeconds / std::max(s.frames, 1), s.initialVolume,
               s.finalVolume, 100.0 * (s.finalVolume / s.initialVolume - 1.0), s.maxIterations, args.outDir);
  } catch (const std::exception& e) {
    fmt::print(stderr, "stokesvdb run: failed: {}\n(frames written so far are kept in {})\n", e.what(),
               args.outDir);
    return 1;
  }
  return 0;
}

}  // namespace stokes::app
