/* problem_solve.c — solving a problem on PETSc: the KSP of a linear problem (direct by
 * default, null spaces, kept factorizations), Newton's method on SNES for a nonlinear one,
 * the solves with the Jacobian at the solution (adjoint, tangent) and the products with the
 * assembled matrix; every failure reported, never ignored. problem.c builds and assembles
 * what this solves. */
#include "problem_int.h"
#include "solver.h"

#include <math.h>
#include <stdint.h>
#include <petscsnes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---------------------------------------------------------------- solving */

static const char *ksp_reason_name(KSPConvergedReason r) {
  const char *s = KSPConvergedReasons[r];
  return s ? s : "UNKNOWN";
}

static int make_outputs(lg_env *env, lg_problem *p, const double *x, lg_function **out) {
  for (int a = 0; a < p->cols.n; a++) {
    expr_func_info *fi = expr_func_get(env->c, p->cols.func[a]);
    char nm[80];
    snprintf(nm, sizeof nm, "%sh", fi->name);
    out[a] = lg_function_new(env, p->lm, p->cdm[a], nm);
    if (!out[a]) {
      for (int b = 0; b < a; b++) lg_function_free(out[b]);
      return 1;
    }
    memcpy(out[a]->x, x + p->cglob[a], sizeof(double) * (size_t)p->cdm[a]->ndof);
  }
  return 0;
}

/* the default solver: a direct LU factorization (solver.c chooses PETSc's or MUMPS);
 * -ksp_type / -pc_type / -pc_factor_mat_solver_type override it */
static int default_lu(lg_env *env, lg_problem *p, PC pc) {
  PCHK(lg_lu_default(pc, p->A, p->N, p->lm->m->dim, p->cols.n, p->nnull), "the default LU");
  return 0;
}

/* 0, or 1 with a message when the last factorization found more null pivots than the null
 * space given */
static int check_null_pivots(lg_env *env, lg_problem *p, KSP ksp) {
  PetscInt n = lg_mumps_null_pivots(ksp);
  if (n <= p->nnull) return 0;
  if (p->nnull)
    lg_seterr(env, "the matrix is singular: %d null pivots, more than the %d null space vectors given with nullspace=", (int)n,
              p->nnull);
  else
    lg_seterr(env, "the matrix is singular (%d null pivot%s in the factorization): are boundary conditions missing? A "
                   "problem determined only up to a constant (pure Neumann, an enclosed flow's pressure) takes "
                   "nullspace = that unknown", (int)n, n == 1 ? "" : "s");
  return 1;
}

/* the integrals of the basis functions of component j of field a (the weights of its mean:
 * mean(x) = sum_i x_i m_i / vol), into m (one per node of the field), from the rank's owned
 * cells (owned) or from all its cells (complete at the dofs it owns, whose cells are all
 * local); returns the measure of those cells */
static double null_weights(const lg_problem *p, int a, int j, int owned, double *m) {
  const mesh_part *P = p->lm->dist;
  int rank = lg_mpi_rank();
  const dofmap *dm = p->cdm[a];
  int bs = dm->bs;
  mesh *m_ = p->lm->m;
  double vol = 0;
  memset(m, 0, sizeof(double) * (size_t)(dm->ndof / bs + 1));
  if (cell_is_simplex(m_->type)) {
    for (int c = 0; c < m_->ncell; c++) {
      if (owned && P && P->cowner[c] != rank) continue;
      double J[3][3], K[3][3], det = fabs(simplex_jacobian(m_, c, J, K));
      const int *cd = dm->cell_dofs + (size_t)c * (size_t)dm->nloc;
      for (int k = 0; k < dm->el.nloc; k++) m[cd[k * bs + j] / bs] += dm->el.mean[k] * det;
      vol += det;
    }
    return vol;
  }
  /* a quadrilateral's or hexahedron's Jacobian varies: a rule of the basis degree + 1 */
  quad_rule q;
  quad_cell(m_->type, 0, dm->degree + 1, &q);
  for (int c = 0; c < m_->ncell; c++) {
    if (owned && P && P->cowner[c] != rank) continue;
    const int *cd = dm->cell_dofs + (size_t)c * (size_t)dm->nloc;
    for (int i = 0; i < q.n; i++) {
      double J[3][3], K[3][3], val[FEM_MAXLOC], grad[FEM_MAXLOC * 3];
      double w = q.w[i] * fabs(cell_jacobian(m_, c, q.x + m_->dim * i, J, K));
      lagrange_eval(&dm->el, q.x + m_->dim * i, val, grad);
      for (int k = 0; k < dm->el.nloc; k++) m[cd[k * bs + j] / bs] += w * val[k];
      vol += w;
    }
  }
  return vol;
}

/* the projection of a constant null space field (Lagrange bases hold the constants:
 * subtracting c from every dof subtracts c), component by component, m the weights above:
 * the state's shift to mean zero, x -> P x = x - 1 (m^T x) / vol (transpose 0), or its
 * transpose, r -> P^T r = r - m (1^T r) / vol, for an adjoint's right side (transpose 1):
 * compatible with the null space (1^T P^T r = 0), its solution the adjoint of the shifted
 * state. Without the transpose a functional's gradient was wrong (a Taylor test's second
 * remainder fell at rate 1, not 2). On a distributed mesh each rank integrates its owned
 * cells (the transpose's weights: all its cells, complete at its owned dofs); 1^T r sums
 * the owned rows; the sums are reduced over the ranks */
static int null_project(lg_env *env, lg_problem *p, double *x, int transpose) {
  const int dist = p->lm->dist != NULL;
  for (int a = 0; a < p->cols.n; a++) {
    if (!p->null_const[a]) continue;
    const dofmap *dm = p->cdm[a];
    int bs = dm->bs;
    double *m = malloc(sizeof(double) * (size_t)(dm->ndof / bs + 1));
    if (!m) { lg_seterr(env, "out of memory"); return 1; }
    for (int j = 0; j < bs; j++) {
      double sv[2] = {0, null_weights(p, a, j, 1, m)}; /* the pairing, the measure */
      if (transpose && dist) null_weights(p, a, j, 0, m);
      for (int i = j; i < dm->ndof; i += bs) {
        if (!transpose) sv[0] += x[p->cglob[a] + i] * m[i / bs];
        else {
          PetscInt row = lg_petsc_row(p, p->cglob[a] + i);
          if (row >= p->lo && row < p->hi) sv[0] += x[p->cglob[a] + i];
        }
      }
      if (transpose ? p->par : dist) lg_allreduce(sv, 1, LG_SUM);
      if (dist) lg_allreduce(sv + 1, 1, LG_SUM);
      double c = sv[1] > 0 ? sv[0] / sv[1] : 0;
      for (int i = j; i < dm->ndof; i += bs) x[p->cglob[a] + i] -= transpose ? m[i / bs] * c : c;
    }
    free(m);
  }
  return 0;
}

/* a 64-bit finalizer (splitmix64's): every input bit moves every output bit */
static uint64_t splitmix(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

/* what a linear problem's matrix depends on: the values of the discrete functions and the
 * parameters its kernels read, and the mesh's geometry. Equal fingerprints: the matrix, its
 * essential rows and its factorization are still valid (a control that enters only the
 * right-hand side costs no reassembly and no refactorization). 0 when it cannot tell. */
static uint64_t matrix_fingerprint(lg_env *env, lg_problem *p) {
  uint64_t h = 1469598103934665603ull;
#define MIX(ptr, bytes)                                                          \
  do {                                                                           \
    const unsigned char *b_ = (const unsigned char *)(ptr);                      \
    for (size_t i_ = 0; i_ < (bytes); i_++) h = (h ^ b_[i_]) * 1099511628211ull; \
  } while (0)
  MIX(&p->lm->geometry, sizeof p->lm->geometry);
  const double *pv = expr_param_values(env->c); /* the parameters the matrix reads */
  for (int i = 0; i < p->nmatpar; i++) MIX(&pv[p->matpar[i]], sizeof(double));
  coef_binding extra[2 * KER_MAXFIELD], bind[KER_MAXCOEF];
  int ne = lg_problem_bind_unknowns(p, p->state, extra);
  for (int i = 0; i < p->nterm; i++) {
    prob_term *t = &p->t[i];
    if (!t->have_mat) continue;
    char keep[LG_ERRLEN];
    memcpy(keep, env->err, sizeof keep);
    int rc = lg_bind_discrete(env, p->lm, &t->kmat, ne, extra, bind);
    memcpy(env->err, keep, sizeof keep);
    if (rc) { h = 0; break; }
    for (int k = 0; k < t->kmat.ncoef; k++) {
      int unknown = 0;
      for (int a = 0; a < ne; a++) unknown |= bind[k].func == extra[a].func;
      if (unknown) continue; /* zero in a linear problem */
      MIX(&bind[k].vals, sizeof bind[k].vals);
      MIX(bind[k].vals, sizeof(double) * (size_t)bind[k].dm->ndof);
    }
  }
  if (h) h |= 1;
  if (p->lm->dist) {
    /* a distributed mesh's ranks hash their own parts: they decide together (whether to
     * assemble, which is collective), on the sum of their hashes each first mixed with its
     * rank (0 if any has none). An XOR of the plain hashes cancelled between ranks whose parts
     * hash alike: a parameter or the geometry's count, the same on every rank, never changed
     * the fingerprint of an even number of ranks, and the first matrix stayed. */
    uint64_t v[2] = {splitmix(h ^ splitmix((uint64_t)lg_mpi_rank() + 1)), h == 0}, all[2] = {0, 0};
    if (MPI_Allreduce(v, all, 2, MPI_UINT64_T, MPI_SUM, PETSC_COMM_WORLD) != MPI_SUCCESS || all[1]) return 0;
    h = all[0] | 1;
  }
#undef MIX
  return h;
}

/* the linear solver of a linear problem: direct LU by default (default_lu), every -ksp_* and
 * -pc_* option (with the problem's prefix) applied once */
/* A fieldsplit PC's splits (the user's -pc_type fieldsplit, or the saddle-point default):
 * the owned rows of each unknown, in the order of the problem's unknowns, named "0", "1", ...
 * (the options -fieldsplit_0_..., as PETSc names them) */
static int field_splits(lg_env *env, lg_problem *p, PC pc) {
  PetscBool fs = PETSC_FALSE;
  PCHK(PetscObjectTypeCompare((PetscObject)pc, PCFIELDSPLIT, &fs), "PetscObjectTypeCompare");
  IS have = NULL;
  if (fs) PCHK(PCFieldSplitGetIS(pc, "0", &have), "PCFieldSplitGetIS");
  if (!fs || have || p->rows.n < 2) return 0;
  int n = p->hi - p->lo, nf = p->rows.n;
  PetscInt *rows = malloc(sizeof(PetscInt) * ((size_t)n + 1));
  int *field = malloc(sizeof(int) * ((size_t)n + 1));
  if (!rows || !field) {
    free(rows); free(field);
    lg_seterr(env, "out of memory for the field splits");
    return 1;
  }
  for (PetscInt r = p->lo; r < p->hi; r++) {
    PetscInt i = lg_problem_row(p, r);
    int a = 0;
    while (a < nf - 1 && i >= p->rglob[a + 1]) a++;
    field[r - p->lo] = a;
  }
  PetscErrorCode ierr = 0;
  for (int a = 0; a < nf && !ierr; a++) {
    PetscInt m = 0;
    for (PetscInt r = p->lo; r < p->hi; r++)
      if (field[r - p->lo] == a) rows[m++] = r;
    IS is;
    char name[16];
    snprintf(name, sizeof name, "%d", a);
    ierr = ISCreateGeneral(PetscObjectComm((PetscObject)pc), m, rows, PETSC_COPY_VALUES, &is);
    /* a vector unknown's components are the split's blocks: its matrix gets them as its block
     * size, and GAMG aggregates nodes, not components (3D Taylor–Hood's velocity: 100 and 148
     * iterations at N = 10 and 14 without) */
    if (!ierr && p->cdm[a]->bs > 1 && m % p->cdm[a]->bs == 0) ierr = ISSetBlockSize(is, p->cdm[a]->bs);
    if (!ierr) ierr = PCFieldSplitSetIS(pc, name, is);
    ISDestroy(&is);
  }
  free(rows);
  free(field);
  if (ierr) return lg_petsc_fail(env, ierr, "the field splits");
  return 0;
}

/* ksp to the saddle point default (solver.c, lg_saddle_setup) with the unknowns as splits */
static int saddle_solver(lg_env *env, lg_problem *p, KSP ksp) {
  PC pc;
  PCHK(lg_saddle_setup(ksp, p->prefix), "the saddle point solver's setup");
  PCHK(KSPGetPC(ksp, &pc), "KSPGetPC");
  return field_splits(env, p, pc);
}

static int ensure_ksp(lg_env *env, lg_problem *p) {
  if (p->ksp) return 0;
  PCHK(KSPCreate(PetscObjectComm((PetscObject)p->A), &p->ksp), "KSPCreate");
  if (p->prefix[0]) PCHK(KSPSetOptionsPrefix(p->ksp, p->prefix), "KSPSetOptionsPrefix");
  PC pc;
  PCHK(KSPGetPC(p->ksp, &pc), "KSPGetPC");
  if (p->mass_cg == 1) {
    PCHK(KSPSetType(p->ksp, KSPCG), "KSPSetType");
    PCHK(PCSetType(pc, PCJACOBI), "PCSetType");
    PCHK(KSPSetTolerances(p->ksp, 1e-14, 0, PETSC_DEFAULT, 500), "KSPSetTolerances");
    PCHK(KSPSetNormType(p->ksp, KSP_NORM_UNPRECONDITIONED), "KSPSetNormType");
  } else {
    PCHK(KSPSetType(p->ksp, KSPPREONLY), "KSPSetType");
    if (default_lu(env, p, pc)) return 1;
  }
  PCHK(KSPSetFromOptions(p->ksp), "KSPSetFromOptions");
  if (field_splits(env, p, pc)) return 1;
  return lg_problem_near_nullspace(env, p, p->ksp);
}

void lg_problem_mass_solver(lg_problem *p) {
  if (!p->ksp) p->mass_cg = 1;
}

/* a mass matrix's CG that did not converge: LU from now on */
static int mass_to_lu(lg_env *env, lg_problem *p) {
  PC pc;
  p->mass_cg = 2;
  PCHK(KSPSetType(p->ksp, KSPPREONLY), "KSPSetType");
  PCHK(KSPGetPC(p->ksp, &pc), "KSPGetPC");
  if (default_lu(env, p, pc)) return 1;
  PCHK(lg_lu_prepare(p->ksp, p->A, p->own_rows, p->nown, p->prefix, 1), "the factorization's choice");
  return 0;
}

/* whether option name was given for this problem (its prefix) */
static int option_set(const lg_problem *p, const char *name) {
  PetscBool set = PETSC_FALSE;
  PetscOptionsHasName(NULL, p->prefix[0] ? p->prefix : NULL, name, &set);
  return set != PETSC_FALSE;
}

/* the direct solver from now on (CG did not converge, or the matrix is no longer SPD) */
static int iterative_to_direct(lg_env *env, lg_problem *p, const char *why) {
  PC pc;
  KSP ksp = p->ksp;
  if (p->nonlinear) {
    p->newton_iter = 2;
    PCHK(SNESGetKSP(p->snes, &ksp), "SNESGetKSP");
  } else p->iter = 2;
  PCHK(KSPSetType(ksp, KSPPREONLY), "KSPSetType");
  PCHK(KSPGetPC(ksp, &pc), "KSPGetPC");
  if (default_lu(env, p, pc)) return 1;
  PCHK(KSPSetOperators(ksp, p->A, p->A), "KSPSetOperators");
  if (env->verbose) fprintf(stderr, "[lugal] %s solver: the direct solver from now on (%s)\n", p->nonlinear ? "Newton's linear" : "linear", why);
  return 0;
}

/* lugal's default solver of the problem's solves with its matrix (1 CG, 3 GMRES with GAMG;
 * 2, 0 or -1 otherwise): a linear problem's KSP's, a nonlinear one's SNES's */
static int default_mode(const lg_problem *p) { return p->nonlinear ? p->newton_iter : p->iter; }

/* whether a default_mode is one of lugal's Krylov defaults: 1 CG, 3 GMRES with GAMG, 4 GMRES
 * with a Schur complement fieldsplit (a saddle point) */
static int krylov_default(int mode) { return mode == 1 || mode == 3 || mode == 4; }

/* whether ksp is CG (lugal's default or the user's -ksp_type cg): its matrix must be
 * symmetric, so the essential columns are eliminated with the rows */
static int ksp_is_cg(KSP ksp) {
  PetscBool cg = PETSC_FALSE;
  if (ksp) PetscObjectTypeCompare((PetscObject)ksp, KSPCG, &cg);
  return cg != PETSC_FALSE;
}

/* whether an iterative default may apply: nfield unknowns (scalar or vector) of at least
 * lg_iterative_size unknowns together, a null space only in a serial run, no solver chosen
 * by the user. A null space is attached to the matrix (MatSetNullSpace), which CG removes
 * from its preconditioned residuals; the adjoint's right side is made compatible with it
 * (null_project) */
static int iterative_allowed(lg_problem *p, int nfield) {
  PetscBool on = PETSC_TRUE;
  PetscOptionsGetBool(NULL, NULL, "-lugal_iterative", &on, NULL);
  /* the saddle point's checks and splits read a serial matrix's field order */
  return on && !p->mass_cg && !(p->nnull && p->par) && !(p->par && nfield > 1) && p->rows.n == nfield && p->cols.n == nfield &&
         p->Nglob >= lg_iterative_size(p->lm->m->dim) && !option_set(p, "-ksp_type") && !option_set(p, "-pc_type") &&
         !option_set(p, "-pc_factor_mat_solver_type");
}

/* A linear problem's default solver, chosen at its first assembly (A as assembled, before
 * the essential rows), for a single field (scalar or vector) of at least lg_iterative_size
 * unknowns without a null space, serial, unless the user chose the solver (-ksp_type,
 * -pc_type, -pc_factor_mat_solver_type) or -lugal_iterative 0: CG with GAMG (solver.c,
 * lg_iterative_setup) where the matrix is symmetric with a positive diagonal, GMRES with
 * GAMG where its diagonal is positive (convection-diffusion), the direct solver otherwise.
 * Each later assembly checks the matrix again for CG (a coefficient may make it
 * unsymmetric). With CG the essential rows and columns are eliminated (solve_linear),
 * whatever symmetric= says; solve_with_jacobian corrects the adjoint and tangent solves for
 * the columns. A Krylov solve that does not converge hands the problem to the direct
 * solver for good. */
static int choose_solver(lg_env *env, lg_problem *p) {
  if (p->iter >= 2) return 0;
  if (ensure_ksp(env, p)) return 1;
  if (p->iter == 0) {
    p->iter = 2;
    if (iterative_allowed(p, 2) && lg_saddle_point(p->A, p->rglob[1])) {
      /* Stokes-like: GMRES with a Schur complement fieldsplit (solver.c) */
      if (saddle_solver(env, p, p->ksp)) return 1;
      p->iter = 4;
      if (env->verbose)
        fprintf(stderr, "[lugal] linear solver: GMRES with a Schur complement fieldsplit (%d unknowns, a saddle point: the "
                        "second unknown's diagonal block is zero; -lugal_iterative 0 or -pc_type lu for the direct solver)\n", p->Nglob);
      return 0;
    }
    if (!iterative_allowed(p, 1)) return 0;
    int kind = lg_matrix_kind(p->A, 1), spd = kind == 1;
    if (kind == 2) {
      if (env->verbose) fprintf(stderr, "[lugal] linear solver: direct (%d unknowns, but the matrix's diagonal is not positive)\n", p->Nglob);
      return 0;
    }
    PCHK(lg_iterative_setup(p->ksp, spd), "the iterative solver's setup");
    if (lg_problem_near_nullspace(env, p, p->ksp)) return 1;
    p->iter = spd ? 1 : 3;
    if (env->verbose)
      fprintf(stderr, "[lugal] linear solver: %s with GAMG (%d unknowns, %s; -lugal_iterative 0 or -pc_type lu for the "
                      "direct solver)\n", spd ? "CG" : "GMRES", p->Nglob,
              spd ? "symmetric, positive diagonal" : "unsymmetric, positive diagonal");
    return 0;
  }
  if (!lg_spd_candidate(p->A)) return iterative_to_direct(env, p, "the reassembled matrix is not symmetric with a positive diagonal");
  return 0;
}

/* column_correction in a parallel run, where an essential column's row may be another
 * rank's: the tangent reads r_b from the whole vector (lg_problem_vec_get), the adjoint adds
 * its corrections to λ_b where b lives (VecSetValues, ADD_VALUES). Collective */
static int column_correction_par(lg_env *env, lg_problem *p, Vec v, int transpose, double D) {
  if (!transpose) {
    double *whole = malloc(sizeof(double) * ((size_t)p->N + 1));
    if (!whole) { lg_seterr(env, "out of memory"); return 1; }
    if (lg_problem_vec_get(env, p, v, whole)) { free(whole); return 1; }
    PetscScalar *a;
    PetscErrorCode ierr = VecGetArray(v, &a);
    if (!ierr) {
      for (size_t e = 0; e < p->bcc_n; e++) a[p->bcc_row[e] - p->lo] -= p->bcc_val[e] * whole[p->bc_rows[p->bcc_col[e]]] / D;
      ierr = VecRestoreArray(v, &a);
    }
    free(whole);
    if (ierr) return lg_petsc_fail(env, ierr, "the column correction");
    return 0;
  }
  PetscInt *rows = malloc(sizeof(PetscInt) * (p->bcc_n + 1));
  PetscScalar *vals = malloc(sizeof(PetscScalar) * (p->bcc_n + 1));
  const PetscScalar *a;
  PetscErrorCode ierr = rows && vals ? VecGetArrayRead(v, &a) : PETSC_ERR_MEM;
  if (!ierr) {
    for (size_t e = 0; e < p->bcc_n; e++) {
      rows[e] = lg_petsc_row(p, p->bc_rows[p->bcc_col[e]]);
      vals[e] = -p->bcc_val[e] * a[p->bcc_row[e] - p->lo] / D;
    }
    ierr = VecRestoreArrayRead(v, &a);
  }
  if (!ierr) ierr = VecSetValues(v, (PetscInt)p->bcc_n, rows, vals, ADD_VALUES);
  /* every rank assembles, with entries or without */
  if (!ierr) ierr = VecAssemblyBegin(v);
  if (!ierr) ierr = VecAssemblyEnd(v);
  free(rows);
  free(vals);
  if (ierr) return lg_petsc_fail(env, ierr, "the column correction");
  return 0;
}

/* the corrections of a solve with a matrix whose essential columns were eliminated for a
 * problem that keeps them (sym_elim without bc_symmetric), from the eliminated entries a_ib
 * (bcc_*), D the essential diagonal: the tangent's right side r_i -= a_ib r_b / D before
 * the solve; the adjoint's (transposed) solution λ_b -= a_ib λ_i / D after it */
static int column_correction(lg_env *env, lg_problem *p, Vec v, int transpose, double D) {
  if (!p->sym_elim || (p->bc_symmetric && !p->nonlinear)) return 0;
  if (p->par) return column_correction_par(env, p, v, transpose, D);
  if (!p->bcc_n) return 0;
  PetscScalar *a;
  PCHK(VecGetArray(v, &a), "VecGetArray");
  for (size_t e = 0; e < p->bcc_n; e++) {
    PetscInt i = p->bcc_row[e] - p->lo, b = lg_petsc_row(p, p->bc_rows[p->bcc_col[e]]) - p->lo;
    if (transpose) a[b] -= p->bcc_val[e] * a[i] / D;
    else a[i] -= p->bcc_val[e] * a[b] / D;
  }
  PCHK(VecRestoreArray(v, &a), "VecRestoreArray");
  return 0;
}

/* the solution's null space part: constants to mean zero, rigid motions projected out */
static int remove_null(lg_env *env, lg_problem *p) {
  if (!p->null) return 0;
  if (p->null_rigid) {
    PCHK(MatNullSpaceRemove(p->null, p->x), "MatNullSpaceRemove");
    return 0;
  }
  if (p->par) { /* the mean over the whole mesh, on the whole vector */
    if (lg_problem_vec_get(env, p, p->x, p->rwhole) || null_project(env, p, p->rwhole, 0)) return 1;
    return lg_problem_vec_set(env, p, p->x, p->rwhole);
  }
  PetscScalar *x;
  PCHK(VecGetArray(p->x, &x), "VecGetArray");
  int rc = null_project(env, p, x, 0);
  PCHK(VecRestoreArray(p->x, &x), "VecRestoreArray");
  return rc;
}

/* one KSPSolve of a linear problem with its checks: 0, 1 with a message, 2 when the
 * default PETSc LU failed and MUMPS should try (lg_lu_fallback), 3 when the default CG did
 * not converge and the direct solver should */
static int linear_solve_checked(lg_env *env, lg_problem *p, lg_solve_info *info) {
  int native = lg_lu_native(p->ksp, p->prefix);
  PetscErrorCode ierr = KSPSolve(p->ksp, p->b, p->x);
  if (ierr) return lg_petsc_fail(env, ierr, "the linear solve");
  if (check_null_pivots(env, p, p->ksp)) return 1;
  KSPConvergedReason reason;
  PCHK(KSPGetConvergedReason(p->ksp, &reason), "KSPGetConvergedReason");
  PetscInt its;
  KSPGetIterationNumber(p->ksp, &its);
  info->iterations = info->linear_iterations = (int)its;
  snprintf(info->reason, sizeof info->reason, "%s", ksp_reason_name(reason));
  if (reason < 0 && native) return 2;
  if (reason < 0 && krylov_default(p->iter)) return 3;
  char why[512];
  lg_solve_failure(p->ksp, why, sizeof why);
  if (reason < 0 && why[0]) {
    lg_seterr(env, "the linear solve failed: %s after %d iterations%s", info->reason, info->iterations, why);
    return 1;
  }
  if (reason < 0) {
    const char *hint = "";
    if (reason == KSP_DIVERGED_PC_FAILED) {
      PC pc;
      PCFailedReason pr = PC_NOERROR;
      KSPGetPC(p->ksp, &pc);
      PCGetFailedReason(pc, &pr);
      if (pr == PC_FACTOR_NUMERIC_ZEROPIVOT || pr == PC_FACTOR_STRUCT_ZEROPIVOT)
        hint = " (zero pivot in the factorization: the system is singular; are boundary conditions missing?)";
    }
    lg_seterr(env, "the linear solve failed: %s after %d iterations%s", info->reason, info->iterations, hint);
    return 1;
  }
  /* a direct solver may return garbage for a singular matrix without failing: check the
   * residual of what it returned */
  KSPType kt;
  KSPGetType(p->ksp, &kt);
  if (kt && !strcmp(kt, KSPPREONLY)) {
    Vec r;
    PetscReal rn, bn;
    PCHK(VecDuplicate(p->b, &r), "VecDuplicate");
    PCHK(MatMult(p->A, p->x, r), "MatMult");
    PCHK(VecAXPY(r, -1.0, p->b), "VecAXPY");
    VecNorm(r, NORM_2, &rn);
    VecNorm(p->b, NORM_2, &bn);
    VecDestroy(&r);
    if (!(rn <= 1e-8 * (bn > 0 ? bn : 1))) {
      if (native) return 2;
      if (why[0])
        lg_seterr(env, "the linear solve failed (its residual is %.2e relative to the right side)%s", bn > 0 ? rn / bn : rn, why);
      else if (p->nnull)
        lg_seterr(env, "the linear solve failed: the right side is not compatible with the null space given (the residual "
                       "is %.2e relative to it): the data must be orthogonal to the null space (for a pure Neumann "
                       "problem, the sources must balance the boundary fluxes)", bn > 0 ? rn / bn : rn);
      else
        lg_seterr(env, "the linear solve failed: the matrix is singular (the direct solver's residual is "
                       "%.2e relative to the right side); are boundary conditions missing?", bn > 0 ? rn / bn : rn);
      return 1;
    }
  }
  return 0;
}

/* symmetric elimination zeroes the essential columns too, moving a_ij g_j to the right
 * side; their entries (rows outside the essential set) are kept so that a solve with the
 * same matrix and new data (an optimization's next evaluation, other essential values)
 * reuses the factorization */
/* the essential condition (its index) of each PETSc row: an array over the whole problem's
 * rows, or on a distributed mesh (whose columns are global) an array over the owned rows
 * and a hash of the other ranks' essential rows */
typedef struct {
  int *at;             /* whole: at[row]; distributed: at[row - lo] for owned rows */
  PetscInt lo, hi;     /* the rows of at */
  PetscInt *key;       /* distributed, other ranks' rows: a hash (-1 empty) */
  int *val, mask;
} bc_index;

static int bc_index_make(lg_problem *p, bc_index *x) {
  memset(x, 0, sizeof *x);
  /* a whole mesh: every row; a distributed one: the owned rows (most columns of the owned
   * rows are owned: a probe of the hash for each was most of the time of the elimination) */
  x->lo = p->lm->dist ? p->lo : 0;
  x->hi = p->lm->dist ? p->hi : p->Nglob;
  if (!(x->at = malloc(sizeof(int) * ((size_t)(x->hi - x->lo) + 1)))) return 1;
  for (PetscInt i = 0; i < x->hi - x->lo; i++) x->at[i] = -1;
  int n = 16, nother = 0;
  for (int k = 0; k < p->nbc; k++) {
    PetscInt r = lg_petsc_row(p, p->bc_rows[k]); /* the matrix's order */
    if (r >= x->lo && r < x->hi) x->at[r - x->lo] = k;
    else nother++;
  }
  if (!p->lm->dist) return 0;
  while (n < 2 * nother + 2) n *= 2;
  x->key = malloc(sizeof(PetscInt) * (size_t)n);
  x->val = malloc(sizeof(int) * (size_t)n);
  if (!x->key || !x->val) { free(x->at); free(x->key); free(x->val); return 1; }
  x->mask = n - 1;
  for (int i = 0; i < n; i++) x->key[i] = -1;
  for (int k = 0; k < p->nbc; k++) {
    PetscInt r = lg_petsc_row(p, p->bc_rows[k]);
    if (r >= x->lo && r < x->hi) continue;
    unsigned h = (unsigned)((uint64_t)r * 0x9e3779b97f4a7c15ull >> 40) & (unsigned)x->mask;
    while (x->key[h] >= 0 && x->key[h] != r) h = (h + 1) & (unsigned)x->mask;
    x->key[h] = r;
    x->val[h] = k;
  }
  return 0;
}

static inline int bc_index_get(const bc_index *x, PetscInt r) {
  if (r >= x->lo && r < x->hi) return x->at[r - x->lo];
  if (!x->key) return -1;
  unsigned h = (unsigned)((uint64_t)r * 0x9e3779b97f4a7c15ull >> 40) & (unsigned)x->mask;
  while (x->key[h] >= 0) {
    if (x->key[h] == r) return x->val[h];
    h = (h + 1) & (unsigned)x->mask;
  }
  return -1;
}

static void bc_index_free(bc_index *x) { free(x->at); free(x->key); free(x->val); }

static int keep_bc_columns(lg_env *env, lg_problem *p) {
  bc_index at;
  if (bc_index_make(p, &at)) { lg_seterr(env, "out of memory"); return 1; }
  size_t n = 0;
  /* the assembled values, before the elimination: the matrix's own array in a serial run,
   * its diagonal and off-diagonal blocks in a parallel one; the owned rows, global columns */
  const PetscScalar *av = p->csr_a;
  const PetscScalar *da = NULL, *oa = NULL;
  if (p->par) {
    Mat Ad, Ao;
    const PetscInt *garray;
    if (MatMPIAIJGetSeqAIJ(p->A, &Ad, &Ao, &garray) || MatSeqAIJGetArrayRead(Ad, &da) || MatSeqAIJGetArrayRead(Ao, &oa)) {
      bc_index_free(&at);
      lg_seterr(env, "the matrix's blocks could not be read");
      return 1;
    }
  }
  for (int pass = 0; pass < 2; pass++) {
    if (pass) {
      free(p->bcc_row); free(p->bcc_col); free(p->bcc_val);
      p->bcc_row = malloc(sizeof(int) * (n + 1));
      p->bcc_col = malloc(sizeof(int) * (n + 1));
      p->bcc_val = malloc(sizeof(double) * (n + 1));
      if (!p->bcc_row || !p->bcc_col || !p->bcc_val) {
        bc_index_free(&at);
        p->bcc_n = 0;
        lg_seterr(env, "out of memory");
        return 1;
      }
      n = 0;
    }
    for (int i = p->lo; i < p->hi; i++) {
      if (bc_index_get(&at, i) >= 0) continue;
      int r = i - p->lo;
      for (PetscInt e = p->csr_i[r]; e < p->csr_i[r + 1]; e++) {
        int k = bc_index_get(&at, p->csr_j[e]);
        if (k < 0) continue;
        double val = da ? *lg_split_entry(p, (PetscScalar *)da, (PetscScalar *)oa, r, e - p->csr_i[r]) : av[e];
        if (val == 0) continue;
        if (pass) { p->bcc_row[n] = i; p->bcc_col[n] = k; p->bcc_val[n] = val; }
        n++;
      }
    }
  }
  p->bcc_n = n;
  bc_index_free(&at);
  if (da) {
    Mat Ad, Ao;
    const PetscInt *garray;
    if (MatMPIAIJGetSeqAIJ(p->A, &Ad, &Ao, &garray) || MatSeqAIJRestoreArrayRead(Ao, &oa) || MatSeqAIJRestoreArrayRead(Ad, &da)) {
      lg_seterr(env, "the matrix's blocks could not be given back");
      return 1;
    }
  }
  return 0;
}

/* A's essential rows replaced by bc_diag identity rows; their columns eliminated too (kept
 * in bcc_*) with symmetric = true or for CG (choose_solver). x, b: the essential values and
 * the right side to adjust, or NULL */
static int eliminate_essential(lg_env *env, lg_problem *p, Vec x, Vec b) {
  if ((p->sym_elim = p->bc_symmetric || p->iter == 1 || ksp_is_cg(p->ksp))) {
    if (keep_bc_columns(env, p)) return 1;
    PCHK(MatZeroRowsColumns(p->A, p->nown, p->own_rows, p->bc_diag, x, b), "MatZeroRowsColumns");
  } else PCHK(MatZeroRows(p->A, p->nown, p->own_rows, p->bc_diag, x, b), "MatZeroRows");
  return 0;
}

/* whether a solve with a matrix other than the factored one may iterate with the old factor
 * (solver.h, lg_keep): linear problems, unless -lugal_keep_factor 0 */
static int keep_usable(lg_env *env, lg_problem *p) {
  return !p->nonlinear && !env->no_keep_factor && !p->no_keep && lg_keep_usable(&p->keep, p->ksp, p->prefix);
}

/* b = -R(0): the right-hand side's owned part (a parallel run assembles the whole-length
 * residual, its own rows complete, and keeps those) */
static int assemble_rhs(lg_env *env, lg_problem *p) {
  PetscScalar *b;
  int n = p->hi - p->lo, rc;
  if (p->par) {
    rc = lg_problem_residual_into(env, p, p->state, p->rwhole);
    if (rc) return 1;
    PCHK(VecGetArray(p->b, &b), "VecGetArray");
    lg_problem_owned_part(p, p->rwhole, -1.0, b);
  } else {
    PCHK(VecGetArray(p->b, &b), "VecGetArray");
    rc = lg_problem_residual_into(env, p, p->state, b);
    for (int i = 0; i < n; i++) b[i] = -b[i];
  }
  PCHK(VecRestoreArray(p->b, &b), "VecRestoreArray");
  return rc;
}

/* The diagonal of a linear problem's essential rows: the mean |a_ii| of its other rows (1
 * where there are none, or the mean is 0 or not finite). A row of 1 beside a diagonal of
 * 1e200 (k = f = 1e200 in a well-posed Poisson problem) was taken by MUMPS for a null pivot
 * and the problem refused as singular. Collective */
static int essential_diagonal(lg_env *env, lg_problem *p, double *D) {
  Vec d;
  PCHK(VecDuplicate(p->x, &d), "VecDuplicate");
  PetscErrorCode ierr = MatGetDiagonal(p->A, d);
  PetscScalar *a = NULL;
  if (!ierr) ierr = VecGetArray(d, &a);
  double s[2] = {0, 0};
  if (!ierr) {
    for (int i = 0; i < p->nown; i++) a[p->own_rows[i] - p->lo] = NAN; /* the essential rows */
    for (PetscInt i = 0; i < p->hi - p->lo; i++)
      if (!isnan(a[i])) { s[0] += fabs(a[i]); s[1]++; }
    VecRestoreArray(d, &a);
  }
  VecDestroy(&d);
  if (ierr) return lg_petsc_fail(env, ierr, "the matrix's diagonal");
  if (p->par && MPI_Allreduce(MPI_IN_PLACE, s, 2, MPI_DOUBLE, MPI_SUM, PetscObjectComm((PetscObject)p->A)) != MPI_SUCCESS) {
    lg_seterr(env, "the sum over the ranks failed");
    return 1;
  }
  *D = s[1] > 0 && s[0] > 0 && isfinite(s[0] / s[1]) ? s[0] / s[1] : 1;
  return 0;
}

/* a vector's owned entries on the essential rows multiplied by s */
static int scale_essential(lg_env *env, lg_problem *p, Vec v, double s) {
  if (s == 1) return 0;
  PetscScalar *a;
  PCHK(VecGetArray(v, &a), "VecGetArray");
  for (int i = 0; i < p->nown; i++) a[p->own_rows[i] - p->lo] *= s;
  PCHK(VecRestoreArray(v, &a), "VecRestoreArray");
  return 0;
}

static int solve_linear(lg_env *env, lg_problem *p, lg_function **out, lg_solve_info *info) {
  double t0 = lg_now_ms();
  memset(p->state, 0, sizeof(double) * (size_t)p->N);
  uint64_t fp = matrix_fingerprint(env, p);
  int reuse = fp && fp == p->matrix_fp && p->ksp;
  p->matrix_fp = 0;
  if (!reuse) {
    p->matrix_ready = 0;
    if (lg_problem_assemble_into(env, p, p->state, p->A) || essential_diagonal(env, p, &p->bc_diag)) return 1;
    if (choose_solver(env, p)) return 1;
  }
  PetscScalar *b;
  int rc = assemble_rhs(env, p);
  if (rc) return 1;
  if (lg_problem_compute_bcs(env, p)) return 1;
  PCHK(VecSet(p->x, 0), "VecSet");
  PCHK(VecSetValues(p->x, p->nown, p->own_rows, p->own_vals, INSERT_VALUES), "VecSetValues");
  PCHK(VecAssemblyBegin(p->x), "VecAssembly");
  PCHK(VecAssemblyEnd(p->x), "VecAssembly");
  if (reuse) { /* the rows are identity rows already: only the right-hand side's, and with
                * symmetric elimination the eliminated columns times the values */
    PCHK(VecGetArray(p->b, &b), "VecGetArray");
    for (size_t i = 0; i < p->bcc_n; i++) b[p->bcc_row[i] - p->lo] -= p->bcc_val[i] * p->bc_vals[p->bcc_col[i]];
    for (int i = 0; i < p->nown; i++) b[p->own_rows[i] - p->lo] = p->bc_diag * p->own_vals[i];
    PCHK(VecRestoreArray(p->b, &b), "VecRestoreArray");
  } else if (eliminate_essential(env, p, p->x, p->b)) return 1;
  info->assemble_ms = lg_now_ms() - t0;
  t0 = lg_now_ms();
  if (ensure_ksp(env, p)) return 1;
  PCHK(KSPSetOperators(p->ksp, p->A, p->A), "KSPSetOperators");
  int refactor = !reuse || p->keep.stale;
  PetscBool kept = PETSC_FALSE;
  if (refactor && keep_usable(env, p)) {
    /* a new matrix close to the factored one (the next control of an optimization) */
    PetscInt its;
    int guess = 0;
    if (p->have_solution) {
      /* the last solution with the essential values, the initial guess */
      if (lg_problem_vec_set(env, p, p->x, p->solution)) return 1;
      PetscScalar *xv;
      PCHK(VecGetArray(p->x, &xv), "VecGetArray");
      for (int i = 0; i < p->nown; i++) xv[p->own_rows[i] - p->lo] = p->own_vals[i];
      PCHK(VecRestoreArray(p->x, &xv), "VecRestoreArray");
      guess = 1;
    }
    PCHK(lg_keep_solve(&p->keep, p->ksp, p->A, p->b, p->x, 0, !reuse, guess, &kept, &its),
         "the solve with the kept factorization");
    if (kept) {
      info->iterations = info->linear_iterations = (int)its;
      snprintf(info->reason, sizeof info->reason, "CONVERGED_RTOL");
      lg_keep_name(&p->keep, info->solver, sizeof info->solver);
      rc = 0;
    } /* else refactored below: the direct solve (preonly) overwrites x */
  }
  if (!kept) {
    if (refactor) PCHK(lg_lu_prepare(p->ksp, p->A, p->own_rows, p->nown, p->prefix, 1), "the factorization's choice");
    lg_mumps_detect_null_pivots(p->ksp);
    while ((rc = linear_solve_checked(env, p, info)) >= 2) {
      if (rc == 3) { /* CG or GMRES did not converge: the direct solver */
        char why[160];
        snprintf(why, sizeof why, "%s stopped with %s after %d iterations", p->iter == 1 ? "CG" : "GMRES", info->reason, info->iterations);
        if (iterative_to_direct(env, p, why)) return 1;
        PCHK(lg_lu_prepare(p->ksp, p->A, p->own_rows, p->nown, p->prefix, 1), "the factorization's choice");
        lg_mumps_detect_null_pivots(p->ksp);
        continue;
      }
      /* PETSc's LU (no pivoting) found a zero pivot or solved inaccurately: MUMPS, once */
      PCHK(lg_lu_fallback(p->ksp, p->A), "the switch to MUMPS");
    }
    if (refactor && !rc) lg_keep_factored(&p->keep, p->ksp);
    lg_solver_name(p->ksp, info->solver, sizeof info->solver);
  }
  info->solve_ms = lg_now_ms() - t0;
  if (rc) return 1;
  if (remove_null(env, p)) return 1;
  if (lg_problem_vec_get(env, p, p->x, p->solution)) return 1;
  for (int i = 0; i < p->N; i++)
    if (!isfinite(p->solution[i])) {
      lg_seterr(env, "the linear solve produced non-finite values (the system is singular or the data is not finite)");
      return 1;
    }
  p->have_solution = 1;
  p->solved_geometry = p->lm->geometry;
  p->matrix_fp = fp;
  return out ? make_outputs(env, p, p->solution, out) : 0;
}

static PetscErrorCode snes_function(SNES snes, Vec X, Vec F, void *ctx) {
  lg_problem *p = ctx;
  (void)snes;
  PetscScalar *f;
  if (lg_problem_vec_get(p->env, p, X, p->state)) {
    p->failed = 1;
    PetscCall(SNESSetFunctionDomainError(snes));
    return 0;
  }
  PetscCall(VecGetArray(F, &f));
  int rc = lg_problem_residual_into(p->env, p, p->state, p->par ? p->rwhole : f);
  if (!rc && p->par) lg_problem_owned_part(p, p->rwhole, 1.0, f);
  if (!rc)
    for (int i = 0; i < p->nown; i++) f[p->own_rows[i] - p->lo] = p->state[lg_problem_row(p, p->own_rows[i])] - p->own_vals[i];
  PetscCall(VecRestoreArray(F, &f));
  if (rc) {
    p->failed = 1;
    PetscCall(SNESSetFunctionDomainError(snes));
  }
  return 0;
}

/* Newton's linear solver for the Jacobian just assembled into A, and A's essential rows
 * replaced by identity rows. By default (iterative_allowed, SNES newtonls) each Jacobian is
 * looked at as choose_solver looks at a linear problem's matrix: CG with GAMG where it is
 * symmetric with a positive diagonal (a hyperelastic energy's second derivative), GMRES with
 * GAMG where only its diagonal is positive (a convection term's Jacobian is unsymmetric once
 * u is not zero), the direct solver for good otherwise. For CG the essential columns are
 * eliminated too, which changes no Newton step: the initial guess satisfies the essential
 * conditions (solve_nonlinear), so F_b = 0 and every step's essential part δ_b = −F_b = 0,
 * and J_ib δ_b vanishes; the adjoint and tangent solves correct for the columns (kept in
 * bcc_*, column_correction), as a linear problem's do. */
static int newton_matrix(lg_env *env, lg_problem *p, KSP ksp) {
  if (p->newton_iter == 0) {
    PetscBool newton = PETSC_FALSE;
    PetscObjectTypeCompare((PetscObject)p->snes, SNESNEWTONLS, &newton);
    p->newton_iter = newton && iterative_allowed(p, 1) ? -1 : 2; /* -1: iterative, not set up yet */
    if (newton && iterative_allowed(p, 2) && lg_saddle_point(p->A, p->rglob[1])) {
      /* Navier–Stokes: the Schur complement fieldsplit of a linear saddle point, for good */
      if (saddle_solver(env, p, ksp)) return 1;
      p->newton_iter = 4;
      if (env->verbose)
        fprintf(stderr, "[lugal] Newton's linear solver: GMRES with a Schur complement fieldsplit (%d unknowns, a saddle point; "
                        "-lugal_iterative 0 or -pc_type lu for the direct solver)\n", p->Nglob);
    }
  }
  if (p->newton_iter != 2 && p->newton_iter != 4) {
    int mode = lg_matrix_kind(p->A, !p->newton_nocg), spd = mode == 1;
    if (mode == 2 && p->newton_iter < 0) {
      p->newton_iter = 2;
      if (env->verbose)
        fprintf(stderr, "[lugal] Newton's linear solver: direct (%d unknowns, but the Jacobian's diagonal is not positive)\n", p->Nglob);
    } else if (mode == 2) {
      if (iterative_to_direct(env, p, "a Jacobian's diagonal is not positive")) return 1;
    } else if (mode != p->newton_iter) {
      PCHK(lg_iterative_setup(ksp, spd), "the iterative solver's setup");
      if (lg_problem_near_nullspace(env, p, ksp)) return 1; /* the rigid body modes of a vector field */
      if (env->verbose && p->newton_iter < 0)
        fprintf(stderr, "[lugal] Newton's linear solver: %s with GAMG (%d unknowns, %s; -lugal_iterative 0 or -pc_type lu for "
                        "the direct solver)\n", spd ? "CG" : "GMRES", p->Nglob, spd ? "symmetric Jacobian, positive diagonal" : "unsymmetric Jacobian, positive diagonal");
      else if (env->verbose) fprintf(stderr, "[lugal] Newton's linear solver: %s from this Jacobian on\n", spd ? "CG" : "GMRES");
      p->newton_iter = mode;
    }
  }
  if ((p->sym_elim = p->newton_iter == 1 || ksp_is_cg(ksp))) {
    if (keep_bc_columns(env, p)) return 1;
    PCHK(MatZeroRowsColumns(p->A, p->nown, p->own_rows, 1.0, NULL, NULL), "MatZeroRowsColumns");
  } else PCHK(MatZeroRows(p->A, p->nown, p->own_rows, 1.0, NULL, NULL), "MatZeroRows");
  return 0;
}

/* the residual reduction of a step with a kept Jacobian that keeps it for the next step */
#define LAG_CONTRACTION 0.1

static PetscErrorCode snes_jacobian(SNES snes, Vec X, Mat J, Mat P, void *ctx) {
  lg_problem *p = ctx;
  (void)J;
  if (lg_problem_vec_get(p->env, p, X, p->state)) {
    p->failed = 1;
    PetscCall(SNESSetJacobianDomainError(snes));
    return 0;
  }
  /* a warm start at the last solution, whose Jacobian the adjoint assembled and factored:
   * leave the matrix alone, so that the solver's factorization is reused, unless what else
   * the Jacobian reads changed (a control in the stiffness, as the SIMP density: the step
   * would be taken with the last control's Jacobian) */
  PetscInt k = 0;
  PetscReal fn = 0;
  PetscCall(SNESGetIterationNumber(snes, &k));
  PetscCall(SNESGetFunctionNorm(snes, &fn));
  int keep = 0;
  if (k == 0) {
    uint64_t fp = p->have_solution && !p->adj_stale && P == p->A ? matrix_fingerprint(p->env, p) : 0;
    keep = fp && p->adj_fp == fp && !memcmp(p->state, p->solution, sizeof(double) * (size_t)p->N);
    if (p->lm->dist) { /* every rank assembles, or none (the assembly is collective) */
      int all = keep;
      MPI_Allreduce(&keep, &all, 1, MPI_INT, MPI_MIN, PETSC_COMM_WORLD);
      keep = all;
    }
  } else
    /* a resolve near the last solution: the last Jacobian stays (its factorization too) for
     * as long as a step with it cut |F| tenfold (chord steps, each a residual and a
     * triangular solve instead of a factorization); a poorer step refreshes it */
    keep = p->chord && p->lag_valid && P == p->A && fn <= LAG_CONTRACTION * p->lag_fnorm;
  p->lag_fnorm = fn;
  if (keep) {
    p->lag_valid = 1;
    return 0;
  }
  p->adj_stale = 1; /* A no longer holds the Jacobian at the solution */
  p->lag_valid = 1;
  if (lg_problem_assemble_into(p->env, p, p->state, P)) {
    p->failed = 1;
    PetscCall(SNESSetJacobianDomainError(snes));
    return 0;
  }
  KSP ksp;
  PetscCall(SNESGetKSP(snes, &ksp));
  if (newton_matrix(p->env, p, ksp)) {
    p->failed = 1;
    PetscCall(SNESSetJacobianDomainError(snes));
    return 0;
  }
  PetscCall(lg_lu_prepare(ksp, P, p->own_rows, p->nown, p->prefix, 0));
  /* with a null space given, MUMPS's null pivot detection, as for a linear problem: without
   * it the pressure constant's pivot of an enclosed flow's Jacobian (rounding, about 1e-16)
   * was divided by, and the step was that constant times 1e16 and what its removal's
   * cancellation left. Where the rounding fell (MUMPS's dynamic scheduling on several
   * ranks) a step now and then came out wrong: the 2-rank lid-driven cavity took 5–11
   * Newton iterations instead of 2–3 in 2 runs of 45 under load */
  if (p->nnull) lg_mumps_detect_null_pivots(ksp);
  return 0;
}

/* what to try when Newton stops without converging (": ...", appended to the message) */
static void newton_advice(SNESConvergedReason reason, KSP ksp, char *out, size_t len) {
  switch (reason) {
  case SNES_DIVERGED_LINEAR_SOLVE:
    lg_solve_failure(ksp, out, len);
    if (!out[0]) snprintf(out, len, ": a linear solve with the Jacobian failed (singular there? the initial guess may sit on a "
                                    "degenerate point: try another initial=)");
    break;
  case SNES_DIVERGED_FNORM_NAN:
    snprintf(out, len, ": the residual or its norm became NaN or infinite (a step left the domain of the equation, e.g. a "
                       "square root or log of a negative value; or the residual's entries pass 1e154, whose squares "
                       "overflow: divide the equation by its scale): try a damped search (-snes_linesearch_type bt), a "
                       "better initial guess (initial=), or continuation in a parameter");
    break;
  case SNES_DIVERGED_FUNCTION_DOMAIN:
    snprintf(out, len, ": a step left the domain of the equation: try -snes_linesearch_type bt or a better initial guess");
    break;
  case SNES_DIVERGED_MAX_IT:
    snprintf(out, len, ": try a better initial guess (initial=), continuation in a parameter (solve for easier values "
                       "first, each solution the next guess), a damped search (-snes_linesearch_type bt), or more "
                       "iterations (-snes_max_it)");
    break;
  case SNES_DIVERGED_LINE_SEARCH:
    snprintf(out, len, ": the line search found no decrease: try -snes_linesearch_type basic (full steps) or l2, or a "
                       "better initial guess");
    break;
  case SNES_DIVERGED_DTOL:
    snprintf(out, len, ": the residual grew past -snes_divergence_tolerance times its first value: try a damped search "
                       "(-snes_linesearch_type bt), or no divergence test (-snes_divergence_tolerance -1, the default)");
    break;
  default: break;
  }
}

static int solve_nonlinear(lg_env *env, lg_problem *p, lg_function **initial, lg_function **out,
                           lg_solve_info *info, int warm) {
  double t0 = lg_now_ms();
  if (lg_problem_compute_bcs(env, p)) return 1;
  double *x = p->state; /* the whole initial guess, then its owned part into p->x */
  for (int i = 0; i < p->N; i++) x[i] = warm && p->have_solution ? p->solution[i] : 0;
  for (int a = 0; a < p->cols.n; a++) {
    lg_function *g = initial ? initial[a] : NULL;
    if (!g) continue;
    if (g->dm != p->cdm[a]) {
      lg_seterr(env, "the initial guess for unknown %d must be a discrete function of the unknown's space (degree %d, %d "
                     "component%s) on the problem's mesh", a + 1, p->cols.degree[a], p->cdm[a]->bs, p->cdm[a]->bs == 1 ? "" : "s");
      return 1;
    }
    expr_func_info *fi = expr_func_get(env->c, p->cols.func[a]);
    char what[96];
    snprintf(what, sizeof what, "the initial guess for %.60s", fi ? fi->name : "the unknown");
    if (lg_check_finite(env, p->cdm[a], g->x, what)) return 1;
    memcpy(x + p->cglob[a], g->x, sizeof(double) * (size_t)p->cdm[a]->ndof);
  }
  for (int i = 0; i < p->nbc; i++) x[p->bc_rows[i]] = p->bc_vals[i];
  if (lg_problem_vec_set(env, p, p->x, x)) return 1;
  if (!p->snes) {
    PCHK(SNESCreate(PetscObjectComm((PetscObject)p->A), &p->snes), "SNESCreate");
    if (p->prefix[0]) PCHK(SNESSetOptionsPrefix(p->snes, p->prefix), "SNESSetOptionsPrefix");
    PCHK(SNESSetFunction(p->snes, p->b, snes_function, p), "SNESSetFunction");
    PCHK(SNESSetJacobian(p->snes, p->A, p->A, snes_jacobian, p), "SNESSetJacobian");
    KSP ksp;
    PC pc;
    PCHK(SNESGetKSP(p->snes, &ksp), "SNESGetKSP");
    PCHK(KSPSetType(ksp, KSPPREONLY), "KSPSetType");
    PCHK(KSPGetPC(ksp, &pc), "KSPGetPC");
    if (default_lu(env, p, pc)) return 1;
    /* full Newton steps by default, as FEniCS and FEniCSx take (-snes_linesearch_type bt
     * restores PETSc's backtracking): on a Neo-Hookean beam the backtracking search cut
     * every step to a tenth after the first full step raised |F| (47 iterations instead of 3) */
    SNESLineSearch ls;
    PCHK(SNESGetLineSearch(p->snes, &ls), "SNESGetLineSearch");
    PCHK(SNESLineSearchSetType(ls, SNESLINESEARCHBASIC), "SNESLineSearchSetType");
    /* no divergence test by default, as DOLFIN's Newton has none: PETSc's stops when |F|
     * passes 1e4 |F0|, and the p-Laplacian from zero stopped with DIVERGED_DTOL after one
     * step where it converges in 14 (-snes_divergence_tolerance restores it) */
    PCHK(SNESSetDivergenceTolerance(p->snes, -1), "SNESSetDivergenceTolerance");
    PCHK(SNESSetFromOptions(p->snes), "SNESSetFromOptions");
    if (field_splits(env, p, pc)) return 1; /* the user's -pc_type fieldsplit */
    if (lg_problem_near_nullspace(env, p, ksp)) return 1;
  }
  static PetscReal hist[128];
  static PetscInt hits[128];
  PCHK(SNESSetConvergenceHistory(p->snes, hist, hits, 128, PETSC_TRUE), "SNESSetConvergenceHistory");
  p->failed = 0;
  p->chord = warm && p->have_solution;
  p->lag_valid = 0;
  info->setup_ms = lg_now_ms() - t0;
  t0 = lg_now_ms();
  PetscErrorCode ierr = SNESSolve(p->snes, NULL, p->x);
  p->chord = 0;
  info->solve_ms = lg_now_ms() - t0;
  if (p->failed) {
    /* a callback failed: at the initial guess that is the data's fault; later, Newton diverged */
    PetscInt its = 0;
    SNESGetIterationNumber(p->snes, &its);
    char why[LG_ERRLEN];
    snprintf(why, sizeof why, "%s", env->err);
    if (its == 0) lg_seterr(env, "at the initial guess: %s", why);
    else lg_seterr(env, "the nonlinear solve did not converge: after %d Newton iterations %s", (int)its, why);
    return 1;
  }
  if (ierr) return lg_petsc_fail(env, ierr, "the nonlinear solve");
  SNESConvergedReason reason;
  PetscInt its, lits, nh;
  SNESGetConvergedReason(p->snes, &reason);
  SNESGetIterationNumber(p->snes, &its);
  SNESGetLinearSolveIterations(p->snes, &lits);
  PetscReal *h;
  PetscInt *hi;
  SNESGetConvergenceHistory(p->snes, &h, &hi, &nh);
  info->iterations = (int)its;
  info->linear_iterations = (int)lits;
  info->nres = (int)(nh < 128 ? nh : 128);
  for (int i = 0; i < info->nres; i++) info->res[i] = h[i];
  snprintf(info->reason, sizeof info->reason, "%s", SNESConvergedReasons[reason]);
  KSP sksp;
  PCHK(SNESGetKSP(p->snes, &sksp), "SNESGetKSP");
  lg_solver_name(sksp, info->solver, sizeof info->solver);
  if (reason == SNES_DIVERGED_LINEAR_SOLVE && krylov_default(p->newton_iter)) {
    /* CG did not converge on a Jacobian (an iterate where the energy is not convex: CG
     * stops on the indefinite matrix): GMRES from now on; GMRES did not: the direct solver.
     * And Newton again */
    char why[160];
    KSPConvergedReason kr = KSP_CONVERGED_ITERATING;
    KSPGetConvergedReason(sksp, &kr);
    snprintf(why, sizeof why, "%s stopped with %s in Newton iteration %d", p->newton_iter == 1 ? "CG" : "GMRES", ksp_reason_name(kr), (int)its);
    if (p->newton_iter == 1 && !p->newton_nocg) {
      p->newton_nocg = 1;
      if (env->verbose) fprintf(stderr, "[lugal] Newton's linear solver: GMRES with GAMG from now on (%s)\n", why);
    } else if (iterative_to_direct(env, p, why)) return 1;
    p->adj_stale = 1;
    return solve_nonlinear(env, p, initial, out, info, warm);
  }
  if (reason < 0 && lg_lu_native(sksp, p->prefix)) {
    /* PETSc's LU (no pivoting) may be what failed: again with MUMPS, once */
    PCHK(lg_lu_fallback(sksp, p->A), "the switch to MUMPS");
    p->adj_stale = 1;
    return solve_nonlinear(env, p, initial, out, info, warm);
  }
  if (reason < 0) {
    char why[600] = "";
    newton_advice(reason, sksp, why, sizeof why);
    lg_seterr(env, "the nonlinear solve did not converge: %s after %d Newton iterations (residual %.3e)%s", info->reason,
              info->iterations, info->nres ? info->res[info->nres - 1] : NAN, why);
    return 1;
  }
  /* a constant null space: the solution with ∫p = 0, as a linear problem's (Newton's steps
   * leave the constant where the first guess and the null pivots put it: the lid-driven
   * cavity's pressure had a mean of −1.1e-3). Not the rigid modes: a nonlinear residual is
   * not invariant under their linear projection */
  if (!p->null_rigid && remove_null(env, p)) return 1;
  if (lg_problem_vec_get(env, p, p->x, p->solution)) return 1;
  p->have_solution = 1;
  p->solved_geometry = p->lm->geometry;
  p->adj_stale = 1;
  return out ? make_outputs(env, p, p->solution, out) : 0;
}

int lg_problem_solve(lg_env *env, lg_problem *p, lg_function **initial, lg_function **out,
                     lg_solve_info *info) {
  memset(info, 0, sizeof *info);
  if (lg_mesh_check(env, p->lm) || lg_problem_follow_geometry(env, p)) return 1;
  return p->nonlinear ? solve_nonlinear(env, p, initial, out, info, 0) : solve_linear(env, p, out, info);
}

int lg_problem_resolve(lg_env *env, lg_problem *p, lg_solve_info *info) {
  memset(info, 0, sizeof *info);
  if (lg_mesh_check(env, p->lm) || lg_problem_follow_geometry(env, p)) return 1;
  return p->nonlinear ? solve_nonlinear(env, p, NULL, NULL, info, 1) : solve_linear(env, p, NULL, info);
}


/* the transposed Jacobian solve of the adjoint: (dR/du)^T lam = rhs at the last solution,
 * where R is the discrete residual with the essential rows u_i - g_i. A linear problem
 * reuses its factorization (KSPSolveTranspose); a nonlinear one assembles its Jacobian at
 * the solution and factors it once per solution. */
/* a solver of dR/du at the last solution: a linear problem's own (its factorization), a
 * nonlinear problem's Jacobian assembled at the solution and factored once per solution */
static int jacobian_solver(lg_env *env, lg_problem *p, KSP *out) {
  if (!p->have_solution) { lg_seterr(env, "the adjoint or sensitivity needs a solved state: solve the problem first"); return 1; }
  if (p->solved_geometry != p->lm->geometry) {
    lg_seterr(env, "the mesh has moved since the problem's last solve, whose state and Jacobian are the old mesh's: solve "
                   "it again first");
    return 1;
  }
  KSP ksp = p->ksp;
  if (p->nonlinear) {
    /* the SNES's own solver, so that the next Newton solve, warm-started at this solution,
     * finds the matrix and its factorization unchanged (snes_jacobian): one factorization
     * less per evaluation of an optimization (three were two Newton steps and this one) */
    if (!p->snes) { lg_seterr(env, "the adjoint needs a solved state: solve the problem first"); return 1; }
    PCHK(SNESGetKSP(p->snes, &ksp), "SNESGetKSP");
    if (p->adj_stale) {
      memcpy(p->state, p->solution, sizeof(double) * (size_t)p->N);
      if (lg_problem_assemble_into(env, p, p->state, p->A) || newton_matrix(env, p, ksp)) return 1;
      PCHK(KSPSetOperators(ksp, p->A, p->A), "KSPSetOperators");
      PCHK(lg_lu_prepare(ksp, p->A, p->own_rows, p->nown, p->prefix, 0), "the factorization's choice");
      if (p->nnull) lg_mumps_detect_null_pivots(ksp); /* as snes_jacobian's */
      p->adj_stale = 0;
      p->adj_fp = matrix_fingerprint(env, p);
    }
  }
  if (!ksp || (!p->nonlinear && !p->matrix_fp && !p->bc_symmetric)) {
    /* a linear problem's matrix was reassembled since its solve (problem:assemble) */
    lg_seterr(env, "the problem's matrix changed since its last solve: solve it again first");
    return 1;
  }
  *out = ksp;
  return 0;
}

/* The transposed solve by a solve: with A's essential rows identity rows (D on the diagonal)
 * and the rest symmetric, A = [D 0; A_ib A_ii], Aᵀλ = r is A_ii λ_i = r_i, a solve of A with
 * the essential entries of r zeroed (which gives λ_b = 0), then λ_b = (r_b − A_ibᵀ λ_i)/D, a
 * product with Aᵀ. PETSc's transposed triangular solves took twice its forward ones (the
 * 128² mother problem's gradient, 1.09-1.26× a warm state solve). */
static PetscErrorCode solve_as_transpose(lg_problem *p, KSP ksp, Vec r, Vec l, double D) {
  Vec z, t;
  PetscScalar *a;
  const PetscScalar *rv, *tv;
  PetscFunctionBeginUser;
  PetscCall(VecDuplicate(r, &z));
  PetscCall(VecCopy(r, z));
  PetscCall(VecGetArray(z, &a));
  for (int i = 0; i < p->nown; i++) a[p->own_rows[i] - p->lo] = 0;
  PetscCall(VecRestoreArray(z, &a));
  PetscErrorCode ierr = KSPSolve(ksp, z, l);
  KSPConvergedReason reason = KSP_CONVERGED_ITS;
  if (!ierr) ierr = KSPGetConvergedReason(ksp, &reason);
  if (!ierr && reason >= 0) {
    t = z;
    ierr = MatMultTranspose(p->A, l, t);
    if (!ierr) ierr = VecGetArray(l, &a);
    if (!ierr) ierr = VecGetArrayRead(r, &rv);
    if (!ierr) ierr = VecGetArrayRead(t, &tv);
    if (!ierr) {
      for (int i = 0; i < p->nown; i++) {
        PetscInt b = p->own_rows[i] - p->lo;
        a[b] = (rv[b] - (tv[b] - D * a[b])) / D; /* tv_b holds D λ_b (λ_b = 0 up to rounding) too */
      }
      VecRestoreArrayRead(t, &tv);
      VecRestoreArrayRead(r, &rv);
      VecRestoreArray(l, &a);
    }
  }
  VecDestroy(&z);
  PetscCall(ierr);
  PetscFunctionReturn(0);
}

/* The transposed solve of a saddle point under lugal's fieldsplit, whose Schur complement
 * PETSc cannot apply transposed (the Navier–Stokes adjoint ran 300 GMRES iterations, then
 * fell back to MUMPS for good): GMRES with the same fieldsplit on Aᵀ, made explicit once per
 * assembly of A. *used: the KSP that solved, for its reason */
static int saddle_transpose_solve(lg_env *env, lg_problem *p, Vec r, Vec l, KSP *used) {
  if (!p->kspT) {
    PCHK(KSPCreate(PetscObjectComm((PetscObject)p->A), &p->kspT), "KSPCreate");
    if (p->prefix[0]) PCHK(KSPSetOptionsPrefix(p->kspT, p->prefix), "KSPSetOptionsPrefix");
    if (saddle_solver(env, p, p->kspT)) return 1;
  }
  if (!p->At || p->At_version != p->a_version) {
    PCHK(MatTranspose(p->A, p->At ? MAT_REUSE_MATRIX : MAT_INITIAL_MATRIX, &p->At), "MatTranspose");
    PCHK(KSPSetOperators(p->kspT, p->At, p->At), "KSPSetOperators");
    p->At_version = p->a_version;
  }
  *used = p->kspT;
  PCHK(KSPSolve(p->kspT, r, l), "the transposed saddle point solve");
  return 0;
}

/* A symmetric apart from its essential rows (checked once per assembly; serial runs) */
static int symmetric_besides_bcs(lg_problem *p) {
  if (p->par) return 0;
  if (p->isym_version != p->a_version || !p->isym_version) {
    p->isym = lg_symmetric_besides(p->A, p->own_rows, p->nown);
    p->isym_version = p->a_version;
  }
  return p->isym;
}

static int solve_with_jacobian(lg_env *env, lg_problem *p, const double *rhs, double *sol, int transpose) {
  KSP ksp;
  if (jacobian_solver(env, p, &ksp)) return 1;
  double *lam = sol;
  Vec r, l;
  PCHK(VecDuplicate(p->b, &r), "VecDuplicate");
  PCHK(VecDuplicate(p->b, &l), "VecDuplicate");
  /* a null space: the state is projected (remove_null), so the adjoint's right side is
   * projected with its transpose, the tangent's solution with it */
  double *proj = NULL;
  if (transpose && p->null && !p->null_rigid) {
    if (!(proj = malloc(sizeof(double) * ((size_t)p->N + 1)))) { lg_seterr(env, "out of memory"); VecDestroy(&r); VecDestroy(&l); return 1; }
    memcpy(proj, rhs, sizeof(double) * (size_t)p->N);
    if (null_project(env, p, proj, 1)) { free(proj); VecDestroy(&r); VecDestroy(&l); return 1; }
    rhs = proj;
  }
  int setf = lg_problem_vec_set(env, p, r, rhs);
  free(proj);
  if (!setf && transpose && p->null_rigid) {
    PetscErrorCode e = MatNullSpaceRemove(p->null, r);
    if (e) setf = lg_petsc_fail(env, e, "the adjoint's right side projected off the rigid modes");
  }
  if (setf) { VecDestroy(&r); VecDestroy(&l); return 1; }
  /* a linear problem's essential rows are bc_diag (u_r - g_r): a sensitivity's right side
   * there scales with them, an adjoint's values there are bc_diag times those of the
   * transposed solve (the rows are scaled: A_D = S A, A_D^T λ' = r gives λ = S λ') */
  double D = p->nonlinear ? 1 : p->bc_diag;
  if (!transpose && (scale_essential(env, p, r, D) || column_correction(env, p, r, 0, D))) {
    VecDestroy(&r);
    VecDestroy(&l);
    return 1;
  }
  PetscErrorCode ierr = 0;
  KSPConvergedReason reason = KSP_CONVERGED_ITS;
  PetscBool kept = PETSC_FALSE;
  /* a linear problem whose state was solved with a kept factorization: the same, or a
   * factorization of the state's matrix when the kept one has cost enough */
  int stale = !p->nonlinear && p->keep.stale;
  if (stale && keep_usable(env, p)) {
    PetscInt its;
    int guess = lg_keep_guess(&p->keep, transpose, l);
    ierr = lg_keep_solve(&p->keep, ksp, p->A, r, l, transpose, 0, guess, &kept, &its);
  }
  while (!ierr && !kept) {
    /* CG's matrix is symmetric (choose_solver): the transposed solve is the solve; a matrix
     * symmetric apart from its essential rows: a solve and a product */
    int cg = ksp_is_cg(ksp), mode = default_mode(p);
    KSP used = ksp;
    if (transpose && !cg && symmetric_besides_bcs(p)) ierr = solve_as_transpose(p, ksp, r, l, D);
    else if (transpose && mode == 4) ierr = saddle_transpose_solve(env, p, r, l, &used) ? PETSC_ERR_LIB : 0;
    else ierr = transpose && !cg ? KSPSolveTranspose(ksp, r, l) : KSPSolve(ksp, r, l);
    reason = KSP_CONVERGED_ITS;
    if (!ierr) KSPGetConvergedReason(used, &reason);
    /* CG or GMRES did not converge (or GAMG has no transposed application): the direct solver */
    if ((ierr || reason < 0) && krylov_default(mode)) {
      if (iterative_to_direct(env, p, ierr ? "the iterative solver failed in an adjoint or tangent solve"
                                            : "the iterative solver did not converge in an adjoint or tangent solve")) {
        VecDestroy(&r);
        VecDestroy(&l);
        return 1;
      }
      ierr = lg_lu_prepare(ksp, p->A, p->own_rows, p->nown, p->prefix, 1);
      continue;
    }
    if (ierr || reason >= 0 || !lg_lu_native(ksp, p->prefix)) break;
    /* PETSc's LU (no pivoting) failed: MUMPS, once */
    if ((ierr = lg_lu_fallback(ksp, p->A))) break;
  }
  if (!ierr && reason >= 0 && transpose && column_correction(env, p, l, 1, D)) ierr = PETSC_ERR_LIB;
  if (!ierr && !kept && stale) lg_keep_factored(&p->keep, ksp);
  /* the next solve's initial guess, where a factor may be kept */
  if (!ierr && !p->nonlinear && !env->no_keep_factor && !p->no_keep && lg_keep_applies(ksp, p->prefix))
    ierr = lg_keep_remember(&p->keep, transpose, l);
  if (!ierr && reason >= 0 && transpose && scale_essential(env, p, l, D)) ierr = PETSC_ERR_LIB;
  if (!ierr && reason >= 0 && !transpose && p->null_rigid) ierr = MatNullSpaceRemove(p->null, l);
  if (!ierr && reason >= 0 && lg_problem_vec_get(env, p, l, lam)) ierr = PETSC_ERR_LIB;
  if (!ierr && reason >= 0 && !transpose && p->null && !p->null_rigid && null_project(env, p, lam, 0)) ierr = PETSC_ERR_LIB;
  VecDestroy(&r);
  VecDestroy(&l);
  const char *what = transpose ? "the adjoint solve" : "the sensitivity solve";
  if (ierr) return lg_petsc_fail(env, ierr, what);
  if (reason < 0) {
    char why[512];
    lg_solve_failure(ksp, why, sizeof why);
    lg_seterr(env, "%s failed: %s%s", what, ksp_reason_name(reason), why);
    return 1;
  }
  for (int i = 0; i < p->N; i++)
    if (!isfinite(lam[i])) { lg_seterr(env, "%s produced non-finite values", what); return 1; }
  return 0;
}

void lg_problem_replayable(lg_problem *p) { p->no_keep = 1; }

int lg_problem_restore(lg_env *env, lg_problem *p, const double *u) {
  if (lg_mesh_check(env, p->lm) || lg_problem_follow_geometry(env, p)) return 1;
  if (p->nonlinear) {
    if (!p->snes) { lg_seterr(env, "a nonlinear problem is restored after its first solve"); return 1; }
    p->adj_stale = 1; /* the Jacobian at u, made by the next adjoint or tangent solve */
  } else {
    /* the matrix at the current coefficients, as a solve would make it (solve_linear): kept
     * while its fingerprint holds (a step whose matrix does not change in time: no
     * assembly and no factorization per step) */
    memset(p->state, 0, sizeof(double) * (size_t)p->N);
    uint64_t fp = matrix_fingerprint(env, p);
    if (!(fp && fp == p->matrix_fp && p->ksp)) {
      p->matrix_fp = 0;
      p->matrix_ready = 0;
      if (lg_problem_assemble_into(env, p, p->state, p->A) || essential_diagonal(env, p, &p->bc_diag)) return 1;
      if (lg_problem_compute_bcs(env, p)) return 1;
      if (choose_solver(env, p)) return 1;
      if (eliminate_essential(env, p, NULL, NULL)) return 1;
      if (ensure_ksp(env, p)) return 1;
      PCHK(KSPSetOperators(p->ksp, p->A, p->A), "KSPSetOperators");
      PCHK(lg_lu_prepare(p->ksp, p->A, p->own_rows, p->nown, p->prefix, 1), "the factorization's choice");
      p->keep.stale = 1; /* the PC's factor is an earlier matrix's: the next solve refactors */
      p->matrix_fp = fp;
    } else if (lg_problem_compute_bcs(env, p)) return 1;
  }
  memcpy(p->solution, u, sizeof(double) * (size_t)p->N);
  p->have_solution = 1;
  p->solved_geometry = p->lm->geometry;
  return 0;
}

int lg_problem_adjoint(lg_env *env, lg_problem *p, const double *rhs, double *lam) {
  return solve_with_jacobian(env, p, rhs, lam, 1);
}

int lg_problem_tangent(lg_env *env, lg_problem *p, const double *rhs, double *du) {
  return solve_with_jacobian(env, p, rhs, du, 0);
}

static int prepare_matrix(lg_env *env, lg_problem *p) {
  /* ready for the data it was made from: a parameter it reads, a discrete function or the
   * mesh's geometry changed since makes it again (a Riesz map's mass matrix on a moved mesh) */
  uint64_t fp = p->matrix_ready ? matrix_fingerprint(env, p) : 0;
  if (!fp || fp != p->ready_fp) p->matrix_ready = 0;
  if (!p->matrix_ready) {
    if (lg_mesh_check(env, p->lm) || lg_problem_follow_geometry(env, p)) return 1;
    memset(p->state, 0, sizeof(double) * (size_t)p->N);
    p->matrix_fp = 0; /* A no longer holds the last solve's matrix */
    p->keep.stale = 0; /* its next solve refactors it */
    if (lg_problem_assemble_into(env, p, p->state, p->A)) return 1;
    if (lg_problem_compute_bcs(env, p)) return 1;
    PCHK(MatZeroRows(p->A, p->nown, p->own_rows, 1.0, NULL, NULL), "MatZeroRows");
    p->sym_elim = 0;
    if (ensure_ksp(env, p)) return 1;
    PCHK(KSPSetOperators(p->ksp, p->A, p->A), "KSPSetOperators");
    PCHK(lg_lu_prepare(p->ksp, p->A, p->own_rows, p->nown, p->prefix, !p->nonlinear), "the factorization's choice");
    p->matrix_ready = 1;
    p->ready_fp = matrix_fingerprint(env, p);
    p->adj_stale = 1; /* a nonlinear problem's A no longer holds its Jacobian */
  }
  return 0;
}


int lg_problem_matrix_mult(lg_env *env, lg_problem *p, const double *x, double *y) {
  if (prepare_matrix(env, p)) return 1;
  if (lg_problem_vec_set(env, p, p->b, x)) return 1;
  PCHK(MatMult(p->A, p->b, p->x), "MatMult");
  return lg_problem_vec_get(env, p, p->x, y);
}

int lg_problem_matrix_diagonal(lg_env *env, lg_problem *p, double *diag, double *rowsum) {
  if (prepare_matrix(env, p)) return 1;
  PCHK(MatGetDiagonal(p->A, p->x), "MatGetDiagonal");
  if (lg_problem_vec_get(env, p, p->x, diag)) return 1;
  PCHK(MatGetRowSum(p->A, p->x), "MatGetRowSum");
  return lg_problem_vec_get(env, p, p->x, rowsum);
}

int lg_problem_matrix_norm(lg_env *env, lg_problem *p, double *norm) {
  if (prepare_matrix(env, p)) return 1;
  PetscReal n;
  PCHK(MatNorm(p->A, NORM_FROBENIUS, &n), "MatNorm");
  *norm = n;
  return 0;
}

/* solve the problem's matrix (assembled at u = 0, essential rows homogeneous) with a given
 * right-hand side: the Riesz maps of gradients (a mass or H1 matrix) */
int lg_problem_solve_vector(lg_env *env, lg_problem *p, const double *rhs, double *x) {
  if (prepare_matrix(env, p)) return 1;
  if (p->iter == 1) { /* its essential rows only replaced: not for CG */
    if (iterative_to_direct(env, p, "a solve with the matrix's essential rows only replaced")) return 1;
    PCHK(lg_lu_prepare(p->ksp, p->A, p->own_rows, p->nown, p->prefix, !p->nonlinear), "the factorization's choice");
  }
  if (lg_problem_vec_set(env, p, p->b, rhs)) return 1;
  PetscScalar *b;
  PCHK(VecGetArray(p->b, &b), "VecGetArray");
  for (int i = 0; i < p->nown; i++) b[p->own_rows[i] - p->lo] = 0;
  PCHK(VecRestoreArray(p->b, &b), "VecRestoreArray");
  PetscErrorCode ierr;
  KSPConvergedReason reason;
  for (;;) {
    ierr = KSPSolve(p->ksp, p->b, p->x);
    if (ierr) return lg_petsc_fail(env, ierr, "a solve with the problem's matrix");
    KSPGetConvergedReason(p->ksp, &reason);
    if (reason < 0 && p->mass_cg == 1) { /* CG on a mass matrix short of 1e-14: LU */
      if (mass_to_lu(env, p)) return 1;
      continue;
    }
    if (reason >= 0 || !lg_lu_native(p->ksp, p->prefix)) break;
    PCHK(lg_lu_fallback(p->ksp, p->A), "the switch to MUMPS"); /* PETSc's LU failed: MUMPS, once */
  }
  if (reason < 0) { lg_seterr(env, "a solve with the problem's matrix failed: %s", ksp_reason_name(reason)); return 1; }
  return lg_problem_vec_get(env, p, p->x, x);
}
