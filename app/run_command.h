#pragma once
// `stokesvdb run SCENE.json --out DIR [--frames K] [--res N] [--threads T] [--model M] [--viscosity V]`:
// simulates a scene file and writes frame_NNNN.vdb / .png and stats.csv into DIR
// (sim/run/scene_runner.h). SCENE that is not a file names a shipped scene, with or without .json:
// <prefix>/share/stokesvdb/scenes beside the installed program, then the source tree's scenes/.
// `--model` / `--viscosity` replace the scene's model.type / viscosity (the
// tile parameters stay the file's), so one file serves the uniform-vs-reduced and
// coupled-vs-decoupled comparisons.
//
// `--resume` continues the run in DIR from its newest checkpoint (sim/run/scene_runner.h), with the
// same scene file and options (--frames and --threads may differ). SIGINT and SIGTERM finish the
// current step, write a checkpoint and exit with status 130 / 143; a second signal ends the process
// at once. A step that fails after its retries exits with status 1 and keeps its last good state.
//
// `stokesvdb compare A.vdb B.vdb`: the symmetric volume difference of two liquid level sets
// (frame files of `run`), absolute and relative to each volume.
#include <optional>
#include <string>
#include <vector>

namespace CLI {
class App;
}

namespace stokes::app {

/// The help group of every command's research knobs (storage layouts, multigrid settings, fits):
/// `--help` lists the options a user needs first and these after them.
inline constexpr const char* kAdvanced = "Advanced";

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
  bool resume = false;                   ///< continue from DIR's newest checkpoint
  std::optional<std::string> backend;    ///< in-house | petsc (replaces solver.backend)
  std::vector<std::string> petscOptions;  ///< PETSc's options from the command line (-ksp_type ...)
};

struct CompareArgs {
  std::string a, b;
  bool json = false;
};

/// Adds the `run` subcommand to `app`, filling `args`.
CLI::App* addRunCommand(CLI::App& app, RunArgs& args);

/// Runs it. Returns 0 on success, 2 on a bad scene file or arguments (SceneError) or a checkpoint
/// that cannot be resumed, 1 when a step fails (the frames written so far are kept), 128 + the
/// signal number when stopped by SIGINT / SIGTERM (after a checkpoint).
int runRunCommand(const RunArgs& args);

/// Adds the `compare` subcommand to `app`, filling `args`.
CLI::App* addCompareCommand(CLI::App& app, CompareArgs& args);

/// Prints |A|, |B|, |A xor B| and |A xor B| relative to |A| and |B|. Returns 0, or 2 when a file
/// cannot be read.
int runCompareCommand(const CompareArgs& args);

}  // namespace stokes::app
