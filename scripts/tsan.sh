#!/usr/bin/env bash
# The ThreadSanitizer job (run by scripts/run_tests.sh after the test suite). Builds the
# thread-determinism tests and the command line with clang and -DSTOKES_SANITIZE_THREAD=ON into
# ./build-tsan, then runs on 2 threads: the parallel reductions and the Krylov methods on them
# (test_krylov), P2G, G2P and the binning under them (test_apic), the solver's steps with every
# loop forking (test_systems), and two scenes (the beam with quadratic tiles, the default scene).
# Each of those tests checks that its 2-thread run did take the parallel path
# (tests/parallel_path.h), so a race there is a race ThreadSanitizer sees. Any data race it reports
# fails the job. `scripts/tsan.sh --all` builds and runs every test binary instead (about an hour on
# 2 cores).
#
# OpenMP: clang's libomp with LLVM's Archer tool (OMP_TOOL_LIBRARIES), which tells TSan about
# OpenMP's barriers and reductions; GCC's libgomp is not instrumented and gives false reports.
# oneTBB's scheduler is not instrumented either: ThreadSanitizer builds run OpenVDB's tools on one
# TBB thread (cmake/tsan_one_tbb_thread.cpp); the project's own parallel code is OpenMP only.
set -euo pipefail
cd "$(dirname "$0")/.."
ARCHER=$(ls /usr/lib/llvm-*/lib/libarcher.so 2>/dev/null | sort -V | tail -n 1 || true)
if [ -z "$ARCHER" ] || ! command -v clang++ >/dev/null; then
  echo "[tsan] clang++ and libomp's libarcher.so are needed: scripts/install_deps.sh --tests" >&2
  exit 1
fi
mkdir -p build-tsan
log=build-tsan/build.log
echo "[tsan] building with clang and -fsanitize=thread (log: $log)"
build_start=$SECONDS
cmake -S . -B build-tsan -DCMAKE_BUILD_TYPE=Release -DCMAKE_CXX_COMPILER=clang++ -DSTOKES_SANITIZE_THREAD=ON \
  -DSTOKES_NATIVE=OFF -DSTOKES_WITH_PETSC=OFF -DSTOKES_BUILD_BENCH=OFF -DSTOKES_BUILD_TESTS=ON > "$log" 2>&1
all=0
[ "${1:-}" = "--all" ] && all=1
if [ "$all" = 1 ]; then
  targets=()
else
  targets=(--target test_systems test_krylov test_apic stokesvdb)
fi
cmake --build build-tsan -j"$(nproc)" "${targets[@]}" >> "$log" 2>&1 || { tail -n 40 "$log"; exit 1; }
echo "[tsan] built in $((SECONDS - build_start)) s"
run_start=$SECONDS
export OMP_TOOL_LIBRARIES="$ARCHER" OMP_NUM_THREADS=2
export TSAN_OPTIONS="halt_on_error=1 exitcode=66 ignore_noninstrumented_modules=1 suppressions=$PWD/tests/tsan.supp"
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
# runs "$@" with its output in $out/<name>.log, shown (its end) if it fails, and says how long it
# took; a GoogleTest run must have run at least one test (a filter that matches none fails)
logged() {
  local name=$1
  shift
  local start=$SECONDS
  echo -n "[tsan] $name ... "
  "$@" > "$out/$name.log" 2>&1 || { echo; tail -n 80 "$out/$name.log"; echo "[tsan] $name failed" >&2; exit 1; }
  if [[ "$1" == */test_* ]] && ! grep -q '^\[  PASSED  \] [1-9]' "$out/$name.log"; then
    echo; echo "[tsan] $name ran no test" >&2; exit 1
  fi
  echo "$((SECONDS - start)) s"
}
if [ "$all" = 1 ]; then
  for t in build-tsan/bin/test_*; do logged "$(basename "$t")" "$t"; done
else
  logged "parallel reductions and Krylov methods" build-tsan/bin/test_krylov --gtest_filter='*ThreadCounts*'
  logged "P2G, G2P and binning" build-tsan/bin/test_apic --gtest_filter='*BitIdentical*:*Binning*:*ReseedingBounds*'
  logged "solver determinism tests" build-tsan/bin/test_systems --gtest_filter='Determinism.*'
fi
logged "beam (quadratic tiles), res 24, 1 frame" \
  build-tsan/bin/stokesvdb run scenes/beam.json --res 24 --frames 1 --threads 2 --out "$out/beam"
logged "default scene, res 16, 1 frame" \
  build-tsan/bin/stokesvdb run scenes/default.json --res 16 --frames 1 --threads 2 --out "$out/default"
echo "[tsan] no data race reported ($((SECONDS - run_start)) s of runs)"
