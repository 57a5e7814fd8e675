#include "app/accuracy_time_study.h"

#include <fmt/core.h>
#include <fmt/os.h>
#include <omp.h>

#include <cstdlib>
#include <filesystem>
#include <stdexcept>
#include <vector>

#include "analytic/analytic_cases.h"

namespace stokes::app {

namespace {

struct Setting {
  const char* model;
  int tile, pad;
  std::string label() const {
    return std::string(model) == "uniform" ? "uniform" : fmt::format("{} {}/{}", model, tile, pad);
  }
};

struct Case {
  const char* name;  ///< column 1 of the CSV and the stem of its plots
  const char* test;
  int dim;
  double mu;
  std::vector<Setting> settings;
};

std::vector<Case> studyCases() {
  return {
      {"box-viscosity", "box-viscosity", 2, 1.0,
       {{"uniform", 0, 0}, {"affine", 16, 2}, {"quadratic", 16, 2}, {"affine", 32, 4}, {"quadratic", 32, 4}}},
      {"disk-stokes", "disk-stokes", 2, 0.1,
       {{"uniform", 0, 0}, {"affine", 16, 3}, {"quadratic", 16, 3}, {"quadratic", 16, 2}, {"quadratic", 32, 4}}},
      {"box-viscosity-3d", "box-viscosity", 3, 1.0,
       {{"uniform", 0, 0}, {"affine", 16, 2}, {"quadratic", 16, 2}, {"quadratic", 8, 2}}},
  };
}

/// The case's options at resolution n: the study's solver (strongest measured, or Jacobi CG on the
/// SPD form as in the thesis' comparison) with the setting's tiling.
analytic::AnalyticOptions caseOptions(const Case& c, const Setting& s, int n, const std::string& solverName) {
  analytic::AnalyticOptions o;
  o.n = n;
  o.dim = c.dim;
  o.mu = c.mu;
  o.model = s.model;
  if (s.tile > 0) {
    o.tileSize = s.tile;
    o.padding = s.pad;
  }
  if (solverName == "strong") {  // everything open: solver::planSolve's fastest measured
    o.form.reset();
    o.preconditioner.reset();
    o.method.reset();
  } else if (solverName == "jacobi") {
    o.form = solver::StokesForm::PressureStress;
    o.preconditioner = solver::PreconditionerKind::Jacobi;
    o.method = solver::KrylovMethod::CG;
  } else {
    throw std::invalid_argument("accuracy-time: unknown solver '" + solverName + "' (strong or jacobi)");
  }
  return o;
}

/// One gnuplot script drawing L1 against `xColumn` (log-log), one line per setting.
void writePlot(const std::filesystem::path& dir, const Case& c, const char* xColumn, int xIndex,
               const char* xLabel, const std::string& png) {
  const std::filesystem::path gp = dir / (png + ".gp");
  auto out = fmt::output_file(gp.string());
  out.print("set terminal pngcairo size 900,650 font ',11'\nset output '{}'\n", (dir / (png + ".png")).string());
  out.print("set datafile separator ','\nset logscale xy\nset grid\nset key outside right\n");
  out.print("set xlabel '{}'\nset ylabel 'L1 error'\nset title '{}: L1 error against {}'\n", xLabel, c.name, xColumn);
  out.print("plot ");
  for (std::size_t k = 0; k < c.settings.size(); ++k) {
    const std::string label = c.settings[k].label();
    out.print("{}'{}' using (strcol(1) eq '{}' && strcol(2) eq '{}' ? ${} : 1/0):6 with linespoints title '{}'",
              k ? ", \\\n     " : "", (dir / "accuracy_time.csv").string(), c.name, label, xIndex, label);
  }
  out.print("\n");
  out.close();
  const std::string cmd = "gnuplot '" + gp.string() + "' 2>&1";
  if (std::system(cmd.c_str()) != 0) fmt::print(stderr, "warning: gnuplot failed on {}\n", gp.string());
}

}  // namespace

int runAccuracyTimeStudy(const AccuracyTimeOptions& opt) {
  const std::filesystem::path dir(opt.outDir);
  std::filesystem::create_directories(dir);
  const std::filesystem::path csv = dir / "accuracy_time.csv";
  auto out = fmt::output_file(csv.string());
  // columns: 1 test, 2 setting, 3 model, 4 tile, 5 pad, 6 L1, 7 Linf, 8 n, 9 total_seconds,
  // 10 solve_seconds, 11 setup_seconds, 12 iterations, 13 unknowns, 14 reduced_dofs, 15 tiles,
  // 16 status, 17 threads, 18 dim, 19 solver (what ran: system, form, method, preconditioner)
  out.print("test,setting,model,tile,pad,L1,Linf,n,total_seconds,solve_seconds,setup_seconds,iterations,unknowns,"
            "reduced_dofs,tiles,status,threads,dim,solver\n");
  const auto cases = studyCases();
  for (const Case& c : cases)
    for (const Setting& s : c.settings)
      for (int n = 16; n <= (c.dim == 3 ? opt.maxN3d : opt.maxN); n *= 2) {
        const analytic::AnalyticOptions o = caseOptions(c, s, n, opt.solver);
        const analytic::AnalyticResult r = std::string(c.test) == "disk-stokes" ? analytic::runDiskStokes(o)
                                                                                : analytic::runBoxViscosity(o);
        out.print("{},{},{},{},{},{:.6e},{:.6e},{},{:.6f},{:.6f},{:.6f},{},{},{},{},{},{},{},\"{}\"\n", c.name, s.label(),
                  s.model, s.tile, s.pad, r.L1, r.Linf, n, r.totalSeconds, r.solveSeconds, r.setupSeconds,
                  r.iterations, r.unknowns, r.reducedDofs, r.tiles, r.status, omp_get_max_threads(), c.dim, r.solver);
        out.flush();
        fmt::print("{:>16} {:>16} N {:>4}: L1 {:.4e}  {:>6} iterations  {:8.3f} s  {}  ({})\n", c.name, s.label(), n,
                   r.L1, r.iterations, r.totalSeconds, r.status, r.solver);
        std::fflush(stdout);
      }
  out.close();
  fmt::print("wrote {}\n", csv.string());
  if (!opt.plots) return 0;
  if (std::system("command -v gnuplot > /dev/null 2>&1") != 0) {
    fmt::print("gnuplot not found: skipping the plots (scripts/install_deps.sh installs gnuplot-nox)\n");
    return 0;
  }
  for (const Case& c : cases) {
    const std::string stem = std::string(c.name);
    writePlot(dir, c, "time", 9, "wall time per step [s] (set-up + solve)", stem + "_error_vs_time");
    writePlot(dir, c, "N", 8, "N (cells across the box / per unit length)", stem + "_error_vs_n");
    fmt::print("wrote {}_error_vs_time.png and {}_error_vs_n.png\n", (dir / stem).string(), (dir / stem).string());
  }
  return 0;
}

}  // namespace stokes::app
