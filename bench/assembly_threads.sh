#!/bin/sh
# bench/assembly_threads.sh — the element loop's threads as a user gets them (issue 56):
# reassembly and time to the first matrix (bench/assembly.lua) with lugal's defaults
# (every core) and with OMP_NUM_THREADS=1, on a quiet machine and beside one busy process,
# rounds alternating, medians of the rounds. With a second build directory the same runs
# of that build alternate with this one's (before/after).
#   sh bench/assembly_threads.sh [rounds] [other-build-dir]
ROOT=$(cd "$(dirname "$0")/.." && pwd)
. "$ROOT/bench/busy.sh"
rounds=${1:-3}
other=$2
cases="40:1:laplace 64:1:laplace 24:2:elasticity 16:2:neohookean"
out=$(mktemp -d)
run() { # build threads case
  N=${3%%:*}; rest=${3#*:}; p=${rest%%:*}; form=${rest#*:}
  env OMP_NUM_THREADS=$2 "$1/lugal" "$ROOT/bench/assembly.lua" "$N" "$p" 5 "$form" tetrahedron -lugal_hugepages 0 2>&1 | tail -1 |
    sed 's/.*assemble_median_s=\([0-9.]*\).*first_s=\([0-9.]*\).*/\1 \2/'
}
builds="$ROOT/build"
[ -n "$other" ] && builds="$other $ROOT/build"
for load in quiet busy; do
  [ $load = busy ] && busy_start
  echo "$load: /proc/loadavg $(cat /proc/loadavg)"
  r=1
  while [ "$r" -le "$rounds" ]; do
    for c in $cases; do
      for b in $builds; do
        for t in 2 1; do
          echo "$(run "$b" $t "$c")" >> "$out/$load.$(basename "$(dirname "$b")")$(basename "$b").$t.$c"
        done
      done
    done
    r=$((r + 1))
  done
  busy_stop
done
echo "/proc/loadavg $(cat /proc/loadavg)"
# medians: reassembly and first matrix (s) per load, build, threads (2 = the default here) and case
for f in "$out"/*; do
  n=$(basename "$f")
  re=$(cut -d' ' -f1 "$f" | sort -g | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}')
  fi=$(cut -d' ' -f2 "$f" | sort -g | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}')
  echo "$n reassembly $re first $fi"
done
rm -rf "$out"
