#pragma once
// Progress of a run (`stokesvdb run`), for a person watching it or a log file:
//
//   on a terminal   one line, rewritten in place after every step (at most 10 times a second):
//                   frame, step, simulated time, iterations, particles, elapsed time, ETA
//   otherwise       one plain line per frame written (the frame's steps, most iterations,
//                   particles, elapsed time, ETA)
//
// Retried steps and other notes get lines of their own in both. Each step's stage times are
// summed for the run's summary (stageSeconds).
#include <chrono>
#include <iosfwd>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "sim/step/simulator.h"

namespace stokes::sim {
inline namespace run {

class RunProgressLine {
 public:
  /// `out` null: silent (the stage sums are still kept). `startTime`: the simulated time the run
  /// starts from (a resumed run's checkpoint), for the ETA.
  RunProgressLine(std::ostream* out, bool terminal, std::string sceneName, int frames, double duration,
                  double startTime);

  void step(const StepStats& s);
  void frameWritten(int frame, double time);
  /// A line of its own (clears the terminal line first).
  void note(const std::string& text);
  /// Ends the terminal line.
  void finish();

  /// Seconds per stage over the steps seen, in the order the stages first ran.
  const std::vector<std::pair<std::string, double>>& stageSeconds() const { return stages_; }

 private:
  double elapsed() const;
  std::string eta(double t) const;
  void add(const char* name, const std::optional<double>& seconds);

  std::ostream* out_;
  bool terminal_;
  std::string name_;
  int frames_;
  double duration_, startTime_;
  std::chrono::steady_clock::time_point start_, lastDraw_{};
  bool lineOpen_ = false;
  int frameSteps_ = 0, frameMaxIterations_ = 0;
  std::size_t particles_ = 0;
  std::vector<std::pair<std::string, double>> stages_;
};

/// The process's peak resident memory in bytes (getrusage), 0 where unknown.
std::size_t peakResidentBytes();

}  // namespace run
}  // namespace stokes::sim
