#!/bin/sh
# bench/default_solver.sh — the default linear solver as a user gets it (issue 56): 3D P1
# Poisson (bench/poisson3d.lua) written with no options, against the hand-tuned CG + GAMG
# (-ksp_type cg -pc_type gamg -ksp_rtol 1e-8, symmetric=true) and the direct solver
# (-lugal_iterative 0), whole process time, peak memory, L2 error; quiet, then beside one
# busy process; rounds alternating, every line printed (medians by eye or awk).
#   sh bench/default_solver.sh [rounds] [sizes]
ROOT=$(cd "$(dirname "$0")/.." && pwd)
. "$ROOT/bench/busy.sh"
rounds=${1:-3}
sizes=${2:-"40 64"}
for load in quiet busy; do
  [ $load = busy ] && busy_start
  echo "$load: /proc/loadavg $(cat /proc/loadavg)"
  r=1
  while [ "$r" -le "$rounds" ]; do
    for N in $sizes; do
      for mode in default tuned lu; do
        [ "$mode" = lu ] && [ "$N" -gt 40 ] && continue # MUMPS at N = 64: minutes and gigabytes
        /usr/bin/time -f "  whole process %e s, peak RSS %M KB" "$ROOT/build/lugal" "$ROOT/bench/poisson3d.lua" "$N" "$mode" 2>&1 |
          tr '\n' ' ' | sed "s/^/$load /"
        echo
      done
    done
    r=$((r + 1))
  done
  busy_stop
done
echo "/proc/loadavg $(cat /proc/loadavg)"
