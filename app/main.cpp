// stokesvdb: command-line front end.
//   stokesvdb analytic box-viscosity|disk-stokes|ball|surface-mode [options]   one analytic case
//   stokesvdb study analytic [--max-n N]                           the convergence table
#include <CLI/CLI.hpp>
#include <fmt/core.h>
#include <omp.h>
#include <sys/resource.h>
#include "sparse_grid/vdb_trees.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <exception>
#include <nlohmann/json.hpp>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "analytic/analytic_cases.h"
#include "app/accuracy_time_study.h"
#include "app/memory_policy.h"
#include "app/openmp_wait_policy.h"
#include "app/run_command.h"
#include "sim/scene/scene.h"
#include "solver/step/solve_plan.h"
#include "solver/step/step_options.h"
#ifdef STOKES_HAVE_PETSC
#include "solver/petsc/petsc_krylov.h"
#endif

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

namespace {

namespace solver = stokes::solver;
using stokes::analytic::AnalyticOptions;
using stokes::app::kAdvanced;
using stokes::analytic::AnalyticResult;

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

/// The analytic cases' defaults (stated once, in AnalyticOptions).
const stokes::analytic::AnalyticOptions kCaseDefaults{};

struct CommonArgs {
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
  int mgDegree = stokes::solver::MultigridOptions{}.smootherDegree;
  double mgRange = stokes::solver::MultigridOptions{}.smootherRange;
  std::string mgSchur = "auto", mgInterpolation = "auto";
  std::string backend = "in-house";
  std::string liquidWeights = "auto";
};

void addCommonOptions(CLI::App* app, CommonArgs& a) {
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
      ->check(CLI::IsMember({"rows", "blocks"}));
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

AnalyticOptions toOptions(const CommonArgs& a, double defaultMu) {
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
  o.rowStencils = a.stencils == "rows";
  o.multigridDegree = a.mgDegree;
  o.multigridRange = a.mgRange;
  o.backend = solver::parseKey<solver::Backend>(a.backend, "backend");
  o.multigridSchur = solver::parseKey<solver::SchurApproximation>(a.mgSchur, "pressure block");
  o.multigridInterpolation = solver::parseKey<solver::FaceInterpolation>(a.mgInterpolation, "interpolation");
  return o;
}

void applyThreads(int threads) {
  if (threads > 0) omp_set_num_threads(threads);
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

/// The main job until scenes exist: convergence tables of the analytic cases against the thesis.
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

int main(int argc, char** argv) {
  stokes::app::choosePassiveWaitPolicy(argv);  // before any OpenMP region (see its header)
  stokes::app::keepFreedMemory();              // before the first large allocation (see its header)
  openvdb::initialize();
  CLI::App app{"StokesVDB: variational Stokes for highly viscous liquids on OpenVDB grids", "stokesvdb"};
  app.set_version_flag("--version", std::string("stokesvdb ") + STOKES_VERSION);
  app.require_subcommand(1);

  CLI::App* analytic = app.add_subcommand("analytic", "run one analytic verification case");
  analytic->require_subcommand(1);
  CommonArgs box, disk, ball;
  CLI::App* boxCmd = analytic->add_subcommand("box-viscosity", "viscosity-only box test (thesis 5.3)");
  addCommonOptions(boxCmd, box);
  CLI::App* diskCmd = analytic->add_subcommand("disk-stokes", "free-surface Stokes disk (thesis 5.4)");
  addCommonOptions(diskCmd, disk);
  CLI::App* ballCmd = analytic->add_subcommand("ball", "3D liquid ball, one unified Stokes step");
  addCommonOptions(ballCmd, ball);
  ballCmd->add_flag("--solids", ball.solids, "rest the ball on a solid floor around a solid sphere");
  std::string rankSetup = "own";
  for (CLI::App* cmd : {diskCmd, ballCmd})
    cmd->add_option("--rank-setup", rankSetup,
                    "--backend petsc: each rank builds the blocks it owns and a halo, as deep as its tiles reach (own), "
                    "or every rank the whole problem (whole; always with adaptive tiles or tiles in the PV form)")
        ->group(kAdvanced)
        ->check(CLI::IsMember({"own", "whole"}))
        ->capture_default_str();
  std::string facesOut, facesCompare;
  ballCmd->add_option("--faces-out", facesOut, "write the liquid's face velocities to this file (one rank)");
  ballCmd->add_option("--faces-compare", facesCompare,
                      "compare the face velocities with a --faces-out file: max |u - u_file| / max |u_file|")
      ->check(CLI::ExistingFile);
  bool versusUniform = false;
  ballCmd->add_flag("--versus-uniform", versusUniform,
                    "reduced models: also solve the uniform one (not timed) and report the rms difference");
  CommonArgs surface;
  AnalyticOptions surfaceShape;
  CLI::App* surfaceCmd = analytic->add_subcommand(
      "surface-mode", "a small disturbance of a viscous pool's surface, one unified Stokes step against linear theory");
  addCommonOptions(surfaceCmd, surface);
  surfaceCmd->add_option("--shape", surfaceShape.shape,
                         "mode (a Fourier mode over the box, n cells per wavelength) or gaussian (one bump or dimple, "
                         "n cells per unit length)")
      ->check(CLI::IsMember({"mode", "gaussian"}));
  surfaceCmd->add_option("--amplitude", surfaceShape.amplitude,
                         "height of the crest in cells: > 0 a bump at the centre, < 0 a dimple");
  surfaceCmd->add_option("--radius", surfaceShape.radius, "gaussian: the feature's radius (2 standard deviations) in cells");
  surfaceCmd->add_option("--crest-offset", surfaceShape.crestOffset,
                         "the crest's offset from the box's centre along each horizontal axis, in cells");
  surfaceCmd->add_option("--level-offset", surfaceShape.levelOffset,
                         "the mean surface's height above the grid line at depth 1, in cells");
  int surfaceWidth = 0;
  surfaceCmd->add_option("--width", surfaceWidth, "box width in wavelengths (mode, default 4) or units (gaussian, default 8)")
      ->check(CLI::Range(2, 64));

  CLI::App* study = app.add_subcommand("study", "run a study");
  study->require_subcommand(1);
  int maxN = 256, max3d = 64, studyThreads = 0;
  bool studyJson = false;
  CLI::App* studyAnalytic = study->add_subcommand("analytic", "convergence table of the analytic cases");
  studyAnalytic->add_option("--max-n", maxN, "largest 2D resolution")->check(CLI::Range(16, 4096));
  studyAnalytic->add_option("--max-n-3d", max3d, "largest 3D resolution")->check(CLI::Range(16, 512));
  studyAnalytic->add_option("--threads", studyThreads, "OpenMP threads (0: all cores)");
  studyAnalytic->add_flag("--json", studyJson, "print JSON");
  std::string studyModels = "uniform,affine,quadratic";
  studyAnalytic->add_option("--models", studyModels, "comma-separated subset of uniform,affine,quadratic");

  stokes::app::AccuracyTimeOptions accuracy;
  CLI::App* accuracyCmd =
      study->add_subcommand("accuracy-time", "error and wall time of every model over N and tilings (CSV + PNG)");
  accuracyCmd->add_option("--out", accuracy.outDir, "output folder");
  accuracyCmd->add_option("--max-n", accuracy.maxN, "largest 2D resolution")->check(CLI::Range(16, 4096));
  accuracyCmd->add_option("--max-n-3d", accuracy.maxN3d, "largest 3D resolution")->check(CLI::Range(16, 512));
  accuracyCmd
      ->add_option("--solver", accuracy.solver,
                   "strong (multigrid where it pays, as --precond auto) or jacobi (Jacobi CG on the SPD form)")
      ->check(CLI::IsMember({"strong", "jacobi"}));
  accuracyCmd->add_flag("!--no-plots", accuracy.plots, "skip the gnuplot PNGs");
  accuracyCmd->add_option("--threads", studyThreads, "OpenMP threads (0: all cores)");

  stokes::app::RunArgs runArgs;
  CLI::App* runCmd = stokes::app::addRunCommand(app, runArgs);
  stokes::app::CompareArgs compareArgs;
  CLI::App* compareCmd = stokes::app::addCompareCommand(app, compareArgs);

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
  const bool petscBackend = (*diskCmd && disk.backend == "petsc") || (*ballCmd && ball.backend == "petsc") ||
                            (*boxCmd && box.backend == "petsc");
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
    if (*boxCmd) {
      applyThreads(box.threads);
      return report(stokes::analytic::runBoxViscosity(toOptions(box, 1.0)), box.json);
    }
    if (*diskCmd) {
      applyThreads(disk.threads);
      AnalyticOptions o = toOptions(disk, 0.1);
      o.rankSetup = rankSetup;
      return report(stokes::analytic::runDiskStokes(o), disk.json);
    }
    if (*ballCmd) {
      applyThreads(ball.threads);
      AnalyticOptions o = toOptions(ball, 1.0);
      o.versusUniform = versusUniform;
      o.rankSetup = rankSetup;
      o.facesOut = facesOut;
      o.facesCompare = facesCompare;
      return report(stokes::analytic::runBall(o), ball.json);
    }
    if (*surfaceCmd) {
      applyThreads(surface.threads);
      AnalyticOptions o = toOptions(surface, 1.0);
      o.shape = surfaceShape.shape;
      o.amplitude = surfaceShape.amplitude;
      o.radius = surfaceShape.radius;
      o.crestOffset = surfaceShape.crestOffset;
      o.levelOffset = surfaceShape.levelOffset;
      if (surfaceCmd->count("--width") > 0) o.width = surfaceWidth;
      return report(stokes::analytic::runSurfaceMode(o), surface.json);
    }
    if (*accuracyCmd) {
      applyThreads(studyThreads);
      return stokes::app::runAccuracyTimeStudy(accuracy);
    }
    if (*studyAnalytic) {
      applyThreads(studyThreads);
      return runStudy(maxN, max3d, studyModels, studyJson);
    }
  } catch (const std::exception& e) {
    fmt::print(stderr, "stokesvdb: error: {}\n", e.what());
    return 2;
  }
  return 0;
}
