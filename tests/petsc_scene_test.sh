#!/bin/bash
# Scenes on PETSc with MPI ranks. A scene without emitters or tiles is split over the ranks by
# blocks (sim/ranks/): each rank holds the particles of its blocks, builds its part of the step and
# solves it with the others. The liquid must end where the in-house run puts it (both solve to
# relative residual 1e-10, so the level sets of the last frame differ by rounding only), on 1 and 2
# ranks alike with the same steps; each rank keeps its own checkpoints, and a resume on the same
# rank count continues them. A scene with an emitter keeps its particles on rank 0, which sends
# each rank its blocks of each step (solver/step/remote_step.h); with reduced tiles rank 0 sends
# every rank the whole problem. Also: the stats name PETSc on 2 ranks, and the combinations the
# backend refuses exit 2 with the reason.
#   tests/petsc_scene_test.sh STOKESVDB_BINARY MPIEXEC
set -euo pipefail
BIN=$1
MPIEXEC=$2
DIR=$(mktemp -d)
trap 'rm -rf "$DIR"' EXIT
cat > "$DIR/drop.json" <<'JSON'
{"name": "petsc-drop", "domain": {"min": [0, 0, 0], "max": [0.2, 0.2, 0.2]},
 "resolution": 16, "frames": 3, "fps": 24, "material": {"density": 1000, "viscosity": 500},
 "gravity": [0, -9.81, 0],
 "liquid": [{"shape": "sphere", "center": [0.1, 0.08, 0.1], "radius": 0.05}],
 "solver": {"tolerance": 1e-10, "max_iterations": 20000},
 "output": {"preview": false}}
JSON
"$BIN" run "$DIR/drop.json" --out "$DIR/inhouse" --threads 1 2> "$DIR/inhouse.log" || { cat "$DIR/inhouse.log"; exit 1; }
"$MPIEXEC" -np 2 "$BIN" run "$DIR/drop.json" --out "$DIR/petsc" --threads 1 --backend petsc 2> "$DIR/petsc.log" ||
  { cat "$DIR/petsc.log"; exit 1; }
grep -q "PETSc cg + jacobi on 2 ranks, each holding its blocks and a halo" "$DIR/petsc/stats.csv" ||
  { echo "stats.csv does not name PETSc on 2 ranks, each with its part of the problem"; exit 1; }
# split over ranks: rank 0 sends particles (migration, ghosts) and halo velocities, no problem;
# sent_bytes counts them (0 in-house); the other rank keeps its checkpoints in ranks/rank_0001
python3 - "$DIR/inhouse/stats.csv" "$DIR/petsc/stats.csv" <<'PY'
import csv, sys
inhouse = [float(r["sent_bytes"]) for r in csv.DictReader(open(sys.argv[1]))]
petsc = list(csv.DictReader(open(sys.argv[2])))
assert all(b == 0 for b in inhouse), "an in-house run sent bytes"
assert all(float(r["sent_bytes"]) > 0 for r in petsc), "a split step sent nothing"
assert all(float(r["migrate_s"]) >= 0 for r in petsc), "no migrate stage"
PY
ls "$DIR/petsc/ranks/rank_0001/checkpoints/"*.ckpt > /dev/null || { echo "rank 1 kept no checkpoint"; exit 1; }
# one rank: the same steps and frame
"$MPIEXEC" -np 1 "$BIN" run "$DIR/drop.json" --out "$DIR/petsc1" --threads 1 --backend petsc 2> "$DIR/petsc1.log" ||
  { cat "$DIR/petsc1.log"; exit 1; }
[ "$(wc -l < "$DIR/petsc1/stats.csv")" -eq "$(wc -l < "$DIR/petsc/stats.csv")" ] ||
  { echo "1 and 2 ranks took different step counts"; exit 1; }
"$BIN" compare "$DIR/petsc1/frame_0003.vdb" "$DIR/petsc/frame_0003.vdb" --json > "$DIR/ranks-compare.json"
python3 -c 'import json, sys; c = json.load(open(sys.argv[1])); assert c["relative_to_a"] <= 1e-6, c' "$DIR/ranks-compare.json"
# resume on 2 ranks from the checkpoints of frame 3: two more frames, as a run of 5 frames has them
"$MPIEXEC" -np 2 "$BIN" run "$DIR/drop.json" --out "$DIR/petsc" --threads 1 --backend petsc --frames 5 --resume \
  2> "$DIR/resume.log" || { cat "$DIR/resume.log"; exit 1; }
"$MPIEXEC" -np 2 "$BIN" run "$DIR/drop.json" --out "$DIR/petsc5" --threads 1 --backend petsc --frames 5 \
  2> "$DIR/petsc5.log" || { cat "$DIR/petsc5.log"; exit 1; }
"$BIN" compare "$DIR/petsc5/frame_0005.vdb" "$DIR/petsc/frame_0005.vdb" --json > "$DIR/resume-compare.json"
python3 -c 'import json, sys; c = json.load(open(sys.argv[1])); assert c["relative_to_a"] <= 1e-6, c' "$DIR/resume-compare.json"
# an emitter keeps the particles on rank 0, which sends each rank its blocks of each step
sed 's/"frames": 3/"frames": 2, "emitters": [{"shape": "disc", "center": [0.1, 0.17, 0.1], "radius": 0.02, "normal": [0, -1, 0], "velocity": [0, -0.2, 0], "start": 0.0}]/' \
  "$DIR/drop.json" > "$DIR/emit.json"
"$BIN" run "$DIR/emit.json" --out "$DIR/emit-inhouse" --threads 1 2> "$DIR/emit-inhouse.log" ||
  { cat "$DIR/emit-inhouse.log"; exit 1; }
"$MPIEXEC" -np 2 "$BIN" run "$DIR/emit.json" --out "$DIR/emit-petsc" --threads 1 --backend petsc 2> "$DIR/emit-petsc.log" ||
  { cat "$DIR/emit-petsc.log"; exit 1; }
python3 - "$DIR/emit-petsc/stats.csv" <<'PY'
import csv, sys
for r in csv.DictReader(open(sys.argv[1])):  # at least the weights and u* of the other rank's half
    assert "each holding its blocks and a halo" in r["solver"], r["solver"]
    assert float(r["sent_bytes"]) >= 8 * 4 * float(r["cells"]) / 2, f"step {r['step']}: {r['sent_bytes']} bytes"
PY
"$BIN" compare "$DIR/emit-inhouse/frame_0002.vdb" "$DIR/emit-petsc/frame_0002.vdb" --json > "$DIR/emit-compare.json"
python3 -c 'import json, sys; c = json.load(open(sys.argv[1])); assert c["relative_to_a"] <= 1e-6, c' "$DIR/emit-compare.json"
"$BIN" compare "$DIR/inhouse/frame_0003.vdb" "$DIR/petsc/frame_0003.vdb" --json > "$DIR/compare.json"
cat "$DIR/compare.json"
python3 - "$DIR/compare.json" <<'PY'
import json, sys
c = json.load(open(sys.argv[1]))
# rounding-level differences move the surface by far less than a cell; 1e-6 of the volume is a
# thousandth of one cell's volume here
assert c["relative_to_a"] <= 1e-6, f"PETSc frame differs from the in-house frame by {c['relative_to_a']:.3g} of its volume"
assert abs(c["volume_b"] / c["volume_a"] - 1.0) <= 1e-6
PY
# with reduced tiles (a tile region may span ranks) rank 0 sends every rank the whole problem: the
# same frame again
sed 's/"frames": 3/"frames": 1, "model": {"type": "quadratic", "tile": 6, "padding": 2}/; s/"resolution": 16/"resolution": 32/' \
  "$DIR/drop.json" > "$DIR/tiles.json"
"$BIN" run "$DIR/tiles.json" --out "$DIR/tiles-inhouse" --threads 1 2> "$DIR/tiles-inhouse.log" ||
  { cat "$DIR/tiles-inhouse.log"; exit 1; }
"$MPIEXEC" -np 2 "$BIN" run "$DIR/tiles.json" --out "$DIR/tiles-petsc" --threads 1 --backend petsc 2> "$DIR/tiles-petsc.log" ||
  { cat "$DIR/tiles-petsc.log"; exit 1; }
python3 - "$DIR/tiles-petsc/stats.csv" <<'PY'
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
assert all(int(r["tiles"]) > 0 for r in rows), "the tiled drop made no tiles"
assert not any("each holding" in r["solver"] for r in rows), "a tiled step was solved by parts"
assert all(float(r["sent_bytes"]) > 0 for r in rows)
PY
"$BIN" compare "$DIR/tiles-inhouse/frame_0001.vdb" "$DIR/tiles-petsc/frame_0001.vdb" --json > "$DIR/tiles-compare.json"
python3 -c 'import json, sys; c = json.load(open(sys.argv[1])); assert c["relative_to_a"] <= 1e-6, c' "$DIR/tiles-compare.json"
# refused combinations: a decoupled viscosity solve on PETSc, PETSc options without the backend
set +e
"$BIN" run "$DIR/drop.json" --out "$DIR/refused" --viscosity decoupled --backend petsc 2> "$DIR/refused.log"
rc=$?
set -e
[ $rc -eq 2 ] && grep -q "decoupled viscosity solve runs in-house only" "$DIR/refused.log" ||
  { echo "decoupled + petsc: exit $rc"; cat "$DIR/refused.log"; exit 1; }
set +e
"$BIN" run "$DIR/drop.json" --out "$DIR/refused2" -pc_type gamg 2> "$DIR/refused2.log"
rc=$?
set -e
[ $rc -eq 2 ] && grep -q "PETSc options (-pc_type ...) need" "$DIR/refused2.log" ||
  { echo "PETSc options without the backend: exit $rc"; cat "$DIR/refused2.log"; exit 1; }
echo "PETSc scene run on 2 ranks matches the in-house run"
