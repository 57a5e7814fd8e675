#pragma once
// STREAM triad a[i] = b[i] + s * c[i] (McCalpin), run inside the benchmark binary so every kernel
// can be compared with the memory bandwidth of the machine it runs on (docs/design.md §5).
//
// Measured: the best of kTriadRepetitions timed triads over kTriadLength doubles per array
// (3 x 256 MiB, far beyond any cache), OpenMP `parallel for schedule(static)` -- the same static
// partition as the kernels. Bytes per triad = 3 arrays x 8 bytes x length (STREAM convention: the
// write-allocate read of `a` is not counted).
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cstddef>
#include <map>

#include "solver/krylov/aligned_vector.h"
#include "solver/krylov/stopwatch.h"

namespace stokes::bench {

inline constexpr std::size_t kTriadLength = std::size_t(1) << 25;
inline constexpr int kTriadRepetitions = 5;

/// The three 64-byte-aligned triad arrays. solver::Vector zero-fills them on the calling thread;
/// they are then initialised again with the triad's static partition (page placement would only
/// matter on a multi-socket machine).
struct TriadArrays {
  solver::Vector a, b, c;

  explicit TriadArrays(std::size_t n) : a(n), b(n), c(n) {
    const std::ptrdiff_t m = std::ptrdiff_t(n);
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t i = 0; i < m; ++i) {
      a[i] = 0.0;
      b[i] = 1.0;
      c[i] = 2.0;
    }
  }
  std::size_t size() const { return a.size(); }
  /// Bytes one triad moves: 3 arrays x 8 bytes per element.
  double bytesPerTriad() const { return 3.0 * sizeof(double) * double(size()); }
};

/// One triad a = b + s c over the arrays (OpenMP static schedule).
inline void triad(TriadArrays& t, double s) {
  double* a = t.a.data();
  const double* b = t.b.data();
  const double* c = t.c.data();
  const std::ptrdiff_t m = std::ptrdiff_t(t.size());
#pragma omp parallel for simd schedule(static)
  for (std::ptrdiff_t i = 0; i < m; ++i) a[i] = b[i] + s * c[i];
}

/// Wall-clock seconds of one triad.
inline double timeTriad(TriadArrays& t, double s) {
  const auto t0 = std::chrono::steady_clock::now();
  triad(t, s);
  return solver::secondsSince(t0);
}

/// Triad bandwidth in GB/s (1e9 bytes/s) with `threads` OpenMP threads: one untimed warm-up, then
/// the best of kTriadRepetitions. Restores the previous thread count.
inline double measureTriadGBs(int threads) {
  const int previous = omp_get_max_threads();
  omp_set_num_threads(threads);
  TriadArrays t(kTriadLength);
  triad(t, 3.0);  // warm-up: page faults, thread start-up
  double best = 1e300;
  for (int r = 0; r < kTriadRepetitions; ++r) best = std::min(best, timeTriad(t, 3.0));
  omp_set_num_threads(previous);
  return t.bytesPerTriad() / best * 1e-9;
}

/// The cached triad bandwidth (GB/s) for `threads` threads, measured once per thread count on
/// first use. This function-local cache is the only static state of the benchmark programs.
inline double streamTriadGBs(int threads) {
  static std::map<int, double> cache;
  auto it = cache.find(threads);
  if (it == cache.end()) it = cache.emplace(threads, measureTriadGBs(threads)).first;
  return it->second;
}

/// Triad bandwidth of the whole machine (omp_get_num_procs() threads).
inline double machineStreamGBs() { return streamTriadGBs(omp_get_num_procs()); }

}  // namespace stokes::bench
