/* solver.c — the direct solvers of lugal's problems: the default LU factorization (PETSc's
 * own for small single-field systems, MUMPS otherwise), the switch to MUMPS when the
 * default one fails, and MUMPS's null pivot detection, which turns a singular matrix into
 * an error instead of a solution of garbage. */
#include "solver.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* PETSc's LU against MUMPS, one factorization and one solve of the P1 Laplacian
 * (bench/RESULTS.md, "Direct solvers"): PETSc's is faster on 2D systems up to about 10^5
 * unknowns (total 0.04 against 0.09 s at 16 641, 0.30 against 0.46 s at 66 049; MUMPS
 * wins at 263 169) and on 3D ones up to about 10^4 (equal at 4 913, MUMPS 16% faster to
 * factor at 15 625), and its triangular solves are 4-7 times faster at every size, which an
 * optimization, solving several times per factorization, feels most */
#define LU_NATIVE_MAX_2D 100000
#define LU_NATIVE_MAX_3D 10000
/* where CG with GAMG is the default (symmetric positive definite systems): from these sizes
 * on it beats the direct solvers (bench/RESULTS.md, "Default solvers") */
#define LG_ITERATIVE_MIN_2D 200000
#define LG_ITERATIVE_MIN_3D 20000

PetscErrorCode lg_lu_default(PC pc, Mat A, PetscInt n, int dim, int nfields, int nnull) {
  PetscFunctionBeginUser;
  PetscCall(PCSetType(pc, PCLU));
  PetscBool have = PETSC_FALSE, own = PETSC_FALSE;
  PetscCall(MatGetFactorAvailable(A, MATSOLVERMUMPS, MAT_FACTOR_LU, &have));
  /* PETSc's own LU factors sequential matrices only (a parallel run's MPIAIJ goes to MUMPS) */
  PetscCall(MatGetFactorAvailable(A, MATSOLVERPETSC, MAT_FACTOR_LU, &own));
  /* PETSc's LU does not pivot: a mixed system (a saddle point's zero block) needs MUMPS,
   * and so does a singular one with its null space given (MUMPS solves past null pivots) */
  int native = own && (!have || (nfields == 1 && nnull == 0 && n <= (dim >= 3 ? LU_NATIVE_MAX_3D : LU_NATIVE_MAX_2D)));
  /* no ordering is set here: PETSc's LU prefers nested dissection by itself, lg_lu_prepare
   * picks minimum degree for short rows once the matrix is known, and an ordering set on the
   * PC is handed to MUMPS too (40 s instead of 0.3 s for one factorization at 66 049 dofs,
   * against MUMPS's own ordering), which lg_lu_fallback therefore resets */
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

/* whether the user gave option name (with the problem's prefix): lugal's choices stand back */
static int user_set(const char *prefix, const char *name) {
  PetscBool set = PETSC_FALSE;
  PetscOptionsHasName(NULL, prefix && prefix[0] ? prefix : NULL, name, &set);
  return set != PETSC_FALSE;
}

int lg_lu_native(KSP ksp, const char *prefix) {
  PC pc;
  MatSolverType st;
  if (!is_lu(ksp, &pc, &st) || strcmp(st, MATSOLVERPETSC)) return 0;
  return !user_set(prefix, "-pc_factor_mat_solver_type");
}

/* whether A is symmetric to rounding, entry by entry: |a_ij − a_ji| ≤ 1e-12 m, m the larger
 * of |a_ij|, |a_ji| and 1e-4 sqrt(|a_ii a_jj|) (the two triangles of a symmetric form's
 * element matrices are summed in different orders; an absolute tolerance would call an
 * identity row with a column of tiny entries symmetric; the diagonals' share counts the
 * rounding of entries that cancel: a 64² P2 stiffness-plus-mass matrix has edge-vertex
 * entries of 2.7e-6, the mass part that the stiffness parts cancel down to, whose triangles
 * differ by 3.5e-18 next to diagonals of 4-6, and it was taken for unsymmetric). A row
 * whose diagonal is zero (a saddle point's pressure rows) counts its largest entry instead:
 * Taylor-Hood's divergence entries that cancel to rounding made a Stokes matrix
 * unsymmetric, and its adjoint took the transposed solve. Read only: MatIsSymmetric marks
 * the matrix changed, which refactors it */
static PetscErrorCode symmetric_skip(Mat A, const char *skip, PetscBool *sym);
static PetscErrorCode symmetric(Mat A, PetscBool *sym) { return symmetric_skip(A, NULL, sym); }

int lg_symmetric_besides(Mat A, const PetscInt *rows, int nrows) {
  PetscBool seq = PETSC_FALSE, sym = PETSC_FALSE;
  PetscInt n;
  if (PetscObjectTypeCompare((PetscObject)A, MATSEQAIJ, &seq) || !seq || MatGetLocalSize(A, &n, NULL)) return 0;
  char *skip = calloc((size_t)n + 1, 1);
  if (!skip) return 0;
  for (int i = 0; i < nrows; i++)
    if (rows[i] >= 0 && rows[i] < n) skip[rows[i]] = 1;
  PetscErrorCode ierr = symmetric_skip(A, skip, &sym);
  free(skip);
  return !ierr && sym;
}

/* symmetric(), the entries in a skipped row or column left out */
static PetscErrorCode symmetric_skip(Mat A, const char *skip, PetscBool *sym) {
  const PetscInt *ia, *ja;
  const PetscScalar *a;
  PetscInt n;
  PetscBool done;
  PetscFunctionBeginUser;
  *sym = PETSC_FALSE;
  PetscCall(MatGetRowIJ(A, 0, PETSC_FALSE, PETSC_FALSE, &n, &ia, &ja, &done));
  if (!done) PetscFunctionReturn(0);
  PetscCall(MatSeqAIJGetArrayRead(A, &a));
  double *dg = malloc(sizeof(double) * ((size_t)n + 1));
  int ok = dg != NULL;
  for (PetscInt i = 0; ok && i < n; i++) { /* |a_ii|, or the row's largest |a_ik| where a_ii = 0 */
    double mx = 0;
    dg[i] = 0;
    for (PetscInt k = ia[i]; k < ia[i + 1]; k++) {
      if (ja[k] == i) dg[i] = PetscAbsScalar(a[k]);
      mx = PetscMax(mx, PetscAbsScalar(a[k]));
    }
    if (dg[i] == 0) dg[i] = mx;
  }
  for (PetscInt i = 0; i < n && ok; i++)
    for (PetscInt k = ia[i]; k < ia[i + 1] && ok; k++) {
      PetscInt j = ja[k];
      if (j <= i || (skip && (skip[i] || skip[j]))) continue;
      /* a_ji: binary search in row j's sorted columns */
      PetscInt lo = ia[j], hi = ia[j + 1] - 1;
      PetscScalar aji = 0;
      while (lo <= hi) {
        PetscInt mid = (lo + hi) / 2;
        if (ja[mid] == i) { aji = a[mid]; break; }
        if (ja[mid] < i) lo = mid + 1; else hi = mid - 1;
      }
      PetscReal m = PetscMax(PetscMax(PetscAbsScalar(a[k]), PetscAbsScalar(aji)), 1e-4 * PetscSqrtReal(dg[i] * dg[j]));
      ok = PetscAbsScalar(a[k] - aji) <= 1e-12 * m;
    }
  free(dg);
  PetscCall(MatSeqAIJRestoreArrayRead(A, &a));
  PetscCall(MatRestoreRowIJ(A, 0, PETSC_FALSE, PETSC_FALSE, &n, &ia, &ja, &done));
  *sym = ok ? PETSC_TRUE : PETSC_FALSE;
  PetscFunctionReturn(0);
}

PetscInt lg_iterative_size(int dim) {
  PetscInt n = dim >= 3 ? LG_ITERATIVE_MIN_3D : LG_ITERATIVE_MIN_2D;
  PetscOptionsGetInt(NULL, NULL, "-lugal_iterative_min", &n, NULL); /* the user's size, if given */
  return n;
}

int lg_positive_diagonal(Mat A) { /* collective */
  Vec d;
  PetscReal mn = 0;
  if (MatCreateVecs(A, &d, NULL)) return 0;
  int ok = !MatGetDiagonal(A, d) && !VecMin(d, NULL, &mn) && mn > 0;
  VecDestroy(&d);
  return ok;
}

/* a parallel matrix's symmetry: against its explicit transpose, row by row over the owned
 * rows (MatGetRow's columns are sorted), the test of symmetric_skip with the row's own
 * diagonal (or largest entry) for the diagonals' share; collective */
static int mpi_symmetric(Mat A) {
  Mat At;
  PetscInt lo, hi;
  if (MatTranspose(A, MAT_INITIAL_MATRIX, &At)) return 0;
  int ok = !MatGetOwnershipRange(A, &lo, &hi);
  for (PetscInt i = lo; ok && i < hi; i++) {
    PetscInt na = 0, nt = 0;
    const PetscInt *ca = NULL, *ct = NULL;
    const PetscScalar *va = NULL, *vt = NULL;
    if (MatGetRow(A, i, &na, &ca, &va)) { ok = 0; break; }
    if (MatGetRow(At, i, &nt, &ct, &vt)) { MatRestoreRow(A, i, &na, &ca, &va); ok = 0; break; }
    double dg = 0, mx = 0;
    for (PetscInt k = 0; k < na; k++) {
      if (ca[k] == i) dg = PetscAbsScalar(va[k]);
      mx = PetscMax(mx, PetscAbsScalar(va[k]));
    }
    if (dg == 0) dg = mx;
    for (PetscInt a = 0, t = 0; ok && (a < na || t < nt);) {
      PetscInt col = a < na && (t >= nt || ca[a] <= ct[t]) ? ca[a] : ct[t];
      PetscScalar x = a < na && ca[a] == col ? va[a++] : 0, y = t < nt && ct[t] == col ? vt[t++] : 0;
      PetscReal m = PetscMax(PetscMax(PetscAbsScalar(x), PetscAbsScalar(y)), 1e-4 * dg);
      ok = PetscAbsScalar(x - y) <= 1e-12 * m;
    }
    MatRestoreRow(At, i, &nt, &ct, &vt);
    MatRestoreRow(A, i, &na, &ca, &va);
  }
  MatDestroy(&At);
  int all = 0;
  if (MPI_Allreduce(&ok, &all, 1, MPI_INT, MPI_MIN, PetscObjectComm((PetscObject)A)) != MPI_SUCCESS) return 0;
  return all;
}

int lg_matrix_kind(Mat A, int check_symmetry) {
  PetscBool sym = PETSC_FALSE, seq = PETSC_FALSE;
  if (!lg_positive_diagonal(A)) return 2;
  if (!check_symmetry || PetscObjectTypeCompare((PetscObject)A, MATSEQAIJ, &seq)) return 3;
  return (seq ? !symmetric(A, &sym) && sym : mpi_symmetric(A)) ? 1 : 3;
}

int lg_spd_candidate(Mat A) { return lg_matrix_kind(A, 1) == 1; }

PetscErrorCode lg_iterative_setup(KSP ksp, int spd) {
  PC pc;
  PetscFunctionBeginUser;
  PetscCall(KSPSetType(ksp, spd ? KSPCG : KSPGMRES));
  PetscCall(KSPGetPC(ksp, &pc));
  PetscCall(PCSetType(pc, PCGAMG));
  /* the true residual: a relative 1e-10 leaves the discretization error unchanged in every
   * digit the benchmarks print, where PETSc's 1e-5 of the preconditioned one changed the
   * third (bench/RESULTS.md, "Default solvers"); GMRES preconditioned on the right has it */
  if (!spd) {
    PetscCall(KSPSetPCSide(ksp, PC_RIGHT));
    PetscCall(KSPGMRESSetRestart(ksp, 100));
  }
  PetscCall(KSPSetNormType(ksp, KSP_NORM_UNPRECONDITIONED));
  /* GMRES that has not converged in 150 iterations hands over to the direct solver (a
   * convection-dominated matrix, where GAMG does not help: 0.4 s lost at 24 389 unknowns) */
  PetscCall(KSPSetTolerances(ksp, LG_ITERATIVE_RTOL, 1e-300, PETSC_DEFAULT, spd ? 2000 : 150));
  /* an optimization's next matrix keeps the coarse spaces (the pattern is the same) */
  PetscCall(PCGAMGSetReuseInterpolation(pc, PETSC_TRUE));
  PetscCall(KSPSetFromOptions(ksp));
  PetscFunctionReturn(0);
}

int lg_saddle_point(Mat A, PetscInt n0) {
  PetscBool seq = PETSC_FALSE;
  if (PetscObjectTypeCompare((PetscObject)A, MATSEQAIJ, &seq) || !seq) return 0;
  Vec d;
  PetscInt n = 0;
  const PetscScalar *a;
  if (MatCreateVecs(A, &d, NULL)) return 0;
  int ok = !MatGetDiagonal(A, d) && !VecGetLocalSize(d, &n) && n0 > 0 && n0 < n && !VecGetArrayRead(d, &a);
  if (ok) {
    for (PetscInt i = 0; i < n && ok; i++) ok = i < n0 ? a[i] > 0 : a[i] == 0;
    VecRestoreArrayRead(d, &a);
  }
  VecDestroy(&d);
  return ok;
}

/* option name (after the prefix) to value, unless the user set it */
static PetscErrorCode default_option(const char *prefix, const char *name, const char *value) {
  char full[256];
  PetscFunctionBeginUser;
  if (user_set(prefix, name)) PetscFunctionReturn(0);
  snprintf(full, sizeof full, "-%s%s", prefix ? prefix : "", name + 1);
  PetscCall(PetscOptionsSetValue(NULL, full, value));
  PetscFunctionReturn(0);
}

/* Taylor-Hood Stokes, 29 114 unknowns (bench/stokes3d.lua 10): 58 iterations, 1.4-1.8 s
 * against MUMPS's 12 s, the same energy and pressure drop to 9 digits; 67 iterations at
 * N = 14 (76 542 unknowns). Tried at N = 10: the upper and full factorizations (57 and 50
 * iterations, 1.5 and 1.9 s); minus the lumped pressure mass matrix for the Schur
 * complement (98 and 106 iterations at N = 10 and 14: worse than selfp here); GAMG on the
 * Schur complement's approximation (no convergence in 400) */
PetscErrorCode lg_saddle_setup(KSP ksp, const char *prefix) {
  PC pc;
  PetscFunctionBeginUser;
  PetscCall(KSPSetType(ksp, KSPGMRES));
  PetscCall(KSPSetPCSide(ksp, PC_RIGHT));
  PetscCall(KSPGMRESSetRestart(ksp, 100));
  PetscCall(KSPSetNormType(ksp, KSP_NORM_UNPRECONDITIONED));
  PetscCall(KSPSetTolerances(ksp, LG_ITERATIVE_RTOL, 1e-300, PETSC_DEFAULT, 300));
  PetscCall(KSPGetPC(ksp, &pc));
  PetscCall(PCSetType(pc, PCFIELDSPLIT));
  PetscCall(PCFieldSplitSetType(pc, PC_COMPOSITE_SCHUR));
  PetscCall(PCFieldSplitSetSchurFactType(pc, PC_FIELDSPLIT_SCHUR_FACT_LOWER));
  PetscCall(PCFieldSplitSetSchurPre(pc, PC_FIELDSPLIT_SCHUR_PRE_SELFP, NULL));
  PetscCall(default_option(prefix, "-fieldsplit_0_ksp_type", "preonly"));
  PetscCall(default_option(prefix, "-fieldsplit_0_pc_type", "gamg"));
  PetscCall(default_option(prefix, "-fieldsplit_1_ksp_type", "preonly"));
  PetscCall(default_option(prefix, "-fieldsplit_1_pc_type", "jacobi"));
  PetscCall(KSPSetFromOptions(ksp));
  PetscFunctionReturn(0);
}

/* LU, and for a symmetric matrix that this PC has factored before Cholesky, unless the user
 * chose the preconditioner. PETSc's Cholesky ignores the ordering (its factor of the 128²
 * P1 Laplacian fills 8.26 times A whatever the ordering) and its symbolic phase is slow,
 * 3-6 times LU's, while its numeric phase takes 0.75-0.9 of LU's: a single factorization is
 * 1.4-2.2 times faster by LU (3D P1 16³: 0.068 against 0.148 s), repeated ones of the same
 * pattern (an optimization's state matrix) by Cholesky, which pays for its symbolic phase
 * from about the 5th (bench/RESULTS.md, "Orderings of PETSc's LU"). So the first
 * factorization is LU and the second and later Cholesky. */
static PetscErrorCode choose_factorization(KSP ksp, Mat A, const char *prefix) {
  PetscBool sym = PETSC_FALSE, ch = PETSC_FALSE;
  PC pc;
  PetscFunctionBeginUser;
  if (user_set(prefix, "-pc_type")) PetscFunctionReturn(0);
  PetscCall(KSPGetPC(ksp, &pc));
  PetscCall(PetscObjectTypeCompare((PetscObject)pc, PCCHOLESKY, &ch));
  PetscCall(symmetric(A, &sym));
  if ((sym != PETSC_FALSE) == (ch != PETSC_FALSE)) PetscFunctionReturn(0);
  if (sym) { /* an LU PC: Cholesky once it holds a factor (PETSc's error when it does not
              * is returned to the caller silently: lugal's error handler prints nothing) */
    Mat F = NULL;
    if (PCFactorGetMatrix(pc, &F) || !F) PetscFunctionReturn(0);
  }
  PetscCall(PCReset(pc));
  PetscCall(PCSetType(pc, sym ? PCCHOLESKY : PCLU));
  PetscCall(PCFactorSetMatSolverType(pc, MATSOLVERPETSC));
  PetscCall(KSPSetOperators(ksp, A, A));
  PetscFunctionReturn(0);
}

/* PETSc's LU orders by nested dissection unless told otherwise; where the rows are short
 * (at most 10 entries per block row: P1 and Q1 in 2D, scalar or vector) approximate minimum
 * degree leaves less fill and factors faster: 15-25% at 64² to 256² P1 (7.08 against 9.58
 * Mflop at 64², 0.25 against 0.30 s at 256², 0.21 against 0.28 s for vector P1 at 128²),
 * while on longer rows (P2, and every 3D space) nested dissection wins by 1.2-3×
 * (bench/RESULTS.md, "Orderings of PETSc's LU"). Not for Cholesky, whose PETSc
 * factorization ignores the ordering, nor when the user chose one. */
static PetscErrorCode choose_ordering(KSP ksp, Mat A, const char *prefix) {
  PC pc;
  PetscBool lu = PETSC_FALSE;
  void (*amd)(void) = NULL;
  PetscFunctionBeginUser;
  PetscCall(KSPGetPC(ksp, &pc));
  PetscCall(PetscObjectTypeCompare((PetscObject)pc, PCLU, &lu));
  if (!lu || user_set(prefix, "-pc_factor_mat_ordering_type")) PetscFunctionReturn(0);
  PetscCall(PetscFunctionListFind(MatOrderingList, MATORDERINGAMD, &amd)); /* PETSc built with SuiteSparse */
  if (!amd) PetscFunctionReturn(0);
  MatInfo info;
  PetscInt n, bs;
  PetscCall(MatGetInfo(A, MAT_LOCAL, &info));
  PetscCall(MatGetLocalSize(A, &n, NULL));
  PetscCall(MatGetBlockSize(A, &bs));
  if (n > 0 && info.nz_used <= 10.0 * (double)n * (double)(bs > 0 ? bs : 1))
    PetscCall(PCFactorSetMatOrderingType(pc, MATORDERINGAMD));
  PetscFunctionReturn(0);
}

PetscErrorCode lg_lu_prepare(KSP ksp, Mat A, const PetscInt *bc_rows, int nbc, const char *prefix, int may_cholesky) {
  PetscFunctionBeginUser;
  if (!lg_lu_native(ksp, prefix)) PetscFunctionReturn(0);
  if (may_cholesky) PetscCall(choose_factorization(ksp, A, prefix));
  PetscCall(choose_ordering(ksp, A, prefix));
  if (user_set(prefix, "-pc_factor_zeropivot")) PetscFunctionReturn(0);
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
  /* MUMPS orders by itself: an ordering lugal chose for PETSc's LU (choose_ordering) would
   * be computed by PETSc and handed to it (see lg_lu_default) */
  const char *pre = NULL;
  PetscCall(PCGetOptionsPrefix(pc, &pre));
  if (!user_set(pre, "-pc_factor_mat_ordering_type")) PetscCall(PCFactorSetMatOrderingType(pc, MATORDERINGEXTERNAL));
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

/* the sizes MUMPS reports: INFOG(2) < 0 counts millions */
static double mumps_count(PetscInt v) { return v < 0 ? -1e6 * (double)v : (double)v; }

void lg_solve_failure(KSP ksp, char *out, size_t len) {
  out[0] = 0;
  PC pc;
  PCType pt = NULL;
  KSPType kt = NULL;
  if (KSPGetPC(ksp, &pc) || PCGetType(pc, &pt) || KSPGetType(ksp, &kt) || !pt || !kt) return;
  Mat F = mumps_factor(ksp, 0);
  PetscInt i1 = 0, i2 = 0, mb = 0, tot = 0;
  if (F && !MatMumpsGetInfog(F, 1, &i1) && i1 < 0) {
    MatMumpsGetInfog(F, 2, &i2);
    MatMumpsGetInfog(F, 16, &mb);  /* the estimated working memory, MB on the largest process */
    MatMumpsGetInfog(F, 17, &tot); /* and in all */
    const char *what = i1 == -13   ? "could not allocate memory"
                       : i1 == -9  ? "ran out of its workspace"
                       : i1 == -19 ? "was given less working memory than it needs (ICNTL(23))"
                       : i1 == -8 || i1 == -14 || i1 == -15 || i1 == -11 ? "ran out of an internal array"
                                                                          : NULL;
    char need[96] = "";
    if (mb > 0) snprintf(need, sizeof need, "; it estimated %ld MB on the largest process, %ld MB in all", (long)mb, (long)tot);
    if (what)
      snprintf(out, len, ": the direct solver MUMPS %s (INFOG(1) = %ld, INFOG(2) = %.0f%s): the factorization needs more "
                         "memory than it can have; an iterative solver needs far less (-ksp_type cg -pc_type gamg for a "
                         "symmetric positive definite problem, -ksp_type gmres -pc_type gamg otherwise)",
               what, (long)i1, mumps_count(i2), need);
    else snprintf(out, len, ": the direct solver MUMPS failed (INFOG(1) = %ld, INFOG(2) = %ld)", (long)i1, (long)i2);
    return;
  }
  /* a preconditioner alone (preonly) that is no factorization solves nothing */
  if (!strcmp(kt, KSPPREONLY) && strcmp(pt, PCLU) && strcmp(pt, PCCHOLESKY) && strcmp(pt, PCQR) && strcmp(pt, PCSVD) &&
      strcmp(pt, PCREDUNDANT) && strcmp(pt, PCTELESCOPE))
    snprintf(out, len, ": -ksp_type preonly applies the preconditioner %s once, which is no solver of this matrix; give it a "
                       "Krylov method (-ksp_type cg or gmres), or a factorization (-pc_type lu)", pt);
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
 * the future); a kept factor ages slowly on an optimization's path, and more was cheaper
 * there (64² inversion L-BFGS, factorizations and triangular solves at their measured unit
 * times, 2.9 ms and 0.2 ms: budget 2: 21 factorizations and 624 solves, 186 ms; 3: 16 and
 * 659, 178 ms; 4: 14 and 698, 180 ms; 6: 15 and 681, 180 ms; LU alike), at a bound of four
 * times */
#define KEEP_BUDGET 3.0
/* a factorization's speed per multiply-add relative to a triangular solve's, and an
 * iteration's vector operations in triangular solves (see factor_solves). Measured on P1
 * Laplacians (PETSc 3.18, -log_view, numeric factorization / MatSolve against the count
 * Σc²/2Σ(c+1)): 2D 33² 10.3 against 13.7, 65² 14.4 (LU 19.5) against 24.1, 129² 24.2
 * (34.7) against 42.0, 201² 29.9 (47.9) against 59.9; 3D 11³ 26.2 (20.1) against 50.9, 17³
 * 58.6 (66.4) against 118, 21³ 87.1 (98.5) against 177: the count over 1.6 is within a
 * third of both everywhere */
#define KEEP_FACTOR_SPEED 1.6
#define KEEP_VECTOR_OPS 0.1

int lg_keep_applies(KSP ksp, const char *prefix) {
  PC pc;
  PetscBool ch = PETSC_FALSE, lu = PETSC_FALSE;
  if (!lg_lu_native(ksp, prefix) || KSPGetPC(ksp, &pc) || PetscObjectTypeCompare((PetscObject)pc, PCCHOLESKY, &ch) ||
      PetscObjectTypeCompare((PetscObject)pc, PCLU, &lu) || !(ch || lu))
    return 0;
  return !user_set(prefix, "-ksp_type") && !user_set(prefix, "-pc_type");
}

int lg_keep_usable(const lg_keep *kp, KSP ksp, const char *prefix) {
  if (kp->skip > 0 || kp->factor_cost <= 0 || kp->extra >= KEEP_BUDGET * kp->factor_cost) return 0;
  return lg_keep_applies(ksp, prefix);
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
    PetscCall(KSPSetPC(kp->cg, pc));
    PetscCall(KSPSetTolerances(kp->cg, KEEP_RTOL, 0.0, PETSC_DEFAULT, KEEP_MAXIT));
    PetscCall(KSPSetErrorIfNotConverged(kp->cg, PETSC_FALSE));
    PetscCall(KSPSetFromOptions(kp->cg));
  }
  /* CG for a Cholesky factor (a symmetric matrix), GMRES preconditioned on the right for
   * an LU one, so that both test the true residual */
  PetscBool ch = PETSC_FALSE;
  PetscCall(PetscObjectTypeCompare((PetscObject)pc, PCCHOLESKY, &ch));
  PetscCall(KSPSetType(kp->cg, ch ? KSPCG : KSPGMRES));
  /* both sides set: a problem's PC turns from LU to Cholesky at its second factorization
   * (choose_factorization), and CG refuses GMRES's right side */
  PetscCall(KSPSetPCSide(kp->cg, ch ? PC_LEFT : PC_RIGHT));
  PetscCall(KSPSetNormType(kp->cg, KSP_NORM_UNPRECONDITIONED));
  /* an iteration: a triangular solve pair, a product with A (its entries against the
   * factor's, each touched once per solve pair and twice per product) and a few vector
   * operations; the residual of a guess one product */
  PetscInt annz = 0;
  MatInfo ai;
  if (!MatGetInfo(A, MAT_LOCAL, &ai)) annz = (PetscInt)ai.nz_used;
  double prod = kp->factor_nnz > 0 ? 0.5 * (double)annz / (double)kp->factor_nnz : 0.5;
  double cost = 0;
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
    cost += prod;
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
  cost += (double)*its * (1 + prod + KEEP_VECTOR_OPS);
  kp->extra += cost - 1; /* beyond the direct solve it replaces */
  kp->cycle_solves++;
  if (reason > 0) {
    *ok = PETSC_TRUE;
    if (changed) kp->saved++; /* a new matrix solved without its factorization */
    kp->stale = 1;
  } else kp->extra = KEEP_BUDGET * kp->factor_cost; /* no more tries before a factorization */
  PetscFunctionReturn(0);
}

/* what a numeric factorization costs in triangular solves (a forward and a backward
 * substitution), from the factor's structure, so that the choices do not depend on timings
 * (a run repeats its results to the bit): the factorization does Σ_j c_j² multiply-adds (c_j
 * the entries below the diagonal in column j of L), the solves 2 Σ_j (c_j + 1); measured
 * here, a factorization runs at KEEP_FACTOR_SPEED times the solves' rate per operation
 * (see KEEP_FACTOR_SPEED). Cholesky: PETSc's SBAIJ factor holds U by rows with the
 * diagonal (row j's length is c_j + 1); LU: L by rows without it (c_j counts column j). */
static double factor_solves(PC pc, PetscInt *nnz) {
  Mat F;
  const PetscInt *ia, *ja;
  PetscInt n;
  PetscBool done = PETSC_FALSE, ch = PETSC_FALSE;
  *nnz = 0;
  if (PetscObjectTypeCompare((PetscObject)pc, PCCHOLESKY, &ch) || PCFactorGetMatrix(pc, &F) ||
      MatGetRowIJ(F, 0, PETSC_FALSE, PETSC_FALSE, &n, &ia, &ja, &done) || !done)
    return 0;
  double *c = calloc((size_t)n + 1, sizeof(double)), s1 = 0, s2 = 0;
  if (c) {
    for (PetscInt i = 0; i < n; i++) {
      if (ch) c[i] = (double)(ia[i + 1] - ia[i] - 1);
      else
        for (PetscInt e = ia[i]; e < ia[i + 1]; e++)
          if (ja[e] >= 0 && ja[e] < n) c[ja[e]] += 1;
    }
    for (PetscInt i = 0; i < n; i++) {
      s1 += c[i] + 1;
      s2 += c[i] * c[i];
    }
    free(c);
  }
  *nnz = (PetscInt)s1;
  MatRestoreRowIJ(F, 0, PETSC_FALSE, PETSC_FALSE, &n, &ia, &ja, &done);
  return s1 > 0 ? s2 / (2 * s1) / KEEP_FACTOR_SPEED : 0;
}

void lg_keep_factored(lg_keep *kp, KSP ksp) {
  /* did the iterative solves since the last factorization save work? */
  if (kp->cycle_solves) {
    if (kp->saved * kp->factor_cost <= kp->extra) {
      kp->skip = kp->backoff ? kp->backoff : 1;
      kp->backoff = kp->skip * 2 > KEEP_BACKOFF_MAX ? KEEP_BACKOFF_MAX : kp->skip * 2;
    } else kp->backoff = 0;
  } else if (kp->skip > 0) kp->skip--;
  kp->cycle_solves = 0;
  PC pc;
  PetscInt nnz = 0;
  kp->factor_cost = KSPGetPC(ksp, &pc) ? 0 : factor_solves(pc, &nnz);
  kp->factor_nnz = nnz;
  kp->extra = 0;
  kp->saved = 0;
  kp->stale = 0;
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

void lg_keep_name(const lg_keep *kp, char *out, size_t len) {
  KSPType kt = NULL;
  PC pc = NULL;
  PCType pt = NULL;
  if (kp->cg && !KSPGetType(kp->cg, &kt) && !KSPGetPC(kp->cg, &pc)) PCGetType(pc, &pt);
  snprintf(out, len, "%s/%s-kept", kt ? kt : "?", pt ? pt : "?");
}

void lg_keep_destroy(lg_keep *kp) {
  if (kp->cg) KSPDestroy(&kp->cg);
  for (int i = 0; i < 2; i++)
    if (kp->last[i]) VecDestroy(&kp->last[i]);
}
