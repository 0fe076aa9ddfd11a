#!/bin/sh
# bench/direct_solvers.sh — PETSc's LU (nested dissection, the default for small
# single-unknown systems) against MUMPS on Laplacians of growing size: symbolic and numeric
# factorization and one triangular solve, from PETSc's -log_view (seconds).
ROOT=$(cd "$(dirname "$0")/.." && pwd)
for c in "2 64 1" "2 128 1" "2 256 1" "2 512 1" "2 128 2" "3 8 1" "3 16 1" "3 24 1" "3 12 2"; do
  for s in petsc mumps; do
    # shellcheck disable=SC2086
    "$ROOT/build/lugal" "$ROOT/bench/direct_solvers.lua" $c -pc_factor_mat_solver_type $s -log_view 2>&1 |
      awk -v s=$s '/^dim=/ {h = $1 " " $2 " " $3 " " $4} /^MatLUFactorSym/ {sy = $4} /^MatLUFactorNum/ {nu = $4} /^MatSolve / {so = $4}
                   END {printf "%s %-5s symbolic %.4f numeric %.4f solve %.5f total %.4f\n", h, s, sy, nu, so, sy + nu + so}'
  done
done
