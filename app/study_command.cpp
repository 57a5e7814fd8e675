// `stokesvdb study ...`: see study_command.h.
#include "app/study_command.h"

#include <CLI/CLI.hpp>
#include <fmt/core.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <map>
#include <string>
#include <vector>

#include "analytic/analytic_cases.h"
#include "app/analytic_command.h"

namespace stokes::app {

namespace {

using analytic::AnalyticOptions;
using analytic::AnalyticResult;

double order(double coarse, double fine, double ratio) { return std::log(coarse / fine) / std::log(ratio); }

/// One row group of the study: a test, a model and its tiling, with the thesis' L1 values.
struct StudySeries {
  const char* test;
  int dim;
  const char* model;
  int tile, pad;
  double mu;
  std::map<int, double> thesisL1;  ///< thesis Table 5.1 / E.1 / F.1 (docs/design.md §4)
};

std::vector<StudySeries> studySeries(const std::string& models) {
  std::vector<StudySeries> all = {
      {"box-viscosity", 2, "uniform", 16, 2, 1.0, {}},
      {"box-viscosity", 2, "affine", 16, 2, 1.0, {{16, 4.982}, {32, 2.307}, {64, 0.9869}, {128, 0.3309}, {256, 0.09653}}},
      {"box-viscosity", 2, "quadratic", 16, 2, 1.0,
       {{16, 1.748}, {32, 0.3799}, {64, 0.04906}, {128, 0.005839}, {256, 0.0006952}}},
      {"disk-stokes", 2, "uniform", 16, 3, 0.1, {{16, 0.045395}, {32, 0.022576}, {64, 0.010988}, {128, 0.0058821}}},
      {"disk-stokes", 2, "affine", 16, 3, 0.1,
       {{16, 2.2858}, {32, 1.5643}, {64, 0.47645}, {128, 0.24068}, {256, 0.10007}}},
      {"disk-stokes", 2, "quadratic", 16, 3, 0.1,
       {{16, 1.5582}, {32, 1.1511}, {64, 0.11502}, {128, 0.020523}, {256, 0.011193}}},
      {"box-viscosity", 3, "uniform", 16, 2, 1.0, {}},
  };
  std::vector<StudySeries> chosen;
  for (auto& s : all)
    if (models.find(s.model) != std::string::npos) chosen.push_back(s);
  return chosen;
}

/// The convergence tables of the analytic cases against the thesis.
int runStudy(int maxN, int max3d, const std::string& models, bool json) {
  nlohmann::json all = nlohmann::json::array();
  for (const StudySeries& row : studySeries(models)) {
    const bool reduced = std::string(row.model) != "uniform";
    if (!json) {
      fmt::print("\n{} ({}D, {}{}, mu {})\n", row.test, row.dim, row.model,
                 reduced ? fmt::format(" {}/{}", row.tile, row.pad) : "", row.mu);
      fmt::print("{:>5} {:>11} {:>6} {:>11} {:>6} {:>11} {:>7} {:>6} {:>9} {:>9}\n", "N", "L1", "order", "Linf",
                 "order", "thesis L1", "iters", "tiles", "solve s", "total s");
    }
    const int top = row.dim == 3 ? max3d : maxN;
    double prevL1 = 0.0, prevLinf = 0.0;
    for (int n = 16; n <= top; n *= 2) {
      AnalyticOptions o;
      o.dim = row.dim;
      o.n = n;
      o.mu = row.mu;
      o.model = row.model;
      o.tileSize = row.tile;
      o.padding = row.pad;
      const AnalyticResult r = std::string(row.test) == "disk-stokes" ? stokes::analytic::runDiskStokes(o)
                                                                     : stokes::analytic::runBoxViscosity(o);
      if (json) {
        all.push_back(toJson(r));
      } else {
        const std::string o1 = prevL1 > 0 ? fmt::format("{:.2f}", order(prevL1, r.L1, 2.0)) : "-";
        const std::string o2 = prevLinf > 0 ? fmt::format("{:.2f}", order(prevLinf, r.Linf, 2.0)) : "-";
        const auto ref = row.thesisL1.find(n);
        const std::string thesis = ref != row.thesisL1.end() ? fmt::format("{:.4g}", ref->second) : "-";
        fmt::print("{:>5} {:>11.4e} {:>6} {:>11.4e} {:>6} {:>11} {:>7} {:>6} {:>9.3f} {:>9.3f}{}\n", n, r.L1, o1,
                   r.Linf, o2, thesis, r.iterations, r.tiles, r.solveSeconds, r.totalSeconds,
                   r.status == "Converged" ? "" : "  " + r.status);
        std::fflush(stdout);
      }
      prevL1 = r.L1;
      prevLinf = r.Linf;
    }
  }
  if (json) fmt::print("{}\n", all.dump(2));
  return 0;
}

}  // namespace

CLI::App* addStudyCommand(CLI::App& app, StudyArgs& a) {
  CLI::App* study = app.add_subcommand("study", "run a study");
  study->require_subcommand(1);
  a.analyticCmd = study->add_subcommand("analytic", "convergence table of the analytic cases");
  a.analyticCmd->add_option("--max-n", a.maxN, "largest 2D resolution")->check(CLI::Range(16, 4096));
  a.analyticCmd->add_option("--max-n-3d", a.max3d, "largest 3D resolution")->check(CLI::Range(16, 512));
  a.analyticCmd->add_option("--threads", a.threads, "OpenMP threads (0: all cores)");
  a.analyticCmd->add_flag("--json", a.json, "print JSON");
  a.analyticCmd->add_option("--models", a.models, "comma-separated subset of uniform,affine,quadratic");

  a.accuracyCmd =
      study->add_subcommand("accuracy-time", "error and wall time of every model over N and tilings (CSV + PNG)");
  a.accuracyCmd->add_option("--out", a.accuracy.outDir, "output folder");
  a.accuracyCmd->add_option("--max-n", a.accuracy.maxN, "largest 2D resolution")->check(CLI::Range(16, 4096));
  a.accuracyCmd->add_option("--max-n-3d", a.accuracy.maxN3d, "largest 3D resolution")->check(CLI::Range(16, 512));
  a.accuracyCmd
      ->add_option("--solver", a.accuracy.solver,
                   "strong (multigrid where it pays, as --precond auto) or jacobi (Jacobi CG on the SPD form)")
      ->check(CLI::IsMember({"strong", "jacobi"}));
  a.accuracyCmd->add_flag("!--no-plots", a.accuracy.plots, "skip the gnuplot PNGs");
  a.accuracyCmd->add_option("--threads", a.threads, "OpenMP threads (0: all cores)");
  return study;
}

std::optional<int> runStudyCommand(const StudyArgs& a) {
  if (*a.accuracyCmd) {
    applyThreads(a.threads);
    return runAccuracyTimeStudy(a.accuracy);
  }
  if (*a.analyticCmd) {
    applyThreads(a.threads);
    return runStudy(a.maxN, a.max3d, a.models, a.json);
  }
  return std::nullopt;
}

}  // namespace stokes::app
