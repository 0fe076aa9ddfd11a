/* expr.c — nodes, hash-consing, simplification at construction, vector calculus on
 * lists, traversal, degree estimates and printing. Differentiation and substitution are in
 * diff.c; tapes, code generation and forms in codegen.c / form.c. */
#include "expr_int.h"

#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>

/* ---------------------------------------------------------------- memo map */

int expr_memo_put(memo_map *m, int64_t key, expr *val) {
  if (2 * (m->n + 1) > m->cap) {
    size_t cap = m->cap ? 2 * m->cap : 256;
    memo_entry *ne = calloc(cap, sizeof *ne);
    if (!ne) return 1;
    for (size_t i = 0; i < m->cap; i++) {
      if (!m->e[i].val) continue;
      size_t h = mix64((uint64_t)m->e[i].key) & (cap - 1);
      while (ne[h].val) h = (h + 1) & (cap - 1);
      ne[h] = m->e[i];
    }
    free(m->e);
    m->e = ne;
    m->cap = cap;
  }
  size_t h = mix64((uint64_t)key) & (m->cap - 1);
  while (m->e[h].val) {
    if (m->e[h].key == key) { m->e[h].val = val; return 0; }
    h = (h + 1) & (m->cap - 1);
  }
  m->e[h].key = key;
  m->e[h].val = val;
  m->n++;
  return 0;
}

/* ---------------------------------------------------------------- context */

typedef struct {
  char name[64];
} param_info;

struct expr_ctx {
  expr **nodes;
  size_t nnodes, capnodes;
  expr **table; /* hash-consing table */
  size_t tcap;
  memo_map dmemo; /* derivative memo: key = node id * 2^24 + var */
  int nparam, capparam;
  param_info *params;
  double *pvals;
  int nfunc, capfunc;
  expr_func_info *funcs;
  int dim;
  int oom;
  size_t used, budget; /* node slots made (a node costs 8 + its children) and the limit */
  char err[EXPR_ERRLEN];
};

expr_ctx *expr_ctx_new(void) {
  expr_ctx *c = calloc(1, sizeof *c);
  if (!c) return NULL;
  c->dim = 2;
  c->budget = EXPR_DEFAULT_BUDGET;
  c->tcap = 1024;
  c->table = calloc(c->tcap, sizeof(expr *));
  if (!c->table) { free(c); return NULL; }
  return c;
}

void expr_ctx_free(expr_ctx *c) {
  if (!c) return;
  for (size_t i = 0; i < c->nnodes; i++) free(c->nodes[i]);
  free(c->nodes);
  free(c->table);
  memo_free(&c->dmemo);
  free(c->params);
  free(c->pvals);
  free(c->funcs);
  free(c);
}

const char *expr_error(const expr_ctx *c) { return c->err; }
void expr_set_error(expr_ctx *c, const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(c->err, sizeof c->err, fmt, ap);
  va_end(ap);
}
void expr_set_dim(expr_ctx *c, int dim) { c->dim = dim; }
int expr_dim(const expr_ctx *c) { return c->dim; }
size_t expr_node_count(const expr_ctx *c) { return c->nnodes; }
memo_map *expr_ctx_dmemo(expr_ctx *c) { return &c->dmemo; }
void expr_set_budget(expr_ctx *c, size_t slots) { c->budget = slots; }

int expr_param_new(expr_ctx *c, const char *name, double value) {
  if (c->nparam == c->capparam) {
    int cap = c->capparam ? 2 * c->capparam : 16;
    param_info *np = realloc(c->params, sizeof *np * (size_t)cap);
    if (!np) return -1;
    c->params = np;
    double *nv = realloc(c->pvals, sizeof(double) * (size_t)cap);
    if (!nv) return -1;
    c->pvals = nv;
    c->capparam = cap;
  }
  snprintf(c->params[c->nparam].name, sizeof c->params[0].name, "%s", name);
  c->pvals[c->nparam] = value;
  return c->nparam++;
}
double *expr_param_values(expr_ctx *c) { return c->pvals; }
int expr_param_count(const expr_ctx *c) { return c->nparam; }
const char *expr_param_name(const expr_ctx *c, int i) { return c->params[i].name; }

int expr_func_new(expr_ctx *c, func_kind kind, const char *name, int degree, int ncomp, void *user) {
  if (c->nfunc == c->capfunc) {
    int cap = c->capfunc ? 2 * c->capfunc : 16;
    expr_func_info *nf = realloc(c->funcs, sizeof *nf * (size_t)cap);
    if (!nf) return -1;
    c->funcs = nf;
    c->capfunc = cap;
  }
  expr_func_info *f = &c->funcs[c->nfunc];
  f->kind = kind;
  snprintf(f->name, sizeof f->name, "%s", name ? name : "f");
  f->degree = degree;
  f->ncomp = ncomp;
  f->disc = 0;
  f->side = 0;
  f->twin = -1;
  f->user = user;
  return c->nfunc++;
}
expr_func_info *expr_func_get(expr_ctx *c, int id) {
  return id >= 0 && id < c->nfunc ? &c->funcs[id] : NULL;
}
int expr_func_count(const expr_ctx *c) { return c->nfunc; }

void expr_func_forget_user(expr_ctx *c, int id) {
  expr_func_info *f = expr_func_get(c, id);
  if (!f) return;
  f->user = NULL;
  if (f->twin >= 0) c->funcs[f->twin].user = NULL;
}

int expr_func_side(expr_ctx *c, int id, int side) {
  expr_func_info *f = expr_func_get(c, id);
  if (!f) return -1;
  if (f->side == side) return id;
  if (f->twin >= 0) return f->twin;
  /* copy before expr_func_new, which may move the table */
  expr_func_info g = *f;
  char name[80];
  snprintf(name, sizeof name, "%.60s('-')", g.name);
  int t = expr_func_new(c, g.kind, name, g.degree, g.ncomp, g.user);
  if (t < 0) return -1;
  c->funcs[t].disc = g.disc;
  c->funcs[t].side = 1;
  c->funcs[t].twin = id;
  c->funcs[id].twin = t;
  return t;
}

expr *expr_restrict(expr_ctx *c, expr *e, int side) {
  e = expr_canon(c, e);
  if (!e || side == 0) return e;
  int n = expr_collect_fields(c, 1, &e, -1, 0, NULL), maxn = -1;
  expr_uses(c, e, E_NORMAL, &maxn);
  size_t cap = (size_t)n + EXPR_MAXDIM + 1;
  expr **from = malloc(sizeof(expr *) * cap), **to = malloc(sizeof(expr *) * cap);
  if (!from || !to) { free(from); free(to); expr_set_error(c, "out of memory"); return NULL; }
  n = expr_collect_fields(c, 1, &e, -1, n, from);
  int m = 0;
  for (int i = 0; i < n; i++) {
    expr_func_info *f = expr_func_get(c, from[i]->i0);
    if (!f || f->side == 1) continue;
    int t = expr_func_side(c, from[i]->i0, 1);
    if (t < 0) { free(from); free(to); expr_set_error(c, "out of memory"); return NULL; }
    from[m] = from[i];
    to[m++] = expr_field(c, t, from[i]->i1, from[i]->alpha);
  }
  for (int k = 0; k <= maxn; k++) {
    from[m] = expr_normal(c, k);
    to[m++] = expr_neg(c, expr_normal(c, k));
  }
  expr *r = m ? expr_subs(c, e, m, from, to) : e;
  free(from);
  free(to);
  return r;
}

/* ---------------------------------------------------------------- hash-consing */

static uint64_t node_hash(expr_kind k, double v, int i0, int i1, const unsigned char *al, int n,
                          expr *const *ch) {
  uint64_t h = mix64((uint64_t)k + 0x1234567ull);
  uint64_t bits;
  memcpy(&bits, &v, sizeof bits);
  h = mix64(h ^ bits);
  h = mix64(h ^ (uint64_t)(uint32_t)i0 ^ ((uint64_t)(uint32_t)i1 << 32));
  h = mix64(h ^ (uint64_t)al[0] ^ ((uint64_t)al[1] << 8) ^ ((uint64_t)al[2] << 16) ^ ((uint64_t)(uint32_t)n << 24));
  for (int i = 0; i < n; i++) h = mix64(h ^ (ch[i]->hash + (uint64_t)i));
  return h;
}

static int node_eq(const expr *e, expr_kind k, double v, int i0, int i1, const unsigned char *al,
                   int n, expr *const *ch) {
  if (e->kind != k || e->n != n || e->i0 != i0 || e->i1 != i1) return 0;
  if (memcmp(&e->value, &v, sizeof v)) return 0;
  if (memcmp(e->alpha, al, EXPR_MAXDIM)) return 0;
  for (int i = 0; i < n; i++)
    if (e->ch[i] != ch[i]) return 0;
  return 1;
}

static int table_grow(expr_ctx *c) {
  size_t cap = 2 * c->tcap;
  expr **nt = calloc(cap, sizeof(expr *));
  if (!nt) return 1;
  for (size_t i = 0; i < c->tcap; i++) {
    expr *e = c->table[i];
    if (!e) continue;
    size_t h = e->hash & (cap - 1);
    while (nt[h]) h = (h + 1) & (cap - 1);
    nt[h] = e;
  }
  free(c->table);
  c->table = nt;
  c->tcap = cap;
  return 0;
}

static expr *intern(expr_ctx *c, expr_kind k, double v, int i0, int i1, const unsigned char *alpha,
                    int n, expr *const *ch) {
  static const unsigned char zero[EXPR_MAXDIM] = {0, 0, 0};
  if (!alpha) alpha = zero;
  if (v == 0) v = 0; /* fold -0.0 */
  for (int i = 0; i < n; i++)
    if (!ch[i]) return NULL;
  uint64_t h = node_hash(k, v, i0, i1, alpha, n, ch);
  size_t pos = h & (c->tcap - 1);
  while (c->table[pos]) {
    expr *e = c->table[pos];
    if (e->hash == h && node_eq(e, k, v, i0, i1, alpha, n, ch)) return e;
    pos = (pos + 1) & (c->tcap - 1);
  }
  if (c->used + 8 + (size_t)n > c->budget) {
    expr_set_error(c, "the expressions grew past %zu node slots (about %zu MB): an expansion that grows without "
                      "bound (a high derivative of a deep chain, a huge product)? Split or simplify it",
                   c->budget, c->budget * 8 >> 20);
    return NULL;
  }
  c->used += 8 + (size_t)n;
  expr *e = calloc(1, sizeof(expr) + sizeof(expr *) * (size_t)n);
  if (!e) { c->oom = 1; expr_set_error(c, "out of memory"); return NULL; }
  e->kind = k;
  e->value = v;
  e->i0 = i0;
  e->i1 = i1;
  memcpy(e->alpha, alpha, EXPR_MAXDIM);
  e->n = n;
  e->ch = (expr **)(e + 1);
  if (n) memcpy(e->ch, ch, sizeof(expr *) * (size_t)n);
  e->hash = h;
  e->id = (int)c->nnodes;
  e->order = alpha[0] + alpha[1] + alpha[2];
  switch (k) {
  case E_PARAM: e->dep = DEP_PARAM; break;
  case E_COORD: case E_NORMAL: case E_FIELD: e->dep = DEP_POINT; break;
  default:
    for (int i = 0; i < n; i++) e->dep |= ch[i]->dep;
  }
  if (c->nnodes == c->capnodes) {
    size_t cap = c->capnodes ? 2 * c->capnodes : 1024;
    expr **nn = realloc(c->nodes, sizeof(expr *) * cap);
    if (!nn) { free(e); c->oom = 1; expr_set_error(c, "out of memory"); return NULL; }
    c->nodes = nn;
    c->capnodes = cap;
  }
  c->nodes[c->nnodes++] = e;
  c->table[pos] = e;
  if (2 * c->nnodes > c->tcap && table_grow(c)) { c->oom = 1; return NULL; }
  return e;
}

/* ---------------------------------------------------------------- leaves */

expr *expr_num(expr_ctx *c, double v) {
  if (!isfinite(v)) { expr_set_error(c, "constant %g is not finite", v); return NULL; }
  return intern(c, E_CONST, v, 0, 0, NULL, 0, NULL);
}
expr *expr_param(expr_ctx *c, int index) {
  if (index < 0 || index >= c->nparam) { expr_set_error(c, "no parameter %d", index); return NULL; }
  return intern(c, E_PARAM, 0, index, 0, NULL, 0, NULL);
}
expr *expr_coord(expr_ctx *c, int comp) {
  if (comp < 0 || comp >= EXPR_MAXDIM) { expr_set_error(c, "coordinate %d out of range 1..3", comp + 1); return NULL; }
  return intern(c, E_COORD, 0, comp, 0, NULL, 0, NULL);
}
expr *expr_normal(expr_ctx *c, int comp) {
  if (comp < 0 || comp >= EXPR_MAXDIM) { expr_set_error(c, "normal component %d out of range", comp + 1); return NULL; }
  return intern(c, E_NORMAL, 0, comp, 0, NULL, 0, NULL);
}
expr *expr_field(expr_ctx *c, int func, int comp, const unsigned char *alpha) {
  if (func < 0 || func >= c->nfunc) { expr_set_error(c, "no function %d", func); return NULL; }
  return intern(c, E_FIELD, 0, func, comp, alpha, 0, NULL);
}


/* ---------------------------------------------------------------- shapes */

int expr_shape(const expr *e, int *rank) {
  int r = 0;
  const expr *p = e;
  while (p && p->kind == E_LIST) { r++; p = p->n ? p->ch[0] : NULL; }
  if (rank) *rank = r;
  return e && e->kind == E_LIST ? e->n : 0;
}

void expr_describe_shape(const expr *e, char *buf, size_t len) {
  int rank;
  int n = expr_shape(e, &rank);
  if (rank == 0) snprintf(buf, len, "a scalar");
  else if (rank == 1) snprintf(buf, len, "a %d-vector", n);
  else if (rank == 2) snprintf(buf, len, "a %dx%d matrix", n, expr_shape(e->ch[0], NULL));
  else snprintf(buf, len, "a rank-%d list", rank);
}

static int same_shape(const expr *a, const expr *b) {
  if (a == b) return 1; /* shared entries: O(rank), not O(entries) */
  if ((a->kind == E_LIST) != (b->kind == E_LIST)) return 0;
  if (a->kind != E_LIST) return 1;
  if (a->n != b->n) return 0;
  for (int i = 0; i < a->n; i++)
    if (!same_shape(a->ch[i], b->ch[i])) return 0;
  return 1;
}

static expr *shape_error(expr_ctx *c, const char *verb, const expr *a, const expr *b) {
  char sa[64], sb[64];
  expr_describe_shape(a, sa, sizeof sa);
  expr_describe_shape(b, sb, sizeof sb);
  expr_set_error(c, "cannot %s %s and %s", verb, sa, sb);
  return NULL;
}

/* scalar entries of a (rectangular) list */
static double list_entries(const expr *e) {
  double n = 1;
  for (; e && e->kind == E_LIST; e = e->n ? e->ch[0] : NULL) n *= e->n;
  return n;
}

expr *expr_list(expr_ctx *c, int n, expr **items) {
  if (n <= 0) { expr_set_error(c, "a list needs at least one entry"); return NULL; }
  for (int i = 0; i < n; i++) {
    if (!items[i]) return NULL;
    items[i] = expr_canon(c, items[i]);
  }
  int rank;
  expr_shape(items[0], &rank);
  if (rank + 1 > EXPR_MAXRANK) {
    expr_set_error(c, "lists nest at most %d deep (this one would be rank %d)", EXPR_MAXRANK, rank + 1);
    return NULL;
  }
  if (n * list_entries(items[0]) > EXPR_MAXENTRIES) {
    expr_set_error(c, "a list of %.0f scalar entries is too large (at most %d)", n * list_entries(items[0]), EXPR_MAXENTRIES);
    return NULL;
  }
  for (int i = 0; i < n; i++) {
    if (!same_shape(items[0], items[i])) {
      expr_set_error(c, "list entries must have the same shape (entry 1 and entry %d differ)", i + 1);
      return NULL;
    }
  }
  return intern(c, E_LIST, 0, 0, 0, NULL, n, items);
}

/* elementwise map over lists of equal shape */
typedef expr *(*binop)(expr_ctx *, expr *, expr *);
static expr *zip(expr_ctx *c, expr *a, expr *b, binop op) {
  expr *tmp[64];
  expr **items = a->n <= 64 ? tmp : malloc(sizeof(expr *) * (size_t)a->n);
  if (!items) return NULL;
  expr *r = NULL;
  int i;
  for (i = 0; i < a->n; i++)
    if (!(items[i] = op(c, a->ch[i], b->ch[i]))) break;
  if (i == a->n) r = expr_list(c, a->n, items);
  if (items != tmp) free(items);
  return r;
}
static expr *map_scalar(expr_ctx *c, expr *s, expr *list, binop op, int scalar_first) {
  expr *tmp[64];
  expr **items = list->n <= 64 ? tmp : malloc(sizeof(expr *) * (size_t)list->n);
  if (!items) return NULL;
  expr *r = NULL;
  int i;
  for (i = 0; i < list->n; i++)
    if (!(items[i] = scalar_first ? op(c, s, list->ch[i]) : op(c, list->ch[i], s))) break;
  if (i == list->n) r = expr_list(c, list->n, items);
  if (items != tmp) free(items);
  return r;
}

/* ---------------------------------------------------------------- sums */

typedef struct {
  expr *rest; /* NULL for the constant */
  double coef;
} term;

static int term_cmp(const void *pa, const void *pb) {
  const term *a = pa, *b = pb;
  if (a->rest->hash != b->rest->hash) return a->rest->hash < b->rest->hash ? -1 : 1;
  return (a->rest->id > b->rest->id) - (a->rest->id < b->rest->id);
}

static void split_coef(expr *t, double *coef, expr **rest, expr_ctx *c) {
  if (t->kind == E_CONST) { *coef = t->value; *rest = NULL; return; }
  if (t->kind == E_PROD && t->ch[0]->kind == E_CONST) {
    *coef = t->ch[0]->value;
    if (t->n == 2) *rest = t->ch[1];
    else *rest = intern(c, E_PROD, 0, 0, 0, NULL, t->n - 1, t->ch + 1);
    return;
  }
  *coef = 1;
  *rest = t;
}

static expr *scale(expr_ctx *c, double s, expr *e);

expr *expr_sum_n(expr_ctx *c, int n, expr **in) {
  for (int i = 0; i < n; i++) {
    if (!in[i]) return NULL;
    in[i] = expr_canon(c, in[i]);
    if (!in[i]) return NULL;
  }
  if (n == 0) return expr_num(c, 0);
  if (n == 1) return in[0];
  /* lists: elementwise */
  int nlist = 0;
  for (int i = 0; i < n; i++) nlist += in[i]->kind == E_LIST;
  if (nlist) {
    expr *acc = in[0];
    for (int i = 1; i < n && acc; i++) {
      if (!same_shape(acc, in[i])) return shape_error(c, "add", acc, in[i]);
      acc = zip(c, acc, in[i], expr_add);
    }
    return acc;
  }
  /* flatten */
  int cnt = 0;
  for (int i = 0; i < n; i++) cnt += in[i]->kind == E_SUM ? in[i]->n : 1;
  term *t = malloc(sizeof(term) * (size_t)cnt);
  if (!t) { expr_set_error(c, "out of memory"); return NULL; }
  int k = 0;
  double konst = 0;
  for (int i = 0; i < n; i++) {
    int m = in[i]->kind == E_SUM ? in[i]->n : 1;
    expr *const *src = in[i]->kind == E_SUM ? in[i]->ch : &in[i];
    for (int j = 0; j < m; j++) {
      double cf;
      expr *rest;
      split_coef(src[j], &cf, &rest, c);
      if (!rest) {
        if (src[j]->kind != E_CONST) { free(t); return NULL; }
        konst += cf;
      } else {
        t[k].rest = rest;
        t[k].coef = cf;
        k++;
      }
    }
  }
  qsort(t, (size_t)k, sizeof(term), term_cmp);
  /* merge like terms */
  int m = 0;
  for (int i = 0; i < k; i++) {
    if (m > 0 && t[m - 1].rest == t[i].rest) t[m - 1].coef += t[i].coef;
    else t[m++] = t[i];
  }
  expr **out = malloc(sizeof(expr *) * (size_t)(m + 1));
  if (!out) { free(t); expr_set_error(c, "out of memory"); return NULL; }
  int o = 0;
  if (konst != 0) out[o++] = expr_num(c, konst);
  for (int i = 0; i < m; i++) {
    if (t[i].coef == 0) continue;
    out[o] = t[i].coef == 1 ? t[i].rest : scale(c, t[i].coef, t[i].rest);
    if (!out[o]) { free(t); free(out); return NULL; }
    o++;
  }
  free(t);
  expr *r;
  if (o == 0) r = expr_num(c, 0);
  else if (o == 1) r = out[0];
  else r = intern(c, E_SUM, 0, 0, 0, NULL, o, out);
  free(out);
  return r;
}

expr *expr_add(expr_ctx *c, expr *a, expr *b) {
  a = expr_canon(c, a);
  b = expr_canon(c, b);
  expr *v[2] = {a, b};
  if (a && b && a->kind == E_LIST && b->kind == E_LIST && !same_shape(a, b))
    return shape_error(c, "add", a, b);
  if (a && b && (a->kind == E_LIST) != (b->kind == E_LIST)) return shape_error(c, "add", a, b);
  return expr_sum_n(c, 2, v);
}

expr *expr_neg(expr_ctx *c, expr *a) {
  a = expr_canon(c, a);
  if (!a) return NULL;
  return expr_mul(c, expr_num(c, -1), a);
}

expr *expr_sub(expr_ctx *c, expr *a, expr *b) {
  a = expr_canon(c, a);
  b = expr_canon(c, b);
  if (a && b && ((a->kind == E_LIST) != (b->kind == E_LIST) || !same_shape(a, b)))
    return shape_error(c, "subtract", b, a);
  return expr_add(c, a, expr_neg(c, b));
}

/* ---------------------------------------------------------------- products */

typedef struct {
  expr *base, *exp;
} factor;

static int factor_cmp(const void *pa, const void *pb) {
  const factor *a = pa, *b = pb;
  if (a->base->hash != b->base->hash) return a->base->hash < b->base->hash ? -1 : 1;
  return (a->base->id > b->base->id) - (a->base->id < b->base->id);
}

/* s * e for a scalar constant s, without re-sorting when e is already canonical */
static expr *scale(expr_ctx *c, double s, expr *e) {
  if (!e) return NULL;
  if (s == 1) return e;
  if (s == 0) return expr_num(c, 0);
  if (e->kind == E_CONST) return expr_num(c, s * e->value);
  if (e->kind == E_PROD) {
    if (e->ch[0]->kind == E_CONST) {
      double v = s * e->ch[0]->value;
      if (v == 1) return e->n == 2 ? e->ch[1] : intern(c, E_PROD, 0, 0, 0, NULL, e->n - 1, e->ch + 1);
      expr *tmp[16];
      expr **ch = e->n <= 16 ? tmp : malloc(sizeof(expr *) * (size_t)e->n);
      if (!ch) return NULL;
      memcpy(ch, e->ch, sizeof(expr *) * (size_t)e->n);
      ch[0] = expr_num(c, v);
      expr *r = intern(c, E_PROD, 0, 0, 0, NULL, e->n, ch);
      if (ch != tmp) free(ch);
      return r;
    }
    expr **ch = malloc(sizeof(expr *) * (size_t)(e->n + 1));
    if (!ch) return NULL;
    ch[0] = expr_num(c, s);
    memcpy(ch + 1, e->ch, sizeof(expr *) * (size_t)e->n);
    expr *r = intern(c, E_PROD, 0, 0, 0, NULL, e->n + 1, ch);
    free(ch);
    return r;
  }
  expr *ch[2] = {expr_num(c, s), e};
  return intern(c, E_PROD, 0, 0, 0, NULL, 2, ch);
}

expr *expr_prod_n(expr_ctx *c, int n, expr **in) {
  for (int i = 0; i < n; i++) {
    if (!in[i]) return NULL;
    in[i] = expr_canon(c, in[i]);
    if (!in[i]) return NULL;
  }
  if (n == 0) return expr_num(c, 1);
  if (n == 1) return in[0];
  int nlist = 0, li = -1;
  for (int i = 0; i < n; i++)
    if (in[i]->kind == E_LIST) { nlist++; li = i; }
  if (nlist > 1) {
    int a = -1, b = -1;
    for (int i = 0; i < n; i++)
      if (in[i]->kind == E_LIST) { if (a < 0) a = i; else if (b < 0) b = i; }
    char sa[64], sb[64];
    expr_describe_shape(in[a], sa, sizeof sa);
    expr_describe_shape(in[b], sb, sizeof sb);
    expr_set_error(c, "cannot multiply %s and %s with *; use lg.dot or lg.inner", sa, sb);
    return NULL;
  }
  if (nlist == 1) {
    expr **rest = malloc(sizeof(expr *) * (size_t)n);
    if (!rest) return NULL;
    int k = 0;
    for (int i = 0; i < n; i++)
      if (i != li) rest[k++] = in[i];
    expr *s = expr_prod_n(c, k, rest);
    free(rest);
    if (!s) return NULL;
    return map_scalar(c, s, in[li], expr_mul, 1);
  }
  int cnt = 0;
  for (int i = 0; i < n; i++) cnt += in[i]->kind == E_PROD ? in[i]->n : 1;
  factor *f = malloc(sizeof(factor) * (size_t)cnt);
  if (!f) { expr_set_error(c, "out of memory"); return NULL; }
  double coef = 1;
  int k = 0;
  expr *one = expr_num(c, 1);
  for (int i = 0; i < n; i++) {
    int m = in[i]->kind == E_PROD ? in[i]->n : 1;
    expr *const *src = in[i]->kind == E_PROD ? in[i]->ch : &in[i];
    for (int j = 0; j < m; j++) {
      expr *e = src[j];
      if (e->kind == E_CONST) { coef *= e->value; continue; }
      if (e->kind == E_POW) { f[k].base = e->ch[0]; f[k].exp = e->ch[1]; }
      else { f[k].base = e; f[k].exp = one; }
      k++;
    }
  }
  if (coef == 0 || !isfinite(coef)) {
    free(f);
    if (!isfinite(coef)) { expr_set_error(c, "constant product is not finite"); return NULL; }
    return expr_num(c, 0);
  }
  qsort(f, (size_t)k, sizeof(factor), factor_cmp);
  int m = 0;
  for (int i = 0; i < k; i++) {
    if (m > 0 && f[m - 1].base == f[i].base) f[m - 1].exp = expr_add(c, f[m - 1].exp, f[i].exp);
    else f[m++] = f[i];
  }
  expr **out = malloc(sizeof(expr *) * (size_t)(m + 1));
  if (!out) { free(f); return NULL; }
  int o = 1;
  for (int i = 0; i < m; i++) {
    if (!f[i].exp) { free(f); free(out); return NULL; }
    expr *p = expr_pow(c, f[i].base, f[i].exp);
    if (!p) { free(f); free(out); return NULL; }
    if (p->kind == E_CONST) { coef *= p->value; continue; }
    if (p->kind == E_PROD) { /* (2x)^2 distributed: fold its constant, keep the rest */
      for (int j = 0; j < p->n; j++) {
        if (p->ch[j]->kind == E_CONST) coef *= p->ch[j]->value;
        else {
          expr **no = realloc(out, sizeof(expr *) * (size_t)(o + p->n + m + 1));
          if (!no) { free(f); free(out); return NULL; }
          out = no;
          out[o++] = p->ch[j];
        }
      }
      continue;
    }
    out[o++] = p;
  }
  free(f);
  expr *r;
  int nf = o - 1;
  if (nf == 0) r = expr_num(c, coef);
  else {
    /* re-sort: folded powers may change order */
    factor *g = malloc(sizeof(factor) * (size_t)nf);
    if (!g) { free(out); return NULL; }
    for (int i = 0; i < nf; i++) { g[i].base = out[i + 1]; g[i].exp = NULL; }
    qsort(g, (size_t)nf, sizeof(factor), factor_cmp);
    for (int i = 0; i < nf; i++) out[i + 1] = g[i].base;
    free(g);
    if (nf == 1 && coef == 1) r = out[1];
    else if (nf == 1 && out[1]->kind == E_SUM) {
      /* a number times a sum is distributed (2(a + b) = 2a + 2b), so that a sum minus
       * itself cancels to 0 term by term */
      expr *S = out[1];
      expr **t = malloc(sizeof(expr *) * (size_t)S->n);
      if (!t) { free(out); expr_set_error(c, "out of memory"); return NULL; }
      for (int i = 0; i < S->n; i++) t[i] = scale(c, coef, S->ch[i]);
      r = expr_sum_n(c, S->n, t);
      free(t);
    } else if (coef == 1) r = intern(c, E_PROD, 0, 0, 0, NULL, nf, out + 1);
    else {
      out[0] = expr_num(c, coef);
      r = intern(c, E_PROD, 0, 0, 0, NULL, nf + 1, out);
    }
  }
  free(out);
  return r;
}

expr *expr_mul(expr_ctx *c, expr *a, expr *b) {
  expr *v[2] = {a, b}; /* expr_prod_n resolves them */
  return expr_prod_n(c, 2, v);
}

/* ---------------------------------------------------------------- pending sums and products */

#define LAZY_MIN 32 /* a sum or product of this many terms grows by pending nodes */

static int big(const expr *e, expr_kind flat, expr_kind lazy) {
  return e && (e->kind == lazy || (e->kind == flat && e->n >= LAZY_MIN));
}

static expr *pending(expr_ctx *c, expr_kind k, expr *base, expr *extra) {
  extra = expr_canon(c, extra);
  if (!extra) return NULL;
  if (k == E_LAZY_SUM && is_const(extra, 0)) return base;
  if (k == E_LAZY_PROD && is_const(extra, 1)) return base;
  if (k == E_LAZY_PROD && is_const(extra, 0)) return extra;
  expr *ch[2] = {base, extra};
  return intern(c, k, 0, 0, 0, NULL, 2, ch);
}

expr *expr_add_lazy(expr_ctx *c, expr *a, expr *b) {
  if (!a || !b) return NULL;
  int ba = big(a, E_SUM, E_LAZY_SUM), bb = big(b, E_SUM, E_LAZY_SUM);
  if (ba && !bb && b->kind != E_LIST) return pending(c, E_LAZY_SUM, a, b);
  if (bb && !ba && a->kind != E_LIST) return pending(c, E_LAZY_SUM, b, a);
  return expr_add(c, a, b);
}

expr *expr_sub_lazy(expr_ctx *c, expr *a, expr *b) {
  if (!a || !b) return NULL;
  if (big(a, E_SUM, E_LAZY_SUM) && b->kind != E_LIST) return pending(c, E_LAZY_SUM, a, expr_neg(c, b));
  return expr_sub(c, a, b);
}

expr *expr_mul_lazy(expr_ctx *c, expr *a, expr *b) {
  if (!a || !b) return NULL;
  int ba = big(a, E_PROD, E_LAZY_PROD), bb = big(b, E_PROD, E_LAZY_PROD);
  if (ba && !bb && b->kind != E_LIST) return pending(c, E_LAZY_PROD, a, b);
  if (bb && !ba && a->kind != E_LIST) return pending(c, E_LAZY_PROD, b, a);
  return expr_mul(c, a, b);
}

expr *expr_canon(expr_ctx *c, expr *e) {
  if (!e || (e->kind != E_LAZY_SUM && e->kind != E_LAZY_PROD)) return e;
  if (e->canon) return e->canon;
  /* the chain of pending nodes down to its resolved base, without recursion */
  expr_kind k = e->kind;
  size_t n = 0, cap = 64;
  expr **ops = malloc(sizeof(expr *) * cap);
  if (!ops) { expr_set_error(c, "out of memory"); return NULL; }
  expr *p = e;
  for (;;) {
    if (n + 2 > cap) {
      expr **no = realloc(ops, sizeof(expr *) * (cap *= 2));
      if (!no) { free(ops); expr_set_error(c, "out of memory"); return NULL; }
      ops = no;
    }
    if (p->kind == k && !p->canon) {
      ops[n++] = p->ch[1];
      p = p->ch[0];
      continue;
    }
    ops[n++] = p->kind == k ? p->canon : expr_canon(c, p);
    break;
  }
  if (n > (size_t)INT_MAX) { free(ops); expr_set_error(c, "a sum of more than %d terms", INT_MAX); return NULL; }
  expr *r = k == E_LAZY_SUM ? expr_sum_n(c, (int)n, ops) : expr_prod_n(c, (int)n, ops);
  free(ops);
  e->canon = r;
  return r;
}

expr *expr_pow(expr_ctx *c, expr *a, expr *b) {
  a = expr_canon(c, a);
  b = expr_canon(c, b);
  if (!a || !b) return NULL;
  if (a->kind == E_LIST || b->kind == E_LIST) return shape_error(c, "raise to a power", a, b);
  if (b->kind == E_CONST) {
    double p = b->value;
    if (p == 0) return expr_num(c, 1);
    if (p == 1) return a;
    if (a->kind == E_CONST) {
      if (a->value == 0 && p < 0) { expr_set_error(c, "division by zero"); return NULL; }
      double v = pow(a->value, p);
      if (!isfinite(v)) { expr_set_error(c, "%g^%g is not a real number", a->value, p); return NULL; }
      return expr_num(c, v);
    }
    int integer = p == floor(p) && fabs(p) < 1e6;
    if (a->kind == E_POW && integer)
      return expr_pow(c, a->ch[0], expr_mul(c, a->ch[1], b));
    if (a->kind == E_PROD && integer) {
      expr **f = malloc(sizeof(expr *) * (size_t)a->n);
      if (!f) return NULL;
      for (int i = 0; i < a->n; i++) f[i] = expr_pow(c, a->ch[i], b);
      expr *r = expr_prod_n(c, a->n, f);
      free(f);
      return r;
    }
  }
  if (is_const(a, 0)) {
    if (b->kind == E_CONST && b->value > 0) return expr_num(c, 0);
  }
  if (is_const(a, 1)) return expr_num(c, 1);
  expr *ch[2] = {a, b};
  return intern(c, E_POW, 0, 0, 0, NULL, 2, ch);
}

expr *expr_div(expr_ctx *c, expr *a, expr *b) {
  a = expr_canon(c, a);
  b = expr_canon(c, b);
  if (!a || !b) return NULL;
  if (b->kind == E_LIST) return shape_error(c, "divide", a, b);
  if (is_const(b, 0)) { expr_set_error(c, "division by zero"); return NULL; }
  return expr_mul(c, a, expr_pow(c, b, expr_num(c, -1)));
}

static double apply_const(expr_fn fn, double x) {
  switch (fn) {
  case FN_SIN: return sin(x);
  case FN_COS: return cos(x);
  case FN_TAN: return tan(x);
  case FN_EXP: return exp(x);
  case FN_LOG: return log(x);
  case FN_SQRT: return sqrt(x);
  case FN_ABS: return fabs(x);
  case FN_TANH: return tanh(x);
  case FN_SINH: return sinh(x);
  case FN_COSH: return cosh(x);
  case FN_ATAN: return atan(x);
  case FN_ASIN: return asin(x);
  case FN_ACOS: return acos(x);
  case FN_SIGN: return (x > 0) - (x < 0);
  default: return NAN;
  }
}

static const char *fn_names[FN_COUNT] = {"sin", "cos", "tan", "exp", "log", "sqrt", "abs",
                                         "tanh", "sinh", "cosh", "atan", "asin", "acos", "sign"};

expr *expr_apply(expr_ctx *c, expr_fn fn, expr *a) {
  a = expr_canon(c, a);
  if (!a) return NULL;
  if (a->kind == E_LIST) {
    char s[64];
    expr_describe_shape(a, s, sizeof s);
    expr_set_error(c, "%s takes a scalar, got %s", fn_names[fn], s);
    return NULL;
  }
  if (fn == FN_SQRT) return expr_pow(c, a, expr_num(c, 0.5));
  if (a->kind == E_CONST) {
    double v = apply_const(fn, a->value);
    if (!isfinite(v)) { expr_set_error(c, "%s(%g) is not a real number", fn_names[fn], a->value); return NULL; }
    return expr_num(c, v);
  }
  if (fn == FN_EXP && a->kind == E_FUNC && a->i0 == FN_LOG) return a->ch[0];
  if (fn == FN_LOG && a->kind == E_FUNC && a->i0 == FN_EXP) return a->ch[0];
  return intern(c, E_FUNC, 0, fn, 0, NULL, 1, &a);
}

/* ---------------------------------------------------------------- vector calculus */

expr *expr_index(expr_ctx *c, expr *l, int i) {
  l = expr_canon(c, l);
  if (!l) return NULL;
  if (l->kind != E_LIST) { expr_set_error(c, "cannot index a scalar"); return NULL; }
  if (i < 0 || i >= l->n) {
    expr_set_error(c, "index %d out of range 1..%d", i + 1, l->n);
    return NULL;
  }
  return l->ch[i];
}

expr *expr_dot(expr_ctx *c, expr *a, expr *b) {
  a = expr_canon(c, a);
  b = expr_canon(c, b);
  if (!a || !b) return NULL;
  if (a->kind != E_LIST && b->kind != E_LIST) return expr_mul(c, a, b);
  if (a->kind != E_LIST || b->kind != E_LIST) return shape_error(c, "take the dot product of", a, b);
  /* contract the last index of a with the first of b */
  int ra, rb;
  expr_shape(a, &ra);
  expr_shape(b, &rb);
  /* the result has entries(a) entries(b) / n^2 entries, each a sum of n products: bound the
   * work before doing it (a rank-8 list dotted with another would be billions of nodes) */
  const expr *last = a;
  while (last->kind == E_LIST && last->n && last->ch[0]->kind == E_LIST) last = last->ch[0];
  double n = last->n, work = list_entries(a) * list_entries(b) / n;
  if (ra + rb - 2 > EXPR_MAXRANK || work > 4.0 * EXPR_MAXENTRIES) {
    char sa[64], sb[64];
    expr_describe_shape(a, sa, sizeof sa);
    expr_describe_shape(b, sb, sizeof sb);
    expr_set_error(c, "the dot product of %s and %s is too large (%.0f products; at most %d)", sa, sb, work, 4 * EXPR_MAXENTRIES);
    return NULL;
  }
  if (ra == 1) {
    if (a->n != b->n) return shape_error(c, "take the dot product of", a, b);
    expr **t = malloc(sizeof(expr *) * (size_t)a->n);
    if (!t) return NULL;
    for (int i = 0; i < a->n; i++) t[i] = expr_mul(c, a->ch[i], b->ch[i]);
    expr *r = expr_sum_n(c, a->n, t);
    free(t);
    return r;
  }
  expr **rows = malloc(sizeof(expr *) * (size_t)a->n);
  if (!rows) return NULL;
  for (int i = 0; i < a->n; i++) rows[i] = expr_dot(c, a->ch[i], b);
  expr *r = expr_list(c, a->n, rows);
  free(rows);
  return r;
}

expr *expr_inner(expr_ctx *c, expr *a, expr *b) {
  a = expr_canon(c, a);
  b = expr_canon(c, b);
  if (!a || !b) return NULL;
  if (!same_shape(a, b)) return shape_error(c, "take the inner product of", a, b);
  if (a->kind != E_LIST) return expr_mul(c, a, b);
  expr **t = malloc(sizeof(expr *) * (size_t)a->n);
  if (!t) return NULL;
  for (int i = 0; i < a->n; i++) t[i] = expr_inner(c, a->ch[i], b->ch[i]);
  expr *r = expr_sum_n(c, a->n, t);
  free(t);
  return r;
}

expr *expr_grad(expr_ctx *c, expr *a) {
  a = expr_canon(c, a);
  if (!a) return NULL;
  expr *t[EXPR_MAXDIM];
  if (a->kind == E_LIST) {
    expr **rows = malloc(sizeof(expr *) * (size_t)a->n);
    if (!rows) return NULL;
    for (int i = 0; i < a->n; i++) rows[i] = expr_grad(c, a->ch[i]);
    expr *r = expr_list(c, a->n, rows);
    free(rows);
    return r;
  }
  for (int d = 0; d < c->dim; d++) t[d] = expr_dx(c, a, d);
  return expr_list(c, c->dim, t);
}

expr *expr_div_op(expr_ctx *c, expr *a) {
  a = expr_canon(c, a);
  if (!a) return NULL;
  int rank;
  int n = expr_shape(a, &rank);
  if (rank == 2 && n >= 1 && n <= EXPR_MAXDIM) {
    /* a matrix: the divergence of each row, (div A)_i = d A_ij / d x_j */
    expr *rows[EXPR_MAXDIM];
    for (int i = 0; i < n; i++)
      if (!(rows[i] = expr_div_op(c, a->ch[i]))) return NULL;
    return expr_list(c, n, rows);
  }
  if (rank != 1 || n != c->dim) {
    char s[64];
    expr_describe_shape(a, s, sizeof s);
    expr_set_error(c, "div takes a %d-vector or a matrix of %d columns, got %s", c->dim, c->dim, s);
    return NULL;
  }
  expr *t[EXPR_MAXDIM];
  for (int d = 0; d < n; d++) t[d] = expr_dx(c, a->ch[d], d);
  return expr_sum_n(c, n, t);
}

/* ---------------------------------------------------------------- traversal */

int expr_post_order(expr_ctx *c, expr *root, memo_map *seen, post_visit visit, post_visit skip, void *ud) {
  typedef struct { expr *e; int next; } frame;
  if (memo_get(seen, root->id)) return 0;
  int cap = 64, sp = 0;
  frame *st = malloc(sizeof(frame) * (size_t)cap);
  if (!st) { expr_set_error(c, "out of memory"); return 1; }
  st[sp++] = (frame){root, 0};
  if (expr_memo_put(seen, root->id, root)) { free(st); expr_set_error(c, "out of memory"); return 1; }
  while (sp) {
    frame *f = &st[sp - 1];
    if (f->next < f->e->n) {
      expr *ch = f->e->ch[f->next++];
      if (memo_get(seen, ch->id) || (skip && skip(ud, ch))) continue;
      if (expr_memo_put(seen, ch->id, ch)) { free(st); expr_set_error(c, "out of memory"); return 1; }
      if (sp == cap) {
        frame *ns = realloc(st, sizeof(frame) * (size_t)(cap *= 2));
        if (!ns) { free(st); expr_set_error(c, "out of memory"); return 1; }
        st = ns;
      }
      st[sp++] = (frame){ch, 0};
      continue;
    }
    expr *done = f->e;
    sp--;
    if (visit(ud, done)) { free(st); return 1; }
  }
  free(st);
  return 0;
}

/* ---------------------------------------------------------------- queries */

typedef struct {
  int func, max, n;
  expr **out;
  expr_kind kind;
  int found, *maxcomp;
} query_ctx;

static int collect_visit(void *ud, expr *e) {
  query_ctx *Q = ud;
  if (e->kind == E_FIELD && (Q->func < 0 || e->i0 == Q->func)) {
    if (Q->n < Q->max) Q->out[Q->n] = e;
    Q->n++;
  }
  return 0;
}

int expr_collect_fields(expr_ctx *c, int nroot, expr **roots, int func, int max, expr **out) {
  memo_map seen = {0, 0, NULL};
  query_ctx Q = {func, max, 0, out, E_FIELD, 0, NULL};
  for (int i = 0; i < nroot; i++) {
    expr *r = expr_canon(c, roots[i]);
    if (r && expr_post_order(c, r, &seen, collect_visit, NULL, &Q)) break;
  }
  memo_free(&seen);
  int n = Q.n;
  /* sort by function, component, derivative: a deterministic order for kernels */
  int m = n < max ? n : max;
  for (int i = 1; i < m; i++) {
    expr *v = out[i];
    int j = i - 1;
    while (j >= 0 && (out[j]->i0 > v->i0 || (out[j]->i0 == v->i0 && (out[j]->i1 > v->i1 ||
           (out[j]->i1 == v->i1 && memcmp(out[j]->alpha, v->alpha, EXPR_MAXDIM) > 0))))) {
      out[j + 1] = out[j];
      j--;
    }
    out[j + 1] = v;
  }
  return n;
}

static int uses_visit(void *ud, expr *e) {
  query_ctx *Q = ud;
  if (e->kind == Q->kind) {
    Q->found = 1;
    if (Q->maxcomp && e->i0 > *Q->maxcomp) *Q->maxcomp = e->i0;
  }
  return 0;
}

int expr_uses(expr_ctx *c, expr *e, expr_kind kind, int *maxcomp) {
  memo_map seen = {0, 0, NULL};
  query_ctx Q = {-1, 0, 0, NULL, kind, 0, maxcomp};
  e = expr_canon(c, e);
  if (e) expr_post_order(c, e, &seen, uses_visit, NULL, &Q);
  memo_free(&seen);
  return Q.found;
}

static int param_visit(void *ud, expr *e) {
  if (e->kind == E_PARAM) ((unsigned char *)ud)[e->i0] = 1;
  return 0;
}

int expr_collect_params(expr_ctx *c, int nroot, expr **roots, int max, int *out) {
  int np = expr_param_count(c), n = 0, rc = 0;
  unsigned char *used = calloc((size_t)np + 1, 1); /* per parameter index */
  if (!used) { expr_set_error(c, "out of memory"); return -1; }
  memo_map seen = {0, 0, NULL};
  for (int i = 0; i < nroot && !rc; i++) {
    expr *r = expr_canon(c, roots[i]);
    if (r) rc = expr_post_order(c, r, &seen, param_visit, NULL, used);
  }
  memo_free(&seen);
  for (int k = 0; k < np; k++)
    if (used[k]) {
      if (n < max) out[n] = k;
      n++;
    }
  free(used);
  return rc ? -1 : n;
}

/* kinks: abs and sign of something that depends on given functions or parameters */
typedef struct {
  memo_map dep; /* nodes that depend on them */
  int nf, np;
  const int *fids, *pids;
  expr *found;
} kink_ctx;

static int kink_visit(void *ud, expr *e) {
  kink_ctx *K = ud;
  int d = 0;
  if (e->kind == E_FIELD)
    for (int i = 0; i < K->nf && !d; i++) d = e->i0 == K->fids[i];
  else if (e->kind == E_PARAM)
    for (int i = 0; i < K->np && !d; i++) d = e->i0 == K->pids[i];
  for (int i = 0; i < e->n && !d; i++) d = memo_get(&K->dep, e->ch[i]->id) != NULL;
  if (!d) return 0;
  if (!K->found && e->kind == E_FUNC && (e->i0 == FN_ABS || e->i0 == FN_SIGN)) K->found = e;
  return expr_memo_put(&K->dep, e->id, e);
}

expr *expr_find_kink(expr_ctx *c, expr *e, int nf, const int *fids, int np, const int *pids) {
  memo_map seen = {0, 0, NULL};
  kink_ctx K = {{0, 0, NULL}, nf, np, fids, pids, NULL};
  e = expr_canon(c, e);
  if (e) expr_post_order(c, e, &seen, kink_visit, NULL, &K);
  memo_free(&seen);
  memo_free(&K.dep);
  return K.found;
}

/* degrees memoized per node (a DAG shared many times is visited once) */
typedef struct {
  expr_ctx *c;
  int cd;
  int simplex;  /* derivatives lower a leaf's degree (not on tensor-product cells) */
  int inexact;  /* a node that is not a polynomial of its arguments (sin, u^0.5, 1/u, ...) */
  memo_map deg; /* node id -> (expr *)(degree + 1) */
} degree_ctx;

static int deg_of(degree_ctx *D, const expr *e) { return (int)(intptr_t)memo_get(&D->deg, e->id) - 1; }

static int degree_visit(void *ud, expr *e) {
  degree_ctx *D = ud;
  int d = 0;
  switch (e->kind) {
  case E_CONST: case E_PARAM: case E_NORMAL: d = 0; break;
  case E_COORD: d = D->cd; break;
  case E_FIELD: {
    expr_func_info *f = expr_func_get(D->c, e->i0);
    d = f ? f->degree - (D->simplex ? e->order : 0) : 0;
    if (d < 0) d = 0;
    break;
  }
  case E_SUM: case E_LIST: case E_LAZY_SUM:
    for (int i = 0; i < e->n; i++) {
      int k = deg_of(D, e->ch[i]);
      if (k > d) d = k;
    }
    break;
  case E_PROD: case E_LAZY_PROD:
    for (int i = 0; i < e->n && d < 1000; i++) d += deg_of(D, e->ch[i]);
    break;
  case E_POW: {
    int b = deg_of(D, e->ch[0]);
    expr *p = e->ch[1];
    if (p->kind == E_CONST && p->value >= 0 && p->value == floor(p->value) && p->value < 100) d = b * (int)p->value;
    else {
      d = b ? b + 2 : 0;
      D->inexact |= b > 0 || deg_of(D, p) > 0;
    }
    break;
  }
  case E_FUNC: {
    int b = deg_of(D, e->ch[0]);
    d = b ? b + 2 : 0;
    D->inexact |= b > 0;
    break;
  }
  }
  if (d > 1000) d = 1000; /* far above any quadrature the caller will take */
  return expr_memo_put(&D->deg, e->id, (expr *)(intptr_t)(d + 1));
}

int expr_degree_exact(expr_ctx *c, expr *e, int cd, int *exact) { return expr_degree_cell(c, e, cd, 1, exact); }

int expr_degree_cell(expr_ctx *c, expr *e, int cd, int simplex, int *exact) {
  if (exact) *exact = 1;
  e = expr_canon(c, e);
  if (!e) return 0;
  memo_map seen = {0, 0, NULL};
  degree_ctx D = {c, cd, simplex, 0, {0, 0, NULL}};
  int d = 0;
  if (!expr_post_order(c, e, &seen, degree_visit, NULL, &D)) d = deg_of(&D, e);
  else D.inexact = 1;
  memo_free(&seen);
  memo_free(&D.deg);
  if (exact) *exact = !D.inexact && d < 1000;
  return d < 0 ? 0 : d;
}

int expr_degree(expr_ctx *c, expr *e, int cd) { return expr_degree_exact(c, e, cd, NULL); }

/* ---------------------------------------------------------------- printing */

typedef struct {
  char *buf;
  size_t len, pos;
} pbuf;

static void pput(pbuf *p, const char *fmt, ...) {
  if (p->pos >= p->len) return;
  va_list ap;
  va_start(ap, fmt);
  int n = vsnprintf(p->buf + p->pos, p->len - p->pos, fmt, ap);
  va_end(ap);
  if (n > 0) p->pos += (size_t)n;
  if (p->pos >= p->len) {
    p->pos = p->len;
    if (p->len > 4) memcpy(p->buf + p->len - 4, "...", 4);
  }
}

/* a text form for people: it stops when the buffer is full (a shared DAG printed as a tree
 * can be exponentially long) and prints deep nesting as "..." */
#define PRINT_DEPTH 64
static void print_rec(expr_ctx *c, const expr *e, pbuf *p, int prec, int depth) {
  static const char *xyz = "xyz";
  if (p->pos >= p->len) return;
  if (depth > PRINT_DEPTH) { pput(p, "..."); return; }
  switch (e->kind) {
  case E_CONST:
    if (e->value < 0 && prec > 0) pput(p, "(%.15g)", e->value);
    else pput(p, "%.15g", e->value);
    return;
  case E_PARAM: pput(p, "%s", c->params[e->i0].name); return;
  case E_COORD: pput(p, "%c", xyz[e->i0]); return;
  case E_NORMAL: pput(p, "n%c", xyz[e->i0]); return;
  case E_FIELD: {
    expr_func_info *f = expr_func_get(c, e->i0);
    const char *nm = f ? f->name : "?";
    char comp[16] = "";
    if (f && f->ncomp > 1) snprintf(comp, sizeof comp, "[%d]", e->i1 + 1);
    if (e->order == 0) { pput(p, "%s%s", nm, comp); return; }
    pput(p, "d");
    for (int d = 0; d < EXPR_MAXDIM; d++)
      for (int k = 0; k < e->alpha[d]; k++) pput(p, "%c", xyz[d]);
    pput(p, "(%s%s)", nm, comp);
    return;
  }
  case E_SUM:
    if (prec > 1) pput(p, "(");
    for (int i = 0; i < e->n && p->pos < p->len; i++) {
      const expr *t = e->ch[i];
      if (i > 0) {
        if (t->kind == E_PROD && t->ch[0]->kind == E_CONST && t->ch[0]->value < 0) {
          pput(p, " - ");
          if (t->ch[0]->value != -1) pput(p, "%.15g*", -t->ch[0]->value);
          for (int j = 1; j < t->n; j++) {
            if (j > 1) pput(p, "*");
            print_rec(c, t->ch[j], p, 2, depth + 1);
          }
          continue;
        }
        if (t->kind == E_CONST && t->value < 0) { pput(p, " - %.15g", -t->value); continue; }
        pput(p, " + ");
      }
      print_rec(c, t, p, 1, depth + 1);
    }
    if (prec > 1) pput(p, ")");
    return;
  case E_PROD:
    if (prec > 2) pput(p, "(");
    for (int i = 0; i < e->n && p->pos < p->len; i++) {
      if (i == 0 && e->ch[0]->kind == E_CONST && e->ch[0]->value == -1) { pput(p, "-"); continue; }
      if (i > 0 && !(i == 1 && e->ch[0]->kind == E_CONST && e->ch[0]->value == -1)) pput(p, "*");
      print_rec(c, e->ch[i], p, 2, depth + 1);
    }
    if (prec > 2) pput(p, ")");
    return;
  case E_POW:
    print_rec(c, e->ch[0], p, 3, depth + 1);
    pput(p, "^");
    print_rec(c, e->ch[1], p, 3, depth + 1);
    return;
  case E_FUNC:
    pput(p, "%s(", fn_names[e->i0]);
    print_rec(c, e->ch[0], p, 0, depth + 1);
    pput(p, ")");
    return;
  case E_LAZY_SUM: case E_LAZY_PROD: /* resolved by expr_print before */
    pput(p, "?");
    return;
  case E_LIST:
    pput(p, "{");
    for (int i = 0; i < e->n && p->pos < p->len; i++) {
      if (i) pput(p, ", ");
      print_rec(c, e->ch[i], p, 0, depth + 1);
    }
    pput(p, "}");
    return;
  }
}

void expr_print(expr_ctx *c, const expr *e, char *buf, size_t len) {
  pbuf p = {buf, len, 0};
  buf[0] = 0;
  if (!e) { pput(&p, "(null)"); return; }
  e = expr_canon(c, (expr *)e);
  if (!e) { pput(&p, "(out of memory)"); return; }
  print_rec(c, e, &p, 0, 0);
}

const char *expr_fn_name(expr_fn fn);
const char *expr_fn_name(expr_fn fn) { return fn_names[fn]; }
