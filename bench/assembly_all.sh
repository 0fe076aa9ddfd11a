#!/bin/sh
# bench/assembly_all.sh [repeats] — issue 11's comparisons in one run: time to the first
# matrix and reassembly for P1 N=32/64, P2 N=24, vector P2 elasticity N=16/24 and the P2
# Neo-Hookean Jacobian N=16 against FEniCSx; the 3D Poisson CG+GAMG whole process at N=64
# with peak RSS against FEniCSx; the 2D demo against FEniCSx and FreeFEM (bench/coldstart.sh).
# FEniCSx (python3-dolfinx) and FreeFEM (freefem++) run when installed; neither is a
# dependency. Each assembly case runs `repeats` times (default 3), lugal and FEniCSx
# alternating, and a summary line gives the medians and their ratios: on a virtual machine
# whose host backs freed memory lazily, a setup that meets memory another process just
# gave back runs at a fraction of its speed (bench/RESULTS.md, "huge pages"), which a
# single pair of runs mistakes for the program's own speed.
ROOT=$(cd "$(dirname "$0")/.." && pwd)
reps=${1:-3}
have_fenicsx=0
/usr/bin/python3 -c "import dolfinx" 2>/dev/null && have_fenicsx=1
tmp=$(mktemp)
trap 'rm -f "$tmp"' EXIT
for args in "32 1 5 laplace" "64 1 5 laplace" "24 2 5 laplace" "16 2 5 elasticity" "24 2 5 elasticity" "16 2 5 neohookean"; do
  : > "$tmp"
  i=0
  while [ $i -lt "$reps" ]; do
    # shellcheck disable=SC2086
    "$ROOT/build/lugal" "$ROOT/bench/assembly.lua" $args tetrahedron | tee -a "$tmp"
    # shellcheck disable=SC2086
    [ $have_fenicsx = 1 ] && /usr/bin/python3 "$ROOT/bench/assembly_fenicsx.py" $args 2>/dev/null | tail -1 | tee -a "$tmp"
    i=$((i + 1))
  done
  # medians of first_s, setup_s (FEniCSx: its setup, create_matrix, and its function space,
  # as lugal's setup builds its dof maps) and assemble_median_s, per program
  awk -v case="$args" '
    function val(k,   i, n, kv) { n = split($0, kv, " "); for (i = 1; i <= n; i++) if (index(kv[i], k "=") == 1) return substr(kv[i], length(k) + 2) + 0; return -1 }
    function med(a, n,   i, j, t) { for (i = 1; i <= n; i++) for (j = i + 1; j <= n; j++) if (a[j] < a[i]) { t = a[i]; a[i] = a[j]; a[j] = t } return n % 2 ? a[(n + 1) / 2] : (a[n / 2] + a[n / 2 + 1]) / 2 }
    $1 == "lugal" { nl++; lf[nl] = val("first_s"); ls[nl] = val("setup_s"); lr[nl] = val("assemble_median_s") }
    $1 == "fenicsx" { nf++; ff[nf] = val("first_s"); fs[nf] = val("setup_s") + val("space_s"); fr[nf] = val("assemble_median_s") }
    END {
      if (!nl) exit
      a = med(lf, nl); b = med(ls, nl); c = med(lr, nl)
      if (nf) { d = med(ff, nf); e = med(fs, nf); f = med(fr, nf)
        printf "summary %s: medians of %d: first %.3f / %.3f s (ratio %.2f), setup %.3f / %.3f s (%.2f), reassembly %.4f / %.4f s (speed-up %.1fx)\n", case, nl, a, d, a / d, b, e, b / e, c, f, f / c }
      else printf "summary %s: medians of %d: first %.3f s, setup %.3f s, reassembly %.4f s\n", case, nl, a, b, c
    }' "$tmp"
done
for i in 1 2; do
  /usr/bin/time -f "lugal poisson3d whole process %e s, peak RSS %M KB" "$ROOT/build/lugal" "$ROOT/bench/poisson3d.lua" 64
  [ $have_fenicsx = 1 ] && /usr/bin/time -f "fenicsx poisson3d whole process %e s, peak RSS %M KB" \
    /usr/bin/python3 "$ROOT/bench/poisson3d_fenicsx.py" 64 2>&1 | grep -v "^INFO\|^WARNING\|warnings.warn\|^$"
done
sh "$ROOT/bench/coldstart.sh" 10
