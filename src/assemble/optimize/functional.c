/* functional.c — functionals of the state and the controls, and what is derived from them
 * without a tape (DESIGN.md, "everything is a derivative"): compiled values and gradients of
 * forms with respect to any function, the adjoint solve, reduced functionals with value,
 * gradient and directional derivative, Riesz maps (L2, H1) of gradients, and the Taylor
 * test.
 *
 * For a state problem R(u, m) = 0 (essential rows u_i - g_i) and a functional J(u, m), the
 * reduced functional is j(m) = J(u(m), m). Its gradient comes from one adjoint solve,
 *   (dR/du)^T lam = -dJ/du,      dj/dm = dJ/dm + lam^T dR/dm,
 * where every vector is a generated kernel: dJ/du and dJ/dm are the gradient tables of J's
 * integrands (form_gradient_table), and lam^T dR/dm is the gradient with respect to m of the
 * equation with its test functions replaced by the adjoint (form_replace_function). */
#include "optimize_int.h"

#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---------------------------------------------------------------- compiled forms */

typedef struct {
  region reg;
  int nitems, *cells, *facets; /* interior facets: cells holds the '+' then the '-' cells */
  int interior;                /* arity 1: the element vector is func on '+', then on '-' */
  lg_kernel k;
  coef_table tab;
  lg_windows win;               /* arity 1: its items' windows of the dofs (lg_assemble_chunks) */
} fk_term;

struct lg_form_kernels {
  int arity;          /* 0: a number; 1: a vector in the space of func */
  int func;
  const dofmap *dm;
  int n;
  fk_term *t;
  lg_chunk_bufs chunks; /* element vectors of a run of items per thread */
};

void lg_form_kernels_free(lg_form_kernels *K) {
  if (!K) return;
  for (int i = 0; i < K->n; i++) {
    coef_table_free(&K->t[i].tab);
    kernel_release(&K->t[i].k);
    free(K->t[i].cells);
    free(K->t[i].facets);
    lg_windows_free(&K->t[i].win);
  }
  free(K->t);
  lg_chunk_bufs_free(&K->chunks);
  free(K);
}

lg_form_kernels *lg_form_kernels_new(lg_env *env, lg_mesh *lm, const form *F, int func, const dofmap *dm) {
  lg_form_kernels *K = calloc(1, sizeof *K);
  if (!K) { lg_seterr(env, "out of memory"); return NULL; }
  K->arity = func >= 0 ? 1 : 0;
  K->func = func;
  K->dm = dm;
  K->t = calloc((size_t)F->n + 1, sizeof(fk_term));
  if (!K->t) { free(K); lg_seterr(env, "out of memory"); return NULL; }
  char err[LG_ERRLEN];
  for (int i = 0; i < F->n; i++) {
    fk_term *t = &K->t[K->n];
    memset(t, 0, sizeof *t);
    t->reg = F->t[i].reg;
    if (t->reg.mesh && t->reg.mesh != (void *)lm) {
      lg_seterr(env, "term %d integrates over a region of a different mesh", i + 1);
      lg_form_kernels_free(K);
      return NULL;
    }
    expr *f = expr_canon(env->c, F->t[i].integrand);
    int qd = lg_quad_degree(env, f, F->t[i].order, lm->m->type);
    kernel_spec s = {0, NULL, f, env->no_vector_math};
    field_layout rows = {0};
    t->interior = K->arity == 1 && t->reg.kind == REGION_INTERIOR;
    if (K->arity == 1) {
      if (form_gradient_table(env->c, f, func, &t->tab)) {
        lg_seterr(env, "%s", expr_error(env->c));
        lg_form_kernels_free(K);
        return NULL;
      }
      int twin = t->interior ? expr_func_side(env->c, func, 1) : -1;
      if (t->interior && twin >= 0) {
        /* an interior facet term also depends on func's '-' side restriction: its leaves'
         * rows follow (the element vector is func on '+', then func on '-') */
        coef_table tm;
        if (form_gradient_table(env->c, f, twin, &tm)) {
          lg_seterr(env, "%s", expr_error(env->c));
          coef_table_free(&t->tab);
          lg_form_kernels_free(K);
          return NULL;
        }
        expr **rl = realloc(t->tab.res_leaf, sizeof(expr *) * (size_t)(t->tab.nres + tm.nres + 1));
        if (rl) t->tab.res_leaf = rl;
        expr **rr = realloc(t->tab.res, sizeof(expr *) * (size_t)(t->tab.nres + tm.nres + 1));
        if (rr) t->tab.res = rr;
        if (!rl || !rr) {
          coef_table_free(&tm);
          coef_table_free(&t->tab);
          lg_form_kernels_free(K);
          lg_seterr(env, "out of memory");
          return NULL;
        }
        for (int r = 0; r < tm.nres; r++) {
          t->tab.res_leaf[t->tab.nres] = tm.res_leaf[r];
          t->tab.res[t->tab.nres++] = tm.res[r];
        }
        coef_table_free(&tm);
      }
      if (t->tab.nres == 0) { coef_table_free(&t->tab); continue; } /* the term does not depend on it */
      s.arity = 1;
      s.tab = &t->tab;
      expr_func_info *fi = expr_func_get(env->c, func);
      rows.n = 1;
      rows.func[0] = func;
      rows.degree[0] = fi ? fi->degree : dm->degree;
      rows.nloc[0] = dm->nloc;
      rows.bs[0] = dm->bs;
      rows.off[0] = 0;
      rows.size = dm->nloc;
      if (t->interior) {
        rows.n = 2;
        rows.func[1] = twin;
        rows.degree[1] = rows.degree[0];
        rows.nloc[1] = dm->nloc;
        rows.bs[1] = dm->bs;
        rows.off[1] = dm->nloc;
        rows.size = 2 * dm->nloc;
      }
      /* the derivative's own, lower degree where that rule integrates it exactly and so
       * gives what the functional's rule gives (alpha/2 f^2: 2 instead of 12 with a
       * transcendental d in the same term); otherwise the functional's rule, so that the
       * gradient is the derivative of the J that was computed (a Taylor test sees any
       * difference: (u - d) v with d = sin(pi x) keeps the rule of (u - d)^2) */
      int exact = F->t[i].order < 0 && cell_is_simplex(lm->m->type); /* a box's map is not affine */
      for (int r = 0; r < t->tab.nres && exact; r++) {
        int ex;
        expr_degree_exact(env->c, t->tab.res[r], 1, &ex);
        exact = ex;
      }
      int own = lg_table_degree(env, &t->tab, 1, lm->m->type);
      if (exact && own <= qd) qd = own;
    } else if (f->kind == E_CONST && f->value == 0)
      continue;
    int facet = t->reg.kind == REGION_BOUNDARY ? 1 : t->reg.kind == REGION_INTERIOR ? 2 : 0;
    if (kernel_build(env->jit, env->c, lm->m->type, facet, qd, &s, K->arity ? &rows : NULL, NULL,
                     &t->k, err, sizeof err)) {
      lg_seterr(env, "%s", err);
      coef_table_free(&t->tab);
      lg_form_kernels_free(K);
      return NULL;
    }
    env->kernel_ms += t->k.compile_ms;
    env->nkernels += !t->k.cached;
    if (lg_region_items(env, lm, &t->reg, &t->nitems, &t->cells, &t->facets)) {
      coef_table_free(&t->tab);
      lg_form_kernels_free(K);
      return NULL;
    }
    K->n++;
  }
  return K;
}

int lg_form_kernels_empty(const lg_form_kernels *K) { return K->n == 0; }

/* a run of element vectors, their dofs in the window added into out (lg_assemble_chunks'
 * consumer) */
typedef struct {
  const lg_form_kernels *K;
  const fk_term *t;
  double *out;
  int first; /* the rank's first item (lg_assemble_share) */
} vec_ctx;

static int add_vector_chunk(void *ud, int first, int n, const double *v, const unsigned char *ew, int w) {
  const vec_ctx *vc = ud;
  const fk_term *t = vc->t;
  int nl = vc->K->dm->nloc, sides = t->interior ? 2 : 1;
  for (int it = first; it < first + n; it++)
    for (int sd = 0; sd < sides; sd++) {
      const int *cd = vc->K->dm->cell_dofs + (size_t)t->cells[sd * t->nitems + vc->first + it] * nl;
      size_t er = ((size_t)(it - first) * sides + sd) * nl;
      const double *ev = v + er;
      for (int k = 0; k < nl; k++)
        if (LG_IN_WINDOW(ew, er + k, w)) vc->out[cd[k]] += ev[k];
    }
  return 0;
}

static int vector_item_dofs(void *ud, int it, int *rows) {
  const vec_ctx *vc = ud;
  const fk_term *t = vc->t;
  int nl = vc->K->dm->nloc, sides = t->interior ? 2 : 1;
  for (int sd = 0; sd < sides; sd++) {
    const int *cd = vc->K->dm->cell_dofs + (size_t)t->cells[sd * t->nitems + vc->first + it] * nl;
    memcpy(rows + sd * nl, cd, sizeof(int) * (size_t)nl);
  }
  return sides * nl;
}

int lg_form_kernels_eval(lg_env *env, lg_mesh *lm, lg_form_kernels *K, int nextra, const coef_binding *extra, double *out) {
  coef_binding bind[KER_MAXCOEF];
  if (K->arity == 0) *out = 0;
  else memset(out, 0, sizeof(double) * (size_t)K->dm->ndof);
  /* a parallel run: each rank its share of the items, then the sum over the ranks */
  int rc = 0;
  for (int i = 0; i < K->n && !rc; i++) {
    fk_term *t = &K->t[i];
    vec_ctx vc = {K, t, out, 0};
    lg_consumer cons = {add_vector_chunk, vector_item_dofs, K->arity ? K->dm->ndof : 1, &vc, &t->win, &K->chunks, 0};
    rc = lg_bind_discrete(env, lm, &t->k, nextra, extra, bind) ||
         lg_assemble_share(env, lm, &t->k, t->nitems, t->cells, t->facets, bind, out, &cons, &vc.first);
  }
  size_t n = K->arity ? (size_t)K->dm->ndof : 1;
  if (lm->dist && K->arity) {
    /* the owned dofs' entries are complete: the ghost dofs get their owners' (every rank
     * takes part, failed or not) */
    double flag = rc;
    if (lg_allreduce(&flag, 1, LG_MAX)) { lg_seterr(env, "the maximum over the ranks failed"); return 1; }
    if (flag && !rc) { lg_seterr(env, "another rank failed to evaluate the derivative (its message is on stderr)"); return 1; }
    if (rc || lg_dist_ghosts(env, lm, K->dm, out)) return 1;
  } else if (lg_sum_ranks(env, out, n, rc)) return 1;
  for (size_t i = 0; i < n; i++)
    if (!isfinite(out[i])) {
      lg_seterr(env, "a functional or its derivative is not finite (%g): its integrand is not finite somewhere "
                     "(a division by zero, the log or square root of a negative value?)", out[i]);
      return 1;
    }
  return 0;
}

/* ---------------------------------------------------------------- reduced functionals */


/* F uses func, or its '-' side restriction (interior facets) */
int lg_form_uses(lg_env *env, const form *F, int func) {
  expr_func_info *fi = expr_func_get(env->c, func);
  int tw = fi ? fi->twin : -1;
  for (int i = 0; i < F->n; i++) {
    expr *e = expr_canon(env->c, F->t[i].integrand), *leaf;
    if (expr_collect_fields(env->c, 1, &e, func, 1, &leaf) > 0) return 1;
    if (tw >= 0 && expr_collect_fields(env->c, 1, &e, tw, 1, &leaf) > 0) return 1;
  }
  return 0;
}

int lg_form_uses_param(lg_env *env, const form *F, int param) {
  for (int i = 0; i < F->n; i++) {
    expr *e = expr_canon(env->c, F->t[i].integrand);
    expr *d = expr_diff(env->c, e, expr_param(env->c, param));
    if (!d) return -1;
    if (!(d->kind == E_CONST && d->value == 0)) return 1;
  }
  return 0;
}

/* a form with each integrand replaced by its derivative with respect to a parameter */
form *lg_form_param_derivative(lg_env *env, const form *F, int param) {
  form *D = form_new();
  if (!D) return NULL;
  expr *pe = expr_param(env->c, param);
  for (int i = 0; i < F->n; i++) {
    expr *d = expr_diff(env->c, F->t[i].integrand, pe);
    if (!d || form_add_term(D, &F->t[i].reg, d, F->t[i].order)) { form_free(D); return NULL; }
  }
  return D;
}

static void free_scratch(lg_env *env, lg_function *f) {
  if (!f) return;
  expr_func_forget_user(env->c, f->fid);
  lg_function_free(f);
}

/* what Hessian actions built (all of it, or what a failed setup got to) */
static void hessian_free(lg_reduced *rf) {
  for (int a = 0; a < rf->nf; a++) {
    lg_form_kernels_free(rf->tan_rhs[a]);
    lg_form_kernels_free(rf->soa_rhs[a]);
    free_scratch(rf->env, rf->du[a]);
    free_scratch(rf->env, rf->dlam[a]);
    rf->tan_rhs[a] = rf->soa_rhs[a] = NULL;
    rf->du[a] = rf->dlam[a] = NULL;
  }
  for (int i = 0; i < rf->nc; i++) {
    lg_form_kernels_free(rf->hD[i]);
    lg_form_kernels_free(rf->hG[i]);
    free_scratch(rf->env, rf->dmf[i]);
    rf->hD[i] = rf->hG[i] = NULL;
    rf->dmf[i] = NULL;
  }
  rf->hess_ready = 0;
}

void lg_reduced_free(lg_reduced *rf) {
  if (!rf) return;
  lg_time_rf_free(rf);
  hessian_free(rf);
  lg_form_kernels_free(rf->Jval);
  for (int a = 0; a < rf->nf; a++) {
    lg_form_kernels_free(rf->dJdu[a]);
    if (rf->lam[a]) {
      expr_func_forget_user(rf->env->c, rf->lam[a]->fid);
      lg_function_free(rf->lam[a]);
    }
  }
  for (int i = 0; i < rf->nc; i++) {
    lg_form_kernels_free(rf->dJdm[i]);
    lg_form_kernels_free(rf->dLdm[i]);
    lg_problem_free(rf->riesz[i][0]);
    lg_problem_free(rf->riesz[i][1]);
  }
  form_free(rf->J);
  form_free(rf->L);
  free(rf->rhs);
  free(rf->lamv);
  free(rf->lamz);
  free(rf);
}

int lg_reduced_setup(lg_env *env, lg_reduced *rf, lg_problem *p, int nc, const lg_control *c, const int *skip) {
  if (nc < 1 || nc > LG_MAXCONTROL) { lg_seterr(env, "a reduced functional has 1 to %d controls (got %d)", LG_MAXCONTROL, nc); return 1; }
  rf->env = env;
  rf->p = p;
  rf->lm = lg_problem_mesh(p);
  rf->nf = lg_problem_fields(p, rf->fld);
  rf->nc = nc;
  memcpy(rf->c, c, sizeof(lg_control) * (size_t)nc);
  int N = lg_problem_size(p);
  rf->rhs = calloc((size_t)N + 1, sizeof(double));
  rf->lamv = calloc((size_t)N + 1, sizeof(double));
  rf->lamz = calloc((size_t)N + 1, sizeof(double));
  if (!rf->rhs || !rf->lamv || !rf->lamz) { lg_seterr(env, "out of memory"); return 1; }
  const form *F = lg_problem_equation(p);
  /* the controls: on the problem's mesh; in the essential values (Dirichlet) only where
   * their columns are kept */
  for (int i = 0; i < nc; i++) {
    int fid = c[i].kind == LG_CONTROL_FIELD ? c[i].f->fid : -1;
    if (fid >= 0 && c[i].f->mesh != rf->lm) { lg_seterr(env, "control %d lives on a different mesh than the problem", i + 1); return 1; }
    int dep = lg_problem_bc_dependence(env, p, fid, c[i].param);
    if (dep < 0) return 1;
    rf->bcdep[i] = dep;
    if (dep && lg_problem_bc_symmetric(p)) {
      lg_seterr(env, "control %d is a Dirichlet control of a problem with symmetric = true: its derivatives need the "
                     "eliminated columns (use symmetric = false)", i + 1);
      return 1;
    }
  }
  /* the adjoint functions, and the equation with its tests replaced by them */
  rf->L = form_new();
  if (!rf->L) { lg_seterr(env, "out of memory"); return 1; }
  for (int a = 0; a < rf->nf; a++) {
    expr_func_info *fu = expr_func_get(env->c, rf->fld[a].unknown);
    char nm[80];
    snprintf(nm, sizeof nm, "lambda_%s", fu ? fu->name : "u");
    rf->lam[a] = lg_function_new(env, rf->lm, (dofmap *)rf->fld[a].dm, nm);
    if (!rf->lam[a]) return 1;
  }
  for (int i = 0; i < F->n; i++) {
    expr *e = F->t[i].integrand;
    for (int a = 0; a < rf->nf && e; a++) e = form_replace_function(env->c, e, rf->fld[a].test, rf->lam[a]->fid);
    if (!e || form_add_term(rf->L, &F->t[i].reg, e, F->t[i].order)) { lg_seterr(env, "%s", expr_error(env->c)); return 1; }
  }
  for (int i = 0; i < nc; i++) {
    if (skip && skip[i]) continue;
    if (c[i].kind == LG_CONTROL_FIELD) {
      if (!(rf->dLdm[i] = lg_form_kernels_new(env, rf->lm, rf->L, c[i].f->fid, c[i].f->dm))) return 1;
    } else {
      form *dL = lg_form_param_derivative(env, rf->L, c[i].param);
      if (!dL) { lg_seterr(env, "%s", expr_error(env->c)); return 1; }
      rf->dLdm[i] = lg_form_kernels_new(env, rf->lm, dL, -1, NULL);
      form_free(dL);
      if (!rf->dLdm[i]) return 1;
    }
  }
  return 0;
}

int lg_functional_check(lg_env *env, lg_reduced *rf, const form *J) {
  /* a number of the state and the controls, no test functions */
  for (int i = 0; i < J->n; i++) {
    expr *e = expr_canon(env->c, J->t[i].integrand), *leaf[64];
    int n = expr_collect_fields(env->c, 1, &e, -1, 64, leaf);
    for (int k = 0; k < n && k < 64; k++) {
      expr_func_info *fi = expr_func_get(env->c, leaf[k]->i0);
      if (fi && fi->kind == FK_TEST) {
        lg_seterr(env, "the functional contains the test function %s: a functional is a number (lg.integral of "
                       "the state and the controls, without test functions)", fi->name);
        return 1;
      }
      if (fi && fi->kind == FK_UNKNOWN) {
        int ours = 0, base = fi->side ? fi->twin : leaf[k]->i0; /* a '-' side restriction is its function's */
        for (int a = 0; a < rf->nf; a++) ours |= rf->fld[a].unknown == base;
        if (!ours) {
          lg_seterr(env, "the functional contains the unknown %s, which is not an unknown of the problem", fi->name);
          return 1;
        }
      }
    }
    if (J->t[i].reg.mesh && J->t[i].reg.mesh != (void *)rf->lm) {
      lg_seterr(env, "the functional integrates over a region of a different mesh than the problem's");
      return 1;
    }
  }
  return 0;
}

int lg_functional_kernels(lg_env *env, lg_reduced *rf, const form *J, const int *skip, lg_form_kernels **val,
                          lg_form_kernels **dJdu, lg_form_kernels **dJdm) {
  if (!(*val = lg_form_kernels_new(env, rf->lm, J, -1, NULL))) return 1;
  for (int a = 0; a < rf->nf; a++)
    if (!(dJdu[a] = lg_form_kernels_new(env, rf->lm, J, rf->fld[a].unknown, rf->fld[a].dm))) return 1;
  for (int i = 0; i < rf->nc; i++) {
    if (skip && skip[i]) continue;
    if (rf->c[i].kind == LG_CONTROL_FIELD) {
      if (!(dJdm[i] = lg_form_kernels_new(env, rf->lm, J, rf->c[i].f->fid, rf->c[i].f->dm))) return 1;
    } else {
      form *dJ = lg_form_param_derivative(env, J, rf->c[i].param);
      if (!dJ) { lg_seterr(env, "%s", expr_error(env->c)); return 1; }
      dJdm[i] = lg_form_kernels_new(env, rf->lm, dJ, -1, NULL);
      form_free(dJ);
      if (!dJdm[i]) return 1;
    }
  }
  return 0;
}

lg_reduced *lg_reduced_new(lg_env *env, lg_problem *p, const form *J, int nc, const lg_control *c) {
  for (int i = 0; i < nc && i < LG_MAXCONTROL; i++)
    if (c[i].per_step) {
      lg_seterr(env, "control %d has a value per step: that is for a time-dependent problem (lg.time_problem)", i + 1);
      return NULL;
    }
  lg_reduced *rf = calloc(1, sizeof *rf);
  if (!rf) { lg_seterr(env, "out of memory"); return NULL; }
  if (lg_reduced_setup(env, rf, p, nc, c, NULL)) goto fail;
  if (!(rf->J = form_copy(J))) { lg_seterr(env, "out of memory"); goto fail; }
  if (lg_functional_check(env, rf, J)) goto fail;
  /* every control in the equation, the functional or the essential values */
  const form *F = lg_problem_equation(p);
  for (int i = 0; i < nc; i++) {
    int inF, inJ, fid = c[i].kind == LG_CONTROL_FIELD ? c[i].f->fid : -1;
    if (fid >= 0) {
      inF = lg_form_uses(env, F, fid);
      inJ = lg_form_uses(env, J, fid);
    } else {
      inF = lg_form_uses_param(env, F, c[i].param);
      inJ = lg_form_uses_param(env, J, c[i].param);
      if (inF < 0 || inJ < 0) { lg_seterr(env, "%s", expr_error(env->c)); goto fail; }
    }
    if (!inF && !inJ && !rf->bcdep[i]) {
      if (fid >= 0) lg_seterr(env, "control %d appears in neither the problem nor the functional", i + 1);
      else lg_seterr(env, "control %d (parameter %s) appears in neither the problem nor the functional", i + 1,
                     expr_param_name(env->c, c[i].param));
      goto fail;
    }
  }
  if (lg_functional_kernels(env, rf, J, NULL, &rf->Jval, rf->dJdu, rf->dJdm)) goto fail;
  return rf;
fail:
  lg_reduced_free(rf);
  return NULL;
}

int lg_reduced_ncontrols(const lg_reduced *rf) { return rf->nc; }
const lg_control *lg_reduced_control(const lg_reduced *rf, int i) { return &rf->c[i]; }
lg_problem *lg_reduced_problem(const lg_reduced *rf) { return rf->p; }
void lg_reduced_changed(lg_reduced *rf) { rf->solved = 0; rf->grad_fresh = 0; }
int lg_reduced_share_state(lg_reduced *rf, const lg_reduced *from) {
  if (rf->tm || from->tm) return 0; /* a march is not shared (yet) */
  if (rf->solved || !from->solved || rf->p != from->p) return 0;
  rf->solved = 1;
  return 1;
}

int lg_reduced_control_size(const lg_reduced *rf, int i) {
  return rf->c[i].kind == LG_CONTROL_FIELD ? rf->c[i].f->dm->ndof * lg_reduced_control_blocks(rf, i) : 1;
}

lg_time *lg_reduced_time(const lg_reduced *rf) { return lg_time_rf_time(rf); }

int lg_reduced_control_blocks(const lg_reduced *rf, int i) { return rf->c[i].per_step ? lg_time_rf_blocks(rf) : 1; }

double *lg_reduced_control_values(lg_reduced *rf, int i) {
  if (rf->c[i].kind == LG_CONTROL_PARAM) return &expr_param_values(rf->env->c)[rf->c[i].param];
  return rf->c[i].per_step ? lg_time_rf_steps(rf, i) : rf->c[i].f->x;
}

/* solve the state at the current controls (if they changed) */
static int ensure_state(lg_env *env, lg_reduced *rf) {
  if (rf->solved) return 0;
  lg_solve_info info;
  if (lg_problem_resolve(env, rf->p, &info)) {
    char why[LG_ERRLEN];
    snprintf(why, sizeof why, "%s", env->err);
    lg_seterr(env, "the state solve failed at this control: %s", why);
    return 1;
  }
  rf->solved = 1;
  return 0;
}

int lg_reduced_value(lg_env *env, lg_reduced *rf, double *J) {
  if (rf->tm) return lg_time_value(env, rf, J);
  if (ensure_state(env, rf)) return 1;
  coef_binding st[2 * KER_MAXFIELD];
  int ns = lg_problem_bind_state(rf->p, st);
  return lg_form_kernels_eval(env, rf->lm, rf->Jval, ns, st, J);
}

/* the derivatives of the essential values for control i: out += s (dg/dm)^T w */
int lg_reduced_bc_transpose(lg_env *env, lg_reduced *rf, int i, const double *w, double s, double *out) {
  int *r, *c;
  double *v;
  int n = lg_problem_bc_derivative(env, rf->p, rf->c[i].kind == LG_CONTROL_FIELD ? rf->c[i].f->fid : -1, rf->c[i].param, &r, &c, &v);
  if (n < 0) return 1;
  if (rf->lm->dist && rf->c[i].kind == LG_CONTROL_PARAM) {
    /* a parameter's: a sum over the rows, each on the rank that owns it */
    double sum = 0;
    for (int k = 0; k < n; k++)
      if (lg_problem_row_owned(rf->p, r[k])) sum += s * v[k] * w[r[k]];
    free(r); free(c); free(v);
    if (lg_allreduce(&sum, 1, LG_SUM)) { lg_seterr(env, "the sum over the ranks failed"); return 1; }
    out[0] += sum;
    return 0;
  }
  for (int k = 0; k < n; k++) out[c[k]] += s * v[k] * w[r[k]];
  free(r); free(c); free(v);
  return 0;
}

/* and the forward action: out[r] += (dg/dm dm)_r on the essential rows */
int lg_reduced_bc_action(lg_env *env, lg_reduced *rf, int i, const double *dm, double *out) {
  int *r, *c;
  double *v;
  int n = lg_problem_bc_derivative(env, rf->p, rf->c[i].kind == LG_CONTROL_FIELD ? rf->c[i].f->fid : -1, rf->c[i].param, &r, &c, &v);
  if (n < 0) return 1;
  for (int k = 0; k < n; k++) out[r[k]] += v[k] * dm[c[k]];
  free(r); free(c); free(v);
  return 0;
}

/* a Dirichlet control's derivative on a distributed mesh: the essential rows added to its
 * owned dofs, which the ghost dofs now take */
int lg_reduced_dirichlet_ghosts(lg_env *env, lg_reduced *rf, int i, double *v) {
  if (!rf->lm->dist || !rf->bcdep[i] || rf->c[i].kind != LG_CONTROL_FIELD) return 0;
  int nd = rf->c[i].f->dm->ndof, nb = lg_reduced_control_blocks(rf, i); /* a per-step control: block by block */
  for (int k = 0; k < nb; k++)
    if (lg_dist_ghosts(env, rf->lm, rf->c[i].f->dm, v + (size_t)k * (size_t)nd)) return 1;
  return 0;
}

int lg_reduced_dot(lg_env *env, lg_reduced *rf, double **a, double **b, double *out) {
  double s[2] = {0, 0}, par = 0; /* field dofs (a distributed mesh's: this rank's owned), failure */
  for (int i = 0; i < rf->nc; i++) {
    int n = lg_reduced_control_size(rf, i);
    if (rf->c[i].kind == LG_CONTROL_PARAM) par += a[i][0] * b[i][0];
    else if (rf->lm->dist) {
      const char *own = lg_dist_owned(env, rf->lm, rf->c[i].f->dm, NULL);
      int nd = rf->c[i].f->dm->ndof; /* a per-step control: block by block */
      for (int k = 0; own && k < n; k += nd) s[0] += lg_dist_dot(own, nd, a[i] + k, b[i] + k);
      if (!own) s[1] = 1;
    } else
      for (int k = 0; k < n; k++) s[0] += a[i][k] * b[i][k];
  }
  if (rf->lm->dist && lg_allreduce(s, 2, LG_SUM)) { lg_seterr(env, "the sum over the ranks failed"); return 1; }
  if (s[1]) { if (!env->err[0]) lg_seterr(env, "another rank failed to number a control's dofs"); return 1; }
  *out = s[0] + par;
  return 0;
}

int lg_reduced_set_adjoint(lg_env *env, lg_reduced *rf, const double *lam) {
  /* lam^T dR/dm: the essential rows (u_i - g_i) do not depend on a control in the equation,
   * so the adjoint enters the equation with those values zero (the test space) */
  (void)env;
  memcpy(rf->lamz, lam, sizeof(double) * (size_t)lg_problem_size(rf->p));
  lg_problem_zero_essential(rf->p, rf->lamz);
  for (int a = 0; a < rf->nf; a++)
    memcpy(rf->lam[a]->x, rf->lamz + rf->fld[a].offset, sizeof(double) * (size_t)rf->fld[a].dm->ndof);
  return 0;
}

int lg_reduced_gradient(lg_env *env, lg_reduced *rf, double **g) {
  if (rf->tm) return lg_time_gradient(env, rf, g);
  if (ensure_state(env, rf)) return 1;
  coef_binding b[3 * KER_MAXFIELD];
  int ns = lg_problem_bind_state(rf->p, b);
  /* the adjoint: (dR/du)^T lam = -dJ/du */
  int N = lg_problem_size(rf->p);
  memset(rf->rhs, 0, sizeof(double) * (size_t)N);
  for (int a = 0; a < rf->nf; a++) {
    double *part = rf->rhs + rf->fld[a].offset;
    if (lg_form_kernels_eval(env, rf->lm, rf->dJdu[a], ns, b, part)) return 1;
  }
  for (int i = 0; i < N; i++) rf->rhs[i] = -rf->rhs[i];
  if (lg_problem_adjoint(env, rf->p, rf->rhs, rf->lamv)) return 1;
  if (lg_reduced_set_adjoint(env, rf, rf->lamv)) return 1;
  rf->grad_fresh = 1;
  /* dj/dm = dJ/dm + lam^T dR/dm */
  for (int i = 0; i < rf->nc; i++) {
    int n = lg_reduced_control_size(rf, i);
    double *tmp = malloc(sizeof(double) * (size_t)n + 8);
    if (!tmp) { lg_seterr(env, "out of memory"); return 1; }
    if (lg_form_kernels_eval(env, rf->lm, rf->dJdm[i], ns, b, g[i]) ||
        lg_form_kernels_eval(env, rf->lm, rf->dLdm[i], ns, b, tmp)) {
      free(tmp);
      return 1;
    }
    for (int k = 0; k < n; k++) g[i][k] += tmp[k];
    /* a Dirichlet control: the essential rows u_r - g_r(m) add -lam_r dg_r/dm */
    if (rf->bcdep[i] && lg_reduced_bc_transpose(env, rf, i, rf->lamv, -1, g[i])) { free(tmp); return 1; }
    free(tmp);
    if (lg_reduced_dirichlet_ghosts(env, rf, i, g[i])) return 1;
  }
  return 0;
}

/* the Gram matrix of a field control's space: L2 (mass) or H1 (mass + stiffness) */
lg_problem *lg_reduced_gram(lg_env *env, lg_reduced *rf, int i, int h1) {
  if (rf->riesz[i][h1]) return rf->riesz[i][h1];
  int deg = rf->c[i].f->degree, bs = rf->c[i].f->dm->bs;
  int ft = expr_func_new(env->c, FK_TEST, "psi", deg, bs, NULL), fu = expr_func_new(env->c, FK_UNKNOWN, "phi", deg, bs, NULL);
  if (ft < 0 || fu < 0) { lg_seterr(env, "out of memory"); return NULL; }
  expr_func_get(env->c, ft)->disc = expr_func_get(env->c, fu)->disc = rf->c[i].f->dm->disc;
  unsigned char z[3] = {0, 0, 0};
  expr *vc[FEM_MAXBS], *uc[FEM_MAXBS];
  for (int j = 0; j < bs; j++) {
    vc[j] = expr_field(env->c, ft, j, z);
    uc[j] = expr_field(env->c, fu, j, z);
  }
  expr *v = bs == 1 ? vc[0] : expr_list(env->c, bs, vc), *u = bs == 1 ? uc[0] : expr_list(env->c, bs, uc);
  expr *e = expr_inner(env->c, u, v);
  if (h1) e = expr_add(env->c, e, expr_inner(env->c, expr_grad(env->c, u), expr_grad(env->c, v)));
  if (!e) { lg_seterr(env, "%s", expr_error(env->c)); return NULL; }
  form *F = form_new();
  region all = {REGION_CELLS, 0, {0}, rf->lm};
  if (!F || form_add_term(F, &all, e, -1)) { form_free(F); lg_seterr(env, "out of memory"); return NULL; }
  lg_problem_spec s = {rf->lm, F, NULL, 1, &ft, &fu, 0, 0, NULL, 0, NULL, 0};
  rf->riesz[i][h1] = lg_problem_new(env, &s);
  if (rf->riesz[i][h1] && !h1) lg_problem_mass_solver(rf->riesz[i][h1]); /* no factor of the mass matrix kept in memory */
  form_free(F);
  return rf->riesz[i][h1];
}

int lg_reduced_riesz(lg_env *env, lg_reduced *rf, int i, int kind, const double *dual, double *out) {
  int n = lg_reduced_control_size(rf, i);
  if (kind == LG_RIESZ_NONE || rf->c[i].kind != LG_CONTROL_FIELD) {
    memcpy(out, dual, sizeof(double) * (size_t)n);
    return 0;
  }
  lg_problem *G = lg_reduced_gram(env, rf, i, kind == LG_RIESZ_H1);
  int nb = lg_reduced_control_blocks(rf, i), nd = rf->c[i].f->dm->ndof; /* a per-step control: block by block */
  for (int b = 0; G && b < nb; b++)
    if (lg_problem_solve_vector(env, G, dual + (size_t)b * (size_t)nd, out + (size_t)b * (size_t)nd)) return 1;
  return G ? 0 : 1;
}

/* ---------------------------------------------------------------- sensitivities */

int lg_sensitivity(lg_env *env, lg_problem *p, int param, double *du) {
  const form *F = lg_problem_equation(p);
  int inB = lg_problem_bc_dependence(env, p, -1, param);
  if (inB < 0) return 1;
  if (inB && lg_problem_bc_symmetric(p)) {
    lg_seterr(env, "the parameter %s appears in an essential condition of a problem with symmetric = true: its "
                   "sensitivity needs the eliminated columns (use symmetric = false)", expr_param_name(env->c, param));
    return 1;
  }
  if (!lg_problem_solution(p)) { lg_seterr(env, "the sensitivity needs a solved state: solve the problem first"); return 1; }
  lg_mesh *lm = lg_problem_mesh(p);
  lg_field_info fld[KER_MAXFIELD];
  int nf = lg_problem_fields(p, fld), N = lg_problem_size(p);
  form *dF = lg_form_param_derivative(env, F, param);
  double *rhs = calloc((size_t)N + 1, sizeof(double));
  if (!dF || !rhs) { form_free(dF); free(rhs); lg_seterr(env, "%s", dF ? "out of memory" : expr_error(env->c)); return 1; }
  coef_binding st[2 * KER_MAXFIELD];
  int ns = lg_problem_bind_state(p, st), rc = 0;
  /* dR/da: the equation differentiated with respect to a, as a linear form in each test space */
  for (int a = 0; a < nf && !rc; a++) {
    lg_form_kernels *K = lg_form_kernels_new(env, lm, dF, fld[a].test, fld[a].dm);
    if (!K || lg_form_kernels_eval(env, lm, K, ns, st, rhs + fld[a].offset)) rc = 1;
    lg_form_kernels_free(K);
  }
  form_free(dF);
  if (!rc) {
    /* the essential rows u_r - g_r(a): du_r = dg_r/da */
    {
      for (int i = 0; i < N; i++) rhs[i] = -rhs[i];
      lg_problem_zero_essential(p, rhs);
      if (inB) {
        int *r, *c;
        double *v;
        int n = lg_problem_bc_derivative(env, p, -1, param, &r, &c, &v);
        if (n < 0) rc = 1;
        for (int k = 0; k < n; k++) rhs[r[k]] += v[k];
        if (n >= 0) { free(r); free(c); free(v); }
      }
      if (!rc) rc = lg_problem_tangent(env, p, rhs, du);
    }
  }
  free(rhs);
  return rc;
}

/* ---------------------------------------------------------------- Hessian actions */

/* the directional derivative of an integrand in the control directions dm */
static expr *control_direction(lg_env *env, lg_reduced *rf, expr *f) {
  expr *sum = expr_num(env->c, 0);
  for (int i = 0; i < rf->nc && sum; i++) {
    const lg_control *c = &rf->c[i];
    expr *d = c->kind == LG_CONTROL_FIELD
                  ? form_directional(env->c, f, c->f->fid, rf->dmf[i]->fid)
                  : expr_mul(env->c, expr_diff(env->c, f, expr_param(env->c, c->param)), expr_param(env->c, rf->dpar[i]));
    sum = expr_add(env->c, sum, d);
  }
  return sum;
}

/* the kernels of a Hessian action, once */
/* abs and sign of the state or a control have no second derivative at their kinks: the
 * Hessian would silently drop the delta there, so refuse and say where */
static int check_kinks(lg_env *env, lg_reduced *rf, const form *F) {
  int fids[KER_MAXFIELD + LG_MAXCONTROL], pids[LG_MAXCONTROL], nf = 0, np = 0;
  for (int a = 0; a < rf->nf; a++) fids[nf++] = rf->fld[a].unknown;
  for (int i = 0; i < rf->nc; i++) {
    if (rf->c[i].kind == LG_CONTROL_FIELD) fids[nf++] = rf->c[i].f->fid;
    else pids[np++] = rf->c[i].param;
  }
  const form *parts[2] = {rf->J, F};
  static const char *const what[2] = {"functional", "equation"};
  for (int k = 0; k < 2; k++)
    for (int i = 0; i < parts[k]->n; i++) {
      expr *kink = expr_find_kink(env->c, parts[k]->t[i].integrand, nf, fids, np, pids);
      if (!kink) continue;
      char buf[160];
      expr_print(env->c, kink, buf, sizeof buf);
      lg_seterr(env, "Hessian actions are not defined: term %d of the %s contains %s, a kink in the state or a control "
                     "(not twice differentiable there); smooth it, e.g. sqrt(x^2 + eps^2) for abs(x)", i + 1, what[k], buf);
      return 1;
    }
  return 0;
}

/* Dirichlet values must be affine in the controls (jointly) for Hessian actions: their
 * second derivatives would need the adjoint on the essential rows in the Lagrangian */
int lg_reduced_bc_affine(lg_env *env, lg_reduced *rf) {
  for (int i = 0; i < rf->nc; i++)
    for (int j = i; j < rf->nc && rf->bcdep[i]; j++) {
      if (!rf->bcdep[j]) continue;
      const lg_control *a = &rf->c[i], *b = &rf->c[j];
      int mixed = lg_problem_bc_mixed(env, rf->p, a->kind == LG_CONTROL_FIELD ? a->f->fid : -1, a->param,
                                      b->kind == LG_CONTROL_FIELD ? b->f->fid : -1, b->param);
      if (mixed < 0) return 1;
      if (mixed) {
        if (i == j) lg_seterr(env, "Hessian actions are not available: control %d enters an essential condition nonlinearly "
                                   "(Dirichlet values affine in the controls are supported)", i + 1);
        else lg_seterr(env, "Hessian actions are not available: controls %d and %d enter an essential condition as a product "
                            "(Dirichlet values affine in the controls are supported)", i + 1, j + 1);
        return 1;
      }
    }
  return 0;
}

static int hessian_setup(lg_env *env, lg_reduced *rf) {
  if (rf->hess_ready) return 0;
  const form *F = lg_problem_equation(rf->p);
  if (check_kinks(env, rf, F) || lg_reduced_bc_affine(env, rf)) return 1;
  for (int i = 0; i < rf->nc; i++) {
    if (rf->c[i].kind == LG_CONTROL_FIELD) {
      if (!(rf->dmf[i] = lg_function_new(env, rf->lm, rf->c[i].f->dm, "dm"))) { hessian_free(rf); return 1; }
    } else if ((rf->dpar[i] = expr_param_new(env->c, "dm", 0)) < 0) {
      lg_seterr(env, "out of memory");
      hessian_free(rf);
      return 1;
    }
  }
  for (int a = 0; a < rf->nf; a++)
    if (!(rf->du[a] = lg_function_new(env, rf->lm, (dofmap *)rf->fld[a].dm, "du")) ||
        !(rf->dlam[a] = lg_function_new(env, rf->lm, (dofmap *)rf->fld[a].dm, "dlambda"))) {
      hessian_free(rf);
      return 1;
    }
  /* Fdm: the equation differentiated in the control directions (the tangent's source);
   * D: the Lagrangian J + lam^T R differentiated in the directions (du, dm);
   * G: the equation with its tests replaced by the second-order adjoint */
  form *Fdm = form_new(), *D = form_new(), *G = form_new();
  int rc = !Fdm || !D || !G;
  for (int i = 0; !rc && i < F->n; i++) {
    expr *e = control_direction(env, rf, F->t[i].integrand);
    expr *g = F->t[i].integrand;
    for (int a = 0; a < rf->nf && g; a++) g = form_replace_function(env->c, g, rf->fld[a].test, rf->dlam[a]->fid);
    rc = !e || !g || form_add_term(Fdm, &F->t[i].reg, e, F->t[i].order) || form_add_term(G, &F->t[i].reg, g, F->t[i].order);
  }
  const form *parts[2] = {rf->J, rf->L};
  for (int k = 0; k < 2 && !rc; k++)
    for (int i = 0; !rc && i < parts[k]->n; i++) {
      expr *l = parts[k]->t[i].integrand;
      expr *e = control_direction(env, rf, l);
      for (int a = 0; a < rf->nf && e; a++) e = expr_add(env->c, e, form_directional(env->c, l, rf->fld[a].unknown, rf->du[a]->fid));
      rc = !e || form_add_term(D, &parts[k]->t[i].reg, e, parts[k]->t[i].order);
    }
  if (rc) lg_seterr(env, "%s", expr_error(env->c)[0] ? expr_error(env->c) : "out of memory");
  for (int a = 0; a < rf->nf && !rc; a++) {
    if (!(rf->tan_rhs[a] = lg_form_kernels_new(env, rf->lm, Fdm, rf->fld[a].test, rf->fld[a].dm))) rc = 1;
    else if (!(rf->soa_rhs[a] = lg_form_kernels_new(env, rf->lm, D, rf->fld[a].unknown, rf->fld[a].dm))) rc = 1;
  }
  for (int i = 0; i < rf->nc && !rc; i++) {
    if (rf->c[i].kind == LG_CONTROL_FIELD) {
      rf->hD[i] = lg_form_kernels_new(env, rf->lm, D, rf->c[i].f->fid, rf->c[i].f->dm);
      rf->hG[i] = rf->hD[i] ? lg_form_kernels_new(env, rf->lm, G, rf->c[i].f->fid, rf->c[i].f->dm) : NULL;
    } else {
      form *dD = lg_form_param_derivative(env, D, rf->c[i].param), *dG = lg_form_param_derivative(env, G, rf->c[i].param);
      rf->hD[i] = dD ? lg_form_kernels_new(env, rf->lm, dD, -1, NULL) : NULL;
      rf->hG[i] = dG && rf->hD[i] ? lg_form_kernels_new(env, rf->lm, dG, -1, NULL) : NULL;
      if (!dD || !dG) lg_seterr(env, "%s", expr_error(env->c));
      form_free(dD);
      form_free(dG);
    }
    if (!rf->hD[i] || !rf->hG[i]) rc = 1;
  }
  form_free(Fdm);
  form_free(D);
  form_free(G);
  if (rc) hessian_free(rf);
  else rf->hess_ready = 1;
  return rc;
}

int lg_reduced_hessian(lg_env *env, lg_reduced *rf, double **dm, double **out) {
  if (rf->tm) return lg_time_hessian(env, rf, dm, out);
  if (hessian_setup(env, rf)) return 1;
  if (!rf->grad_fresh || !rf->solved) { /* the first-order adjoint at the current controls */
    double *g[LG_MAXCONTROL];
    int ok = 1;
    for (int i = 0; i < rf->nc; i++) ok &= (g[i] = malloc(sizeof(double) * ((size_t)lg_reduced_control_size(rf, i) + 1))) != NULL;
    int rc = !ok || lg_reduced_gradient(env, rf, g);
    if (!ok) lg_seterr(env, "out of memory");
    for (int i = 0; i < rf->nc; i++) free(g[i]);
    if (rc) return 1;
  }
  for (int i = 0; i < rf->nc; i++) {
    if (rf->c[i].kind == LG_CONTROL_FIELD) memcpy(rf->dmf[i]->x, dm[i], sizeof(double) * (size_t)rf->c[i].f->dm->ndof);
    else expr_param_values(env->c)[rf->dpar[i]] = dm[i][0];
  }
  coef_binding st[2 * KER_MAXFIELD];
  int ns = lg_problem_bind_state(rf->p, st), N = lg_problem_size(rf->p);
  double *v = malloc(sizeof(double) * ((size_t)N + 1));
  int rc = !v;
  if (rc) lg_seterr(env, "out of memory");
  /* the tangent: (dR/du) du = -(dR/dm) dm, zero on the essential rows */
  for (int a = 0; a < rf->nf && !rc; a++) rc = lg_form_kernels_eval(env, rf->lm, rf->tan_rhs[a], ns, st, rf->rhs + rf->fld[a].offset);
  if (!rc) {
    for (int i = 0; i < N; i++) rf->rhs[i] = -rf->rhs[i];
    lg_problem_zero_essential(rf->p, rf->rhs);
    for (int i = 0; i < rf->nc && !rc; i++)
      if (rf->bcdep[i]) rc = lg_reduced_bc_action(env, rf, i, dm[i], rf->rhs); /* du_r = dg_r/dm dm */
    if (!rc) rc = lg_problem_tangent(env, rf->p, rf->rhs, v);
  }
  for (int a = 0; a < rf->nf && !rc; a++) memcpy(rf->du[a]->x, v + rf->fld[a].offset, sizeof(double) * (size_t)rf->fld[a].dm->ndof);
  /* the second-order adjoint: (dR/du)^T dlam = -(L_uu du + L_um dm) */
  for (int a = 0; a < rf->nf && !rc; a++) rc = lg_form_kernels_eval(env, rf->lm, rf->soa_rhs[a], ns, st, rf->rhs + rf->fld[a].offset);
  if (!rc) {
    for (int i = 0; i < N; i++) rf->rhs[i] = -rf->rhs[i];
    rc = lg_problem_adjoint(env, rf->p, rf->rhs, v);
  }
  /* H dm = L_mu du + L_mm dm + (dR/dm)^T dlam; a Dirichlet control's rows u_r - g_r(m), linear
   * in m, add -dlam_r dg_r/dm */
  double *dlr = rc ? NULL : malloc(sizeof(double) * ((size_t)N + 1));
  if (!rc && !dlr) { lg_seterr(env, "out of memory"); rc = 1; }
  if (!rc) {
    memcpy(dlr, v, sizeof(double) * (size_t)N);
    lg_problem_zero_essential(rf->p, v); /* it enters the equation as a test function */
    for (int a = 0; a < rf->nf; a++) memcpy(rf->dlam[a]->x, v + rf->fld[a].offset, sizeof(double) * (size_t)rf->fld[a].dm->ndof);
  }
  for (int i = 0; i < rf->nc && !rc; i++) {
    int n = lg_reduced_control_size(rf, i);
    double *tmp = malloc(sizeof(double) * ((size_t)n + 1));
    rc = !tmp || lg_form_kernels_eval(env, rf->lm, rf->hD[i], ns, st, out[i]) || lg_form_kernels_eval(env, rf->lm, rf->hG[i], ns, st, tmp);
    if (!rc)
      for (int k = 0; k < n; k++) out[i][k] += tmp[k];
    if (!rc && rf->bcdep[i]) rc = lg_reduced_bc_transpose(env, rf, i, dlr, -1, out[i]);
    if (!rc) rc = lg_reduced_dirichlet_ghosts(env, rf, i, out[i]);
    free(tmp);
  }
  free(dlr);
  free(v);
  return rc;
}
