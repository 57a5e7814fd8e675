#!/usr/bin/env bash
# Iteration counts and times, unpreconditioned against each preconditioner, for the
# 2D disk (unified Stokes), the 2D box (decoupled viscosity) and the 3D ball (unified Stokes).
# Writes CSV rows to stdout: test,dim,n,system,form,solver,precond,iterations,status,L1,solve_s,mg_setup_s,levels
# Usage: bench/scripts/preconditioner_study.sh [max2d] [max3d] [threads] > bench/results/preconditioners.csv
#   max2d / max3d = 0 skips that part; MIN2D / MIN3D (env) skip smaller sizes; BIN=path picks the
#   binary, TOL the relative tolerance. On the largest sizes (2D N = 512, 3D n = 128) the
#   unpreconditioned and Jacobi runs are capped at CAP (default 1000) iterations -- their status then
#   reads MaxIterations and the row is a lower bound -- and the slow SPD V-cycle row is skipped.
set -uo pipefail
BIN="${BIN:-build/bin/stokesvdb}"
MAX2D="${1:-512}"
MAX3D="${2:-128}"
TOL="${TOL:-1e-8}"
THREADS="${3:-1}"
MIN2D="${MIN2D:-0}"
MIN3D="${MIN3D:-0}"
CAP="${CAP:-1000}"
MAXIT=40000
[ -n "${NO_HEADER:-}" ] || echo "test,dim,n,system,form,solver,precond,iterations,status,L1,solve_s,mg_setup_s,levels"
row() {  # test n extra-args... ; prints one CSV row (the SPD form unless --form pv is given)
  local test=$1 n=$2; shift 2
  local form=(--form spd)
  [[ " $* " == *" --form "* ]] && form=()
  "$BIN" analytic "$test" --n "$n" --tol "$TOL" --max-iter "$MAXIT" --threads "$THREADS" --json "${form[@]}" "$@" | python3 -c '
import json, sys
d = json.load(sys.stdin); a = sys.argv[1:]
get = lambda k, dflt: a[a.index(k) + 1] if k in a else dflt
print(",".join(str(x) for x in [d["test"], get("--dim", "3" if d["test"].startswith("ball") else "2"), d["n"],
      get("--system", "unified" if d["test"] != "box-viscosity" else "viscosity") + ("+solids" if "--solids" in a else ""), get("--form", "spd"),
      get("--solver", "cg"), get("--precond", "jacobi"), d["iterations"], d["status"], d.get("L1", ""),
      round(d["solve_seconds"], 3), round(d.get("preconditioner_seconds", 0), 3), d.get("multigrid_levels", 0)]))
' "$@"
}
for n in 64 128 256 512; do
  [ "$n" -le "$MAX2D" ] && [ "$n" -ge "$MIN2D" ] || continue
  large=$([ "$n" -ge 512 ] && echo 1 || echo 0)
  [ "$large" = 1 ] && MAXIT=$CAP
  row disk-stokes $n --precond none
  row disk-stokes $n --precond jacobi
  MAXIT=40000
  [ "$large" = 1 ] || row disk-stokes $n --precond multigrid
  [ "$large" = 1 ] || row disk-stokes $n --form pv --solver minres --precond jacobi
  row disk-stokes $n --form pv --solver minres --precond multigrid
  row box-viscosity $n --precond none
  row box-viscosity $n --precond jacobi
  row box-viscosity $n --precond multigrid
done
for n in 64 128; do
  [ "$n" -le "$MAX3D" ] && [ "$n" -ge "$MIN3D" ] || continue
  large=$([ "$n" -ge 128 ] && echo 1 || echo 0)
  [ "$large" = 1 ] && MAXIT=$CAP
  row ball $n --precond none
  row ball $n --precond jacobi
  MAXIT=40000
  [ "$large" = 1 ] || row ball $n --precond multigrid
  row ball $n --form pv --solver minres --precond multigrid
  row ball $n --system decoupled --precond jacobi
  row ball $n --system decoupled --precond multigrid
  [ "$large" = 1 ] || row ball $n --solids --form pv --solver minres --precond jacobi
  row ball $n --solids --form pv --solver minres --precond multigrid
done
