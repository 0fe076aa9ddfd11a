#!/bin/sh
# lugal-mesh quality on a tangled quadrilateral mesh and on a Gmsh triangle mesh: the table,
# the count of inverted cells, the SVG picture (one red outline per invalid cell), the
# histogram (its bars add up to the cell count), the VTU, and usage errors.
set -e
BUILD=$1
ROOT=$(pwd)
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
cat > "$T/tangle.lua" <<'LUA'
local lg = require "lugal"
local m = lg.mesh.rectangle{nx = 6, ny = 6, cell = "quadrilateral"}
m:write(arg[2])
local x, y = m:coordinates(24)
m:set_coordinates(24, x + 0.05, y + 0.04)
m:write(arg[3])
m:set_coordinates(24, x + 0.3, y + 0.25)
m:write(arg[1])
LUA
"$BUILD/lugal" "$T/tangle.lua" "$T/tangled.msh" "$T/rest.msh" "$T/bumped.msh"
out=$("$BUILD/lugal-mesh" quality "$T/tangled.msh" --picture "$T/p.svg" --svg "$T/h.svg" --vtu "$T/q.vtu" --bins 8)
echo "$out"
echo "$out" | grep -q "36 quadrilaterals, 49 vertices"
echo "$out" | grep -q "inverted or degenerate cells: 3 (cells 15, 20, 21)"
echo "$out" | grep -q "kappa2_max"
# the red group holds exactly the invalid cells
red=$(sed -n '/stroke="#e00"/,/<\/g>/p' "$T/p.svg" | grep -c '<polygon')
[ "$red" -eq 3 ] || { echo "expected 3 red outlines, got $red"; exit 1; }
[ "$(grep -c '<polygon' "$T/p.svg")" -eq 39 ] || { echo "expected 36 cells + 3 outlines"; exit 1; }
# histogram bars: 8 bars whose heights are proportional to counts summing to 36 (title says so)
grep -q "(36 cells)" "$T/h.svg"
[ "$(grep -c '<rect x=' "$T/h.svg")" -ge 8 ]
grep -q 'Name="scaled_jacobian"' "$T/q.vtu"
# a triangle mesh from Gmsh
"$BUILD/lugal-mesh" quality "$ROOT/examples/domain.msh" | grep -q "1092 triangles"
# errors: unknown measure and missing file are reported with an exit status
if "$BUILD/lugal-mesh" quality "$T/tangled.msh" --measure mean_ratio 2> "$T/err"; then exit 1; fi
grep -q "does not apply to quadrilaterals" "$T/err"
if "$BUILD/lugal-mesh" quality "$T/none.msh" 2> "$T/err"; then exit 1; fi
grep -q "cannot open" "$T/err"
# untangle: the tangled mesh comes back valid, only the pulled vertex moves, and quality
# agrees; --report prints the three stages; smooth keeps the minimum and raises the mean
out=$("$BUILD/lugal-mesh" untangle "$T/tangled.msh" "$T/fixed.msh" --report)
echo "$out"
echo "$out" | grep -q "1 feasible set .*invalid 3 -> 0"
echo "$out" | grep -q "3 feasible set (J >= beta)"
echo "$out" | grep -q "untangle: done — 0 invalid left, 1 vertices moved"
"$BUILD/lugal-mesh" quality "$T/fixed.msh" | grep -q "inverted or degenerate cells: 0"
out=$("$BUILD/lugal-mesh" smooth "$T/fixed.msh" "$T/smooth.msh")
echo "$out"
echo "$out" | grep -q "smooth (local): corner_condition min"
out=$("$BUILD/lugal-mesh" smooth "$T/fixed.msh" "$T/smooth.msh" --method global)
echo "$out" | grep -q "smooth (global): corner_condition min"
out=$("$BUILD/lugal-mesh" smooth "$T/fixed.msh" "$T/smooth.msh" --method energy)
echo "$out" | grep -q "smooth (energy, Newton): corner_condition min"
out=$("$BUILD/lugal-mesh" smooth "$T/fixed.msh" "$T/smooth.msh" --method energy --optimizer lbfgs)
echo "$out" | grep -q "smooth (energy, L-BFGS): corner_condition min"
# a sliding boundary: the pass kept is named (here the optimizer's, which reaches the grid)
out=$("$BUILD/lugal-mesh" smooth "$T/bumped.msh" "$T/x.msh" --method energy)
echo "$out" | grep -q "smooth (energy, Newton, boundary slid in the optimizer): corner_condition min 0.7571 -> 1,"
out=$("$BUILD/lugal-mesh" smooth "$T/bumped.msh" "$T/x.msh" --method energy --sliding local)
echo "$out" | grep -q "smooth (energy, Newton, boundary slid by local steps): corner_condition min 0.7571 -> "
if "$BUILD/lugal-mesh" smooth "$T/bumped.msh" "$T/x.msh" --method energy --sliding both 2> "$T/err"; then exit 1; fi
grep -q "sliding must be best, optimizer or local" "$T/err"
if "$BUILD/lugal-mesh" smooth "$T/bumped.msh" "$T/x.msh" --sliding local 2> "$T/err"; then exit 1; fi
grep -q "sliding needs --method energy" "$T/err"
if "$BUILD/lugal-mesh" smooth "$T/fixed.msh" "$T/x.msh" --method energy --optimizer bfgs 2> "$T/err"; then exit 1; fi
grep -q "optimizer must be auto, newton or lbfgs" "$T/err"
if "$BUILD/lugal-mesh" smooth "$T/fixed.msh" "$T/x.msh" --optimizer newton 2> "$T/err"; then exit 1; fi
grep -q "optimizer needs --method energy" "$T/err"
# --reference: the rest grid's shapes, per corner: untangling repairs, smoothing a bumped
# copy towards them reaches them; another mesh or measure is refused
out=$("$BUILD/lugal-mesh" untangle "$T/tangled.msh" "$T/x.msh" --reference "$T/rest.msh")
echo "$out" | grep -q "invalid 3 -> 0,"
out=$("$BUILD/lugal-mesh" untangle "$T/tangled.msh" "$T/x.msh" --motion-weight 2 --no-global)
echo "$out" | grep -q "invalid 3 -> 0,"
if "$BUILD/lugal-mesh" untangle "$T/tangled.msh" "$T/x.msh" --motion-weight -2 2> "$T/err"; then exit 1; fi
grep -q "motion-weight must be a finite number" "$T/err"
out=$("$BUILD/lugal-mesh" smooth "$T/bumped.msh" "$T/x.msh" --reference "$T/rest.msh")
echo "$out"
echo "$out" | grep -Eq "smooth \(energy, Newton\): corner_condition relative to the reference min 0\.[0-9]+ -> (1|0\.999[0-9]*),"
out=$("$BUILD/lugal-mesh" smooth "$T/bumped.msh" "$T/x.msh" --reference "$T/rest.msh" --optimizer lbfgs)
echo "$out" | grep -Eq "smooth \(energy, L-BFGS\): corner_condition relative to the reference min 0\.[0-9]+ -> (1|0\.999[0-9]*),"
if "$BUILD/lugal-mesh" smooth "$T/fixed.msh" "$T/x.msh" --reference "$ROOT/examples/domain.msh" 2> "$T/err"; then exit 1; fi
grep -q "must be the same mesh" "$T/err"
if "$BUILD/lugal-mesh" untangle "$T/tangled.msh" "$T/x.msh" --reference "$ROOT/examples/domain.msh" 2> "$T/err"; then exit 1; fi
grep -q "must be the same mesh" "$T/err"
if "$BUILD/lugal-mesh" smooth "$T/fixed.msh" "$T/x.msh" --reference "$T/rest.msh" --measure scaled_jacobian 2> "$T/err"; then exit 1; fi
grep -q "reference shapes need" "$T/err"
if "$BUILD/lugal-mesh" smooth "$T/fixed.msh" "$T/x.msh" --method newton 2> "$T/err"; then exit 1; fi
grep -q "method must be auto, local, global or energy" "$T/err"
if "$BUILD/lugal-mesh" smooth "$T/tangled.msh" "$T/x.msh" 2> "$T/err"; then exit 1; fi
grep -q "untangle it first" "$T/err"
if "$BUILD/lugal-mesh" untangle "$T/tangled.msh" "$T/x.msh" --beta -1 2> "$T/err"; then exit 1; fi
grep -q "beta must be a finite number >= 0" "$T/err"
# options are range-checked as the integers and numbers they become
if "$BUILD/lugal-mesh" untangle "$T/tangled.msh" "$T/x.msh" --beta inf 2> "$T/err"; then exit 1; fi
grep -q "beta must be a finite number >= 0, got inf" "$T/err"
if "$BUILD/lugal-mesh" untangle "$T/tangled.msh" "$T/x.msh" --max-iterations 99999999999 2> "$T/err"; then exit 1; fi
grep -q "max-iterations must be an integer from 1 to 1000000, got 99999999999" "$T/err"
if "$BUILD/lugal-mesh" quality "$T/tangled.msh" --bins 1e3 2> "$T/err"; then exit 1; fi
grep -q "bins must be an integer from 1 to 1000, got 1e3" "$T/err"
if "$BUILD/lugal-mesh" quality /tmp 2> "$T/err"; then exit 1; fi
grep -q "cannot read /tmp: Is a directory" "$T/err"
# a tangle that cannot be undone with the boundary fixed: exit status 3, file still written
cat > "$T/edge.lua" <<'LUA'
local lg = require "lugal"
local m = lg.mesh.rectangle{nx = 10, cell = "triangle"}
m:set_coordinates(4, 0.45, 0)
m:write(arg[1])
LUA
"$BUILD/lugal" "$T/edge.lua" "$T/edge.msh"
set +e
"$BUILD/lugal-mesh" untangle "$T/edge.msh" "$T/edge_fixed.msh" --boundary fixed > "$T/out"
rc=$?
set -e
[ "$rc" -eq 3 ] || { echo "expected exit status 3, got $rc"; exit 1; }
[ -s "$T/edge_fixed.msh" ]
"$BUILD/lugal-mesh" untangle "$T/edge.msh" "$T/edge_slide.msh" | grep -q "invalid 1 -> 0"
echo "lugal-mesh: ok"
