#!/bin/sh
# bench/run.sh — every benchmark, lugal and (when installed) FEniCSx side by side in one
# run. Results and the machine go to stdout; bench/RESULTS.md records a run.
ROOT=$(cd "$(dirname "$0")/.." && pwd)
echo "date: $(date -u '+%Y-%m-%d %H:%M UTC')"
echo "machine: $(nproc) cores, $(awk '/MemTotal/ {printf "%.0f GiB", $2/1048576}' /proc/meminfo), $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //')"
echo "PETSc $(pkg-config --modversion PETSc), $(tcc -v 2>&1 | head -1)"
# assembly, the 3D Poisson whole process and the 2D demo (issue 11; includes coldstart.sh)
sh "$ROOT/bench/assembly_all.sh"
# nanoseconds per element of each kernel shape, libtcc's code and the system compiler's
"$ROOT/build/lugal" "$ROOT/bench/kernels.lua" 5 -lugal_jit tcc
"$ROOT/build/lugal" "$ROOT/bench/kernels.lua" 5 -lugal_jit cc
have_fenicsx=0
/usr/bin/python3 -c "import dolfinx" 2>/dev/null && have_fenicsx=1
"$ROOT/build/lugal" "$ROOT/bench/quality.lua" 119
[ $have_fenicsx = 1 ] && /usr/bin/python3 -c "import vtk" 2>/dev/null && /usr/bin/python3 "$ROOT/bench/quality_vtk.py" 119
# untangling (issue 4): tangled meshes at 1k / 10k / 100k vertices, and placement in stage 1
"$ROOT/build/lugal" "$ROOT/bench/untangle.lua" 3
"$ROOT/build/lugal" "$ROOT/bench/placement.lua"
# issue 13's 100 000-vertex hard classes: untangle + energy smoothing, every case under 2 s?
"$ROOT/build/lugal" "$ROOT/bench/untangle_100k.lua"
# the energy smoother's Newton steps on Tutte-solved spirals (the softened first steps)
"$ROOT/build/lugal" "$ROOT/bench/smooth_tutte_steps.lua"
# 36 hard tangles in many sizes and shapes: untangle + energy smoothing, quality and steps
"$ROOT/build/lugal" "$ROOT/bench/untangle_sweep.lua"
# smoothing (issue 4): local against global, two sizes
"$ROOT/build/lugal" "$ROOT/bench/smooth.lua"
"$ROOT/build/lugal" "$ROOT/bench/smooth.lua" 100 16
# PDE-constrained optimization against pyadjoint on legacy FEniCS (issue 10), when installed
sh "$ROOT/bench/optimization.sh"
