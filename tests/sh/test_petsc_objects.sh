#!/bin/sh
# test_petsc_objects.sh BUILD — lugal destroys every PETSc object and frees every PETSc
# allocation it makes: PETSc's own accounting (-malloc_debug -malloc_dump) lists nothing at
# PetscFinalize for a linear, a nonlinear, a coupled and a time-stepping run. (This replaces
# the old blanket LeakSanitizer suppression of libpetsc, which would hide such leaks.)
BUILD=$1
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
cd "$T" || exit 1
for s in "$ROOT/examples/poisson.lua 16" "$ROOT/examples/bratu.lua 16" "$ROOT/tests/lua/test_systems.lua" "$ROOT/examples/heat.lua"; do
  # shellcheck disable=SC2086
  "$BUILD/lugal" $s -malloc_debug -malloc_dump > out 2>&1 || { echo "FAIL: $s"; cat out; exit 1; }
  if grep -E "^\[ ?0\] [0-9]+ bytes" out; then echo "FAIL: PETSc memory left at finalize by $s"; exit 1; fi
done
echo "PETSc objects: none left"
