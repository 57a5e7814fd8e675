#!/usr/bin/env bash
# The ThreadSanitizer job (run by scripts/run_tests.sh after the test suite). Builds the
# solver determinism tests and the command line with clang and -DSTOKES_SANITIZE_THREAD=ON into
# ./build-tsan, then runs them and two scenes (the beam with quadratic tiles, the default scene) on
# 2 threads. Any data race ThreadSanitizer reports fails the job. `scripts/tsan.sh --all` builds
# and runs every test binary instead (about an hour on 2 cores).
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
cmake -S . -B build-tsan -DCMAKE_BUILD_TYPE=Release -DCMAKE_CXX_COMPILER=clang++ -DSTOKES_SANITIZE_THREAD=ON \
  -DSTOKES_NATIVE=OFF -DSTOKES_WITH_PETSC=OFF -DSTOKES_BUILD_BENCH=OFF -DSTOKES_BUILD_TESTS=ON > "$log" 2>&1
all=0
[ "${1:-}" = "--all" ] && all=1
if [ "$all" = 1 ]; then
  targets=()
else
  targets=(--target test_systems stokesvdb)
fi
cmake --build build-tsan -j"$(nproc)" "${targets[@]}" >> "$log" 2>&1 || { tail -n 40 "$log"; exit 1; }
export OMP_TOOL_LIBRARIES="$ARCHER" OMP_NUM_THREADS=2
export TSAN_OPTIONS="halt_on_error=1 exitcode=66 ignore_noninstrumented_modules=1 suppressions=$PWD/tests/tsan.supp"
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
# runs "$@" with its output in $out/<name>.log, shown (its end) if it fails
logged() {
  local name=$1
  shift
  echo "[tsan] $name"
  "$@" > "$out/$name.log" 2>&1 || { tail -n 80 "$out/$name.log"; echo "[tsan] $name failed" >&2; exit 1; }
}
if [ "$all" = 1 ]; then
  for t in build-tsan/bin/test_*; do logged "$(basename "$t")" "$t"; done
else
  logged "solver determinism tests" build-tsan/bin/test_systems --gtest_filter='Determinism.*'
fi
logged "beam (quadratic tiles), res 24, 1 frame" \
  build-tsan/bin/stokesvdb run scenes/beam.json --res 24 --frames 1 --threads 2 --out "$out/beam"
logged "default scene, res 16, 1 frame" \
  build-tsan/bin/stokesvdb run scenes/default.json --res 16 --frames 1 --threads 2 --out "$out/default"
echo "[tsan] no data race reported"
