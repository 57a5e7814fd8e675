#pragma once
// `stokesvdb run SCENE.json --out DIR [--frames K] [--res N] [--threads T] [--model M] [--viscosity V]`:
// simulates a scene file and writes frame_NNNN.vdb / .png and stats.csv into DIR
// (sim/scene_runner.h). `--model` / `--viscosity` replace the scene's model.type / viscosity (the
// tile parameters stay the file's), so one file serves the uniform-vs-reduced and
// coupled-vs-decoupled comparisons.
//
// `stokesvdb compare A.vdb B.vdb`: the symmetric volume difference of two liquid level sets
// (frame files of `run`), absolute and relative to each volume.
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
  std::optional<std::string> model;      ///< uniform | affine | quadratic
  std::optional<std::string> viscosity;  ///< coupled | decoupled | none
  std::optional<std::string> rows;       ///< auto | compact | padded
  std::optional<std::string> stencils;   ///< rows | blocks
  std::optional<std::string> warmStart;  ///< on | off
};

struct CompareArgs {
  std::string a, b;
  bool json = false;
};

/// Adds the `run` subcommand to `app`, filling `args`.
CLI::App* addRunCommand(CLI::App& app, RunArgs& args);

/// Runs it. Returns 0 on success, 2 on a bad scene file or arguments (SceneError), 1 when a step
/// fails (the frames written so far are kept).
int runRunCommand(const RunArgs& args);

/// Adds the `compare` subcommand to `app`, filling `args`.
CLI::App* addCompareCommand(CLI::App& app, CompareArgs& args);

/// Prints |A|, |B|, |A xor B| and |A xor B| relative to |A| and |B|. Returns 0, or 2 when a file
/// cannot be read.
int runCompareCommand(const CompareArgs& args);

}  // namespace stokes::app
