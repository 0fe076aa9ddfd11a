/* solver.h — the direct solvers of lugal's problems (solver.c): which LU factorization a
 * problem gets by default, MUMPS's null pivot detection, and the switch to MUMPS when the
 * default non-pivoting LU fails. Internal to the assembly layer (problem.c). */
#ifndef LUGAL_SOLVER_H
#define LUGAL_SOLVER_H

#include <petscksp.h>

/* the default preconditioner of a problem's KSP: LU, by PETSc's own factorization with a
 * nested dissection ordering for small single-field systems without a null space (no
 * pivoting, several times less overhead), by MUMPS otherwise (pivoting, null pivots) */
PetscErrorCode lg_lu_default(PC pc, Mat A, PetscInt n, int dim, int nfields, int nnull);

/* 1 if the KSP's factorization is the default PETSc LU (not one the user asked for with
 * -pc_factor_mat_solver_type): it may be replaced by MUMPS after a failure */
int lg_lu_native(KSP ksp, const char *prefix);

/* after each assembly of A, before its factorization, for the default PETSc LU: its zero
 * pivot threshold relative to the size of the matrix's diagonal outside the essential rows,
 * and with may_cholesky (a linear problem's fixed form) Cholesky while A is symmetric */
PetscErrorCode lg_lu_prepare(KSP ksp, Mat A, const PetscInt *bc_rows, int nbc, const char *prefix, int may_cholesky);

/* replace the native LU by MUMPS (with null pivot detection) after a failure */
PetscErrorCode lg_lu_fallback(KSP ksp, Mat A);

/* MUMPS: count null pivots in the next factorizations (call after the operators are set,
 * before the first factorization; nothing for other solvers) */
void lg_mumps_detect_null_pivots(KSP ksp);

/* the null pivots of MUMPS's last factorization, or 0 for other solvers */
PetscInt lg_mumps_null_pivots(KSP ksp);

/* what solved: "lu/petsc", "lu/mumps", or "KSP type/PC type" */
void lg_solver_name(KSP ksp, char *out, size_t len);

#endif
