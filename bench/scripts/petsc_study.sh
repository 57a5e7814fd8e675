#!/usr/bin/env bash
# The PETSc backend against the in-house solvers: the same analytic problems, one
# Markdown row per run, with iterations, seconds, ns per unknown per iteration and peak memory
# (summed over ranks). One thread per rank; the in-house rows run on 1 and on 2 threads.
# "set-up s" is the system set-up plus the preconditioner's build; "solve s" includes that build.
# Usage: bench/scripts/petsc_study.sh table|weak > out.md
#   table: disk N = 256 and ball 128^3 (override with DISK / BALL), in-house multigrid and Jacobi,
#          PETSc with each of $PETSC_VARIANTS (';'-separated option sets; the ball: $BALL_VARIANTS),
#          on 1 and 2 ranks.
#   weak:  the same work per rank on 1 and 2 ranks: disk N and N sqrt 2, ball n and n 2^(1/3).
#   BIN picks the binary, TOL the relative tolerance, RANKS the rank counts, T the timeout per run.
set -uo pipefail
BIN="${BIN:-build/bin/stokesvdb}"
TOL="${TOL:-1e-8}"
DISK="${DISK:-256}"
BALL="${BALL:-128}"
RANKS="${RANKS:-1 2}"
T="${T:-1800}"
# the fewest iterations found (GAMG, Chebyshev/SOR smoothing) and the fastest (Jacobi), see
# bench/results/petsc.md; GAMG takes 30 s on the 64^3 ball, so the 128^3 ball runs Jacobi only
GAMG="-pc_type gamg -pc_gamg_threshold 0.05 -mg_levels_ksp_type chebyshev -mg_levels_pc_type sor"
PETSC_VARIANTS="${PETSC_VARIANTS:-$GAMG;-pc_type jacobi}"
BALL_VARIANTS="${BALL_VARIANTS:--pc_type jacobi}"
export OMP_WAIT_POLICY="${OMP_WAIT_POLICY:-passive}"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_btl_vader_single_copy_mechanism=none
echo "| case | solver | ranks x threads | unknowns | iterations | set-up s | solve s | total s | ns / unknown / iteration | peak RSS MB (all ranks) | Linf error | status |"
echo "|---|---|---|---|---|---|---|---|---|---|---|---|"
row() {  # label ranks threads command...
  local label=$1 ranks=$2 threads=$3; shift 3
  local out
  out=$(OMP_NUM_THREADS=$threads timeout "$T" "$@" --tol "$TOL" --threads "$threads" --json < /dev/null 2>&1)
  echo "$out" | python3 -c "
import json, sys
label, ranks, threads = sys.argv[1], sys.argv[2], sys.argv[3]
js = [json.loads(l) for l in sys.stdin if l.startswith('{')]
if not js:
    print(f'| {label} | (no result: failed or timed out) | {ranks} x {threads} | | | | | | | | | |'); sys.exit()
j = js[-1]
its = max(j['iterations'], 1)
ns = 1e9 * j['solve_seconds'] / (its * j['unknowns'])
rss = j.get('peak_rss_mb_all_ranks', j['peak_rss_mb'])
print(f\"| {label} | {j['solver']} | {ranks} x {threads} | {j['unknowns']:,} | {j['iterations']:,} | {j['setup_seconds'] + j['preconditioner_seconds']:.2f} | {j['solve_seconds']:.2f} | {j['total_seconds']:.2f} | {ns:.1f} | {rss:.0f} | {j['Linf']:.4g} | {j['status']} |\")
" "$label" "$ranks" "$threads"
}
inhouse() {  # label args...
  local label=$1; shift
  for th in 1 2; do
    row "$label" 1 $th "$BIN" analytic "$@" --precond multigrid
    row "$label" 1 $th "$BIN" analytic "$@" --precond jacobi --form spd
  done
}
petsc() {  # label variants args...
  local label=$1 variants=$2; shift 2
  local IFS_SAVE=$IFS opts
  IFS=';' read -ra sets <<< "$variants"
  IFS=$IFS_SAVE
  for opts in "${sets[@]}"; do
    for r in $RANKS; do
      row "$label" "$r" 1 mpirun -np "$r" "$BIN" analytic "$@" --backend petsc $opts
    done
  done
}
case "${1:-table}" in
  table)
    inhouse "disk N = $DISK" disk-stokes --n "$DISK"
    petsc "disk N = $DISK" "$PETSC_VARIANTS" disk-stokes --n "$DISK"
    inhouse "ball ${BALL}^3" ball --n "$BALL"
    petsc "ball ${BALL}^3" "$BALL_VARIANTS" ball --n "$BALL"
    ;;
  weak)
    D1="${WEAK_DISK:-256}"; D2=$(python3 -c "print(round($D1 * 2 ** 0.5))")
    B1="${WEAK_BALL:-64}"; B2=$(python3 -c "print(round($B1 * 2 ** (1 / 3)))")
    row "disk N = $D1 (1 rank's share)" 1 1 mpirun -np 1 "$BIN" analytic disk-stokes --n "$D1" --backend petsc
    row "disk N = $D2 (2 ranks' share)" 2 1 mpirun -np 2 "$BIN" analytic disk-stokes --n "$D2" --backend petsc
    row "ball ${B1}^3 (1 rank's share)" 1 1 mpirun -np 1 "$BIN" analytic ball --n "$B1" --backend petsc
    row "ball ${B2}^3 (2 ranks' share)" 2 1 mpirun -np 2 "$BIN" analytic ball --n "$B2" --backend petsc
    ;;
esac
