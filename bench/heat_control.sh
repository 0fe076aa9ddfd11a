#!/bin/sh
# bench/heat_control.sh — the whole optimization of examples/heat_control.lua's problem, lugal
# (bench/heat_control.lua, its defaults: L-BFGS) and pyadjoint 2023.0.0.post0 on legacy FEniCS
# (bench/heat_control_pyadjoint.py: scipy's L-BFGS-B) side by side, alternating, three rounds
# at N = 8 (dolfin-adjoint's demo) and one at N = 16, OMP_NUM_THREADS=1, one busy process
# beside them (issue 55). pyadjoint is found in PYADJOINT (a checkout of its 2023.0.0.post0
# tag) with Debian's python3-dolfin and python3-scipy; none of them is a dependency of lugal.
ROOT=$(cd "$(dirname "$0")/.." && pwd)
PYADJOINT=${PYADJOINT:-/opt/pyadjoint}
export OMP_NUM_THREADS=1
have_pa=0
PYTHONPATH="$PYADJOINT" /usr/bin/python3 -c "import fenics_adjoint, scipy" 2> /dev/null && have_pa=1
. "$ROOT/bench/busy.sh"
busy_start
cat /proc/loadavg
for cfg in "8 1" "8 2" "8 3" "16 1"; do
  n=${cfg% *}
  "$ROOT/build/lugal" "$ROOT/bench/heat_control.lua" "$n"
  [ $have_pa = 1 ] && PYTHONPATH="$PYADJOINT" /usr/bin/python3 "$ROOT/bench/heat_control_pyadjoint.py" "$n" 2> /dev/null |
    grep "^heat_control"
done
cat /proc/loadavg
