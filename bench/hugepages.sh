#!/bin/sh
# bench/hugepages.sh [rounds] [pause] [busy] — lugal's memory on transparent huge pages
# (-lugal_hugepages 1, glibc.malloc.hugetlb=1) against 4 KiB pages (-lugal_hugepages 0, the
# default since issue 56's third session), alternating in each round, each run after a pause
# of [pause] seconds (default 3: what a run after a moment's idleness meets; this VM hands
# memory that stays free for about 2 s back to its host, and a first touch of it then faults
# in the host too). Cases: the setup, first matrix and reassembly of bench/assembly.lua (P1
# N = 64, P2 elasticity N = 24, Neo-Hookean N = 16) and the whole 3D Poisson solve of
# bench/poisson3d.lua 48 with lugal's default solver; each line the medians and every run's
# setup (or wall time), the kernel's share (sys) beside it. A third argument "busy" runs it
# all beside one busy process.
ROOT=$(cd "$(dirname "$0")/.." && pwd)
rounds=${1:-3}
pause=${2:-3}
out=$(mktemp -d)
. "$ROOT/bench/busy.sh"
bench_cleanup() { rm -rf "$out"; }
[ "$3" = busy ] && busy_start
echo "${3:-quiet}, pause ${pause} s: /proc/loadavg $(cat /proc/loadavg)"
key() { echo "$1" | tr ' ' '_'; }
one() { # one run: case, hugepages (0/1) -> a line "setup first assemble wall sys"
  c=$1 hp=$2
  sleep "$pause"
  case $c in
    poisson*) n=${c#poisson }
      /usr/bin/time -f "TIME %e %S" "$ROOT/build/lugal" "$ROOT/bench/poisson3d.lua" "$n" default -lugal_hugepages "$hp" 2>&1 |
        awk '/^TIME/ { printf "- - - %s %s\n", $2, $3 }' ;;
    *) # shellcheck disable=SC2086
      /usr/bin/time -f "TIME %e %S" "$ROOT/build/lugal" "$ROOT/bench/assembly.lua" $c tetrahedron -lugal_hugepages "$hp" 2>&1 |
        awk 'function val(k,   i, n, kv) { n = split($0, kv, " "); for (i = 1; i <= n; i++) if (index(kv[i], k "=") == 1) return substr(kv[i], length(k) + 2); return "-" }
             /^lugal / { s = val("setup_s"); f = val("first_s"); a = val("assemble_median_s") }
             /^TIME/ { printf "%s %s %s %s %s\n", s, f, a, $2, $3 }' ;;
  esac
}
cases="64_1_5_laplace 24_2_5_elasticity 16_2_5_neohookean poisson_48"
r=1
while [ "$r" -le "$rounds" ]; do
  for k in $cases; do
    c=$(echo "$k" | tr '_' ' ')
    if [ $((r % 2)) -eq 1 ]; then order="1 0"; else order="0 1"; fi
    for hp in $order; do one "$c" "$hp" >> "$out/$k.$hp"; done
  done
  r=$((r + 1))
done
busy_stop
echo "/proc/loadavg $(cat /proc/loadavg)"
for k in $cases; do
  for hp in 1 0; do
    awk -v case="$k" -v hp="$hp" '
      function med(a, n,   i, j, t) { for (i = 1; i <= n; i++) for (j = i + 1; j <= n; j++) if (a[j] < a[i]) { t = a[i]; a[i] = a[j]; a[j] = t } return a[int((n + 1) / 2)] }
      { n++; s[n] = $1; f[n] = $2; a[n] = $3; w[n] = $4; k[n] = $5; runs = runs " " ($1 == "-" ? $4 : $1) }
      END { if (s[1] == "-") printf "%-20s hugepages %s: wall %.2f s, sys %.2f s (medians of %d; walls%s)\n", case, hp, med(w, n), med(k, n), n, runs
            else printf "%-20s hugepages %s: setup %.3f s, first matrix %.3f s, reassembly %.4f s, wall %.2f s, sys %.2f s (medians of %d; setups%s)\n", case, hp, med(s, n), med(f, n), med(a, n), med(w, n), med(k, n), n, runs }' "$out/$k.$hp"
  done
done
