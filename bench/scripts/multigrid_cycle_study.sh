#!/usr/bin/env bash
# Cost of the multigrid cycle: the Chebyshev smoother's degree and range against
# iterations and seconds, for the pressure-velocity form under MINRES with the block V-cycle and,
# for comparison, the SPD form under Jacobi CG. Each configuration runs REPS times (default 3);
# the table gives the median solve time, the multigrid set-up share and ms per iteration.
#   bash bench/scripts/multigrid_cycle_study.sh [threads] [reps] [cases...]
# cases: ball48 ball64 disk128 disk256 (default: ball48 disk128)
set -euo pipefail
DEFAULT_CASES=(ball48 disk128)
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
source "$(dirname "$0")/study_common.sh" "$@"
summarise() {  # label, then JSON lines on stdin
  python3 "$(dirname "$0")/summarise_solves.py" "$1" status iterations solve setup_share ms_per_it
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
