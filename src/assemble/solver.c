/* solver.c — the direct solvers of lugal's problems: the default LU factorization (PETSc's
 * own for small single-field systems, MUMPS otherwise), the switch to MUMPS when the
 * default one fails, and MUMPS's null pivot detection, which turns a singular matrix into
 * an error instead of a solution of garbage. */
#include "solver.h"

#include <stdio.h>
#include <string.h>
#include <time.h>

/* PETSc's LU against MUMPS, one factorization and one solve of the P1 Laplacian
 * (bench/RESULTS.md, "Direct solvers"): PETSc's is faster on 2D systems up to about 10^5
 * unknowns (total 0.04 against 0.09 s at 16 641, 0.30 against 0.46 s at 66 049; MUMPS
 * wins at 263 169) and on 3D ones up to about 10^4 (equal at 4 913, MUMPS 16% faster to
 * factor at 15 625), and its triangular solves are 4-7 times faster at every size, which an
 * optimization, solving several times per factorization, feels most */
#define LU_NATIVE_MAX_2D 100000
#define LU_NATIVE_MAX_3D 10000

PetscErrorCode lg_lu_default(PC pc, Mat A, PetscInt n, int dim, int nfields, int nnull) {
  PetscFunctionBeginUser;
  PetscCall(PCSetType(pc, PCLU));
  PetscBool have = PETSC_FALSE;
  PetscCall(MatGetFactorAvailable(A, MATSOLVERMUMPS, MAT_FACTOR_LU, &have));
  /* PETSc's LU does not pivot: a mixed system (a saddle point's zero block) needs MUMPS,
   * and so does a singular one with its null space given (MUMPS solves past null pivots) */
  int native = !have || (nfields == 1 && nnull == 0 && n <= (dim >= 3 ? LU_NATIVE_MAX_3D : LU_NATIVE_MAX_2D));
  /* no ordering is set: PETSc's LU prefers nested dissection by itself, and an ordering set
   * on the PC would be handed to MUMPS too after a switch (40 s instead of 0.3 s for one
   * factorization at 66 049 dofs, against MUMPS's own ordering) */
  PetscCall(PCFactorSetMatSolverType(pc, native ? MATSOLVERPETSC : MATSOLVERMUMPS));
  PetscFunctionReturn(0);
}

/* a direct factorization (LU, or the Cholesky lugal picks for symmetric matrices) */
static int is_lu(KSP ksp, PC *pc, MatSolverType *st) {
  PetscBool lu = PETSC_FALSE, ch = PETSC_FALSE;
  *st = NULL;
  if (KSPGetPC(ksp, pc) || PetscObjectTypeCompare((PetscObject)*pc, PCLU, &lu) ||
      PetscObjectTypeCompare((PetscObject)*pc, PCCHOLESKY, &ch) || !(lu || ch))
    return 0;
  if (PCFactorGetMatSolverType(*pc, st) || !*st) return 0;
  return 1;
}

int lg_lu_native(KSP ksp, const char *prefix) {
  PC pc;
  MatSolverType st;
  if (!is_lu(ksp, &pc, &st) || strcmp(st, MATSOLVERPETSC)) return 0;
  PetscBool user = PETSC_FALSE;
  PetscOptionsHasName(NULL, prefix && prefix[0] ? prefix : NULL, "-pc_factor_mat_solver_type", &user);
  return !user;
}

/* whether A is symmetric to rounding, entry by entry relative to the larger of a_ij, a_ji
 * (the two triangles of a symmetric form's element matrices are summed in different
 * orders; an absolute tolerance would call an identity row with a column of tiny entries
 * symmetric). Read only: MatIsSymmetric marks the matrix changed, which refactors it */
static PetscErrorCode symmetric(Mat A, PetscBool *sym) {
  const PetscInt *ia, *ja;
  const PetscScalar *a;
  PetscInt n;
  PetscBool done;
  PetscFunctionBeginUser;
  *sym = PETSC_FALSE;
  PetscCall(MatGetRowIJ(A, 0, PETSC_FALSE, PETSC_FALSE, &n, &ia, &ja, &done));
  if (!done) PetscFunctionReturn(0);
  PetscCall(MatSeqAIJGetArrayRead(A, &a));
  int ok = 1;
  for (PetscInt i = 0; i < n && ok; i++)
    for (PetscInt k = ia[i]; k < ia[i + 1] && ok; k++) {
      PetscInt j = ja[k];
      if (j <= i) continue;
      /* a_ji: binary search in row j's sorted columns */
      PetscInt lo = ia[j], hi = ia[j + 1] - 1;
      PetscScalar aji = 0;
      while (lo <= hi) {
        PetscInt mid = (lo + hi) / 2;
        if (ja[mid] == i) { aji = a[mid]; break; }
        if (ja[mid] < i) lo = mid + 1; else hi = mid - 1;
      }
      PetscReal m = PetscMax(PetscAbsScalar(a[k]), PetscAbsScalar(aji));
      ok = PetscAbsScalar(a[k] - aji) <= 1e-12 * m;
    }
  PetscCall(MatSeqAIJRestoreArrayRead(A, &a));
  PetscCall(MatRestoreRowIJ(A, 0, PETSC_FALSE, PETSC_FALSE, &n, &ia, &ja, &done));
  *sym = ok ? PETSC_TRUE : PETSC_FALSE;
  PetscFunctionReturn(0);
}

/* Cholesky (half the work of LU) for a matrix that is symmetric, LU otherwise, unless the
 * user chose the preconditioner */
static PetscErrorCode choose_factorization(KSP ksp, Mat A, const char *prefix) {
  PetscBool user = PETSC_FALSE, sym = PETSC_FALSE, ch = PETSC_FALSE;
  PC pc;
  PetscFunctionBeginUser;
  PetscCall(PetscOptionsHasName(NULL, prefix && prefix[0] ? prefix : NULL, "-pc_type", &user));
  if (user) PetscFunctionReturn(0);
  PetscCall(KSPGetPC(ksp, &pc));
  PetscCall(PetscObjectTypeCompare((PetscObject)pc, PCCHOLESKY, &ch));
  PetscCall(symmetric(A, &sym));
  if ((sym != PETSC_FALSE) == (ch != PETSC_FALSE)) PetscFunctionReturn(0);
  PetscCall(PCReset(pc));
  PetscCall(PCSetType(pc, sym ? PCCHOLESKY : PCLU));
  PetscCall(PCFactorSetMatSolverType(pc, MATSOLVERPETSC));
  PetscCall(KSPSetOperators(ksp, A, A));
  PetscFunctionReturn(0);
}

PetscErrorCode lg_lu_prepare(KSP ksp, Mat A, const PetscInt *bc_rows, int nbc, const char *prefix, int may_cholesky) {
  PetscFunctionBeginUser;
  if (!lg_lu_native(ksp, prefix)) PetscFunctionReturn(0);
  if (may_cholesky) PetscCall(choose_factorization(ksp, A, prefix));
  PetscBool user = PETSC_FALSE;
  PetscCall(PetscOptionsHasName(NULL, prefix && prefix[0] ? prefix : NULL, "-pc_factor_zeropivot", &user));
  if (user) PetscFunctionReturn(0);
  /* PETSc compares pivots with an absolute threshold (1e-12 by default), which a matrix in
   * small units fails and a large one passes when singular: take 1e-12 of the mean
   * diagonal outside the essential rows (whose diagonal is 1), the rule lugal gives MUMPS */
  Vec d;
  PetscInt n;
  const PetscScalar *a;
  PetscCall(MatCreateVecs(A, &d, NULL));
  PetscCall(MatGetDiagonal(A, d));
  PetscCall(VecGetLocalSize(d, &n));
  PetscCall(VecGetArrayRead(d, &a));
  /* the essential rows skipped, not subtracted: their 1s would swallow a tiny diagonal */
  char *bc;
  PetscCall(PetscCalloc1(n, &bc));
  for (int i = 0; i < nbc; i++)
    if (bc_rows[i] >= 0 && bc_rows[i] < n) bc[bc_rows[i]] = 1;
  double s = 0;
  PetscInt m = 0;
  for (PetscInt i = 0; i < n; i++)
    if (!bc[i]) { s += PetscAbsScalar(a[i]); m++; }
  PetscCall(PetscFree(bc));
  PetscCall(VecRestoreArrayRead(d, &a));
  PetscCall(VecDestroy(&d));
  double mean = m ? s / (double)m : 1.0;
  PC pc;
  PetscCall(KSPGetPC(ksp, &pc));
  PetscCall(PCFactorSetZeroPivot(pc, mean > 0 ? 1e-12 * mean : 1e-12));
  PetscFunctionReturn(0);
}

PetscErrorCode lg_lu_fallback(KSP ksp, Mat A) {
  PC pc;
  PetscFunctionBeginUser;
  PetscCall(KSPGetPC(ksp, &pc));
  PetscCall(PCReset(pc));
  PetscCall(PCSetType(pc, PCLU));
  PetscCall(PCFactorSetMatSolverType(pc, MATSOLVERMUMPS));
  PetscCall(KSPSetOperators(ksp, A, A));
  lg_mumps_detect_null_pivots(ksp);
  PetscCall(PetscInfo(ksp, "lugal: PETSc's LU failed; refactoring with MUMPS\n"));
  PetscFunctionReturn(0);
}

/* the MUMPS factor of a KSP's LU preconditioner, or NULL (another solver or method) */
static Mat mumps_factor(KSP ksp, int create) {
  PC pc;
  MatSolverType st;
  Mat F = NULL;
  if (!is_lu(ksp, &pc, &st) || strcmp(st, MATSOLVERMUMPS)) return NULL;
  if (create && PCFactorSetUpMatSolverType(pc)) return NULL;
  if (PCFactorGetMatrix(pc, &F)) return NULL;
  return F;
}

/* MUMPS returns a solution of a singular system without failing; with null pivot detection
 * (ICNTL(24)) it counts the null pivots (INFOG(28)), so a singular matrix is reported
 * instead of solved into garbage, and a singular system with its null space given (the
 * pressure of an enclosed flow) is solved */
void lg_mumps_detect_null_pivots(KSP ksp) {
  Mat F = mumps_factor(ksp, 1);
  if (!F) return;
  MatMumpsSetIcntl(F, 24, 1);
  /* a pivot below 1e-12 |A| is null (MUMPS's default, 1e-5 eps |A|, missed the constant of
   * a pure Neumann Laplacian, whose pivot was 1e-15 |A|; a SIMP stiffness with a 1e-9
   * contrast keeps its pivots well above); -mat_mumps_cntl_3 overrides */
  MatMumpsSetCntl(F, 3, -1e-12);
}

PetscInt lg_mumps_null_pivots(KSP ksp) {
  Mat F = mumps_factor(ksp, 0);
  PetscInt n = 0;
  if (!F || MatMumpsGetInfog(F, 28, &n)) return 0;
  return n;
}

void lg_solver_name(KSP ksp, char *out, size_t len) {
  PC pc;
  MatSolverType st;
  KSPType kt = NULL;
  PCType pt = NULL;
  KSPGetType(ksp, &kt);
  if (KSPGetPC(ksp, &pc) == 0) PCGetType(pc, &pt);
  int direct = kt && !strcmp(kt, KSPPREONLY);
  if (is_lu(ksp, &pc, &st) && direct) snprintf(out, len, "%s/%s", pt ? pt : "lu", st);
  else snprintf(out, len, "%s/%s", kt ? kt : "?", pt ? pt : "?");
}

/* ---------------------------------------------------------------- a kept factorization */

/* the solves' relative residual (unpreconditioned, as a direct solve's would be checked)
 * and the iterations after which CG gives up and the matrix is refactored */
#define KEEP_RTOL 1e-12
#define KEEP_MAXIT 60
#define KEEP_BACKOFF_MAX 16
/* the extra cost of iterative solves, in factorizations, after which the matrix is
 * refactored: 1 is ski rental's bound (never more than twice the best choice made knowing
 * the future); a kept factor ages slowly on an optimization's path, and 2 was cheaper there
 * (64² inversion L-BFGS, factorization and triangular solve times summed: budget 0.5: 0.219 s,
 * 1: 0.182, 2: 0.167, 4: 0.165, 8: 0.180), at a bound of three times */
#define KEEP_BUDGET 2.0

static double wall_ms(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return t.tv_sec * 1e3 + t.tv_nsec * 1e-6;
}

int lg_keep_usable(const lg_keep *kp, KSP ksp, const char *prefix) {
  PC pc;
  PetscBool ch = PETSC_FALSE, user = PETSC_FALSE;
  if (kp->skip > 0 || kp->factor_ms <= 0 || kp->extra_ms >= KEEP_BUDGET * kp->factor_ms) return 0;
  if (!lg_lu_native(ksp, prefix) || KSPGetPC(ksp, &pc) || PetscObjectTypeCompare((PetscObject)pc, PCCHOLESKY, &ch) || !ch)
    return 0;
  PetscOptionsHasName(NULL, prefix && prefix[0] ? prefix : NULL, "-ksp_type", &user);
  return !user;
}

PetscErrorCode lg_keep_solve(lg_keep *kp, KSP ksp, Mat A, Vec b, Vec x, int transpose, int changed, int guess,
                             PetscBool *ok, PetscInt *its) {
  PC pc;
  PetscFunctionBeginUser;
  *ok = PETSC_FALSE;
  *its = 0;
  PetscCall(KSPGetPC(ksp, &pc));
  if (!kp->cg) {
    const char *prefix = NULL;
    PetscCall(KSPCreate(PETSC_COMM_SELF, &kp->cg));
    PetscCall(KSPGetOptionsPrefix(ksp, &prefix));
    /* its own prefix, so that the direct KSP's options (-ksp_monitor for a direct solve)
     * do not change it; -lugal_keep_ksp_monitor shows its iterations */
    PetscCall(KSPSetOptionsPrefix(kp->cg, prefix));
    PetscCall(KSPAppendOptionsPrefix(kp->cg, "lugal_keep_"));
    PetscCall(KSPSetType(kp->cg, KSPCG));
    PetscCall(KSPSetPC(kp->cg, pc));
    PetscCall(KSPSetNormType(kp->cg, KSP_NORM_UNPRECONDITIONED));
    PetscCall(KSPSetTolerances(kp->cg, KEEP_RTOL, 0.0, PETSC_DEFAULT, KEEP_MAXIT));
    PetscCall(KSPSetErrorIfNotConverged(kp->cg, PETSC_FALSE));
    PetscCall(KSPSetFromOptions(kp->cg));
  }
  double t0 = wall_ms();
  if (guess) {
    /* the last solution of a nearby matrix and right side: CG's tolerance is relative to
     * |b|, so a good guess saves iterations; a poor one (another direction's tangent) is
     * dropped */
    Vec r;
    PetscReal rn, bn;
    PetscCall(VecDuplicate(b, &r));
    PetscCall(transpose ? MatMultTranspose(A, x, r) : MatMult(A, x, r));
    PetscCall(VecAYPX(r, -1.0, b));
    PetscCall(VecNorm(r, NORM_2, &rn));
    PetscCall(VecNorm(b, NORM_2, &bn));
    PetscCall(VecDestroy(&r));
    if (!(rn < bn)) guess = 0;
  }
  if (!guess) PetscCall(VecSet(x, 0.0));
  PetscCall(KSPSetInitialGuessNonzero(kp->cg, guess ? PETSC_TRUE : PETSC_FALSE));
  PetscCall(KSPSetOperators(kp->cg, A, A));
  PetscCall(PCSetReusePreconditioner(pc, PETSC_TRUE));
  PetscErrorCode ierr = transpose ? KSPSolveTranspose(kp->cg, b, x) : KSPSolve(kp->cg, b, x);
  PetscCall(PCSetReusePreconditioner(pc, PETSC_FALSE));
  PetscCall(ierr);
  KSPConvergedReason reason;
  PetscCall(KSPGetConvergedReason(kp->cg, &reason));
  PetscCall(KSPGetIterationNumber(kp->cg, its));
  double t = wall_ms() - t0;
  kp->extra_ms += t - kp->solve_ms;
  kp->cycle_solves++;
  kp->solves++;
  kp->iterations += *its;
  if (reason > 0) {
    *ok = PETSC_TRUE;
    if (changed) kp->saved++; /* a new matrix solved without its factorization */
    kp->stale = 1;
  } else kp->extra_ms = KEEP_BUDGET * kp->factor_ms; /* no more tries before a factorization */
  PetscFunctionReturn(0);
}

void lg_keep_factored(lg_keep *kp, double ms) {
  /* did the iterative solves since the last factorization save time? */
  if (kp->cycle_solves) {
    if (kp->saved * kp->factor_ms <= kp->extra_ms) {
      kp->skip = kp->backoff ? kp->backoff : 1;
      kp->backoff = kp->skip * 2 > KEEP_BACKOFF_MAX ? KEEP_BACKOFF_MAX : kp->skip * 2;
    } else kp->backoff = 0;
  } else if (kp->skip > 0) kp->skip--;
  kp->cycle_solves = 0;
  double f = ms - kp->solve_ms;
  kp->factor_ms = f > 0 ? f : ms;
  kp->extra_ms = 0;
  kp->saved = 0;
  kp->stale = 0;
  kp->factorizations++;
}

void lg_keep_direct(lg_keep *kp, double ms) {
  kp->solve_ms = kp->solve_ms > 0 ? 0.5 * (kp->solve_ms + ms) : ms;
}

PetscErrorCode lg_keep_remember(lg_keep *kp, int transpose, Vec x) {
  PetscFunctionBeginUser;
  if (!kp->last[transpose]) PetscCall(VecDuplicate(x, &kp->last[transpose]));
  PetscCall(VecCopy(x, kp->last[transpose]));
  PetscFunctionReturn(0);
}

int lg_keep_guess(const lg_keep *kp, int transpose, Vec x) {
  return kp->last[transpose] && VecCopy(kp->last[transpose], x) == 0;
}

void lg_keep_destroy(lg_keep *kp) {
  if (kp->cg) KSPDestroy(&kp->cg);
  for (int i = 0; i < 2; i++)
    if (kp->last[i]) VecDestroy(&kp->last[i]);
}
