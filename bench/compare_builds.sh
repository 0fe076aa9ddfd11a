#!/bin/sh
# bench/compare_builds.sh OLD NEW — two builds of lugal side by side (OLD and NEW: their
# checkouts, each built with make), alternating, three rounds, OMP_NUM_THREADS=1, one busy
# process beside them, /proc/loadavg before and after: the P2 Laplacian's reassembly and the
# mother problem's optimization (issue 54: the rooms split, the same speed). For two commits:
#   git worktree add /tmp/old COMMIT && (cd /tmp/old && ./configure && make bins)
#   sh bench/compare_builds.sh /tmp/old .
ROOT=$(cd "$(dirname "$0")/.." && pwd)
OLD=$(cd "$1" && pwd) NEW=$(cd "$2" && pwd)
export OMP_NUM_THREADS=1
. "$ROOT/bench/busy.sh"
busy_start
cat /proc/loadavg
for r in 1 2 3; do
  for b in "$OLD" "$NEW"; do
    echo "== $b round $r"
    (cd /tmp && "$b/build/lugal" "$ROOT/bench/assembly.lua" 24 2 5 laplace tetrahedron 2>&1 | tail -n 2)
    (cd /tmp && "$b/build/lugal" "$ROOT/bench/optimization.lua" mother 64 2>&1 | tail -n 4)
  done
done
cat /proc/loadavg
