#!/usr/bin/env bash
# Installs dependencies, builds (Release, tests on, benchmarks off) and runs the test suite, then
# the ThreadSanitizer job (scripts/tsan.sh: a clang build with -fsanitize=thread, two scenes).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install_deps.sh --tests
bash scripts/build.sh --all -DSTOKES_BUILD_TESTS=ON -DSTOKES_BUILD_BENCH=OFF
(cd build && OMP_NUM_THREADS="${OMP_NUM_THREADS:-2}" ctest --output-on-failure -j1)
bash scripts/tsan.sh
