/* codegen.c — evaluation tapes (topologically sorted DAG nodes), the tape interpreter
 * used for boundary values and interpolation, and plain C99 generation with common
 * subexpressions hoisted into named temporaries. Generated names are t<k>, P[i] and the
 * leaf names a caller supplies: never user text. */
#include "expr.h"

#include <math.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>

void sb_printf(strbuf *b, const char *fmt, ...) {
  if (b->failed) return;
  for (;;) {
    va_list ap;
    va_start(ap, fmt);
    size_t room = b->cap - b->len;
    int n = b->s ? vsnprintf(b->s + b->len, room, fmt, ap) : -2;
    va_end(ap);
    if (n >= 0 && (size_t)n < room) { b->len += (size_t)n; return; }
    size_t cap = b->cap ? 2 * b->cap : 4096;
    while (n >= 0 && cap < b->len + (size_t)n + 1) cap *= 2;
    char *s = realloc(b->s, cap);
    if (!s) { b->failed = 1; return; }
    b->s = s;
    b->cap = cap;
  }
}

void sb_free(strbuf *b) { free(b->s); b->s = NULL; b->len = b->cap = 0; }

/* ---------------------------------------------------------------- tapes */

/* node id → tape index: an open-addressing table of (id, index) pairs */
typedef struct {
  int cap;
  int *kv;
} tape_index_map;

static int tim_build(const expr_tape *t, tape_index_map *m) {
  m->cap = 16;
  while (m->cap < 2 * t->n) m->cap <<= 1;
  m->kv = malloc(sizeof(int) * (size_t)m->cap * 2);
  if (!m->kv) return 1;
  for (int i = 0; i < m->cap; i++) m->kv[2 * i] = -1;
  for (int k = 0; k < t->n; k++) {
    unsigned h = (unsigned)t->node[k]->id * 2654435761u & (unsigned)(m->cap - 1);
    while (m->kv[2 * h] >= 0) h = (h + 1) & (unsigned)(m->cap - 1);
    m->kv[2 * h] = t->node[k]->id;
    m->kv[2 * h + 1] = k;
  }
  return 0;
}

/* tape index of a node known to be on the tape */
static int tim_get(const tape_index_map *m, const expr *e) {
  unsigned h = (unsigned)e->id * 2654435761u & (unsigned)(m->cap - 1);
  while (m->kv[2 * h] != e->id) h = (h + 1) & (unsigned)(m->cap - 1);
  return m->kv[2 * h + 1];
}

static int tape_visit(expr *e, expr_tape *t, int *cap, int *mark, int maxid) {
  if (e->id >= maxid) return 1;
  if (mark[e->id]) return 0;
  /* iterative post-order to survive deep DAGs */
  typedef struct { expr *e; int next; } frame;
  int scap = 64, sp = 0;
  frame *st = malloc(sizeof(frame) * (size_t)scap);
  if (!st) return 1;
  st[sp++] = (frame){e, 0};
  mark[e->id] = -1;
  while (sp) {
    frame *f = &st[sp - 1];
    if (f->next < f->e->n) {
      expr *ch = f->e->ch[f->next++];
      if (mark[ch->id]) continue;
      mark[ch->id] = -1;
      if (sp == scap) {
        scap *= 2;
        frame *ns = realloc(st, sizeof(frame) * (size_t)scap);
        if (!ns) { free(st); return 1; }
        st = ns;
      }
      st[sp++] = (frame){ch, 0};
      continue;
    }
    if (t->n == *cap) {
      *cap *= 2;
      expr **nn = realloc(t->node, sizeof(expr *) * (size_t)*cap);
      if (!nn) { free(st); return 1; }
      t->node = nn;
    }
    mark[f->e->id] = t->n + 1;
    t->node[t->n++] = f->e;
    sp--;
  }
  free(st);
  return 0;
}

int expr_tape_build(expr_ctx *c, int nroot, expr **roots, expr_tape *t) {
  for (int i = 0; i < nroot; i++) roots[i] = expr_canon(c, roots[i]); /* may make nodes */
  int maxid = (int)expr_node_count(c);
  int *mark = calloc((size_t)maxid + 1, sizeof(int));
  int cap = 64;
  t->n = 0;
  t->node = malloc(sizeof(expr *) * (size_t)cap);
  t->nroot = nroot;
  t->root = malloc(sizeof(int) * (size_t)(nroot + 1));
  if (!mark || !t->node || !t->root) goto fail;
  for (int i = 0; i < nroot; i++) {
    if (!roots[i] || tape_visit(roots[i], t, &cap, mark, maxid)) goto fail;
    t->root[i] = mark[roots[i]->id] - 1;
  }
  free(mark);
  return 0;
fail:
  free(mark);
  expr_tape_free(t);
  expr_set_error(c, "out of memory building an evaluation tape");
  return 1;
}

void expr_tape_free(expr_tape *t) {
  free(t->node);
  free(t->root);
  t->node = NULL;
  t->root = NULL;
  t->n = t->nroot = 0;
}

int expr_tape_eval(const expr_tape *t, const double *params, expr_leaf_fn leaf, void *ud,
                   double *w, double *out) {
  tape_index_map m;
  if (tim_build(t, &m)) return 1;
  int rc = 0;
  for (int k = 0; k < t->n && !rc; k++) {
    const expr *e = t->node[k];
    double v = 0;
    switch (e->kind) {
    case E_CONST: v = e->value; break;
    case E_PARAM: v = params[e->i0]; break;
    case E_COORD: case E_NORMAL: case E_FIELD:
      if (leaf(ud, e, &v)) rc = 1;
      break;
    case E_SUM:
      for (int i = 0; i < e->n; i++) v += w[tim_get(&m, e->ch[i])];
      break;
    case E_PROD:
      v = 1;
      for (int i = 0; i < e->n; i++) v *= w[tim_get(&m, e->ch[i])];
      break;
    case E_POW: case E_FUNC: {
      double a[2];
      for (int i = 0; i < e->n; i++) a[i] = w[tim_get(&m, e->ch[i])];
      if (e->kind == E_POW) {
        double p = a[1];
        if (p == 2) v = a[0] * a[0];
        else if (p == -1) v = 1.0 / a[0];
        else if (p == 0.5) v = sqrt(a[0]);
        else v = pow(a[0], p);
      } else {
        double x = a[0];
        switch ((expr_fn)e->i0) {
        case FN_SIN: v = sin(x); break;
        case FN_COS: v = cos(x); break;
        case FN_TAN: v = tan(x); break;
        case FN_EXP: v = exp(x); break;
        case FN_LOG: v = log(x); break;
        case FN_SQRT: v = sqrt(x); break;
        case FN_ABS: v = fabs(x); break;
        case FN_TANH: v = tanh(x); break;
        case FN_SINH: v = sinh(x); break;
        case FN_COSH: v = cosh(x); break;
        case FN_ATAN: v = atan(x); break;
        case FN_ASIN: v = asin(x); break;
        case FN_ACOS: v = acos(x); break;
        case FN_SIGN: v = (x > 0) - (x < 0); break;
        default: v = NAN;
        }
      }
      break;
    }
    case E_LIST: case E_LAZY_SUM: case E_LAZY_PROD: v = NAN; break;
    }
    w[k] = v;
  }
  for (int i = 0; i < t->nroot && !rc; i++) out[i] = w[t->root[i]];
  free(m.kv);
  return rc;
}

/* ---------------------------------------------------------------- point caches */

/* Which nodes of a kernel's tape a per-point cache can hold: the largest subexpressions that
 * depend on the coordinates only (no field, normal or parameter below them) and call a
 * transcendental function or pow (a target sin(pi x) sin(pi y), a source exp(-40 r^2)).
 * Their values at the quadrature points do not change between assemblies on the same
 * geometry, so an optimization loop that assembles J and its gradient hundreds of times
 * computes them once. Classes (for the nodes that vary in the cell):
 *   PC_CACHED: a cached value (slot[k] its index);
 *   PC_INNER:  needed only to compute cached values (skipped when they are loaded);
 *   PC_SHARED: coordinate-only, needed elsewhere too, cheap (computed always, first);
 *   PC_OTHER:  the rest (computed always, after). */
int expr_tape_point_cache(const expr_tape *t, unsigned char *cls, int *slot) {
  tape_index_map m;
  if (tim_build(t, &m)) return -1;
  int n = t->n;
  unsigned char *f = calloc((size_t)n + 1, 1);
  if (!f) { free(m.kv); return -1; }
  enum { XONLY = 1, HASFN = 2, NONX_PARENT = 4, LIVE = 8, CLOS = 16 };
  for (int k = 0; k < n; k++) {
    const expr *e = t->node[k];
    int x = 1, fn = 0;
    if (e->kind == E_FIELD || e->kind == E_NORMAL || e->kind == E_PARAM) x = 0;
    if (!(e->dep & DEP_POINT)) x = 0;
    if (e->kind == E_FUNC) fn = 1;
    if (e->kind == E_POW) {
      const expr *p = e->ch[1];
      fn = !(p->kind == E_CONST && p->value == floor(p->value) && fabs(p->value) <= 4);
    }
    for (int i = 0; i < e->n; i++) {
      int c = tim_get(&m, e->ch[i]);
      if (t->node[c]->dep & DEP_POINT) x &= (f[c] & XONLY) != 0;
      else if (t->node[c]->dep & DEP_PARAM) x = 0;
      fn |= (f[c] & HASFN) != 0;
    }
    f[k] = (unsigned char)((x ? XONLY : 0) | (fn ? HASFN : 0));
    if (!x)
      for (int i = 0; i < e->n; i++) f[tim_get(&m, e->ch[i])] |= NONX_PARENT;
  }
  int nc = 0;
  for (int r = 0; r < t->nroot; r++) f[t->root[r]] |= NONX_PARENT | LIVE;
  for (int k = 0; k < n; k++) {
    slot[k] = -1;
    if ((f[k] & (XONLY | HASFN | NONX_PARENT)) == (XONLY | HASFN | NONX_PARENT) && t->node[k]->kind != E_COORD)
      slot[k] = nc++;
  }
  /* parents come after their children on the tape: walk it backwards */
  for (int k = n - 1; k >= 0; k--) {
    const expr *e = t->node[k];
    int live = (f[k] & LIVE) && slot[k] < 0, clos = slot[k] >= 0 || (f[k] & CLOS);
    for (int i = 0; i < e->n; i++) {
      int c = tim_get(&m, e->ch[i]);
      if (live) f[c] |= LIVE;
      if (clos) f[c] |= CLOS;
    }
  }
  for (int k = 0; k < n; k++) {
    if (slot[k] >= 0) cls[k] = PC_CACHED;
    else if ((f[k] & LIVE) && (f[k] & XONLY)) cls[k] = PC_SHARED;
    else if (f[k] & LIVE) cls[k] = PC_OTHER;
    else if (f[k] & CLOS) cls[k] = PC_INNER;
    else cls[k] = PC_OTHER;
  }
  free(f);
  free(m.kv);
  return nc;
}

/* ---------------------------------------------------------------- vector calls */

static int vector_fn(int fn) {
  return fn == FN_SIN || fn == FN_COS || fn == FN_TAN || fn == FN_EXP || fn == FN_LOG || fn == FN_TANH ||
         fn == FN_SINH || fn == FN_COSH || fn == FN_ATAN || fn == FN_ASIN || fn == FN_ACOS;
}

int expr_tape_vector_calls(const expr_tape *t, int *level) {
  tape_index_map m;
  if (tim_build(t, &m)) return -1;
  unsigned char *xo = malloc((size_t)t->n + 1);
  if (!xo) { free(m.kv); return -1; }
  int nv = 0;
  for (int k = 0; k < t->n; k++) {
    const expr *e = t->node[k];
    int x = e->kind != E_FIELD && e->kind != E_NORMAL;
    for (int i = 0; i < e->n; i++) x &= xo[tim_get(&m, e->ch[i])];
    xo[k] = (unsigned char)x;
    level[k] = 0;
    if (e->kind == E_FUNC && vector_fn(e->i0) && x && (e->dep & DEP_POINT)) nv++, level[k] = 1;
  }
  /* levels: 1 + the highest level of the calls below the argument */
  int *below = calloc((size_t)t->n + 1, sizeof(int));
  if (!below) { free(xo); free(m.kv); return -1; }
  for (int k = 0; k < t->n; k++) {
    const expr *e = t->node[k];
    int b = 0;
    for (int i = 0; i < e->n; i++) {
      int c = tim_get(&m, e->ch[i]);
      int bc = level[c] ? level[c] : below[c];
      if (bc > b) b = bc;
    }
    below[k] = b;
    if (level[k]) level[k] = 1 + b;
  }
  /* calls nested deeper than EXPR_VECTOR_LEVELS stay per point (a deep chain of calls
   * would otherwise get a loop each); so does everything above them */
  for (int k = 0; k < t->n; k++)
    if (level[k] > EXPR_VECTOR_LEVELS) { level[k] = 0; nv--; }
  free(below);
  free(xo);
  free(m.kv);
  return nv;
}

int expr_tape_vector_closure(const expr_tape *t, const unsigned char *roots, const int *level, unsigned char *mark) {
  tape_index_map m;
  if (tim_build(t, &m)) return -1;
  /* parents come after their children: one backward pass over a "needed" flag */
  unsigned char *need = calloc((size_t)t->n + 1, 1);
  if (!need) { free(m.kv); return -1; }
  for (int j = t->n - 1; j >= 0; j--) {
    const expr *f = t->node[j];
    if (roots[j]) {
      for (int i = 0; i < f->n; i++) need[tim_get(&m, f->ch[i])] = 1;
      continue;
    }
    if (!need[j] || !(f->dep & DEP_POINT)) continue; /* the others are computed before the loops */
    if (level[j]) { mark[j] = 3; continue; }
    mark[j] = 1;
    for (int i = 0; i < f->n; i++) need[tim_get(&m, f->ch[i])] = 1;
  }
  free(need);
  free(m.kv);
  return 0;
}

int expr_tape_live(const expr_tape *t, const unsigned char *need, const int *level, unsigned char *live) {
  tape_index_map m;
  if (tim_build(t, &m)) return -1;
  /* parents come after their children: one backward pass */
  for (int j = t->n - 1; j >= 0; j--) {
    const expr *f = t->node[j];
    if (need[j]) live[j] = 1;
    if (!live[j] || !(f->dep & DEP_POINT) || level[j]) continue;
    for (int i = 0; i < f->n; i++) live[tim_get(&m, f->ch[i])] = 1;
  }
  free(m.kv);
  return 0;
}

/* ---------------------------------------------------------------- C code */

void expr_codegen_ref(const expr_tape *t, int k, const char *prefix, expr_leaf_name_fn leafname,
                      void *ud, char *buf, size_t len) {
  const expr *e = t->node[k];
  switch (e->kind) {
  case E_CONST:
    if (e->value < 0) snprintf(buf, len, "(%.17g)", e->value);
    else snprintf(buf, len, "%.17g", e->value);
    /* make integer literals doubles */
    if (!strpbrk(buf, ".eEn")) {
      size_t l = strlen(buf);
      if (buf[l - 1] == ')') { buf[l - 1] = 0; snprintf(buf + l - 1, len - l + 1, ".0)"); }
      else snprintf(buf + l, len - l, ".0");
    }
    return;
  case E_COORD: case E_NORMAL: case E_FIELD:
    leafname(ud, e, buf, len);
    return;
  default:
    snprintf(buf, len, "%s%d", prefix, k);
  }
}

static const char *c_fn(expr_fn fn) {
  static const char *n[FN_COUNT] = {"sin", "cos", "tan", "exp", "log", "sqrt", "fabs",
                                    "tanh", "sinh", "cosh", "atan", "asin", "acos", NULL};
  return n[fn];
}

void expr_codegen(strbuf *b, const expr_tape *t, const char *prefix, const char *param_array,
                  const unsigned char *select, expr_leaf_name_fn leafname, void *ud,
                  const char *indent) {
  tape_index_map m;
  if (tim_build(t, &m)) { b->failed = 1; return; }
  char r0[128], r1[128];
  for (int k = 0; k < t->n; k++) {
    if (!select[k]) continue;
    const expr *e = t->node[k];
    if (e->kind == E_CONST || e->kind == E_COORD || e->kind == E_NORMAL || e->kind == E_FIELD ||
        e->kind == E_LIST)
      continue;
    if (e->kind == E_PARAM) {
      sb_printf(b, "%sconst double %s%d = %s[%d];\n", indent, prefix, k, param_array, e->i0);
      continue;
    }
    if (select[k] == 3 || select[k] == 4) {
      sb_printf(b, select[k] == 4 ? "%s%s%d = V%d[q];\n" : "%sconst double %s%d = V%d[q];\n", indent, prefix, k, k);
      continue;
    }
    int ci[2] = {0, 0};
    sb_printf(b, select[k] == 2 ? "%s%s%d = " : "%sconst double %s%d = ", indent, prefix, k);
    for (int i = 0; i < e->n; i++) {
      int c = tim_get(&m, e->ch[i]);
      if (i < 2) ci[i] = c;
      if (e->kind == E_SUM || e->kind == E_PROD) {
        expr_codegen_ref(t, c, prefix, leafname, ud, r0, sizeof r0);
        if (e->ch[i]->kind == E_PARAM) snprintf(r0, sizeof r0, "%s%d", prefix, c);
        sb_printf(b, "%s%s", i ? (e->kind == E_SUM ? " + " : "*") : "", r0);
      }
    }
    if (e->kind == E_POW || e->kind == E_FUNC) {
      expr_codegen_ref(t, ci[0], prefix, leafname, ud, r0, sizeof r0);
      if (t->node[ci[0]]->kind == E_PARAM) snprintf(r0, sizeof r0, "%s%d", prefix, ci[0]);
      if (e->kind == E_FUNC) {
        if (e->i0 == FN_SIGN) sb_printf(b, "(double)((%s > 0.0) - (%s < 0.0))", r0, r0);
        else sb_printf(b, "%s(%s)", c_fn((expr_fn)e->i0), r0);
      } else {
        const expr *p = e->ch[1];
        if (p->kind == E_CONST && p->value == floor(p->value) && fabs(p->value) <= 4) {
          int n = (int)fabs(p->value);
          if (p->value < 0) sb_printf(b, "1.0/(");
          for (int i = 0; i < n; i++) sb_printf(b, "%s%s", i ? "*" : "", r0);
          if (p->value < 0) sb_printf(b, ")");
        } else if (p->kind == E_CONST && p->value == 0.5) {
          sb_printf(b, "sqrt(%s)", r0);
        } else if (p->kind == E_CONST && p->value == -0.5) {
          sb_printf(b, "1.0/sqrt(%s)", r0);
        } else {
          expr_codegen_ref(t, ci[1], prefix, leafname, ud, r1, sizeof r1);
          if (t->node[ci[1]]->kind == E_PARAM) snprintf(r1, sizeof r1, "%s%d", prefix, ci[1]);
          sb_printf(b, "pow(%s, %s)", r0, r1);
        }
      }
    }
    sb_printf(b, ";\n");
  }
  free(m.kv);
}
