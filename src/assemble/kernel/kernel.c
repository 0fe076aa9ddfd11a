/* kernel.c — generated element kernels (the JIT that compiles them is jit.c). Generated C
 * is self-contained (no #include: it costs milliseconds in libtcc), names only generated
 * identifiers, bakes the basis tabulations in as static tables and hoists parameter-only
 * subexpressions out of the quadrature loop. */
#include "kernel.h"
#include "../../mesh/mesh.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---------------------------------------------------------------- generation */

typedef struct {
  const lg_kernel *k;
  int dim;
} leafctx;

static int coef_index(const lg_kernel *k, int func) {
  for (int i = 0; i < k->ncoef; i++)
    if (k->coef_func[i] == func) return i;
  return -1;
}

static void leafname(void *ud, const expr *e, char *buf, size_t len) {
  leafctx *lc = ud;
  if (e->kind == E_COORD) { snprintf(buf, len, "x%d", e->i0); return; }
  if (e->kind == E_NORMAL) { snprintf(buf, len, "n%d", e->i0); return; }
  int ci = coef_index(lc->k, e->i0);
  int dir = -1;
  for (int d = 0; d < EXPR_MAXDIM; d++)
    if (e->alpha[d]) dir = d;
  char comp[16] = "";
  if (lc->k->coef_ncomp[ci] > 1) snprintf(comp, sizeof comp, "c%d", e->i1);
  if (dir < 0) snprintf(buf, len, "w%d%sv", ci, comp);
  else snprintf(buf, len, "w%d%sg%d", ci, comp, dir);
}

/* the main loop loads the vector calls' values (expr_codegen's select 3 and 4) */
static void vector_select(unsigned char *sel, const int *vlev, int n) {
  for (int i = 0; i < n; i++)
    if (vlev[i] && (sel[i] == 1 || sel[i] == 2)) sel[i] = (unsigned char)(sel[i] + 2);
}

/* the quadrature loop emits only the live nodes (expr_tape_live) */
static void keep_live(unsigned char *sel, const unsigned char *live, int n) {
  for (int i = 0; i < n; i++)
    if (!live[i]) sel[i] = 0;
}

static void emit_table(strbuf *b, const char *name, const double *v, long n) {
  sb_printf(b, "static const double %s[%ld] = {", name, n);
  for (long i = 0; i < n; i++) sb_printf(b, "%s%.17g", i ? (i % 4 ? ", " : ",\n  ") : "", v[i]);
  sb_printf(b, "};\n");
}

/* straight-line code for loops of at most this many trips: libtcc keeps every value on the
 * stack and computes every index, so an unrolled loop of constant indices runs about twice
 * as fast as the loop (bench/RESULTS.md "Kernels that libtcc runs well"); the sums keep
 * their order, so the values are the same to the bit */
#define KER_UNROLL 10

/* 1 if the n rows of len values each are all equal to the first: a P1 or P0 basis's
 * reference gradients, the same at every quadrature point */
static int rows_equal(const double *t, long n, int len) {
  for (long r = 1; r < n; r++)
    if (memcmp(t, t + r * len, sizeof(double) * (size_t)len)) return 0;
  return 1;
}

/* the physical gradients g<m><p>_<d>[i] of the nl basis functions of degree p (side m: ""
 * or "m"; tables and map suffixed M on the '-' side) at reference row `row` of table
 * G<M><p>: K^T times the reference gradients, unrolled for short bases */
static void emit_grads(strbuf *b, int dim, int nl, int p, const char *m, const char *M, const char *row, const char *ind) {
  sb_printf(b, "%sdouble ", ind);
  for (int d = 0; d < dim; d++) sb_printf(b, "%sg%s%d_%d[%d]", d ? ", " : "", m, p, d, nl);
  sb_printf(b, ";\n");
  if (nl <= KER_UNROLL) {
    sb_printf(b, "%sconst double *gr%s%d = G%s%d + %s*%d;\n", ind, m, p, M, p, row, nl * dim);
    for (int i = 0; i < nl; i++)
      for (int d = 0; d < dim; d++) {
        sb_printf(b, "%sg%s%d_%d[%d] = ", ind, m, p, d, i);
        for (int kk = 0; kk < dim; kk++) sb_printf(b, "%sgr%s%d[%d]*K%s%d%d", kk ? " + " : "", m, p, i * dim + kk, M, kk, d);
        sb_printf(b, ";\n");
      }
    return;
  }
  sb_printf(b, "%sfor (int i = 0; i < %d; ++i) {\n%s  const double *gr = G%s%d + (%s*%d + i)*%d;\n", ind, nl, ind, M, p, row, nl, dim);
  for (int d = 0; d < dim; d++) {
    sb_printf(b, "%s  g%s%d_%d[i] = ", ind, m, p, d);
    for (int kk = 0; kk < dim; kk++) sb_printf(b, "%sgr[%d]*K%s%d%d", kk ? " + " : "", kk, M, kk, d);
    sb_printf(b, ";\n");
  }
  sb_printf(b, "%s}\n", ind);
}

static int leaf_dir(const expr *e) {
  for (int d = 0; d < EXPR_MAXDIM; d++)
    if (e->alpha[d]) return d;
  return -1;
}

/* name of the basis array for field leaf e of degree p: values b<p> or gradient g<p>_<d> */
/* the basis values (b) or derivatives (g) of degree p at the point, on the '-' side of an
 * interior facet (bm, gm) for the restriction of a function to it */
static void basis_name(expr_ctx *c, const expr *e, int p, char *buf, size_t len) {
  int d = leaf_dir(e);
  expr_func_info *fi = expr_func_get(c, e->i0);
  const char *m = fi && fi->side ? "m" : "";
  if (d < 0) snprintf(buf, len, "b%s%d", m, p);
  else snprintf(buf, len, "g%s%d_%d", m, p, d);
}

static int func_side(expr_ctx *c, int f) {
  expr_func_info *fi = expr_func_get(c, f);
  return fi ? fi->side : 0;
}

/* a bilinear or trilinear map's J, det J and K = J^-1 at quadrature point `qi` (the shape
 * gradients from table `gt`, the vertices from `xn`), names suffixed by sf ('-' side: M) */
static void emit_point_map(strbuf *b, int dim, int nv, const char *xn, const char *gt, const char *qi, const char *sf) {
  sb_printf(b, "    const double *gq%s = %s + %s*%d;\n", sf, gt, qi, nv * dim);
  for (int i = 0; i < dim; i++)
    for (int kk = 0; kk < dim; kk++) {
      sb_printf(b, "    const double J%s%d%d = ", sf, i, kk);
      for (int j = 0; j < nv; j++) sb_printf(b, "%s%s[%d]*gq%s[%d]", j ? " + " : "", xn, j * dim + i, sf, j * dim + kk);
      sb_printf(b, ";\n");
    }
  if (dim == 2) {
    sb_printf(b, "    const double det%s = J%s00*J%s11 - J%s01*J%s10, idet%s = 1.0/det%s;\n", sf, sf, sf, sf, sf, sf, sf);
    sb_printf(b, "    const double K%s00 = J%s11*idet%s, K%s01 = -J%s01*idet%s, K%s10 = -J%s10*idet%s, K%s11 = J%s00*idet%s;\n", sf,
              sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf);
    return;
  }
  sb_printf(b, "    const double C%s00 = J%s11*J%s22 - J%s12*J%s21, C%s01 = J%s02*J%s21 - J%s01*J%s22, C%s02 = J%s01*J%s12 - J%s02*J%s11;\n",
            sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf);
  sb_printf(b, "    const double det%s = J%s00*C%s00 + J%s10*C%s01 + J%s20*C%s02, idet%s = 1.0/det%s;\n", sf, sf, sf, sf, sf, sf, sf, sf,
            sf);
  sb_printf(b, "    const double K%s00 = C%s00*idet%s, K%s01 = C%s01*idet%s, K%s02 = C%s02*idet%s;\n", sf, sf, sf, sf, sf, sf, sf, sf, sf);
  sb_printf(b, "    const double K%s10 = (J%s12*J%s20 - J%s10*J%s22)*idet%s, K%s11 = (J%s00*J%s22 - J%s02*J%s20)*idet%s, "
               "K%s12 = (J%s02*J%s10 - J%s00*J%s12)*idet%s;\n", sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf);
  sb_printf(b, "    const double K%s20 = (J%s10*J%s21 - J%s11*J%s20)*idet%s, K%s21 = (J%s01*J%s20 - J%s00*J%s21)*idet%s, "
               "K%s22 = (J%s00*J%s11 - J%s01*J%s10)*idet%s;\n", sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf);
}

/* an affine simplex's J, det J and K = J^-1 from the vertex coordinates xn, the names
 * suffixed by sfx (the '-' cell of an interior facet: JM00, detM, KM00) */
static void emit_affine_geometry(strbuf *b, int dim, const char *xn, const char *sf) {
  if (dim == 1) {
    sb_printf(b, "  const double J%s00 = %s[1] - %s[0], det%s = J%s00, idet%s = 1.0/det%s, K%s00 = idet%s;\n", sf, xn, xn, sf, sf, sf,
              sf, sf, sf);
  } else if (dim == 2) {
    sb_printf(b, "  const double J%s00 = %s[2] - %s[0], J%s01 = %s[4] - %s[0], J%s10 = %s[3] - %s[1], J%s11 = %s[5] - %s[1];\n", sf,
              xn, xn, sf, xn, xn, sf, xn, xn, sf, xn, xn);
    sb_printf(b, "  const double det%s = J%s00*J%s11 - J%s01*J%s10, idet%s = 1.0/det%s;\n", sf, sf, sf, sf, sf, sf, sf);
    sb_printf(b, "  const double K%s00 = J%s11*idet%s, K%s01 = -J%s01*idet%s, K%s10 = -J%s10*idet%s, K%s11 = J%s00*idet%s;\n", sf, sf,
              sf, sf, sf, sf, sf, sf, sf, sf, sf, sf);
  } else {
    for (int i = 0; i < 3; i++)
      sb_printf(b, "  const double J%s%d0 = %s[%d] - %s[%d], J%s%d1 = %s[%d] - %s[%d], J%s%d2 = %s[%d] - %s[%d];\n", sf, i, xn, 3 + i, xn,
                i, sf, i, xn, 6 + i, xn, i, sf, i, xn, 9 + i, xn, i);
    sb_printf(b, "  const double C%s00 = J%s11*J%s22 - J%s12*J%s21, C%s01 = J%s02*J%s21 - J%s01*J%s22, C%s02 = J%s01*J%s12 - J%s02*J%s11;\n",
              sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf);
    sb_printf(b, "  const double det%s = J%s00*C%s00 + J%s10*C%s01 + J%s20*C%s02, idet%s = 1.0/det%s;\n", sf, sf, sf, sf, sf, sf, sf,
              sf, sf);
    sb_printf(b, "  const double K%s00 = C%s00*idet%s, K%s01 = C%s01*idet%s, K%s02 = C%s02*idet%s;\n", sf, sf, sf, sf, sf, sf, sf, sf,
              sf);
    sb_printf(b, "  const double K%s10 = (J%s12*J%s20 - J%s10*J%s22)*idet%s, K%s11 = (J%s00*J%s22 - J%s02*J%s20)*idet%s, "
                 "K%s12 = (J%s02*J%s10 - J%s00*J%s12)*idet%s;\n", sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf);
    sb_printf(b, "  const double K%s20 = (J%s10*J%s21 - J%s11*J%s20)*idet%s, K%s21 = (J%s01*J%s20 - J%s00*J%s21)*idet%s, "
                 "K%s22 = (J%s00*J%s11 - J%s01*J%s10)*idet%s;\n", sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf, sf);
  }
}

/* the scalar blocks of a layout: one per (field, component), its local dofs off + i*stride */
#define KER_MAXV (KER_MAXFIELD * FEM_MAXBS)
typedef struct {
  int n;
  int func[KER_MAXV], comp[KER_MAXV], degree[KER_MAXV], nloc[KER_MAXV], off[KER_MAXV], stride[KER_MAXV];
  int size;
} vlayout;

static void vlayout_of(const field_layout *l, vlayout *v) {
  v->n = 0;
  v->size = l ? l->size : 0;
  for (int a = 0; l && a < l->n; a++) {
    int bs = l->bs[a] > 1 ? l->bs[a] : 1;
    for (int j = 0; j < bs && v->n < KER_MAXV; j++) {
      int i = v->n++;
      v->func[i] = l->func[a];
      v->comp[i] = j;
      v->degree[i] = l->degree[a];
      v->nloc[i] = l->nloc[a] / bs;
      v->off[i] = l->off[a] + j;
      v->stride[i] = bs;
    }
  }
}

/* the block of a field leaf (its function and component) */
static int layout_find(const vlayout *l, const expr *leaf) {
  for (int i = 0; i < l->n; i++)
    if (l->func[i] == leaf->i0 && l->comp[i] == leaf->i1) return i;
  return -1;
}

static int same_block(const vlayout *l, int a, const expr *leaf) { return l->func[a] == leaf->i0 && l->comp[a] == leaf->i1; }

/* does block (a, b) have any reference tensor */
static int block_used(unsigned char used[4][4]) {
  int any = 0;
  for (int k = 0; k < 4; k++)
    for (int l = 0; l < 4; l++) any |= used[k][l];
  return any;
}

/* a coefficient's derivative whose basis gradients are the same at every point: it is too,
 * and is computed once per item */
static int coef_hoisted(const lg_kernel *k, expr_ctx *c, const expr *e, int cgrad[2][4]) {
  return leaf_dir(e) >= 0 && cgrad[func_side(c, e->i0)][k->coef_degree[coef_index(k, e->i0)]];
}

/* a coefficient's value or derivative at the point: its element values times the basis
 * values or gradients */
static void emit_coef(strbuf *b, const lg_kernel *k, expr_ctx *c, leafctx *lc, const expr *e, const lagrange_element *el,
                      const char *ind) {
  int ci = coef_index(k, e->i0), p = k->coef_degree[ci], nl = el[p].nloc, nc = k->coef_ncomp[ci];
  int off = k->coef_off[ci] + (nc > 1 ? e->i1 : 0);
  char nm[32], bn[32];
  leafname(lc, e, nm, sizeof nm);
  basis_name(c, e, p, bn, sizeof bn);
  if (nl <= KER_UNROLL) {
    sb_printf(b, "%sconst double %s = ", ind, nm);
    for (int i = 0; i < nl; i++) sb_printf(b, "%sW[%d]*%s[%d]", i ? " + " : "", off + i * nc, bn, i);
    sb_printf(b, ";\n");
  } else if (nc == 1)
    sb_printf(b, "%sdouble %s = 0.0;\n%sfor (int i = 0; i < %d; ++i) %s += W[%d + i]*%s[i];\n", ind, nm, ind, nl, nm, off, bn);
  else
    sb_printf(b, "%sdouble %s = 0.0;\n%sfor (int i = 0; i < %d; ++i) %s += W[%d + i*%d]*%s[i];\n", ind, nm, ind, nl, nm, off, nc, bn);
}

/* kernel_source's state, shared by the emitters below, which write the kernel in order:
 * scan_leaves and plan_entries decide what it needs, the emit_* functions write its
 * tables, its signature and per-item geometry, the exact entries, and the quadrature loop.
 * Each returns 0, or 1 with the message in err */
typedef struct {
  expr_ctx *c;
  cell_type ct;
  int facet, qdeg;
  const kernel_spec *s;
  lg_kernel *k;
  char *err;
  size_t errlen;
  strbuf b;
  expr_tape tape;
  leafctx lc;
  /* interior facets (facet == 2): the item's code is f+ + nf*(f- + nf*perm), the '-' side's
   * points tabulated per (f-, perm), perm the rank of the facet vertex permutation between
   * the two cells (mesh_perm_of_rank); simplices, intervals and quadrilaterals (whose '-'
   * side gets its own bilinear map per point) */
  int dim, nf, interior, nvf, nperm, affine;
  vlayout vr, vc;
  int *vlev, nvec, maxlev; /* the tape's vector calls: their levels, count, deepest level */
  /* per side (0: the cell, or '+'; 1: the '-' cell of an interior facet) and degree */
  int need_val[2][4], need_grad[2][4], need_x, need_n;
  /* cgrad[side][p]: the physical gradients of degree p are the same at every point (an
   * affine cell and reference gradients equal at every point): computed once per item */
  int cgrad[2][4];
  lagrange_element el[4];
  unsigned char *isconst; /* Jacobian entries integrated exactly (nent of them; nvar others) */
  int nent, nvar;
  quad_rule q;
  double *qx;
  unsigned char rused[KER_MAXV][KER_MAXV][4][4]; /* reference tensors used by block pair */
  unsigned char *sel, *pcls, *live;
  int *pslot, xlive[3];
} kgen;

#define KERR(...) do { snprintf(g->err, g->errlen, __VA_ARGS__); return 1; } while (0)

/* the tape of the coefficient expressions and its vector calls (transcendental calls of the
 * coordinates, evaluated for all points of an item at once by the vector math routine,
 * vmath.c, that the JIT hands the kernel as lugal_vmath), and what its leaves need:
 * coefficient functions (their sorted W layout), coordinates, normals; the elements of
 * every degree the cell type has */
static int scan_leaves(kgen *g) {
  expr_tape *tape = &g->tape;
  expr_ctx *c = g->c;
  const cell_type ct = g->ct;
  const int facet = g->facet;
  const kernel_spec *s = g->s;
  lg_kernel *k = g->k;
  const int dim = g->dim;
  const int interior = g->interior;
  int (*need_val)[4] = g->need_val;
  int (*need_grad)[4] = g->need_grad;
  lagrange_element *el = g->el;
  /* the coefficient expressions */
  int nroot = s->arity == 2 ? s->tab->njac : s->arity == 1 ? s->tab->nres : 1;
  expr **roots = malloc(sizeof(expr *) * (size_t)(nroot + 1));
  if (!roots) KERR("out of memory");
  for (int i = 0; i < nroot; i++)
    roots[i] = s->arity == 2 ? s->tab->jac[i] : s->arity == 1 ? s->tab->res[i] : s->integrand;
  if (expr_tape_build(c, nroot, roots, tape)) { free(roots); KERR("%s", expr_error(c)); }
  free(roots);
  /* transcendental calls of the coordinates: evaluated for all points of an item at once by
   * the vector math routine (vmath.c) the JIT hands the kernel as lugal_vmath */
  int *vlev = g->vlev = calloc((size_t)tape->n + 1, sizeof(int));
  if (!vlev) KERR("out of memory");
  if (!s->scalar_math && (g->nvec = expr_tape_vector_calls(tape, vlev)) < 0) KERR("out of memory");
  for (int i = 0; i < tape->n; i++)
    if (vlev[i] > g->maxlev) g->maxlev = vlev[i];

  /* leaves: coefficient functions, coordinates, normals */
  /* per side (0: the cell, or '+'; 1: the '-' cell of an interior facet) and degree */
  /* cgrad[side][p]: the physical gradients of degree p are the same at every point (an
   * affine cell and reference gradients equal at every point): computed once per item */
  for (int i = 0; i < tape->n; i++) {
    const expr *e = tape->node[i];
    if (e->kind == E_COORD) {
      if (e->i0 >= dim) KERR("the integrand uses the coordinate %c, but the mesh is %dD", "xyz"[e->i0], dim);
      g->need_x = 1;
    } else if (e->kind == E_NORMAL) {
      if (!facet) KERR("the normal vector can only be used in boundary and interior facet integrals");
      if (e->i0 >= dim) KERR("the integrand uses normal component %d on a %dD mesh", e->i0 + 1, dim);
      g->need_n = 1;
    } else if (e->kind == E_FIELD) {
      expr_func_info *fi = expr_func_get(c, e->i0);
      if (!fi) KERR("unknown function in an integrand");
      if (fi->kind == FK_TEST) KERR("the integrand contains the test function %s: integrate it inside a form (lg.integral) and solve a problem instead", fi->name);
      if (e->order > 1) KERR("second and higher derivatives of %s are not supported yet", fi->name);
      int d = leaf_dir(e);
      if (d >= dim) KERR("the integrand differentiates %s in %c, but the mesh is %dD", fi->name, "xyz"[d], dim);
      int ci = coef_index(k, e->i0);
      if (ci < 0) {
        if (k->ncoef == KER_MAXCOEF)
          KERR("an integrand reads more than %d discrete functions (coefficients, controls), the most a kernel takes: split "
               "the integral into several (docs/lua-api.md, \"Limits\")", KER_MAXCOEF);
        ci = k->ncoef++;
        k->coef_func[ci] = e->i0;
        k->coef_degree[ci] = fi->degree;
        k->coef_ncomp[ci] = fi->ncomp > 1 ? fi->ncomp : 1;
      }
      if (e->i1 >= k->coef_ncomp[ci]) KERR("component %d of %s, which has %d", e->i1 + 1, fi->name, k->coef_ncomp[ci]);
      if (fi->degree < 0 || fi->degree > 3) KERR("coefficient %s has unsupported degree %d", fi->name, fi->degree);
      if (fi->side && !interior) KERR("%s is restricted to the '-' side of a facet (lg.jump, lg.avg, lg.minus): that needs an integral over mesh:interior_facets()", fi->name);
      if (d < 0) need_val[fi->side][fi->degree] = 1;
      else need_grad[fi->side][fi->degree] = 1;
    }
  }
  /* sort coefficients by function id for a canonical W layout */
  for (int i = 1; i < k->ncoef; i++)
    for (int j = i; j > 0 && k->coef_func[j - 1] > k->coef_func[j]; j--) {
      int t = k->coef_func[j]; k->coef_func[j] = k->coef_func[j - 1]; k->coef_func[j - 1] = t;
      t = k->coef_degree[j]; k->coef_degree[j] = k->coef_degree[j - 1]; k->coef_degree[j - 1] = t;
      t = k->coef_ncomp[j]; k->coef_ncomp[j] = k->coef_ncomp[j - 1]; k->coef_ncomp[j - 1] = t;
    }
  /* the elements of every degree the cell type has (P0-P3 on simplices, Q0-Q2 on boxes);
   * the others stay zero: no function of their degree can live on this cell */
  const int maxp = g->affine ? 3 : 2;
  for (int p = 0; p <= maxp; p++)
    if (lagrange_init(&el[p], ct, p, g->err)) return 1;
  for (int i = 0; i < k->ncoef; i++)
    if (k->coef_degree[i] > maxp) KERR("a function of degree %d on %s (at most %d)", k->coef_degree[i], cell_plural(ct), maxp);
  for (int i = 0; i < k->ncoef; i++) k->coef_side[i] = func_side(c, k->coef_func[i]);
  k->wsize = 0;
  for (int i = 0; i < k->ncoef; i++) {
    k->coef_off[i] = k->wsize;
    k->wsize += el[k->coef_degree[i]].nloc * k->coef_ncomp[i];
  }
  return 0;
}

/* which Jacobian entries are integrated exactly on the reference cell (a constant
 * coefficient on an affine cell: FFC's tensor representation), and the test and trial
 * bases the others need */
static int plan_entries(kgen *g) {
  expr_ctx *c = g->c;
  const int facet = g->facet;
  const int qdeg = g->qdeg;
  const kernel_spec *s = g->s;
  const int dim = g->dim;
  const int interior = g->interior;
  const int affine = g->affine;
  int (*need_val)[4] = g->need_val;
  int (*need_grad)[4] = g->need_grad;
  const vlayout *vrp = &g->vr;
  const vlayout *vcp = &g->vc;
  /* Jacobian entries whose coefficient is constant on the cell (no coordinate, field or
   * normal in it) are integrated exactly on the reference cell ahead of time: on an
   * affine cell their element matrix is a contraction of reference tensors with
   * geometry factors, as in FFC's tensor representation; only the others need the
   * quadrature loop */
  const int nent = g->nent = s->arity == 2 ? s->tab->njac : 0;
  unsigned char *isconst = g->isconst = calloc((size_t)nent + 1, 1);
  if (!isconst) KERR("out of memory");
  /* with a one-point rule (P1 stiffness) the quadrature loop is the cheaper of the two */
  int nq_est = 1;
  for (int d = 0; d < dim; d++) nq_est *= (qdeg + 2) / 2;
  for (int i = 0; i < nent; i++) {
    isconst[i] = affine && !facet && nq_est > 1 && !(s->tab->jac[i]->dep & DEP_POINT);
    g->nvar += !isconst[i];
  }
  /* test and trial basis needs */
  if (s->arity >= 1) {
    int n = s->arity == 2 ? s->tab->njac : s->tab->nres;
    for (int i = 0; i < n; i++) {
      if (s->arity == 2 && isconst[i]) continue;
      const expr *tl = s->arity == 2 ? s->tab->jac_test[i] : s->tab->res_leaf[i];
      int fi = layout_find(vrp, tl);
      if (fi < 0) KERR("internal error: test function not in the row layout");
      if (tl->order > 1) KERR("second derivatives of test functions are not supported yet");
      if (leaf_dir(tl) >= dim) KERR("the form differentiates a test function in %c on a %dD mesh", "xyz"[leaf_dir(tl)], dim);
      int ts = func_side(c, vrp->func[fi]);
      if (ts && !interior) KERR("a test function is restricted to the '-' side of a facet: that needs an integral over mesh:interior_facets()");
      if (tl->order) need_grad[ts][vrp->degree[fi]] = 1; else need_val[ts][vrp->degree[fi]] = 1;
      if (s->arity == 2) {
        const expr *ul = s->tab->jac_trial[i];
        int fj = layout_find(vcp, ul);
        if (fj < 0) KERR("internal error: unknown not in the column layout");
        if (ul->order > 1) KERR("second derivatives of unknowns are not supported yet");
        if (leaf_dir(ul) >= dim) KERR("the form differentiates an unknown in %c on a %dD mesh", "xyz"[leaf_dir(ul)], dim);
        int us = func_side(c, vcp->func[fj]);
        if (us && !interior) KERR("an unknown is restricted to the '-' side of a facet: that needs an integral over mesh:interior_facets()");
        if (ul->order) need_grad[us][vcp->degree[fj]] = 1; else need_val[us][vcp->degree[fj]] = 1;
      }
    }
  }
  return 0;
}

/* the header, the quadrature rule's weights and points (per facet for facet kernels), and
 * on quadrilaterals and hexahedra the bilinear / trilinear map's tables; g->qx holds the
 * reference points for emit_bases */
static int emit_quadrature(kgen *g) {
  strbuf *b = &g->b;
  const cell_type ct = g->ct;
  const int facet = g->facet;
  const int qdeg = g->qdeg;
  const kernel_spec *s = g->s;
  lg_kernel *k = g->k;
  const int dim = g->dim;
  const int nf = g->nf;
  const int affine = g->affine;
  const int nvec = g->nvec;
  const int need_x = g->need_x;
  /* quadrature */
  if (quad_cell(ct, facet != 0, qdeg, &g->q)) KERR("no quadrature rule of degree %d on %s", qdeg, cell_plural(ct));
  k->nq = g->q.n;

  sb_printf(b, "/* generated by lugal: %s %s kernel, arity %d, quadrature degree %d, %d points */\n",
            cell_name(ct), facet ? "facet" : "cell", s->arity, g->q.degree, g->q.n);
  sb_printf(b, "double sin(double); double cos(double); double tan(double); double exp(double);\n"
                "double log(double); double sqrt(double); double fabs(double); double tanh(double);\n"
                "double sinh(double); double cosh(double); double atan(double); double asin(double);\n"
                "double acos(double); double pow(double, double);\n");
  if (nvec) sb_printf(b, "void (*lugal_vmath)(int, double *, int);\n");
  /* weights and reference points (per facet for facet kernels) */
  double *qx = g->qx = malloc(sizeof(double) * (size_t)nf * (size_t)g->q.n * 3);
  if (!qx) KERR("out of memory");
  for (int f = 0; f < nf; f++)
    for (int i = 0; i < g->q.n; i++) {
      double xi[3] = {0, 0, 0};
      if (facet) ref_facet_point(ct, f, g->q.x + g->q.dim * i, xi);
      else memcpy(xi, g->q.x + dim * i, sizeof(double) * (size_t)dim);
      memcpy(qx + ((size_t)f * g->q.n + i) * dim, xi, sizeof(double) * (size_t)dim);
    }
  double wsum = 0;
  for (int i = 0; i < g->q.n; i++) wsum += g->q.w[i];
  double *qw = malloc(sizeof(double) * (size_t)g->q.n);
  if (!qw) KERR("out of memory");
  for (int i = 0; i < g->q.n; i++) qw[i] = facet ? g->q.w[i] / wsum : g->q.w[i];
  emit_table(b, "QW", qw, g->q.n);
  free(qw);
  if (need_x && affine) emit_table(b, "QX", qx, (long)nf * g->q.n * dim);
  if (!affine) {
    /* the bilinear / trilinear map at every point: vertex shape values (for x) and
     * reference gradients (for J); the facets' reference tangents (for their measure) */
    int nv = cell_nverts(ct);
    double *gn = malloc(sizeof(double) * (size_t)nf * g->q.n * nv * (dim + 1));
    if (!gn) KERR("out of memory");
    double *gv = gn + (size_t)nf * g->q.n * nv * dim;
    for (size_t i = 0; i < (size_t)nf * g->q.n; i++) q1_shape(ct, qx + i * dim, gv + i * nv, gn + i * nv * dim);
    emit_table(b, "GQ", gn, (long)nf * g->q.n * nv * dim);
    if (need_x) emit_table(b, "NQ", gv, (long)nf * g->q.n * nv);
    free(gn);
    if (facet) {
      double ft[6 * 6];
      for (int f = 0; f < cell_nfacets(ct); f++) ref_facet_tangents(ct, f, ft + 6 * f, ft + 6 * f + 3);
      emit_table(b, "FT", ft, 6L * cell_nfacets(ct));
    }
  }
  return 0;
}

/* the basis tables of both sides (the '-' side of an interior facet at the points of the
 * '+' side, per facet and vertex permutation) and the reference normals */
static int emit_bases(kgen *g) {
  const double *qx = g->qx;
  strbuf *b = &g->b;
  const cell_type ct = g->ct;
  const int dim = g->dim;
  const int nf = g->nf;
  const int interior = g->interior;
  const int nvf = g->nvf;
  const int nperm = g->nperm;
  const int affine = g->affine;
  const int need_n = g->need_n;
  int (*need_val)[4] = g->need_val;
  int (*need_grad)[4] = g->need_grad;
  int (*cgrad)[4] = g->cgrad;
  lagrange_element *el = g->el;
  /* basis tables */
  for (int p = 0; p <= 3; p++) {
    if (!need_val[0][p] && !need_grad[0][p]) continue;
    int nl = el[p].nloc;
    double *bv = malloc(sizeof(double) * (size_t)nf * g->q.n * nl);
    double *bg = malloc(sizeof(double) * (size_t)nf * g->q.n * nl * dim);
    if (!bv || !bg) { free(bv); free(bg); KERR("out of memory"); }
    for (int f = 0; f < nf; f++)
      for (int i = 0; i < g->q.n; i++) {
        size_t qq = (size_t)f * g->q.n + i;
        lagrange_eval(&el[p], qx + qq * dim, bv + qq * nl, bg + qq * nl * dim);
      }
    char nm[16];
    if (need_val[0][p]) { snprintf(nm, sizeof nm, "B%d", p); emit_table(b, nm, bv, (long)nf * g->q.n * nl); }
    if (need_grad[0][p]) { snprintf(nm, sizeof nm, "G%d", p); emit_table(b, nm, bg, (long)nf * g->q.n * nl * dim); }
    cgrad[0][p] = need_grad[0][p] && affine && rows_equal(bg, (long)nf * g->q.n, nl * dim);
    free(bv);
    free(bg);
  }
  free(g->qx);
  g->qx = NULL;
  if (interior) {
    /* the '-' side: facet point i of the '+' side is sum_k lambda_k(s_i) times facet vertex k,
     * which is facet vertex perm[k] of the '-' cell's facet f-: its reference point there */
    size_t nm_pts = (size_t)nf * (size_t)nperm * (size_t)g->q.n;
    double *qm = malloc(sizeof(double) * nm_pts * 3 + 1);
    if (!qm) KERR("out of memory");
    for (int fm = 0; fm < nf; fm++)
      for (int pr = 0; pr < nperm; pr++) {
        int perm[4];
        mesh_perm_of_rank(nvf, pr, perm);
        const int *fv = cell_facet_verts(ct, fm);
        for (int i = 0; i < g->q.n; i++) {
          const double *sp = g->q.x + g->q.dim * i;
          double lam[3] = {1, 0, 0};
          if (dim == 2) { lam[0] = 1 - sp[0]; lam[1] = sp[0]; }
          if (dim == 3) { lam[0] = 1 - sp[0] - sp[1]; lam[1] = sp[0]; lam[2] = sp[1]; }
          double *xi = qm + (((size_t)pr * nf + fm) * g->q.n + i) * dim; /* fmq = f- + nf*perm */
          for (int d = 0; d < dim; d++) xi[d] = 0;
          for (int kk = 0; kk < nvf; kk++) {
            const double *rv = ref_vertex(ct, fv[perm[kk]]);
            for (int d = 0; d < dim; d++) xi[d] += lam[kk] * rv[d];
          }
        }
      }
    if (!affine) {
      /* the '-' cell's bilinear map at those points: its J varies from point to point */
      int nv = cell_nverts(ct);
      double *gm = malloc(sizeof(double) * nm_pts * nv * dim + 1);
      if (!gm) { free(qm); KERR("out of memory"); }
      for (size_t i = 0; i < nm_pts; i++) q1_shape(ct, qm + i * dim, NULL, gm + i * nv * dim);
      emit_table(b, "GQM", gm, (long)(nm_pts * nv * dim));
      free(gm);
    }
    for (int p = 0; p <= 3; p++) {
      if (!need_val[1][p] && !need_grad[1][p]) continue;
      int nl = el[p].nloc;
      double *bv = malloc(sizeof(double) * nm_pts * nl + 1), *bg = malloc(sizeof(double) * nm_pts * nl * dim + 1);
      if (!bv || !bg) { free(bv); free(bg); free(qm); KERR("out of memory"); }
      for (size_t i = 0; i < nm_pts; i++) lagrange_eval(&el[p], qm + i * dim, bv + i * nl, bg + i * nl * dim);
      char nm[16];
      if (need_val[1][p]) { snprintf(nm, sizeof nm, "BM%d", p); emit_table(b, nm, bv, (long)(nm_pts * nl)); }
      if (need_grad[1][p]) { snprintf(nm, sizeof nm, "GM%d", p); emit_table(b, nm, bg, (long)(nm_pts * nl * dim)); }
      cgrad[1][p] = need_grad[1][p] && affine && rows_equal(bg, (long)nm_pts, nl * dim);
      free(bv);
      free(bg);
    }
    free(qm);
  }
  if (need_n) {
    double nr[18];
    for (int f = 0; f < cell_nfacets(ct); f++) ref_facet_normal(ct, f, nr + f * dim);
    emit_table(b, "NR", nr, (long)cell_nfacets(ct) * dim);
  }
  return 0;
}

/* the reference tensors of the entries integrated exactly (plan_entries) */
static int emit_reference_tensors(kgen *g) {
  strbuf *b = &g->b;
  const kernel_spec *s = g->s;
  const int dim = g->dim;
  const int nent = g->nent;
  unsigned char *isconst = g->isconst;
  unsigned char (*rused)[KER_MAXV][4][4] = g->rused;
  lagrange_element *el = g->el;
  const vlayout *vrp = &g->vr;
  const vlayout *vcp = &g->vc;
  /* reference tensors R<pa><pb>_<k><l>[i][j] = ∫ D_k phi_i D_l psi_j on the reference cell
   * for degrees pa, pb (shared by every block pair of those degrees), k, l = 0 for values and
   * 1..dim for derivatives, exact (degree pa + pb) */
  unsigned char dused[4][4][4][4];
  memset(dused, 0, sizeof dused);
  for (int i = 0; i < nent; i++) {
    if (!isconst[i]) continue;
    int a = layout_find(vrp, s->tab->jac_test[i]), bb = layout_find(vcp, s->tab->jac_trial[i]);
    int da = leaf_dir(s->tab->jac_test[i]), db = leaf_dir(s->tab->jac_trial[i]);
    for (int kk = (da < 0 ? -1 : 0); kk < (da < 0 ? 0 : dim); kk++)
      for (int ll = (db < 0 ? -1 : 0); ll < (db < 0 ? 0 : dim); ll++) {
        rused[a][bb][kk + 1][ll + 1] = 1;
        dused[vrp->degree[a]][vcp->degree[bb]][kk + 1][ll + 1] = 1;
      }
  }
  for (int pa = 0; pa <= 3; pa++)
    for (int pb = 0; pb <= 3; pb++) {
      if (!block_used(dused[pa][pb])) continue;
      const lagrange_element *ea = &el[pa], *eb = &el[pb];
      quad_rule rq;
      if (quad_simplex(dim, ea->degree + eb->degree, &rq)) KERR("no reference rule");
      int na = ea->nloc, nb = eb->nloc;
      double *R = calloc((size_t)16 * na * nb, sizeof(double));
      if (!R) KERR("out of memory");
      for (int qi = 0; qi < rq.n; qi++) {
        double va[FEM_MAXLOC], ga[FEM_MAXLOC * 3], vb[FEM_MAXLOC], gb[FEM_MAXLOC * 3];
        lagrange_eval(ea, rq.x + dim * qi, va, ga);
        lagrange_eval(eb, rq.x + dim * qi, vb, gb);
        for (int kk = 0; kk <= dim; kk++)
          for (int ll = 0; ll <= dim; ll++) {
            if (!dused[pa][pb][kk][ll]) continue;
            double *r = R + (size_t)(kk * 4 + ll) * na * nb;
            for (int i = 0; i < na; i++) {
              double fi = kk ? ga[i * dim + kk - 1] : va[i];
              for (int j = 0; j < nb; j++) r[i * nb + j] += rq.w[qi] * fi * (ll ? gb[j * dim + ll - 1] : vb[j]);
            }
          }
      }
      for (int kk = 0; kk <= dim; kk++)
        for (int ll = 0; ll <= dim; ll++) {
          if (!dused[pa][pb][kk][ll]) continue;
          char nm[32];
          snprintf(nm, sizeof nm, "R%d%d_%d%d", pa, pb, kk, ll);
          emit_table(b, nm, R + (size_t)(kk * 4 + ll) * na * nb, (long)na * nb);
        }
      free(R);
    }
  return 0;
}

/* the kernel's signature and the geometry computed once per item: an affine simplex's
 * Jacobian, its measure or its facet's, and the facet normal */
static int emit_signature(kgen *g) {
  strbuf *b = &g->b;
  const cell_type ct = g->ct;
  const int facet = g->facet;
  const int dim = g->dim;
  const int nf = g->nf;
  const int interior = g->interior;
  const int affine = g->affine;
  const int need_n = g->need_n;
  sb_printf(b, "void lugal_kernel(const double *restrict X, const double *restrict W, "
                "const double *restrict P, int %s, double *restrict A, double *restrict C, int cm)\n{\n",
            interior ? "fcode" : "facet");
  if (interior)
    sb_printf(b, "  const int facet = fcode %% %d, fmq = fcode / %d;\n  const double *XM = X + %d;\n", nf, nf,
              cell_nverts(ct) * dim);
  sb_printf(b, "  (void)W; (void)P; (void)facet; (void)C; (void)cm;\n");
  /* geometry: once for an affine simplex; a quadrilateral's or hexahedron's varies from
   * point to point and is computed in the quadrature loop */
  if (affine) emit_affine_geometry(b, dim, "X", "");
  if (interior && affine) emit_affine_geometry(b, dim, "XM", "M");
  if (!affine) {
  } else if (!facet) {
    sb_printf(b, "  const double scale = det < 0.0 ? -det : det;\n");
  } else {
    /* facet measure from the facet's vertices */
    int nvf = dim;
    sb_printf(b, "  static const int FV[%d][%d] = {", cell_nfacets(ct), nvf);
    for (int f = 0; f < cell_nfacets(ct); f++) {
      const int *fv = cell_facet_verts(ct, f);
      sb_printf(b, "%s{", f ? ", " : "");
      for (int i = 0; i < nvf; i++) sb_printf(b, "%s%d", i ? ", " : "", fv[i]);
      sb_printf(b, "}");
    }
    sb_printf(b, "};\n");
    if (dim == 1) {
      sb_printf(b, "  const double scale = 1.0; (void)FV;\n"); /* a point */
    } else if (dim == 2) {
      sb_printf(b, "  const double *fa = X + 2*FV[facet][0], *fb = X + 2*FV[facet][1];\n"
                    "  const double scale = sqrt((fb[0]-fa[0])*(fb[0]-fa[0]) + (fb[1]-fa[1])*(fb[1]-fa[1]));\n");
    } else {
      sb_printf(b, "  const double *fa = X + 3*FV[facet][0], *fb = X + 3*FV[facet][1], *fc = X + 3*FV[facet][2];\n"
                    "  const double e0 = fb[0]-fa[0], e1 = fb[1]-fa[1], e2 = fb[2]-fa[2];\n"
                    "  const double h0 = fc[0]-fa[0], h1 = fc[1]-fa[1], h2 = fc[2]-fa[2];\n"
                    "  const double c0 = e1*h2 - e2*h1, c1 = e2*h0 - e0*h2, c2 = e0*h1 - e1*h0;\n"
                    "  const double scale = 0.5*sqrt(c0*c0 + c1*c1 + c2*c2);\n");
    }
    if (need_n) {
      /* n = K^T n_ref normalized; the sign of det keeps it outward for inverted maps */
      for (int d = 0; d < dim; d++) {
        sb_printf(b, "  double m%d = ", d);
        for (int kk = 0; kk < dim; kk++) sb_printf(b, "%sK%d%d*NR[facet*%d+%d]", kk ? " + " : "", kk, d, dim, kk);
        sb_printf(b, ";\n");
      }
      sb_printf(b, "  const double mn = 1.0/sqrt(m0*m0%s%s);\n", dim >= 2 ? " + m1*m1" : "", dim == 3 ? " + m2*m2" : "");
      for (int d = 0; d < dim; d++) sb_printf(b, "  const double n%d = m%d*mn;\n", d, d);
    }
  }
  return 0;
}

/* the parameter-only subexpressions, computed once per item, and the point cache's
 * classes and signature */
static int emit_hoisted(kgen *g) {
  strbuf *b = &g->b;
  expr_tape *tape = &g->tape;
  const cell_type ct = g->ct;
  const int facet = g->facet;
  const int qdeg = g->qdeg;
  lg_kernel *k = g->k;
  /* hoisted parameter-only subexpressions */
  unsigned char *sel = g->sel = malloc((size_t)tape->n + 1);
  if (!sel) KERR("out of memory");
  for (int i = 0; i < tape->n; i++) sel[i] = !(tape->node[i]->dep & DEP_POINT);
  expr_codegen(b, tape, "t", "P", sel, leafname, &g->lc, "  ");
  unsigned char *pcls = g->pcls = malloc((size_t)tape->n + 1);
  int *pslot = g->pslot = malloc(sizeof(int) * ((size_t)tape->n + 1));
  if (!pcls || !pslot) KERR("out of memory");
  k->ncache = expr_tape_point_cache(tape, pcls, pslot);
  if (k->ncache < 0) KERR("out of memory");
  /* what the cache holds: kernels with the same signature share their values (kernel.h) */
  k->csig = 0x84222325cbf29ce4ull ^ ((uint64_t)ct << 40) ^ ((uint64_t)facet << 32) ^ ((uint64_t)qdeg << 16) ^ (uint64_t)k->nq;
  for (int i = 0; i < tape->n; i++)
    if (pcls[i] == PC_CACHED) {
      k->csig = (k->csig ^ (tape->node[i]->hash + (uint64_t)pslot[i])) * 0x9E3779B97F4A7C15ull;
      k->csig ^= k->csig >> 31;
    }
  return 0;
}

/* the exactly integrated entries: geometry factors contracted with the reference tensors.
 * 2 when they are all (nothing is left for the quadrature loop) */
static int emit_exact(kgen *g) {
  strbuf *b = &g->b;
  expr_tape *tape = &g->tape;
  const kernel_spec *s = g->s;
  lg_kernel *k = g->k;
  const int dim = g->dim;
  const int nent = g->nent;
  const int nvar = g->nvar;
  unsigned char *isconst = g->isconst;
  unsigned char (*rused)[KER_MAXV][4][4] = g->rused;
  const vlayout *vrp = &g->vr;
  const vlayout *vcp = &g->vc;
  char ref[128];
  for (int a = 0; a < vrp->n; a++)
    for (int bb = 0; bb < vcp->n; bb++) {
      if (!block_used(rused[a][bb])) continue;
      for (int kk = 0; kk <= dim; kk++)
        for (int ll = 0; ll <= dim; ll++)
          if (rused[a][bb][kk][ll]) sb_printf(b, "  double G%d_%d_%d%d = 0.0;\n", a, bb, kk, ll);
      for (int i = 0; i < nent; i++) {
        if (!isconst[i] || !same_block(vrp, a, s->tab->jac_test[i]) || !same_block(vcp, bb, s->tab->jac_trial[i])) continue;
        int da = leaf_dir(s->tab->jac_test[i]), db = leaf_dir(s->tab->jac_trial[i]);
        expr_codegen_ref(tape, tape->root[i], "t", leafname, &g->lc, ref, sizeof ref);
        /* physical derivative d/dx_da = sum_k K[k][da] d/dxi_k */
        for (int kk = (da < 0 ? -1 : 0); kk < (da < 0 ? 0 : dim); kk++)
          for (int ll = (db < 0 ? -1 : 0); ll < (db < 0 ? 0 : dim); ll++) {
            sb_printf(b, "  G%d_%d_%d%d += %s", a, bb, kk + 1, ll + 1, ref);
            if (da >= 0) sb_printf(b, "*K%d%d", kk, da);
            if (db >= 0) sb_printf(b, "*K%d%d", ll, db);
            sb_printf(b, ";\n");
          }
      }
      int na = vrp->nloc[a], nb = vcp->nloc[bb];
      sb_printf(b, "  for (int i = 0; i < %d; ++i) {\n    double *Ai = A + (%d + i*%d)*%d + %d;\n", na, vrp->off[a], vrp->stride[a],
                vcp->size, vcp->off[bb]);
      int unroll = nb <= KER_UNROLL;
      for (int jj = 0; jj < (unroll ? nb : 1); jj++) {
        char jx[16] = "j";
        if (unroll) {
          snprintf(jx, sizeof jx, "%d", jj);
          sb_printf(b, "    Ai[%d] += scale*(", jj * vcp->stride[bb]);
        } else sb_printf(b, "    for (int j = 0; j < %d; ++j) Ai[j*%d] += scale*(", nb, vcp->stride[bb]);
        int first = 1;
        for (int kk = 0; kk <= dim; kk++)
          for (int ll = 0; ll <= dim; ll++) {
            if (!rused[a][bb][kk][ll]) continue;
            sb_printf(b, "%sG%d_%d_%d%d*R%d%d_%d%d[i*%d + %s]", first ? "" : " + ", a, bb, kk, ll, vrp->degree[a], vcp->degree[bb], kk,
                      ll, nb, jx);
            first = 0;
          }
        sb_printf(b, ");\n");
      }
      sb_printf(b, "  }\n");
    }
  if (s->arity == 2 && nvar == 0) {
    /* everything was exact on the reference cell */
    k->ncache = 0;
    sb_printf(b, "  (void)K00; (void)scale;\n}\n");
    return 2;
  }
  return 0;
}

/* what the quadrature loop needs (the live nodes), and what is computed once per item
 * before it: constant gradients, hoisted coefficients, the vector calls */
static int emit_item(kgen *g) {
  strbuf *b = &g->b;
  expr_tape *tape = &g->tape;
  expr_ctx *c = g->c;
  const cell_type ct = g->ct;
  const int facet = g->facet;
  const kernel_spec *s = g->s;
  lg_kernel *k = g->k;
  const int dim = g->dim;
  const int affine = g->affine;
  const int nvec = g->nvec;
  const int maxlev = g->maxlev;
  int *vlev = g->vlev;
  unsigned char *isconst = g->isconst;
  unsigned char *pcls = g->pcls;
  int (*cgrad)[4] = g->cgrad;
  int *xlive = g->xlive;
  lagrange_element *el = g->el;
  char ref[128];
  /* what the quadrature loop needs: the contraction's integrands and the cached values, and
   * what they are computed from there (libtcc does not drop dead code) */
  unsigned char *live = g->live = calloc((size_t)tape->n + 1, 1);
  unsigned char *need = calloc((size_t)tape->n + 1, 1);
  if (!live || !need) { free(need); KERR("out of memory"); }
  for (int i = 0; i < tape->nroot; i++) need[tape->root[i]] = s->arity < 2 || !isconst[i];
  for (int i = 0; i < tape->n; i++) need[i] |= k->ncache > 0 && pcls[i] == PC_CACHED;
  int lrc = expr_tape_live(tape, need, vlev, live);
  free(need);
  if (lrc) KERR("out of memory");
  for (int i = 0; i < tape->n; i++)
    if (live[i] && tape->node[i]->kind == E_COORD) xlive[tape->node[i]->i0] = 1;
  /* constant gradients: the bases' and the coefficients' derivatives, once per item */
  for (int sd = 0; sd < 2; sd++)
    for (int p = 0; p <= 3; p++)
      if (cgrad[sd][p]) emit_grads(b, dim, el[p].nloc, p, sd ? "m" : "", sd ? "M" : "", "0", "  ");
  for (int i = 0; i < tape->n; i++)
    if (live[i] && tape->node[i]->kind == E_FIELD && coef_hoisted(k, c, tape->node[i], cgrad))
      emit_coef(b, k, c, &g->lc, tape->node[i], el, "  ");
  if (nvec) {
    /* the vector calls: their arguments at every point, then one call per node. Those that
     * only the point cache's values need (its cached and inner nodes) are skipped when the
     * cache is read; the others come first, level by level (a call inside another's
     * argument has the lower level) */
    for (int i = 0; i < tape->n; i++)
      if (vlev[i]) sb_printf(b, "  double V%d[%d];\n", i, g->q.n);
    unsigned char *mk = malloc((size_t)tape->n + 1), *rt = malloc((size_t)tape->n + 1);
    if (!mk || !rt) { free(mk); free(rt); KERR("out of memory"); }
    for (int grp = 0; grp < 2; grp++) {
      int any = 0;
      for (int i = 0; i < tape->n; i++)
        any |= vlev[i] && (grp == (k->ncache > 0 && (pcls[i] == PC_CACHED || pcls[i] == PC_INNER)));
      if (!any) continue;
      if (grp) sb_printf(b, "  if (cm != 2) {\n");
      for (int L = 1; L <= maxlev; L++) {
        memset(mk, 0, (size_t)tape->n);
        int n = 0;
        for (int i = 0; i < tape->n; i++) {
          rt[i] = vlev[i] == L && grp == (k->ncache > 0 && (pcls[i] == PC_CACHED || pcls[i] == PC_INNER));
          n += rt[i];
        }
        if (!n) continue;
        if (expr_tape_vector_closure(tape, rt, vlev, mk)) { free(mk); free(rt); KERR("out of memory"); }
        sb_printf(b, "  for (int q = 0; q < %d; ++q) {\n", g->q.n);
        sb_printf(b, facet ? "    const int qq = facet*%d + q;\n" : "    const int qq = q; (void)qq;\n", g->q.n);
        for (int d = 0; d < dim; d++) {
          sb_printf(b, "    const double x%d = ", d);
          if (affine) {
            sb_printf(b, "X[%d]", d);
            for (int kk = 0; kk < dim; kk++) sb_printf(b, " + J%d%d*QX[qq*%d+%d]", d, kk, dim, kk);
          } else {
            int nv = cell_nverts(ct);
            for (int j = 0; j < nv; j++) sb_printf(b, "%sNQ[qq*%d + %d]*X[%d]", j ? " + " : "", nv, j, j * dim + d);
          }
          sb_printf(b, ";\n");
        }
        expr_codegen(b, tape, "t", "P", mk, leafname, &g->lc, "    ");
        for (int i = 0; i < tape->n; i++) {
          if (!rt[i]) continue;
          /* the argument: a node of the tape before the call (or a leaf) */
          int a0 = i - 1;
          while (a0 >= 0 && tape->node[a0] != tape->node[i]->ch[0]) a0--;
          if (a0 < 0) { free(mk); free(rt); KERR("internal error: a call's argument is not on the tape"); }
          expr_codegen_ref(tape, a0, "t", leafname, &g->lc, ref, sizeof ref);
          sb_printf(b, "    V%d[q] = %s;\n", i, ref);
        }
        sb_printf(b, "  }\n");
        for (int i = 0; i < tape->n; i++)
          if (rt[i]) sb_printf(b, "  lugal_vmath(%d, V%d, %d);\n", tape->node[i]->i0, i, g->q.n);
      }
      if (grp) sb_printf(b, "  }\n");
    }
    free(mk);
    free(rt);
  }
  return 0;
}

/* the quadrature loop's head: the point's geometry (quadrilaterals and hexahedra), bases,
 * coefficients, the point cache's values and the integrand's nodes */
static int emit_point(kgen *g) {
  strbuf *b = &g->b;
  expr_tape *tape = &g->tape;
  expr_ctx *c = g->c;
  const cell_type ct = g->ct;
  const int facet = g->facet;
  lg_kernel *k = g->k;
  const int dim = g->dim;
  const int interior = g->interior;
  const int affine = g->affine;
  const int need_x = g->need_x;
  const int need_n = g->need_n;
  int *vlev = g->vlev;
  unsigned char *sel = g->sel;
  unsigned char *pcls = g->pcls;
  int *pslot = g->pslot;
  unsigned char *live = g->live;
  int (*need_val)[4] = g->need_val;
  int (*need_grad)[4] = g->need_grad;
  int (*cgrad)[4] = g->cgrad;
  int *xlive = g->xlive;
  lagrange_element *el = g->el;
  sb_printf(b, "  for (int q = 0; q < %d; ++q) {\n", g->q.n);
  if (facet) sb_printf(b, "    const int qq = facet*%d + q;\n", g->q.n);
  else sb_printf(b, "    const int qq = q;\n");
  if (interior) sb_printf(b, "    const int qm = fmq*%d + q;\n", g->q.n);
  if (!affine) {
    int nv = cell_nverts(ct);
    emit_point_map(b, dim, nv, "X", "GQ", "qq", "");
    /* the '-' quadrilateral's map at the same physical point */
    if (interior) emit_point_map(b, dim, nv, "XM", "GQM", "qm", "M");
    if (!facet) sb_printf(b, "    const double scale = det < 0.0 ? -det : det;\n");
    else if (dim == 2)
      sb_printf(b, "    const double e0 = J00*FT[facet*6] + J01*FT[facet*6+1], e1 = J10*FT[facet*6] + J11*FT[facet*6+1];\n"
                    "    const double scale = sqrt(e0*e0 + e1*e1);\n");
    else {
      sb_printf(b, "    const double *ta = FT + facet*6, *tb = FT + facet*6 + 3;\n");
      for (int i = 0; i < 3; i++)
        sb_printf(b, "    const double a%d = J%d0*ta[0] + J%d1*ta[1] + J%d2*ta[2], b%d = J%d0*tb[0] + J%d1*tb[1] + J%d2*tb[2];\n", i, i, i,
                  i, i, i, i, i);
      sb_printf(b, "    const double c0 = a1*b2 - a2*b1, c1 = a2*b0 - a0*b2, c2 = a0*b1 - a1*b0;\n"
                    "    const double scale = sqrt(c0*c0 + c1*c1 + c2*c2);\n");
    }
    if (facet && need_n) {
      for (int d = 0; d < dim; d++) {
        sb_printf(b, "    const double m%d = ", d);
        for (int kk = 0; kk < dim; kk++) sb_printf(b, "%sK%d%d*NR[facet*%d+%d]", kk ? " + " : "", kk, d, dim, kk);
        sb_printf(b, ";\n");
      }
      sb_printf(b, "    const double mn = (det < 0.0 ? -1.0 : 1.0)/sqrt(m0*m0 + m1*m1%s);\n", dim == 3 ? " + m2*m2" : "");
      for (int d = 0; d < dim; d++) sb_printf(b, "    const double n%d = m%d*mn;\n", d, d);
    }
    if (need_x)
      for (int d = 0; d < dim; d++) {
        if (!xlive[d]) continue;
        sb_printf(b, "    const double x%d = ", d);
        for (int j = 0; j < nv; j++) sb_printf(b, "%sNQ[qq*%d + %d]*X[%d]", j ? " + " : "", nv, j, j * dim + d);
        sb_printf(b, ";\n");
      }
  }
  sb_printf(b, "    const double wq = QW[q]*scale;\n");
  if (need_x && affine) {
    for (int d = 0; d < dim; d++) {
      if (!xlive[d]) continue;
      sb_printf(b, "    const double x%d = X[%d]", d, d);
      for (int kk = 0; kk < dim; kk++) sb_printf(b, " + J%d%d*QX[qq*%d+%d]", d, kk, dim, kk);
      sb_printf(b, ";\n");
    }
  }
  for (int sd = 0; sd < 2; sd++)
    for (int p = 0; p <= 3; p++) {
      int nl = el[p].nloc;
      const char *m = sd ? "m" : "", *M = sd ? "M" : "", *qi = sd ? "qm" : "qq";
      if (need_val[sd][p]) sb_printf(b, "    const double *b%s%d = B%s%d + %s*%d;\n", m, p, M, p, qi, nl);
      if (need_grad[sd][p] && !cgrad[sd][p]) emit_grads(b, dim, nl, p, m, M, qi, "    ");
    }
  /* coefficient values and gradients (those of constant gradients are computed above) */
  for (int i = 0; i < tape->n; i++)
    if (live[i] && tape->node[i]->kind == E_FIELD && !coef_hoisted(k, c, tape->node[i], cgrad))
      emit_coef(b, k, c, &g->lc, tape->node[i], el, "    ");
  if (k->ncache > 0) {
    /* cached coordinate-only values: read them, or compute (and store) them */
    int nc = k->ncache;
    sb_printf(b, "    double ");
    for (int i = 0, j = 0; i < tape->n; i++)
      if (pcls[i] == PC_CACHED) sb_printf(b, "%st%d", j++ ? ", " : "", i);
    sb_printf(b, ";\n");
    for (int i = 0; i < tape->n; i++) sel[i] = (tape->node[i]->dep & DEP_POINT) && pcls[i] == PC_SHARED;
    vector_select(sel, vlev, tape->n);
    keep_live(sel, live, tape->n);
    expr_codegen(b, tape, "t", "P", sel, leafname, &g->lc, "    ");
    sb_printf(b, "    if (cm == 2) {\n");
    for (int i = 0; i < tape->n; i++)
      if (pcls[i] == PC_CACHED) sb_printf(b, "      t%d = C[q*%d + %d];\n", i, nc, pslot[i]);
    sb_printf(b, "    } else {\n");
    for (int i = 0; i < tape->n; i++)
      sel[i] = pcls[i] == PC_CACHED ? 2 : (tape->node[i]->dep & DEP_POINT) && pcls[i] == PC_INNER;
    vector_select(sel, vlev, tape->n);
    keep_live(sel, live, tape->n);
    expr_codegen(b, tape, "t", "P", sel, leafname, &g->lc, "      ");
    sb_printf(b, "      if (cm == 1) {\n");
    for (int i = 0; i < tape->n; i++)
      if (pcls[i] == PC_CACHED) sb_printf(b, "        C[q*%d + %d] = t%d;\n", nc, pslot[i], i);
    sb_printf(b, "      }\n    }\n");
    for (int i = 0; i < tape->n; i++) sel[i] = (tape->node[i]->dep & DEP_POINT) && pcls[i] == PC_OTHER;
  } else {
    for (int i = 0; i < tape->n; i++) sel[i] = !sel[i];
  }
  vector_select(sel, vlev, tape->n);
  keep_live(sel, live, tape->n);
  expr_codegen(b, tape, "t", "P", sel, leafname, &g->lc, "    ");
  return 0;
}

/* the integrand's values times the bases into the element tensor (arity 0, 1 or 2) */
static int emit_contraction(kgen *g) {
  strbuf *b = &g->b;
  expr_tape *tape = &g->tape;
  expr_ctx *c = g->c;
  const kernel_spec *s = g->s;
  unsigned char *isconst = g->isconst;
  char ref[128];
  const vlayout *vrp = &g->vr;
  const vlayout *vcp = &g->vc;
  /* contraction */
  if (s->arity == 0) {
    expr_codegen_ref(tape, tape->root[0], "t", leafname, &g->lc, ref, sizeof ref);
    sb_printf(b, "    A[0] += wq*%s;\n", ref);
  } else if (s->arity == 1) {
    for (int a = 0; a < vrp->n; a++) {
      int any = 0;
      for (int i = 0; i < s->tab->nres; i++) any |= same_block(vrp, a, s->tab->res_leaf[i]);
      if (!any) continue;
      int unroll = vrp->nloc[a] <= KER_UNROLL;
      for (int ii = 0; ii < (unroll ? vrp->nloc[a] : 1); ii++) {
        char ix[16] = "i";
        if (unroll) {
          snprintf(ix, sizeof ix, "%d", ii);
          sb_printf(b, "    A[%d] += wq*(", vrp->off[a] + ii * vrp->stride[a]);
        } else sb_printf(b, "    for (int i = 0; i < %d; ++i) A[%d + i*%d] += wq*(", vrp->nloc[a], vrp->off[a], vrp->stride[a]);
        int first = 1;
        for (int i = 0; i < s->tab->nres; i++) {
          const expr *tl = s->tab->res_leaf[i];
          if (!same_block(vrp, a, tl)) continue;
          char bn[32];
          basis_name(c, tl, vrp->degree[a], bn, sizeof bn);
          expr_codegen_ref(tape, tape->root[i], "t", leafname, &g->lc, ref, sizeof ref);
          sb_printf(b, "%s%s*%s[%s]", first ? "" : " + ", ref, bn, ix);
          first = 0;
        }
        sb_printf(b, ");\n");
      }
    }
  } else {
    for (int a = 0; a < vrp->n; a++)
      for (int bb = 0; bb < vcp->n; bb++) {
        /* distinct test leaves for this block */
        const expr *tls[64];
        int nt = 0;
        for (int i = 0; i < s->tab->njac; i++) {
          const expr *tl = s->tab->jac_test[i];
          if (isconst[i] || !same_block(vrp, a, tl) || !same_block(vcp, bb, s->tab->jac_trial[i])) continue;
          int found = 0;
          for (int t = 0; t < nt; t++) found |= tls[t] == tl;
          if (!found && nt < 64) tls[nt++] = tl;
        }
        if (!nt) continue;
        /* the trial loop written out too for the smallest bases (P1, Q1: 3 or 4 trips) */
        int jun = vcp->nloc[bb] <= 4;
        for (int jj = 0; jj < (jun ? vcp->nloc[bb] : 1); jj++) {
          char jx[16] = "j";
          if (jun) {
            snprintf(jx, sizeof jx, "%d", jj);
            sb_printf(b, "    {\n");
          } else sb_printf(b, "    for (int j = 0; j < %d; ++j) {\n", vcp->nloc[bb]);
          for (int t = 0; t < nt; t++) {
            sb_printf(b, "      const double u%d = wq*(", t);
            int first = 1;
            for (int i = 0; i < s->tab->njac; i++) {
              if (isconst[i] || s->tab->jac_test[i] != tls[t] || !same_block(vcp, bb, s->tab->jac_trial[i])) continue;
              char bn[32];
              basis_name(c, s->tab->jac_trial[i], vcp->degree[bb], bn, sizeof bn);
              expr_codegen_ref(tape, tape->root[i], "t", leafname, &g->lc, ref, sizeof ref);
              sb_printf(b, "%s%s*%s[%s]", first ? "" : " + ", ref, bn, jx);
              first = 0;
            }
            sb_printf(b, ");\n");
          }
          if (jun) sb_printf(b, "      double *Aj = A + %d;\n", vcp->off[bb] + jj * vcp->stride[bb]);
          else sb_printf(b, "      double *Aj = A + %d + j*%d;\n", vcp->off[bb], vcp->stride[bb]);
          int unroll = vrp->nloc[a] <= KER_UNROLL;
          for (int ii = 0; ii < (unroll ? vrp->nloc[a] : 1); ii++) {
            char ix[16] = "i";
            if (unroll) {
              snprintf(ix, sizeof ix, "%d", ii);
              sb_printf(b, "      Aj[%d] += ", (vrp->off[a] + ii * vrp->stride[a]) * vcp->size);
            } else
              sb_printf(b, "      for (int i = 0; i < %d; ++i) Aj[(%d + i*%d)*%d] += ", vrp->nloc[a], vrp->off[a], vrp->stride[a], vcp->size);
            for (int t = 0; t < nt; t++) {
              char bn[32];
              basis_name(c, tls[t], vrp->degree[a], bn, sizeof bn);
              sb_printf(b, "%s%s[%s]*u%d", t ? " + " : "", bn, ix, t);
            }
            sb_printf(b, ";\n");
          }
          sb_printf(b, "    }\n");
        }
      }
  }
  return 0;
}

/* the kernel's C source (malloc'ed), or NULL with the message in err */
char *kernel_source(expr_ctx *c, cell_type ct, int facet, int qdeg, const kernel_spec *s,
                    const field_layout *rows, const field_layout *cols, lg_kernel *k,
                    char *err, size_t errlen) {
  if (facet == 2 && ct == CELL_HEXAHEDRON) {
    snprintf(err, errlen, "interior facet integrals are implemented on intervals, triangles, quadrilaterals and tetrahedra");
    return NULL;
  }
  kgen *g = calloc(1, sizeof *g);
  if (!g) { snprintf(err, errlen, "out of memory generating a kernel"); return NULL; }
  g->c = c;
  g->ct = ct;
  g->facet = facet;
  g->qdeg = qdeg;
  g->s = s;
  g->k = k;
  g->err = err;
  g->errlen = errlen;
  g->dim = cell_dim(ct);
  g->nf = facet ? cell_nfacets(ct) : 1;
  g->interior = facet == 2;
  g->nvf = g->dim;
  g->nperm = 1;
  for (int i = 2; i <= g->nvf; i++) g->nperm *= i;
  g->affine = cell_is_simplex(ct);
  memset(k, 0, sizeof *k);
  k->arity = s->arity;
  k->facet = facet;
  k->qdeg = qdeg;
  if (rows) k->rows = *rows;
  if (cols) k->cols = *cols;
  vlayout_of(rows, &g->vr);
  vlayout_of(cols, &g->vc);
  g->lc = (leafctx){k, g->dim};
  int rc = scan_leaves(g) || plan_entries(g) || emit_quadrature(g) || emit_bases(g) || emit_reference_tensors(g) ||
           emit_signature(g) || emit_hoisted(g);
  if (!rc) rc = emit_exact(g);
  if (!rc) {
    rc = emit_item(g) || emit_point(g) || emit_contraction(g);
    if (!rc) sb_printf(&g->b, "  }\n}\n");
  }
  char *out = NULL;
  if (rc != 1 && g->b.failed) snprintf(err, errlen, "out of memory generating a kernel");
  else if (rc != 1) out = g->b.s;
  if (!out) sb_free(&g->b);
  free(g->sel);
  free(g->isconst);
  free(g->pcls);
  free(g->pslot);
  free(g->vlev);
  free(g->live);
  free(g->qx);
  expr_tape_free(&g->tape);
  free(g);
  return out;
}

int kernel_build(lg_jit *j, expr_ctx *c, cell_type ct, int facet, int qdeg, const kernel_spec *s,
                 const field_layout *rows, const field_layout *cols, lg_kernel *k, char *err,
                 size_t errlen) {
  char *src = kernel_source(c, ct, facet, qdeg, s, rows, cols, k, err, errlen);
  if (!src) return 1;
  if (getenv("LUGAL_SHOW_KERNELS")) fprintf(stderr, "%s\n", src);
  int rc = jit_compile(j, src, &k->fn, &k->jid, &k->compile_ms, &k->cached, err, errlen);
  free(src);
  if (rc) return 1;
  if (jit_verbose(j) && !k->cached)
    fprintf(stderr, "lugal: kernel %d: %s %s integral, arity %d, quadrature degree %d (%d points), %d cached values per point, "
                    "compiled in %.2f ms\n", k->jid, cell_name(ct), facet ? "facet" : "cell", k->arity, qdeg, k->nq, k->ncache,
            k->compile_ms);
  if (k->ncache > 0 && !(k->pc = calloc(1, sizeof *k->pc))) {
    snprintf(err, errlen, "out of memory");
    return 1;
  }
  return 0;
}

void kernel_pcache_unlink(kernel_pcache *pc) {
  kernel_pcache_group *g = pc->g;
  pc->g = NULL;
  if (!g || --g->refs > 0) return;
  g->prev->next = g->next;
  g->next->prev = g->prev;
  free(g->v);
  free(g);
}

void kernel_release(lg_kernel *k) {
  if (!k || !k->pc) return;
  kernel_pcache_unlink(k->pc);
  free(k->pc);
  k->pc = NULL;
}
