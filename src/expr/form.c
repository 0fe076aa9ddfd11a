/* form.c — forms (sums of integrals over regions) and their linearization into
 * coefficient tables: "everything is a derivative" (DESIGN.md). */
#include "expr.h"

#include <stdlib.h>
#include <string.h>

form *form_new(void) { return calloc(1, sizeof(form)); }

void form_free(form *f) {
  if (!f) return;
  free(f->t);
  free(f);
}

int form_add_term(form *f, const region *r, expr *integrand, int order) {
  if (f->n == f->cap) {
    int cap = f->cap ? 2 * f->cap : 4;
    form_term *nt = realloc(f->t, sizeof(form_term) * (size_t)cap);
    if (!nt) return 1;
    f->t = nt;
    f->cap = cap;
  }
  f->t[f->n].reg = *r;
  f->t[f->n].integrand = integrand;
  f->t[f->n].order = order;
  f->n++;
  return 0;
}

form *form_copy(const form *f) {
  form *g = form_new();
  if (!g) return NULL;
  for (int i = 0; i < f->n; i++)
    if (form_add_term(g, &f->t[i].reg, f->t[i].integrand, f->t[i].order)) { form_free(g); return NULL; }
  return g;
}

form *form_combine(expr_ctx *c, const form *f, double s, const form *g) {
  form *r = form_copy(f);
  if (!r) return NULL;
  for (int i = 0; g && i < g->n; i++) {
    expr *e = expr_mul(c, expr_num(c, s), g->t[i].integrand);
    if (!e || form_add_term(r, &g->t[i].reg, e, g->t[i].order)) { form_free(r); return NULL; }
  }
  return r;
}

void coef_table_free(coef_table *t) {
  free(t->res_leaf);
  free(t->res);
  free(t->jac_test);
  free(t->jac_trial);
  free(t->jac);
  memset(t, 0, sizeof *t);
}

#define MAXLEAF 256

int form_linearize(expr_ctx *c, expr *f, int ntest, const int *test_funcs, int ntrial,
                   const int *trial_funcs, int want_jacobian, coef_table *out) {
  memset(out, 0, sizeof *out);
  expr *tl[MAXLEAF];
  int nt = 0;
  for (int i = 0; i < ntest; i++) {
    int k = expr_collect_fields(c, 1, &f, test_funcs[i], MAXLEAF - nt, tl + nt);
    if (k > MAXLEAF - nt) { expr_set_error(c, "too many test-function leaves in one integrand"); return 1; }
    nt += k;
  }
  /* the integrand must vanish when the test functions do */
  expr **zeros = malloc(sizeof(expr *) * (size_t)(nt + 1));
  if (!zeros) return 1;
  for (int i = 0; i < nt; i++) zeros[i] = expr_num(c, 0);
  expr *f0 = expr_subs(c, f, nt, tl, zeros);
  free(zeros);
  if (!f0) return 1;
  if (!(f0->kind == E_CONST && f0->value == 0)) {
    char buf[200];
    expr_print(c, f0, buf, sizeof buf);
    expr_set_error(c, "the form is not linear in the test function: the term %s does not "
                      "contain it", buf);
    return 1;
  }
  out->res_leaf = malloc(sizeof(expr *) * (size_t)(nt + 1));
  out->res = malloc(sizeof(expr *) * (size_t)(nt + 1));
  if (!out->res_leaf || !out->res) { coef_table_free(out); return 1; }
  int cap = 16;
  if (want_jacobian) {
    out->jac_test = malloc(sizeof(expr *) * (size_t)cap);
    out->jac_trial = malloc(sizeof(expr *) * (size_t)cap);
    out->jac = malloc(sizeof(expr *) * (size_t)cap);
    if (!out->jac_test || !out->jac_trial || !out->jac) { coef_table_free(out); return 1; }
  }
  for (int i = 0; i < nt; i++) {
    expr *r = expr_diff(c, f, tl[i]);
    if (!r) { coef_table_free(out); return 1; }
    expr *dummy[1];
    for (int j = 0; j < ntest; j++) {
      if (expr_collect_fields(c, 1, &r, test_funcs[j], 1, dummy) > 0) {
        expr_set_error(c, "the form is not linear in the test function: it contains a "
                          "product of test functions");
        coef_table_free(out);
        return 1;
      }
    }
    if (r->kind == E_CONST && r->value == 0) continue;
    out->res_leaf[out->nres] = tl[i];
    out->res[out->nres] = r;
    out->nres++;
    if (!want_jacobian) continue;
    expr *ul[MAXLEAF];
    int nu = 0;
    for (int j = 0; j < ntrial; j++) {
      int k = expr_collect_fields(c, 1, &r, trial_funcs[j], MAXLEAF - nu, ul + nu);
      if (k > MAXLEAF - nu) { expr_set_error(c, "too many unknown leaves"); coef_table_free(out); return 1; }
      nu += k;
    }
    for (int j = 0; j < nu; j++) {
      expr *jv = expr_diff(c, r, ul[j]);
      if (!jv) { coef_table_free(out); return 1; }
      if (jv->kind == E_CONST && jv->value == 0) continue;
      if (out->njac == cap) {
        cap *= 2;
        expr **a = realloc(out->jac_test, sizeof(expr *) * (size_t)cap);
        if (a) out->jac_test = a;
        expr **b = realloc(out->jac_trial, sizeof(expr *) * (size_t)cap);
        if (b) out->jac_trial = b;
        expr **d = realloc(out->jac, sizeof(expr *) * (size_t)cap);
        if (d) out->jac = d;
        if (!a || !b || !d) { coef_table_free(out); return 1; }
      }
      out->jac_test[out->njac] = tl[i];
      out->jac_trial[out->njac] = ul[j];
      out->jac[out->njac] = jv;
      out->njac++;
    }
  }
  return 0;
}

int form_gradient_table(expr_ctx *c, expr *f, int func, coef_table *out) {
  memset(out, 0, sizeof *out);
  f = expr_canon(c, f);
  if (!f) return 1;
  expr *leaf[MAXLEAF];
  int n = expr_collect_fields(c, 1, &f, func, MAXLEAF, leaf);
  if (n > MAXLEAF) { expr_set_error(c, "too many leaves of one function in an integrand"); return 1; }
  out->res_leaf = malloc(sizeof(expr *) * (size_t)(n + 1));
  out->res = malloc(sizeof(expr *) * (size_t)(n + 1));
  if (!out->res_leaf || !out->res) { coef_table_free(out); expr_set_error(c, "out of memory"); return 1; }
  for (int i = 0; i < n; i++) {
    expr *r = expr_diff(c, f, leaf[i]);
    if (!r) { coef_table_free(out); return 1; }
    if (r->kind == E_CONST && r->value == 0) continue;
    out->res_leaf[out->nres] = leaf[i];
    out->res[out->nres] = r;
    out->nres++;
  }
  return 0;
}

static expr *replace_one(expr_ctx *c, expr *f, int from, int to);

/* a function's restriction to the '-' side of interior facets (expr_func_side) follows it:
 * replaced by the restriction of `to` */
expr *form_replace_function(expr_ctx *c, expr *f, int from, int to) {
  expr_func_info *fi = expr_func_get(c, from);
  int tw = fi && !fi->side ? fi->twin : -1;
  f = replace_one(c, f, from, to);
  if (f && tw >= 0) {
    int tt = expr_func_side(c, to, 1);
    f = tt < 0 ? NULL : replace_one(c, f, tw, tt);
  }
  return f;
}

static expr *replace_one(expr_ctx *c, expr *f, int from, int to) {
  f = expr_canon(c, f);
  if (!f) return NULL;
  expr *leaf[MAXLEAF];
  int n = expr_collect_fields(c, 1, &f, from, MAXLEAF, leaf);
  if (n > MAXLEAF) { expr_set_error(c, "too many leaves of one function in an integrand"); return NULL; }
  expr *img[MAXLEAF];
  for (int i = 0; i < n; i++) {
    img[i] = expr_field(c, to, leaf[i]->i1, leaf[i]->alpha);
    if (!img[i]) return NULL;
  }
  return n ? expr_subs(c, f, n, leaf, img) : f;
}

static expr *directional_one(expr_ctx *c, expr *f, int func, int dir);

/* with the '-' side's restriction of func (interior facets) in the direction's restriction */
expr *form_directional(expr_ctx *c, expr *f, int func, int dir) {
  expr_func_info *fi = expr_func_get(c, func);
  int tw = fi && !fi->side ? fi->twin : -1;
  expr *d = directional_one(c, f, func, dir);
  if (d && tw >= 0) {
    int td = expr_func_side(c, dir, 1);
    expr *d2 = td < 0 ? NULL : directional_one(c, f, tw, td);
    d = d2 ? expr_add(c, d, d2) : NULL;
  }
  return d;
}

static expr *directional_one(expr_ctx *c, expr *f, int func, int dir) {
  f = expr_canon(c, f);
  if (!f) return NULL;
  expr *leaf[MAXLEAF];
  int n = expr_collect_fields(c, 1, &f, func, MAXLEAF, leaf);
  if (n > MAXLEAF) { expr_set_error(c, "too many leaves of one function in an integrand"); return NULL; }
  expr **terms = malloc(sizeof(expr *) * (size_t)(n + 1));
  if (!terms) { expr_set_error(c, "out of memory"); return NULL; }
  for (int i = 0; i < n; i++) {
    expr *d = expr_diff(c, f, leaf[i]);
    expr *l = expr_field(c, dir, leaf[i]->i1, leaf[i]->alpha);
    terms[i] = d && l ? expr_mul(c, d, l) : NULL;
    if (!terms[i]) { free(terms); return NULL; }
  }
  expr *r = expr_sum_n(c, n, terms);
  free(terms);
  return r;
}

form *form_variation(expr_ctx *c, const form *F, int n, const int *funcs, const int *dirs) {
  form *G = form_new();
  if (!G) { expr_set_error(c, "out of memory"); return NULL; }
  for (int i = 0; i < F->n; i++) {
    expr *sum = expr_num(c, 0);
    for (int k = 0; k < n && sum; k++) {
      expr *d = form_directional(c, F->t[i].integrand, funcs[k], dirs[k]);
      sum = d ? expr_add(c, sum, d) : NULL;
    }
    if (!sum) { form_free(G); return NULL; }
    if (sum->kind == E_CONST && sum->value == 0) continue; /* the term does not depend on them */
    if (form_add_term(G, &F->t[i].reg, sum, F->t[i].order)) { expr_set_error(c, "out of memory"); form_free(G); return NULL; }
  }
  return G;
}
