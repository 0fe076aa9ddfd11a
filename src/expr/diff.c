/* diff.c — differentiation of expressions: with respect to a leaf (a field variable D^a f_c
 * or a parameter) for the coefficient tables of residuals, Jacobians, adjoints and
 * sensitivities, and in space (d/dx_i, pushed to the leaves by the chain and product rules
 * when an expression is built); memoized per (node, leaf, direction) in the context; and
 * substitution of leaves (rebuilding the DAG above them). */
#include "expr_int.h"

#include <math.h>
#include <string.h>

/* ---------------------------------------------------------------- differentiation */

/* mode: leaf != NULL: d/d(leaf); else spatial derivative in direction dir */
static expr *deriv(expr_ctx *c, expr *e, expr *leaf, int dir);

static expr *deriv_fn(expr_ctx *c, expr_fn fn, expr *a) {
  switch (fn) {
  case FN_SIN: return expr_apply(c, FN_COS, a);
  case FN_COS: return expr_neg(c, expr_apply(c, FN_SIN, a));
  case FN_TAN: { expr *t = expr_apply(c, FN_TAN, a); return expr_add(c, expr_num(c, 1), expr_mul(c, t, t)); }
  case FN_EXP: return expr_apply(c, FN_EXP, a);
  case FN_LOG: return expr_pow(c, a, expr_num(c, -1));
  case FN_ABS: return expr_apply(c, FN_SIGN, a);
  case FN_TANH: { expr *t = expr_apply(c, FN_TANH, a); return expr_sub(c, expr_num(c, 1), expr_mul(c, t, t)); }
  case FN_SINH: return expr_apply(c, FN_COSH, a);
  case FN_COSH: return expr_apply(c, FN_SINH, a);
  case FN_ATAN: return expr_pow(c, expr_add(c, expr_num(c, 1), expr_mul(c, a, a)), expr_num(c, -1));
  case FN_ASIN: return expr_pow(c, expr_sub(c, expr_num(c, 1), expr_mul(c, a, a)), expr_num(c, -0.5));
  case FN_ACOS: return expr_neg(c, expr_pow(c, expr_sub(c, expr_num(c, 1), expr_mul(c, a, a)), expr_num(c, -0.5)));
  case FN_SIGN: return expr_num(c, 0);
  default: return NULL;
  }
}

/* the product rule on a flat product of n factors that all depend on the variable makes n
 * terms of n - 1 factors: past this many, an error instead of gigabytes */
#define PROD_RULE_MAX 4096
static int deriv_zero(const expr *e, const expr *leaf);

static expr *deriv_uncached(expr_ctx *c, expr *e, expr *leaf, int dir) {
  switch (e->kind) {
  case E_CONST: case E_PARAM: case E_NORMAL:
    return expr_num(c, leaf && e == leaf ? 1 : 0);
  case E_COORD:
    if (leaf) return expr_num(c, e == leaf ? 1 : 0);
    return expr_num(c, e->i0 == dir ? 1 : 0);
  case E_FIELD:
    if (leaf) return expr_num(c, e == leaf ? 1 : 0);
    {
      unsigned char al[EXPR_MAXDIM];
      memcpy(al, e->alpha, EXPR_MAXDIM);
      if (al[dir] >= 250) { expr_set_error(c, "derivative order too high"); return NULL; }
      al[dir]++;
      return expr_field(c, e->i0, e->i1, al);
    }
  case E_LIST: {
    expr **t = malloc(sizeof(expr *) * (size_t)e->n);
    if (!t) return NULL;
    for (int i = 0; i < e->n; i++) t[i] = deriv(c, e->ch[i], leaf, dir);
    expr *r = expr_list(c, e->n, t);
    free(t);
    return r;
  }
  case E_LAZY_SUM: case E_LAZY_PROD: /* never memoized unresolved: deriv resolves first */
    return deriv(c, expr_canon(c, e), leaf, dir);
  case E_SUM: {
    /* one term that depends on the variable (g + 0.001): its derivative as it is, still
     * pending, so that a chain through such sums stays linear in size */
    int k = 0, last = -1;
    for (int i = 0; i < e->n; i++)
      if (!deriv_zero(e->ch[i], leaf)) { k++; last = i; }
    if (k == 0) return expr_num(c, 0);
    if (k == 1) return deriv(c, e->ch[last], leaf, dir);
    expr **t = malloc(sizeof(expr *) * (size_t)e->n);
    if (!t) return NULL;
    for (int i = 0; i < e->n; i++) t[i] = deriv(c, e->ch[i], leaf, dir);
    expr *r = expr_sum_n(c, e->n, t);
    free(t);
    return r;
  }
  case E_PROD: {
    /* product rule: (the other factors) * d(factor i), the derivative kept pending so that
     * a chain of products does not flatten into quadratically many factors */
    int ndep = 0;
    for (int i = 0; i < e->n; i++) ndep += !deriv_zero(e->ch[i], leaf);
    if (ndep > PROD_RULE_MAX) { /* the result would hold ndep^2 factors */
      expr_set_error(c, "differentiating a product of %d factors that all depend on the variable would make %d terms "
                        "of %d factors each (at most %d such factors)", ndep, ndep, ndep - 1, PROD_RULE_MAX);
      return NULL;
    }
    expr **t = malloc(sizeof(expr *) * (size_t)e->n);
    expr **f = malloc(sizeof(expr *) * (size_t)e->n);
    if (!t || !f) { free(t); free(f); return NULL; }
    int k = 0;
    for (int i = 0; i < e->n; i++) {
      expr *d = deriv(c, e->ch[i], leaf, dir);
      if (!d) { free(t); free(f); return NULL; }
      if (is_const(d, 0)) continue;
      int m = 0;
      for (int j = 0; j < e->n; j++)
        if (j != i) f[m++] = e->ch[j];
      t[k] = expr_mul_lazy(c, m == 1 ? f[0] : expr_prod_n(c, m, f), d);
      if (!t[k++]) { free(t); free(f); return NULL; }
    }
    expr *r = k == 1 ? t[0] : expr_sum_n(c, k, t);
    free(t);
    free(f);
    return r;
  }
  case E_POW: {
    expr *a = e->ch[0], *b = e->ch[1];
    expr *da = deriv(c, a, leaf, dir), *db = deriv(c, b, leaf, dir);
    if (!da || !db) return NULL;
    expr *r1 = NULL, *r2 = NULL;
    if (!is_const(da, 0)) /* b a^(b-1) a' */
      r1 = expr_mul_lazy(c, expr_mul(c, b, expr_pow(c, a, expr_sub(c, b, expr_num(c, 1)))), da);
    if (!is_const(db, 0)) /* a^b log(a) b' */
      r2 = expr_mul_lazy(c, expr_mul(c, e, expr_apply(c, FN_LOG, a)), db);
    if (r1 && r2) return expr_add(c, r1, r2);
    if (r1 || r2) return r1 ? r1 : r2;
    return is_const(da, 0) && is_const(db, 0) ? expr_num(c, 0) : NULL;
  }
  case E_FUNC: {
    expr *a = e->ch[0];
    expr *da = deriv(c, a, leaf, dir);
    if (!da) return NULL;
    if (is_const(da, 0)) return da;
    return expr_mul_lazy(c, deriv_fn(c, (expr_fn)e->i0, a), da);
  }
  }
  return NULL;
}

/* d e / d leaf (leaf != NULL) or d e / d x_dir: zero when e cannot depend on it */
static int deriv_zero(const expr *e, const expr *leaf) {
  if (leaf) return !(e->dep & leaf->dep) && e != leaf;
  return !(e->dep & DEP_POINT);
}

static int64_t deriv_key(const expr *e, const expr *leaf, int dir) {
  return ((int64_t)e->id << 32) | (leaf ? (int64_t)leaf->id : (int64_t)0x80000000 + dir);
}

/* the derivatives of the nodes under e, children before parents (post_order): then
 * deriv_uncached(e) finds every child's derivative memoized, and no depth of expression (a
 * chain of 100 000 functions) recurses on the C stack */
typedef struct {
  expr_ctx *c;
  expr *root, *leaf;
  int dir;
} deriv_walk;

static int deriv_skip(void *ud, expr *ch) {
  deriv_walk *D = ud;
  return ch->n == 0 || deriv_zero(ch, D->leaf) || memo_get(expr_ctx_dmemo(D->c), deriv_key(ch, D->leaf, D->dir));
}

static int deriv_visit(void *ud, expr *e) {
  deriv_walk *D = ud;
  if (e == D->root) return 0; /* the caller's */
  expr *r = deriv_uncached(D->c, e, D->leaf, D->dir);
  return !r || expr_memo_put(expr_ctx_dmemo(D->c), deriv_key(e, D->leaf, D->dir), r);
}

static int deriv_below(expr_ctx *c, expr *e, expr *leaf, int dir) {
  deriv_walk D = {c, e, leaf, dir};
  memo_map seen = {0, 0, NULL};
  int rc = expr_post_order(c, e, &seen, deriv_visit, deriv_skip, &D);
  memo_free(&seen);
  return rc;
}

static expr *deriv(expr_ctx *c, expr *e, expr *leaf, int dir) {
  if (!e) return NULL;
  if (deriv_zero(e, leaf)) return expr_num(c, 0);
  if (e->n == 0) return deriv_uncached(c, e, leaf, dir);
  int64_t key = deriv_key(e, leaf, dir);
  expr *m = memo_get(expr_ctx_dmemo(c), key);
  if (m) return m;
  if (deriv_below(c, e, leaf, dir)) return NULL;
  expr *r = deriv_uncached(c, e, leaf, dir);
  if (r && expr_memo_put(expr_ctx_dmemo(c), key, r)) return NULL;
  return r;
}

expr *expr_diff(expr_ctx *c, expr *e, expr *leaf) {
  e = expr_canon(c, e);
  if (!e || !leaf) return NULL;
  if (leaf->kind != E_FIELD && leaf->kind != E_PARAM && leaf->kind != E_COORD && leaf->kind != E_NORMAL) {
    expr_set_error(c, "can only differentiate with respect to a field, parameter or coordinate");
    return NULL;
  }
  return expr_canon(c, deriv(c, expr_canon(c, e), leaf, -1));
}

expr *expr_dx(expr_ctx *c, expr *e, int dir) {
  if (!e) return NULL;
  if (dir < 0 || dir >= EXPR_MAXDIM) { expr_set_error(c, "direction %d out of range 1..3", dir + 1); return NULL; }
  return expr_canon(c, deriv(c, expr_canon(c, e), NULL, dir));
}

/* ---------------------------------------------------------------- rebuild / subs */

static expr *rebuild(expr_ctx *c, const expr *e, expr **ch) {
  switch (e->kind) {
  case E_SUM: return expr_sum_n(c, e->n, ch);
  case E_PROD: return expr_prod_n(c, e->n, ch);
  case E_POW: return expr_pow(c, ch[0], ch[1]);
  case E_FUNC: return expr_apply(c, (expr_fn)e->i0, ch[0]);
  case E_LIST: return expr_list(c, e->n, ch);
  default: return (expr *)e;
  }
}

typedef struct {
  expr_ctx *c;
  int n;
  expr **from, **to;
  memo_map out; /* node id -> its image */
} subs_ctx;

static int subs_visit(void *ud, expr *e) {
  subs_ctx *S = ud;
  for (int i = 0; i < S->n; i++)
    if (e == S->from[i]) return expr_memo_put(&S->out, e->id, S->to[i]);
  if (e->n == 0) return expr_memo_put(&S->out, e->id, e);
  expr *tmp[8];
  expr **ch = e->n <= 8 ? tmp : malloc(sizeof(expr *) * (size_t)e->n);
  if (!ch) return 1;
  int changed = 0;
  for (int i = 0; i < e->n; i++) {
    ch[i] = memo_get(&S->out, e->ch[i]->id);
    changed |= ch[i] != e->ch[i];
  }
  expr *r = changed ? rebuild(S->c, e, ch) : e;
  if (ch != tmp) free(ch);
  return !r || expr_memo_put(&S->out, e->id, r);
}

expr *expr_subs(expr_ctx *c, expr *e, int n, expr **from, expr **to) {
  e = expr_canon(c, e);
  if (!e) return NULL;
  for (int i = 0; i < n; i++) {
    to[i] = expr_canon(c, to[i]);
    if (!to[i]) return NULL;
  }
  memo_map seen = {0, 0, NULL};
  subs_ctx S = {c, n, from, to, {0, 0, NULL}};
  expr *r = NULL;
  if (!expr_post_order(c, e, &seen, subs_visit, NULL, &S)) r = memo_get(&S.out, e->id);
  memo_free(&seen);
  memo_free(&S.out);
  return r;
}

