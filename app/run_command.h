#pragma once
// `stokesvdb run SCENE.json --out DIR [--frames K] [--res N] [--threads T]`: simulates a scene file
// and writes frame_NNNN.vdb / .png and stats.csv into DIR (sim/scene_runner.h).
#include <optional>
#include <string>

namespace CLI {
class App;
}

namespace stokes::app {

struct RunArgs {
  std::string scene;
  std::string outDir;
  std::optional<int> frames, resolution;
  int threads = 0;  ///< 0: all cores
};

/// Adds the `run` subcommand to `app`, filling `args`.
CLI::App* addRunCommand(CLI::App& app, RunArgs& args);

/// Runs it. Returns 0 on success, 2 on a bad scene file or arguments (SceneError), 1 when a step
/// fails (the frames written so far are kept).
int runRunCommand(const RunArgs& args);

}  // namespace stokes::app
