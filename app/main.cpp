// stokesvdb: the command-line program. One file per command:
//   stokesvdb run SCENE --out DIR [options]       simulate a scene (run_command.h)
//   stokesvdb compare A.vdb B.vdb                 two frames' symmetric volume difference (run_command.h)
//   stokesvdb analytic CASE [options]             one analytic verification case (analytic_command.h)
//   stokesvdb study analytic|accuracy-time        the convergence and accuracy-time studies (study_command.h)
// Before any work: the passive OpenMP wait policy and the heap policy (their headers say why).
#include <CLI/CLI.hpp>
#include <fmt/core.h>
#include "sparse_grid/vdb_trees.h"

#include <algorithm>
#include <cstdio>
#include <exception>
#include <string>
#include <vector>

#include "app/analytic_command.h"
#include "app/memory_policy.h"
#include "app/openmp_wait_policy.h"
#include "app/run_command.h"
#include "app/study_command.h"

namespace mpi = stokes::app::mpi;

int main(int argc, char** argv) {
  stokes::app::choosePassiveWaitPolicy(argv);  // before any OpenMP region (see its header)
  stokes::app::keepFreedMemory();              // before the first large allocation (see its header)
  openvdb::initialize();
  CLI::App app{"StokesVDB: variational Stokes for highly viscous liquids on OpenVDB grids", "stokesvdb"};
  app.set_version_flag("--version", std::string("stokesvdb ") + STOKES_VERSION);
  app.require_subcommand(1);

  stokes::app::RunArgs runArgs;
  CLI::App* runCmd = stokes::app::addRunCommand(app, runArgs);
  stokes::app::CompareArgs compareArgs;
  CLI::App* compareCmd = stokes::app::addCompareCommand(app, compareArgs);
  stokes::app::AnalyticArgs analyticArgs;
  stokes::app::addAnalyticCommand(app, analyticArgs);
  stokes::app::StudyArgs studyArgs;
  stokes::app::addStudyCommand(app, studyArgs);

  // PETSc's own options (-ksp_type cg -pc_type gamg ...) go to its options database; CLI11 parses
  // the rest.
  std::vector<std::string> words(argv + 1, argv + argc), rest, petscOptions;
  mpi::splitPetscOptions(words, rest, petscOptions);
  std::reverse(rest.begin(), rest.end());  // CLI11 takes a reversed vector
  try {
    app.parse(rest);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  [[maybe_unused]] mpi::Session petsc;  // finalises PETSc and MPI at exit if they were started
  const bool petscBackend = stokes::app::wantsPetsc(analyticArgs);
  if (!petscOptions.empty() && !petscBackend && !*runCmd) {
    fmt::print(stderr, "stokesvdb: error: PETSc options ({} ...) need --backend petsc\n", petscOptions.front());
    return 2;
  }
  if (petscBackend) {
    try {
      mpi::Session::initialise(petscOptions);
    } catch (const std::exception& e) {
      fmt::print(stderr, "stokesvdb: error: {}\n", e.what());
      return 2;
    }
    if (mpi::rank() != 0 && !std::freopen("/dev/null", "w", stdout)) return 2;
  }
  runArgs.petscOptions = petscOptions;
  if (*runCmd) return stokes::app::runRunCommand(runArgs);
  if (*compareCmd) return stokes::app::runCompareCommand(compareArgs);
  try {
    if (const auto status = stokes::app::runAnalyticCommand(analyticArgs)) return *status;
    if (const auto status = stokes::app::runStudyCommand(studyArgs)) return *status;
  } catch (const std::exception& e) {
    fmt::print(stderr, "stokesvdb: error: {}\n", e.what());
    return 2;
  }
  return 0;
}
