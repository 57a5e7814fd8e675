#!/usr/bin/env bash
# The scenes' default solver ("preconditioner": "auto", per step by size) against Jacobi CG over
# several frames (bench/results/multigrid_scenes.md): per run the steps, the solvers the
# steps ran, the Stokes stage's seconds per frame (stats.csv stokes_s), the wall time and peak
# memory (/usr/bin/time -v), then the symmetric volume difference of the last frames
# (`stokesvdb compare`).
#   bash bench/scripts/auto_solver_study.sh [threads] [frames] [scene:res ...]
# defaults: 2 threads, 3 frames, film_spreading:64 armadillos:128.
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
BIN=${BIN:-$ROOT/build/bin/stokesvdb}
THREADS=${1:-2}
FRAMES=${2:-3}
shift $(( $# > 2 ? 2 : $# ))
CASES=("$@")
[ ${#CASES[@]} -gt 0 ] || CASES=(film_spreading:64 armadillos:128)
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT

source "$ROOT/bench/scripts/scene_study_common.sh"

one_run() {  # label, scene file, res, output folder
  local wall peak
  /usr/bin/time -v "$BIN" run "$2" --out "$4" --frames "$FRAMES" --res "$3" --threads "$THREADS" >/dev/null 2>"$TMP/err"
  wall=$(grep "Elapsed (wall" "$TMP/err" | awk '{print $NF}')
  peak=$(grep "Maximum resident" "$TMP/err" | awk '{print $NF}')
  awk -F, -v label="$1" -v wall="$wall" -v peak="$peak" -v frames="$FRAMES" \
    'NR == 1 { for (i = 1; i <= NF; ++i) col[$i] = i; next }
     { steps++; stokes += $col["stokes_s"]; its += $col["iterations"]
       if ($col["solver"] ~ /multigrid/) mg++; else jac++ }
     END { printf "| %s | %d | %d / %d | %.0f | %.3f | %s | %.0f |\n", label, steps, jac, mg, its / steps,
           stokes / frames, wall, peak / 1024 }' "$4/stats.csv"
}

echo "threads $THREADS, $FRAMES frames, $(date -u +%FT%TZ), load $(cut -d' ' -f1-3 /proc/loadavg)"
echo "| run | steps | steps on Jacobi CG / multigrid | mean iterations | Stokes s per frame | wall | peak MB |"
echo "|---|---|---|---|---|---|---|"
for c in "${CASES[@]}"; do
  scene=${c%%:*}
  res=${c##*:}
  one_run "$scene $res Jacobi CG" "$(scene_with "$scene" jacobi)" "$res" "$TMP/jacobi"
  one_run "$scene $res auto" "$(scene_with "$scene" auto)" "$res" "$TMP/auto"
  last=$(printf "frame_%04d.vdb" "$FRAMES")
  echo "  last frame, auto against Jacobi CG: $("$BIN" compare "$TMP/jacobi/$last" "$TMP/auto/$last")"
  rm -rf "$TMP/jacobi" "$TMP/auto"
done
