#!/bin/sh
# bench/coldstart.sh [runs] — whole-process wall time of the 64×64 P1 Poisson demo
# (solve, L2 and H1 errors, VTU output): lugal, and FEniCSx on the same problem when
# python3-dolfinx is installed (its JIT cache warmed by one run first). Median of runs.
runs=${1:-10}
ROOT=$(cd "$(dirname "$0")/.." && pwd)
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
median() { sort -n | awk '{ a[NR] = $1 } END { print a[int((NR + 1) / 2)] }'; }
timeit() {
  i=0
  while [ $i -lt "$runs" ]; do
    s=$(date +%s%N)
    "$@" > /dev/null 2>&1 || { echo "failed: $*" >&2; return 1; }
    e=$(date +%s%N)
    echo $(( (e - s) / 1000 ))
    i=$((i + 1))
  done | median
}
cd "$tmp"
us=$(timeit "$ROOT/build/lugal" "$ROOT/examples/poisson.lua" 64 1)
printf 'coldstart lugal %s poisson 64x64 P1: median %.3f s over %d runs\n' "$("$ROOT/build/lugal" --version | cut -d' ' -f2)" "$(echo "$us" | awk '{print $1/1e6}')" "$runs"
if /usr/bin/python3 -c "import dolfinx" 2>/dev/null; then
  /usr/bin/python3 "$ROOT/bench/poisson_fenicsx.py" 64 > /dev/null 2>&1
  us=$(timeit /usr/bin/python3 "$ROOT/bench/poisson_fenicsx.py" 64)
  printf 'coldstart fenicsx %s poisson 64x64 P1 (warm JIT cache): median %.3f s over %d runs\n' \
    "$(/usr/bin/python3 -c 'import dolfinx; print(dolfinx.__version__)')" "$(echo "$us" | awk '{print $1/1e6}')" "$runs"
fi
# FreeFEM on the same work (bench/poisson_freefem.edp: UMFPACK, L2 and H1 errors, VTU), when
# installed (Debian freefem++ and libfreefem++; its plugins live in /usr/lib/freefem++)
if command -v FreeFem++-nw > /dev/null 2>&1; then
  export FF_LOADPATH=${FF_LOADPATH:-/usr/lib/freefem++}
  us=$(timeit FreeFem++-nw "$ROOT/bench/poisson_freefem.edp" -n 64)
  printf 'coldstart freefem %s poisson 64x64 P1: median %.3f s over %d runs\n' \
    "$(dpkg-query -W -f='${Version}' freefem++ 2>/dev/null)" "$(echo "$us" | awk '{print $1/1e6}')" "$runs"
fi
