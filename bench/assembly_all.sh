#!/bin/sh
# bench/assembly_all.sh — issue 11's comparisons in one run: time to the first matrix and
# reassembly for P1 N=32/64, P2 N=24, vector P2 elasticity N=16/24 and the P2 Neo-Hookean
# Jacobian N=16 against FEniCSx; the 3D Poisson CG+GAMG whole process at N=64 with peak RSS
# against FEniCSx; the 2D demo against FEniCSx and FreeFEM (bench/coldstart.sh). FEniCSx
# (python3-dolfinx) and FreeFEM (freefem++) run when installed; neither is a dependency.
ROOT=$(cd "$(dirname "$0")/.." && pwd)
have_fenicsx=0
/usr/bin/python3 -c "import dolfinx" 2>/dev/null && have_fenicsx=1
for args in "32 1 5 laplace" "64 1 5 laplace" "24 2 5 laplace" "16 2 5 elasticity" "24 2 5 elasticity" "16 2 5 neohookean"; do
  # shellcheck disable=SC2086
  "$ROOT/build/lugal" "$ROOT/bench/assembly.lua" $args tetrahedron
  # shellcheck disable=SC2086
  [ $have_fenicsx = 1 ] && /usr/bin/python3 "$ROOT/bench/assembly_fenicsx.py" $args 2>/dev/null | tail -1
done
for i in 1 2; do
  /usr/bin/time -f "lugal poisson3d whole process %e s, peak RSS %M KB" "$ROOT/build/lugal" "$ROOT/bench/poisson3d.lua" 64
  [ $have_fenicsx = 1 ] && /usr/bin/time -f "fenicsx poisson3d whole process %e s, peak RSS %M KB" \
    /usr/bin/python3 "$ROOT/bench/poisson3d_fenicsx.py" 64 2>&1 | grep -v "^INFO\|^WARNING\|warnings.warn\|^$"
done
sh "$ROOT/bench/coldstart.sh" 10
