/* optimize.c — minimization of reduced functionals with PETSc's TAO: the controls are one
 * vector (field dofs, then parameters) and TAO gets the value and the gradient from one
 * state and one adjoint solve.
 *
 * TAO works in the Euclidean inner product of its vector, which for a field control would
 * be the dofs' inner product: iteration counts then grow with mesh refinement. So TAO sees
 * scaled variables x_i = sqrt(d_i) m_i, with d the diagonal of the control space's mass matrix
 * scaled to keep its total (HRZ lumping, positive for every Lagrange degree): the Euclidean
 * norm of x is an L2 norm of m, spectrally equivalent to the consistent one, and the gradient
 * TAO gets, g_i / sqrt(d_i), measures in the dual norm. TAO's own L-BFGS scaling then works
 * as designed (a fixed mass-matrix initial Hessian, TaoLMVMSetH0, is not rescaled by PETSc and
 * needed over 2000 iterations on the Poisson mother problem at alpha = 1e-6, against 150 to
 * 300 here). Bounds scale the same way. Every -tao_* option applies (TaoSetFromOptions).
 *
 * The Newton methods (nls: line search, ntr: trust region; bnls/bntr with bounds) get the
 * Hessian as a matrix-free operator in the same variables, S^-1 H S^-1 with S = diag(sqrt(d)):
 * each product is one tangent-linear and one second-order adjoint solve at the point where
 * TAO last asked for the Hessian (lg_reduced_hessian). */
#include "optimize.h"

#include <math.h>
#include <petsctao.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct {
  lg_env *env;
  lg_reduced *rf;
  const lg_minimize_opts *o;
  int nc, off[LG_MAXCONTROL + 1];
  /* TAO's vector on this rank: control i's entries off[i] .. off[i + 1] are its dofs idx[i]
   * (NULL: all, in order). A distributed mesh's (dist): the owned dofs of each field control
   * and the parameters on rank 0, in one vector over the ranks; otherwise every rank holds
   * the whole vector (a whole-mesh run repeats the same iterations on each) */
  int dist, *idx[LG_MAXCONTROL];
  double *g[LG_MAXCONTROL];
  double *sq;       /* sqrt(d): x = sq m */
  int failed, evals, hess_failed, hmults;
  double *xh;       /* the point of the Hessian (TAO's variables) */
  double *dm[LG_MAXCONTROL], *hd[LG_MAXCONTROL];
  lg_series *series;           /* the controls per iteration (o->series) */
  double *cg[LG_MAXCONTROL]; /* a constraint's gradient */
  Tao outer;                 /* almm hands its monitors to its subsolver: report the outer one */
  double *xlast;             /* almm: the point last set (the objective and the constraints
                              * are asked at the same point one after the other) */
  double fs, cs[LG_MAXCONS];  /* almm: TAO sees J / fs and (g_j - c_j) / cs_j */
} opt_ctx;

static int tao_fail(lg_env *env, PetscErrorCode ierr, const char *what) {
  const char *text = NULL;
  PetscErrorMessage(ierr, &text, NULL);
  lg_seterr(env, "%s failed: %s", what, text ? text : "PETSc error");
  return 1;
}
#define TCHK(call, what) do { PetscErrorCode ierr_ = (call); if (ierr_) { rc = tao_fail(env, ierr_, what); goto done; } } while (0)

/* the dof of control i at its entry j of TAO's vector */
static inline int dof_at(const opt_ctx *C, int i, int j) { return C->idx[i] ? C->idx[i][j] : j; }

/* does any rank see a difference (a distributed mesh's ranks decide together what to
 * recompute: every rank takes part in the solves) */
static int any_rank(const opt_ctx *C, int differs) {
  if (!C->dist) return differs;
  int any = differs;
  MPI_Allreduce(&differs, &any, 1, MPI_INT, MPI_MAX, PETSC_COMM_WORLD);
  return any;
}

/* v (TAO's entries of control i, divided by the scaling) into the dofs of out: every local
 * dof, a distributed mesh's ghosts from their owners, a parameter from rank 0 */
static void spread(opt_ctx *C, int i, const PetscScalar *v, double *out) {
  const lg_control *c = lg_reduced_control(C->rf, i);
  const double *q = C->sq + C->off[i];
  int nl = C->off[i + 1] - C->off[i];
  for (int j = 0; j < nl; j++) out[dof_at(C, i, j)] = v[C->off[i] + j] / q[j];
  if (!C->dist) return;
  if (c->kind == LG_CONTROL_PARAM) {
    if (MPI_Bcast(out, 1, MPI_DOUBLE, 0, PETSC_COMM_WORLD) != MPI_SUCCESS) C->failed = 1;
    return;
  }
  int nd = c->f->dm->ndof, n = lg_reduced_control_size(C->rf, i); /* a per-step control: block by block */
  for (int k = 0; k < n; k += nd)
    if (lg_dist_ghosts(C->env, c->f->mesh, c->f->dm, out + k)) C->failed = 1;
}

/* controls <-> the TAO vector x = sqrt(d) m */
static void to_controls(opt_ctx *C, const PetscScalar *x) {
  int n = C->off[C->nc];
  if (C->xlast) {
    if (!any_rank(C, C->xlast[n] != 1 || memcmp(C->xlast, x, sizeof(double) * (size_t)n))) return;
    memcpy(C->xlast, x, sizeof(double) * (size_t)n);
    C->xlast[n] = 1;
  }
  for (int i = 0; i < C->nc; i++) spread(C, i, x, lg_reduced_control_values(C->rf, i));
  lg_reduced_changed(C->rf);
  for (int j = 0; j < C->o->ncons; j++) lg_reduced_changed(C->o->cons[j].rf);
}
/* TAO's entries of the dof vectors v[i] (dual: s = -1 divides by the scaling, primal: s = 1
 * multiplies), each times f */
static void gather_entries(opt_ctx *C, double **v, int s, double f, PetscScalar *x) {
  for (int i = 0; i < C->nc; i++) {
    const double *q = C->sq + C->off[i];
    for (int j = 0; j < C->off[i + 1] - C->off[i]; j++) {
      double d = v[i][dof_at(C, i, j)];
      x[C->off[i] + j] = (s > 0 ? d * q[j] : d / q[j]) * f;
    }
  }
}
static void from_controls(opt_ctx *C, PetscScalar *x) {
  double *v[LG_MAXCONTROL];
  for (int i = 0; i < C->nc; i++) v[i] = lg_reduced_control_values(C->rf, i);
  gather_entries(C, v, 1, 1, x);
}

static PetscErrorCode objective_gradient(Tao tao, Vec X, PetscReal *f, Vec G, void *ud) {
  opt_ctx *C = ud;
  (void)tao;
  const PetscScalar *x;
  PetscCall(VecGetArrayRead(X, &x));
  to_controls(C, x);
  PetscCall(VecRestoreArrayRead(X, &x));
  C->evals++;
  double J;
  for (int j = 0; j < C->o->ncons; j++) lg_reduced_share_state(C->rf, C->o->cons[j].rf);
  if (lg_reduced_value(C->env, C->rf, &J) || lg_reduced_gradient(C->env, C->rf, C->g)) {
    C->failed = 1;
    *f = PETSC_INFINITY; /* lets a line search back off; a failure at the start is reported */
    PetscCall(VecSet(G, 0));
    return 0;
  }
  *f = J / C->fs;
  PetscScalar *g;
  PetscCall(VecGetArray(G, &g));
  gather_entries(C, C->g, -1, 1 / C->fs, g);
  PetscCall(VecRestoreArray(G, &g));
  return 0;
}

/* functional constraints for TAO's augmented Lagrangian, in its convention: c_E(x) = 0 and
 * c_I(x) >= 0, so g <= c is c - g >= 0 and g >= c is g - c >= 0; which = LG_CON_EQ for the
 * equalities, else the inequalities (in the order given) */
static int constraint_values(opt_ctx *C, Vec X, Vec V, int eq) {
  const PetscScalar *x;
  if (VecGetArrayRead(X, &x)) return 1;
  to_controls(C, x);
  VecRestoreArrayRead(X, &x);
  PetscScalar *v;
  PetscInt nv;
  if (VecGetLocalSize(V, &nv) || VecGetArray(V, &v)) return 1;
  int r = 0, bad = 0;
  for (int j = 0; j < C->o->ncons && !bad; j++) {
    int kind = C->o->cons[j].kind;
    if ((kind == LG_CON_EQ) != eq) continue;
    double g;
    lg_reduced_share_state(C->o->cons[j].rf, C->rf);
    if (lg_reduced_value(C->env, C->o->cons[j].rf, &g)) { bad = 1; break; }
    if (r < nv) v[r] = (kind == LG_CON_LE ? C->o->cons[j].c - g : g - C->o->cons[j].c) / C->cs[j];
    r++; /* (a distributed run's are on rank 0) */
  }
  VecRestoreArray(V, &v);
  if (bad) C->failed = 1;
  return bad;
}
static PetscErrorCode ineq_constraints(Tao tao, Vec X, Vec V, void *ud) {
  (void)tao;
  return constraint_values(ud, X, V, 0) ? PETSC_ERR_LIB : 0;
}
static PetscErrorCode eq_constraints(Tao tao, Vec X, Vec V, void *ud) {
  (void)tao;
  return constraint_values(ud, X, V, 1) ? PETSC_ERR_LIB : 0;
}
/* their Jacobian in TAO's variables: rows d c_j / dx = +-(dg_j/dm) / sqrt(d) */
static int constraint_jacobian(opt_ctx *C, Vec X, Mat A, int eq) {
  const PetscScalar *x;
  if (VecGetArrayRead(X, &x)) return 1;
  to_controls(C, x);
  VecRestoreArrayRead(X, &x);
  int r = 0, n = C->off[C->nc];
  PetscInt *cols = malloc(sizeof(PetscInt) * ((size_t)n + 1)), c0 = 0;
  PetscScalar *row = malloc(sizeof(PetscScalar) * ((size_t)n + 1));
  if (!cols || !row) { free(cols); free(row); lg_seterr(C->env, "out of memory"); C->failed = 1; return 1; }
  if (VecGetOwnershipRange(X, &c0, NULL)) { free(cols); free(row); return 1; }
  for (int k = 0; k < n; k++) cols[k] = c0 + k; /* this rank's columns (rows on rank 0 get them) */
  for (int j = 0; j < C->o->ncons; j++) {
    int kind = C->o->cons[j].kind;
    if ((kind == LG_CON_EQ) != eq) continue;
    double g;
    lg_reduced *rg = C->o->cons[j].rf;
    lg_reduced_share_state(rg, C->rf);
    if (lg_reduced_value(C->env, rg, &g) || lg_reduced_gradient(C->env, rg, C->cg)) {
      free(cols); free(row); C->failed = 1; return 1;
    }
    gather_entries(C, C->cg, -1, (kind == LG_CON_LE ? -1 : 1) / C->cs[j], row);
    PetscInt rr = r++;
    if (MatSetValues(A, 1, &rr, n, cols, row, INSERT_VALUES)) { free(cols); free(row); return 1; }
  }
  free(cols);
  free(row);
  return MatAssemblyBegin(A, MAT_FINAL_ASSEMBLY) || MatAssemblyEnd(A, MAT_FINAL_ASSEMBLY);
}
static PetscErrorCode ineq_jacobian(Tao tao, Vec X, Mat A, Mat B, void *ud) {
  (void)tao; (void)B;
  return constraint_jacobian(ud, X, A, 0) ? PETSC_ERR_LIB : 0;
}
static PetscErrorCode eq_jacobian(Tao tao, Vec X, Mat A, Mat B, void *ud) {
  (void)tao; (void)B;
  return constraint_jacobian(ud, X, A, 1) ? PETSC_ERR_LIB : 0;
}

/* TAO asks for the Hessian at X: remember the point; the products come later */
static PetscErrorCode hessian_at(Tao tao, Vec X, Mat H, Mat Hpre, void *ud) {
  opt_ctx *C = ud;
  (void)tao; (void)H; (void)Hpre;
  const PetscScalar *x;
  PetscCall(VecGetArrayRead(X, &x));
  memcpy(C->xh, x, sizeof(double) * (size_t)C->off[C->nc]);
  PetscCall(VecRestoreArrayRead(X, &x));
  return 0;
}

/* y = S^-1 H(m) S^-1 v at the point of the Hessian */
static PetscErrorCode hessian_mult(Mat H, Vec V, Vec Y) {
  opt_ctx *C;
  PetscCall(MatShellGetContext(H, &C));
  int n = C->off[C->nc];
  /* the controls may have moved since (a line search): back to the Hessian's point */
  double *cur = C->hd[0]; /* scratch, overwritten below */
  from_controls(C, cur);
  if (any_rank(C, memcmp(cur, C->xh, sizeof(double) * (size_t)n) != 0)) to_controls(C, C->xh);
  const PetscScalar *v;
  PetscCall(VecGetArrayRead(V, &v));
  for (int i = 0; i < C->nc; i++) spread(C, i, v, C->dm[i]);
  PetscCall(VecRestoreArrayRead(V, &v));
  C->hmults++;
  if (lg_reduced_hessian(C->env, C->rf, C->dm, C->hd)) {
    C->failed = C->hess_failed = 1;
    return PETSC_ERR_LIB; /* stops TAO: the message is in env */
  }
  PetscScalar *y;
  PetscCall(VecGetArray(Y, &y));
  gather_entries(C, C->hd, -1, 1, y);
  PetscCall(VecRestoreArray(Y, &y));
  return 0;
}

/* write the field controls at this iteration into the series */
static int write_step(opt_ctx *C, int it) {
  const lg_control *c = NULL;
  for (int i = 0; i < C->nc && !c; i++)
    if (lg_reduced_control(C->rf, i)->kind == LG_CONTROL_FIELD && !lg_reduced_control(C->rf, i)->per_step) c = lg_reduced_control(C->rf, i);
  if (!c) return 0;
  mesh_field fl[LG_MAXCONTROL];
  int nf = 0;
  for (int i = 0; i < C->nc; i++) {
    const lg_control *ci = lg_reduced_control(C->rf, i);
    if (ci->kind != LG_CONTROL_FIELD || ci->per_step || ci->f->mesh != c->f->mesh) continue;
    expr_func_info *fi = expr_func_get(C->env->c, ci->f->fid);
    fl[nf++] = (mesh_field){fi ? fi->name : "m", 1, ci->f->dm->degree == 0, ci->f->x};
  }
  if (!C->series && !(C->series = lg_series_new(C->env, C->o->series))) return 1;
  return lg_series_write(C->env, C->series, c->f->mesh, nf, fl, it);
}

/* the monitor's context is a PetscContainer holding the opt_ctx: TAOALMM hands its monitors
 * to its subsolver with a PetscObjectReference of their contexts (PETSc 3.18), which
 * incremented a field of a plain struct (found as a pointer of 1 in a control's dof list) */
static PetscErrorCode monitor_ctx_destroy(void **ctx) { return PetscContainerDestroy((PetscContainer *)ctx); }

static PetscErrorCode monitor(Tao tao, void *ud) {
  opt_ctx *C;
  PetscCall(PetscContainerGetPointer((PetscContainer)ud, (void **)&C));
  PetscInt it;
  PetscReal f, gnorm, cnorm, step;
  TaoConvergedReason reason;
  if (C->outer && tao != C->outer) return 0;
  PetscCall(TaoGetSolutionStatus(tao, &it, &f, &gnorm, &cnorm, &step, &reason));
  int show = C->o->monitor && lg_mpi_rank() == 0; /* every rank runs the same iterations */
  if (show && C->o->ncons) {
    printf("  iteration %3d: J = %.10e  |g| = %.3e  |c| = %.3e  evaluations %d\n", (int)it, (double)f * C->fs,
           (double)gnorm, (double)cnorm, C->evals);
    fflush(stdout);
  } else if (show) {
    printf("  iteration %3d: J = %.10e  |g| = %.3e  step = %.3e\n", (int)it, (double)f, (double)gnorm, (double)step);
    fflush(stdout);
  }
  if (C->o->series && write_step(C, (int)it)) C->failed = 1;
  return 0;
}

/* TAO's vector on this rank: each control's entries (C->off, C->idx), n in all; collective
 * on a distributed mesh (every rank numbers, failed or not) */
static int number_controls(lg_env *env, opt_ctx *C, int *n) {
  int rc = 0;
  lg_mesh *lm = lg_problem_mesh(lg_reduced_problem(C->rf));
  C->dist = lm->dist != NULL;
  *n = 0;
  for (int i = 0; i < C->nc; i++) {
    C->off[i] = *n;
    const lg_control *c = lg_reduced_control(C->rf, i);
    if (!C->dist) *n += lg_reduced_control_size(C->rf, i);
    else if (c->kind == LG_CONTROL_PARAM) *n += lg_mpi_rank() == 0;
    else { /* the owned dofs */
      int nown = 0, ni = lg_reduced_control_size(C->rf, i), nd = c->f->dm->ndof, nb = ni / nd;
      const char *own = lg_dist_owned(env, lm, c->f->dm, &nown);
      C->idx[i] = own ? malloc(sizeof(int) * ((size_t)nown * (size_t)nb + 1)) : NULL;
      if (!C->idx[i]) { if (own) lg_seterr(env, "out of memory"); rc = 1; continue; }
      for (int k = 0, j = 0; k < ni; k++) /* a per-step control: each block's owned dofs */
        if (own[k % nd]) C->idx[i][j++] = k;
      *n += nown * nb;
    }
  }
  C->off[C->nc] = *n;
  if (C->dist) {
    double bad = rc;
    if (lg_allreduce(&bad, 1, LG_MAX) || bad) {
      if (!rc) lg_seterr(env, "another rank failed to number the controls' dofs");
      rc = 1;
    }
  }
  return rc;
}

/* the scaling of TAO's variables: the square root of the HRZ-lumped mass of each field
 * control (its total kept), 1 for parameters and with inner_product = "dofs"; into C->sq */
static int mass_scaling(lg_env *env, opt_ctx *C, int n) {
  int rc = 0;
  C->sq = malloc(sizeof(double) * ((size_t)n + 1));
  if (!C->sq) { lg_seterr(env, "out of memory"); return 1; }
  for (int i = 0; i < C->nc; i++) {
    const lg_control *c = lg_reduced_control(C->rf, i);
    int ni = lg_reduced_control_size(C->rf, i), nl = C->off[i + 1] - C->off[i];
    double *q = C->sq + C->off[i];
    if (c->kind == LG_CONTROL_PARAM || C->o->riesz == LG_RIESZ_NONE) {
      for (int k = 0; k < nl; k++) q[k] = 1;
      continue;
    }
    lg_problem *G = lg_reduced_gram(env, C->rf, i, 0);
    ni /= lg_reduced_control_blocks(C->rf, i); /* a per-step control: each block as one field (whole meshes) */
    double *dg = malloc(sizeof(double) * ((size_t)ni + 1)), *rs = malloc(sizeof(double) * ((size_t)ni + 1));
    if (!G || !dg || !rs || lg_problem_matrix_diagonal(env, G, dg, rs)) {
      if (!rs || !dg) lg_seterr(env, "out of memory");
      free(rs);
      free(dg);
      return 1;
    }
    double sum[2] = {0, 0}; /* the row sums' and the diagonal's totals (over the ranks) */
    for (int j = 0; j < nl; j++) {
      sum[0] += rs[dof_at(C, i, j) % ni];
      sum[1] += dg[dof_at(C, i, j) % ni];
    }
    if (C->dist && lg_allreduce(sum, 2, LG_SUM)) { lg_seterr(env, "the sum over the ranks failed"); rc = 1; }
    for (int j = 0; j < nl && !rc; j++) {
      q[j] = sqrt(dg[dof_at(C, i, j) % ni] * sum[0] / sum[1]);
      if (!(q[j] > 0)) { lg_seterr(env, "the mass matrix of control %d is not positive", i + 1); rc = 1; }
    }
    free(rs);
    free(dg);
    if (rc) return 1;
  }
  return 0;
}

/* the Newton methods' Hessian: a matrix-free operator (hessian_mult) into *H. Their Krylov
 * solver answers to -tao_ksp_* and -tao_pc_* (not the state's -ksp_* and -pc_*); no
 * preconditioner by default (the operator is matrix-free; in the scaled variables CG needs
 * about 70 products on the Poisson mother problem at every resolution from 16^2 to 64^2, and
 * -tao_pc_type lmvm did not lower that) */
static PetscErrorCode setup_newton(Tao tao, opt_ctx *C, MPI_Comm comm, int n, PetscInt N, Mat *H) {
  PetscCall(MatCreateShell(comm, n, n, N, N, C, H));
  PetscCall(MatShellSetOperation(*H, MATOP_MULT, (void (*)(void))hessian_mult));
  PetscCall(MatSetOption(*H, MAT_SYMMETRIC, PETSC_TRUE));
  PetscCall(TaoSetHessian(tao, *H, *H, hessian_at, C));
  KSP ksp;
  PetscCall(TaoGetKSP(tao, &ksp));
  if (!ksp) return 0;
  PetscCall(KSPSetOptionsPrefix(ksp, "tao_"));
  PetscBool set = PETSC_FALSE;
  PetscOptionsHasName(NULL, NULL, "-tao_pc_type", &set);
  PC pc;
  PetscCall(KSPGetPC(ksp, &pc));
  if (!set) PetscCall(PCSetType(pc, PCNONE));
  return 0;
}

/* the m equality (eq) or inequality constraints' values and Jacobian for almm: their rows on
 * the rank that holds them (r0), dense */
static PetscErrorCode setup_constraints(Tao tao, opt_ctx *C, MPI_Comm comm, int n, PetscInt N, int m, int r0, int eq, Vec *V,
                                        Mat *A) {
  PetscCall(VecCreateMPI(comm, r0 ? m : 0, m, V));
  PetscCall(MatCreateDense(comm, r0 ? m : 0, n, m, N, NULL, A));
  if (eq) {
    PetscCall(TaoSetEqualityConstraintsRoutine(tao, *V, eq_constraints, C));
    PetscCall(TaoSetJacobianEqualityRoutine(tao, *A, *A, eq_jacobian, C));
  } else {
    PetscCall(TaoSetInequalityConstraintsRoutine(tao, *V, ineq_constraints, C));
    PetscCall(TaoSetJacobianInequalityRoutine(tao, *A, *A, ineq_jacobian, C));
  }
  return 0;
}

/* the bounds in TAO's (scaled) variables, ±infinity where a control has none */
static PetscErrorCode setup_bounds(Tao tao, opt_ctx *C, Vec X, Vec *XL, Vec *XU) {
  const lg_minimize_opts *o = C->o;
  PetscCall(VecDuplicate(X, XL));
  PetscCall(VecDuplicate(X, XU));
  PetscScalar *l, *u;
  PetscCall(VecGetArray(*XL, &l));
  PetscCall(VecGetArray(*XU, &u));
  for (int i = 0; i < C->nc; i++)
    for (int j = 0; j < C->off[i + 1] - C->off[i]; j++) {
      int k = dof_at(C, i, j);
      l[C->off[i] + j] = o->lower[i] ? o->lower[i][k] * C->sq[C->off[i] + j] : PETSC_NINFINITY;
      u[C->off[i] + j] = o->upper[i] ? o->upper[i][k] * C->sq[C->off[i] + j] : PETSC_INFINITY;
    }
  PetscCall(VecRestoreArray(*XL, &l));
  PetscCall(VecRestoreArray(*XU, &u));
  return TaoSetVariableBounds(tao, *XL, *XU);
}

/* lugal's defaults for the quasi-Newton matrix, unless the user chose: a scalar (Shanno-Phua)
 * initial scaling and 10 updates. PETSc 3.18's diagonal scaling stalled on the Poisson mother
 * problem (alpha = 1e-6: over 2000 iterations; these: 149 at 32^2, 121 at 64^2, to 1e-8 of
 * the first gradient) */
static void lmvm_defaults(int almm, int bounded) {
  const char *pre = almm ? "-tao_almm_subsolver_tao_bqnls_mat_lmvm_" : bounded ? "-tao_blmvm_mat_lmvm_" : "-tao_lmvm_mat_lmvm_";
  static const char *const kv[][2] = {{"scale_type", "scalar"}, {"hist_size", "10"}};
  for (int i = 0; i < 2; i++) {
    char name[96];
    snprintf(name, sizeof name, "%s%s", pre, kv[i][0]);
    PetscBool set = PETSC_FALSE;
    PetscOptionsHasName(NULL, NULL, name, &set);
    if (!set) PetscOptionsSetValue(NULL, name, kv[i][1]);
  }
}

/* after TaoSolve (ierr its result): the iterate into the controls, info filled (with the
 * constraints' values and multipliers for almm), and the outcome: 0 with a usable iterate
 * (converged or not: info->converged), 1 with the reason in env->err. nee, nie: the equality
 * and inequality constraints; r0: this rank holds the constraints' rows */
static int tao_results(lg_env *env, opt_ctx *C, Tao tao, PetscErrorCode ierr, int newton, int almm, int nee, int nie, int r0,
                       lg_minimize_info *info) {
  const lg_minimize_opts *o = C->o;
  int rc = 0;
  PetscInt it;
  PetscReal f, gnorm, cnorm, step;
  TaoConvergedReason reason;
  TaoGetSolutionStatus(tao, &it, &f, &gnorm, &cnorm, &step, &reason);
  info->iterations = (int)it;
  info->J = f * C->fs;
  info->gnorm = gnorm;
  info->evaluations = C->evals;
  info->hessian_products = C->hmults;
  snprintf(info->reason, sizeof info->reason, "%s", TaoConvergedReasons[reason]);
  info->converged = reason > 0;
  info->cnorm = cnorm;
  /* the controls hold the solution TAO returns (not its last trial point) */
  const PetscScalar *xs;
  Vec S;
  TaoGetSolution(tao, &S);
  VecGetArrayRead(S, &xs);
  to_controls(C, xs);
  VecRestoreArrayRead(S, &xs);
  if (!ierr && almm) {
    /* the constraints at the minimizer, and the multipliers in the user's convention:
     * TAO's Lagrangian is J - y_E c_E - y_I c_I, so lambda = y for g <= c, -y otherwise */
    Vec Y = NULL;
    IS ise = NULL, isi = NULL;
    const PetscScalar *y = NULL;
    /* (PETSc 3.18 has the index sets only when there are both kinds) */
    int have = !TaoALMMGetMultipliers(tao, &Y) && Y && (!(nee && nie) || !TaoALMMGetDualIS(tao, &ise, &isi)) &&
               !VecGetArrayRead(Y, &y);
    const PetscInt *ie = NULL, *ii = NULL;
    if (have && ise) ISGetIndices(ise, &ie);
    if (have && isi) ISGetIndices(isi, &ii);
    int ke = 0, ki = 0;
    for (int j = 0; j < o->ncons; j++) {
      double g = NAN;
      lg_reduced_changed(o->cons[j].rf);
      if (lg_reduced_value(env, o->cons[j].rf, &g)) { rc = 1; break; }
      info->g[j] = g;
      int kind = o->cons[j].kind;
      /* where each constraint's multiplier is in TAO's vector (equalities, inequalities) */
      int k = kind == LG_CON_EQ ? ke++ : ki++;
      const PetscInt *at = kind == LG_CON_EQ ? ie : ii;
      PetscInt pos = at ? at[k] : (kind == LG_CON_EQ ? k : nee + k);
      info->lambda[j] = have && r0 ? (kind == LG_CON_LE ? 1 : -1) * y[pos] * C->fs / C->cs[j] : NAN;
    }
    if (C->dist && MPI_Bcast(info->lambda, o->ncons, MPI_DOUBLE, 0, PETSC_COMM_WORLD) != MPI_SUCCESS) rc = 1; /* rank 0 holds them */
    if (ie) ISRestoreIndices(ise, &ie);
    if (ii) ISRestoreIndices(isi, &ii);
    if (have) VecRestoreArrayRead(Y, &y);
    if (rc) return 1;
  }
  if (ierr && C->hess_failed) {
    char why[LG_ERRLEN];
    snprintf(why, sizeof why, "%s", env->err);
    lg_seterr(env, "the optimization failed at iteration %d (a Hessian product): %s", (int)it, why);
    return 1;
  }
  if (ierr && newton && ierr == PETSC_ERR_SUP) {
    lg_seterr(env, "the optimization failed: the Hessian is matrix-free (products only), so -tao_pc_type must be none "
                   "or lmvm, and -tao_ksp_type a Krylov method (stcg, nash, gltr, cg)");
    return 1;
  }
  if (ierr) return tao_fail(env, ierr, "the optimization");
  if (C->failed && (it == 0 || !isfinite(f))) {
    char why[LG_ERRLEN];
    snprintf(why, sizeof why, "%s", env->err);
    lg_seterr(env, "the optimization failed at iteration %d: %s", (int)it, why);
    return 1;
  }
  if (reason < 0 && lg_mpi_rank() == 0) {
    /* the controls hold TAO's last iterate, a usable point (a line search that failed at
     * rounding level, the iteration limit): returned with converged = false, not raised */
    fprintf(stderr, "lg.minimize: stopped without converging: %s after %d iterations (J = %g, |g| = %.3e)%s%s; the controls "
                    "hold the last iterate (info.converged = false)\n", info->reason, (int)it, info->J, gnorm,
            C->failed ? "; the last trial point failed: " : "", C->failed ? env->err : "");
  }
  return rc;
}

int lg_minimize(lg_env *env, lg_reduced *rf, const lg_minimize_opts *o, lg_minimize_info *info) {
  memset(info, 0, sizeof *info);
  opt_ctx C;
  memset(&C, 0, sizeof C);
  C.env = env;
  C.rf = rf;
  C.o = o;
  C.nc = lg_reduced_ncontrols(rf);
  C.fs = 1;
  for (int j = 0; j < LG_MAXCONS; j++) C.cs[j] = 1;
  int n = 0, rc = number_controls(env, &C, &n);
  if (rc) goto done_early;
  static const struct { const char *name; TaoType type; int bounded, newton; } methods[] = {
      {"lmvm", TAOLMVM, 0, 0}, {"blmvm", TAOBLMVM, 1, 0}, {"nls", TAONLS, 0, 1},
      {"ntr", TAONTR, 0, 1},   {"bnls", TAOBNLS, 1, 1},   {"bntr", TAOBNTR, 1, 1},
      {"almm", TAOALMM, 1, 0}};
  int mi = -1;
  for (int i = 0; i < (int)(sizeof methods / sizeof methods[0]); i++)
    if (!strcmp(o->method, methods[i].name)) mi = i;
  if (mi < 0) {
    lg_seterr(env, "unknown method \"%s\" (lmvm, blmvm, nls, ntr, bnls, bntr, almm)", o->method);
    return 1;
  }
  int bounded = methods[mi].bounded, newton = methods[mi].newton, almm = !strcmp(o->method, "almm");
  if (almm != (o->ncons > 0)) {
    lg_seterr(env, almm ? "method almm needs constraints" : "constraints need method almm");
    return 1;
  }
  for (int j = 0; j < o->ncons; j++) {
    const lg_reduced *rg = o->cons[j].rf;
    int same = lg_reduced_ncontrols(rg) == C.nc;
    for (int i = 0; same && i < C.nc; i++) {
      const lg_control *a = lg_reduced_control(rf, i), *b = lg_reduced_control(rg, i);
      same = a->kind == b->kind && a->f == b->f && a->param == b->param;
    }
    if (!same) {
      lg_seterr(env, "constraint %d is a reduced functional of other controls than the objective's (the same controls, "
                     "in the same order, are needed)", j + 1);
      return 1;
    }
  }
  int any_bounds = 0;
  for (int i = 0; i < C.nc; i++) any_bounds |= o->lower[i] || o->upper[i];
  if (any_bounds && !bounded) { lg_seterr(env, "bounds need a bounded method (blmvm, bnls, bntr)"); return 1; }
  for (int i = 0; i < C.nc; i++) {
    size_t sz = sizeof(double) * ((size_t)lg_reduced_control_size(rf, i) + 1);
    C.g[i] = malloc(sz);
    C.dm[i] = newton ? malloc(sz) : NULL;
    /* hd[0] doubles as a scratch of all n values in hessian_mult */
    size_t all = sizeof(double) * ((size_t)n + 1);
    C.hd[i] = newton ? malloc(i || all < sz ? sz : all) : NULL;
    C.cg[i] = almm ? malloc(sz) : NULL;
    if (almm && i == 0 && !(C.xlast = calloc((size_t)n + 1, sizeof(double)))) { lg_seterr(env, "out of memory"); rc = 1; goto done_early; }
    if (!C.g[i] || (newton && (!C.dm[i] || !C.hd[i])) || (almm && !C.cg[i])) { lg_seterr(env, "out of memory"); rc = 1; goto done_early; }
  }
  if (newton && !(C.xh = malloc(sizeof(double) * ((size_t)n + 1)))) { lg_seterr(env, "out of memory"); rc = 1; goto done_early; }
  Tao tao = NULL;
  Vec X = NULL, XL = NULL, XU = NULL, CI = NULL, CE = NULL;
  Mat H = NULL, AI = NULL, AE = NULL;
  int nie = 0, nee = 0;
  for (int j = 0; j < o->ncons; j++) {
    if (o->cons[j].kind == LG_CON_EQ) nee++;
    else nie++;
  }
  if (mass_scaling(env, &C, n)) { rc = 1; goto done; }
  MPI_Comm comm = C.dist ? PETSC_COMM_WORLD : PETSC_COMM_SELF;
  PetscInt N = C.dist ? PETSC_DETERMINE : n;
  int r0 = lg_mpi_rank() == 0 || !C.dist; /* holds the constraints */
  if (C.dist) TCHK(VecCreateMPI(comm, n, N, &X), "VecCreateMPI");
  else TCHK(VecCreateSeq(comm, n, &X), "VecCreateSeq");
  PetscScalar *x;
  TCHK(VecGetArray(X, &x), "VecGetArray");
  from_controls(&C, x);
  TCHK(VecRestoreArray(X, &x), "VecRestoreArray");
  TCHK(TaoCreate(comm, &tao), "TaoCreate");
  TCHK(TaoSetType(tao, methods[mi].type), "TaoSetType");
  C.outer = tao;
  TCHK(TaoSetSolution(tao, X), "TaoSetSolution");
  TCHK(TaoSetObjectiveAndGradient(tao, NULL, objective_gradient, &C), "TaoSetObjectiveAndGradient");
  if (newton) TCHK(setup_newton(tao, &C, comm, n, N, &H), "the Newton methods' Hessian");
  if (almm) {
    /* TAO's augmented Lagrangian starts its penalty at 10 whenever the constraints hold at
     * the start: with J ~ 1e-5 and g ~ 0.2 (the Poisson mother problem under a bound on int f)
     * the penalty outweighs J a thousand times and the subproblems take 449 evaluations (the
     * classic formulation: over 10 000 each). It sees J / |J(m0)| and each (g_j - c_j) /
     * max(|c_j|, |g_j(m0)|) instead: 150 evaluations, and gatol is relative to J(m0) */
    double J0, gj;
    if (lg_reduced_value(env, rf, &J0)) { rc = 1; goto done; }
    C.fs = fabs(J0) > 0 && isfinite(J0) ? fabs(J0) : 1;
    for (int j = 0; j < o->ncons; j++) {
      if (lg_reduced_value(env, o->cons[j].rf, &gj)) { rc = 1; goto done; }
      double sc = fmax(fabs(o->cons[j].c), fabs(gj));
      C.cs[j] = sc > 0 && isfinite(sc) ? sc : 1;
    }
    /* few dense constraints: their Jacobians are small dense matrices */
    if (nie) TCHK(setup_constraints(tao, &C, comm, n, N, nie, r0, 0, &CI, &AI), "the inequality constraints");
    if (nee) TCHK(setup_constraints(tao, &C, comm, n, N, nee, r0, 1, &CE, &AE), "the equality constraints");
  }
  if (bounded) TCHK(setup_bounds(tao, &C, X, &XL, &XU), "the bounds");
  TCHK(TaoSetTolerances(tao, o->gatol >= 0 ? o->gatol : almm ? 1e-6 : PETSC_DEFAULT, o->grtol >= 0 ? o->grtol : PETSC_DEFAULT,
                        o->gttol >= 0 ? o->gttol : PETSC_DEFAULT), "TaoSetTolerances");
  if (o->maxit > 0) TCHK(TaoSetMaximumIterations(tao, o->maxit), "TaoSetMaximumIterations");
  {
    PetscContainer mc;
    TCHK(PetscContainerCreate(comm, &mc), "PetscContainerCreate");
    TCHK(PetscContainerSetPointer(mc, &C), "PetscContainerSetPointer");
    TCHK(TaoSetMonitor(tao, monitor, mc, monitor_ctx_destroy), "TaoSetMonitor"); /* the Tao owns it */
  }
  if (!newton) lmvm_defaults(almm, bounded);
  TCHK(TaoSetFromOptions(tao), "TaoSetFromOptions");
  PetscErrorCode ierr = TaoSolve(tao);
  rc = tao_results(env, &C, tao, ierr, newton, almm, nee, nie, r0, info);
done:
  if (tao) TaoDestroy(&tao);
  if (X) VecDestroy(&X);
  if (XL) VecDestroy(&XL);
  if (XU) VecDestroy(&XU);
  if (H) MatDestroy(&H);
  if (CI) VecDestroy(&CI);
  if (CE) VecDestroy(&CE);
  if (AI) MatDestroy(&AI);
  if (AE) MatDestroy(&AE);
  free(C.sq);
  lg_series_free(C.series);
done_early:
  for (int i = 0; i < C.nc; i++) { free(C.g[i]); free(C.dm[i]); free(C.hd[i]); free(C.cg[i]); free(C.idx[i]); }
  free(C.xh);
  free(C.xlast);
  return rc;
}
