#!/usr/bin/env bash
# The multigrid against Jacobi CG in the shipped scenes (bench/results/multigrid_scenes.md).
# Each row runs `stokesvdb run SCENE --frames 1 --res R --threads T` under /usr/bin/time -v, REPS
# times in a row, interleaving the solvers; it prints per run the layout's active cells, the iterations and Krylov seconds of
# each step (stats.csv: krylov_s includes setup_s) and the peak resident memory.
#   bash bench/scripts/multigrid_scenes_study.sh [threads] [reps] [scene:res ...]
# defaults: 2 threads, 3 runs, armadillos:128 beam:64. The multigrid rows are the shipped scene with
# "preconditioner": "multigrid", written to a temporary folder (mesh paths made absolute).
# BASELINE=/path/to/older/stokesvdb adds that binary's multigrid rows.
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
BIN=${BIN:-$ROOT/build/bin/stokesvdb}
THREADS=${1:-2}
REPS=${2:-3}
shift $(( $# > 2 ? 2 : $# ))
CASES=("$@")
[ ${#CASES[@]} -gt 0 ] || CASES=(armadillos:128 beam:64)
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT

source "$ROOT/bench/scripts/scene_study_common.sh"

one_run() {  # label, binary, scene file, res
  local out="$TMP/out" peak
  rm -rf "$out"
  peak=$( { /usr/bin/time -v "$2" run "$3" --out "$out" --frames 1 --res "$4" --threads "$THREADS" >/dev/null 2>"$TMP/err"; } 2>&1; \
          grep "Maximum resident" "$TMP/err" | awk '{print $NF}')
  awk -F, -v label="$1" -v peak="$peak" 'NR == 1 { for (i = 1; i <= NF; ++i) col[$i] = i; next }
    { its = its sep $col["iterations"]; ks = ks sep sprintf("%.3f", $col["krylov_s"]);
      su = su sep sprintf("%.3f", $col["setup_s"]); rows = $col["krylov_rows"]; if (cells == "") cells = $col["cells"]; sep = " / " }
    END { printf "| %s | %s | %s | %s | %s | %s | %.0f |\n", label, cells, rows, its, ks, su, peak / 1024 }' "$out/stats.csv"
}

echo "threads $THREADS, $REPS runs, $(date -u +%FT%TZ), load $(cut -d' ' -f1-3 /proc/loadavg)"
echo "| run | cells (first step) | Krylov rows | iterations per step | Krylov s per step | set-up s | peak MB |"
echo "|---|---|---|---|---|---|---|"
for c in "${CASES[@]}"; do
  scene=${c%%:*}
  res=${c##*:}
  jacobi=$(scene_with "$scene" jacobi)
  mg=$(scene_with "$scene" multigrid)
  for ((r = 1; r <= REPS; ++r)); do
    one_run "$scene $res Jacobi CG" "$BIN" "$jacobi" "$res"
    one_run "$scene $res multigrid" "$BIN" "$mg" "$res"
    if [ -n "${BASELINE:-}" ]; then one_run "$scene $res multigrid (baseline binary)" "$BASELINE" "$mg" "$res"; fi
  done
done
