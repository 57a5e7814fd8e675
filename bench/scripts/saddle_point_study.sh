#!/usr/bin/env bash
# The pressure-velocity form's Krylov method and block preconditioner on the scenes
# (bench/results/saddle_point.md): Jacobi CG on the SPD form, the multigrid under MINRES (block
# diagonal) and under GMRES (block upper-triangular), and the default ("auto"), each over the same
# frames. Per run: steps, steps on the multigrid, median iterations per step, Krylov and set-up
# seconds, the Stokes stage's seconds (stats.csv stokes_s), peak memory (/usr/bin/time -v); then
# per viscous number mu dt / (rho dx^2) the multigrid / Jacobi Krylov time on matched steps.
#   bash bench/scripts/saddle_point_study.sh THREADS FRAMES SCENE:RES [VARIANT ...]
# variants (default all): jacobi multigrid:minres multigrid:gmres auto
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
BIN=${BIN:-$ROOT/build/bin/stokesvdb}
THREADS=${1:?threads}
FRAMES=${2:?frames}
CASE=${3:?scene:res}
shift 3
VARIANTS=("$@")
[ ${#VARIANTS[@]} -gt 0 ] || VARIANTS=(jacobi multigrid:minres multigrid:gmres auto)
SCENE=${CASE%%:*}
RES=${CASE##*:}
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
source "$ROOT/bench/scripts/scene_study_common.sh"

echo "$SCENE res $RES, $FRAMES frames, $THREADS threads, $(date -u +%FT%TZ), load $(cut -d' ' -f1-3 /proc/loadavg)"
echo "| run | steps | multigrid steps | median iterations | Krylov s | set-up s | Stokes s | peak MB |"
echo "|---|---|---|---|---|---|---|---|"
for v in "${VARIANTS[@]}"; do
  pre=${v%%:*}
  method=auto
  [[ $v == *:* ]] && method=${v##*:}
  out="$TMP/out_${pre}_$method"
  /usr/bin/time -v "$BIN" run "$(scene_with "$SCENE" "$pre" "$method")" --out "$out" --frames "$FRAMES" --res "$RES" \
    --threads "$THREADS" >/dev/null 2>"$TMP/err"
  peak=$(grep "Maximum resident" "$TMP/err" | awk '{print $NF}')
  /usr/bin/python3 - "$out/stats.csv" "$v" "$peak" <<'PY'
import csv, statistics, sys
rows = list(csv.DictReader(open(sys.argv[1])))
total = lambda key: sum(float(r[key] or 0) for r in rows)
mg = sum("multigrid" in r["solver"] for r in rows)
its = statistics.median(int(r["iterations"]) for r in rows)
print(f"| {sys.argv[2]} | {len(rows)} | {mg} | {its:.0f} | {total('krylov_s'):.2f} | {total('setup_s'):.2f} | "
      f"{total('stokes_s'):.2f} | {int(sys.argv[3]) // 1024} |")
PY
done
if [ -d "$TMP/out_jacobi_auto" ] && [ -d "$TMP/out_multigrid_gmres" ]; then
  /usr/bin/python3 - "$ROOT/scenes/$SCENE.json" "$RES" "$TMP/out_jacobi_auto/stats.csv" "$TMP/out_multigrid_gmres/stats.csv" <<'PY'
import collections, csv, json, sys
scene = json.load(open(sys.argv[1]))
extent = [b - a for a, b in zip(scene["domain"]["min"], scene["domain"]["max"])]
dx = max(extent) / int(sys.argv[2])
nu_per_dt = scene["material"]["viscosity"] / (scene["material"]["density"] * dx * dx)
a = list(csv.DictReader(open(sys.argv[3])))
b = list(csv.DictReader(open(sys.argv[4])))
bins = collections.defaultdict(lambda: [0, 0.0, 0.0, 0, 0])
for ra, rb in zip(a, b):
    if ra["dt"] != rb["dt"]:
        continue
    nu = nu_per_dt * float(ra["dt"])
    key = int(nu) if nu < 20 else (int(nu / 10) * 10 if nu < 100 else int(nu / 100) * 100)
    e = bins[key]
    e[0] += 1; e[1] += float(ra["krylov_s"]); e[2] += float(rb["krylov_s"])
    e[3] += int(ra["iterations"]); e[4] += int(rb["iterations"])
print("\n| viscous number (bin) | matched steps | Jacobi CG Krylov s | multigrid (GMRES) Krylov s | ratio | mean iterations |")
print("|---|---|---|---|---|---|")
for key in sorted(bins):
    n, ka, kb, ia, ib = bins[key]
    print(f"| {key} | {n} | {ka:.2f} | {kb:.2f} | {kb / ka:.2f} | {ia // n} / {ib // n} |")
PY
fi
