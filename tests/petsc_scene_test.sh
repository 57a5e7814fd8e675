#!/bin/bash
# Scenes on PETSc with MPI ranks. A scene without reduced tiles is split over the ranks by blocks
# (sim/ranks/): each rank holds the particles of its blocks, builds its part of the step and solves
# it with the others. The liquid must end where the in-house run puts it (both solve to relative
# residual 1e-10, so the level sets of the last frame differ by rounding only), and a run on 1 rank
# must be the run on 2, bit for bit, with and without an emitter; each rank keeps its own
# checkpoints, and a resume on the same rank count continues them. With reduced tiles each rank
# builds the tiles near its blocks, and a tiled drop is the same run on 1, 2 and 3 ranks; adaptive
# tiles gather the whole problem on every rank, the same run on 1 and 2 ranks. Also: the stats name PETSc on 2 ranks, and the combinations
# the backend refuses exit 2 with the reason.
#   tests/petsc_scene_test.sh STOKESVDB_BINARY MPIEXEC
set -euo pipefail
BIN=$1
MPIEXEC=$2
DIR=$(mktemp -d)
trap 'rm -rf "$DIR"' EXIT
# same_run A.csv B.csv: every statistic but the timings, the solver's name and the bytes sent is
# the same in two runs' stats.csv (a split run on two rank counts)
same_run() {
  python3 - "$1" "$2" <<'PY'
import csv, sys
one, two = (list(csv.DictReader(open(p))) for p in sys.argv[1:])
assert len(one) == len(two) and float(one[-1]["particles"]) > 0, f"{len(one)} against {len(two)} steps"
for a, b in zip(one, two):
    for k in a:
        if not (k.endswith("_s") or k in ("solver", "sent_bytes")):
            assert a[k] == b[k], f"{sys.argv[1]}, step {a['step']}: {k} {a[k]} against {b[k]}"
PY
}
# run_both NAME: NAME.json run in-house into NAME-inhouse, and on PETSc on 1 and 2 ranks into
# NAME-petsc1 and NAME-petsc2
run_both() {
  "$BIN" run "$DIR/$1.json" --out "$DIR/$1-inhouse" --threads 1 2> "$DIR/$1-inhouse.log" ||
    { cat "$DIR/$1-inhouse.log"; exit 1; }
  for np in 1 2; do
    "$MPIEXEC" -np $np "$BIN" run "$DIR/$1.json" --out "$DIR/$1-petsc$np" --threads 1 --backend petsc \
      2> "$DIR/$1-petsc$np.log" || { cat "$DIR/$1-petsc$np.log"; exit 1; }
  done
}
# close_frames A.vdb B.vdb NAME: the two level sets differ by at most 1e-6 of A's volume (the
# solves' tolerance moves the surface by far less than a cell)
close_frames() {
  "$BIN" compare "$1" "$2" --json > "$DIR/$3.json"
  python3 -c 'import json, sys; c = json.load(open(sys.argv[1])); assert c["relative_to_a"] <= 1e-6, c' "$DIR/$3.json"
}
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
# one rank: the same run bit for bit -- the particle stages do not depend on the rank count, and
# the solve's dot products are exact (solver/petsc/exact_dot.h): every statistic but the timings,
# the solver's name and the bytes sent is the same, and so is the frame
"$MPIEXEC" -np 1 "$BIN" run "$DIR/drop.json" --out "$DIR/petsc1" --threads 1 --backend petsc 2> "$DIR/petsc1.log" ||
  { cat "$DIR/petsc1.log"; exit 1; }
same_run "$DIR/petsc1/stats.csv" "$DIR/petsc/stats.csv"
"$BIN" compare "$DIR/petsc1/frame_0003.vdb" "$DIR/petsc/frame_0003.vdb" --json > "$DIR/ranks-compare.json"
python3 -c 'import json, sys; c = json.load(open(sys.argv[1])); assert c["symmetric_difference"] == 0, c' "$DIR/ranks-compare.json"
# the analytic ball (PETSc CG + Jacobi, set up per rank) on 1 and 3 ranks: the same velocities on
# every face, bit for bit, and the same iterations
"$MPIEXEC" -np 1 "$BIN" analytic ball --n 20 --form spd --backend petsc --faces-out "$DIR/faces.bin" --json \
  > "$DIR/ball1.json" 2> /dev/null < /dev/null
"$MPIEXEC" -np 3 "$BIN" analytic ball --n 20 --form spd --backend petsc --faces-compare "$DIR/faces.bin" --json \
  > "$DIR/ball3.json" 2> /dev/null < /dev/null
python3 - "$DIR/ball1.json" "$DIR/ball3.json" <<'PY'
import json, sys
one, three = (json.loads(open(p).readline()) for p in sys.argv[1:])
assert one["iterations"] == three["iterations"], (one["iterations"], three["iterations"])
assert three["faces_compared"] > 0 and three["faces_difference"] == 0.0, three
PY
# resume on 2 ranks from the checkpoints of frame 3: two more frames, as a run of 5 frames has them
"$MPIEXEC" -np 2 "$BIN" run "$DIR/drop.json" --out "$DIR/petsc" --threads 1 --backend petsc --frames 5 --resume \
  2> "$DIR/resume.log" || { cat "$DIR/resume.log"; exit 1; }
"$MPIEXEC" -np 2 "$BIN" run "$DIR/drop.json" --out "$DIR/petsc5" --threads 1 --backend petsc --frames 5 \
  2> "$DIR/petsc5.log" || { cat "$DIR/petsc5.log"; exit 1; }
close_frames "$DIR/petsc5/frame_0005.vdb" "$DIR/petsc/frame_0005.vdb" resume-compare
# an emitter: rank 0 seeds, every rank sets the velocity of its particles in the emitter, and the
# coil-free statistics are the same on 1 and 2 ranks; the frame matches the in-house run
sed 's/"frames": 3/"frames": 2, "emitters": [{"shape": "disc", "center": [0.1, 0.17, 0.1], "radius": 0.02, "normal": [0, -1, 0], "velocity": [0, -0.2, 0], "start": 0.0}]/' \
  "$DIR/drop.json" > "$DIR/emit.json"
run_both emit
same_run "$DIR/emit-petsc1/stats.csv" "$DIR/emit-petsc2/stats.csv"
close_frames "$DIR/emit-inhouse/frame_0002.vdb" "$DIR/emit-petsc2/frame_0002.vdb" emit-compare
# with reduced tiles each rank builds the tiles near its blocks on a deeper halo and solves its
# part: the same frame as in-house, and the same run on 1, 2 and 3 ranks
sed 's/"frames": 3/"frames": 1, "model": {"type": "quadratic", "tile": 6, "padding": 2}/; s/"resolution": 16/"resolution": 32/' \
  "$DIR/drop.json" > "$DIR/tiles.json"
run_both tiles
"$MPIEXEC" -np 3 "$BIN" run "$DIR/tiles.json" --out "$DIR/tiles-petsc3" --threads 1 --backend petsc \
  2> "$DIR/tiles-petsc3.log" || { cat "$DIR/tiles-petsc3.log"; exit 1; }
python3 - "$DIR/tiles-petsc2/stats.csv" <<'PY'
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
assert all(int(r["tiles"]) > 0 for r in rows), "the tiled drop made no tiles"
assert all("each holding" in r["solver"] for r in rows), "a tiled step was not solved by parts"
assert all(float(r["sent_bytes"]) > 0 for r in rows)
PY
same_run "$DIR/tiles-petsc1/stats.csv" "$DIR/tiles-petsc2/stats.csv"
same_run "$DIR/tiles-petsc1/stats.csv" "$DIR/tiles-petsc3/stats.csv"
close_frames "$DIR/tiles-inhouse/frame_0001.vdb" "$DIR/tiles-petsc2/frame_0001.vdb" tiles-compare
# adaptive tiles (whose split test reads the whole liquid): every rank gathers the whole problem
# and solves it with the others, the same run on 1 and 2 ranks
sed 's/"frames": 3/"frames": 1, "model": {"type": "quadratic", "tile": 8, "tile_min": 4, "tile_accuracy": 0.2, "padding": 2}/; s/"resolution": 16/"resolution": 32/' \
  "$DIR/drop.json" > "$DIR/adaptive.json"
for np in 1 2; do
  "$MPIEXEC" -np $np "$BIN" run "$DIR/adaptive.json" --out "$DIR/adaptive-petsc$np" --threads 1 --backend petsc \
    2> "$DIR/adaptive-petsc$np.log" || { cat "$DIR/adaptive-petsc$np.log"; exit 1; }
done
python3 - "$DIR/adaptive-petsc2/stats.csv" <<'PY'
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
assert all(int(r["tiles"]) > 0 for r in rows), "the adaptive drop made no tiles"
assert not any("each holding" in r["solver"] for r in rows), "an adaptive tiled step was solved by parts"
PY
same_run "$DIR/adaptive-petsc1/stats.csv" "$DIR/adaptive-petsc2/stats.csv"
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
