#!/bin/bash
# The installed package works for a program outside the tree: cmake --install
# this build into a temporary prefix, configure and build examples/drop_ball against it with
# find_package(StokesVDB), run it (it checks its liquid volume itself); and the installed program,
# from another folder, finds an installed scene by name (the armadillos: its mesh too) and looks
# in the prefix first; the Python module imports from the prefix.
#   tests/install_example_test.sh BUILD_DIR SOURCE_DIR
set -euo pipefail
BUILD=$1
SRC=$2
DIR=$(mktemp -d)
trap 'rm -rf "$DIR"' EXIT
cmake --install "$BUILD" --prefix "$DIR/prefix" > "$DIR/install.log"
test -f "$DIR/prefix/lib/cmake/StokesVDB/StokesVDBConfig.cmake"
test -f "$DIR/prefix/include/stokesvdb/sim/step/simulator.h"
cmake -S "$SRC/examples/drop_ball" -B "$DIR/build" -DCMAKE_PREFIX_PATH="$DIR/prefix" -DCMAKE_BUILD_TYPE=Release \
  > "$DIR/configure.log" || { cat "$DIR/configure.log"; exit 1; }
cmake --build "$DIR/build" -j2 > "$DIR/build.log" 2>&1 || { tail -40 "$DIR/build.log"; exit 1; }
"$DIR/build/drop_ball"
test -f "$DIR/prefix/share/stokesvdb/scenes/scene.schema.json"
mkdir "$DIR/elsewhere"
cd "$DIR/elsewhere"
if "$DIR/prefix/bin/stokesvdb" run no_such_scene --out out 2> missing.txt; then exit 1; fi
grep -q "no such file here, nor among the shipped scenes ($DIR/prefix/share/stokesvdb/scenes" missing.txt ||
  { cat missing.txt; exit 1; }
"$DIR/prefix/bin/stokesvdb" run armadillos --out out --frames 1 --res 16 --threads 2 2> run.txt ||
  { cat run.txt; exit 1; }
test -f out/frame_0001.vdb
# the Python module, where the build has it, imports from the prefix's dist-packages
if ls "$BUILD"/python/stokesvdb*.so > /dev/null 2>&1; then
  SITE=$(ls -d "$DIR"/prefix/lib/python3*/dist-packages)
  PYTHONPATH="$SITE" /usr/bin/python3 -c "
import stokesvdb
scene = stokesvdb.load_scene('$DIR/prefix/share/stokesvdb/scenes/default.json', resolution=8, frames=1)
assert stokesvdb.__file__.startswith('$SITE'), stokesvdb.__file__
print('installed module', stokesvdb.__version__, 'reads', scene.name, scene.cells)"
fi
