#pragma once
// `stokesvdb analytic box-viscosity|disk-stokes|ball|surface-mode [options]`: one analytic
// verification case (analytic/analytic_cases.h), printed as text or one JSON object; and the MPI
// calls the command line makes (PETSc's over ranks, or one process in a build without it).
#include <nlohmann/json.hpp>

#include <optional>
#include <string>
#include <vector>

#include "analytic/analytic_cases.h"
#include "solver/multigrid/multigrid.h"
#ifdef STOKES_HAVE_PETSC
#include "solver/petsc/petsc_krylov.h"
#endif

namespace CLI {
class App;
}

namespace stokes::app {

#ifdef STOKES_HAVE_PETSC
namespace mpi = stokes::solver::petsc;
#else
// A build without the PETSc backend runs as one process; `--backend petsc` is refused by the solve.
namespace mpi {
inline int rank() { return 0; }
inline int ranks() { return 1; }
inline double sumOverRanks(double v) { return v; }
inline double maxOverRanks(double v) { return v; }
inline void splitPetscOptions(const std::vector<std::string>& args, std::vector<std::string>& rest,
                              std::vector<std::string>&) {
  rest = args;
}
struct Session {
  static void initialise(const std::vector<std::string>&) {}
};
}  // namespace mpi
#endif

/// The analytic cases' defaults (stated once, in AnalyticOptions).
inline const analytic::AnalyticOptions kCaseDefaults{};

/// The options every analytic case takes.
struct CaseArgs {
  std::string model = kCaseDefaults.model;
  int tile = kCaseDefaults.tileSize, pad = kCaseDefaults.padding, bandAir = kCaseDefaults.bandAir,
      bandSolid = kCaseDefaults.bandSolid, minRegion = kCaseDefaults.minRegion, tileMin = kCaseDefaults.minTileSize;
  double tileAccuracy = kCaseDefaults.tileAccuracy;
  std::string tileRule = "auto";
  std::string family = kCaseDefaults.family, fit = kCaseDefaults.fit, form = "auto", tileCache = kCaseDefaults.tileCache;
  int n = kCaseDefaults.n, dim = kCaseDefaults.dim, threads = 0, maxIterations = kCaseDefaults.maxIterations;
  std::optional<double> mu, rho, dt;
  double tol = kCaseDefaults.tolerance;
  std::string solverName = "auto", precond = "auto", system = "unified";
  bool json = false, solids = false;
  std::string rows = "auto";
  std::string stencils = "rows";
  int mgDegree = solver::MultigridOptions{}.smootherDegree;
  double mgRange = solver::MultigridOptions{}.smootherRange;
  std::string mgSchur = "auto", mgInterpolation = "auto";
  std::string backend = "in-house";
  std::string liquidWeights = "auto";
};

struct AnalyticArgs {
  CaseArgs box, disk, ball, surface;
  std::string rankSetup = "own";
  std::string facesOut, facesCompare;
  bool versusUniform = false;
  analytic::AnalyticOptions surfaceShape;
  int surfaceWidth = 0;
  CLI::App *boxCmd = nullptr, *diskCmd = nullptr, *ballCmd = nullptr, *surfaceCmd = nullptr;
};

/// Adds `analytic` and its cases to `app`, filling `args`.
CLI::App* addAnalyticCommand(CLI::App& app, AnalyticArgs& args);

/// Whether the chosen case asks for the PETSc backend (MPI is started for it).
bool wantsPetsc(const AnalyticArgs& args);

/// Runs the chosen case: 0 when it converged, 3 when not; nullopt when no analytic case was chosen.
/// Throws what the case throws (std::invalid_argument for options it cannot take).
std::optional<int> runAnalyticCommand(const AnalyticArgs& args);

/// One case's result as JSON (the `--json` output; `study analytic --json` lists them).
nlohmann::json toJson(const analytic::AnalyticResult& r);

/// OpenMP threads for what follows (0: leave the default).
void applyThreads(int threads);

}  // namespace stokes::app
