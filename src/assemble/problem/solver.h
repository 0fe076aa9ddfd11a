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

/* The default solver of a large symmetric positive definite system: the LU's fill and time
 * grow far faster than CG's with algebraic multigrid (3D P1 Poisson, N = 40: 20 s against
 * 0.9 s; bench/RESULTS.md, "Default solvers"). lg_iterative_size: the least number of
 * unknowns for which CG with GAMG is the default, by the mesh's dimension. */
PetscInt lg_iterative_size(int dim);
/* whether A (AIJ, sequential or parallel, before the essential rows are replaced) is
 * symmetric to rounding with a positive diagonal (what lets CG run), or has a positive
 * diagonal; collective */
int lg_spd_candidate(Mat A);
int lg_positive_diagonal(Mat A);
/* both tests with one reading of the diagonal: 1 symmetric with a positive diagonal (CG), 3
 * a positive diagonal only (GMRES; or symmetry not asked for), 2 neither (direct) */
int lg_matrix_kind(Mat A, int check_symmetry);
/* ksp to CG (spd) or GMRES (restart 100, preconditioned on the right) with GAMG, the
 * residual of the system itself (not the preconditioned one) to LG_ITERATIVE_RTOL of the
 * right side's, the user's -ksp_* and -pc_* options after */
#define LG_ITERATIVE_RTOL 1e-10
PetscErrorCode lg_iterative_setup(KSP ksp, int spd);

/* A saddle point system (Stokes: a velocity, then a pressure whose diagonal block is zero):
 * whether A (sequential AIJ, before the essential rows) has a positive diagonal on its first
 * n0 rows and a zero one on the rest; lg_saddle_setup makes ksp GMRES (preconditioned on the
 * right, restart 100, at most 300 iterations, the true residual to LG_ITERATIVE_RTOL) with a
 * Schur complement fieldsplit (lower factorization; the first block by GAMG, the Schur
 * complement by Jacobi on A11 − A10 diag(A00)⁻¹ A01), each choice only where the user set
 * none (the prefix's -fieldsplit_0_..., -fieldsplit_1_...); the caller gives the splits */
int lg_saddle_point(Mat A, PetscInt n0);
PetscErrorCode lg_saddle_setup(KSP ksp, const char *prefix);

/* whether A (sequential AIJ) is symmetric to rounding apart from the given rows and their
 * columns (the essential rows, replaced by identity rows): then the transposed solve of A
 * is a solve of A and a product with Aᵀ (problem_solve.c, solve_with_jacobian) */
int lg_symmetric_besides(Mat A, const PetscInt *rows, int nrows);

/* replace the native LU by MUMPS (with null pivot detection) after a failure */
PetscErrorCode lg_lu_fallback(KSP ksp, Mat A);

/* MUMPS: count null pivots in the next factorizations (call after the operators are set,
 * before the first factorization; nothing for other solvers) */
void lg_mumps_detect_null_pivots(KSP ksp);

/* the null pivots of MUMPS's last factorization, or 0 for other solvers */
PetscInt lg_mumps_null_pivots(KSP ksp);

/* why a solve with ksp failed, where the solver can tell (": ..." to append to a message; ""
 * when it cannot): MUMPS's own reason (INFOG(1), INFOG(2), the memory it wanted) instead of
 * DIVERGED_PC_FAILED, or a preconditioner used alone (-ksp_type preonly -pc_type jacobi) */
void lg_solve_failure(KSP ksp, char *out, size_t len);

/* A factorization kept while the matrix changes: the state matrix of an optimization is
 * reassembled at every new control, and refactoring it was half of an L-BFGS run. While the
 * matrix stays close to the factored one, conjugate gradients preconditioned by the old
 * Cholesky factor (GMRES, preconditioned on the right, by an old LU factor) solve it in a
 * few iterations (each a triangular solve and a product).
 * The rule is ski rental: iterative solves are taken while what they cost beyond direct ones,
 * summed since the last factorization, stays below three factorizations; then the
 * matrix is refactored. Costs are counted in operations from the factor's structure and the
 * iteration counts, never timed, so that a run's choices, and its results, repeat. A run
 * of iterative solves that did not save a factorization turns the keeping off for the next
 * 1, 2, 4, ... 16 factorizations. Only for the native Cholesky or LU lugal chose
 * (lg_keep_applies); -lugal_keep_factor 0 turns it off. */
typedef struct {
  KSP cg;            /* CG or GMRES on the operator, preconditioned by the direct KSP's own PC */
  int stale;         /* the PC holds the factor of an earlier matrix than the operator */
  double factor_cost; /* the last factorization's cost, in triangular solves (from its structure) */
  PetscInt factor_nnz; /* its entries */
  double extra;      /* what the iterative solves cost beyond direct ones since then (solves) */
  int saved;         /* factorizations the iterative solves replaced since then */
  int cycle_solves;  /* iterative solves since then */
  int skip, backoff; /* factorizations to make before keeping again; the next pause */
  Vec last[2];       /* the last tangent and adjoint solutions (initial guesses) */
} lg_keep;

/* 1 if the KSP's solver is one a factor may be kept for: lugal's native Cholesky or LU,
 * with no -ksp_type, -pc_type or -pc_factor_mat_solver_type from the user */
int lg_keep_applies(KSP ksp, const char *prefix);
/* 1 if, besides, the next solve with a changed (or stale) matrix may iterate with the kept
 * factor (the budget since the last factorization is not spent, no pause) */
int lg_keep_usable(const lg_keep *kp, KSP ksp, const char *prefix);

/* solve A x = b (A^T x = b with transpose) by CG preconditioned with the factor the KSP's PC
 * holds, without refactoring, from x as the initial guess when guess (a last solution: kept
 * when it leaves a smaller residual than zero does); *ok = 0 when it did not converge (the
 * caller refactors) */
PetscErrorCode lg_keep_solve(lg_keep *kp, KSP ksp, Mat A, Vec b, Vec x, int transpose, int changed, int guess,
                             PetscBool *ok, PetscInt *its);

/* the last tangent (transpose 0) or adjoint (1) solution, the next one's initial guess:
 * lg_keep_guess copies it into x and returns 1, or returns 0 when there is none */
PetscErrorCode lg_keep_remember(lg_keep *kp, int transpose, Vec x);
int lg_keep_guess(const lg_keep *kp, int transpose, Vec x);

/* after a direct solve that (re)factored the matrix */
void lg_keep_factored(lg_keep *kp, KSP ksp);

void lg_keep_destroy(lg_keep *kp);

/* what the last kept solve used: "cg/cholesky-kept" or "gmres/lu-kept" */
void lg_keep_name(const lg_keep *kp, char *out, size_t len);

/* what solved: "lu/petsc", "lu/mumps", or "KSP type/PC type" */
void lg_solver_name(KSP ksp, char *out, size_t len);

#endif
