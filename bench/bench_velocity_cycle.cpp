// The Galerkin velocity cycle of the pressure-velocity form (solver/multigrid/galerkin_cycle.h) on
// the liquid ball of bench_problems.h: what one apply of the finest level's operator and one
// V-cycle cost per row, uniform against reduced tiles.
//
//   BM_VelocityLevel0/n:N/tiles:T/factored:F/threads:K   y = A_0 x on level 0's rows (the smoother's
//                                                        and the residual's product, 5 per cycle
//                                                        at degree 2)
//   BM_VelocityCycle/n:N/tiles:T/factored:F/threads:K    z = B r, one V-cycle from z = 0
//
// tiles: 0 the uniform grid; T > 0 quadratic divergence-free tiles of T cells with padding 3
// (T = 32: padding 2), as `stokesvdb analytic ball-stokes --model quadratic --tile T --pad P`.
// factored: 1 level 0 applies the tiles' couplings in factored form (tile_coupled_rows.h), 0 as
// the assembled matrix's dense rows (GalerkinVelocityHierarchy::TileCouplings).
// Counters: rows of level 0, its work per row (multiply-adds: stored entries, and in factored form
// those of J and J^T, TileCoupledRows::work), the coarse levels' stored entries per level-0 row,
// the tiles, and ns_per_row = seconds per call / level-0 rows.
#include <benchmark/benchmark.h>

#include <array>
#include <map>
#include <memory>
#include <utility>

#include "bench/bench_problems.h"
#include "bench/manual_timing.h"
#include "solver/multigrid/galerkin_cycle.h"
#include "solver/reduced/reduced_tiles.h"
#include "solver/step/stokes_step.h"
#include "solver/systems/pressure_velocity_system.h"

namespace stokes::bench {
namespace {

constexpr double kMu = 0.1;  // rho = dt = 1: mu dt / (rho dx^2) = 0.1 n^2, the viscous regime

struct CycleCase {
  std::unique_ptr<BenchProblem<3>> problem;
  std::unique_ptr<solver::ReducedTiles<3>> tiles;
  std::unique_ptr<solver::PressureVelocitySystem<3>> sys;
  std::unique_ptr<solver::GalerkinVelocityHierarchy<3>> hierarchy;
  std::vector<solver::MultigridLevel> levels;  // the cycle's view, for level 0's apply
  std::shared_ptr<solver::Multigrid> cycle;
  solver::Vector x, y;

  CycleCase(int n, int tile, bool factored) : problem(buildBallProblem(n, kMu)) {
    if (tile > 0) {
      solver::ReducedOptions r;
      r.order = solver::PolynomialOrder::Quadratic;
      r.tiling.tileSize = tile;
      r.tiling.padding = tile == 32 ? 2 : 3;
      tiles = std::make_unique<solver::ReducedTiles<3>>(problem->prob, r,
                                                         solver::couplingKinds(solver::SystemKind::UnifiedStokes));
    }
    sys = std::make_unique<solver::PressureVelocitySystem<3>>(problem->prob, tiles.get());
    const solver::RowSelection rows =
        solver::RowSelection::positiveDiagonal({sys->diagonal().data(), sys->velocityRows()});
    solver::MultigridOptions opt;
    opt.smootherDegree = solver::kPressureVelocitySmootherDegree;
    using H = solver::GalerkinVelocityHierarchy<3>;
    hierarchy = std::make_unique<H>(*sys, rows, opt, factored ? H::TileCouplings::Factored : H::TileCouplings::Assembled);
    levels = solver::assembledLevels(hierarchy->levels());
    cycle = solver::assembledMultigrid(hierarchy->levels(), opt);
    x.assign(rows.size(), 0.0);
    for (std::size_t i = 0; i < x.size(); ++i) x[i] = double((i * 7919) % 1000) / 1000.0 - 0.5;
    y.assign(rows.size(), 0.0);
  }
};

class CaseLibrary {
 public:
  CycleCase& get(const benchmark::State& state) {
    const int n = int(state.range(0)), tile = int(state.range(1)), factored = int(state.range(2));
    const std::array<int, 3> key{n, tile, factored};
    if (!cases_.count(key)) {
      if (n > 96) cases_.clear();  // the ball at n = 128 holds ~1 GB: one such case at a time
      cases_[key] = std::make_unique<CycleCase>(n, tile, factored != 0);
    }
    return *cases_[key];
  }

 private:
  std::map<std::array<int, 3>, std::unique_ptr<CycleCase>> cases_;
};

void report(benchmark::State& state, const CycleCase& c, double seconds) {
  const auto& l0 = c.hierarchy->levels()->front();
  const double rows = double(l0.rows());
  state.counters["rows"] = rows;
  state.counters["work_per_row"] = double(l0.factored.rows ? l0.factored.entries : l0.a.entries()) / rows;
  state.counters["levels"] = double(c.cycle->numLevels());
  double coarse = 0.0;  // the coarse levels' stored entries per level-0 row
  for (std::size_t l = 1; l < c.hierarchy->levels()->size(); ++l) coarse += double((*c.hierarchy->levels())[l].a.entries());
  state.counters["coarse_entries_per_row"] = coarse / rows;
  state.counters["tiles"] = c.tiles ? double(c.tiles->numTiles()) : 0.0;
  state.counters["ns_per_row"] = 1e9 * seconds / rows;
}

void level0Benchmark(benchmark::State& state, CaseLibrary& cases) {
  CycleCase& c = cases.get(state);
  ThreadScope threads(int(state.range(3)));
  const solver::MultigridLevel& l0 = c.levels.front();
  const double s = timeApplies(state, [&] { l0.apply(c.x.data(), c.y.data()); });
  report(state, c, s);
}

void cycleBenchmark(benchmark::State& state, CaseLibrary& cases) {
  CycleCase& c = cases.get(state);
  ThreadScope threads(int(state.range(3)));
  const double s = timeApplies(state, [&] { c.cycle->apply(c.x.data(), c.y.data()); });
  report(state, c, s);
}

void registerAll(CaseLibrary& cases) {
  for (auto [name, fn] : {std::pair{"BM_VelocityLevel0", &level0Benchmark}, std::pair{"BM_VelocityCycle", &cycleBenchmark}}) {
    auto* b = benchmark::RegisterBenchmark(name, [fn, &cases](benchmark::State& st) { fn(st, cases); });
    b->ArgNames({"n", "tiles", "factored", "threads"})->UseManualTime()->Unit(benchmark::kMillisecond);
    for (int n : {96, 128})
      for (int tile : {0, 16, 32})
        for (int factored : {0, 1})
          for (int threads : {1, 2})
            if (tile > 0 || factored == 0) b->Args({n, tile, factored, threads});
  }
}

}  // namespace
}  // namespace stokes::bench

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  stokes::bench::CaseLibrary cases;  // outlives every benchmark run
  stokes::bench::registerAll(cases);
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
