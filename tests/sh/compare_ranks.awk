# compare_ranks.awk — `paste serial parallel | awk -v what="2 ranks" -f compare_ranks.awk`:
# lines "name class value" of a serial run and a parallel one (tests/lua/mpi_cases.lua,
# mpi_dist.lua), the same names in the same order; class direct: 1e-10 relative, iter
# (iterative solvers, optimization): 1e-8, count: integers within 1. Exits 1 on a mismatch.
{ if ($1 != $4) { print "FAIL: line " NR ": " $1 " against " $4; bad = 1; next }
  a = $3 + 0; b = $6 + 0; d = a - b; if (d < 0) d = -d; s = a < 0 ? -a : a
  tol = $2 == "direct" ? 1e-10 : $2 == "iter" ? 1e-8 : 1
  ok = $2 == "count" ? d <= 1 : d <= tol * (s > 1e-300 ? s : 1)
  if (!ok) { print "FAIL: " $1 " on " what ": " b " against " a " (" $2 ")"; bad = 1 }
  else if ($2 != "count" && d > worst) worst = d / (s > 1e-300 ? s : 1) }
END { if (bad) exit 1; printf "%s: %d quantities as on one (largest relative difference %.1e)\n", what, NR, worst }
