#!/usr/bin/env bash
# Per-rank work and messages of the PETSc backend (docs/petsc.md, "Partition" and "Per-rank
# set-up"), as counts: they do not depend on the timing, so the ranks may be oversubscribed.
# 1. The analytic ball's pressure-stress solve set up per rank (each rank builds its blocks and a
#    halo) on 1, 2, 4, 8 and 16 ranks, a few CG iterations each: owned rows per rank (fewest-most),
#    the padded rows rank 0 holds, the halo rows the largest rank receives per apply and their sum
#    over the ranks (8 bytes each), and the largest rank's peak memory.
# 2. A scene split over the ranks (SCENE, default the armadillos, uniform model, at SCENE_RES,
#    default 96) for one frame on the same rank counts: per step the bytes the ranks sent each
#    other outside the solve (migration, ghosts, halo velocities) in all and per rank, the rows per
#    rank, and the largest rank's peak memory.
# 3. The pressure-velocity form on PETSc (MINRES, geometric multigrid on the velocity block), ball PV_N (default
#    64), to convergence on 1, 2, 4, 8 and 16 ranks: MINRES iterations and the largest rank's memory.
#   bash bench/scripts/rank_counts.sh [n ...]      (default: 64 128; PARTS="2 3" runs only those parts)
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
BIN=${BIN:-$ROOT/build/bin/stokesvdb}
SIZES=("$@")
[ ${#SIZES[@]} -gt 0 ] || SIZES=(64 128)
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMP_NUM_THREADS=1
export OMPI_MCA_mpi_yield_when_idle=1
PARTS=${PARTS:-1 2 3}
part() { [[ " $PARTS " == *" $1 "* ]]; }
part 1 && echo "case ranks rows_per_rank padded_rows_rank0 halo_max halo_sum bytes_per_apply_max bytes_per_apply_sum peak_mb_largest_rank"
part 1 && for n in "${SIZES[@]}"; do
  for ranks in 1 2 4 8 16; do
    # --max-iter 3: the solve stops unconverged (exit status 3) once the split is made and used
    json=$( (mpirun --oversubscribe -np "$ranks" "$BIN" analytic ball --n "$n" --form spd --backend petsc \
               --rank-setup own --max-iter 3 --json 2>/dev/null || true) | head -1)
    python3 - "$n" "$ranks" "$json" <<'PY'
import json, re, sys
n, ranks, text = sys.argv[1:]
r = json.loads(text)
m = re.search(r"rows per rank (\d+)-(\d+), halo rows per apply (\d+) on the largest rank, (\d+) in all", r["solver"])
lo, hi, hmax, hsum = map(int, m.groups()) if m else (r["krylov_rows"], r["krylov_rows"], 0, 0)
peak = r.get("peak_rss_mb_largest_rank", r["peak_rss_mb"])
print(f"ball{n} {ranks} {lo}-{hi} {r['padded_rows']} {hmax} {hsum} {8 * hmax} {8 * hsum} {peak:.0f}")
PY
  done
done

SCENE=${SCENE:-$ROOT/scenes/armadillos.json}
SCENE_RES=${SCENE_RES:-96}
OUT=$(mktemp -d)
trap 'rm -rf "$OUT"' EXIT
part 2 && echo "scene ranks step cells particles sent_bytes sent_bytes_per_rank bytes_per_cell_per_rank rows_per_rank peak_mb_largest_rank"
part 2 && for ranks in 1 2 4 8 16; do
  rm -rf "$OUT/run"
  mpirun --oversubscribe -np "$ranks" "$BIN" run "$SCENE" --out "$OUT/run" --res "$SCENE_RES" --frames 1 --threads 1 \
    --model uniform --backend petsc >/dev/null 2>"$OUT.log" < /dev/null
  python3 - "$OUT/run/stats.csv" "$(basename "$SCENE" .json)$SCENE_RES" "$ranks" "$OUT.log" <<'PY'
import csv, re, sys
name, ranks = sys.argv[2], int(sys.argv[3])
peak = re.search(r"peak memory (\d+) MB", open(sys.argv[4]).read())
for r in csv.DictReader(open(sys.argv[1])):
    cells, sent = float(r["cells"]), float(r["sent_bytes"])
    per = sent / ranks
    m = re.search(r"rows per rank (\d+-\d+)", r["solver"])
    print(f"{name} {ranks} {r['step']} {int(cells)} {r['particles']} {int(sent)} {int(per)} {per / cells:.1f} "
          f"{m.group(1) if m else r['unknowns']} {peak.group(1) if peak else '?'}")
PY
done

PV_N=${PV_N:-64}
part 3 && echo "case ranks minres_iterations true_relative_residual peak_mb_largest_rank"
part 3 && for ranks in 1 2 4 8 16; do
  json=$( (mpirun --oversubscribe -np "$ranks" "$BIN" analytic ball --n "$PV_N" --form pv --backend petsc --json \
             2>/dev/null || true) | head -1)
  python3 - "$PV_N" "$ranks" "$json" <<'PY'
import json, sys
n, ranks, text = sys.argv[1:]
r = json.loads(text)
print(f"ball{n}-pv {ranks} {r['iterations']} {r['relative_residual']:.2e} {r.get('peak_rss_mb_largest_rank', r['peak_rss_mb']):.0f}")
PY
done
