#!/bin/sh
# bench/direct_solvers.sh — PETSc's LU against MUMPS on Laplacians of growing size, then
# PETSc's LU in nested dissection order (its default) against approximate minimum degree
# (lugal's choice for rows of at most 10 entries per block: P1 and Q1 in 2D): symbolic and
# numeric factorization and one triangular solve, from PETSc's -log_view (seconds).
ROOT=$(cd "$(dirname "$0")/.." && pwd)
run() { # label, then the case and the options
  label=$1; shift
  # shellcheck disable=SC2086
  "$ROOT/build/lugal" "$ROOT/bench/direct_solvers.lua" "$@" -log_view 2>&1 |
    awk -v s="$label" '/^dim=/ {h = $1 " " $2 " " $3 " " $4} /^MatLUFactorSym/ {sy = $4} /^MatLUFactorNum/ {nu = $4} /^MatSolve / {so = $4}
                       END {printf "%s %-9s symbolic %.4f numeric %.4f solve %.5f total %.4f\n", h, s, sy, nu, so, sy + nu + so}'
}
for c in "2 64 1" "2 128 1" "2 256 1" "2 512 1" "2 128 2" "3 8 1" "3 16 1" "3 24 1" "3 12 2"; do
  for s in petsc mumps; do
    # shellcheck disable=SC2086
    run $s $c -pc_factor_mat_solver_type $s
  done
done
for c in "2 64 1" "2 128 1" "2 256 1" "2 64 2" "2 128 2" "3 12 1" "3 16 1" "3 8 2"; do
  for o in nd amd; do
    # shellcheck disable=SC2086
    run "petsc/$o" $c -pc_factor_mat_ordering_type $o
  done
done
