# mpi_lib.sh — sourced by the parallel tests (test_mpi.sh, test_mpi_dist.sh) with BUILD set:
# a scratch folder T removed at exit, fail(), Open MPI's settings for root and for more
# ranks than cores, ROOT and LUGAL. KEEP_T=DIR (an existing folder) keeps the scratch files
# there to look at after a failure.
T=${KEEP_T:-$(mktemp -d)}
[ -n "$KEEP_T" ] || trap 'rm -rf "$T"' EXIT
fail() { echo "FAIL: $*"; exit 1; }
command -v mpiexec > /dev/null 2>&1 || fail "mpiexec not found (Debian's openmpi-bin comes with petsc-dev)"
# Open MPI refuses root unless told, and a 2-core machine has 2 slots
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1
# ranks waiting in MPI yield the core instead of spinning on it: three ranks on two cores
# otherwise take turns at the scheduler's pace (a distributed minimization ran 20 s to 2 min)
export OMPI_MCA_mpi_yield_when_idle=1
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
case "$BUILD" in /*) LUGAL=$BUILD/lugal ;; *) LUGAL=$ROOT/$BUILD/lugal ;; esac
