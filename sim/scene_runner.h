#pragma once
// A whole run of a scene into an output folder (the `stokesvdb run` command):
//
//   DIR/frame_NNNN.vdb   the liquid level set (grid "liquid"), plus the particles (points grid
//                        "particles" with velocity "v") when the scene's output.particles is set;
//                        frame 0 is the initial state, frame k the state at t = k / fps
//   DIR/frame_NNNN.png   a ray-cast preview (output.preview), the scene's camera or one framing
//                        the domain; solids drawn grey
//   DIR/stats.csv        one row per step (columns in statsColumns(); a stage's time column is
//                        empty when the stage did not run)
//
// Files are written to a temporary name and renamed (sim/output.h), so a failed step leaves the
// frames written so far and no partial file. A progress line per step goes to `progress`.
#include <functional>
#include <iosfwd>
#include <string>
#include <vector>

#include "sim/scene.h"
#include "sim/simulator.h"

namespace stokes::sim {

struct RunOptions {
  std::string outDir;
  std::ostream* progress = nullptr;  ///< progress lines (null: none)
  /// Called after every step (tests read the statistics here).
  std::function<void(const StepStats&)> onStep;
};

struct RunSummary {
  int frames = 0;
  int steps = 0;
  double wallSeconds = 0.0;
  double initialVolume = 0.0;  ///< levelSetVolume of frame 0
  double finalVolume = 0.0;    ///< levelSetVolume of the last frame written
  int maxIterations = 0;       ///< most Krylov iterations in one step
};

/// Column names of stats.csv.
std::vector<std::string> statsColumns();

/// Runs all frames of `scene`. Throws SimulationError (naming frame, step and stage) when a step
/// fails, std::runtime_error when a file cannot be written.
RunSummary runScene(const Scene& scene, const RunOptions& options);

}  // namespace stokes::sim
