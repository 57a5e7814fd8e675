#!/usr/bin/env bash
# Rows and halo per MPI rank of the PETSc backend's split (docs/petsc.md, "Partition"), as counts:
# the analytic ball's pressure-stress solve on 1, 2, 4, 8 and 16 ranks (oversubscribed where the
# machine has fewer cores; the counts do not depend on the timing), a few CG iterations each.
# Then the per-step broadcast of a scene on 2 ranks (rank 0 sends each step's problem to every
# other rank; each receives the same bytes whatever the rank count): SCENE (default the armadillos)
# at SCENE_RES (default 96) for one frame.
#   bash bench/scripts/rank_counts.sh [n ...]      (default: 64 128)
# Prints one line per case and rank count: owned rows per rank (fewest-most), the halo rows the
# largest rank receives per apply and their sum over the ranks, and the bytes per apply (8 each);
# then per step of the scene its cells and the bytes each other rank received.
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
BIN=${BIN:-$ROOT/build/bin/stokesvdb}
SIZES=("$@")
[ ${#SIZES[@]} -gt 0 ] || SIZES=(64 128)
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMP_NUM_THREADS=1
echo "case ranks rows_per_rank halo_max halo_sum bytes_per_apply_max bytes_per_apply_sum"
for n in "${SIZES[@]}"; do
  for ranks in 1 2 4 8 16; do
    # --max-iter 3: the solve stops unconverged (exit status 3) once the split is made and used
    line=$( (mpirun --oversubscribe -np "$ranks" "$BIN" analytic ball --n "$n" --form spd --backend petsc \
               --max-iter 3 --json 2>/dev/null || true) | head -1 |
           python3 -c 'import json,sys; print(json.load(sys.stdin)["solver"])')
    python3 - "$n" "$ranks" "$line" <<'PY'
import re, sys
n, ranks, solver = sys.argv[1:]
m = re.search(r"rows per rank (\d+)-(\d+), halo rows per apply (\d+) on the largest rank, (\d+) in all", solver)
if m:
    lo, hi, hmax, hsum = map(int, m.groups())
    print(f"ball{n} {ranks} {lo}-{hi} {hmax} {hsum} {8 * hmax} {8 * hsum}")
else:
    print(f"ball{n} {ranks} (one rank: no halo) 0 0 0 0")
PY
  done
done

SCENE=${SCENE:-$ROOT/scenes/armadillos.json}
SCENE_RES=${SCENE_RES:-96}
OUT=$(mktemp -d)
trap 'rm -rf "$OUT"' EXIT
mpirun --oversubscribe -np 2 "$BIN" run "$SCENE" --out "$OUT" --res "$SCENE_RES" --frames 1 --threads 1 \
  --backend petsc >/dev/null 2>"$OUT.log" < /dev/null
python3 - "$OUT/stats.csv" "$(basename "$SCENE" .json)" "$SCENE_RES" <<'PY'
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
print(f"scene {sys.argv[2]} res {sys.argv[3]}: step cells sent_bytes bytes_per_cell")
for r in rows:
    cells, sent = float(r["cells"]), float(r["sent_bytes"])
    print(f"  {r['step']} {int(cells)} {int(sent)} {sent / cells:.1f}")
PY
