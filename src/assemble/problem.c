/* problem.c — linear and nonlinear problems on PETSc: linearization of the equation into
 * coefficient tables, kernels, CSR assembly (the pattern from the dof maps, element entries
 * added in place), essential boundary conditions by row replacement, KSP and SNES
 * solves with failures reported, never ignored. */
#include "problem_int.h"
#include "solver.h"

#include <ctype.h>
#include <math.h>
#include <stdint.h>
#include <petscsnes.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>


int lg_petsc_fail(lg_env *env, PetscErrorCode ierr, const char *what) {
  const char *text = NULL;
  PetscErrorMessage(ierr, &text, NULL);
  lg_seterr(env, "%s failed: %s", what, text ? text : "PETSc error");
  return 1;
}

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

static int compute_bcs(lg_env *env, lg_problem *p) {
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

/* the rows this rank owns: whole nodes (B rows each), the nodes split evenly over the ranks
 * in their global order (a serial run owns them all) */
static void set_ownership(lg_problem *p) {
  int size = lg_mpi_size(), rank = lg_mpi_rank(), B = lg_matrix_block_size(p), Nn = p->N / B;
  p->par = size > 1;
  long first = (long)Nn * rank / size, last = (long)Nn * (rank + 1) / size;
  p->lo = (int)first * B;
  p->hi = (int)last * B;
}

/* a parallel run: each term keeps the items that touch an owned row (in their order, so
 * that each matrix entry sums its contributions in the serial run's order) */
static void restrict_items(lg_problem *p) {
  PetscInt rg[2 * KER_MAXFIELD * FEM_MAXLOC * FEM_MAXBS];
  for (int i = 0; i < p->nterm; i++) {
    prob_term *t = &p->t[i];
    int n = 0, two = t->interior;
    for (int it = 0; it < t->nitems; it++) {
      lg_term_nodes(p, t, it, 1, 1, rg);
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
  double t0 = now_ms();
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
  ph[0] = now_ms();
  if (layout(env, s->mesh, s->nfield, s->test, &p->rows, p->rdm, p->rglob, "test")) goto fail;
  if (layout(env, s->mesh, s->nfield, s->unknown, &p->cols, p->cdm, p->cglob, "unknown")) goto fail;
  p->N = p->rglob[s->nfield];
  if (!s->eqn || s->eqn->n == 0) { lg_seterr(env, "the equation has no integrals"); goto fail; }
  ph[1] = now_ms();
  set_ownership(p);
  if (setup_terms(env, p, s->eqn, s->test, s->unknown, s->nfield)) goto fail;
  if (p->par) restrict_items(p);
  ph[2] = now_ms();
  if (setup_bcs(env, p, s->bc, s->test, s->unknown, s->nfield)) goto fail;
  ph[3] = now_ms();
  if (lg_problem_setup_matrix(env, p)) goto fail;
  if (lg_problem_setup_nullspace(env, p, s)) goto fail;
  ph[4] = now_ms();
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
            p->N, (long)p->ncoo, env->nkernels, env->kernel_ms, now_ms() - t0, ph[1] - ph[0], ph[2] - ph[1],
            ph[3] - ph[2], ph[4] - ph[3]);
  if (env->verbose)
    fprintf(stderr, "[lugal] sparsity and matrix: pattern %.2f ms (%ld nonzeros, %d thread%s), PETSc matrix %.2f ms, near null space %.2f ms\n",
            p->setup_ms[0], (long)p->nnz, p->pattern_threads, p->pattern_threads == 1 ? "" : "s", p->setup_ms[1], p->setup_ms[2]);
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
  free(p);
}

int lg_problem_size(const lg_problem *p) { return p->N; }

long lg_problem_nnz(const lg_problem *p) {
  MatInfo info;
  if (!p->A || MatGetInfo(p->A, MAT_GLOBAL_SUM, &info)) return -1;
  return (long)info.nz_used;
}

/* ---------------------------------------------------------------- distributed vectors */

int lg_problem_vec_set(lg_env *env, lg_problem *p, Vec v, const double *whole) {
  PetscScalar *a;
  PCHK(VecGetArray(v, &a), "VecGetArray");
  memcpy(a, whole + p->lo, sizeof(double) * (size_t)(p->hi - p->lo));
  PCHK(VecRestoreArray(v, &a), "VecRestoreArray");
  return 0;
}

int lg_problem_vec_get(lg_env *env, lg_problem *p, Vec v, double *whole) {
  Vec src = v; /* a serial run's vector is whole already */
  if (p->par) {
    if (!p->to_all) PCHK(VecScatterCreateToAll(v, &p->to_all, &p->whole), "VecScatterCreateToAll");
    PCHK(VecScatterBegin(p->to_all, v, p->whole, INSERT_VALUES, SCATTER_FORWARD), "VecScatterBegin");
    PCHK(VecScatterEnd(p->to_all, v, p->whole, INSERT_VALUES, SCATTER_FORWARD), "VecScatterEnd");
    src = p->whole;
  }
  const PetscScalar *a;
  PCHK(VecGetArrayRead(src, &a), "VecGetArrayRead");
  memcpy(whole, a, sizeof(double) * (size_t)p->N);
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
  for (int i = 0; i < p->nbc; i++)
    if (p->bc_rows[i] >= p->lo && p->bc_rows[i] < p->hi) {
      p->own_rows[p->nown] = p->bc_rows[i];
      p->own_vals[p->nown++] = p->bc_vals[i];
    }
  return 0;
}

/* ---------------------------------------------------------------- assembly */

/* the unknowns' values (and their '-' side copies', for interior facet terms) from state */
static int bind_unknowns(lg_problem *p, const double *state, coef_binding *extra) {
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

/* one chunk of element tensors of a term, checked and added in place into the matrix's
 * value array or the vector (lg_assemble_chunks calls it in item order on one thread while
 * the others compute the next chunk) */
typedef struct {
  lg_env *env;
  lg_problem *p;
  int term;
  PetscScalar *a; /* matrices */
  double *r;      /* vectors */
} scatter_ctx;

/* the element matrices of items first .. first + n - 1 into the value array a: each entry
 * at its row's start plus its rank (times B) (T: the ranks' type). B = 1: the element rows'
 * starts read one after another; B > 1: a node row's start and length from its node */
#define SCATTER_RANKS(T)                                                                            \
  do {                                                                                              \
    const T *rk = (const T *)p->rank + t->rank_off + (size_t)first * (size_t)(rn * cn);            \
    if (B == 1) {                                                                                   \
      const PetscInt *rs = p->row_start + t->erow_first + (size_t)first * (size_t)rn;              \
      const double *vr = v;                                                                         \
      if (cn == 4) /* P1 tetrahedra, Q1 quadrilaterals: straight-line code */                     \
        for (size_t er = 0, ner = (size_t)n * rn; er < ner; er++, rk += 4, vr += 4) {               \
          if (rs[er] < 0) continue; /* another rank's row */                                       \
          PetscScalar *row0 = a + rs[er];                                                           \
          row0[rk[0]] += vr[0]; row0[rk[1]] += vr[1]; row0[rk[2]] += vr[2]; row0[rk[3]] += vr[3];   \
        }                                                                                           \
      else                                                                                          \
        for (size_t er = 0, ner = (size_t)n * rn; er < ner; er++, rk += cn, vr += cn) {             \
          if (rs[er] < 0) continue;                                                                 \
          PetscScalar *row0 = a + rs[er];                                                           \
          for (int j = 0; j < cn; j++) row0[rk[j]] += vr[j];                                        \
        }                                                                                           \
      break;                                                                                        \
    }                                                                                               \
    PetscInt R[KER_MAXFIELD * FEM_MAXLOC * 2];                                                      \
    for (int e = 0; e < n; e++, rk += rn * cn) {                                                    \
      const double *ve = v + (size_t)e * size;                                                      \
      lg_term_nodes(p, t, first + e, 1, B, R);                                                      \
      for (int i = 0; i < rn; i++) {                                                                \
        if (R[i] < R0 || R[i] >= R1) continue; /* another rank's row */                             \
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

static int scatter_matrix_chunk(void *ud, int first, int n, const double *v) {
  scatter_ctx *sc = ud;
  lg_problem *p = sc->p;
  const prob_term *t = &p->t[sc->term];
  int size = t->rl.size * t->cl.size;
  if (check_element_tensors(sc->env, p, sc->term, first, n, v, size, p->nonlinear ? "Jacobian" : "matrix")) return 1;
  PetscScalar *a = sc->a;
  const PetscInt *ia = p->csr_i;
  int B = lg_matrix_block_size(p), rn = t->rl.size / B, cn = t->cl.size / B, cs = t->cl.size;
  int R0 = p->lo / B, R1 = p->hi / B; /* the owned node rows */
  if (p->rank_w == 1) SCATTER_RANKS(uint8_t);
  else if (p->rank_w == 2) SCATTER_RANKS(uint16_t);
  else SCATTER_RANKS(uint32_t);
  return 0;
}
#undef SCATTER_RANKS

static int scatter_vector_chunk(void *ud, int first, int n, const double *v) {
  scatter_ctx *sc = ud;
  lg_problem *p = sc->p;
  const prob_term *t = &p->t[sc->term];
  int size = t->rl.size;
  if (check_element_tensors(sc->env, p, sc->term, first, n, v, size, p->nonlinear ? "residual" : "right-hand side")) return 1;
  PetscInt rg[2 * KER_MAXFIELD * FEM_MAXLOC * FEM_MAXBS];
  for (int e = 0; e < n; e++) {
    const double *ev = v + (size_t)e * size;
    lg_term_nodes(p, t, first + e, 1, 1, rg);
    for (int k = 0; k < size; k++) sc->r[rg[k]] += ev[k];
  }
  return 0;
}

static int assemble_matrix(lg_env *env, lg_problem *p, const double *state, Mat A) {
  coef_binding extra[2 * KER_MAXFIELD], bind[KER_MAXCOEF];
  int ne = bind_unknowns(p, state, extra);
  /* element matrices a chunk of items at a time, added in place into the value array (no
   * per-entry buffer beyond two chunks) */
  /* a serial run adds into the matrix's own value array; a parallel one into csr_a, which
   * PETSc then copies into its diagonal and off-diagonal blocks */
  PetscScalar *a = p->csr_a;
  if (!p->par) PCHK(MatSeqAIJGetArray(A, &a), "matrix assembly");
  memset(a, 0, sizeof(PetscScalar) * (size_t)p->nnz);
  int rc = 0;
  for (int i = 0; i < p->nterm && !rc; i++) {
    prob_term *t = &p->t[i];
    if (!t->have_mat) continue;
    scatter_ctx sc = {env, p, i, a, NULL};
    int size = t->rl.size * t->cl.size;
    rc = lg_chunk_bufs_reserve(env, &p->chunks, size) || lg_bind_discrete(env, p->lm, &t->kmat, ne, extra, bind) ||
         lg_assemble_chunks(env, p->lm, &t->kmat, t->nitems, t->cells, t->facets, bind, lg_chunk_items(size),
                            p->chunks.b, scatter_matrix_chunk, &sc);
  }
  if (!p->par) PCHK(MatSeqAIJRestoreArray(A, &a), "matrix assembly");
  else if (!rc) PCHK(MatUpdateMPIAIJWithArray(A, a), "matrix assembly");
  return rc;
}

/* R(state) into r (N), before boundary conditions */
static int assemble_residual(lg_env *env, lg_problem *p, const double *state, double *r) {
  coef_binding extra[2 * KER_MAXFIELD], bind[KER_MAXCOEF];
  int ne = bind_unknowns(p, state, extra);
  memset(r, 0, sizeof(double) * (size_t)p->N);
  for (int i = 0; i < p->nterm; i++) {
    prob_term *t = &p->t[i];
    if (!t->have_res) continue;
    scatter_ctx sc = {env, p, i, NULL, r};
    if (lg_chunk_bufs_reserve(env, &p->chunks, t->rl.size) || lg_bind_discrete(env, p->lm, &t->kres, ne, extra, bind) ||
        lg_assemble_chunks(env, p->lm, &t->kres, t->nitems, t->cells, t->facets, bind, lg_chunk_items(t->rl.size),
                           p->chunks.b, scatter_vector_chunk, &sc))
      return 1;
  }
  return 0;
}

int lg_problem_assemble_matrix(lg_env *env, lg_problem *p, double *ms) {
  double t0 = now_ms();
  p->matrix_fp = 0;
  p->adj_stale = 1;
  if (assemble_matrix(env, p, p->state, p->A)) return 1;
  if (ms) *ms = now_ms() - t0;
  return 0;
}

int lg_problem_dense_matrix(lg_env *env, lg_problem *p, double *dense, int n) {
  if (n != p->N) { lg_seterr(env, "dense matrix size %d != %d", n, p->N); return 1; }
  p->matrix_fp = 0;
  p->adj_stale = 1;
  if (assemble_matrix(env, p, p->state, p->A)) return 1;
  memset(dense, 0, sizeof(double) * (size_t)n * (size_t)n);
  for (PetscInt i = p->lo; i < p->hi; i++) {
    PetscInt nc;
    const PetscInt *cols;
    const PetscScalar *vals;
    PCHK(MatGetRow(p->A, i, &nc, &cols, &vals), "MatGetRow");
    for (PetscInt k = 0; k < nc; k++) dense[(size_t)i * n + cols[k]] = vals[k];
    PCHK(MatRestoreRow(p->A, i, &nc, &cols, &vals), "MatRestoreRow");
  }
  /* every rank its rows: the whole matrix on every rank */
  for (size_t at = 0, all = (size_t)n * (size_t)n; p->par && at < all; at += 1 << 24)
    if (lg_allreduce(dense + at, (int)(all - at < (1u << 24) ? all - at : 1u << 24), LG_SUM)) {
      lg_seterr(env, "the reduction of the dense matrix failed");
      return 1;
    }
  return 0;
}

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

/* a constant null space field: shift it to mean zero (Lagrange bases hold the constants:
 * subtracting c from every dof subtracts c) */
static void null_mean_zero(lg_env *env, lg_problem *p, double *x) {
  for (int a = 0; a < p->cols.n; a++) {
    if (!p->null_const[a]) continue;
    const dofmap *dm = p->cdm[a];
    int bs = dm->bs;
    for (int j = 0; j < bs; j++) {
      /* the mean of component j: the integral of the interpolant over the mesh's measure */
      double num = 0, vol = 0;
      mesh *m = p->lm->m;
      if (cell_is_simplex(m->type)) {
        for (int c = 0; c < m->ncell; c++) {
          double J[3][3], K[3][3], det = fabs(simplex_jacobian(m, c, J, K));
          double s = 0;
          const int *cd = dm->cell_dofs + (size_t)c * (size_t)dm->nloc;
          for (int k = 0; k < dm->el.nloc; k++) s += x[p->cglob[a] + cd[k * bs + j]] * dm->el.mean[k];
          num += s * det;
          vol += det;
        }
      } else {
        /* a quadrilateral's or hexahedron's Jacobian varies: a rule of the basis degree + 1 */
        quad_rule q;
        quad_cell(m->type, 0, dm->degree + 1, &q);
        for (int c = 0; c < m->ncell; c++) {
          const int *cd = dm->cell_dofs + (size_t)c * (size_t)dm->nloc;
          for (int i = 0; i < q.n; i++) {
            double J[3][3], K[3][3], val[FEM_MAXLOC], grad[FEM_MAXLOC * 3];
            double w = q.w[i] * fabs(cell_jacobian(m, c, q.x + m->dim * i, J, K)), s = 0;
            lagrange_eval(&dm->el, q.x + m->dim * i, val, grad);
            for (int k = 0; k < dm->el.nloc; k++) s += x[p->cglob[a] + cd[k * bs + j]] * val[k];
            num += w * s;
            vol += w;
          }
        }
      }
      double mean = vol > 0 ? num / vol : 0;
      for (int i = j; i < dm->ndof; i += bs) x[p->cglob[a] + i] -= mean;
    }
  }
  (void)env;
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
  const double *pv = expr_param_values(env->c);
  MIX(pv, sizeof(double) * (size_t)expr_param_count(env->c));
  coef_binding extra[2 * KER_MAXFIELD], bind[KER_MAXCOEF];
  int ne = bind_unknowns(p, p->state, extra);
  for (int i = 0; i < p->nterm; i++) {
    prob_term *t = &p->t[i];
    if (!t->have_mat) continue;
    char keep[LG_ERRLEN];
    memcpy(keep, env->err, sizeof keep);
    int rc = lg_bind_discrete(env, p->lm, &t->kmat, ne, extra, bind);
    memcpy(env->err, keep, sizeof keep);
    if (rc) return 0;
    for (int k = 0; k < t->kmat.ncoef; k++) {
      int unknown = 0;
      for (int a = 0; a < ne; a++) unknown |= bind[k].func == extra[a].func;
      if (unknown) continue; /* zero in a linear problem */
      MIX(&bind[k].vals, sizeof bind[k].vals);
      MIX(bind[k].vals, sizeof(double) * (size_t)bind[k].dm->ndof);
    }
  }
#undef MIX
  return h | 1;
}

/* the linear solver of a linear problem: direct LU by default (default_lu), every -ksp_* and
 * -pc_* option (with the problem's prefix) applied once */
static int ensure_ksp(lg_env *env, lg_problem *p) {
  if (p->ksp) return 0;
  PCHK(KSPCreate(PetscObjectComm((PetscObject)p->A), &p->ksp), "KSPCreate");
  if (p->prefix[0]) PCHK(KSPSetOptionsPrefix(p->ksp, p->prefix), "KSPSetOptionsPrefix");
  PC pc;
  PCHK(KSPSetType(p->ksp, KSPPREONLY), "KSPSetType");
  PCHK(KSPGetPC(p->ksp, &pc), "KSPGetPC");
  if (default_lu(env, p, pc)) return 1;
  PCHK(KSPSetFromOptions(p->ksp), "KSPSetFromOptions");
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
    if (lg_problem_vec_get(env, p, p->x, p->rwhole)) return 1;
    null_mean_zero(env, p, p->rwhole);
    return lg_problem_vec_set(env, p, p->x, p->rwhole);
  }
  PetscScalar *x;
  PCHK(VecGetArray(p->x, &x), "VecGetArray");
  null_mean_zero(env, p, x);
  PCHK(VecRestoreArray(p->x, &x), "VecRestoreArray");
  return 0;
}

/* one KSPSolve of a linear problem with its checks: 0, 1 with a message, or 2 when the
 * default PETSc LU failed and MUMPS should try (lg_lu_fallback) */
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
      if (p->nnull)
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
static int keep_bc_columns(lg_env *env, lg_problem *p) {
  int *at = malloc(sizeof(int) * ((size_t)p->N + 1));
  if (!at) { lg_seterr(env, "out of memory"); return 1; }
  for (int i = 0; i < p->N; i++) at[i] = -1;
  for (int k = 0; k < p->nbc; k++) at[p->bc_rows[k]] = k;
  size_t n = 0;
  /* the assembled values, before the elimination: the matrix's own array in a serial run,
   * the array PETSc copied them from in a parallel one; the owned rows, global columns */
  const PetscScalar *av = p->csr_a;
  for (int pass = 0; pass < 2; pass++) {
    if (pass) {
      free(p->bcc_row); free(p->bcc_col); free(p->bcc_val);
      p->bcc_row = malloc(sizeof(int) * (n + 1));
      p->bcc_col = malloc(sizeof(int) * (n + 1));
      p->bcc_val = malloc(sizeof(double) * (n + 1));
      if (!p->bcc_row || !p->bcc_col || !p->bcc_val) {
        free(at);
        p->bcc_n = 0;
        lg_seterr(env, "out of memory");
        return 1;
      }
      n = 0;
    }
    for (int i = p->lo; i < p->hi; i++) {
      if (at[i] >= 0) continue;
      for (PetscInt e = p->csr_i[i - p->lo]; e < p->csr_i[i - p->lo + 1]; e++) {
        int k = at[p->csr_j[e]];
        if (k < 0 || av[e] == 0) continue;
        if (pass) { p->bcc_row[n] = i; p->bcc_col[n] = k; p->bcc_val[n] = av[e]; }
        n++;
      }
    }
  }
  p->bcc_n = n;
  free(at);
  return 0;
}

/* whether a solve with a matrix other than the factored one may iterate with the old factor
 * (solver.h, lg_keep): linear problems, unless -lugal_keep_factor 0 */
static int keep_usable(lg_env *env, lg_problem *p) {
  return !p->nonlinear && !env->no_keep_factor && lg_keep_usable(&p->keep, p->ksp, p->prefix);
}

/* b = -R(0): the right-hand side's owned part (a parallel run assembles the whole-length
 * residual, its own rows complete, and keeps those) */
static int assemble_rhs(lg_env *env, lg_problem *p) {
  PetscScalar *b;
  int n = p->hi - p->lo, rc;
  if (p->par) {
    rc = assemble_residual(env, p, p->state, p->rwhole);
    if (rc) return 1;
    PCHK(VecGetArray(p->b, &b), "VecGetArray");
    for (int i = 0; i < n; i++) b[i] = -p->rwhole[p->lo + i];
  } else {
    PCHK(VecGetArray(p->b, &b), "VecGetArray");
    rc = assemble_residual(env, p, p->state, b);
    for (int i = 0; i < n; i++) b[i] = -b[i];
  }
  PCHK(VecRestoreArray(p->b, &b), "VecRestoreArray");
  return rc;
}

static int solve_linear(lg_env *env, lg_problem *p, lg_function **out, lg_solve_info *info) {
  double t0 = now_ms();
  memset(p->state, 0, sizeof(double) * (size_t)p->N);
  uint64_t fp = matrix_fingerprint(env, p);
  int reuse = fp && fp == p->matrix_fp && p->ksp;
  p->matrix_fp = 0;
  if (!reuse) {
    p->matrix_ready = 0;
    if (assemble_matrix(env, p, p->state, p->A)) return 1;
  }
  PetscScalar *b;
  int rc = assemble_rhs(env, p);
  if (rc) return 1;
  if (compute_bcs(env, p)) return 1;
  PCHK(VecSet(p->x, 0), "VecSet");
  PCHK(VecSetValues(p->x, p->nown, p->own_rows, p->own_vals, INSERT_VALUES), "VecSetValues");
  PCHK(VecAssemblyBegin(p->x), "VecAssembly");
  PCHK(VecAssemblyEnd(p->x), "VecAssembly");
  if (reuse) { /* the rows are identity rows already: only the right-hand side's, and with
                * symmetric elimination the eliminated columns times the values */
    PCHK(VecGetArray(p->b, &b), "VecGetArray");
    for (size_t i = 0; i < p->bcc_n; i++) b[p->bcc_row[i] - p->lo] -= p->bcc_val[i] * p->bc_vals[p->bcc_col[i]];
    for (int i = 0; i < p->nown; i++) b[p->own_rows[i] - p->lo] = p->own_vals[i];
    PCHK(VecRestoreArray(p->b, &b), "VecRestoreArray");
  } else if (p->bc_symmetric) {
    if (keep_bc_columns(env, p)) return 1;
    PCHK(MatZeroRowsColumns(p->A, p->nown, p->own_rows, 1.0, p->x, p->b), "MatZeroRowsColumns");
  } else PCHK(MatZeroRows(p->A, p->nown, p->own_rows, 1.0, p->x, p->b), "MatZeroRows");
  info->assemble_ms = now_ms() - t0;
  t0 = now_ms();
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
    while ((rc = linear_solve_checked(env, p, info)) == 2)
      /* PETSc's LU (no pivoting) found a zero pivot or solved inaccurately: MUMPS, once */
      PCHK(lg_lu_fallback(p->ksp, p->A), "the switch to MUMPS");
    if (refactor && !rc) lg_keep_factored(&p->keep, p->ksp);
    lg_solver_name(p->ksp, info->solver, sizeof info->solver);
  }
  info->solve_ms = now_ms() - t0;
  if (rc) return 1;
  if (remove_null(env, p)) return 1;
  if (lg_problem_vec_get(env, p, p->x, p->solution)) return 1;
  for (int i = 0; i < p->N; i++)
    if (!isfinite(p->solution[i])) {
      lg_seterr(env, "the linear solve produced non-finite values (the system is singular or the data is not finite)");
      return 1;
    }
  p->have_solution = 1;
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
  int rc = assemble_residual(p->env, p, p->state, p->par ? p->rwhole : f);
  if (!rc && p->par)
    for (int i = p->lo; i < p->hi; i++) f[i - p->lo] = p->rwhole[i];
  if (!rc)
    for (int i = 0; i < p->nown; i++) f[p->own_rows[i] - p->lo] = p->state[p->own_rows[i]] - p->own_vals[i];
  PetscCall(VecRestoreArray(F, &f));
  if (rc) {
    p->failed = 1;
    PetscCall(SNESSetFunctionDomainError(snes));
  }
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
  if (k == 0)
    keep = p->have_solution && !p->adj_stale && P == p->A &&
           !memcmp(p->state, p->solution, sizeof(double) * (size_t)p->N) && p->adj_fp &&
           p->adj_fp == matrix_fingerprint(p->env, p);
  else
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
  if (assemble_matrix(p->env, p, p->state, P)) {
    p->failed = 1;
    PetscCall(SNESSetJacobianDomainError(snes));
    return 0;
  }
  PetscCall(MatZeroRows(P, p->nown, p->own_rows, 1.0, NULL, NULL));
  KSP ksp;
  PetscCall(SNESGetKSP(snes, &ksp));
  PetscCall(lg_lu_prepare(ksp, P, p->own_rows, p->nown, p->prefix, 0));
  return 0;
}

static int solve_nonlinear(lg_env *env, lg_problem *p, lg_function **initial, lg_function **out,
                           lg_solve_info *info, int warm) {
  double t0 = now_ms();
  if (compute_bcs(env, p)) return 1;
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
    PCHK(SNESSetFromOptions(p->snes), "SNESSetFromOptions");
  }
  static PetscReal hist[128];
  static PetscInt hits[128];
  PCHK(SNESSetConvergenceHistory(p->snes, hist, hits, 128, PETSC_TRUE), "SNESSetConvergenceHistory");
  p->failed = 0;
  p->chord = warm && p->have_solution;
  p->lag_valid = 0;
  info->setup_ms = now_ms() - t0;
  t0 = now_ms();
  PetscErrorCode ierr = SNESSolve(p->snes, NULL, p->x);
  p->chord = 0;
  info->solve_ms = now_ms() - t0;
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
  if (reason < 0 && lg_lu_native(sksp, p->prefix)) {
    /* PETSc's LU (no pivoting) may be what failed: again with MUMPS, once */
    PCHK(lg_lu_fallback(sksp, p->A), "the switch to MUMPS");
    p->adj_stale = 1;
    return solve_nonlinear(env, p, initial, out, info, warm);
  }
  if (reason < 0) {
    lg_seterr(env, "the nonlinear solve did not converge: %s after %d Newton iterations (residual %.3e)",
              info->reason, info->iterations, info->nres ? info->res[info->nres - 1] : NAN);
    return 1;
  }
  if (lg_problem_vec_get(env, p, p->x, p->solution)) return 1;
  p->have_solution = 1;
  p->adj_stale = 1;
  return out ? make_outputs(env, p, p->solution, out) : 0;
}

int lg_problem_solve(lg_env *env, lg_problem *p, lg_function **initial, lg_function **out,
                     lg_solve_info *info) {
  memset(info, 0, sizeof *info);
  if (lg_mesh_check(env, p->lm)) return 1;
  return p->nonlinear ? solve_nonlinear(env, p, initial, out, info, 0) : solve_linear(env, p, out, info);
}

int lg_problem_resolve(lg_env *env, lg_problem *p, lg_solve_info *info) {
  memset(info, 0, sizeof *info);
  if (lg_mesh_check(env, p->lm)) return 1;
  return p->nonlinear ? solve_nonlinear(env, p, NULL, NULL, info, 1) : solve_linear(env, p, NULL, info);
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
  return bind_unknowns((lg_problem *)p, p->solution, b);
}

/* the transposed Jacobian solve of the adjoint: (dR/du)^T lam = rhs at the last solution,
 * where R is the discrete residual with the essential rows u_i - g_i. A linear problem
 * reuses its factorization (KSPSolveTranspose); a nonlinear one assembles its Jacobian at
 * the solution and factors it once per solution. */
/* a solver of dR/du at the last solution: a linear problem's own (its factorization), a
 * nonlinear problem's Jacobian assembled at the solution and factored once per solution */
static int jacobian_solver(lg_env *env, lg_problem *p, KSP *out) {
  if (!p->have_solution) { lg_seterr(env, "the adjoint or sensitivity needs a solved state: solve the problem first"); return 1; }
  KSP ksp = p->ksp;
  if (p->nonlinear) {
    /* the SNES's own solver, so that the next Newton solve, warm-started at this solution,
     * finds the matrix and its factorization unchanged (snes_jacobian): one factorization
     * less per evaluation of an optimization (three were two Newton steps and this one) */
    if (!p->snes) { lg_seterr(env, "the adjoint needs a solved state: solve the problem first"); return 1; }
    PCHK(SNESGetKSP(p->snes, &ksp), "SNESGetKSP");
    if (p->adj_stale) {
      memcpy(p->state, p->solution, sizeof(double) * (size_t)p->N);
      if (assemble_matrix(env, p, p->state, p->A)) return 1;
      PCHK(MatZeroRows(p->A, p->nown, p->own_rows, 1.0, NULL, NULL), "MatZeroRows");
      PCHK(KSPSetOperators(ksp, p->A, p->A), "KSPSetOperators");
      PCHK(lg_lu_prepare(ksp, p->A, p->own_rows, p->nown, p->prefix, 0), "the factorization's choice");
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

static int solve_with_jacobian(lg_env *env, lg_problem *p, const double *rhs, double *sol, int transpose) {
  KSP ksp;
  if (jacobian_solver(env, p, &ksp)) return 1;
  double *lam = sol;
  Vec r, l;
  PCHK(VecDuplicate(p->b, &r), "VecDuplicate");
  PCHK(VecDuplicate(p->b, &l), "VecDuplicate");
  if (lg_problem_vec_set(env, p, r, rhs)) { VecDestroy(&r); VecDestroy(&l); return 1; }
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
    ierr = transpose ? KSPSolveTranspose(ksp, r, l) : KSPSolve(ksp, r, l);
    reason = KSP_CONVERGED_ITS;
    if (!ierr) KSPGetConvergedReason(ksp, &reason);
    if (ierr || reason >= 0 || !lg_lu_native(ksp, p->prefix)) break;
    /* PETSc's LU (no pivoting) failed: MUMPS, once */
    if ((ierr = lg_lu_fallback(ksp, p->A))) break;
  }
  if (!ierr && !kept && stale) lg_keep_factored(&p->keep, ksp);
  /* the next solve's initial guess, where a factor may be kept */
  if (!ierr && !p->nonlinear && !env->no_keep_factor && lg_keep_applies(ksp, p->prefix))
    ierr = lg_keep_remember(&p->keep, transpose, l);
  if (!ierr && reason >= 0 && lg_problem_vec_get(env, p, l, lam)) ierr = PETSC_ERR_LIB;
  VecDestroy(&r);
  VecDestroy(&l);
  const char *what = transpose ? "the adjoint solve" : "the sensitivity solve";
  if (ierr) return lg_petsc_fail(env, ierr, what);
  if (reason < 0) { lg_seterr(env, "%s failed: %s", what, ksp_reason_name(reason)); return 1; }
  for (int i = 0; i < p->N; i++)
    if (!isfinite(lam[i])) { lg_seterr(env, "%s produced non-finite values", what); return 1; }
  return 0;
}

int lg_problem_adjoint(lg_env *env, lg_problem *p, const double *rhs, double *lam) {
  return solve_with_jacobian(env, p, rhs, lam, 1);
}

int lg_problem_tangent(lg_env *env, lg_problem *p, const double *rhs, double *du) {
  return solve_with_jacobian(env, p, rhs, du, 0);
}

static int prepare_matrix(lg_env *env, lg_problem *p) {
  if (!p->matrix_ready) {
    if (lg_mesh_check(env, p->lm)) return 1;
    memset(p->state, 0, sizeof(double) * (size_t)p->N);
    p->matrix_fp = 0; /* A no longer holds the last solve's matrix */
    p->keep.stale = 0; /* its next solve refactors it */
    if (assemble_matrix(env, p, p->state, p->A)) return 1;
    if (compute_bcs(env, p)) return 1;
    PCHK(MatZeroRows(p->A, p->nown, p->own_rows, 1.0, NULL, NULL), "MatZeroRows");
    if (ensure_ksp(env, p)) return 1;
    PCHK(KSPSetOperators(p->ksp, p->A, p->A), "KSPSetOperators");
    PCHK(lg_lu_prepare(p->ksp, p->A, p->own_rows, p->nown, p->prefix, !p->nonlinear), "the factorization's choice");
    p->matrix_ready = 1;
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
    if (reason >= 0 || !lg_lu_native(p->ksp, p->prefix)) break;
    PCHK(lg_lu_fallback(p->ksp, p->A), "the switch to MUMPS"); /* PETSc's LU failed: MUMPS, once */
  }
  if (reason < 0) { lg_seterr(env, "a solve with the problem's matrix failed: %s", ksp_reason_name(reason)); return 1; }
  return lg_problem_vec_get(env, p, p->x, x);
}
