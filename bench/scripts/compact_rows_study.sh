#!/usr/bin/env bash
# Krylov vectors on the live rows against the padded 8^Dim blocks, in the same
# binary: analytic disks and balls (Jacobi CG, unified Stokes, SPD form) and the first frames of
# the armadillos. Three layouts: "rows" (live rows, stencils through the neighbour index of
# kernels/compact_stencils.h), "blocks" (live rows, stencils sweeping the blocks that hold them),
# "padded" (every slot of every block). Prints one Markdown row per run and peak RSS (GNU time).
# Usage: bench/scripts/compact_rows_study.sh [threads] > table.md
#   BIN picks the binary, TOL the relative tolerance (analytic cases), SCENE_RES / SCENE_FRAMES the
#   scene run (SCENE_FRAMES=0 skips it), DISKS / BALLS the sizes.
set -uo pipefail
BIN="${BIN:-build/bin/stokesvdb}"
THREADS="${1:-1}"
TOL="${TOL:-1e-8}"
DISKS="${DISKS:-64 128 256}"
BALLS="${BALLS:-32 48 64}"
SCENE_RES="${SCENE_RES:-96}"
SCENE_FRAMES="${SCENE_FRAMES:-2}"
export OMP_WAIT_POLICY="${OMP_WAIT_POLICY:-passive}"
flags() {  # layout -> command-line flags
  case $1 in rows) echo "--rows compact --stencils rows" ;; blocks) echo "--rows compact --stencils blocks" ;;
    *) echo "--rows padded" ;; esac
}
LAYOUTS="${LAYOUTS:-rows blocks padded}"
echo "| case | rows | unknowns | Krylov rows | padded rows | iterations | solve s | ns / unknown / iteration | peak RSS MB |"
echo "|---|---|---|---|---|---|---|---|---|"
analytic() {  # test n rows extra...
  local test=$1 n=$2 rows=$3; shift 3
  local out
  out=$(/usr/bin/time -f "RSS %M" "$BIN" analytic "$test" --n "$n" --tol "$TOL" --threads "$THREADS" $(flags "$rows") \
        --form spd --precond jacobi --json "$@" 2>&1)
  python3 - "$test" "$n" "$rows" "$*" <<EOF
import json, sys
lines = """$out""".splitlines()
d = json.loads([l for l in lines if l.startswith("{")][0])
rss = int([l for l in lines if l.startswith("RSS ")][0].split()[1]) / 1024
t, n, rows, extra = sys.argv[1:5]
ns = 1e9 * d["solve_seconds"] / max(1, d["iterations"]) / max(1, d["unknowns"])
print(f"| {t} N={n} {extra} | {rows} | {d['unknowns']:,} | {d['krylov_rows']:,} | {d['padded_rows']:,} | "
      f"{d['iterations']} | {d['solve_seconds']:.2f} | {ns:.1f} | {rss:.0f} |")
EOF
}
for n in $DISKS; do for rows in $LAYOUTS; do analytic disk-stokes "$n" $rows; done; done
for n in 128; do for rows in $LAYOUTS; do analytic disk-stokes "$n" $rows --model quadratic; done; done
for n in $BALLS; do for rows in $LAYOUTS; do analytic ball "$n" $rows; done; done
[ "$SCENE_FRAMES" -gt 0 ] || exit 0
for rows in $LAYOUTS; do
  out=$(mktemp -d)
  /usr/bin/time -f "RSS %M" "$BIN" run scenes/armadillos.json --res "$SCENE_RES" --frames "$SCENE_FRAMES" \
    --threads "$THREADS" $(flags "$rows") --out "$out" > "$out/log" 2>&1
  python3 - "$out" "$rows" "$SCENE_RES" <<'EOF'
import csv, sys
out, rows, res = sys.argv[1:4]
r = [x for x in csv.DictReader(open(f"{out}/stats.csv")) if int(x["iterations"]) > 0]
rss = int([l for l in open(f"{out}/log") if l.startswith("RSS ")][0].split()[1]) / 1024
it = sum(int(x["iterations"]) for x in r); s = sum(float(x["krylov_s"]) for x in r)
unk = sum(int(x["unknowns"]) for x in r) / len(r)
print(f"| armadillos res {res}, {len(r)} solves | {rows} | {unk:,.0f} (mean) | - | - | {it / len(r):.0f} (mean) | "
      f"{s / len(r):.2f} (mean) | {1e9 * s / it / unk:.0f} | {rss:.0f} |")
EOF
  rm -rf "$out"
done
