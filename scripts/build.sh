#!/usr/bin/env bash
# Configures and builds StokesVDB (Release) into ./build. Extra arguments go to CMake, e.g.
#   scripts/build.sh -DSTOKES_NATIVE=OFF        (portable binaries, no -march=native)
set -euo pipefail
cd "$(dirname "$0")/.."
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release "$@"
cmake --build build -j"$(nproc)"
