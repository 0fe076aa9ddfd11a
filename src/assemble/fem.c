/* fem.c — quadrature on simplices (Gauss–Jacobi collapsed products), Lagrange elements
 * (nodal basis from the inverse Vandermonde matrix of monomials), and dof maps with
 * globally consistent edge orientation. */
#include "fem.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---------------------------------------------------------------- Gauss–Jacobi */

/* cyclic Jacobi eigenvalue method for a small symmetric matrix (n <= 64); a becomes
 * diagonal, v holds the eigenvectors as columns */
static void sym_eig(int n, double *a, double *v) {
  for (int i = 0; i < n; i++)
    for (int j = 0; j < n; j++) v[i * n + j] = i == j;
  for (int sweep = 0; sweep < 100; sweep++) {
    double off = 0;
    for (int i = 0; i < n; i++)
      for (int j = i + 1; j < n; j++) off += a[i * n + j] * a[i * n + j];
    if (off < 1e-32) break;
    for (int p = 0; p < n; p++)
      for (int q = p + 1; q < n; q++) {
        double apq = a[p * n + q];
        if (fabs(apq) < 1e-300) continue;
        double theta = (a[q * n + q] - a[p * n + p]) / (2 * apq);
        double t = (theta >= 0 ? 1 : -1) / (fabs(theta) + sqrt(theta * theta + 1));
        double c = 1 / sqrt(t * t + 1), s = t * c;
        for (int k = 0; k < n; k++) {
          double akp = a[k * n + p], akq = a[k * n + q];
          a[k * n + p] = c * akp - s * akq;
          a[k * n + q] = s * akp + c * akq;
        }
        for (int k = 0; k < n; k++) {
          double apk = a[p * n + k], aqk = a[q * n + k];
          a[p * n + k] = c * apk - s * aqk;
          a[q * n + k] = s * apk + c * aqk;
        }
        for (int k = 0; k < n; k++) {
          double vkp = v[k * n + p], vkq = v[k * n + q];
          v[k * n + p] = c * vkp - s * vkq;
          v[k * n + q] = s * vkp + c * vkq;
        }
      }
  }
}

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
  sym_eig(n, T, V);
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

static const double tri_v[3][2] = {{0, 0}, {1, 0}, {0, 1}};
static const double tet_v[4][3] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};

void ref_facet_point(cell_type t, int f, const double *s, double *xi) {
  const int *fv = cell_facet_verts(t, f);
  if (t == CELL_TRIANGLE) {
    for (int d = 0; d < 2; d++) xi[d] = (1 - s[0]) * tri_v[fv[0]][d] + s[0] * tri_v[fv[1]][d];
  } else {
    for (int d = 0; d < 3; d++)
      xi[d] = (1 - s[0] - s[1]) * tet_v[fv[0]][d] + s[0] * tet_v[fv[1]][d] + s[1] * tet_v[fv[2]][d];
  }
}

void ref_facet_normal(cell_type t, int f, double *n) {
  static const double tn[3][2] = {{0.70710678118654752, 0.70710678118654752}, {-1, 0}, {0, -1}};
  static const double en[4][3] = {{0.57735026918962576, 0.57735026918962576, 0.57735026918962576},
                                  {-1, 0, 0}, {0, -1, 0}, {0, 0, -1}};
  if (t == CELL_TRIANGLE) { n[0] = tn[f][0]; n[1] = tn[f][1]; }
  else { n[0] = en[f][0]; n[1] = en[f][1]; n[2] = en[f][2]; }
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

int lagrange_init(lagrange_element *e, cell_type cell, int p, char *err) {
  memset(e, 0, sizeof *e);
  if (cell != CELL_TRIANGLE && cell != CELL_TETRAHEDRON) {
    snprintf(err, 256, "Lagrange elements on %s are not implemented yet (triangles and "
                       "tetrahedra are)", cell_plural(cell));
    return 1;
  }
  if (p < 0 || p > 3) {
    snprintf(err, 256, "Lagrange degree %d is not available (0, 1, 2 and 3 are)", p);
    return 1;
  }
  int dim = cell == CELL_TRIANGLE ? 2 : 3;
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
    for (int d = 0; d < dim; d++) e->node[k * 3 + d] = dim == 2 ? tri_v[v][d] : tet_v[v][d];
    e->ent_dim[k] = 0; e->ent_id[k] = v; e->ent_k[k] = 0;
  }
  /* edges: p-1 nodes from the first to the second local vertex */
  int ne = p == 0 ? 0 : cell_nedges(cell);
  for (int ed = 0; ed < ne; ed++) {
    const int *ev = cell_edge_verts(cell, ed);
    for (int j = 1; j < p; j++, k++) {
      double s = (double)j / p;
      for (int d = 0; d < dim; d++) {
        double a = dim == 2 ? tri_v[ev[0]][d] : tet_v[ev[0]][d];
        double b = dim == 2 ? tri_v[ev[1]][d] : tet_v[ev[1]][d];
        e->node[k * 3 + d] = (1 - s) * a + s * b;
      }
      e->ent_dim[k] = 1; e->ent_id[k] = ed; e->ent_k[k] = j - 1;
    }
  }
  /* P3: one node per triangular face (the triangle itself in 2D: interior) */
  if (p == 3) {
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
    for (int b = 0; a + b <= p; b++) {
      if (dim == 2) { e->mono[m][0] = a; e->mono[m][1] = b; e->mono[m][2] = 0; m++; continue; }
      for (int c = 0; a + b + c <= p; c++) { e->mono[m][0] = a; e->mono[m][1] = b; e->mono[m][2] = c; m++; }
    }
  e->nmono = m;
  if (m != k) { snprintf(err, 256, "internal error: %d nodes for %d monomials", k, m); return 1; }
  /* V[n][m] = mono_m(node_n); coef = V^-1 so that phi_n(x) = sum_m coef[m][n] mono_m(x) */
  double V[FEM_MAXLOC * FEM_MAXLOC], I[FEM_MAXLOC * FEM_MAXLOC];
  for (int n = 0; n < k; n++)
    for (int j = 0; j < m; j++) V[n * k + j] = mono_eval(e->mono[j], e->node + 3 * n, dim);
  for (int i = 0; i < k * k; i++) I[i] = (i / k) == (i % k);
  if (gauss_solve(k, V, k, I)) { snprintf(err, 256, "singular Vandermonde matrix"); return 1; }
  memcpy(e->coef, I, sizeof(double) * (size_t)k * k);
  /* facet closures: nodes whose barycentric coordinate opposite the facet vanishes */
  int nf = cell_nfacets(cell);
  for (int f = 0; f < nf; f++) {
    int c = 0;
    for (int n = 0; n < k; n++) {
      const double *x = e->node + 3 * n;
      double lam = f == 0 ? 1 - x[0] - x[1] - (dim == 3 ? x[2] : 0) : x[f - 1];
      if (fabs(lam) < 1e-12) e->facet_dofs[f][c++] = n;
    }
    e->nfacet_dofs = c;
  }
  /* the mean of each basis function over the cell (exact: a rule of the element's degree) */
  quad_rule q;
  if (quad_simplex(dim, p > 0 ? p : 1, &q)) { snprintf(err, 256, "no quadrature rule for the basis means"); return 1; }
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

double simplex_jacobian(const mesh *m, int c, double J[3][3], double K[3][3]) {
  int d = m->dim;
  const int *v = m->cells + (size_t)c * (size_t)m->nvc;
  const double *x0 = m->x + d * v[0];
  for (int i = 0; i < d; i++)
    for (int k = 0; k < d; k++) J[i][k] = m->x[d * v[k + 1] + i] - x0[i];
  double det;
  if (d == 2) {
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

const double *dofmap_node_ref(const dofmap *dm, int k) { return dm->el.node + 3 * (k / dm->bs); }

void dofmap_node_coords(const dofmap *dm, int c, int k, double *x) {
  const mesh *m = dm->m;
  int d = m->dim;
  const int *v = m->cells + (size_t)c * (size_t)m->nvc;
  const double *xi = dofmap_node_ref(dm, k);
  double lam0 = 1;
  for (int i = 0; i < d; i++) lam0 -= xi[i];
  for (int i = 0; i < d; i++) {
    double s = lam0 * m->x[d * v[0] + i];
    for (int j = 0; j < d; j++) s += xi[j] * m->x[d * v[j + 1] + i];
    x[i] = s;
  }
}

dofmap *dofmap_new(mesh *m, int degree, char *err) {
  dofmap *dm = calloc(1, sizeof *dm);
  if (!dm) { snprintf(err, 256, "out of memory"); return NULL; }
  dm->m = m;
  dm->degree = degree;
  dm->bs = 1;
  if (lagrange_init(&dm->el, m->type, degree, err)) { free(dm); return NULL; }
  int p = degree, nloc = dm->el.nloc;
  dm->nloc = nloc;
  if (p >= 2 && mesh_build_edges(m)) { snprintf(err, 256, "%.200s", m->err); free(dm); return NULL; }
  if (p >= 3 && m->dim == 3 && mesh_build_faces(m)) { snprintf(err, 256, "%.200s", m->err); free(dm); return NULL; }
  long nd = p == 0 ? 0 : m->nvert; /* P0: the cells' dofs only */
  long edge_off = nd;
  if (p >= 2) nd += (long)m->nedge * (p - 1);
  long face_off = nd;
  if (p >= 3 && m->dim == 3) nd += m->nface;
  long cell_off = nd;
  if ((p >= 3 && m->dim == 2) || p == 0) nd += m->ncell;
  if (nd > 2000000000L) { snprintf(err, 256, "too many dofs"); free(dm); return NULL; }
  dm->ndof = (int)nd;
  dm->cell_dofs = malloc(sizeof(int) * (size_t)m->ncell * (size_t)nloc);
  if (!dm->cell_dofs) { snprintf(err, 256, "out of memory"); free(dm); return NULL; }
  int ne = cell_nedges(m->type);
  for (int c = 0; c < m->ncell; c++) {
    const int *v = m->cells + (size_t)c * (size_t)m->nvc;
    int *cd = dm->cell_dofs + (size_t)c * (size_t)nloc;
    for (int k = 0; k < nloc; k++) {
      int ed = dm->el.ent_dim[k], id = dm->el.ent_id[k], j = dm->el.ent_k[k];
      if (ed == 0) cd[k] = v[id];
      else if (ed == 1) {
        int ge = m->cell_edges[(size_t)c * (size_t)ne + (size_t)id];
        const int *lv = cell_edge_verts(m->type, id);
        int forward = v[lv[0]] < v[lv[1]]; /* global edges run from the lower vertex id */
        int jj = forward ? j : (p - 2 - j);
        cd[k] = (int)(edge_off + (long)ge * (p - 1) + jj);
      } else if (ed == 2) {
        cd[k] = (int)(face_off + m->cell_faces[(size_t)c * 4 + (size_t)id]);
      } else {
        cd[k] = (int)(cell_off + c);
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

void dofmap_free(dofmap *d) {
  if (!d) return;
  free(d->cell_dofs);
  free(d);
}
