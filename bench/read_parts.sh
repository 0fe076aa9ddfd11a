#!/bin/sh
# bench/read_parts.sh [N ...] — reading a Gmsh file under mpiexec (issue 14): the box of
# N×N×N cubes × 6 tetrahedra written as MSH 2.2, read on 1 rank, then on 2 ranks in parts
# (each rank its run of the file, read_dist.c) and whole by rank 0 (-lugal_read_parts 0):
# lg.mesh.read's time and each rank's peak memory (bench/read_parts.lua), whole process.
ROOT=$(cd "$(dirname "$0")/.." && pwd)
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
for N in ${*:-64 96}; do
  echo "local lg = require 'lugal'; lg.mesh.box{nx = $N}:write('$T/box$N.msh')" > "$T/gen.lua"
  "$ROOT/build/lugal" "$T/gen.lua" || exit 1
  echo "box $N: $(wc -c < "$T/box$N.msh") bytes"
  /usr/bin/time -f "  whole process %e s" "$ROOT/build/lugal" "$ROOT/bench/read_parts.lua" "$T/box$N.msh" 2>&1 | sed 's/^/  1 rank: /'
  /usr/bin/time -f "  whole process %e s" mpiexec -n 2 "$ROOT/build/lugal" "$ROOT/bench/read_parts.lua" "$T/box$N.msh" 2>&1 | sed 's/^read/  2 ranks, in parts: read/'
  /usr/bin/time -f "  whole process %e s" mpiexec -n 2 "$ROOT/build/lugal" "$ROOT/bench/read_parts.lua" "$T/box$N.msh" -lugal_read_parts 0 2>&1 | sed 's/^read/  2 ranks, whole on rank 0: read/'
done
