/* problem.c — linear and nonlinear problems on PETSc: linearization of the equation into
 * coefficient tables, kernels, CSR assembly (the pattern is sparsity.c's, element entries
 * added in place), essential boundary conditions by row replacement, and the derivatives
 * of those conditions for adjoints. problem_solve.c solves what this assembles. */
#include "problem_int.h"
#include "solver.h"

#include <ctype.h>
#include <limits.h>
#include <math.h>
#include <stdint.h>
#include <petscsnes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>


/* ---------------------------------------------------------------- setup */

static int layout(lg_env *env, lg_mesh *lm, int n, const int *funcs, field_layout *l, dofmap **dm,
                  int *glob, const char *what) {
  l->n = n;
  l->size = 0;
  glob[0] = 0;
  for (int i = 0; i < n; i++) {
    expr_func_info *fi = expr_func_get(env->c, funcs[i]);
    if (!fi) { lg_seterr(env, "bad %s function", what); return 1; }
    l->func[i] = funcs[i];
    l->degree[i] = fi->degree;
    dm[i] = lg_mesh_dofmap(env, lm, fi->degree, fi->ncomp > 1 ? fi->ncomp : 1, fi->disc);
    if (!dm[i]) return 1;
    l->nloc[i] = dm[i]->nloc;
    l->bs[i] = dm[i]->bs;
    l->off[i] = l->size;
    l->size += dm[i]->nloc;
    glob[i + 1] = glob[i] + dm[i]->ndof;
  }
  return 0;
}

static int contains_funcs(lg_env *env, expr *e, int n, const int *funcs, expr **which) {
  for (int i = 0; i < n; i++) {
    expr *leaf[1];
    if (expr_collect_fields(env->c, 1, &e, funcs[i], 1, leaf) > 0) {
      if (which) *which = leaf[0];
      return 1;
    }
  }
  return 0;
}

/* p->matpar: the parameters the matrix terms' Jacobian tables read. A parameter of the
 * right-hand side only (the time of a source term, a load) then leaves the matrix and its
 * factorization alone when it changes (heat.lua: before, each step reassembled the matrix
 * and solved by the kept factor's iterations) */
static int matrix_params(lg_env *env, lg_problem *p) {
  int nroot = 0;
  for (int i = 0; i < p->nterm; i++) nroot += p->t[i].tab.njac;
  expr **roots = malloc(sizeof(expr *) * ((size_t)nroot + 1));
  int np = expr_param_count(env->c);
  p->matpar = malloc(sizeof(int) * ((size_t)np + 1));
  if (!roots || !p->matpar) { free(roots); lg_seterr(env, "out of memory"); return 1; }
  nroot = 0;
  for (int i = 0; i < p->nterm; i++)
    for (int j = 0; j < p->t[i].tab.njac; j++) roots[nroot++] = p->t[i].tab.jac[j];
  p->nmatpar = expr_collect_params(env->c, nroot, roots, np, p->matpar);
  free(roots);
  if (p->nmatpar < 0) { lg_seterr(env, "%s", expr_error(env->c)); return 1; }
  return 0;
}

static int setup_terms(lg_env *env, lg_problem *p, const form *eqn, const int *test, const int *unk, int nf) {
  p->nterm = eqn->n;
  p->t = calloc((size_t)eqn->n + 1, sizeof(prob_term));
  if (!p->t) { lg_seterr(env, "out of memory"); return 1; }
  char err[LG_ERRLEN];
  for (int i = 0; i < eqn->n; i++) {
    prob_term *t = &p->t[i];
    t->reg = eqn->t[i].reg;
    if (t->reg.mesh && t->reg.mesh != (void *)p->lm) {
      lg_seterr(env, "term %d of the equation integrates over a region of a different mesh", i + 1);
      return 1;
    }
    expr *f = eqn->t[i].integrand;
    /* an interior facet term is linearized in the test functions and unknowns of both
     * sides: its element rows and columns are the fields on '+', then on '-' */
    t->interior = t->reg.kind == REGION_INTERIOR;
    int continuous = 0; /* a test field with nodes shared by cells */
    for (int a = 0; a < p->rows.n; a++) continuous |= !p->rdm[a]->disc && p->rdm[a]->degree > 0;
    if (t->interior && p->lm->dist && continuous && p->lm->dist->layers < 2) {
      /* a discontinuous field's rows are its owned cells', whose facets' both sides are
       * here; a continuous field's row also takes the facets of its ghost cells, whose
       * other sides are in a second ghost layer */
      lg_seterr(env, "term %d of the equation integrates over interior facets with a continuous test function: on a "
                     "distributed mesh (-lugal_distribute) that needs a second layer of ghost cells, "
                     "-lugal_ghost_layers 2 (set before the mesh is made)", i + 1);
      return 1;
    }
    t->rl = p->rows;
    t->cl = p->cols;
    int tf[2 * KER_MAXFIELD], uf[2 * KER_MAXFIELD], nt = nf;
    memcpy(tf, test, sizeof(int) * (size_t)nf);
    memcpy(uf, unk, sizeof(int) * (size_t)nf);
    if (t->interior) {
      if (2 * nf > KER_MAXFIELD) {
        lg_seterr(env, "term %d integrates over interior facets: at most %d unknowns there (got %d)", i + 1, KER_MAXFIELD / 2, nf);
        return 1;
      }
      for (int a = 0; a < nf; a++) {
        tf[nf + a] = expr_func_side(env->c, test[a], 1);
        uf[nf + a] = expr_func_side(env->c, unk[a], 1);
        if (tf[nf + a] < 0 || uf[nf + a] < 0) { lg_seterr(env, "out of memory"); return 1; }
      }
      nt = 2 * nf;
      field_layout *ls[2] = {&t->rl, &t->cl};
      for (int w = 0; w < 2; w++) {
        field_layout *l = ls[w];
        for (int a = 0; a < nf; a++) {
          l->func[nf + a] = w ? uf[nf + a] : tf[nf + a];
          l->degree[nf + a] = l->degree[a];
          l->nloc[nf + a] = l->nloc[a];
          l->bs[nf + a] = l->bs[a];
          l->off[nf + a] = l->off[a] + l->size;
        }
        l->n = 2 * nf;
        l->size *= 2;
      }
    }
    if (form_linearize(env->c, f, nt, tf, nt, uf, 1, &t->tab)) {
      lg_seterr(env, "%s", expr_error(env->c));
      return 1;
    }
    if (!p->nonlinear) {
      /* a linear problem: J must not depend on u; the right side is -R(0) */
      for (int j = 0; j < t->tab.njac; j++) {
        expr *w;
        if (contains_funcs(env, t->tab.jac[j], nt, uf, &w)) {
          expr_func_info *fi = expr_func_get(env->c, w->i0);
          lg_seterr(env, "the equation is not linear in the unknown %s; use lg.nonlinear_problem", fi->name);
          return 1;
        }
      }
      expr *ul[256];
      int nu = 0;
      for (int j = 0; j < nt; j++) nu += expr_collect_fields(env->c, t->tab.nres, t->tab.res, uf[j], 256 - nu, ul + nu);
      if (nu > 256) { lg_seterr(env, "too many unknown leaves"); return 1; }
      expr *zero[256];
      for (int j = 0; j < nu; j++) zero[j] = expr_num(env->c, 0);
      int k = 0;
      for (int j = 0; j < t->tab.nres; j++) {
        expr *r0 = expr_subs(env->c, t->tab.res[j], nu, ul, zero);
        if (!r0) { lg_seterr(env, "%s", expr_error(env->c)); return 1; }
        if (r0->kind == E_CONST && r0->value == 0) continue;
        t->tab.res_leaf[k] = t->tab.res_leaf[j];
        t->tab.res[k++] = r0;
      }
      t->tab.nres = k;
    }
    t->qdeg = lg_quad_degree(env, f, eqn->t[i].order, p->lm->m->type);
    int facet = t->reg.kind == REGION_BOUNDARY ? 1 : t->interior ? 2 : 0;
    if (t->tab.njac > 0) {
      kernel_spec s = {2, &t->tab, NULL, env->no_vector_math};
      int qd = eqn->t[i].order >= 0 ? t->qdeg : lg_table_degree(env, &t->tab, 2, p->lm->m->type);
      if (kernel_build(env->jit, env->c, p->lm->m->type, facet, qd, &s, &t->rl, &t->cl, &t->kmat, err, sizeof err)) {
        lg_seterr(env, "%s", err);
        return 1;
      }
      t->have_mat = 1;
      env->kernel_ms += t->kmat.compile_ms;
      env->nkernels += !t->kmat.cached;
    }
    if (t->tab.nres > 0) {
      kernel_spec s = {1, &t->tab, NULL, env->no_vector_math};
      int qd = eqn->t[i].order >= 0 ? t->qdeg : lg_table_degree(env, &t->tab, 1, p->lm->m->type);
      if (kernel_build(env->jit, env->c, p->lm->m->type, facet, qd, &s, &t->rl, &t->cl, &t->kres, err, sizeof err)) {
        lg_seterr(env, "%s", err);
        return 1;
      }
      t->have_res = 1;
      env->kernel_ms += t->kres.compile_ms;
      env->nkernels += !t->kres.cached;
    }
    if (lg_region_items(env, p->lm, &t->reg, &t->nitems, &t->cells, &t->facets)) return 1;
  }
  return 0;
}

static int setup_bcs(lg_env *env, lg_problem *p, const form *bc, const int *test, const int *unk, int nf) {
  if (!bc || !bc->n) return 0;
  p->bct = calloc((size_t)bc->n * (size_t)nf * FEM_MAXBS + 1, sizeof(bc_term)); /* a term per test leaf: field and component */
  if (!p->bct) { lg_seterr(env, "out of memory"); return 1; }
  long cap = 0;
  for (int i = 0; i < bc->n; i++) {
    const form_term *ft = &bc->t[i];
    if (ft->reg.kind == REGION_CELLS || ft->reg.kind == REGION_INTERIOR) {
      lg_seterr(env, "an essential boundary condition must be given on boundary facets (mesh:boundary(...)) or vertices "
                     "(mesh:vertices{near = ...})");
      return 1;
    }
    coef_table tab;
    if (form_linearize(env->c, ft->integrand, nf, test, 0, NULL, 0, &tab)) {
      lg_seterr(env, "essential_bc: %s", expr_error(env->c));
      return 1;
    }
    if (tab.nres == 0) {
      coef_table_free(&tab);
      lg_seterr(env, "essential_bc: boundary condition %d is zero: it constrains nothing (write it as v*(u - g))", i + 1);
      return 1;
    }
    for (int j = 0; j < tab.nres; j++) {
      expr *tl = tab.res_leaf[j];
      if (tl->order) {
        coef_table_free(&tab);
        lg_seterr(env, "essential_bc: the test function must appear without derivatives, as in v*(u - g)");
        return 1;
      }
      int a = -1;
      for (int k = 0; k < nf; k++)
        if (test[k] == tl->i0) a = k;
      expr *r = tab.res[j];
      /* r = a*u + rest with u the unknown paired with this test function */
      unsigned char zero3[3] = {0, 0, 0};
      expr *u = expr_field(env->c, unk[a], tl->i1, zero3);
      expr *ca = expr_diff(env->c, r, u);
      expr *z = expr_num(env->c, 0);
      expr *rest = expr_subs(env->c, r, 1, &u, &z);
      expr *bad;
      if (!ca || !rest) { coef_table_free(&tab); lg_seterr(env, "%s", expr_error(env->c)); return 1; }
      if (contains_funcs(env, ca, nf, unk, &bad) || contains_funcs(env, rest, nf, unk, &bad)) {
        expr_func_info *fi = expr_func_get(env->c, bad->i0);
        char buf[200];
        expr_print(env->c, r, buf, sizeof buf);
        coef_table_free(&tab);
        lg_seterr(env, "essential_bc: the condition %s = 0 must be linear in the unknown paired with the "
                       "test function and contain no derivative of it (found %s)", buf, fi->name);
        return 1;
      }
      if (ca->kind == E_CONST && ca->value == 0) {
        expr_func_info *fi = expr_func_get(env->c, unk[a]);
        coef_table_free(&tab);
        lg_seterr(env, "essential_bc: the condition does not contain the unknown %s; write it as v*(%s - g)", fi->name, fi->name);
        return 1;
      }
      bc_term *bt = &p->bct[p->nbct++];
      bt->field = a;
      bt->comp = tl->i1;
      bt->src = i;
      expr *roots[2] = {ca, rest};
      bt->g = expr_div(env->c, expr_neg(env->c, rest), ca);
      if (!bt->g || expr_tape_build(env->c, 2, roots, &bt->tape)) { coef_table_free(&tab); lg_seterr(env, "%s", expr_error(env->c)); return 1; }
      if (lg_region_items(env, p->lm, &ft->reg, &bt->nitems, &bt->cells, &bt->facets)) { coef_table_free(&tab); return 1; }
      bt->points = ft->reg.kind == REGION_POINTS;
      cap += (long)bt->nitems * (bt->points ? 1 : p->rdm[a]->el.nfacet_dofs);
    }
    coef_table_free(&tab);
  }
  p->bc_cap = cap;
  p->bc_rows = malloc(sizeof(PetscInt) * (size_t)(cap + 1));
  p->bc_vals = malloc(sizeof(PetscScalar) * (size_t)(cap + 1));
  p->bc_org = malloc(sizeof(int) * 3 * (size_t)(cap + 1));
  if (!p->bc_rows || !p->bc_vals || !p->bc_org) { lg_seterr(env, "out of memory"); return 1; }
  return 0;
}

static int own_bcs(lg_env *env, lg_problem *p);

/* evaluate the boundary values at the boundary nodes: rows and values, deduplicated */
typedef struct {
  lg_env *env;
  lg_problem *p;
  int cell;
  double xi[3], x[3], K[3][3];
} bc_pt;

static int bc_leaf(void *ud, const expr *e, double *val) {
  bc_pt *b = ud;
  if (e->kind == E_COORD) { *val = b->x[e->i0]; return 0; }
  if (e->kind == E_NORMAL) { lg_seterr(b->env, "essential_bc: the normal vector cannot be used in a Dirichlet value"); return 1; }
  expr_func_info *fi = expr_func_get(b->env->c, e->i0);
  if (!fi || fi->kind != FK_DISCRETE || !fi->user) { lg_seterr(b->env, "essential_bc: %s has no value here", fi ? fi->name : "?"); return 1; }
  lg_function *fn = fi->user;
  if (fn->mesh != b->p->lm) { lg_seterr(b->env, "essential_bc: %s lives on a different mesh", fi->name); return 1; }
  *val = lg_eval_leaf(fn->dm, fn->x, b->cell, b->xi, b->K, e);
  return 0;
}

/* (row, position): by row, then by position, so that within a row the later condition comes last */
static int cmp_row(const void *a, const void *b) {
  const PetscInt *x = a, *y = b;
  if (x[0] != y[0]) return (x[0] > y[0]) - (x[0] < y[0]);
  return (x[1] > y[1]) - (x[1] < y[1]);
}

int lg_problem_compute_bcs(lg_env *env, lg_problem *p) {
  p->nbc = 0;
  mesh *m = p->lm->m;
  int *src = malloc(sizeof(int) * (size_t)(p->bc_cap + 1));
  if (!src) { lg_seterr(env, "out of memory"); return 1; }
  for (int i = 0; i < p->nbct; i++) {
    bc_term *bt = &p->bct[i];
    dofmap *dm = p->rdm[bt->field];
    if (!dm->el.nfacet_dofs && bt->points) {
      free(src);
      lg_seterr(env, "essential_bc: condition %d pins a vertex of a piecewise-constant (P0) field, which has no vertex "
                     "values (they belong to cells)", bt->src + 1);
      return 1;
    }
    if (!dm->el.nfacet_dofs) {
      free(src);
      lg_seterr(env, "essential_bc: boundary condition %d is on a piecewise-constant (P0) field, which has no values on "
                     "the boundary (they belong to cells): impose it weakly, in the equation", bt->src + 1);
      return 1;
    }
    double *w = malloc(sizeof(double) * (size_t)(bt->tape.n + 1));
    if (!w) { free(src); lg_seterr(env, "out of memory"); return 1; }
    bc_pt pt = {env, p, 0, {0, 0, 0}, {0, 0, 0}, {{0}}};
    for (int it = 0; it < bt->nitems; it++) {
      int c = bt->cells[it], f = bt->facets[it];
      double J[3][3];
      pt.cell = c;
      int nk = bt->points ? 1 : dm->el.nfacet_dofs;
      for (int kk = 0; kk < nk; kk++) {
        int node = -1;
        if (bt->points) {
          for (int j = 0; j < dm->el.nloc; j++)
            if (dm->el.ent_dim[j] == 0 && dm->el.ent_id[j] == f) node = j;
        } else node = dm->el.facet_dofs[f][kk];
        if (node < 0) {
          free(w);
          free(src);
          lg_seterr(env, "essential_bc: condition %d pins a vertex of a field without vertex values (P0)", bt->src + 1);
          return 1;
        }
        int k = node * dm->bs + bt->comp; /* the local dof */
        memcpy(pt.xi, dofmap_node_ref(dm, k), sizeof pt.xi);
        cell_jacobian(m, c, pt.xi, J, pt.K);
        dofmap_node_coords(dm, c, k, pt.x);
        double out[2];
        if (expr_tape_eval(&bt->tape, expr_param_values(env->c), bc_leaf, &pt, w, out)) { free(w); free(src); return 1; }
        if (out[0] == 0 || !isfinite(out[0]) || !isfinite(out[1]) || !isfinite(out[1] / out[0])) {
          free(w);
          free(src);
          lg_seterr(env, "essential_bc: the value of boundary condition %d is not defined or not finite at (%g, %g%s) "
                         "(a division by zero, a non-finite parameter?)", bt->src + 1, pt.x[0], pt.x[1], m->dim == 3 ? ", ..." : "");
          return 1;
        }
        p->bc_rows[p->nbc] = p->rglob[bt->field] + dm->cell_dofs[(size_t)c * dm->nloc + k];
        p->bc_vals[p->nbc] = -out[1] / out[0];
        p->bc_org[3 * p->nbc] = i;
        p->bc_org[3 * p->nbc + 1] = c;
        p->bc_org[3 * p->nbc + 2] = k;
        src[p->nbc] = bt->src;
        p->nbc++;
      }
    }
    free(w);
  }
  /* one value per row: a node shared by facets of one condition has one value; where two
   * conditions meet (a corner) the later one in the list wins; a condition that another
   * one overrides with different values on every one of its dofs is an error */
  if (p->nbc > 1) {
    PetscInt *pairs = malloc(sizeof(PetscInt) * 2 * (size_t)p->nbc);
    PetscScalar *v = malloc(sizeof(PetscScalar) * (size_t)p->nbc);
    int nsrc = 0;
    for (int i = 0; i < p->nbct; i++) nsrc = p->bct[i].src + 1 > nsrc ? p->bct[i].src + 1 : nsrc;
    int *ndof = calloc((size_t)nsrc + 1, sizeof(int)), *nover = calloc((size_t)nsrc + 1, sizeof(int)),
        *by = calloc((size_t)nsrc + 1, sizeof(int));
    double *mine = calloc((size_t)nsrc + 1, sizeof(double)), *theirs = calloc((size_t)nsrc + 1, sizeof(double));
    int *org = malloc(sizeof(int) * 3 * (size_t)p->nbc);
    if (!pairs || !v || !ndof || !nover || !by || !mine || !theirs || !org) {
      free(pairs); free(v); free(ndof); free(nover); free(by); free(mine); free(theirs); free(org); free(src);
      lg_seterr(env, "out of memory");
      return 1;
    }
    for (int i = 0; i < p->nbc; i++) { pairs[2 * i] = p->bc_rows[i]; pairs[2 * i + 1] = i; }
    qsort(pairs, (size_t)p->nbc, 2 * sizeof(PetscInt), cmp_row);
    int k = 0;
    for (int i = 0; i < p->nbc;) {
      int j = i;
      while (j < p->nbc && pairs[2 * j] == pairs[2 * i]) j++;
      int last = (int)pairs[2 * (j - 1) + 1];
      double val = p->bc_vals[last];
      /* each condition's view of this row (counted once per condition) */
      for (int q = i; q < j; q++) {
        int e = (int)pairs[2 * q + 1], sc = src[e];
        if (q > i && src[(int)pairs[2 * (q - 1) + 1]] == sc) continue;
        ndof[sc]++;
        double mv = p->bc_vals[e];
        if (sc != src[last] && fabs(mv - val) > 1e-12 * (1 + fabs(mv) + fabs(val))) {
          if (!nover[sc]) { by[sc] = src[last]; mine[sc] = mv; theirs[sc] = val; }
          nover[sc]++;
        }
      }
      v[k] = val;
      p->bc_rows[k] = pairs[2 * i];
      org[3 * k] = p->bc_org[3 * last];
      org[3 * k + 1] = p->bc_org[3 * last + 1];
      org[3 * k + 2] = p->bc_org[3 * last + 2];
      k++;
      i = j;
    }
    int bad = -1;
    for (int sc = 0; sc < nsrc && bad < 0; sc++)
      if (ndof[sc] && nover[sc] == ndof[sc]) bad = sc;
    if (bad >= 0)
      lg_seterr(env, "essential_bc: boundary conditions %d and %d give different values on the same dofs (condition "
                     "%d is overridden on every one of its %d dofs, e.g. %g by %g): drop one of them", bad + 1, by[bad] + 1,
                bad + 1, ndof[bad], mine[bad], theirs[bad]);
    else {
      memcpy(p->bc_vals, v, sizeof(PetscScalar) * (size_t)k);
      memcpy(p->bc_org, org, sizeof(int) * 3 * (size_t)k);
      p->nbc = k;
      if (env->verbose)
        for (int sc = 0; sc < nsrc; sc++)
          if (nover[sc])
            fprintf(stderr, "[lugal] essential_bc: condition %d is overridden by condition %d on %d of its %d dofs "
                            "(where they meet; the later one wins)\n", sc + 1, by[sc] + 1, nover[sc], ndof[sc]);
    }
    free(pairs); free(v); free(ndof); free(nover); free(by); free(mine); free(theirs); free(org);
    if (bad >= 0) { free(src); return 1; }
  }
  free(src);
  return own_bcs(env, p);
}

/* a parallel run: each term keeps the items that touch an owned row (in their order, so
 * that each matrix entry sums its contributions in the serial run's order) */
static void restrict_items(lg_problem *p) {
  PetscInt rg[2 * KER_MAXFIELD * FEM_MAXLOC * FEM_MAXBS];
  for (int i = 0; i < p->nterm; i++) {
    prob_term *t = &p->t[i];
    int n = 0, two = t->interior;
    for (int it = 0; it < t->nitems; it++) {
      lg_term_nodes(p, t, it, 1, 1, 1, rg);
      int mine = 0;
      for (int k = 0; k < t->rl.size && !mine; k++) mine = rg[k] >= p->lo && rg[k] < p->hi;
      if (!mine) continue;
      t->cells[n] = t->cells[it];
      if (t->facets) t->facets[n] = t->facets[it];
      if (two) t->cells[t->nitems + n] = t->cells[t->nitems + it]; /* the '-' cells, compacted below */
      n++;
    }
    if (two) memmove(t->cells + n, t->cells + t->nitems, sizeof(int) * (size_t)n);
    t->nitems = n;
  }
}

lg_problem *lg_problem_new(lg_env *env, const lg_problem_spec *s) {
  double t0 = lg_now_ms();
  if (s->nfield < 1 || s->nfield > KER_MAXFIELD) {
    lg_seterr(env, "a problem has 1 to %d unknowns (got %d)", KER_MAXFIELD, s->nfield);
    return NULL;
  }
  if (lg_mesh_check(env, s->mesh)) return NULL;
  lg_problem *p = calloc(1, sizeof *p);
  if (!p) { lg_seterr(env, "out of memory"); return NULL; }
  p->env = env;
  p->lm = s->mesh;
  p->nonlinear = s->nonlinear;
  p->bc_symmetric = s->bc_symmetric;
  p->bc_diag = 1;
  if (s->prefix) {
    /* PETSc option names: letters, digits and underscores, the prefix ends where the option
     * name starts (-<prefix>ksp_type) */
    size_t n = strlen(s->prefix);
    int ok = n > 0 && n < sizeof p->prefix && (isalpha((unsigned char)s->prefix[0]));
    for (size_t i = 0; ok && i < n; i++) ok = isalnum((unsigned char)s->prefix[i]) || s->prefix[i] == '_';
    if (!ok) {
      lg_seterr(env, "the options prefix \"%.80s\" must be 1 to %d letters, digits and underscores starting with a "
                     "letter (e.g. \"state_\", giving -state_ksp_type)", s->prefix, (int)sizeof p->prefix - 1);
      goto fail;
    }
    snprintf(p->prefix, sizeof p->prefix, "%s", s->prefix);
  }
  for (int i = 0; i < s->nfield; i++) {
    expr_func_info *ft = expr_func_get(env->c, s->test[i]), *fu = expr_func_get(env->c, s->unknown[i]);
    if (!ft || ft->kind != FK_TEST) { lg_seterr(env, "test %d is not a test function", i + 1); goto fail; }
    if (!fu || fu->kind != FK_UNKNOWN) { lg_seterr(env, "unknown %d is not an unknown (lg.unknown)", i + 1); goto fail; }
    if (ft->degree != fu->degree) {
      lg_seterr(env, "the test function %s has degree %d but the unknown %s has degree %d; pair "
                     "each unknown with a test function of the same basis", ft->name, ft->degree, fu->name, fu->degree);
      goto fail;
    }
  }
  double ph[5];
  ph[0] = lg_now_ms();
  if (layout(env, s->mesh, s->nfield, s->test, &p->rows, p->rdm, p->rglob, "test")) goto fail;
  if (layout(env, s->mesh, s->nfield, s->unknown, &p->cols, p->cdm, p->cglob, "unknown")) goto fail;
  p->N = p->rglob[s->nfield];
  if (!s->eqn || s->eqn->n == 0) { lg_seterr(env, "the equation has no integrals"); goto fail; }
  ph[1] = lg_now_ms();
  if (lg_problem_set_ownership(env, p)) goto fail;
  if (setup_terms(env, p, s->eqn, s->test, s->unknown, s->nfield)) goto fail;
  if (matrix_params(env, p)) goto fail;
  if (p->par) restrict_items(p);
  ph[2] = lg_now_ms();
  if (setup_bcs(env, p, s->bc, s->test, s->unknown, s->nfield)) goto fail;
  ph[3] = lg_now_ms();
  if (lg_problem_setup_matrix(env, p)) goto fail;
  if (lg_problem_setup_nullspace(env, p, s)) goto fail;
  ph[4] = lg_now_ms();
  p->state = calloc((size_t)p->N + 1, sizeof(double));
  p->solution = calloc((size_t)p->N + 1, sizeof(double));
  if (p->par && !(p->rwhole = calloc((size_t)p->N + 1, sizeof(double)))) { lg_seterr(env, "out of memory"); goto fail; }
  p->eqn = form_copy(s->eqn);
  p->bcf = s->bc ? form_copy(s->bc) : form_new();
  if (!p->state || !p->solution || !p->eqn || !p->bcf) { lg_seterr(env, "out of memory"); goto fail; }
  memcpy(p->test, s->test, sizeof(int) * (size_t)s->nfield);
  memcpy(p->unk, s->unknown, sizeof(int) * (size_t)s->nfield);
  if (env->verbose)
    fprintf(stderr, "[lugal] problem: %d dofs, %ld matrix entries before summation, %d kernels compiled in %.2f ms, setup %.2f ms "
                    "(dof maps %.2f, terms and kernels %.2f, essential conditions %.2f, sparsity and matrix %.2f)\n",
            p->N, (long)p->ncoo, env->nkernels, env->kernel_ms, lg_now_ms() - t0, ph[1] - ph[0], ph[2] - ph[1],
            ph[3] - ph[2], ph[4] - ph[3]);
  if (env->verbose)
    fprintf(stderr, "[lugal] sparsity and matrix: pattern %.2f ms (%ld nonzeros, %d thread%s), PETSc matrix %.2f ms\n",
            p->setup_ms[0], (long)p->nnz, p->pattern_threads, p->pattern_threads == 1 ? "" : "s", p->setup_ms[1]);
  return p;
fail:
  lg_problem_free(p);
  return NULL;
}

void lg_problem_free(lg_problem *p) {
  if (!p) return;
  if (p->null) MatNullSpaceDestroy(&p->null);
  for (int i = 0; i < p->nterm; i++) {
    coef_table_free(&p->t[i].tab);
    kernel_release(&p->t[i].kmat);
    kernel_release(&p->t[i].kres);
    free(p->t[i].cells);
    free(p->t[i].facets);
    lg_windows_free(&p->t[i].wmat);
    lg_windows_free(&p->t[i].wres);
  }
  free(p->t);
  for (int i = 0; i < p->nbct; i++) {
    expr_tape_free(&p->bct[i].tape);
    free(p->bct[i].cells);
    free(p->bct[i].facets);
  }
  for (int k = 0; k < p->nbcd; k++) {
    for (int i = 0; i < p->bcd[k].n; i++) expr_tape_free(&p->bcd[k].tape[i]);
    free(p->bcd[k].tape);
  }
  free(p->bct);
  free(p->perm);
  free(p->matpar);
  free(p->iperm);
  if (p->own_rows != p->bc_rows) free(p->own_rows);
  if (p->own_vals != p->bc_vals) free(p->own_vals);
  free(p->bc_rows);
  free(p->bc_vals);
  free(p->bc_org);
  if (p->to_all) VecScatterDestroy(&p->to_all);
  if (p->whole) VecDestroy(&p->whole);
  lg_chunk_bufs_free(&p->chunks);
  free(p->rank);
  free(p->row_start);
  free(p->state);
  free(p->solution);
  free(p->rwhole);
  form_free(p->eqn);
  form_free(p->bcf);
  if (p->A) MatDestroy(&p->A);
  free(p->sd_i); free(p->sd_j); free(p->sd_a);
  free(p->so_i); free(p->so_j); free(p->so_a);
  free(p->s_left);
  free(p->csr_i);
  free(p->csr_j);
  free(p->csr_a);
  free(p->bcc_row);
  free(p->bcc_col);
  free(p->bcc_val);
  if (p->b) VecDestroy(&p->b);
  if (p->x) VecDestroy(&p->x);
  lg_keep_destroy(&p->keep);
  if (p->ksp) KSPDestroy(&p->ksp);
  if (p->snes) SNESDestroy(&p->snes);
  if (p->kspT) KSPDestroy(&p->kspT);
  if (p->At) MatDestroy(&p->At);
  free(p);
}

int lg_problem_size(const lg_problem *p) { return p->N; }
int lg_problem_global_size(const lg_problem *p) { return p->Nglob; }

static int cmp_petscint(const void *a, const void *b) {
  PetscInt x = *(const PetscInt *)a, y = *(const PetscInt *)b;
  return (x > y) - (x < y);
}

void lg_problem_ownership(const lg_problem *p, int *rows, long *ghosts) {
  *rows = p->hi - p->lo;
  *ghosts = -1;
  if (!p->csr_i) return;
  int B = p->pB, R0 = p->lo / B, R1 = p->hi / B;
  /* the pattern's columns are nodes (B > 1: every B-th entry of a row is a node's first)
   * outside the owned ones, sorted and counted once each (no array of the whole size) */
  size_t m = 0;
  for (int R = R0; R < R1; R++)
    for (PetscInt e = p->csr_i[(size_t)(R - R0) * B]; e < p->csr_i[(size_t)(R - R0) * B + 1]; e += B) {
      PetscInt c = p->csr_j[e] / B;
      m += c < R0 || c >= R1;
    }
  PetscInt *col = malloc(sizeof(PetscInt) * (m + 1));
  if (!col) return;
  m = 0;
  for (int R = R0; R < R1; R++)
    for (PetscInt e = p->csr_i[(size_t)(R - R0) * B]; e < p->csr_i[(size_t)(R - R0) * B + 1]; e += B) {
      PetscInt c = p->csr_j[e] / B;
      if (c < R0 || c >= R1) col[m++] = c;
    }
  qsort(col, m, sizeof(PetscInt), cmp_petscint);
  long n = 0;
  for (size_t i = 0; i < m; i++) n += !i || col[i] != col[i - 1];
  free(col);
  *ghosts = n * B;
}

long lg_problem_nnz(const lg_problem *p) {
  MatInfo info;
  if (!p->A || MatGetInfo(p->A, MAT_GLOBAL_SUM, &info)) return -1;
  return (long)info.nz_used;
}

/* ---------------------------------------------------------------- distributed vectors */

void lg_problem_owned_part(const lg_problem *p, const double *whole, double sign, double *owned) {
  int B = p->pB;
  if (!p->iperm) {
    for (int r = p->lo; r < p->hi; r++) owned[r - p->lo] = sign * whole[r];
    return;
  }
  /* node by node: PETSc's node R holds the problem's node iperm[R - ioff] */
  for (int R = p->lo / B; R < p->hi / B; R++) {
    const double *w = whole + (size_t)p->iperm[R - p->ioff] * B;
    double *o = owned + ((size_t)R * B - (size_t)p->lo);
    for (int j = 0; j < B; j++) o[j] = sign * w[j];
  }
}

int lg_problem_vec_set(lg_env *env, lg_problem *p, Vec v, const double *whole) {
  PetscScalar *a;
  PCHK(VecGetArray(v, &a), "VecGetArray");
  lg_problem_owned_part(p, whole, 1.0, a);
  PCHK(VecRestoreArray(v, &a), "VecRestoreArray");
  return 0;
}

/* a distributed mesh's problem: the scatter of a distributed vector to the local nodes'
 * dofs (owned and ghost), PETSc's entries perm[node] * B + j */
static int local_scatter(lg_env *env, lg_problem *p, Vec v) {
  int B = p->pB, Nn = p->N / B;
  PetscInt *idx;
  PCHK(PetscMalloc1((size_t)Nn + 1, &idx), "PetscMalloc1");
  for (int i = 0; i < Nn; i++) idx[i] = p->perm[i];
  IS is;
  PCHK(ISCreateBlock(PETSC_COMM_SELF, B, Nn, idx, PETSC_OWN_POINTER, &is), "ISCreateBlock");
  PCHK(VecCreateSeq(PETSC_COMM_SELF, p->N, &p->whole), "VecCreateSeq");
  PCHK(VecScatterCreate(v, is, p->whole, NULL, &p->to_all), "VecScatterCreate");
  PCHK(ISDestroy(&is), "ISDestroy");
  return 0;
}

int lg_problem_vec_get(lg_env *env, lg_problem *p, Vec v, double *whole) {
  Vec src = v; /* a serial run's vector is whole already */
  if (p->par) {
    if (!p->to_all) {
      if (p->lm->dist) { if (local_scatter(env, p, v)) return 1; }
      else PCHK(VecScatterCreateToAll(v, &p->to_all, &p->whole), "VecScatterCreateToAll");
    }
    PCHK(VecScatterBegin(p->to_all, v, p->whole, INSERT_VALUES, SCATTER_FORWARD), "VecScatterBegin");
    PCHK(VecScatterEnd(p->to_all, v, p->whole, INSERT_VALUES, SCATTER_FORWARD), "VecScatterEnd");
    src = p->whole;
  }
  const PetscScalar *a;
  PCHK(VecGetArrayRead(src, &a), "VecGetArrayRead");
  if (p->iperm && !p->lm->dist) /* node by node, as lg_problem_owned_part */
    for (int R = 0, B = p->pB; R < p->N / B; R++) memcpy(whole + (size_t)p->iperm[R] * B, a + (size_t)R * B, sizeof(double) * (size_t)B);
  else if (p->N) memcpy(whole, a, sizeof(double) * (size_t)p->N); /* a distributed mesh's: in the local order already
                                                                    * (an empty part's array may be NULL) */
  PCHK(VecRestoreArrayRead(src, &a), "VecRestoreArrayRead");
  return 0;
}

/* the owned essential rows and values (after compute_bcs) */
static int own_bcs(lg_env *env, lg_problem *p) {
  if (!p->par) {
    p->nown = p->nbc;
    p->own_rows = p->bc_rows;
    p->own_vals = p->bc_vals;
    return 0;
  }
  if (!p->own_rows || p->own_rows == p->bc_rows) {
    p->own_rows = malloc(sizeof(PetscInt) * (size_t)(p->bc_cap + 1));
    p->own_vals = malloc(sizeof(PetscScalar) * (size_t)(p->bc_cap + 1));
    if (!p->own_rows || !p->own_vals) { lg_seterr(env, "out of memory"); return 1; }
  }
  p->nown = 0;
  for (int i = 0; i < p->nbc; i++) {
    PetscInt r = lg_petsc_row(p, p->bc_rows[i]);
    if (r >= p->lo && r < p->hi) {
      p->own_rows[p->nown] = r;
      p->own_vals[p->nown++] = p->bc_vals[i];
    }
  }
  return 0;
}

/* ---------------------------------------------------------------- assembly */

/* the unknowns' values (and their '-' side copies', for interior facet terms) from state */
int lg_problem_bind_unknowns(lg_problem *p, const double *state, coef_binding *extra) {
  int n = 0;
  for (int a = 0; a < p->cols.n; a++) {
    extra[n].func = p->cols.func[a];
    extra[n].dm = p->cdm[a];
    extra[n++].vals = state + p->cglob[a];
    expr_func_info *fi = expr_func_get(p->env->c, p->cols.func[a]);
    if (fi && fi->twin >= 0) {
      extra[n] = extra[n - 1];
      extra[n++].func = fi->twin;
    }
  }
  return n;
}

/* the centre of cell c, for messages */
static void cell_centre(const mesh *m, int c, char *buf, size_t len) {
  double x[3] = {0, 0, 0};
  for (int i = 0; i < m->nvc; i++)
    for (int d = 0; d < m->dim; d++) x[d] += m->x[(size_t)m->cells[(size_t)c * m->nvc + i] * m->dim + d] / m->nvc;
  if (m->dim == 2) snprintf(buf, len, "cell %d, near (%g, %g)", c + 1, x[0], x[1]);
  else snprintf(buf, len, "cell %d, near (%g, %g, %g)", c + 1, x[0], x[1], x[2]);
}

/* element tensors of term t (size values per item) all finite, or a message saying where */
/* items first .. first + n - 1 of a term (v: their tensors) */
static int check_element_tensors(lg_env *env, lg_problem *p, int term, int first, int n, const double *v, int size,
                                 const char *what) {
  const prob_term *t = &p->t[term];
  /* first a branch-free pass with four sums of x - x (0 for a finite x, NaN for an infinite
   * or NaN one; the per-value isfinite branch was 13% of a P1 reassembly), then the search
   * for the culprit only when needed */
  double z0 = 0, z1 = 0, z2 = 0, z3 = 0;
  const size_t nv = (size_t)n * (size_t)size;
  size_t i = 0;
  for (; i + 4 <= nv; i += 4) {
    z0 += v[i] - v[i];
    z1 += v[i + 1] - v[i + 1];
    z2 += v[i + 2] - v[i + 2];
    z3 += v[i + 3] - v[i + 3];
  }
  for (; i < nv; i++) z0 += v[i] - v[i];
  if (z0 + z1 + z2 + z3 == 0) return 0;
  for (int it = 0; it < n; it++)
    for (int k = 0; k < size; k++)
      if (!isfinite(v[(size_t)it * size + k])) {
        char at[128];
        cell_centre(p->lm->m, t->cells[first + it], at, sizeof at);
        lg_seterr(env, "the %s is not finite (%g) in %s, from term %d of the equation: the integrand is not finite "
                       "there (a division by zero, the log or square root of a negative value, an overflow?)",
                  what, v[(size_t)it * size + k], at, term + 1);
        return 1;
      }
  return 0;
}

/* a run of element tensors of a term, checked, and their rows in the window added in place
 * into the matrix's value array or the vector (lg_assemble_chunks: each window's runs in
 * item order, windows on any thread) */
typedef struct {
  lg_env *env;
  lg_problem *p;
  int term;
  PetscScalar *a; /* matrices: a serial run's values */
  double *r;      /* vectors */
  PetscScalar *da, *oa; /* matrices: a parallel run's diagonal and off-diagonal blocks' values */
} scatter_ctx;

/* the element matrices of items first .. first + n - 1 into the value array a: each entry
 * at its row's start plus its rank (times B) (T: the ranks' type). B = 1: the element rows'
 * rows read one after another, their starts from csr_i; B > 1: a node row's start and length from its node */
#define SCATTER_RANKS(T)                                                                            \
  do {                                                                                              \
    const T *rk = (const T *)p->rank + t->rank_off + (size_t)first * (size_t)(rn * cn);            \
    if (B == 1) {                                                                                   \
      const PetscInt *rs = t->rows + (size_t)first * (size_t)rn;              \
      const double *vr = v;                                                                         \
      if (cn == 4) /* P1 tetrahedra, Q1 quadrilaterals: straight-line code */                     \
        for (size_t er = 0, ner = (size_t)n * rn; er < ner; er++, rk += 4, vr += 4) {               \
          if (rs[er] < 0 || !LG_IN_WINDOW(ew, er, w)) continue; /* another rank's or window's row */ \
          PetscScalar *row0 = a + ia[rs[er]];                                                       \
          row0[rk[0]] += vr[0]; row0[rk[1]] += vr[1]; row0[rk[2]] += vr[2]; row0[rk[3]] += vr[3];   \
        }                                                                                           \
      else                                                                                          \
        for (size_t er = 0, ner = (size_t)n * rn; er < ner; er++, rk += cn, vr += cn) {             \
          if (rs[er] < 0 || !LG_IN_WINDOW(ew, er, w)) continue;                                     \
          PetscScalar *row0 = a + ia[rs[er]];                                                       \
          for (int j = 0; j < cn; j++) row0[rk[j]] += vr[j];                                        \
        }                                                                                           \
      break;                                                                                        \
    }                                                                                               \
    PetscInt R[KER_MAXFIELD * FEM_MAXLOC * 2];                                                      \
    for (int e = 0; e < n; e++, rk += rn * cn) {                                                    \
      const double *ve = v + (size_t)e * size;                                                      \
      lg_term_nodes(p, t, first + e, 1, B, 1, R);                                                   \
      for (int i = 0; i < rn; i++) {                                                                \
        if (R[i] < R0 || R[i] >= R1 || !LG_IN_WINDOW(ew, e * rn + i, w)) continue;                  \
        const T *ri = rk + i * cn;                                                                  \
        const PetscInt *ir = ia + (size_t)(R[i] - R0) * B;                                         \
        PetscScalar *row0 = a + ir[0];                                                              \
        PetscInt stride = ir[1] - ir[0];                                                            \
        for (int r = 0; r < B; r++) {                                                               \
          const double *vr = ve + (size_t)(i * B + r) * cs;                                         \
          PetscScalar *dr = row0 + r * stride;                                                      \
          if (B == 3)                                                                               \
            for (int j = 0; j < cn; j++) {                                                          \
              PetscScalar *dst = dr + 3 * (size_t)ri[j];                                            \
              dst[0] += vr[3 * j]; dst[1] += vr[3 * j + 1]; dst[2] += vr[3 * j + 2];                \
            }                                                                                       \
          else                                                                                      \
            for (int j = 0; j < cn; j++)                                                            \
              for (int c = 0; c < B; c++) dr[(size_t)ri[j] * B + c] += vr[j * B + c];               \
        }                                                                                           \
      }                                                                                             \
    }                                                                                               \
  } while (0)

/* the same into a parallel run's split blocks. B = 1: element rows one after another, as
 * SCATTER_RANKS; a row with no off-diagonal entries (inside the part) adds into its diagonal
 * block with no per-entry choice (a generic loop here was 39% of a rank's profile). B > 1:
 * a node's rows from its node */
#define SCATTER_SPLIT(T)                                                                            \
  do {                                                                                              \
    const T *rk = (const T *)p->rank + t->rank_off + (size_t)first * (size_t)(rn * cn);             \
    if (B == 1) {                                                                                   \
      const PetscInt *rs = t->rows + (size_t)first * (size_t)rn;               \
      const double *vr = v;                                                                         \
      for (size_t er = 0, ner = (size_t)n * rn; er < ner; er++, rk += cn, vr += cn) {               \
        PetscInt row = rs[er];                                                                      \
        if (row < 0 || !LG_IN_WINDOW(ew, er, w)) continue; /* another rank's or window's row */     \
        if (p->so_i[row + 1] == p->so_i[row]) {                                                     \
          PetscScalar *dd = da + p->sd_i[row];                                                      \
          if (cn == 4) { dd[rk[0]] += vr[0]; dd[rk[1]] += vr[1]; dd[rk[2]] += vr[2]; dd[rk[3]] += vr[3]; } \
          else                                                                                      \
            for (int j = 0; j < cn; j++) dd[rk[j]] += vr[j];                                        \
          continue;                                                                                 \
        }                                                                                           \
        lg_split_row S = lg_split_row_at(p, row, da, oa);                                           \
        for (int j = 0; j < cn; j++) *lg_split_row_entry(&S, (PetscInt)rk[j]) += vr[j];             \
      }                                                                                             \
      break;                                                                                        \
    }                                                                                               \
    PetscInt R[KER_MAXFIELD * FEM_MAXLOC * 2];                                                      \
    for (int e = 0; e < n; e++, rk += rn * cn) {                                                    \
      const double *ve = v + (size_t)e * size;                                                      \
      lg_term_nodes(p, t, first + e, 1, B, 1, R);                                                   \
      for (int i = 0; i < rn; i++) {                                                                \
        if (R[i] < R0 || R[i] >= R1 || !LG_IN_WINDOW(ew, e * rn + i, w)) continue;                  \
        const T *ri = rk + i * cn;                                                                  \
        for (int r = 0; r < B; r++) {                                                               \
          lg_split_row S = lg_split_row_at(p, (R[i] - R0) * B + r, da, oa);                         \
          const double *vr = ve + (size_t)(i * B + r) * cs;                                         \
          for (int j = 0; j < cn; j++)                                                              \
            for (int c = 0; c < B; c++) *lg_split_row_entry(&S, (PetscInt)ri[j] * B + c) += vr[j * B + c]; \
        }                                                                                           \
      }                                                                                             \
    }                                                                                               \
  } while (0)

static int scatter_matrix_chunk(void *ud, int first, int n, const double *v, const unsigned char *ew, int w) {
  scatter_ctx *sc = ud;
  lg_problem *p = sc->p;
  const prob_term *t = &p->t[sc->term];
  int size = t->rl.size * t->cl.size;
  if (check_element_tensors(sc->env, p, sc->term, first, n, v, size, p->nonlinear ? "Jacobian" : "matrix")) return 1;
  PetscScalar *a = sc->a;
  const PetscInt *ia = p->csr_i;
  int B = lg_matrix_block_size(p), rn = t->rl.size / B, cn = t->cl.size / B, cs = t->cl.size;
  int R0 = p->lo / B, R1 = p->hi / B; /* the owned node rows */
  if (p->par) {
    PetscScalar *da = sc->da, *oa = sc->oa;
    if (p->rank_w == 1) SCATTER_SPLIT(uint8_t);
    else if (p->rank_w == 2) SCATTER_SPLIT(uint16_t);
    else SCATTER_SPLIT(uint32_t);
  } else if (p->rank_w == 1) SCATTER_RANKS(uint8_t);
  else if (p->rank_w == 2) SCATTER_RANKS(uint16_t);
  else SCATTER_RANKS(uint32_t);
  return 0;
}
#undef SCATTER_RANKS
#undef SCATTER_SPLIT

static int scatter_vector_chunk(void *ud, int first, int n, const double *v, const unsigned char *ew, int w) {
  scatter_ctx *sc = ud;
  lg_problem *p = sc->p;
  const prob_term *t = &p->t[sc->term];
  int size = t->rl.size;
  if (check_element_tensors(sc->env, p, sc->term, first, n, v, size, p->nonlinear ? "residual" : "right-hand side")) return 1;
  PetscInt rg[2 * KER_MAXFIELD * FEM_MAXLOC * FEM_MAXBS];
  for (int e = 0; e < n; e++) {
    const double *ev = v + (size_t)e * size;
    lg_term_nodes(p, t, first + e, 1, 1, 0, rg);
    for (int k = 0; k < size; k++)
      if (LG_IN_WINDOW(ew, (size_t)e * size + k, w)) sc->r[rg[k]] += ev[k];
  }
  return 0;
}

/* an item's element rows for the windows (lg_item_rows): the matrix's owned node rows from
 * 0 (B rows per node; another rank's: -1), the vector's problem dofs */
static int matrix_item_rows(void *ud, int it, int *rows) {
  const scatter_ctx *sc = ud;
  const lg_problem *p = sc->p;
  const prob_term *t = &p->t[sc->term];
  int B = lg_matrix_block_size(p), R0 = p->lo / B, R1 = p->hi / B, rn = t->rl.size / B;
  PetscInt R[KER_MAXFIELD * FEM_MAXLOC * 2];
  lg_term_nodes(p, t, it, 1, B, 1, R);
  for (int i = 0; i < rn; i++) rows[i] = R[i] >= R0 && R[i] < R1 ? (int)(R[i] - R0) : -1;
  return rn;
}

static int vector_item_rows(void *ud, int it, int *rows) {
  const scatter_ctx *sc = ud;
  const prob_term *t = &sc->p->t[sc->term];
  PetscInt rg[2 * KER_MAXFIELD * FEM_MAXLOC * FEM_MAXBS];
  lg_term_nodes(sc->p, t, it, 1, 1, 0, rg);
  for (int k = 0; k < t->rl.size; k++) rows[k] = (int)rg[k];
  return t->rl.size;
}

int lg_problem_assemble_into(lg_env *env, lg_problem *p, const double *state, Mat A) {
  coef_binding extra[2 * KER_MAXFIELD], bind[KER_MAXCOEF];
  if (A == p->A) p->a_version++;
  int ne = lg_problem_bind_unknowns(p, state, extra);
  /* element matrices a chunk of items at a time, added in place into the value array (no
   * per-entry buffer beyond two chunks) */
  /* a serial run adds into the matrix's own value array; a parallel one into its diagonal
   * and off-diagonal blocks (split arrays) */
  PetscScalar *a = NULL, *da = NULL, *oa = NULL;
  if (p->par) {
    if (A != p->A) { lg_seterr(env, "the matrix assembly: a parallel run assembles only the problem's own matrix"); return 1; }
    if (lg_problem_split_open(env, p, &da, &oa)) return 1;
  } else {
    PCHK(MatSeqAIJGetArray(A, &a), "matrix assembly");
    memset(a, 0, sizeof(PetscScalar) * (size_t)p->nnz);
  }
  int rc = 0;
  for (int i = 0; i < p->nterm && !rc; i++) {
    prob_term *t = &p->t[i];
    if (!t->have_mat) continue;
    scatter_ctx sc = {env, p, i, a, NULL, da, oa};
    int B = lg_matrix_block_size(p);
    lg_consumer cons = {scatter_matrix_chunk, matrix_item_rows, (p->hi - p->lo) / B, &sc, &t->wmat, &p->chunks, 0};
    rc = lg_bind_discrete(env, p->lm, &t->kmat, ne, extra, bind) ||
         lg_assemble_chunks(env, p->lm, &t->kmat, t->nitems, t->cells, t->facets, bind, &cons);
  }
  if (!p->par) PCHK(MatSeqAIJRestoreArray(A, &a), "matrix assembly");
  else if (lg_problem_split_close(env, p, da, oa, !rc)) return 1;
  return rc;
}

/* R(state) into r (N), before boundary conditions */
int lg_problem_residual_into(lg_env *env, lg_problem *p, const double *state, double *r) {
  coef_binding extra[2 * KER_MAXFIELD], bind[KER_MAXCOEF];
  int ne = lg_problem_bind_unknowns(p, state, extra);
  memset(r, 0, sizeof(double) * (size_t)p->N);
  for (int i = 0; i < p->nterm; i++) {
    prob_term *t = &p->t[i];
    if (!t->have_res) continue;
    scatter_ctx sc = {env, p, i, NULL, r, NULL, NULL};
    lg_consumer cons = {scatter_vector_chunk, vector_item_rows, p->N, &sc, &t->wres, &p->chunks, 0};
    if (lg_bind_discrete(env, p->lm, &t->kres, ne, extra, bind) ||
        lg_assemble_chunks(env, p->lm, &t->kres, t->nitems, t->cells, t->facets, bind, &cons))
      return 1;
  }
  return 0;
}

int lg_problem_assemble_matrix(lg_env *env, lg_problem *p, double *ms) {
  double t0 = lg_now_ms();
  p->matrix_fp = 0;
  p->adj_stale = 1;
  if (lg_problem_assemble_into(env, p, p->state, p->A)) return 1;
  if (ms) *ms = lg_now_ms() - t0;
  return 0;
}

/* this rank's owned rows of p's matrix into the dense n x n array, rows and columns at
 * order[] (a distributed problem) or the problem's own numbering */
static int dense_rows(lg_env *env, lg_problem *p, double *dense, int n, const int *order) {
  memset(dense, 0, sizeof(double) * (size_t)n * (size_t)n);
  for (PetscInt i = p->lo; i < p->hi; i++) {
    PetscInt nc;
    const PetscInt *cols;
    const PetscScalar *vals;
    PCHK(MatGetRow(p->A, i, &nc, &cols, &vals), "MatGetRow");
    for (PetscInt k = 0; k < nc; k++) {
      PetscInt r = order ? order[i] : lg_problem_row(p, i), c = order ? order[cols[k]] : lg_problem_row(p, cols[k]);
      dense[(size_t)r * n + c] = vals[k];
    }
    PCHK(MatRestoreRow(p->A, i, &nc, &cols, &vals), "MatRestoreRow");
  }
  return 0;
}

int lg_problem_dense_matrix(lg_env *env, lg_problem *p, double *dense, int n) {
  if (n != p->Nglob) { lg_seterr(env, "dense matrix size %d != %d", n, p->Nglob); return 1; }
  p->matrix_fp = 0;
  p->adj_stale = 1;
  if (lg_problem_assemble_into(env, p, p->state, p->A)) return 1;
  /* a distributed problem's rows and columns in its fields' gathered order (f:values()'s),
   * which does not depend on the number of ranks */
  int *order = p->lm->dist ? malloc(sizeof(int) * ((size_t)n + 1)) : NULL;
  if (p->lm->dist && (!order || lg_dist_problem_order(env, p, order))) {
    if (!order) lg_seterr(env, "out of memory for a dense matrix's order");
    free(order);
    return 1;
  }
  int rc = dense_rows(env, p, dense, n, order);
  free(order);
  if (rc) return 1;
  /* every rank its rows: the whole matrix on every rank */
  for (size_t at = 0, all = (size_t)n * (size_t)n; p->par && at < all; at += 1 << 24)
    if (lg_allreduce(dense + at, (int)(all - at < (1u << 24) ? all - at : 1u << 24), LG_SUM)) {
      lg_seterr(env, "the reduction of the dense matrix failed");
      return 1;
    }
  return 0;
}

/* ---------------------------------------------------------------- derived operators */

int lg_problem_fields(const lg_problem *p, lg_field_info *f) {
  for (int a = 0; a < p->cols.n; a++) {
    f[a].test = p->test[a];
    f[a].unknown = p->unk[a];
    f[a].dm = p->cdm[a];
    f[a].offset = p->cglob[a];
  }
  return p->cols.n;
}

const form *lg_problem_equation(const lg_problem *p) { return p->eqn; }
const form *lg_problem_bcs(const lg_problem *p) { return p->bcf; }
lg_mesh *lg_problem_mesh(const lg_problem *p) { return p->lm; }
int lg_problem_is_nonlinear(const lg_problem *p) { return p->nonlinear; }

const double *lg_problem_solution(const lg_problem *p) { return p->have_solution ? p->solution : NULL; }

int lg_problem_essential_rows(const lg_problem *p, int *rows, int max) {
  for (int i = 0; i < p->nbc && i < max; i++) rows[i] = (int)p->bc_rows[i];
  return p->nbc;
}

void lg_problem_zero_essential(const lg_problem *p, double *v) {
  for (int i = 0; i < p->nbc; i++) v[p->bc_rows[i]] = 0;
}

/* ---- essential values that depend on a control (Dirichlet controls) */

static expr *control_leaf(lg_env *env, int fid, int param) {
  unsigned char z[3] = {0, 0, 0};
  return fid >= 0 ? expr_field(env->c, fid, 0, z) : expr_param(env->c, param);
}

int lg_problem_bc_symmetric(const lg_problem *p) { return p->bc_symmetric; }

int lg_problem_bc_dependence(lg_env *env, const lg_problem *p, int fid, int param) {
  int dep = 0;
  expr *leaf = control_leaf(env, fid, param);
  for (int i = 0; i < p->nbct && leaf; i++) {
    expr *g = p->bct[i].g, *lv[64];
    if (fid >= 0) {
      int n = expr_collect_fields(env->c, 1, &g, fid, 64, lv);
      for (int k = 0; k < n && k < 64; k++)
        if (lv[k]->order) {
          expr_func_info *fi = expr_func_get(env->c, fid);
          lg_seterr(env, "the control %s enters essential condition %d through a derivative: a Dirichlet control gives "
                         "the value itself", fi ? fi->name : "?", p->bct[i].src + 1);
          return -1;
        }
      if (!n) continue;
    }
    expr *d = expr_diff(env->c, g, leaf);
    if (!d) { lg_seterr(env, "%s", expr_error(env->c)); return -1; }
    if (d->kind == E_CONST && d->value == 0) continue;
    expr *dd = expr_diff(env->c, d, leaf);
    if (!dd) { lg_seterr(env, "%s", expr_error(env->c)); return -1; }
    int lin = dd->kind == E_CONST && dd->value == 0;
    if (!lin || !dep) dep = lin ? 1 : 2;
  }
  if (!leaf) { lg_seterr(env, "%s", expr_error(env->c)); return -1; }
  return dep;
}

int lg_problem_bc_mixed(lg_env *env, const lg_problem *p, int fid1, int param1, int fid2, int param2) {
  expr *l1 = control_leaf(env, fid1, param1), *l2 = control_leaf(env, fid2, param2);
  if (!l1 || !l2) { lg_seterr(env, "%s", expr_error(env->c)); return -1; }
  for (int i = 0; i < p->nbct; i++) {
    expr *d = expr_diff(env->c, p->bct[i].g, l1);
    expr *dd = d ? expr_diff(env->c, d, l2) : NULL;
    if (!dd) { lg_seterr(env, "%s", expr_error(env->c)); return -1; }
    if (!(dd->kind == E_CONST && dd->value == 0)) return 1;
  }
  return 0;
}

int lg_problem_row_owned(const lg_problem *p, int r) {
  PetscInt g = lg_petsc_row(p, r);
  return !p->par || (g >= p->lo && g < p->hi);
}

int lg_problem_bc_derivative(lg_env *env, lg_problem *p, int fid, int param, int **rows, int **cols, double **vals) {
  *rows = *cols = NULL;
  *vals = NULL;
  /* the tapes of dg/dcontrol per bc term, once */
  int slot = -1;
  for (int k = 0; k < p->nbcd; k++)
    if (p->bcd[k].fid == fid && p->bcd[k].param == param) slot = k;
  if (slot < 0) {
    if (p->nbcd == LG_BCD_CACHE) { lg_seterr(env, "at most %d controls in the essential conditions", LG_BCD_CACHE); return -1; }
    expr *leaf = control_leaf(env, fid, param);
    expr_tape *t = calloc((size_t)p->nbct + 1, sizeof(expr_tape));
    if (!leaf || !t) { free(t); lg_seterr(env, "out of memory"); return -1; }
    for (int i = 0; i < p->nbct; i++) {
      expr *d = expr_diff(env->c, p->bct[i].g, leaf);
      if (!d || expr_tape_build(env->c, 1, &d, &t[i])) {
        for (int j = 0; j < i; j++) expr_tape_free(&t[j]);
        free(t);
        lg_seterr(env, "%s", expr_error(env->c));
        return -1;
      }
    }
    slot = p->nbcd++;
    p->bcd[slot].fid = fid;
    p->bcd[slot].param = param;
    p->bcd[slot].n = p->nbct;
    p->bcd[slot].tape = t;
  }
  lg_function *fn = NULL;
  if (fid >= 0) {
    expr_func_info *fi = expr_func_get(env->c, fid);
    fn = fi ? fi->user : NULL;
    if (!fn) { lg_seterr(env, "the control has no values"); return -1; }
  }
  int per = fn ? fn->dm->nloc : 1;
  size_t cap = (size_t)p->nbc * (size_t)per + 1;
  int *r = malloc(sizeof(int) * cap), *c = malloc(sizeof(int) * cap);
  double *v = malloc(sizeof(double) * cap);
  size_t wn = 1;
  for (int i = 0; i < p->nbct; i++) wn = (size_t)p->bcd[slot].tape[i].n + 1 > wn ? (size_t)p->bcd[slot].tape[i].n + 1 : wn;
  double *w = malloc(sizeof(double) * wn);
  if (!r || !c || !v || !w) { free(r); free(c); free(v); free(w); lg_seterr(env, "out of memory"); return -1; }
  int n = 0;
  mesh *m = p->lm->m;
  for (int q = 0; q < p->nbc; q++) {
    int t = p->bc_org[3 * q], cell = p->bc_org[3 * q + 1], k = p->bc_org[3 * q + 2];
    bc_term *bt = &p->bct[t];
    dofmap *dm = p->rdm[bt->field];
    bc_pt pt = {env, p, cell, {0, 0, 0}, {0, 0, 0}, {{0}}};
    double J[3][3], d;
    memcpy(pt.xi, dofmap_node_ref(dm, k), sizeof pt.xi);
    cell_jacobian(m, cell, pt.xi, J, pt.K);
    dofmap_node_coords(dm, cell, k, pt.x);
    if (expr_tape_eval(&p->bcd[slot].tape[t], expr_param_values(env->c), bc_leaf, &pt, w, &d)) {
      free(r); free(c); free(v); free(w);
      return -1;
    }
    if (!isfinite(d)) {
      free(r); free(c); free(v); free(w);
      lg_seterr(env, "the derivative of essential condition %d with respect to the control is not finite at (%g, %g)", bt->src + 1,
                pt.x[0], pt.x[1]);
      return -1;
    }
    if (d == 0) continue;
    if (!fn) { r[n] = (int)p->bc_rows[q]; c[n] = 0; v[n++] = d; continue; }
    double phi[FEM_MAXLOC], grad[FEM_MAXLOC * 3];
    lagrange_eval(&fn->dm->el, pt.xi, phi, grad);
    const int *cd = fn->dm->cell_dofs + (size_t)cell * fn->dm->nloc;
    for (int j = 0; j < fn->dm->nloc; j++)
      if (fabs(phi[j]) > 1e-14) { r[n] = (int)p->bc_rows[q]; c[n] = cd[j]; v[n++] = d * phi[j]; }
  }
  free(w);
  *rows = r;
  *cols = c;
  *vals = v;
  return n;
}

int lg_problem_bind_state(const lg_problem *p, coef_binding *b) {
  return lg_problem_bind_unknowns((lg_problem *)p, p->solution, b);
}

int lg_problem_bind_values(const lg_problem *p, const double *u, coef_binding *b) {
  return lg_problem_bind_unknowns((lg_problem *)p, u, b);
}

