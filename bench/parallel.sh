#!/bin/sh
# bench/parallel.sh [N ...] — issue 14's benchmark: the 3D Poisson problem of
# bench/poisson3d.lua (P1, CG + GAMG) whole process on 1 and 2 ranks, lugal then FEniCSx
# (python3-dolfinx, when installed) in the same minute; per-rank peak memory and lugal's
# assembly time. lugal on 1 rank runs once with one OpenMP thread and once with the
# machine's cores (its default); on 2 ranks once with the mesh whole on every rank
# (-lugal_distribute 0) and once distributed (the default since the fourteenth session).
ROOT=$(cd "$(dirname "$0")/.." && pwd)
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
have_fenicsx=0
/usr/bin/python3 -c "import dolfinx" 2>/dev/null && have_fenicsx=1
for N in ${*:-64 96}; do
  /usr/bin/time -f "  whole process %e s" env OMP_NUM_THREADS=1 "$ROOT/build/lugal" "$ROOT/bench/poisson3d.lua" "$N" 2>&1 | sed 's/^lugal/lugal (1 thread)/'
  /usr/bin/time -f "  whole process %e s" "$ROOT/build/lugal" "$ROOT/bench/poisson3d.lua" "$N" 2>&1 | sed 's/^lugal/lugal (threads)/'
  /usr/bin/time -f "  whole process %e s" mpiexec -n 2 "$ROOT/build/lugal" "$ROOT/bench/poisson3d.lua" "$N" -lugal_distribute 0 2>&1
  /usr/bin/time -f "  whole process %e s" mpiexec -n 2 "$ROOT/build/lugal" "$ROOT/bench/poisson3d.lua" "$N" -lugal_distribute 2>&1 | sed 's/^lugal/lugal (distributed mesh)/'
  if [ $have_fenicsx = 1 ]; then
    /usr/bin/time -f "  whole process %e s" /usr/bin/python3 "$ROOT/bench/poisson3d_fenicsx.py" "$N" 2>&1 | grep -v "^INFO\|^WARNING\|warnings.warn\|^$"
    /usr/bin/time -f "  whole process %e s" mpiexec -n 2 /usr/bin/python3 "$ROOT/bench/poisson3d_fenicsx.py" "$N" 2>&1 | grep -v "^INFO\|^WARNING\|warnings.warn\|^$"
  fi
done
