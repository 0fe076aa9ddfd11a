#!/bin/sh
# bench/time_adjoint.sh — time-dependent gradients, lugal (every state kept, and 16
# snapshots) and pyadjoint 2023.0.0.post0 on legacy FEniCS side by side, alternating, three
# rounds each (the lines give each run's median of three evaluations; RESULTS.md the medians
# over rounds), OMP_NUM_THREADS=1, with one busy process beside them (issue 55). pyadjoint is
# found in PYADJOINT (a checkout of its 2023.0.0.post0 tag) with Debian's python3-dolfin;
# neither is a dependency of lugal: without them only lugal runs. `sh bench/time_adjoint.sh
# memory` runs the memory lines alone.
ROOT=$(cd "$(dirname "$0")/.." && pwd)
PYADJOINT=${PYADJOINT:-/opt/pyadjoint}
export OMP_NUM_THREADS=1
have_pa=0
PYTHONPATH="$PYADJOINT" /usr/bin/python3 -c "import fenics_adjoint" 2> /dev/null && have_pa=1
. "$ROOT/bench/busy.sh"
busy_start
cat /proc/loadavg
[ "$1" = memory ] || for cfg in "32 100" "32 1000" "64 100" "64 1000"; do
  for round in 1 2 3; do
    # shellcheck disable=SC2086
    "$ROOT/build/lugal" "$ROOT/bench/time_adjoint.lua" $cfg
    # shellcheck disable=SC2086
    "$ROOT/build/lugal" "$ROOT/bench/time_adjoint.lua" $cfg 16
    # shellcheck disable=SC2086
    [ $have_pa = 1 ] && PYTHONPATH="$PYADJOINT" /usr/bin/python3 "$ROOT/bench/time_adjoint_pyadjoint.py" $cfg 2> /dev/null | grep -v "^Calling FFC"
  done
done
# memory over a long march: the plain forward run, 16 snapshots, every state kept; with
# lugal's defaults (4 KiB pages since issue 56), then with huge pages (-lugal_hugepages 1:
# their 2 MB grain moves the figures by a few MB from run to run)
for pages in "" "-lugal_hugepages 1"; do
  for cfg in "32 5000" "64 5000" "128 1000"; do
    # shellcheck disable=SC2086
    "$ROOT/build/lugal" "$ROOT/bench/time_adjoint.lua" $cfg plain $pages
    # shellcheck disable=SC2086
    "$ROOT/build/lugal" "$ROOT/bench/time_adjoint.lua" $cfg 16 $pages
    # shellcheck disable=SC2086
    "$ROOT/build/lugal" "$ROOT/bench/time_adjoint.lua" $cfg all $pages
  done
done
# snapshots on disk (the multistage schedule) against the same number in memory
[ "$1" = memory ] || for round in 1 2 3; do
  for ck in 16 14+2 8+8; do
    "$ROOT/build/lugal" "$ROOT/bench/time_adjoint.lua" 64 1000 $ck
  done
done
cat /proc/loadavg
