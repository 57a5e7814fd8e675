// `stokesvdb run`: see run_command.h.
#include "app/run_command.h"

#include <CLI/CLI.hpp>
#include <fmt/core.h>
#include <omp.h>

#include <unistd.h>

#include <csignal>
#include <filesystem>
#include <optional>
#include <iostream>
#include <limits>
#include <string>

#include "app/openmp_wait_policy.h"
#include "sim/geometry/geometry.h"
#include "sim/output/vdb_frame.h"
#include "sim/ranks/rank_comm.h"
#include "sim/run/scene_runner.h"
#include "sim/step/stokes_stage.h"
#ifdef STOKES_HAVE_PETSC
#include <mpi.h>

#include "solver/petsc/petsc_krylov.h"
#endif

namespace stokes::app {

namespace {

/// One solver choice as the start line names it: system, form, Krylov method, preconditioner and
/// tolerance.
std::string describeOptions(const sim::Scene& scene, const solver::StepOptions& o) {
  const char* method = solver::toString(o.method.value());
  const char* preconditioner = solver::toString(o.preconditioner);
  std::string system;
  switch (o.system) {
    case solver::SystemKind::UnifiedStokes:
      system = o.form == solver::StokesForm::PressureStress ? "unified Stokes, pressure-stress form (SPD)"
                                                            : "unified Stokes, pressure-velocity form";
      break;
    case solver::SystemKind::Viscosity:
    case solver::SystemKind::DecoupledStokes: system = "viscosity, then pressure projection"; break;
    case solver::SystemKind::PressureProjection: system = "pressure projection"; break;
  }
  const char* blockRows = o.rows == solver::RowStorage::Compact ? "live rows" : "live rows where blocks are under 2/3 live";
  const char* spdRows = o.rowStencils ? "live rows, neighbour-index stencils" : blockRows;
  std::string rows;
  if (o.rows == solver::RowStorage::Padded) rows = "padded blocks";
  else if (o.system == solver::SystemKind::UnifiedStokes)
    rows = o.form == solver::StokesForm::PressureStress ? spdRows
           : o.rowStencils                             ? "live rows, neighbour-index stencils"
                                                       : "live rows";
  else if (o.system == solver::SystemKind::PressureProjection) rows = spdRows;
  else rows = fmt::format("{} (projection: {})", blockRows, spdRows);
  const bool warm = scene.solver.warmStart;
  if (o.backend == solver::Backend::Petsc)
    return fmt::format("{}; PETSc (method and preconditioner from its options database, default CG + Jacobi) on the "
                       "MPI ranks, relative tolerance {:g}{}",
                       system, o.krylov.relativeTolerance, scene.solver.warmStart ? "; warm start from the previous step" : "");
  return fmt::format("{}; {} + {}, relative tolerance {:g}; Krylov vectors on {}{}{}", system, method, preconditioner,
                     o.krylov.relativeTolerance, rows, warm ? "; warm start from the previous step" : "",
                     o.threads == 1 ? "; on one thread" : "");
}

/// The solve a scene's steps run (sim::planStokes chooses it from the scene): one choice, or the
/// two a step picks between by its viscous number and size (solver::kMultigridMinViscousNumber,
/// solver::kMultigridMinLiquidCells, solver::kMultigridSmallStepMinViscousNumber; an open
/// preconditioner), and the thread count of small solves.
std::string describeSolve(const sim::Scene& scene) {
  const sim::StokesPlan plan = sim::planStokes(scene, nullptr);
  static_assert(solver::kParallelSolveMinLiquidCells == solver::kMultigridMinLiquidCells,
                "the start line names one size at which the plan changes");
  const std::size_t threshold = solver::kMultigridMinLiquidCells;
  const double inf = std::numeric_limits<double>::infinity();
  const solver::StepOptions viscous = plan.optionsFor(threshold, inf), inertial = plan.optionsFor(threshold, 0.0),
                            smallInertial = plan.optionsFor(threshold - 1, 0.0);
  const std::string oneThread =
      smallInertial.threads == 1 ? fmt::format("; steps below {} liquid cells on one thread", threshold) : "";
  if (inertial.preconditioner == viscous.preconditioner && inertial.form == viscous.form)
    return describeOptions(scene, viscous) + oneThread;
  return fmt::format("chosen per step -- a viscous number mu dt/(rho dx^2) below {:g}, or below {:g} with fewer than "
                     "{} liquid cells: {} | else: {}{}",
                     solver::kMultigridMinViscousNumber, solver::kMultigridSmallStepMinViscousNumber, threshold,
                     describeOptions(scene, inertial), describeOptions(scene, viscous), oneThread);
}

/// The signal that asked the run to stop (0: none). A second signal takes the default action.
volatile std::sig_atomic_t g_stopSignal = 0;

extern "C" void requestStop(int signal) {
  g_stopSignal = signal;
  std::signal(signal, SIG_DFL);
}

/// The command line's options that change a run's results (not --frames, --threads, --out).
std::string optionSignature(const RunArgs& a) {
  auto opt = [](const char* name, const std::optional<std::string>& v) {
    return v ? fmt::format(" {}={}", name, *v) : std::string();
  };
  return fmt::format("res={}", a.resolution ? std::to_string(*a.resolution) : std::string("scene")) +
         opt("model", a.model) + opt("viscosity", a.viscosity) + opt("rows", a.rows) + opt("stencils", a.stencils) +
         opt("warm-start", a.warmStart);
}

}  // namespace

CLI::App* addRunCommand(CLI::App& app, RunArgs& args) {
  CLI::App* cmd = app.add_subcommand("run", "simulate a scene file (scenes/*.json) into --out DIR");
  cmd->add_option("scene", args.scene,
                  "scene file (JSON, schema in scenes/README.md), or the name of a shipped scene (honey_coil)")
      ->required();
  cmd->add_option("--out", args.outDir, "output folder: frame_NNNN.vdb / .png, stats.csv")->required();
  cmd->add_option("--frames", args.frames, "number of frames (overrides the scene's)");
  cmd->add_option("--res", args.resolution, "cells along the longest domain axis (overrides the scene's)");
  cmd->add_option("--threads", args.threads, "OpenMP threads (0: all cores)")->check(CLI::NonNegativeNumber);
  cmd->add_option("--model", args.model, "replace the scene's model.type (tile parameters stay the file's)")
      ->check(CLI::IsMember(solver::keysOf<sim::ModelType>()));
  cmd->add_option("--viscosity", args.viscosity, "replace the scene's viscosity mode")
      ->check(CLI::IsMember(sim::viscosityModeKeys()));
  cmd->add_option("--rows", args.rows, "replace the scene's solver.rows (Krylov vectors on live rows or padded blocks)")
      ->group(kAdvanced)
      ->check(CLI::IsMember(solver::keysOf<solver::RowStorage>()));
  cmd->add_option("--stencils", args.stencils, "replace the scene's solver.stencils (rows: neighbour index, blocks: block sweep)")
      ->group(kAdvanced)
      ->check(CLI::IsMember(solver::keysOf<solver::StencilSweep>()));
  cmd->add_option("--warm-start", args.warmStart,
                  "replace the scene's solver.warm_start (on: each solve starts from the previous step's unknowns)")
      ->group(kAdvanced)
      ->check(CLI::IsMember({"on", "off"}));
  cmd->add_option("--backend", args.backend,
                  "replace the scene's solver.backend: in-house, or petsc (mpirun -np R stokesvdb run ...; PETSc "
                  "options such as -pc_type gamg anywhere on the line)")
      ->check(CLI::IsMember(solver::keysOf<solver::Backend>()));
  cmd->add_flag("--resume", args.resume,
                "continue the run in --out from its newest checkpoint (same scene and options; --frames may "
                "extend it)");
  return cmd;
}

CLI::App* addCompareCommand(CLI::App& app, CompareArgs& args) {
  CLI::App* cmd = app.add_subcommand("compare", "symmetric volume difference of two liquid level sets (.vdb)");
  cmd->add_option("a", args.a, "first level set (a frame_NNNN.vdb of `run`)")->required();
  cmd->add_option("b", args.b, "second level set")->required();
  cmd->add_flag("--json", args.json, "print one JSON object");
  return cmd;
}

int runCompareCommand(const CompareArgs& args) {
  openvdb::FloatGrid::Ptr a, b;
  try {
    a = sim::readLiquidGrid(args.a);
    b = sim::readLiquidGrid(args.b);
  } catch (const std::exception& e) {
    fmt::print(stderr, "stokesvdb compare: {}\n", e.what());
    return 2;
  }
  const double va = sim::levelSetVolume(*a), vb = sim::levelSetVolume(*b);
  const double diff = sim::symmetricVolumeDifference(*a, *b);
  const double relA = va > 0.0 ? diff / va : NAN, relB = vb > 0.0 ? diff / vb : NAN;
  if (args.json)
    fmt::print("{{\"volume_a\": {:.9g}, \"volume_b\": {:.9g}, \"symmetric_difference\": {:.9g}, "
               "\"relative_to_a\": {:.6g}, \"relative_to_b\": {:.6g}}}\n",
               va, vb, diff, relA, relB);
  else
    fmt::print("volume A {:.6g} m^3, volume B {:.6g} m^3 ({:+.2f}%), symmetric difference {:.6g} m^3 = {:.2f}% of A, "
               "{:.2f}% of B\n",
               va, vb, 100.0 * (vb / va - 1.0), diff, 100.0 * relA, 100.0 * relB);
  return 0;
}

std::vector<std::filesystem::path> sceneDirectories() {
  namespace fs = std::filesystem;
  std::vector<fs::path> dirs;
  std::error_code error;
  const fs::path program = fs::read_symlink("/proc/self/exe", error);
  if (!error) dirs.push_back(program.parent_path().parent_path() / "share" / "stokesvdb" / "scenes");
  dirs.emplace_back(STOKES_SOURCE_SCENES_DIR);
  return dirs;
}

std::optional<std::string> findScene(const std::string& name, std::string& searched) {
  namespace fs = std::filesystem;
  std::error_code error;
  if (fs::is_regular_file(name, error)) return name;
  if (fs::path(name).is_absolute()) return std::nullopt;
  for (const fs::path& dir : sceneDirectories()) {
    searched += (searched.empty() ? "" : ", ") + dir.lexically_normal().string();
    for (const std::string& file : {name, name + ".json"})
      if (fs::is_regular_file(dir / file, error)) return (dir / file).lexically_normal().string();
  }
  return std::nullopt;
}

int runRunCommand(const RunArgs& args) {
  std::string searched;
  const std::optional<std::string> sceneFile = findScene(args.scene, searched);
  if (!sceneFile) {
    fmt::print(stderr, "stokesvdb run: scene '{}': no such file here{}\n", args.scene,
               searched.empty() ? std::string() : ", nor among the shipped scenes (" + searched + ")");
    return 2;
  }
  sim::Scene scene;
  try {
    scene = sim::loadScene(*sceneFile, sim::SceneOverrides{args.resolution, args.frames});
  } catch (const sim::SceneError& e) {
    fmt::print(stderr, "stokesvdb run: {}\n", e.what());
    return 2;
  }
  if (args.model) scene.model.type = solver::parseKey<sim::ModelType>(*args.model, "model");
  if (args.viscosity) scene.system = sim::parseViscosityMode(*args.viscosity);
  if (args.rows) scene.solver.rows = solver::parseKey<solver::RowStorage>(*args.rows, "rows");
  if (args.stencils)
    scene.solver.rowStencils =
        solver::parseKey<solver::StencilSweep>(*args.stencils, "stencils") == solver::StencilSweep::Rows;
  if (args.warmStart) scene.solver.warmStart = *args.warmStart == "on";
  if (args.backend) scene.solver.backend = solver::parseKey<solver::Backend>(*args.backend, "backend");
  if (args.threads > 0) omp_set_num_threads(args.threads);
  std::string solveLine;
  try {
    solveLine = describeSolve(scene);
  } catch (const std::invalid_argument& e) {
    fmt::print(stderr, "stokesvdb run: {}\n", e.what());
    return 2;
  }
  const bool petsc = scene.solver.backend == solver::Backend::Petsc;
  if (!args.petscOptions.empty() && !petsc) {
    fmt::print(stderr, "stokesvdb run: PETSc options ({} ...) need solver.backend \"petsc\" or --backend petsc\n",
               args.petscOptions.front());
    return 2;
  }
#ifdef STOKES_HAVE_PETSC
  if (petsc) {
    try {
      solver::petsc::Session::initialise(args.petscOptions);
    } catch (const std::exception& e) {
      fmt::print(stderr, "stokesvdb run: {}\n", e.what());
      return 2;
    }
    // every rank runs the scene, each with the particles and grid of its blocks (sim::splitsOverRanks)
  }
  const bool reports = solver::petsc::rank() == 0;
#else
  if (petsc) {
    fmt::print(stderr, "stokesvdb run: solver.backend \"petsc\": this build has no PETSc backend (install PETSc with "
                       "scripts/install_deps.sh and configure with -DSTOKES_WITH_PETSC=ON)\n");
    return 2;
  }
  const bool reports = true;
#endif
  if (reports)
    fmt::print(stderr,
             "stokesvdb run: {} at res {} ({} x {} x {} cells, dx = {:g} m), {} frames, model {}, viscosity {}, "
             "liquid weights {}; {} OpenMP threads, wait policy {}\nstokesvdb run: solve: {}\n",
             scene.name, scene.resolution, scene.resolutionCells()[0], scene.resolutionCells()[1],
             scene.resolutionCells()[2], scene.dx(), scene.frames, sim::toString(scene.model.type),
             sim::viscosityModeKey(scene.system),
             sparse_grid::fractionRuleName(scene.liquidWeights),
             omp_get_max_threads(), waitPolicy(), solveLine);
  sim::RunOptions options;
  options.outDir = args.outDir;
  options.progress = reports ? &std::cerr : nullptr;
  options.progressIsTerminal = ::isatty(STDERR_FILENO) == 1;
  options.resume = args.resume;
  options.signature = optionSignature(args);
  options.stopRequested = [] { return g_stopSignal != 0; };
  std::signal(SIGINT, requestStop);
  std::signal(SIGTERM, requestStop);
  try {
    const sim::RunSummary s = sim::runScene(scene, options);
    const bool split = sim::splitsOverRanks(scene);
    const double peakLargest = split ? sim::maxOverRanks(double(s.peakResidentBytes)) : double(s.peakResidentBytes);
    if (!reports) return s.stopped ? 128 + int(g_stopSignal) : 0;
    if (s.stopped) {
      fmt::print(stderr, "stokesvdb run: stopped by signal {} after {} steps; checkpoint {}; continue with --resume\n",
                 int(g_stopSignal), s.stepsTotal, s.lastCheckpoint);
      return 128 + int(g_stopSignal);
    }
    // A scene that starts empty (emitters only) has no volume to drift from.
    const std::string drift = s.initialVolume > 0.0
                                  ? fmt::format("{:+.2f}%", 100.0 * (s.finalVolume / s.initialVolume - 1.0))
                                  : std::string("emitted");
    fmt::print(stderr,
               "stokesvdb run: {} frames, {} steps in {:.1f} s ({:.2f} s per frame); liquid volume {:.6g} -> {:.6g} "
               "m^3 ({}); at most {} iterations per step; {} steps retried with a smaller dt; output in {}\n",
               s.frames, s.steps, s.wallSeconds, s.wallSeconds / std::max(s.frames, 1), s.initialVolume,
               s.finalVolume, drift, s.maxIterations, s.retriedSteps, args.outDir);
    double stageTotal = 0.0;
    for (const auto& [name, seconds] : s.stageSeconds) stageTotal += seconds;
    std::string stages;
    for (const auto& [name, seconds] : s.stageSeconds)
      stages += fmt::format("{}{} {:.1f} s ({:.0f}%)", stages.empty() ? "" : ", ", name, seconds,
                            stageTotal > 0.0 ? 100.0 * seconds / stageTotal : 0.0);
    fmt::print(stderr, "stokesvdb run: stages: {}; peak memory {:.0f} MB{}\n", stages.empty() ? "none" : stages,
               peakLargest / (1024.0 * 1024.0),
               split ? fmt::format(" on the largest of {} ranks, each holding the particles of its blocks", sim::rankCount())
                     : std::string());
  } catch (const sim::SimulationError& e) {  // (every rank of a split run fails the same step)
    if (reports)
      fmt::print(stderr, "stokesvdb run: failed: {}\n(frames written so far are kept in {})\n", e.what(), args.outDir);
    return 1;
  } catch (const sim::ResumeError& e) {
    if (reports) fmt::print(stderr, "stokesvdb run: {}\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    fmt::print(stderr, "stokesvdb run{}: failed: {}\n(frames written so far are kept in {})\n",
               reports ? "" : fmt::format(" (rank {})", sim::thisRank()), e.what(), args.outDir);
#ifdef STOKES_HAVE_PETSC
    // an error on one rank of a split run would leave the others waiting for it
    if (sim::splitsOverRanks(scene) && sim::rankCount() > 1) MPI_Abort(MPI_COMM_WORLD, 1);
#endif
    return 1;
  }
  return 0;
}

}  // namespace stokes::app
