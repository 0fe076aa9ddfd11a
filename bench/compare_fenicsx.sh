#!/bin/sh
# bench/compare_fenicsx.sh — the same answers as FEniCSx: runs examples/stokes.lua and
# examples/elasticity.lua, then bench/compare_fenicsx.py solves the same problems with
# FEniCSx (Debian python3-dolfinx) on the meshes lugal wrote and compares the vertex values.
# Needs /usr/bin/python3 with dolfinx and scipy; never part of the build or tests.
ROOT=$(cd "$(dirname "$0")/.." && pwd)
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
cd "$T" || exit 1
if ! /usr/bin/python3 -c "import dolfinx, scipy" 2>/dev/null; then echo "FEniCSx (python3-dolfinx) or scipy is not installed"; exit 1; fi
for run in "stokes 32" "stokes 64" "elasticity 3" "elasticity 5"; do
  set -- $run
  "$ROOT/lugal" "$ROOT/examples/$1.lua" "$2" | head -n 1
  /usr/bin/python3 "$ROOT/bench/compare_fenicsx.py" "$1" "$1.vtu" 2>/dev/null | tail -n 1
done
