#!/bin/bash
# A frame opened in Blender: `stokesvdb run` of a ball resting on the floor with
# output.mesh and up_axis "z", then Blender (Debian's package, background mode) imports the frame's
# PLY mesh and its .vdb volume; both must lie where the ball lies, z-up: on the floor z = 0, centred
# at x = 0.1, y = -0.1 (the scene's z = 0.1 turned to -y). Skipped (77) where Blender is absent.
#   tests/blender_import_test.sh STOKESVDB_BINARY SOURCE_DIR
set -euo pipefail
BIN=$1
SRC=$2
command -v blender > /dev/null || { echo "blender not installed: skipped"; exit 77; }
DIR=$(mktemp -d)
trap 'rm -rf "$DIR"' EXIT
cat > "$DIR/ball.json" <<'JSON'
{"name": "blender", "domain": {"min": [0, 0, 0], "max": [0.2, 0.2, 0.2]},
 "resolution": 32, "frames": 1, "fps": 24, "material": {"density": 1000, "viscosity": 1000},
 "gravity": [0, -9.81, 0],
 "liquid": [{"shape": "box", "min": [0.05, 0.0, 0.05], "max": [0.15, 0.05, 0.15]}],
 "output": {"preview": false, "mesh": true, "up_axis": "z"}}
JSON
"$BIN" run "$DIR/ball.json" --out "$DIR/out" --threads 2 2> "$DIR/run.log" || { cat "$DIR/run.log"; exit 1; }
# a 0.1 x 0.05 x 0.1 m block of stiff liquid on the floor, after 1/24 s: z-up, x in [0.05, 0.15],
# y in [-0.15, -0.05], z in [0, 0.05]; the surface lies within about half a cell (3 mm) of it
set +e
blender -b --factory-startup --python-exit-code 1 --python "$SRC/scripts/blender_check_frame.py" -- \
  "$DIR/out/frame_0001.ply" "$DIR/out/frame_0001.vdb" 0.05 -0.15 0.0 0.15 -0.05 0.05 0.006 > "$DIR/blender.log" 2>&1
rc=$?
grep -E "mesh:|volume:|blender_check_frame|Error|error" "$DIR/blender.log"
exit $rc
