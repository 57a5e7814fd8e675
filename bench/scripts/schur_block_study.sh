#!/usr/bin/env bash
# The pressure block of the pressure-velocity form's block multigrid (SchurApproximation in
# solver/multigrid/multigrid.h): the Schur diagonal estimate alone against Cahouet-Chabard (plus a
# V-cycle of the projection operator), across the viscous number mu dt / (rho dx^2). MINRES to
# relative residual 1e-8; each configuration runs REPS times (default 3), medians.
#   bash bench/scripts/schur_block_study.sh [threads] [reps] [cases...]
# A case is BASE[-MODEL]-muVALUE, BASE one of disk64 disk128 disk256 ball48 ball48solids, MODEL
# uniform (default), affine or quadratic. Default cases: the table of bench/results/schur_block.md.
set -euo pipefail
DEFAULT_CASES=(disk128-mu1e-5 disk128-mu1e-4 disk128-mu1e-3 disk128-mu1e-2 disk128-mu0.1 disk128-quadratic-mu0.1
               ball48-mu1e-4 ball48-mu1e-2 ball48-mu1 ball48-quadratic-mu1 ball48solids-mu1)
args_of() {
  local base=${1%%-*} rest=${1#*-} model=uniform
  case $rest in
    mu*) ;;
    *-mu*) model=${rest%%-mu*}; rest=${rest#*-} ;;
    *) echo "case $1 has no -muVALUE" >&2; exit 2 ;;
  esac
  case $base in
    disk64) echo -n "disk-stokes --n 64" ;;
    disk128) echo -n "disk-stokes --n 128" ;;
    disk256) echo -n "disk-stokes --n 256" ;;
    ball48) echo -n "ball --n 48 --tile 12 --pad 2" ;;
    ball48solids) echo -n "ball --n 48 --tile 12 --pad 2 --solids" ;;
    *) echo "unknown case $1" >&2; exit 2 ;;
  esac
  case $model in uniform|affine|quadratic) ;; *) echo "unknown model in case $1" >&2; exit 2 ;; esac
  echo " --mu ${rest#mu} --model $model --form pv --precond multigrid --max-iter 3000"
}
source "$(dirname "$0")/study_common.sh" "$@"
summarise() {  # label, then JSON lines on stdin
  python3 "$(dirname "$0")/summarise_solves.py" "$1" viscous_number schur_block status iterations solve ms_per_it_total L1
}
echo "threads $THREADS, $REPS runs per row, $(date -u +%FT%TZ), load $(cut -d' ' -f1-3 /proc/loadavg)"
echo "| case | mu dt / (rho dx^2) | pressure block | status | iterations | solve s (median) | ms per iteration | L1 error |"
echo "|---|---|---|---|---|---|---|---|"
for c in "${CASES[@]}"; do
  for s in cahouet-chabard diagonal; do
    run "$c" --mg-schur "$s" | summarise "$c"
  done
done
