#!/bin/bash
# Jacobi-CG time per iteration (disk-stokes, uniform, 400 iterations) of two stokesvdb binaries,
# idle and beside a second run of the same binary: the OpenMP wait policy and the fused CG step
# (bench/results/threads.md). Usage: OLD=path NEW=path bash bench/scripts/wait_policy_study.sh
m() { local B=$1 n=$2 thr=$3; shift 3; env "$@" $B analytic disk-stokes --model uniform --n $n --max-iter 400 --threads $thr --json 2>/dev/null | tail -n 1 | /usr/bin/python3 -c 'import json,sys; d=json.load(sys.stdin); print("%.4f"%(1e3*d["solve_seconds"]/d["iterations"]))'; }
OLD=${OLD:?path of the baseline stokesvdb} NEW=${NEW:-build/bin/stokesvdb}
for n in 48 128; do
  for rep in 1 2 3; do
    echo "idle n=$n: old-spin2 $(m $OLD $n 2 GOMP_SPINCOUNT=300000) new-spin2 $(m $NEW $n 2 GOMP_SPINCOUNT=300000) old-passive2 $(m $OLD $n 2 OMP_WAIT_POLICY=passive) new-passive2 $(m $NEW $n 2 OMP_WAIT_POLICY=passive) new-default2 $(m $NEW $n 2 X=1) new-1thr $(m $NEW $n 1 X=1) old-1thr $(m $OLD $n 1 X=1)"
  done
done
# beside a second run of the same binary with the same (default) environment
for pair in "OLD X=1" "NEW X=1"; do
  set -- $pair; B=${!1}
  $B analytic disk-stokes --model uniform --n 256 --threads 2 --json > /dev/null 2>&1 & OTHER=$!
  sleep 1
  for n in 48 128; do echo "beside-second-run $1 default n=$n 2thr: $(m $B $n 2 X=1) $(m $B $n 2 X=1) $(m $B $n 2 X=1) | 1thr: $(m $B $n 1 X=1)"; done
  kill $OTHER; wait $OTHER 2>/dev/null
done
