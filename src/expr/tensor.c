/* tensor.c — tensor algebra on lists with checked shapes: transpose, symmetric and skew
 * parts, trace, determinant, inverse, identity, outer and cross products, deviator. Every
 * result is built from the engine's scalar operations, so it differentiates like any other
 * expression (the derivative of det F is cof F : dF without a rule of its own). */
#include "expr.h"

#include <stdio.h>

/* a square matrix (a list of n lists of n scalars), n = 1..3; its size, or 0 with a message */
static int square(expr_ctx *c, const expr *a, const char *what) {
  char sh[64];
  if (!a) return 0;
  int n = a->kind == E_LIST ? a->n : 0;
  int ok = n >= 1 && n <= 3;
  for (int i = 0; ok && i < n; i++) {
    const expr *r = a->ch[i];
    ok = r->kind == E_LIST && r->n == n;
    for (int j = 0; ok && j < n; j++) ok = r->ch[j]->kind != E_LIST;
  }
  if (!ok) {
    expr_describe_shape(a, sh, sizeof sh);
    expr_set_error(c, "%s needs a square matrix (1x1 to 3x3), got %s", what, sh);
    return 0;
  }
  return n;
}

static expr *entry(const expr *a, int i, int j) { return a->ch[i]->ch[j]; }

static expr *matrix(expr_ctx *c, int n, int m, expr *v[3][3]) {
  expr *rows[3];
  for (int i = 0; i < n; i++) {
    for (int j = 0; j < m; j++)
      if (!v[i][j]) return NULL;
    if (!(rows[i] = expr_list(c, m, v[i]))) return NULL;
  }
  return expr_list(c, n, rows);
}

expr *expr_transpose(expr_ctx *c, expr *a) {
  if (!a) return NULL;
  char sh[64];
  int n = a->kind == E_LIST ? a->n : 0, m = n && a->ch[0]->kind == E_LIST ? a->ch[0]->n : 0;
  int ok = n >= 1 && n <= 3 && m >= 1 && m <= 3;
  for (int i = 0; ok && i < n; i++) {
    ok = a->ch[i]->kind == E_LIST && a->ch[i]->n == m;
    for (int j = 0; ok && j < m; j++) ok = a->ch[i]->ch[j]->kind != E_LIST;
  }
  if (!ok) {
    expr_describe_shape(a, sh, sizeof sh);
    expr_set_error(c, "transpose needs a matrix (up to 3x3), got %s", sh);
    return NULL;
  }
  expr *v[3][3];
  for (int i = 0; i < m; i++)
    for (int j = 0; j < n; j++) v[i][j] = entry(a, j, i);
  return matrix(c, m, n, v);
}

/* (A + s A^T) / 2: the symmetric (s = 1) or skew (s = -1) part */
static expr *half_sum(expr_ctx *c, expr *a, double sgn, const char *what) {
  int n = square(c, a, what);
  if (!n) return NULL;
  expr *v[3][3], *h = expr_num(c, 0.5), *s = expr_num(c, sgn);
  for (int i = 0; i < n; i++)
    for (int j = 0; j < n; j++) v[i][j] = expr_mul(c, h, expr_add(c, entry(a, i, j), expr_mul(c, s, entry(a, j, i))));
  return matrix(c, n, n, v);
}

expr *expr_sym(expr_ctx *c, expr *a) { return half_sum(c, a, 1, "sym"); }

expr *expr_skew(expr_ctx *c, expr *a) { return half_sum(c, a, -1, "skew"); }

expr *expr_trace(expr_ctx *c, expr *a) {
  int n = square(c, a, "tr");
  if (!n) return NULL;
  expr *d[3];
  for (int i = 0; i < n; i++) d[i] = entry(a, i, i);
  return expr_sum_n(c, n, d);
}

expr *expr_det(expr_ctx *c, expr *a) {
  int n = square(c, a, "det");
  if (!n) return NULL;
  if (n == 1) return entry(a, 0, 0);
  if (n == 2) return expr_sub(c, expr_mul(c, entry(a, 0, 0), entry(a, 1, 1)), expr_mul(c, entry(a, 0, 1), entry(a, 1, 0)));
  /* the first row against its cofactors */
  expr *s = expr_num(c, 0);
  for (int j = 0; j < 3; j++) {
    int j1 = (j + 1) % 3, j2 = (j + 2) % 3;
    expr *cof = expr_sub(c, expr_mul(c, entry(a, 1, j1), entry(a, 2, j2)), expr_mul(c, entry(a, 1, j2), entry(a, 2, j1)));
    s = expr_add(c, s, expr_mul(c, entry(a, 0, j), cof));
  }
  return s;
}

expr *expr_inv(expr_ctx *c, expr *a) {
  int n = square(c, a, "inv");
  if (!n) return NULL;
  expr *d = expr_det(c, a), *v[3][3];
  if (!d) return NULL;
  if (d->kind == E_CONST && d->value == 0) { expr_set_error(c, "inv: the matrix is singular (its determinant is 0)"); return NULL; }
  if (n == 1) {
    v[0][0] = expr_div(c, expr_num(c, 1), d);
    return matrix(c, 1, 1, v);
  }
  if (n == 2) {
    v[0][0] = expr_div(c, entry(a, 1, 1), d);
    v[0][1] = expr_div(c, expr_neg(c, entry(a, 0, 1)), d);
    v[1][0] = expr_div(c, expr_neg(c, entry(a, 1, 0)), d);
    v[1][1] = expr_div(c, entry(a, 0, 0), d);
    return matrix(c, 2, 2, v);
  }
  /* the adjugate over the determinant: inv(A)_ij = cof(A)_ji / det A */
  for (int i = 0; i < 3; i++)
    for (int j = 0; j < 3; j++) {
      int i1 = (i + 1) % 3, i2 = (i + 2) % 3, j1 = (j + 1) % 3, j2 = (j + 2) % 3;
      expr *cof = expr_sub(c, expr_mul(c, entry(a, i1, j1), entry(a, i2, j2)), expr_mul(c, entry(a, i1, j2), entry(a, i2, j1)));
      v[j][i] = expr_div(c, cof, d);
    }
  return matrix(c, 3, 3, v);
}

expr *expr_identity(expr_ctx *c, int n) {
  if (n < 1 || n > 3) { expr_set_error(c, "identity: the size must be 1, 2 or 3, got %d", n); return NULL; }
  expr *v[3][3];
  for (int i = 0; i < n; i++)
    for (int j = 0; j < n; j++) v[i][j] = expr_num(c, i == j);
  return matrix(c, n, n, v);
}

static int vector_len(expr_ctx *c, const expr *a, const char *what, int argno) {
  if (!a) return 0;
  int ok = a->kind == E_LIST && a->n >= 1 && a->n <= 3;
  for (int i = 0; ok && i < a->n; i++) ok = a->ch[i]->kind != E_LIST;
  if (!ok) {
    char sh[64];
    expr_describe_shape(a, sh, sizeof sh);
    expr_set_error(c, "%s: argument %d must be a vector of 1 to 3 entries, got %s", what, argno, sh);
    return 0;
  }
  return a->n;
}

expr *expr_outer(expr_ctx *c, expr *a, expr *b) {
  int n = vector_len(c, a, "outer", 1), m = n ? vector_len(c, b, "outer", 2) : 0;
  if (!n || !m) return NULL;
  expr *v[3][3];
  for (int i = 0; i < n; i++)
    for (int j = 0; j < m; j++) v[i][j] = expr_mul(c, a->ch[i], b->ch[j]);
  return matrix(c, n, m, v);
}

expr *expr_cross(expr_ctx *c, expr *a, expr *b) {
  int n = vector_len(c, a, "cross", 1), m = n ? vector_len(c, b, "cross", 2) : 0;
  if (!n || !m) return NULL;
  if (n != m || n < 2) {
    expr_set_error(c, "cross needs two 3-vectors (or two 2-vectors: the scalar a1 b2 - a2 b1), got a %d- and a %d-vector", n, m);
    return NULL;
  }
  if (n == 2) return expr_sub(c, expr_mul(c, a->ch[0], b->ch[1]), expr_mul(c, a->ch[1], b->ch[0]));
  expr *v[3];
  for (int i = 0; i < 3; i++) {
    int i1 = (i + 1) % 3, i2 = (i + 2) % 3;
    v[i] = expr_sub(c, expr_mul(c, a->ch[i1], b->ch[i2]), expr_mul(c, a->ch[i2], b->ch[i1]));
    if (!v[i]) return NULL;
  }
  return expr_list(c, 3, v);
}

expr *expr_dev(expr_ctx *c, expr *a) {
  int n = square(c, a, "dev");
  if (!n) return NULL;
  expr *t = expr_div(c, expr_trace(c, a), expr_num(c, n)), *v[3][3];
  for (int i = 0; i < n; i++)
    for (int j = 0; j < n; j++) v[i][j] = i == j ? expr_sub(c, entry(a, i, j), t) : entry(a, i, j);
  return matrix(c, n, n, v);
}
