#!/usr/bin/env bash
# Cost of the multigrid cycle (issue 13, item 3): the Chebyshev smoother's degree and range against
# iterations and seconds, for the pressure-velocity form under MINRES with the block V-cycle and,
# for comparison, the SPD form under Jacobi CG. Each configuration runs REPS times (default 3);
# the table gives the median solve time, the multigrid set-up share and ms per iteration.
#   bash bench/scripts/multigrid_cycle_study.sh [threads] [reps] [cases...]
# cases: ball48 ball64 disk128 disk256 (default: ball48 disk128)
set -euo pipefail
B=${STOKESVDB:-build/bin/stokesvdb}
THREADS=${1:-1}
REPS=${2:-3}
shift 2 || true
CASES=("$@")
[ ${#CASES[@]} -eq 0 ] && CASES=(ball48 disk128)
DEGREES=${DEGREES:-"1 2 3 4 6"}
RANGES=${RANGES:-"20"}
args_of() {
  case $1 in
    ball48) echo "ball --n 48" ;;
    ball64) echo "ball --n 64" ;;
    disk128) echo "disk-stokes --n 128" ;;
    disk256) echo "disk-stokes --n 256" ;;
    *) echo "unknown case $1" >&2; exit 2 ;;
  esac
}
run() {  # prints one JSON line per repetition
  for _ in $(seq "$REPS"); do "$B" analytic $(args_of "$1") --tol 1e-8 --threads "$THREADS" --json "${@:2}"; done
}
summarise() {  # label, then JSON lines on stdin
  python3 -c '
import json, statistics, sys
rows = [json.loads(l) for l in sys.stdin if l.strip()]
solve = statistics.median(r["solve_seconds"] for r in rows)
setup = statistics.median(r["preconditioner_seconds"] for r in rows)
it = rows[0]["iterations"]
status = rows[0]["status"]
print(f"| {sys.argv[1]} | {status} | {it} | {solve:.3f} | {100 * setup / solve:.1f}% | {1e3 * (solve - setup) / max(it, 1):.2f} |")
' "$1"
}
echo "threads $THREADS, $REPS runs per row, $(date -u +%FT%TZ), load $(cut -d' ' -f1-3 /proc/loadavg)"
echo "| case / configuration | status | iterations | solve s (median) | set-up share | ms per iteration |"
echo "|---|---|---|---|---|---|"
for c in "${CASES[@]}"; do
  run "$c" --form spd --precond jacobi | summarise "$c SPD Jacobi CG"
  for r in $RANGES; do
    for d in $DEGREES; do
      run "$c" --form pv --precond multigrid --mg-degree "$d" --mg-range "$r" | summarise "$c PV MINRES multigrid degree $d range $r"
    done
  done
done
