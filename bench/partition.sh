#!/bin/sh
# bench/partition.sh [N ...] — issue 14: bench/partition.lua (P1 on a cube mesh numbered in a
# shuffled order, CG + GAMG) on 1 rank and on 2 ranks with the rows by PTScotch's partition of
# the cells (the default chooses it here) and in the numbering's order (-lugal_partitioner
# natural), then bench/poisson3d.lua (the box generator's ordered mesh, where the default
# keeps the numbering's order) forced through PTScotch: what the partition costs there.
# Meshes whole on every rank (-lugal_distribute 0), as when these figures were taken.
ROOT=$(cd "$(dirname "$0")/.." && pwd)
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
for N in ${*:-32 48}; do
  /usr/bin/time -f "  whole process %e s" "$ROOT/build/lugal" "$ROOT/bench/partition.lua" "$N" 2>&1
  /usr/bin/time -f "  whole process %e s" mpiexec -n 2 "$ROOT/build/lugal" "$ROOT/bench/partition.lua" "$N" -lugal_distribute 0 -lugal_verbose 2>&1 |
    grep -v "kernel\|sparsity\|problem:"
  /usr/bin/time -f "  whole process %e s" mpiexec -n 2 "$ROOT/build/lugal" "$ROOT/bench/partition.lua" "$N" -lugal_distribute 0 -lugal_partitioner natural 2>&1
done
/usr/bin/time -f "  whole process %e s" mpiexec -n 2 "$ROOT/build/lugal" "$ROOT/bench/poisson3d.lua" 64 -lugal_distribute 0 -lugal_verbose 2>&1 | grep "partition\|poisson3d\|whole"
/usr/bin/time -f "  whole process %e s" mpiexec -n 2 "$ROOT/build/lugal" "$ROOT/bench/poisson3d.lua" 64 -lugal_distribute 0 -lugal_verbose -lugal_partitioner ptscotch 2>&1 |
  grep "partition\|poisson3d\|whole"
