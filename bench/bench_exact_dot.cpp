// What rank-count-free dot products cost (solver/petsc/exact_dot.h): exactDot against a plain
// serial dot over the same two vectors, one MPI rank, 2^16 / 2^20 / 2^23 entries. Counter:
// ns_per_entry. Both include one MPI reduction (the plain dot's sum; the exact dot's maximum and
// its three level sums), as a distributed solve pays them.
//   mpirun -np 1 build/bin/bench_exact_dot
#include <benchmark/benchmark.h>
#include <mpi.h>

#include <random>
#include <vector>

#include "solver/petsc/exact_dot.h"

namespace {

struct Vectors {
  std::vector<double> a, b;
  explicit Vectors(std::size_t n) : a(n), b(n) {
    std::mt19937_64 rng(7);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    for (double& x : a) x = u(rng);
    for (double& x : b) x = u(rng) * 1e-3;
  }
};

void reportPerEntry(benchmark::State& state, std::size_t n) {
  state.counters["ns_per_entry"] =
      benchmark::Counter(double(n) * 1e-9, benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
}

void BM_PlainDot(benchmark::State& state) {
  const std::size_t n = std::size_t(state.range(0));
  const Vectors v(n);
  for (auto _ : state) {
    double local = 0.0, sum = 0.0;
    for (std::size_t i = 0; i < n; ++i) local += v.a[i] * v.b[i];
    MPI_Allreduce(&local, &sum, 1, MPI_DOUBLE, MPI_SUM, MPI_COMM_WORLD);
    benchmark::DoNotOptimize(sum);
  }
  reportPerEntry(state, n);
}

void BM_ExactDot(benchmark::State& state) {
  const std::size_t n = std::size_t(state.range(0));
  const Vectors v(n);
  for (auto _ : state)
    benchmark::DoNotOptimize(stokes::solver::petsc::exactDot(v.a.data(), v.b.data(), n, std::int64_t(n), MPI_COMM_WORLD));
  reportPerEntry(state, n);
}

BENCHMARK(BM_PlainDot)->Arg(1 << 16)->Arg(1 << 20)->Arg(1 << 23);
BENCHMARK(BM_ExactDot)->Arg(1 << 16)->Arg(1 << 20)->Arg(1 << 23);

}  // namespace

int main(int argc, char** argv) {
  MPI_Init(&argc, &argv);
  benchmark::Initialize(&argc, argv);
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  MPI_Finalize();
  return 0;
}
