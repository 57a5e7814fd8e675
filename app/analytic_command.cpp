// `stokesvdb analytic ...`: see analytic_command.h.
#include "app/analytic_command.h"

#include <CLI/CLI.hpp>
#include <fmt/core.h>
#include <omp.h>
#include <sys/resource.h>

#include <cmath>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "app/run_command.h"
#include "sim/scene/scene.h"
#include "sparse_grid/volume_weights.h"
#include "solver/step/solve_plan.h"
#include "solver/step/step_options.h"

namespace stokes::app {

namespace {

namespace solver = stokes::solver;
using analytic::AnalyticOptions;
using analytic::AnalyticResult;

/// Peak resident memory of this process so far in MB (getrusage; Linux reports KiB).
double peakResidentMB() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return double(usage.ru_maxrss) / 1024.0;
}

/// {"edge": tiles, ...}
nlohmann::json tilesByEdgeJson(const std::map<int, std::size_t>& byEdge) {
  nlohmann::json j = nlohmann::json::object();
  for (const auto& [edge, count] : byEdge) j[std::to_string(edge)] = count;
  return j;
}

void printHuman(const AnalyticResult& r) {
  fmt::print("{} ({}D, model {}, n {}): ", r.test, r.dim, r.model, r.n);
  if (r.measured) fmt::print("L1 {:.6g}  Linf {:.6g}\n", r.L1, r.Linf);
  else fmt::print("not measured, the solve ended {}\n", r.status);
  fmt::print("  solve: {} after {} iterations (relative residual {:.3g}), {} unknowns, Krylov vectors of {} rows "
             "({} padded)\n",
             r.status, r.iterations, r.relativeResidual, r.unknowns, r.krylovRows, r.paddedRows);
  fmt::print("  solver: {}\n", r.solver);
  fmt::print("  time: setup {:.3f} s, solve {:.3f} s, total {:.3f} s ({} threads); peak memory {:.0f} MB\n",
             r.setupSeconds, r.solveSeconds, r.totalSeconds, omp_get_max_threads(), peakResidentMB());
  if (r.multigridLevels > 0)
    fmt::print("  multigrid: {} levels, built in {:.3f} s (part of the solve time){}\n", r.multigridLevels,
               r.preconditionerSeconds, r.schurBlock.empty() ? "" : ", pressure block " + r.schurBlock);
  if (r.tiles > 0 || r.fallbackTiles > 0)
    fmt::print("  tiles: {} ({} reduced + {} Cartesian unknowns; {} keep fewer modes than the basis; {} fell back to "
               "Cartesian), fit Linf {:.3g}, tile set-up {:.3f} s, library {} hits / {} misses\n",
               r.tiles, r.reducedDofs, r.cartesianDofs, r.partialTiles, r.fallbackTiles, r.reconstructionLinf, r.tileSeconds,
               r.cacheHits, r.cacheMisses);
  if (!r.tileRule.empty())
    fmt::print("  tile rule: {}, {} tiles returned to Cartesian as not paying; kept tiles' estimated work per iteration: "
               "{:.0f} rows saved, {:.0f} rows of overhead\n",
               r.tileRule, r.unpaidTiles, r.tileWorkSaved, r.tileWorkOverhead);
  if (r.tilesByEdge.size() > 1) {
    std::string edges;
    for (auto it = r.tilesByEdge.rbegin(); it != r.tilesByEdge.rend(); ++it)
      edges += fmt::format("{}{} of edge {}", edges.empty() ? "" : ", ", it->second, it->first);
    fmt::print("  tile cubes: {}\n", edges);
  }
  if (r.facesDifference >= 0.0)
    fmt::print("  against the faces file: max |u - u_file| / max |u_file| = {:.3g} over {} faces\n", r.facesDifference,
               r.facesCompared);
  if (r.versusUniform >= 0.0)
    fmt::print("  versus the uniform model: rms difference {:.3g} of its rms velocity variation\n", r.versusUniform);
  if (r.theoryRate > 0.0)
    fmt::print("  decay rate {:.6g} against the linear theory's {:.6g} (ratio {:.4f}); quasi-static rate {:.6g}\n",
               r.rate, r.theoryRate, r.rate / r.theoryRate, r.quasiStaticRate);
  if (r.maxDivergence > 0.0 || r.kineticEnergyBefore > 0.0)
    fmt::print("  kinetic energy {:.6g} -> {:.6g}, max |div| {:.3g}\n", r.kineticEnergyBefore, r.kineticEnergyAfter,
               r.maxDivergence);
}

/// "auto" followed by a table's keys, for an option that planSolve may decide.
std::vector<std::string> withAuto(std::vector<std::string> keys) {
  keys.insert(keys.begin(), "auto");
  return keys;
}

/// The liquid-weight rules' names, from their one table (sparse_grid::kFractionRuleNames).
std::vector<std::string> fractionRuleKeys() {
  std::vector<std::string> keys;
  for (const auto& [name, rule] : stokes::sparse_grid::kFractionRuleNames) keys.emplace_back(name);
  return keys;
}

void addCaseOptions(CLI::App* app, CaseArgs& a) {
  app->add_option("--model", a.model, "uniform grid, or affine / quadratic reduced tiles")
      ->check(CLI::IsMember(solver::keysOf<stokes::sim::ModelType>()));
  app->add_option("--tile", a.tile, "tile size in cells (with --tile-min: the largest)")->check(CLI::Range(2, 1024));
  app->add_option("--tile-min", a.tileMin,
                  "adaptive tiles: cubes of --tile cells split in halves, down to this edge, where the quadratic "
                  "or affine fit of the start velocity misses by more than --tile-accuracy (0: one size)")
      ->check(CLI::Range(0, 1024));
  app->add_option("--tile-accuracy", a.tileAccuracy,
                  "with --tile-min: the largest rms misfit of a tile's fit, as a fraction of the liquid's rms "
                  "velocity variation (e.g. 0.02)")
      ->check(CLI::NonNegativeNumber);
  app->add_option("--tile-rule", a.tileRule,
                  "which tiles are kept: all, paying (only where the engine's work estimate says a tile saves "
                  "more than it costs), or auto (paying under the pressure-velocity multigrid, "
                  "else all)")
      ->check(CLI::IsMember(withAuto(solver::keysOf<solver::TileRule>())));
  app->add_option("--pad", a.pad, "Cartesian padding between tiles (>= 2 with viscosity)")->check(CLI::Range(0, 1024));
  app->add_option("--band-air", a.bandAir, "Cartesian band next to air")->check(CLI::Range(0, 64));
  app->add_option("--band-solid", a.bandSolid, "Cartesian band next to solids")->check(CLI::Range(0, 64));
  app->add_option("--min-region", a.minRegion, "regions narrower than this go back to Cartesian")
      ->check(CLI::Range(1, 1024));
  app->add_option("--family", a.family, "basis family: auto (full for viscosity, else divfree), divfree, full")
      ->group(kAdvanced)
      ->check(CLI::IsMember({"auto", "divfree", "full"}));
  app->add_option("--fit", a.fit, "least-squares fit faces: auto, boundary, all")
      ->group(kAdvanced)
      ->check(CLI::IsMember({"auto", "boundary", "all"}));
  app->add_option("--form", a.form,
                  "unified Stokes: spd (pressure-stress, CG), pv (pressure-velocity: GMRES with the multigrid, else "
                  "MINRES) or auto (pv with multigrid, the fastest; else spd)")
      ->check(CLI::IsMember(withAuto(solver::keysOf<solver::StokesForm>())));
  app->add_option("--tile-cache", a.tileCache, "tile factorisations: none, library (cube tiles), shapes (any shape)")
      ->group(kAdvanced)
      ->check(CLI::IsMember(solver::keysOf<stokes::sim::TileCache>()));
  app->add_option("--n", a.n, "resolution: cells across the box, or per unit length")->check(CLI::Range(2, 1 << 14));
  app->add_option("--dim", a.dim, "dimension (box-viscosity: 2 or 3)")->check(CLI::IsMember({2, 3}));
  app->add_option("--mu", a.mu, "dynamic viscosity")->check(CLI::NonNegativeNumber);
  app->add_option("--rho", a.rho, "density")->check(CLI::PositiveNumber);
  app->add_option("--dt", a.dt, "time step")->check(CLI::PositiveNumber);
  app->add_option("--tol", a.tol, "relative residual tolerance of the Krylov solve")->check(CLI::PositiveNumber);
  app->add_option("--max-iter", a.maxIterations, "iteration cap")->check(CLI::PositiveNumber);
  app->add_option("--threads", a.threads, "OpenMP threads (0: all cores)")->check(CLI::NonNegativeNumber);
  app->add_option("--solver", a.solverName,
                  "Krylov method: cg, bicgstab, minres, gmres, fgmres or auto (cg on the SPD form; on the "
                  "pressure-velocity form gmres with the multigrid's block upper-triangular preconditioner, "
                  "else minres)")
      ->check(CLI::IsMember(withAuto(solver::keysOf<solver::KrylovMethod>())));
  app->add_option("--precond", a.precond,
                  "none, jacobi, multigrid or auto (multigrid, except Jacobi for reduced tiles outside unified "
                  "Stokes, where the tiles are Jacobi rows beside the cycle)")
      ->check(CLI::IsMember(withAuto(solver::keysOf<solver::PreconditionerKind>())));
  app->add_option("--system", a.system,
                  "disk/ball: unified (Stokes), decoupled (viscosity then projection), pressure (projection only)")
      ->check(CLI::IsMember({solver::keyOf(solver::SystemKind::UnifiedStokes),
                             solver::keyOf(solver::SystemKind::DecoupledStokes),
                             solver::keyOf(solver::SystemKind::PressureProjection)}));
  app->add_option("--rows", a.rows,
                  "Krylov vectors on the live rows only (compact), on the padded blocks (padded), or auto "
                  "(compact when blocks are at most 2/3 live)")
      ->group(kAdvanced)
      ->check(CLI::IsMember(solver::keysOf<solver::RowStorage>()));
  app->add_option("--stencils", a.stencils,
                  "on live rows, the SPD form's stencils run over a compact neighbour index (rows) or sweep "
                  "the blocks holding the rows (blocks); the same operator bit for bit")
      ->group(kAdvanced)
      ->check(CLI::IsMember(solver::keysOf<solver::StencilSweep>()));
  app->add_option("--mg-degree", a.mgDegree,
                  "multigrid: Chebyshev smoother degree per pre- and post-smoothing (0: 3, or 2 for --form pv)")
      ->group(kAdvanced)
      ->check(CLI::Range(0, 16));
  app->add_option("--mg-range", a.mgRange,
                  "multigrid: the smoother damps eigenvalues of D^-1 A in [lambda_max / range, lambda_max]")
      ->group(kAdvanced)
      ->check(CLI::Range(1.5, 1000.0));
  app->add_option("--mg-schur", a.mgSchur,
                  "multigrid, --form pv: pressure block, diagonal (Schur diagonal estimate), cahouet-chabard (plus a "
                  "V-cycle of the projection) or auto (cahouet-chabard iff mu dt / (rho dx^2) < 10)")
      ->group(kAdvanced)
      ->check(CLI::IsMember(solver::keysOf<solver::SchurApproximation>()));
  app->add_option("--mg-interpolation", a.mgInterpolation,
                  "multigrid, --form pv, 3D: the velocity cycle's interpolation across the face normals, constant, "
                  "linear, or auto (linear iff mu dt / (rho dx^2) >= 1000; on PETSc the finest transfer stays "
                  "constant)")
      ->group(kAdvanced)
      ->check(CLI::IsMember(solver::keysOf<solver::FaceInterpolation>()));
  app->add_option("--backend", a.backend,
                  "who solves: in-house, or petsc (run under mpirun -np R; the SPD form unless --form pv or --precond "
                  "multigrid; PETSc "
                  "options such as -ksp_type cg -pc_type gamg follow anywhere on the line)")
      ->check(CLI::IsMember(solver::keysOf<solver::Backend>()));
  app->add_option("--liquid-weights", a.liquidWeights,
                  "disk, ball, surface-mode: W_L by plane cuts (plane-cut), by 3 sub-samples per axis (subsample), "
                  "or auto (the engine's rule, as the scenes: plane-cut)")
      ->group(kAdvanced)
      ->check(CLI::IsMember(withAuto(fractionRuleKeys())));
  app->add_flag("--json", a.json, "print one JSON object instead of text");
}

/// The value a table key names, or nullopt for "auto" (solver::planSolve decides).
template <class E>
std::optional<E> keyOrAuto(const std::string& key, const char* what) {
  if (key == "auto") return std::nullopt;
  return solver::parseKey<E>(key, what);
}

AnalyticOptions toOptions(const CaseArgs& a, double defaultMu) {
  AnalyticOptions o;
  if (a.liquidWeights != "auto") o.liquidWeights = stokes::sparse_grid::fractionRuleNamed(a.liquidWeights);
  o.model = a.model;
  o.tileSize = a.tile;
  o.padding = a.pad;
  o.bandAir = a.bandAir;
  o.bandSolid = a.bandSolid;
  o.minRegion = a.minRegion;
  o.minTileSize = a.tileMin;
  o.tileAccuracy = a.tileAccuracy;
  o.tileRule = keyOrAuto<solver::TileRule>(a.tileRule, "tile rule");
  o.family = a.family;
  o.fit = a.fit;
  o.form = keyOrAuto<solver::StokesForm>(a.form, "form");
  o.tileCache = a.tileCache;
  o.system = solver::parseKey<solver::SystemKind>(a.system, "system");
  o.n = a.n;
  o.dim = a.dim;
  o.mu = a.mu.value_or(defaultMu);
  o.rho = a.rho.value_or(1.0);
  o.dt = a.dt.value_or(1.0);
  o.tolerance = a.tol;
  o.maxIterations = a.maxIterations;
  o.method = keyOrAuto<solver::KrylovMethod>(a.solverName, "Krylov method");
  o.preconditioner = keyOrAuto<solver::PreconditionerKind>(a.precond, "preconditioner");
  o.solids = a.solids;
  o.rows = solver::parseKey<solver::RowStorage>(a.rows, "rows");
  o.rowStencils = solver::parseKey<solver::StencilSweep>(a.stencils, "stencils") == solver::StencilSweep::Rows;
  o.multigridDegree = a.mgDegree;
  o.multigridRange = a.mgRange;
  o.backend = solver::parseKey<solver::Backend>(a.backend, "backend");
  o.multigridSchur = solver::parseKey<solver::SchurApproximation>(a.mgSchur, "pressure block");
  o.multigridInterpolation = solver::parseKey<solver::FaceInterpolation>(a.mgInterpolation, "interpolation");
  return o;
}

int report(const AnalyticResult& r, bool json) {
  // every rank takes part in the sum; only rank 0 prints (the others' stdout is closed)
  const double peakAllRanks = mpi::sumOverRanks(peakResidentMB()), peakLargest = mpi::maxOverRanks(peakResidentMB());
  const int ranks = mpi::ranks();
  if (json) {
    nlohmann::json j = toJson(r);
    j["ranks"] = ranks;
    j["peak_rss_mb_all_ranks"] = peakAllRanks;
    j["peak_rss_mb_largest_rank"] = peakLargest;
    fmt::print("{}\n", j.dump());
  } else {
    printHuman(r);
    if (ranks > 1)
      fmt::print("  {} MPI ranks: peak memory {:.0f} MB over all ranks, {:.0f} MB on the largest\n", ranks, peakAllRanks,
                 peakLargest);
  }
  return r.status == "Converged" ? 0 : 3;
}

}  // namespace

nlohmann::json toJson(const AnalyticResult& r) {
  return {{"test", r.test},
          {"model", r.model},
          {"dim", r.dim},
          {"n", r.n},
          {"mu", r.mu},
          {"rho", r.rho},
          {"dt", r.dt},
          {"L1", r.L1},
          {"Linf", r.Linf},
          {"iterations", r.iterations},
          {"unknowns", r.unknowns},
          {"padded_rows", r.paddedRows},
          {"krylov_rows", r.krylovRows},
          {"relative_residual", r.relativeResidual},
          {"setup_seconds", r.setupSeconds},
          {"solve_seconds", r.solveSeconds},
          {"preconditioner_seconds", r.preconditionerSeconds},
          {"multigrid_levels", r.multigridLevels},
          {"schur_block", r.schurBlock},
          {"solver", r.solver},
          {"total_seconds", r.totalSeconds},
          {"kinetic_energy_before", r.kineticEnergyBefore},
          {"kinetic_energy_after", r.kineticEnergyAfter},
          {"max_divergence", r.maxDivergence},
          {"tiles", r.tiles},
          {"fallback_tiles", r.fallbackTiles},
          {"partial_tiles", r.partialTiles},
          {"unpaid_tiles", r.unpaidTiles},
          {"tile_rule", r.tileRule},
          {"tile_work_saved", r.tileWorkSaved},
          {"tile_work_overhead", r.tileWorkOverhead},
          {"tiles_by_edge", tilesByEdgeJson(r.tilesByEdge)},
          {"versus_uniform", r.versusUniform},
          {"faces_difference", r.facesDifference},
          {"faces_compared", r.facesCompared},
          {"rate", r.rate},
          {"theory_rate", r.theoryRate},
          {"quasi_static_rate", r.quasiStaticRate},
          {"tile_cache_hits", r.cacheHits},
          {"tile_cache_misses", r.cacheMisses},
          {"reduced_dofs", r.reducedDofs},
          {"cartesian_dofs", r.cartesianDofs},
          {"reconstruction_Linf", r.reconstructionLinf},
          {"tile_setup_seconds", r.tileSeconds},
          {"threads", omp_get_max_threads()},
          {"peak_rss_mb", peakResidentMB()},
          {"status", r.status},
          {"measured", r.measured}};
}

void applyThreads(int threads) {
  if (threads > 0) omp_set_num_threads(threads);
}

CLI::App* addAnalyticCommand(CLI::App& app, AnalyticArgs& a) {
  CLI::App* analytic = app.add_subcommand("analytic", "run one analytic verification case");
  analytic->require_subcommand(1);
  a.boxCmd = analytic->add_subcommand("box-viscosity", "viscosity-only box test (thesis 5.3)");
  addCaseOptions(a.boxCmd, a.box);
  a.diskCmd = analytic->add_subcommand("disk-stokes", "free-surface Stokes disk (thesis 5.4)");
  addCaseOptions(a.diskCmd, a.disk);
  a.ballCmd = analytic->add_subcommand("ball", "3D liquid ball, one unified Stokes step");
  addCaseOptions(a.ballCmd, a.ball);
  a.ballCmd->add_flag("--solids", a.ball.solids, "rest the ball on a solid floor around a solid sphere");
    for (CLI::App* cmd : {a.diskCmd, a.ballCmd})
    cmd->add_option("--rank-setup", a.rankSetup,
                    "--backend petsc: each rank builds the blocks it owns and a halo, as deep as its tiles reach (own), "
                    "or every rank the whole problem (whole; always with adaptive tiles or tiles in the PV form)")
        ->group(kAdvanced)
        ->check(CLI::IsMember({"own", "whole"}))
        ->capture_default_str();
    a.ballCmd->add_option("--faces-out", a.facesOut, "write the liquid's face velocities to this file (one rank)");
  a.ballCmd->add_option("--faces-compare", a.facesCompare,
                      "compare the face velocities with a --faces-out file: max |u - u_file| / max |u_file|")
      ->check(CLI::ExistingFile);
    a.ballCmd->add_flag("--versus-uniform", a.versusUniform,
                    "reduced models: also solve the uniform one (not timed) and report the rms difference");
    a.surfaceCmd = analytic->add_subcommand(
      "surface-mode", "a small disturbance of a viscous pool's surface, one unified Stokes step against linear theory");
  addCaseOptions(a.surfaceCmd, a.surface);
  a.surfaceCmd->add_option("--shape", a.surfaceShape.shape,
                         "mode (a Fourier mode over the box, n cells per wavelength) or gaussian (one bump or dimple, "
                         "n cells per unit length)")
      ->check(CLI::IsMember({"mode", "gaussian"}));
  a.surfaceCmd->add_option("--amplitude", a.surfaceShape.amplitude,
                         "height of the crest in cells: > 0 a bump at the centre, < 0 a dimple");
  a.surfaceCmd->add_option("--radius", a.surfaceShape.radius, "gaussian: the feature's radius (2 standard deviations) in cells");
  a.surfaceCmd->add_option("--crest-offset", a.surfaceShape.crestOffset,
                         "the crest's offset from the box's centre along each horizontal axis, in cells");
  a.surfaceCmd->add_option("--level-offset", a.surfaceShape.levelOffset,
                         "the mean surface's height above the grid line at depth 1, in cells");
    a.surfaceCmd->add_option("--width", a.surfaceWidth, "box width in wavelengths (mode, default 4) or units (gaussian, default 8)")
      ->check(CLI::Range(2, 64));
  return analytic;
}

bool wantsPetsc(const AnalyticArgs& a) {
  return (*a.diskCmd && a.disk.backend == "petsc") || (*a.ballCmd && a.ball.backend == "petsc") ||
         (*a.boxCmd && a.box.backend == "petsc");
}

std::optional<int> runAnalyticCommand(const AnalyticArgs& a) {
  if (*a.boxCmd) {
    applyThreads(a.box.threads);
    return report(stokes::analytic::runBoxViscosity(toOptions(a.box, 1.0)), a.box.json);
  }
  if (*a.diskCmd) {
    applyThreads(a.disk.threads);
    AnalyticOptions o = toOptions(a.disk, 0.1);
    o.rankSetup = a.rankSetup;
    return report(stokes::analytic::runDiskStokes(o), a.disk.json);
  }
  if (*a.ballCmd) {
    applyThreads(a.ball.threads);
    AnalyticOptions o = toOptions(a.ball, 1.0);
    o.versusUniform = a.versusUniform;
    o.rankSetup = a.rankSetup;
    o.facesOut = a.facesOut;
    o.facesCompare = a.facesCompare;
    return report(stokes::analytic::runBall(o), a.ball.json);
  }
  if (*a.surfaceCmd) {
    applyThreads(a.surface.threads);
    AnalyticOptions o = toOptions(a.surface, 1.0);
    o.shape = a.surfaceShape.shape;
    o.amplitude = a.surfaceShape.amplitude;
    o.radius = a.surfaceShape.radius;
    o.crestOffset = a.surfaceShape.crestOffset;
    o.levelOffset = a.surfaceShape.levelOffset;
    if (a.surfaceCmd->count("--width") > 0) o.width = a.surfaceWidth;
    return report(stokes::analytic::runSurfaceMode(o), a.surface.json);
  }
  return std::nullopt;
}

}  // namespace stokes::app
