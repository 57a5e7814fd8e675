#!/usr/bin/env bash
# The armadillo pile at rest at a large resolution (PolyStokes' size, ~2-3 M uniform unknowns),
# uniform against quadratic tiles (bench/results/reduced_tiles.md):
#  1. scenes/armadillo_pile.json, uniform, at REST_RES to its last frame (at rest), writing the
#     liquid surface (output.mesh);
#  2. that surface as the liquid of a copy of the scene (the liquid at rest, v = 0), run at RES for
#     FRAMES frames uniform and with each TILE/PAD of quadratic tiles, one after the other;
#  3. per run and frame: steps, iterations, Stokes and step seconds, Krylov rows, tiles; per run
#     the wall time and peak memory (/usr/bin/time -v), ns per Krylov row per iteration, and the
#     symmetric volume difference of its last frame from the uniform one (`stokesvdb compare`).
# Falling to rest at RES itself would take ~100 steps per frame; the study starts from the rest
# that the coarse run reached.
#   bash bench/scripts/pile_at_rest_study.sh [res] [frames] [tile/pad ...]
# defaults: res 896, 2 frames, 32/4 16/3; REST_RES (default 192), THREADS (default 2), BIN.
# Takes ~25 minutes on 2 cores with the defaults; keeps its folders in $OUT (default a temporary one).
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
BIN=${BIN:-$ROOT/build/bin/stokesvdb}
THREADS=${THREADS:-2}
REST_RES=${REST_RES:-192}
RES=${1:-896}
FRAMES=${2:-2}
shift $(( $# > 2 ? 2 : $# ))
TILINGS=("$@")
[ ${#TILINGS[@]} -gt 0 ] || TILINGS=(32/4 16/3)
OUT=${OUT:-$(mktemp -d)}
mkdir -p "$OUT"

# 1. the pile at rest at REST_RES, its last surface as an OBJ mesh
python3 - "$ROOT/scenes/armadillo_pile.json" "$OUT/pile_mesh.json" <<'PY'
import json, os, sys
src, dst = sys.argv[1:]
j = json.load(open(src))
for shape in j["liquid"]:
    shape["file"] = os.path.normpath(os.path.join(os.path.dirname(src), shape["file"]))
j["output"].update({"mesh": True, "preview": False})
json.dump(j, open(dst, "w"), indent=1)
PY
"$BIN" run "$OUT/pile_mesh.json" --out "$OUT/rest$REST_RES" --res "$REST_RES" --threads "$THREADS" --model uniform >/dev/null 2>"$OUT/rest$REST_RES.log"
LAST=$(ls "$OUT/rest$REST_RES"/frame_*.ply | tail -1)
python3 - "$LAST" "$OUT/rest.obj" <<'PY'
import struct, sys
src, dst = sys.argv[1:]
data = open(src, "rb").read()
end = data.index(b"end_header\n") + len(b"end_header\n")
header = data[:end].decode().split("\n")
count = lambda element: int(next(l for l in header if l.startswith("element " + element)).split()[-1])
nv, nf = count("vertex"), count("face")
points = struct.unpack_from("<%df" % (3 * nv), data, end)
with open(dst, "w") as out:
    for i in range(nv):
        out.write("v %.7g %.7g %.7g\n" % points[3 * i:3 * i + 3])
    at = end + 12 * nv
    for f in range(nf):
        n, a, b, c = struct.unpack_from("<Biii", data, at + 13 * f)
        out.write("f %d %d %d\n" % (a + 1, b + 1, c + 1))
PY

# 2. the rest scene per tiling, runs at RES
rest_scene() {  # tile, pad -> the scene's path
  python3 - "$OUT/pile_mesh.json" "$OUT/rest.obj" "$1" "$2" "$OUT/rest_$1_$2.json" <<'PY'
import json, sys
src, mesh, tile, pad, dst = sys.argv[1:]
j = json.load(open(src))
j["name"] = "armadillo_pile_at_rest"
j["liquid"] = [{"shape": "mesh", "file": mesh, "scale": 1.0, "rotation_degrees": [0, 0, 0], "translation": [0, 0, 0]}]
j["model"].update({"tile": int(tile), "padding": int(pad)})
j["output"].update({"mesh": False})
json.dump(j, open(dst, "w"), indent=1)
PY
  echo "$OUT/rest_$1_$2.json"
}

one_run() {  # label, scene, model, folder
  /usr/bin/time -v "$BIN" run "$2" --out "$4" --frames "$FRAMES" --res "$RES" --threads "$THREADS" --model "$3" >/dev/null 2>"$4.time"
  local wall peak
  wall=$(grep "Elapsed (wall" "$4.time" | awk '{print $NF}')
  peak=$(grep "Maximum resident" "$4.time" | awk '{print $NF}')
  awk -F, -v label="$1" 'NR == 1 { for (i = 1; i <= NF; ++i) col[$i] = i; next }
     { f = $col["frame"]; last = f > last ? f : last; steps[f]++; its[f] += $col["iterations"]; stokes[f] += $col["stokes_s"]; step[f] += $col["step_s"]
       rows[f] = $col["krylov_rows"]; tiles[f] = $col["tiles"]; dofs[f] = $col["tile_unknowns"]
       work += $col["iterations"] * $col["krylov_rows"]; krylov += $col["krylov_s"] }
     END { for (f = 1; f <= last; ++f) printf "| %s | %d | %d | %d | %.1f | %.1f | %d | %d (%d) |\n", label, f, steps[f], its[f],
             stokes[f], step[f], rows[f], tiles[f], dofs[f]
           printf "| %s | ns per Krylov row per iteration %.1f |\n", label, 1e9 * krylov / work }' "$4/stats.csv"
  echo "| $1 | wall $wall, peak $((peak / 1024)) MB |"
}

echo "pile at rest: res $RES (rest from res $REST_RES), $FRAMES frames, $THREADS threads, $(date -u +%FT%TZ), load $(cut -d' ' -f1-3 /proc/loadavg)"
echo "| run | frame | steps | iterations | Stokes s | step s | Krylov rows | tiles (DOFs) |"
echo "|---|---|---|---|---|---|---|---|"
first=${TILINGS[0]}
one_run uniform "$(rest_scene "${first%/*}" "${first#*/}")" uniform "$OUT/uniform"
for t in "${TILINGS[@]}"; do
  one_run "quadratic $t" "$(rest_scene "${t%/*}" "${t#*/}")" quadratic "$OUT/quadratic_${t%/*}_${t#*/}"
done
LASTFRAME=$(printf "frame_%04d.vdb" "$FRAMES")
for t in "${TILINGS[@]}"; do
  echo "quadratic $t against uniform, frame $FRAMES: $("$BIN" compare "$OUT/uniform/$LASTFRAME" "$OUT/quadratic_${t%/*}_${t#*/}/$LASTFRAME" | tail -1)"
done
