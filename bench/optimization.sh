#!/bin/sh
# bench/optimization.sh — PDE-constrained optimization, lugal (the default tiered JIT,
# libtcc only, and the system compiler only)
# and pyadjoint 2023.0.0.post0 on legacy FEniCS side by side in one run (issue 10).
# pyadjoint is found on PYTHONPATH or in PYADJOINT (a checkout of its 2023.0.0.post0 tag:
# git clone -b 2023.0.0.post0 https://github.com/dolfin-adjoint/pyadjoint); legacy FEniCS
# is Debian's python3-dolfin. Neither is a dependency of lugal: without them only lugal runs.
ROOT=$(cd "$(dirname "$0")/.." && pwd)
PYADJOINT=${PYADJOINT:-/opt/pyadjoint}
have_pa=0
PYTHONPATH="$PYADJOINT:$PYTHONPATH" /usr/bin/python3 -c "import fenics_adjoint" 2>/dev/null && have_pa=1
for cn in "mother 32" "mother 64" "mother 128" "mother0 32" "mother0 64" "nonlinear 32" "nonlinear 64" "inversion 32" "inversion 64"; do
  # shellcheck disable=SC2086
  "$ROOT/build/lugal" "$ROOT/bench/optimization.lua" $cn
  # shellcheck disable=SC2086
  "$ROOT/build/lugal" "$ROOT/bench/optimization.lua" $cn -lugal_jit tcc | sed 's/^lugal/lugal-tcc/'
  # shellcheck disable=SC2086
  "$ROOT/build/lugal" "$ROOT/bench/optimization.lua" $cn -lugal_jit cc | sed 's/^lugal/lugal-cc/'
  # shellcheck disable=SC2086
  [ $have_pa = 1 ] && PYTHONPATH="$PYADJOINT:$PYTHONPATH" /usr/bin/python3 "$ROOT/bench/optimization_pyadjoint.py" $cn 2>/dev/null | grep -v "^Calling FFC"
done
