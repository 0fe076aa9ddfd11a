/* fem.c — quadrature on simplices (Gauss–Jacobi collapsed products), Lagrange elements
 * (nodal basis from the inverse Vandermonde matrix of monomials), and dof maps with
 * globally consistent edge orientation. */
#include "fem.h"

#include "../../mesh/dense.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---------------------------------------------------------------- Gauss–Jacobi */

int gauss_jacobi(int n, double a, double b, double *x, double *w) {
  if (n < 1 || n > 64) return 1;
  double *T = calloc((size_t)n * n, sizeof(double)), *V = malloc(sizeof(double) * (size_t)n * n);
  if (!T || !V) { free(T); free(V); return 1; }
  for (int k = 0; k < n; k++) {
    double s = 2 * k + a + b;
    T[k * n + k] = (k == 0) ? (b - a) / (a + b + 2) : (b * b - a * a) / (s * (s + 2));
    if (k + 1 < n) {
      int j = k + 1;
      double sj = 2 * j + a + b;
      double bj = 4.0 * j * (j + a) * (j + b) * (j + a + b) / (sj * sj * (sj + 1) * (sj - 1));
      T[k * n + j] = T[j * n + k] = sqrt(bj);
    }
  }
  dense_sym_eigen(n, T, V, 1e-32, 0); /* Golub–Welsch */
  double mu0 = pow(2, a + b + 1) * tgamma(a + 1) * tgamma(b + 1) / tgamma(a + b + 2);
  for (int i = 0; i < n; i++) {
    x[i] = T[i * n + i];
    w[i] = mu0 * V[i] * V[i];
  }
  /* sort ascending */
  for (int i = 1; i < n; i++) {
    double xv = x[i], wv = w[i];
    int j = i - 1;
    while (j >= 0 && x[j] > xv) { x[j + 1] = x[j]; w[j + 1] = w[j]; j--; }
    x[j + 1] = xv;
    w[j + 1] = wv;
  }
  free(T);
  free(V);
  return 0;
}

int quad_simplex(int dim, int degree, quad_rule *q) {
  if (degree < 0) degree = 0;
  if (degree > FEM_MAXDEG) return 1;
  if (dim == 0) { /* a point (an interval's facet) */
    q->dim = 0;
    q->degree = FEM_MAXDEG;
    q->n = 1;
    q->w[0] = 1;
    return 0;
  }
  if (dim >= 2 && !quad_table_rule(dim, degree, q)) return 0;
  int m = (degree + 2) / 2; /* exact for 2m-1 >= degree */
  double xa[64], wa[64], xb[64], wb[64], xc[64], wc[64];
  q->dim = dim;
  q->degree = 2 * m - 1;
  if (gauss_jacobi(m, 0, 0, xa, wa)) return 1;
  if (dim == 1) {
    q->n = m;
    for (int i = 0; i < m; i++) { q->x[i] = 0.5 * (1 + xa[i]); q->w[i] = 0.5 * wa[i]; }
    return 0;
  }
  if (gauss_jacobi(m, 1, 0, xb, wb)) return 1;
  if (dim == 2) {
    if (m * m > FEM_MAXQ) return 1;
    q->n = 0;
    for (int i = 0; i < m; i++)
      for (int j = 0; j < m; j++) {
        double a = xa[i], b = xb[j];
        q->x[2 * q->n] = 0.25 * (1 + a) * (1 - b);
        q->x[2 * q->n + 1] = 0.5 * (1 + b);
        q->w[q->n] = wa[i] * wb[j] / 8.0;
        q->n++;
      }
    return 0;
  }
  if (gauss_jacobi(m, 2, 0, xc, wc)) return 1;
  if (m * m * m > FEM_MAXQ) return 1;
  q->n = 0;
  for (int i = 0; i < m; i++)
    for (int j = 0; j < m; j++)
      for (int k = 0; k < m; k++) {
        double a = xa[i], b = xb[j], c = xc[k];
        q->x[3 * q->n] = 0.125 * (1 + a) * (1 - b) * (1 - c);
        q->x[3 * q->n + 1] = 0.25 * (1 + b) * (1 - c);
        q->x[3 * q->n + 2] = 0.5 * (1 + c);
        q->w[q->n] = wa[i] * wb[j] * wc[k] / 64.0;
        q->n++;
      }
  return 0;
}

/* ---------------------------------------------------------------- reference facets */

static const double int_v[2][3] = {{0, 0, 0}, {1, 0, 0}};
static const double tri_v[3][3] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
static const double tet_v[4][3] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
/* the unit square and cube, vertices in the mesh layer's order (counterclockwise, bottom
 * then top) */
static const double quad_v[4][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
static const double hex_v[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};

int cell_is_simplex(cell_type t) { return t == CELL_TRIANGLE || t == CELL_TETRAHEDRON || t == CELL_INTERVAL; }

const double *ref_vertex(cell_type t, int v) {
  switch (t) {
  case CELL_INTERVAL: return int_v[v];
  case CELL_TRIANGLE: return tri_v[v];
  case CELL_TETRAHEDRON: return tet_v[v];
  case CELL_QUADRILATERAL: return quad_v[v];
  default: return hex_v[v];
  }
}

void ref_facet_point(cell_type t, int f, const double *s, double *xi) {
  const int *fv = cell_facet_verts(t, f);
  int dim = cell_dim(t);
  const double *a = ref_vertex(t, fv[0]), *b = dim >= 2 ? ref_vertex(t, fv[1]) : a;
  if (dim == 1) {
    xi[0] = a[0];
  } else if (dim == 2) {
    for (int d = 0; d < 2; d++) xi[d] = (1 - s[0]) * a[d] + s[0] * b[d];
  } else if (t == CELL_TETRAHEDRON) {
    const double *c = ref_vertex(t, fv[2]);
    for (int d = 0; d < 3; d++) xi[d] = (1 - s[0] - s[1]) * a[d] + s[0] * b[d] + s[1] * c[d];
  } else {
    /* a hexahedron's face: the unit square along its first and last edges (cyclic order) */
    const double *c = ref_vertex(t, fv[3]);
    for (int d = 0; d < 3; d++) xi[d] = a[d] + s[0] * (b[d] - a[d]) + s[1] * (c[d] - a[d]);
  }
}

void ref_facet_tangents(cell_type t, int f, double t0[3], double t1[3]) {
  const int *fv = cell_facet_verts(t, f);
  if (t == CELL_INTERVAL) { /* a point: no tangents */
    for (int d = 0; d < 3; d++) t0[d] = t1[d] = 0;
    return;
  }
  const double *a = ref_vertex(t, fv[0]), *b = ref_vertex(t, fv[1]);
  const double *c = ref_vertex(t, fv[cell_dim(t) == 3 && t == CELL_HEXAHEDRON ? 3 : cell_dim(t) == 3 ? 2 : 1]);
  for (int d = 0; d < 3; d++) {
    t0[d] = b[d] - a[d];
    t1[d] = c[d] - a[d];
  }
}

void ref_facet_normal(cell_type t, int f, double *n) {
  static const double tn[3][2] = {{0.70710678118654752, 0.70710678118654752}, {-1, 0}, {0, -1}};
  static const double en[4][3] = {{0.57735026918962576, 0.57735026918962576, 0.57735026918962576},
                                  {-1, 0, 0}, {0, -1, 0}, {0, 0, -1}};
  if (t == CELL_INTERVAL) { n[0] = f == 0 ? 1 : -1; return; } /* facet 0 is x = 1 */
  if (t == CELL_TRIANGLE) { n[0] = tn[f][0]; n[1] = tn[f][1]; return; }
  if (t == CELL_TETRAHEDRON) { n[0] = en[f][0]; n[1] = en[f][1]; n[2] = en[f][2]; return; }
  /* the unit square and cube: the axis from the centre through the facet's centre */
  int dim = cell_dim(t), nv = dim == 2 ? 2 : 4;
  const int *fv = cell_facet_verts(t, f);
  for (int d = 0; d < dim; d++) {
    double c = 0;
    for (int i = 0; i < nv; i++) c += ref_vertex(t, fv[i])[d];
    c = c / nv - 0.5;
    n[d] = c > 0.25 ? 1 : c < -0.25 ? -1 : 0;
  }
}

/* the bilinear (trilinear) map of a quadrilateral (hexahedron): shape values and reference
 * gradients of its vertices at xi */
void q1_shape(cell_type t, const double *xi, double *N, double *dN) {
  int nv = t == CELL_QUADRILATERAL ? 4 : 8, dim = cell_dim(t);
  for (int i = 0; i < nv; i++) {
    const double *v = ref_vertex(t, i);
    double f[3], g[3];
    for (int d = 0; d < dim; d++) {
      f[d] = v[d] > 0.5 ? xi[d] : 1 - xi[d];
      g[d] = v[d] > 0.5 ? 1 : -1;
    }
    double p = 1;
    for (int d = 0; d < dim; d++) p *= f[d];
    if (N) N[i] = p;
    for (int d = 0; d < dim && dN; d++) {
      double q = g[d];
      for (int e = 0; e < dim; e++)
        if (e != d) q *= f[e];
      dN[i * dim + d] = q;
    }
  }
}

/* ---------------------------------------------------------------- tensor rules */

/* Gauss-Legendre with m points per direction on [0,1]^dim: exact to degree 2m - 1 in each
 * variable (the rule of quadrilaterals and hexahedra, and of a hexahedron's faces) */
static int gauss_box(int dim, int degree, quad_rule *q) {
  int m = (degree + 2) / 2;
  if (m < 1) m = 1;
  double x[64], w[64];
  if (m > 64 || gauss_jacobi(m, 0, 0, x, w)) return 1;
  long n = 1;
  for (int d = 0; d < dim; d++) n *= m;
  if (n > FEM_MAXQ) return 1;
  q->dim = dim;
  q->degree = 2 * m - 1;
  q->n = (int)n;
  for (long i = 0; i < n; i++) {
    long r = i;
    double wt = 1;
    for (int d = 0; d < dim; d++) {
      int k = (int)(r % m);
      r /= m;
      q->x[i * dim + d] = 0.5 * (1 + x[k]);
      wt *= 0.5 * w[k];
    }
    q->w[i] = wt;
  }
  return 0;
}

int quad_cell(cell_type t, int facet, int degree, quad_rule *q) {
  int dim = cell_dim(t) - (facet ? 1 : 0);
  if (cell_is_simplex(t) || (facet && t == CELL_QUADRILATERAL)) return quad_simplex(dim, degree, q);
  return gauss_box(dim, degree, q);
}

/* ---------------------------------------------------------------- Lagrange */

static double mono_eval(const int *p, const double *x, int dim) {
  double v = 1;
  for (int d = 0; d < dim; d++)
    for (int k = 0; k < p[d]; k++) v *= x[d];
  return v;
}

/* solve A X = B in place by Gaussian elimination with partial pivoting (A: n×n, B: n×m) */
static int gauss_solve(int n, double *A, int m, double *B) {
  for (int c = 0; c < n; c++) {
    int piv = c;
    for (int r = c + 1; r < n; r++)
      if (fabs(A[r * n + c]) > fabs(A[piv * n + c])) piv = r;
    if (fabs(A[piv * n + c]) < 1e-14) return 1;
    if (piv != c) {
      for (int k = 0; k < n; k++) { double t = A[c * n + k]; A[c * n + k] = A[piv * n + k]; A[piv * n + k] = t; }
      for (int k = 0; k < m; k++) { double t = B[c * m + k]; B[c * m + k] = B[piv * m + k]; B[piv * m + k] = t; }
    }
    for (int r = 0; r < n; r++) {
      if (r == c) continue;
      double f = A[r * n + c] / A[c * n + c];
      if (f == 0) continue;
      for (int k = c; k < n; k++) A[r * n + k] -= f * A[c * n + k];
      for (int k = 0; k < m; k++) B[r * m + k] -= f * B[c * m + k];
    }
  }
  for (int r = 0; r < n; r++)
    for (int k = 0; k < m; k++) B[r * m + k] /= A[r * n + r];
  return 0;
}

static int lagrange_finish(lagrange_element *e, char *err);

/* Q0, Q1, Q2 on the unit square and cube: vertices, edge midpoints, face centres, the
 * centre; the basis spans the monomials of degree <= p in each variable */
static int lagrange_init_box(lagrange_element *e, cell_type cell, int p, char *err) {
  int dim = cell_dim(cell), k = 0;
  e->cell = cell;
  e->dim = dim;
  e->degree = p;
  if (p == 0) {
    for (int d = 0; d < dim; d++) e->node[d] = 0.5;
    e->ent_dim[0] = 3; e->ent_id[0] = 0; e->ent_k[0] = 0;
    k = 1;
  } else {
    for (int v = 0; v < cell_nverts(cell); v++, k++) {
      memcpy(e->node + 3 * k, ref_vertex(cell, v), sizeof(double) * 3);
      e->ent_dim[k] = 0; e->ent_id[k] = v; e->ent_k[k] = 0;
    }
    if (p == 2) {
      for (int ed = 0; ed < cell_nedges(cell); ed++, k++) {
        const int *ev = cell_edge_verts(cell, ed);
        for (int d = 0; d < 3; d++) e->node[3 * k + d] = 0.5 * (ref_vertex(cell, ev[0])[d] + ref_vertex(cell, ev[1])[d]);
        e->ent_dim[k] = 1; e->ent_id[k] = ed; e->ent_k[k] = 0;
      }
      for (int f = 0; dim == 3 && f < cell_nfacets(cell); f++, k++) {
        const int *fv = cell_facet_verts(cell, f);
        for (int d = 0; d < 3; d++) {
          double c = 0;
          for (int i = 0; i < 4; i++) c += ref_vertex(cell, fv[i])[d];
          e->node[3 * k + d] = c / 4;
        }
        e->ent_dim[k] = 2; e->ent_id[k] = f; e->ent_k[k] = 0;
      }
      for (int d = 0; d < dim; d++) e->node[3 * k + d] = 0.5;
      e->ent_dim[k] = 3; e->ent_id[k] = 0; e->ent_k[k] = 0;
      k++;
    }
  }
  e->nloc = k;
  int m = 0;
  for (int a = 0; a <= p; a++)
    for (int b = 0; b <= p; b++)
      for (int c = 0; c <= (dim == 3 ? p : 0); c++) {
        e->mono[m][0] = a; e->mono[m][1] = b; e->mono[m][2] = c;
        m++;
      }
  e->nmono = m;
  if (m != k) { snprintf(err, 256, "internal error: %d nodes for %d monomials", k, m); return 1; }
  return 0;
}

int lagrange_init(lagrange_element *e, cell_type cell, int p, char *err) {
  memset(e, 0, sizeof *e);
  if (!cell_is_simplex(cell)) {
    if (p < 0 || p > 2) {
      snprintf(err, 256, "Lagrange degree %d is not available on %s (0, 1 and 2 are)", p, cell_plural(cell));
      return 1;
    }
    if (lagrange_init_box(e, cell, p, err)) return 1;
    return lagrange_finish(e, err);
  }
  if (p < 0 || p > 3) {
    snprintf(err, 256, "Lagrange degree %d is not available (0, 1, 2 and 3 are)", p);
    return 1;
  }
  int dim = cell_dim(cell);
  e->cell = cell;
  e->dim = dim;
  e->degree = p;
  int nv = dim + 1, k = 0;
  if (p == 0) { /* P0: one node at the centroid, owned by the cell */
    for (int d = 0; d < dim; d++) e->node[d] = 1.0 / (dim + 1);
    e->ent_dim[0] = 3; e->ent_id[0] = 0; e->ent_k[0] = 0;
    k = 1;
    nv = 0;
  }
  /* vertices */
  for (int v = 0; v < nv; v++, k++) {
    for (int d = 0; d < dim; d++) e->node[k * 3 + d] = ref_vertex(cell, v)[d];
    e->ent_dim[k] = 0; e->ent_id[k] = v; e->ent_k[k] = 0;
  }
  /* edges: p-1 nodes from the first to the second local vertex */
  int ne = p == 0 ? 0 : cell_nedges(cell);
  for (int ed = 0; ed < ne; ed++) {
    const int *ev = cell_edge_verts(cell, ed);
    for (int j = 1; j < p; j++, k++) {
      double s = (double)j / p;
      for (int d = 0; d < dim; d++) {
        double a = ref_vertex(cell, ev[0])[d];
        double b = ref_vertex(cell, ev[1])[d];
        e->node[k * 3 + d] = (1 - s) * a + s * b;
      }
      e->ent_dim[k] = 1; e->ent_id[k] = ed; e->ent_k[k] = j - 1;
    }
  }
  /* an interval's interior nodes belong to the cell */
  for (int j = 1; dim == 1 && j < p; j++, k++) {
    e->node[k * 3] = (double)j / p;
    e->ent_dim[k] = 3; e->ent_id[k] = 0; e->ent_k[k] = j - 1;
  }
  /* P3: one node per triangular face (the triangle itself in 2D: interior) */
  if (p == 3 && dim >= 2) {
    if (dim == 2) {
      e->node[k * 3] = e->node[k * 3 + 1] = 1.0 / 3;
      e->ent_dim[k] = 3; e->ent_id[k] = 0; e->ent_k[k] = 0;
      k++;
    } else {
      for (int f = 0; f < 4; f++, k++) {
        const int *fv = cell_facet_verts(cell, f);
        for (int d = 0; d < 3; d++)
          e->node[k * 3 + d] = (tet_v[fv[0]][d] + tet_v[fv[1]][d] + tet_v[fv[2]][d]) / 3;
        e->ent_dim[k] = 2; e->ent_id[k] = f; e->ent_k[k] = 0;
      }
    }
  }
  e->nloc = k;
  /* monomials of total degree <= p */
  int m = 0;
  for (int a = 0; a <= p; a++)
    for (int b = 0; a + b <= p && (dim >= 2 || b == 0); b++) {
      if (dim <= 2) { e->mono[m][0] = a; e->mono[m][1] = b; e->mono[m][2] = 0; m++; continue; }
      for (int c = 0; a + b + c <= p; c++) { e->mono[m][0] = a; e->mono[m][1] = b; e->mono[m][2] = c; m++; }
    }
  e->nmono = m;
  if (m != k) { snprintf(err, 256, "internal error: %d nodes for %d monomials", k, m); return 1; }
  return lagrange_finish(e, err);
}

/* the nodal basis (an inverse Vandermonde matrix), the facet closures and the basis means
 * of an element whose nodes and monomials are set */
static int lagrange_finish(lagrange_element *e, char *err) {
  int k = e->nloc, m = e->nmono, dim = e->dim, p = e->degree;
  cell_type cell = e->cell;
  /* V[n][m] = mono_m(node_n); coef = V^-1 so that phi_n(x) = sum_m coef[m][n] mono_m(x) */
  double V[FEM_MAXLOC * FEM_MAXLOC], I[FEM_MAXLOC * FEM_MAXLOC];
  for (int n = 0; n < k; n++)
    for (int j = 0; j < m; j++) V[n * k + j] = mono_eval(e->mono[j], e->node + 3 * n, dim);
  for (int i = 0; i < k * k; i++) I[i] = (i / k) == (i % k);
  if (gauss_solve(k, V, k, I)) { snprintf(err, 256, "singular Vandermonde matrix"); return 1; }
  memcpy(e->coef, I, sizeof(double) * (size_t)k * k);
  /* facet closures: nodes whose barycentric coordinate opposite the facet vanishes (a
   * simplex), or that lie on the facet's coordinate plane (the unit square and cube) */
  int nf = cell_nfacets(cell);
  for (int f = 0; f < nf; f++) {
    int c = 0;
    double nr[3] = {0, 0, 0};
    if (!cell_is_simplex(cell)) ref_facet_normal(cell, f, nr);
    for (int n = 0; n < k; n++) {
      const double *x = e->node + 3 * n;
      double lam;
      if (cell_is_simplex(cell)) lam = f == 0 ? 1 - x[0] - x[1] - (dim == 3 ? x[2] : 0) : x[f - 1];
      else {
        lam = 0;
        for (int d = 0; d < dim; d++)
          if (nr[d] != 0) lam = nr[d] > 0 ? 1 - x[d] : x[d];
      }
      if (fabs(lam) < 1e-12) e->facet_dofs[f][c++] = n;
    }
    e->nfacet_dofs = c;
  }
  /* the mean of each basis function over the cell (exact: a rule of the element's degree) */
  quad_rule q;
  if (quad_cell(cell, 0, p > 0 ? p : 1, &q)) { snprintf(err, 256, "no quadrature rule for the basis means"); return 1; }
  double vol = 0;
  memset(e->mean, 0, sizeof e->mean);
  for (int i = 0; i < q.n; i++) {
    double val[FEM_MAXLOC], grad[FEM_MAXLOC * 3];
    lagrange_eval(e, q.x + dim * i, val, grad);
    for (int n = 0; n < k; n++) e->mean[n] += q.w[i] * val[n];
    vol += q.w[i];
  }
  for (int n = 0; n < k; n++) e->mean[n] /= vol;
  return 0;
}

void lagrange_eval(const lagrange_element *e, const double *xi, double *val, double *grad) {
  int k = e->nloc, dim = e->dim;
  double mv[FEM_MAXLOC], md[FEM_MAXLOC][3];
  for (int j = 0; j < e->nmono; j++) {
    mv[j] = mono_eval(e->mono[j], xi, dim);
    for (int d = 0; d < dim; d++) {
      int p[3] = {e->mono[j][0], e->mono[j][1], e->mono[j][2]};
      if (p[d] == 0) { md[j][d] = 0; continue; }
      double f = p[d];
      p[d]--;
      md[j][d] = f * mono_eval(p, xi, dim);
    }
  }
  for (int n = 0; n < k; n++) {
    double v = 0, g[3] = {0, 0, 0};
    for (int j = 0; j < e->nmono; j++) {
      double c = e->coef[j * k + n];
      v += c * mv[j];
      for (int d = 0; d < dim; d++) g[d] += c * md[j][d];
    }
    if (val) val[n] = v;
    if (grad)
      for (int d = 0; d < dim; d++) grad[n * dim + d] = g[d];
  }
}

/* ---------------------------------------------------------------- dof maps */

/* K = J^-1 (2x2 or 3x3); returns det J */
static double invert_jacobian(int d, double J[3][3], double K[3][3]) {
  double det;
  if (d == 1) {
    det = J[0][0];
    K[0][0] = 1 / det;
  } else if (d == 2) {
    det = J[0][0] * J[1][1] - J[0][1] * J[1][0];
    K[0][0] = J[1][1] / det; K[0][1] = -J[0][1] / det;
    K[1][0] = -J[1][0] / det; K[1][1] = J[0][0] / det;
  } else {
    det = J[0][0] * (J[1][1] * J[2][2] - J[1][2] * J[2][1]) - J[0][1] * (J[1][0] * J[2][2] - J[1][2] * J[2][0]) +
          J[0][2] * (J[1][0] * J[2][1] - J[1][1] * J[2][0]);
    K[0][0] = (J[1][1] * J[2][2] - J[1][2] * J[2][1]) / det;
    K[0][1] = (J[0][2] * J[2][1] - J[0][1] * J[2][2]) / det;
    K[0][2] = (J[0][1] * J[1][2] - J[0][2] * J[1][1]) / det;
    K[1][0] = (J[1][2] * J[2][0] - J[1][0] * J[2][2]) / det;
    K[1][1] = (J[0][0] * J[2][2] - J[0][2] * J[2][0]) / det;
    K[1][2] = (J[0][2] * J[1][0] - J[0][0] * J[1][2]) / det;
    K[2][0] = (J[1][0] * J[2][1] - J[1][1] * J[2][0]) / det;
    K[2][1] = (J[0][1] * J[2][0] - J[0][0] * J[2][1]) / det;
    K[2][2] = (J[0][0] * J[1][1] - J[0][1] * J[1][0]) / det;
  }
  return det;
}

double simplex_jacobian(const mesh *m, int c, double J[3][3], double K[3][3]) {
  int d = m->dim;
  const int *v = m->cells + (size_t)c * (size_t)m->nvc;
  const double *x0 = m->x + d * v[0];
  for (int i = 0; i < d; i++)
    for (int k = 0; k < d; k++) J[i][k] = m->x[d * v[k + 1] + i] - x0[i];
  return invert_jacobian(d, J, K);
}

double cell_jacobian(const mesh *m, int c, const double *xi, double J[3][3], double K[3][3]) {
  if (cell_is_simplex(m->type)) return simplex_jacobian(m, c, J, K);
  int d = m->dim;
  const int *v = m->cells + (size_t)c * (size_t)m->nvc;
  double dN[8 * 3];
  q1_shape(m->type, xi, NULL, dN);
  for (int i = 0; i < d; i++)
    for (int k = 0; k < d; k++) {
      double s = 0;
      for (int j = 0; j < m->nvc; j++) s += m->x[d * v[j] + i] * dN[j * d + k];
      J[i][k] = s;
    }
  return invert_jacobian(d, J, K);
}

const double *dofmap_node_ref(const dofmap *dm, int k) { return dm->el.node + 3 * (k / dm->bs); }

void dofmap_node_coords(const dofmap *dm, int c, int k, double *x) {
  const mesh *m = dm->m;
  int d = m->dim;
  const int *v = m->cells + (size_t)c * (size_t)m->nvc;
  const double *xi = dofmap_node_ref(dm, k);
  if (!cell_is_simplex(m->type)) {
    double N[8];
    q1_shape(m->type, xi, N, NULL);
    for (int i = 0; i < d; i++) {
      double s = 0;
      for (int j = 0; j < m->nvc; j++) s += N[j] * m->x[d * v[j] + i];
      x[i] = s;
    }
    return;
  }
  double lam0 = 1;
  for (int i = 0; i < d; i++) lam0 -= xi[i];
  for (int i = 0; i < d; i++) {
    double s = lam0 * m->x[d * v[0] + i];
    for (int j = 0; j < d; j++) s += xi[j] * m->x[d * v[j + 1] + i];
    x[i] = s;
  }
}

dofmap *dofmap_new(mesh *m, int degree, int disc, char *err) {
  dofmap *dm = calloc(1, sizeof *dm);
  if (!dm) { snprintf(err, 256, "out of memory"); return NULL; }
  dm->m = m;
  dm->degree = degree;
  dm->bs = 1;
  dm->disc = disc;
  if (lagrange_init(&dm->el, m->type, degree, err)) { free(dm); return NULL; }
  int nloc = dm->el.nloc;
  dm->nloc = nloc;
  /* the entities that own dofs: count the element's nodes on each kind (discontinuous: the
   * cell owns them all) */
  int nper[4] = {0, 0, 0, 0};
  for (int k = 0; k < nloc; k++) nper[disc ? 3 : dm->el.ent_dim[k]]++;
  int ne = cell_nedges(m->type), nfc = cell_nfacets(m->type);
  int edge_per = ne ? nper[1] / ne : 0, face_per = m->dim == 3 ? nper[2] / nfc : 0, cell_per = nper[3];
  if (nper[1] && mesh_build_edges(m)) { snprintf(err, 256, "%.200s", m->err); free(dm); return NULL; }
  if (nper[2] && mesh_build_faces(m)) { snprintf(err, 256, "%.200s", m->err); free(dm); return NULL; }
  long nd = nper[0] ? m->nvert : 0; /* P0: the cells' dofs only */
  long edge_off = nd;
  nd += (long)m->nedge * edge_per;
  long face_off = nd;
  nd += (long)m->nface * face_per;
  long cell_off = nd;
  nd += (long)m->ncell * cell_per;
  if (nd > 2000000000L) { snprintf(err, 256, "too many dofs"); free(dm); return NULL; }
  dm->ndof = (int)nd;
  /* continuous P1 / Q1: the dofs are the vertices in the cells' own order, so the dof map is
   * the mesh's cell list (not a copy: 25 MB on 1.57 M tetrahedra); the mesh outlives it */
  int vertices = !disc && nper[0] == nloc && nloc == m->nvc;
  for (int k = 0; vertices && k < nloc; k++) vertices = dm->el.ent_dim[k] == 0 && dm->el.ent_id[k] == k;
  if (vertices) {
    dm->cell_dofs = m->cells;
    dm->alias = 1;
    return dm;
  }
  dm->cell_dofs = malloc(sizeof(int) * (size_t)m->ncell * (size_t)nloc);
  if (!dm->cell_dofs) { snprintf(err, 256, "out of memory"); free(dm); return NULL; }
  for (int c = 0; c < m->ncell; c++) {
    const int *v = m->cells + (size_t)c * (size_t)m->nvc;
    int *cd = dm->cell_dofs + (size_t)c * (size_t)nloc;
    for (int k = 0; k < nloc; k++) {
      int ed = disc ? 3 : dm->el.ent_dim[k], id = dm->el.ent_id[k], j = disc ? k : dm->el.ent_k[k];
      if (ed == 0) cd[k] = v[id];
      else if (ed == 1) {
        int ge = m->cell_edges[(size_t)c * (size_t)ne + (size_t)id];
        const int *lv = cell_edge_verts(m->type, id);
        int forward = v[lv[0]] < v[lv[1]]; /* global edges run from the lower vertex id */
        int jj = forward ? j : (edge_per - 1 - j);
        cd[k] = (int)(edge_off + (long)ge * edge_per + jj);
      } else if (ed == 2) {
        cd[k] = (int)(face_off + (long)m->cell_faces[(size_t)c * (size_t)nfc + (size_t)id] * face_per + j);
      } else {
        cd[k] = (int)(cell_off + (long)c * cell_per + j);
      }
    }
  }
  return dm;
}

dofmap *dofmap_block(const dofmap *s, int bs, char *err) {
  if (bs < 1 || bs > 3 || s->bs != 1) { snprintf(err, 256, "a vector space has 1 to 3 components (got %d)", bs); return NULL; }
  if ((long)s->ndof * bs > 2000000000L) { snprintf(err, 256, "too many dofs"); return NULL; }
  dofmap *dm = malloc(sizeof *dm);
  if (!dm) { snprintf(err, 256, "out of memory"); return NULL; }
  *dm = *s;
  dm->alias = 0;
  dm->bs = bs;
  dm->nloc = s->nloc * bs;
  dm->ndof = s->ndof * bs;
  size_t n = (size_t)s->m->ncell * (size_t)s->nloc;
  dm->cell_dofs = malloc(sizeof(int) * n * (size_t)bs + 1);
  if (!dm->cell_dofs) { free(dm); snprintf(err, 256, "out of memory"); return NULL; }
  for (size_t i = 0; i < n; i++)
    for (int j = 0; j < bs; j++) dm->cell_dofs[i * (size_t)bs + (size_t)j] = bs * s->cell_dofs[i] + j;
  return dm;
}

void dofmap_dof_entity(const dofmap *d, int s, int *kind, int *id, int *j) {
  const mesh *m = d->m;
  int nloc = d->el.nloc, nper[4] = {0, 0, 0, 0};
  for (int k = 0; k < nloc; k++) nper[d->disc ? 3 : d->el.ent_dim[k]]++;
  long n[4] = {nper[0] ? m->nvert : 0, 0, 0, m->ncell};
  int per[4] = {1, 0, 0, nper[3]};
  int ne = cell_nedges(m->type), nfc = cell_nfacets(m->type);
  if (nper[1]) { per[1] = nper[1] / ne; n[1] = m->nedge; }
  if (nper[2] && m->dim == 3) { per[2] = nper[2] / nfc; n[2] = m->nface; }
  long r = s;
  for (int k = 0; k < 4; k++) {
    long here = n[k] * per[k];
    if (r < here || k == 3) {
      *kind = k;
      *id = (int)(r / per[k]);
      *j = (int)(r % per[k]);
      return;
    }
    r -= here;
  }
}

void dofmap_free(dofmap *d) {
  if (!d) return;
  if (!d->alias) free(d->cell_dofs);
  free(d);
}
