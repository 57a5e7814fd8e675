// Whole-solve benchmarks: one unified-Stokes step of an analytic case, set-up and Krylov solve
// timed separately (analytic/analytic_cases.h). Each case runs exactly once (Iterations(1)); the
// reported time is the Krylov solve alone (manual time = AnalyticResult::solveSeconds).
//
//   BM_DiskStokesSolve/N:{64,128,256,512}/model:{0,1,2}   2D free-surface disk, mu = 0.1, Jacobi-PCG;
//                                            model 0 uniform, 1 affine 16/3, 2 quadratic 16/3
//   BM_BallStokesSolve/n:{64,128}/model:{0,1,2}            3D liquid ball (radius 0.3, free surface)
//   BM_TileCache/strategy:{none,library,shapes}            3D box viscosity n = 64, quadratic 16/2
//                                            (64 cube tiles): tile set-up time per strategy
//   BM_DiskPreconditioner/N:128/precond:{none,jacobi,multigrid}  CG iterations per preconditioner
//   BM_DiskPreconditioner/N:128/form:pv/precond:multigrid     MINRES on the pressure-velocity form
// The two largest cases (disk N = 512, ball n = 128) take minutes each on the 2-core development
// machine; they stay registered but the default run skips them (see kDefaultFilter):
// --benchmark_filter=all runs everything, --benchmark_filter='N:512|n:128' only them.
// All use model "uniform", rho = dt = 1 and the default tolerance of AnalyticOptions (relative
// residual 1e-10), with every OpenMP thread.
//
// Counters:
//   iterations          Krylov iterations (CG: one operator apply each)
//   unknowns            active rows (non-zero diagonal) of the system
//   solve_seconds       wall time of the Krylov solve
//   setup_seconds       wall time of building the system (scalings, diagonal, right-hand side)
//   ns_per_unknown_iteration   solve_seconds / (iterations * unknowns), in ns
//   L1                  disk only: sum over liquid faces of |u - u_exact| dx^2
//   relative_residual   true ||b - A x|| / ||b|| after the solve
//   converged           1 if the solver reported Converged (the label shows the status)
#include <benchmark/benchmark.h>
#include <omp.h>

#include <string>

#include "analytic/analytic_cases.h"

namespace stokes::bench {
namespace {

using analytic::AnalyticOptions;
using analytic::AnalyticResult;

constexpr double kMu = 0.1;

constexpr const char* kModels[] = {"uniform", "affine", "quadratic"};

AnalyticOptions caseOptions(int n, int model = 0) {
  AnalyticOptions o;
  o.n = n;
  o.mu = kMu;
  o.model = kModels[model];
  o.tileSize = 16;
  o.padding = 3;
  return o;  // tolerance, rho, dt, CG + Jacobi: the AnalyticOptions defaults
}

/// Copies one solve's figures into the counters and sets the manual time to the solve time.
void reportSolve(benchmark::State& state, const AnalyticResult& r, bool withL1) {
  state.SetIterationTime(r.solveSeconds);
  state.SetLabel(r.status);
  state.counters["iterations"] = r.iterations;
  state.counters["unknowns"] = double(r.unknowns);
  state.counters["solve_seconds"] = r.solveSeconds;
  state.counters["setup_seconds"] = r.setupSeconds;
  state.counters["tile_setup_seconds"] = r.tileSeconds;
  state.counters["tiles"] = double(r.tiles);
  state.counters["reduced_dofs"] = double(r.reducedDofs);
  if (r.iterations > 0 && r.unknowns > 0)
    state.counters["ns_per_unknown_iteration"] = r.solveSeconds * 1e9 / (double(r.iterations) * double(r.unknowns));
  if (withL1) state.counters["L1"] = r.L1;
  state.counters["relative_residual"] = r.relativeResidual;
  state.counters["converged"] = r.status == "Converged" ? 1.0 : 0.0;
  state.counters["threads"] = omp_get_max_threads();
}

/// One disk solve with `o`; the loop body runs once (Iterations(1)).
void runDisk(benchmark::State& state, const AnalyticOptions& o) {
  for (auto _ : state) reportSolve(state, analytic::runDiskStokes(o), /*withL1=*/true);
}

void diskSolveBenchmark(benchmark::State& state) {
  runDisk(state, caseOptions(int(state.range(0)), int(state.range(1))));
}

void ballSolveBenchmark(benchmark::State& state) {
  const AnalyticOptions o = caseOptions(int(state.range(0)), int(state.range(1)));
  for (auto _ : state) reportSolve(state, analytic::runBall(o), /*withL1=*/false);
}

/// The disk at N = 128 with the given preconditioner (iterations counter is the figure of merit).
/// `pv`: the pressure-velocity form with MINRES instead of the SPD form with CG.
void diskPreconditionerBenchmark(benchmark::State& state, solver::PreconditionerKind kind, bool pv) {
  AnalyticOptions o = caseOptions(128);
  o.preconditioner = kind;
  if (pv) {
    o.form = solver::StokesForm::PressureVelocity;
    o.method = solver::KrylovMethod::MINRES;
  }
  runDisk(state, o);
}

/// Tile set-up (tiling, fits, factorisations) under one cache strategy, on a 3D scene whose
/// tiles are all cubes; the figure of merit is tile_setup_seconds.
void tileCacheBenchmark(benchmark::State& state, const char* strategy) {
  AnalyticOptions o;
  o.dim = 3;
  o.n = 64;
  o.model = "quadratic";
  o.tileSize = 16;
  o.padding = 2;
  o.tileCache = strategy;
  for (auto _ : state) {
    const AnalyticResult r = analytic::runBoxViscosity(o);
    reportSolve(state, r, /*withL1=*/true);
    state.SetIterationTime(r.tileSeconds);
    state.counters["cache_hits"] = double(r.cacheHits);
    state.counters["cache_misses"] = double(r.cacheMisses);
  }
}

/// Every solve benchmark runs its case once and reports the solve time in seconds.
benchmark::internal::Benchmark* once(benchmark::internal::Benchmark* b) {
  return b->Iterations(1)->UseManualTime()->Unit(benchmark::kSecond);
}

/// Default --benchmark_filter: everything except the two multi-minute cases.
constexpr const char* kDefaultFilter = "-(N:512|n:128)/";

/// Applies kDefaultFilter unless the command line chose a filter (Google Benchmark's default is ".").
void applyDefaultFilter() {
  const std::string f = benchmark::GetBenchmarkFilter();
  if (f.empty() || f == ".") benchmark::SetBenchmarkFilter(kDefaultFilter);
}

void registerAll() {
  auto* disk = once(benchmark::RegisterBenchmark("BM_DiskStokesSolve", diskSolveBenchmark))->ArgNames({"N", "model"});
  for (int N : {64, 128, 256, 512})
    for (int m : {0, 1, 2}) disk->Args({N, m});

  auto* ball = once(benchmark::RegisterBenchmark("BM_BallStokesSolve", ballSolveBenchmark))->ArgNames({"n", "model"});
  for (int n : {64, 128})
    for (int m : {0, 1, 2}) ball->Args({n, m});

  for (const char* strategy : {"none", "library", "shapes"})
    once(benchmark::RegisterBenchmark((std::string("BM_TileCache/strategy:") + strategy).c_str(), tileCacheBenchmark,
                                      strategy));

  using solver::PreconditionerKind;
  once(benchmark::RegisterBenchmark("BM_DiskPreconditioner/N:128/precond:none", diskPreconditionerBenchmark,
                                    PreconditionerKind::None, false));
  once(benchmark::RegisterBenchmark("BM_DiskPreconditioner/N:128/precond:jacobi", diskPreconditionerBenchmark,
                                    PreconditionerKind::Jacobi, false));
  once(benchmark::RegisterBenchmark("BM_DiskPreconditioner/N:128/precond:multigrid", diskPreconditionerBenchmark,
                                    PreconditionerKind::Multigrid, false));
  once(benchmark::RegisterBenchmark("BM_DiskPreconditioner/N:128/form:pv/precond:multigrid",
                                    diskPreconditionerBenchmark, PreconditionerKind::Multigrid, true));
}

}  // namespace
}  // namespace stokes::bench

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  stokes::bench::applyDefaultFilter();
  stokes::bench::registerAll();
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
