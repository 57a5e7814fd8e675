#pragma once
// A whole run of a scene into an output folder (the `stokesvdb run` command):
//
//   DIR/frame_NNNN.vdb   the liquid level set (grid "surface"), its velocity ("vel"), plus the particles (points grid
//                        "particles" with velocity "v") when the scene's output.particles is set;
//                        frame 0 is the initial state, frame k the state at t = k / fps
//   DIR/frame_NNNN.ply   the liquid surface as a binary PLY mesh (output.mesh; sim/output/surface_mesh.h);
//                        .vdb and .ply are z-up with output.up_axis "z" (Blender), else y-up
//   DIR/frame_NNNN.png   a ray-cast preview (output.preview), the scene's camera or one framing
//                        the domain; solids drawn grey
//   DIR/stats.csv        one row per step (columns in statsColumns(); a stage's time column is
//                        empty when the stage did not run)
//   DIR/checkpoints/     the newest two checkpoints (sim/run/checkpoint.h), every
//                        output.checkpoint_every frames, when a stop is requested, and when a step
//                        fails for good
//
// Files are written to a temporary name and renamed (sim/output/atomic_file.h), so a failed step leaves the
// frames written so far and no partial file. Progress goes to `progress` (sim/run/run_progress.h).
//
// Resume (RunOptions::resume): the run continues from the newest complete checkpoint in DIR. Its
// frames and statistics are bit for bit those of a run that was never interrupted (the state is
// the simulator's whole carried state; the random draws follow the step index); stats.csv keeps
// its rows before the checkpoint's step and the frames after the checkpoint's are written again.
// The checkpoint's signature (the scene file's text and the options that change results) must
// match the run's; the frame count may differ, so a finished run can be extended.
//
// A step that fails after its retries (Simulator::advanceFrame) leaves a checkpoint of the last
// good state and DIR/failed_step_SSSSSSSSS.vdb (its level set and particles) before the error
// propagates.
#include <functional>
#include <iosfwd>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "sim/scene/scene.h"
#include "sim/step/simulator.h"

namespace stokes::sim {
inline namespace run {

struct RunOptions {
  std::string outDir;
  std::ostream* progress = nullptr;  ///< progress (null: none; sim/run/run_progress.h)
  bool progressIsTerminal = false;   ///< one line rewritten in place, instead of a line per frame
  /// Called after every step (tests read the statistics here).
  std::function<void(const StepStats&)> onStep;
  /// Continue from the newest checkpoint in outDir (see the top of this file).
  bool resume = false;
  /// What besides the scene file's text fixes the run's results (the command line's overrides);
  /// stored in checkpoints and compared on resume.
  std::string signature;
  /// Polled after every step and once per Krylov iteration; when it returns true the run writes a
  /// checkpoint of the last complete step and returns with RunSummary::stopped set (SIGINT /
  /// SIGTERM in `stokesvdb run`).
  std::function<bool()> stopRequested;
};

struct RunSummary {
  int frames = 0;
  int steps = 0;              ///< steps taken in this process
  int stepsTotal = 0;         ///< steps of the whole run so far (with those before a resume)
  int retriedSteps = 0;       ///< steps that needed a smaller dt (StepStats::retryLevel > 0)
  double wallSeconds = 0.0;
  double initialVolume = 0.0;  ///< levelSetVolume of frame 0
  double finalVolume = 0.0;    ///< levelSetVolume of the last frame written
  int maxIterations = 0;       ///< most Krylov iterations in one step
  bool stopped = false;        ///< stopped on request, after a checkpoint
  int resumedFromStep = -1;    ///< the checkpoint's step when resumed (-1: a fresh run)
  std::string lastCheckpoint;  ///< the newest checkpoint written ("" if none)
  std::vector<std::pair<std::string, double>> stageSeconds;  ///< wall time per stage, this process
  std::size_t peakResidentBytes = 0;
};

/// A resume that cannot start: no complete checkpoint, or one of another run.
class ResumeError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// The run signature of a scene: its file's text (or, parsed from memory, its name) and `options`.
std::string runSignature(const Scene& scene, const std::string& options);

/// Column names of stats.csv.
std::vector<std::string> statsColumns();

/// One step's numeric stats.csv columns (all but "solver", which is StepStats::grid.solver), by
/// name; a stage's time appears only when the stage ran.
std::vector<std::pair<std::string, double>> statsRow(const StepStats& s);

/// Runs all frames of `scene`. Throws SimulationError (naming frame, step and stage) when a step
/// fails for good, std::runtime_error when a file cannot be written or a resume finds no
/// matching checkpoint.
RunSummary runScene(const Scene& scene, const RunOptions& options);

}  // namespace run
}  // namespace stokes::sim
