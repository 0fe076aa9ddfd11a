#!/bin/sh
# bench/waiting_threads.sh — libgomp's waiting policy against the P2 elasticity reassembly at
# N = 24 (bench/assembly.lua): the reassembly's median and the time to the first matrix for
# each setting in turn, rounds alternating, on a quiet machine and beside one busy process
# (issue 56). The settings are given to lugal-core through the launcher, which keeps a
# GOMP_SPINCOUNT or OMP_WAIT_POLICY the user set ("default" here is libgomp's own: the
# launcher's 1000 is what `GOMP_SPINCOUNT=1000` measures).
#   sh bench/waiting_threads.sh [rounds]
ROOT=$(cd "$(dirname "$0")/.." && pwd)
. "$ROOT/bench/busy.sh"
rounds=${1:-3}
run() {
  env "$@" "$ROOT/build/lugal" "$ROOT/bench/assembly.lua" 24 2 5 elasticity 2>&1 | tail -1 |
    sed 's/.*assemble_median_s=\([0-9.]*\).*first_s=\([0-9.]*\).*/reassembly \1 s, first matrix \2 s/'
}
for load in quiet busy; do
  [ $load = busy ] && busy_start
  cat /proc/loadavg
  r=1
  while [ $r -le "$rounds" ]; do
    for e in GOMP_SPINCOUNT=300000 GOMP_SPINCOUNT=10000 GOMP_SPINCOUNT=1000 GOMP_SPINCOUNT=100 OMP_WAIT_POLICY=passive \
             OMP_NUM_THREADS=1; do
      echo "$load $e: $(run $e)"
    done
    r=$((r + 1))
  done
  busy_stop
done
cat /proc/loadavg
