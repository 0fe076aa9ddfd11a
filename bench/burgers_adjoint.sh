#!/bin/sh
# bench/burgers_adjoint.sh — time-dependent gradients with Newton steps: viscous Burgers at
# 1000 cells and 1000 steps, lugal (every state kept, and 16 snapshots) and pyadjoint
# 2023.0.0.post0 on legacy FEniCS side by side, alternating, three rounds (each lugal line the
# median of three evaluations), OMP_NUM_THREADS=1, one busy process beside them (issue 55).
# pyadjoint is found in PYADJOINT with Debian's python3-dolfin; not a dependency of lugal.
ROOT=$(cd "$(dirname "$0")/.." && pwd)
PYADJOINT=${PYADJOINT:-/opt/pyadjoint}
export OMP_NUM_THREADS=1
have_pa=0
PYTHONPATH="$PYADJOINT" /usr/bin/python3 -c "import fenics_adjoint" 2> /dev/null && have_pa=1
. "$ROOT/bench/busy.sh"
busy_start
cat /proc/loadavg
for round in 1 2 3; do
  "$ROOT/build/lugal" "$ROOT/bench/burgers_adjoint.lua" 1000 1000
  "$ROOT/build/lugal" "$ROOT/bench/burgers_adjoint.lua" 1000 1000 16
  [ $have_pa = 1 ] && PYTHONPATH="$PYADJOINT" /usr/bin/python3 "$ROOT/bench/burgers_adjoint_pyadjoint.py" 1000 1000 2> /dev/null |
    grep "^pyadjoint"
done
cat /proc/loadavg
