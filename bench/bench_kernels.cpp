// Operator-apply benchmarks: how long one matrix-free y = A x takes per unknown, and what fraction
// of the machine's STREAM triad bandwidth it reaches (docs/design.md §5).
//
// Measured (wall clock, manual timing of each apply, problem set-up excluded):
//   BM_StreamTriad            the triad of stream.h, 3 x 2^25 doubles
//   BM_DiskStokesApply        PressureStressSystem<2>::apply, unified Stokes, disk N = 128/256/512
//   BM_BallStokesApply        PressureStressSystem<3>::apply, unified Stokes, ball n = 64/128
//   BM_BallStokesRowsApply    PressureStressRows<3>::apply, the same operator on the live rows through
//                             the neighbour index (unknowns: the live rows)
//   BM_BallViscosityApply     ViscositySystem<3>::apply on the same ball
//   BM_FacesFromCells3        kernels::facesFromCells<3> with the unified-Stokes inputs (K x, scaled)
//   BM_CellsFromFaces3        kernels::cellsFromFaces<3> with the unified-Stokes outputs (K^T f + C x)
// each for 1 and 2 OpenMP threads (/threads:T); and
//   BM_GramSchmidt            one GMRES orthogonalisation of w against k basis vectors of 2^21 rows
//                             (the pile at res 896 has 2.2 M): /classical:1 the fused classical pass
//                             of solver/krylov/gmres.h, /classical:0 modified Gram-Schmidt by dot and
//                             axpy; counter ns_per_row (per row of w, all k vectors).
//
// Counters (per benchmark, all plain values computed from the measured time per apply t):
//   unknowns            rows of the operator (sys.size(), padding slots of the blocks included);
//                       for the two kernels the unified-Stokes size (1 + kCount) numSlots, so the
//                       two kernels' ns_per_unknown add up to the operator's
//   ns_per_unknown      t / unknowns, in ns
//   bytes_per_apply     compulsory memory traffic of one apply (formulas at bytes*() below)
//   GB_per_s            bytes_per_apply / t, in 1e9 bytes/s
//   fraction_of_stream  GB_per_s / STREAM triad GB/s with the same thread count
//   fraction_of_machine_stream  GB_per_s / STREAM triad GB/s with all cores
//   stream_GB_per_s     the triad bandwidth fraction_of_stream divides by (cached, see stream.h)
#include <benchmark/benchmark.h>

#include <initializer_list>
#include <map>
#include <memory>

#include "bench/bench_problems.h"
#include "bench/manual_timing.h"
#include "bench/stream.h"
#include "kernels/staggered_stencils.h"
#include "solver/systems/pressure_stress_system.h"
#include "solver/reduced/reduced_tiles.h"
#include "solver/step/stokes_step.h"
#include "solver/systems/pressure_stress_rows.h"
#include "solver/systems/viscosity_system.h"
#include "solver/krylov/gmres.h"

namespace stokes::bench {
namespace {

using solver::Vector;

constexpr double kMu = 0.1;  // viscosity of every benchmark problem (values do not change the cost)

// ---- memory-traffic estimates ------------------------------------------------------------------
// n = numSlots, D = Dim, C = StressChannels<D>::kCount (3 in 2D, 6 in 3D). Each array is counted
// once per pass, 8 bytes per double, reads and writes alike (STREAM convention: no write-allocate).
// The halo reads of neighbouring blocks' boundary layers are NOT counted (assumed cache hits), so
// these are lower bounds on the real traffic.

/// facesFromCells, unified-Stokes form: reads p, wp, tau (C), wt (C), S (D); writes f (D).
///   doubles = (2 (1 + C) + 2 D) n          2D: 12 n, 3D: 20 n
template <int Dim>
double bytesFacesFromCells(std::size_t n) {
  constexpr int C = sparse_grid::StressChannels<Dim>::kCount;
  return 8.0 * double(2 * (1 + C) + 2 * Dim) * double(n);
}

/// cellsFromFaces, unified-Stokes form: reads f (D), wp, wt (C), compliance (C), tau x (C);
/// writes y_p, y_tau (1 + C).
///   doubles = (D + 2 + 4 C) n              2D: 16 n, 3D: 29 n
template <int Dim>
double bytesCellsFromFaces(std::size_t n) {
  constexpr int C = sparse_grid::StressChannels<Dim>::kCount;
  return 8.0 * double(Dim + 2 + 4 * C) * double(n);
}

/// PressureStressSystem::apply = facesFromCells then cellsFromFaces (the face vector f is written
/// by the first pass and read back by the second).
///   doubles = (3 D + 4 + 6 C) n            2D: 28 n (7 per unknown), 3D: 49 n (7 per unknown)
template <int Dim>
double bytesStokesApply(std::size_t n) {
  return bytesFacesFromCells<Dim>(n) + bytesCellsFromFaces<Dim>(n);
}

/// ViscositySystem::apply: cellsFromFaces (reads u (D), Q (C); writes tau (C)), facesFromCells
/// (reads tau (C), unknown mask (D); writes y (D)), mass loop (reads y, mass, u; writes y: 4 D).
///   doubles = (7 D + 3 C) n                3D: 39 n (13 per unknown)
template <int Dim>
double bytesViscosityApply(std::size_t n) {
  constexpr int C = sparse_grid::StressChannels<Dim>::kCount;
  return 8.0 * double(7 * Dim + 3 * C) * double(n);
}

// ---- benchmark cases, built once on first use ---------------------------------------------------

/// Unified Stokes on the disk: the system and an input / output vector pair.
struct DiskCase {
  std::unique_ptr<BenchProblem<2>> problem;
  solver::PressureStressSystem<2> stokes;
  Vector x, y;

  explicit DiskCase(int N)
      : problem(buildDiskProblem(N, kMu)), stokes(problem->prob, /*withStress=*/true), x(stokes.rhs()),
        y(stokes.size(), 0.0) {}
};

/// The ball with its unified-Stokes and viscosity systems, and the arrays the stand-alone kernel
/// benchmarks stream (shaped exactly like the system's: a face scaling S, a compliance diagonal).
struct BallCase {
  std::unique_ptr<BenchProblem<3>> problem;
  solver::PressureStressSystem<3> stokes;
  solver::ViscositySystem<3> viscosity;
  Vector x, y;                        // unified Stokes: [p | tau] in and out
  Vector u, v;                        // viscosity: face velocities in and out
  Vector faceScale, compliance, faces;  // kernel benchmarks: S (D n), C (kCount n), f (D n)

  explicit BallCase(int N)
      : problem(buildBallProblem(N, kMu)), stokes(problem->prob, /*withStress=*/true),
        viscosity(problem->prob), x(stokes.rhs()), y(stokes.size(), 0.0), u(problem->prob.uStar),
        v(viscosity.size(), 0.0), faceScale(3 * slots(), 1.0),
        compliance(sparse_grid::StressChannels<3>::kCount * slots(), 0.5), faces(3 * slots(), 0.0) {}

  std::size_t slots() const { return problem->layout.numSlots(); }

  /// The unified-Stokes inputs of K x: p and tau with their liquid weights.
  kernels::CellStressInput stokesInput() const {
    kernels::CellStressInput in;
    in.p = x.data();
    in.pWeight = problem->prob.liquidCell.data();
    in.tau = x.data() + slots();
    in.tauWeight = problem->prob.liquidStress.data();
    return in;
  }
  /// The unified-Stokes outputs of K^T f + C x.
  kernels::CellStressOutput stokesOutput() {
    kernels::CellStressOutput out;
    out.p = y.data();
    out.pWeight = problem->prob.liquidCell.data();
    out.tau = y.data() + slots();
    out.tauWeight = problem->prob.liquidStress.data();
    out.tauDiag = compliance.data();
    out.tauX = x.data() + slots();
    return out;
  }
};

/// The disk with quadratic 16/3 tiles coupled into unified Stokes: the J^T B^-1 J pass alone.
struct DiskTilesCase {
  std::unique_ptr<BenchProblem<2>> problem;
  solver::ReducedTiles<2> tiles;
  Vector faces;

  explicit DiskTilesCase(int N)
      : problem(buildDiskProblem(N, kMu)),
        tiles(problem->prob, tileOptions(), solver::couplingKinds(solver::SystemKind::UnifiedStokes)),
        faces(problem->prob.uStar) {}

  static solver::ReducedOptions tileOptions() {
    solver::ReducedOptions r;
    r.order = solver::PolynomialOrder::Quadratic;
    r.tiling.tileSize = 16;
    r.tiling.padding = 3;
    r.fitAllFaces = true;
    return r;
  }
  /// Coupling faces summed over the tiles.
  std::size_t couplingFaces() const {
    std::size_t k = 0;
    for (std::size_t t = 0; t < tiles.numTiles(); ++t) k += tiles.tile(t).coupling.size();
    return k;
  }
};

/// Builds each case the first time a benchmark asks for it and keeps it for the rest of the run,
/// so repetitions and Google Benchmark's iteration search do not redo the set-up. Owned by main().
class CaseLibrary {
 public:
  DiskCase& disk(int N) { return get(disks_, N); }
  BallCase& ball(int N) { return get(balls_, N); }
  DiskTilesCase& diskTiles(int N) { return get(diskTiles_, N); }

 private:
  template <class Case>
  static Case& get(std::map<int, std::unique_ptr<Case>>& cases, int N) {
    auto& slot = cases[N];
    if (!slot) slot = std::make_unique<Case>(N);
    return *slot;
  }
  std::map<int, std::unique_ptr<DiskCase>> disks_;
  std::map<int, std::unique_ptr<BallCase>> balls_;
  std::map<int, std::unique_ptr<DiskTilesCase>> diskTiles_;
};

// ---- timing and counters ------------------------------------------------------------------------

/// The counters listed at the top of this file, from the mean seconds per apply.
void reportOperator(benchmark::State& state, double secondsPerApply, std::size_t unknowns, double bytes,
                    int threads) {
  if (!(secondsPerApply > 0.0)) return;
  const double gbs = bytes / secondsPerApply * 1e-9;
  state.counters["unknowns"] = double(unknowns);
  state.counters["ns_per_unknown"] = secondsPerApply * 1e9 / double(unknowns);
  state.counters["bytes_per_apply"] = bytes;
  state.counters["GB_per_s"] = gbs;
  state.counters["fraction_of_stream"] = gbs / streamTriadGBs(threads);
  state.counters["stream_GB_per_s"] = streamTriadGBs(threads);
  state.counters["fraction_of_machine_stream"] = gbs / machineStreamGBs();
}

/// Measures the STREAM bandwidths a benchmark will be compared with before anything is timed.
void warmStreamCache(int threads) {
  streamTriadGBs(threads);
  machineStreamGBs();
}

// ---- the benchmarks -----------------------------------------------------------------------------

/// One triad per iteration; GB_per_s from the mean iteration time, stream_GB_per_s is the cached
/// best-of-5 value every other benchmark divides by.
void streamTriadBenchmark(benchmark::State& state) {
  const int threads = int(state.range(0));
  warmStreamCache(threads);
  ThreadScope scope(threads);
  TriadArrays arrays(kTriadLength);
  const double seconds = timeApplies(state, [&] { triad(arrays, 3.0); });
  if (seconds > 0.0) state.counters["GB_per_s"] = arrays.bytesPerTriad() / seconds * 1e-9;
  state.counters["stream_GB_per_s"] = streamTriadGBs(threads);
}

/// y = A x for the unified-Stokes disk system.
void diskStokesApplyBenchmark(benchmark::State& state, CaseLibrary& cases) {
  const int N = int(state.range(0)), threads = int(state.range(1));
  warmStreamCache(threads);
  DiskCase& c = cases.disk(N);
  ThreadScope scope(threads);
  const double s = timeApplies(state, [&] { c.stokes.apply(c.x.data(), c.y.data()); });
  reportOperator(state, s, c.stokes.size(), bytesStokesApply<2>(c.problem->layout.numSlots()), threads);
}

/// y = A x for the unified-Stokes ball system.
void ballStokesApplyBenchmark(benchmark::State& state, CaseLibrary& cases) {
  const int N = int(state.range(0)), threads = int(state.range(1));
  warmStreamCache(threads);
  BallCase& c = cases.ball(N);
  ThreadScope scope(threads);
  const double s = timeApplies(state, [&] { c.stokes.apply(c.x.data(), c.y.data()); });
  reportOperator(state, s, c.stokes.size(), bytesStokesApply<3>(c.slots()), threads);
}

/// y_R = A_R x_R for the unified-Stokes ball system on its live rows (neighbour-index stencils).
/// Traffic: the index, and per row x (twice), w, wx (written, read), y, C; per face S, f (written, read).
void ballStokesRowsApplyBenchmark(benchmark::State& state, CaseLibrary& cases) {
  const int N = int(state.range(0)), threads = int(state.range(1));
  warmStreamCache(threads);
  BallCase& c = cases.ball(N);
  const solver::RowSelection rows = solver::RowSelection::positiveDiagonal(c.stokes.diagonal());
  const solver::PressureStressRows<3> op(c.stokes, rows);
  const Vector xr = rows.gathered(c.x);
  Vector yr(rows.size(), 0.0);
  ThreadScope scope(threads);
  const double s = timeApplies(state, [&] { op.apply(xr.data(), yr.data()); });
  const double bytes = double(op.indexBytes()) + 8.0 * (7.0 * double(rows.size()) + 3.0 * double(op.faces()));
  reportOperator(state, s, rows.size(), bytes, threads);
}

/// v = A u for the decoupled-viscosity ball system.
void ballViscosityApplyBenchmark(benchmark::State& state, CaseLibrary& cases) {
  const int N = int(state.range(0)), threads = int(state.range(1));
  warmStreamCache(threads);
  BallCase& c = cases.ball(N);
  ThreadScope scope(threads);
  const double s = timeApplies(state, [&] { c.viscosity.apply(c.u.data(), c.v.data()); });
  reportOperator(state, s, c.viscosity.size(), bytesViscosityApply<3>(c.slots()), threads);
}

/// f = S ⊙ (G (wp ⊙ p) + D^T (wt ⊙ tau)) alone, unified-Stokes inputs on the ball.
void facesFromCellsBenchmark(benchmark::State& state, CaseLibrary& cases) {
  const int N = int(state.range(0)), threads = int(state.range(1));
  warmStreamCache(threads);
  BallCase& c = cases.ball(N);
  ThreadScope scope(threads);
  const kernels::CellStressInput in = c.stokesInput();
  const double s = timeApplies(
      state, [&] { kernels::facesFromCells<3>(c.problem->layout, in, c.faceScale.data(), c.faces.data()); });
  reportOperator(state, s, c.stokes.size(), bytesFacesFromCells<3>(c.slots()), threads);
}

/// y = [wp ⊙ G^T f | wt ⊙ D f + C ⊙ tau] alone, unified-Stokes outputs on the ball.
void cellsFromFacesBenchmark(benchmark::State& state, CaseLibrary& cases) {
  const int N = int(state.range(0)), threads = int(state.range(1));
  warmStreamCache(threads);
  BallCase& c = cases.ball(N);
  ThreadScope scope(threads);
  kernels::facesFromCells<3>(c.problem->layout, c.stokesInput(), c.faceScale.data(), c.faces.data());
  const kernels::CellStressOutput out = c.stokesOutput();
  const double s = timeApplies(state, [&] { kernels::cellsFromFaces<3>(c.problem->layout, c.faces.data(), out); });
  reportOperator(state, s, c.stokes.size(), bytesCellsFromFaces<3>(c.slots()), threads);
}

/// faces|coupling <- J^T B^-1 J faces|coupling for every tile (gather, dense m x m, scatter).
/// Bytes per apply: per coupling face its cached basis row (m doubles), the face index, one read
/// and one write of the face value; the m x m inverses are cache-resident and not counted.
void tileCouplingBenchmark(benchmark::State& state, CaseLibrary& cases) {
  const int N = int(state.range(0)), threads = int(state.range(1));
  warmStreamCache(threads);
  DiskTilesCase& c = cases.diskTiles(N);
  ThreadScope scope(threads);
  const std::size_t nc = c.couplingFaces();
  const double m = c.tiles.dofsPerTile();
  const double s = timeApplies(state, [&] { c.tiles.coupleFaces(c.faces.data()); });
  reportOperator(state, s, nc, double(nc) * (8.0 * m + 8.0 + 16.0), threads);
  state.counters["tiles"] = double(c.tiles.numTiles());
}

/// The three parts of the coupling pass on their own (same disk, same tiles), so that each kernel
/// has its own bytes and bandwidth fraction. `part`: 0 = J gather F = J f (per coupling face: its
/// basis row, index and value read), 1 = B^-1 block apply V = B^-1 F (per tile: the m x m inverse
/// and two m-vectors: 8 (m^2 + 2m) bytes), 2 = J^T scatter f = C V (row, index, value written).
void tileCouplingPartBenchmark(benchmark::State& state, CaseLibrary& cases, int part) {
  const int N = int(state.range(0)), threads = int(state.range(1));
  warmStreamCache(threads);
  DiskTilesCase& c = cases.diskTiles(N);
  ThreadScope scope(threads);
  const std::size_t nc = c.couplingFaces(), dofs = c.tiles.totalDofs();
  const double m = c.tiles.dofsPerTile();
  solver::Vector F(dofs, 1.0), V(dofs, 0.0);
  double seconds = 0.0, bytes = 0.0;
  std::size_t rows = nc;
  switch (part) {
    case 0:
      seconds = timeApplies(state, [&] { c.tiles.gather(c.faces.data(), F.data()); });
      bytes = double(nc) * (8.0 * m + 16.0) + 8.0 * double(dofs);
      break;
    case 1:
      seconds = timeApplies(state, [&] { c.tiles.applyInverses(F.data(), V.data()); });
      bytes = double(c.tiles.numTiles()) * 8.0 * (m * m + 2.0 * m);
      rows = dofs;
      break;
    default:
      seconds = timeApplies(state, [&] { c.tiles.scatter(V.data(), c.faces.data(), /*couplingOnly=*/true); });
      bytes = double(nc) * (8.0 * m + 16.0) + 8.0 * double(dofs);
  }
  reportOperator(state, seconds, rows, bytes, threads);
  state.counters["tiles"] = double(c.tiles.numTiles());
}

// ---- registration -------------------------------------------------------------------------------

constexpr int kThreadCounts[] = {1, 2};

/// Registers `fn` (bound to `cases`) for every size and thread count, named
/// name/<sizeName>:size/threads:T.
template <class Fn>
void registerOperator(const char* name, Fn fn, CaseLibrary& cases, const char* sizeName,
                      std::initializer_list<int> sizes) {
  auto* b = benchmark::RegisterBenchmark(name, [fn, &cases](benchmark::State& st) { fn(st, cases); });
  b->ArgNames({sizeName, "threads"})->UseManualTime()->Unit(benchmark::kMicrosecond);
  for (int size : sizes)
    for (int t : kThreadCounts) b->Args({size, t});
}

void registerAll(CaseLibrary& cases) {
  auto* triadBench = benchmark::RegisterBenchmark("BM_StreamTriad", streamTriadBenchmark);
  triadBench->ArgName("threads")->UseManualTime()->Unit(benchmark::kMillisecond);
  for (int t : kThreadCounts) triadBench->Arg(t);

  registerOperator("BM_DiskStokesApply", diskStokesApplyBenchmark, cases, "N", {128, 256, 512});
  registerOperator("BM_BallStokesApply", ballStokesApplyBenchmark, cases, "n", {64, 128});
  registerOperator("BM_BallStokesRowsApply", ballStokesRowsApplyBenchmark, cases, "n", {64, 128});
  registerOperator("BM_BallViscosityApply", ballViscosityApplyBenchmark, cases, "n", {64, 128});
  registerOperator("BM_FacesFromCells3", facesFromCellsBenchmark, cases, "n", {64, 128});
  registerOperator("BM_CellsFromFaces3", cellsFromFacesBenchmark, cases, "n", {64, 128});
  registerOperator("BM_TileCoupling2", tileCouplingBenchmark, cases, "N", {128, 256});
  const char* parts[] = {"BM_TileGatherJ2", "BM_TileInverseB2", "BM_TileScatterJT2"};
  for (int part = 0; part < 3; ++part)
    registerOperator(
        parts[part], [part](benchmark::State& st, CaseLibrary& c) { tileCouplingPartBenchmark(st, c, part); }, cases,
        "N", {128, 256});
}

/// One Arnoldi orthogonalisation, fused classical (with its selective second pass) or modified
/// Gram-Schmidt, on random unit basis vectors (nearly orthogonal, as GMRES keeps them).
void gramSchmidtBenchmark(benchmark::State& state) {
  const bool classical = state.range(0) != 0;
  const std::size_t k = std::size_t(state.range(1)), n = std::size_t(1) << 21;
  std::vector<solver::Vector> basis(k, solver::Vector(n));
  solver::Vector w(n), w0(n);
  std::uint64_t seed = 12345;
  const auto next = [&seed] {
    seed = seed * 6364136223846793005ULL + 1442695040888963407ULL;
    return double(seed >> 11) * 0x1.0p-53 - 0.5;
  };
  for (auto& v : basis) {
    for (std::size_t i = 0; i < n; ++i) v[i] = next();
    solver::scale(1.0 / solver::norm2(v.data(), n), v.data(), n);
  }
  for (std::size_t i = 0; i < n; ++i) w0[i] = next();
  std::vector<const double*> rows(k);
  for (std::size_t j = 0; j < k; ++j) rows[j] = basis[j].data();
  std::vector<double> h(k + 1);
  for (auto _ : state) {
    state.PauseTiming();
    solver::copy(w0.data(), w.data(), n);
    state.ResumeTiming();
    if (classical) {
      h[k] = solver::detail::orthogonalize(rows, k, w.data(), h.data(), n);
    } else {
      for (std::size_t j = 0; j < k; ++j) {
        h[j] = solver::dot(w.data(), rows[j], n);
        solver::axpy(-h[j], rows[j], w.data(), n);
      }
      h[k] = solver::norm2(w.data(), n);
    }
    benchmark::DoNotOptimize(h.data());
  }
  state.counters["ns_per_row"] =
      benchmark::Counter(double(n) * 1e-9, benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
}
BENCHMARK(gramSchmidtBenchmark)
    ->Name("BM_GramSchmidt")
    ->ArgNames({"classical", "k"})
    ->ArgsProduct({{0, 1}, {5, 10, 20}})
    ->Unit(benchmark::kMillisecond);

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
