#!/usr/bin/env bash
# Installs every build and run dependency of StokesVDB from Debian 12 packages.
# Idempotent: packages already present are skipped by apt. Needs root (or sudo).
set -euo pipefail
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
PACKAGES=(
  build-essential cmake ninja-build git pkg-config ccache
  libopenvdb-dev libboost-iostreams-dev libtbb-dev libblosc-dev libeigen3-dev
  libgtest-dev libgmock-dev libbenchmark-dev libcli11-dev nlohmann-json3-dev libfmt-dev
  libstb-dev gnuplot-nox
  pybind11-dev python3-dev python3-numpy  # the Python module (python/), for /usr/bin/python3
  petsc-dev  # the PETSc backend (3.18, with OpenMPI and hypre): CMake option STOKES_WITH_PETSC
)
# `install_deps.sh --tests`: also what only the tests use (Blender imports a frame in background
# mode: tests/blender_import_test.sh; python3-jsonschema checks the scenes against their schema:
# tests/scene_schema_test.py; python3-openvdb reads a frame back: tests/frame_grids_test.py; each
# skipped without it).
# clang and libomp (with its Archer tool): the ThreadSanitizer job, scripts/tsan.sh.
if [ "${1:-}" = "--tests" ]; then PACKAGES+=(blender python3-jsonschema python3-openvdb clang libomp-dev); fi
missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ "${#missing[@]}" -gt 0 ]; then
  echo "[install_deps] installing: ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
else
  echo "[install_deps] all packages present"
fi
