#!/bin/sh
# bench/setup_fenicsx.sh [rounds] [busy] — setup (dof maps, sparsity pattern, matrix creation),
# time to the first matrix and reassembly against FEniCSx 0.5.2 (issue 56), lugal with its
# defaults and with OMP_NUM_THREADS=1 and FEniCSx (bench/assembly_fenicsx.py, its setup_s plus
# space_s: its function space and dof map, as lugal's setup builds its dof maps) alternating
# in each round; medians of the rounds. A second argument "busy" runs it all beside one busy
# process. Needs python3-dolfinx (never a dependency).
ROOT=$(cd "$(dirname "$0")/.." && pwd)
rounds=${1:-3}
out=$(mktemp -d)
. "$ROOT/bench/busy.sh"
bench_cleanup() { rm -rf "$out"; }
[ "$2" = busy ] && busy_start
echo "${2:-quiet}: /proc/loadavg $(cat /proc/loadavg)"
key() { echo "$1" | tr ' ' '_'; }
r=1
while [ "$r" -le "$rounds" ]; do
  ci=0
  for c in "40 1 5 laplace" "64 1 5 laplace" "24 2 5 laplace" "16 2 5 neohookean"; do
    # FEniCSx first, then lugal's two in turn: the run right after FEniCSx pays for the
    # memory it freed (this VM reports freed memory to its host, which takes it back; a
    # first touch of it then faults in the host too: P1 N = 64 beside a busy process, one
    # thread's setup 0.62-0.89 s right after FEniCSx, 0.26-0.27 s otherwise). The order
    # alternates with the round and the case, so that neither lugal column always follows
    # it (the rotation before this let lugal's default follow FEniCSx in every round)
    if [ $(((r + ci) % 2)) -eq 0 ]; then order="fenicsx lugal lugal1"; else order="fenicsx lugal1 lugal"; fi
    ci=$((ci + 1))
    k=$(key "$c")
    for who in $order; do
      # shellcheck disable=SC2086
      case $who in
        lugal) "$ROOT/build/lugal" "$ROOT/bench/assembly.lua" $c tetrahedron | tail -1 >> "$out/lugal.$k" ;;
        lugal1) OMP_NUM_THREADS=1 "$ROOT/build/lugal" "$ROOT/bench/assembly.lua" $c tetrahedron | tail -1 >> "$out/lugal1.$k" ;;
        fenicsx) /usr/bin/python3 "$ROOT/bench/assembly_fenicsx.py" $c 2> /dev/null | tail -1 >> "$out/fenicsx.$k" ;;
      esac
    done
  done
  r=$((r + 1))
done
busy_stop
echo "/proc/loadavg $(cat /proc/loadavg)"
for c in "40 1 5 laplace" "64 1 5 laplace" "24 2 5 laplace" "16 2 5 neohookean"; do
  k=$(key "$c")
  for who in lugal lugal1 fenicsx; do
    awk -v who="$who" -v case="$c" '
      function val(k,   i, n, kv) { n = split($0, kv, " "); for (i = 1; i <= n; i++) if (index(kv[i], k "=") == 1) return substr(kv[i], length(k) + 2) + 0; return -1 }
      function med(a, n,   i, j, t) { for (i = 1; i <= n; i++) for (j = i + 1; j <= n; j++) if (a[j] < a[i]) { t = a[i]; a[i] = a[j]; a[j] = t } return a[int((n + 1) / 2)] }
      { n++; s[n] = val("setup_s") + (who == "fenicsx" ? val("space_s") : 0); f[n] = val("first_s"); a[n] = val("assemble_median_s") }
      function all(a, n,   i, t) { t = ""; for (i = 1; i <= n; i++) t = t (i > 1 ? " " : "") sprintf("%.3f", a[i]); return t }
      END { printf "%s %-8s setup %.3f s, first matrix %.3f s, reassembly %.4f s (medians of %d; setups %s)\n", case, who, med(s, n), med(f, n), med(a, n), n, all(s, n) }' "$out/$who.$k"
  done
done
