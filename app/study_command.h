#pragma once
// `stokesvdb study analytic`: the convergence table of the analytic cases against the thesis' L1
// errors (Tables 5.1, E.1, F.1); `stokesvdb study accuracy-time`: what accuracy costs in time
// (accuracy_time_study.h).
#include <optional>
#include <string>

#include "app/accuracy_time_study.h"

namespace CLI {
class App;
}

namespace stokes::app {

struct StudyArgs {
  int maxN = 256, max3d = 64, threads = 0;
  bool json = false;
  std::string models = "uniform,affine,quadratic";
  AccuracyTimeOptions accuracy;
  CLI::App *analyticCmd = nullptr, *accuracyCmd = nullptr;
};

/// Adds `study` and its two studies to `app`, filling `args`.
CLI::App* addStudyCommand(CLI::App& app, StudyArgs& args);

/// Runs the chosen study (0 on success); nullopt when no study was chosen.
std::optional<int> runStudyCommand(const StudyArgs& args);

}  // namespace stokes::app
