#!/usr/bin/env bash
# Configures and builds StokesVDB (Release) into ./build.
#   scripts/build.sh                          the stokesvdb program and the libraries it links
#   scripts/build.sh --all [CMake options]    every target the configuration enables (tests, benchmarks)
#   scripts/build.sh --target bench_solves    named targets (repeatable)
# Other arguments go to CMake, e.g. -DSTOKES_NATIVE=OFF (portable binaries, no -march=native).
# A new build folder uses Ninja where it is installed (scripts/install_deps.sh installs it): it
# compiles any object whose inputs are ready, where Make waits for each library to be linked
# first. ccache (also installed there) keeps compiled objects across builds and clones.
set -euo pipefail
cd "$(dirname "$0")/.."
targets=(--target stokesvdb)
named=()
cmake_args=()
while [ $# -gt 0 ]; do
  case "$1" in
    --all) targets=(); shift ;;
    --target) named+=(--target "$2"); shift 2 ;;
    *) cmake_args+=("$1"); shift ;;
  esac
done
[ ${#named[@]} -gt 0 ] && targets=("${named[@]}")
generator=()
if [ ! -f build/CMakeCache.txt ] && command -v ninja > /dev/null; then generator=(-G Ninja); fi
cmake -S . -B build "${generator[@]}" -DCMAKE_BUILD_TYPE=Release "${cmake_args[@]}"
cmake --build build -j"$(nproc)" "${targets[@]}"
