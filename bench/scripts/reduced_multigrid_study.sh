#!/usr/bin/env bash
# Reduced tiles inside the strong preconditioner: for each model (uniform, affine,
# quadratic) the SPD form under Jacobi CG against the pressure-velocity form under MINRES with the
# block multigrid, whose velocity cycle has the tile DOFs on its finest level. Relative residual
# 1e-8. Each configuration runs REPS times (default 3); the table gives the median solve time, the
# multigrid set-up share and ns per unknown per iteration (solve minus set-up).
#   bash bench/scripts/reduced_multigrid_study.sh [threads] [reps] [cases...]
# cases: disk64 disk128 disk256 disk512 ball48 ball64 ball128 (default: disk128 disk256 ball48).
# CONFIGS (default "spd-jacobi pv-multigrid") picks the configurations.
# The ball's tiles: --tile 12 --pad 2 (the default 16 / 3 leaves few tiles in a 48^3 ball).
set -euo pipefail
DEFAULT_CASES=(disk128 disk256 ball48)
MODELS=${MODELS:-"uniform affine quadratic"}
args_of() {
  case $1 in
    disk64) echo "disk-stokes --n 64" ;;
    disk128) echo "disk-stokes --n 128" ;;
    disk256) echo "disk-stokes --n 256" ;;
    ball48) echo "ball --n 48 --tile 12 --pad 2" ;;
    ball64) echo "ball --n 64 --tile 12 --pad 2" ;;
    disk512) echo "disk-stokes --n 512" ;;
    ball128) echo "ball --n 128 --tile 12 --pad 2" ;;
    *) echo "unknown case $1" >&2; exit 2 ;;
  esac
}
source "$(dirname "$0")/study_common.sh" "$@"
summarise() {  # label, then JSON lines on stdin
  python3 "$(dirname "$0")/summarise_solves.py" "$1" tiles unknowns status iterations solve setup_share ns_per_unknown_it \
    peak_rss_mb bytes_per_unknown L1
}
echo "threads $THREADS, $REPS runs per row, $(date -u +%FT%TZ), load $(cut -d' ' -f1-3 /proc/loadavg)"
echo "| case / model / configuration | tiles | unknowns | status | iterations | solve s (median) | set-up share | ns per unknown per iteration | peak RSS MB | bytes per unknown | L1 error |"
echo "|---|---|---|---|---|---|---|---|---|---|---|"
for c in "${CASES[@]}"; do
  for m in $MODELS; do
    for cfg in ${CONFIGS:-spd-jacobi pv-multigrid}; do
      case $cfg in
        spd-jacobi) run "$c" --model "$m" --form spd --precond jacobi | summarise "$c $m SPD Jacobi CG" ;;
        pv-multigrid) run "$c" --model "$m" --form pv --precond multigrid | summarise "$c $m PV MINRES multigrid" ;;
        *) echo "unknown configuration $cfg" >&2; exit 2 ;;
      esac
    done
  done
done
