/* untangle_global.c — the global untangling stage: all interior vertices of a simplicial
 * mesh together minimize a regularized barrier energy (the "foldover-free maps" approach of
 * Garanzha et al., ACM TOG 2021): per cell, with J the map from a regular reference simplex
 * of the mesh's mean cell size to the cell (per corner of a quadrilateral or hexahedron,
 * from a square's or cube's corner: section 1's "valid if each corner is valid"),
 *     f(J) = (1 - θ) tr(JᵀJ) / χ(det J, ε)^(2/d) + θ (det²J + 1) / χ(det J, ε),
 *     χ(D, ε) = (D + sqrt(ε² + D²)) / 2,
 * which is finite for inverted cells (χ > 0 for every D when ε > 0) and, as ε falls, a
 * barrier against det J ≤ 0; ε is set from the worst cell before each minimization,
 * ε = sqrt(1e-8 + 0.04 min(det_min, 0)²), so that it goes to 1e-4 once every cell is valid.
 * This is where the local stages stall: knots whose every vertex has an empty feasible set
 * (30% of the cells of a Tutte-started spiral strip). Gradient analytic: ∂det/∂J is the
 * cofactor matrix. See untangle_int.h. */
#include "untangle_int.h"

#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* rounds of the ε schedule without fewer invalid cells after which the stage gives up */
#define GLOBAL_PATIENCE 8

static double chi(double D, double eps) { return 0.5 * (D + sqrt(eps * eps + D * D)); }
static double dchi(double D, double eps) { return 0.5 * (1 + D / sqrt(eps * eps + D * D)); }

/* J = E W⁻¹ of corner k of cell c (E: the edge vectors from the corner vertex to its d
 * neighbours as columns, C->ct), its determinant; *vout the cell's vertices. A simplex has
 * one corner, a quadrilateral 4 and a hexahedron 8: their energy sums the corners' */
static double cell_map(const ctx *C, const double *x, int c, int k, const double *winv, double J[3][3], const int **vout) {
  int d = C->d;
  const int *v = C->m->cells + (size_t)c * (size_t)C->nvc, *ct = C->ct[k];
  *vout = v;
  double E[3][3];
  const double *p = x + (size_t)v[ct[0]] * d;
  for (int i = 0; i < d; i++)
    for (int j = 0; j < d; j++) E[i][j] = x[(size_t)v[ct[j + 1]] * d + i] - p[i];
  for (int i = 0; i < d; i++)
    for (int j = 0; j < d; j++) {
      double s = 0;
      for (int l = 0; l < d; l++) s += E[i][l] * winv[l * d + j];
      J[i][j] = s;
    }
  if (d == 2) return J[0][0] * J[1][1] - J[0][1] * J[1][0];
  return J[0][0] * (J[1][1] * J[2][2] - J[1][2] * J[2][1]) - J[0][1] * (J[1][0] * J[2][2] - J[1][2] * J[2][0]) +
         J[0][2] * (J[1][0] * J[2][1] - J[1][1] * J[2][0]);
}

/* ∂ det J / ∂ J_ik */
static void cofactor(int d, double J[3][3], double K[3][3]) {
  if (d == 2) {
    K[0][0] = J[1][1]; K[0][1] = -J[1][0];
    K[1][0] = -J[0][1]; K[1][1] = J[0][0];
    return;
  }
  for (int i = 0; i < 3; i++)
    for (int k = 0; k < 3; k++) {
      int i1 = (i + 1) % 3, i2 = (i + 2) % 3, k1 = (k + 1) % 3, k2 = (k + 2) % 3;
      K[i][k] = J[i1][k1] * J[i2][k2] - J[i1][k2] * J[i2][k1];
    }
}

/* W⁻¹ of a regular simplex whose edge matrix has determinant mean > 0 */
void ut_regular_winv(int d, double mean, double *w) {
  double s;
  if (d == 2) { /* columns (1, 0), (1/2, √3/2), scaled */
    s = sqrt(mean / (sqrt(3.0) / 2));
    double r[4] = {s, s / 2, 0, s * sqrt(3.0) / 2};
    double det = r[0] * r[3] - r[1] * r[2];
    w[0] = r[3] / det; w[1] = -r[1] / det; w[2] = -r[2] / det; w[3] = r[0] / det;
  } else { /* columns (1,0,0), (1/2,√3/2,0), (1/2,√3/6,√(2/3)), scaled */
    s = cbrt(mean / (sqrt(2.0) / 2));
    double r[3][3] = {{s, s / 2, s / 2}, {0, s * sqrt(3.0) / 2, s * sqrt(3.0) / 6}, {0, 0, s * sqrt(2.0 / 3.0)}};
    double J[3][3], K[3][3];
    memcpy(J, r, sizeof J);
    cofactor(3, J, K);
    double det = r[0][0] * K[0][0] + r[0][1] * K[0][1] + r[0][2] * K[0][2];
    for (int a = 0; a < 3; a++)
      for (int b = 0; b < 3; b++) w[a * 3 + b] = K[b][a] / det; /* inverse = cofactorᵀ / det */
  }
}

double *ut_reference_winv(const ctx *C, const double *xref, char *err) {
  const mesh *m = C->m;
  int d = C->d, nv = C->nvc, nk = C->ncorner;
  double *w = malloc(sizeof(double) * (size_t)m->ncell * nk * d * d + 1);
  if (!w) { snprintf(err, MESH_ERRLEN, "out of memory"); return NULL; }
  for (int c = 0; c < m->ncell; c++) {
    const int *v = m->cells + (size_t)c * (size_t)nv;
    /* each corner's edge matrix in the reference (a simplex has one corner: its own) */
    for (int kc = 0; kc < nk; kc++) {
      const int *ct = C->ct[kc];
      double E[3][3], K[3][3], det;
      for (int i = 0; i < d; i++)
        for (int k = 0; k < d; k++) E[i][k] = xref[(size_t)v[ct[k + 1]] * d + i] - xref[(size_t)v[ct[0]] * d + i];
      if (d == 2) {
        det = E[0][0] * E[1][1] - E[0][1] * E[1][0];
        K[0][0] = E[1][1]; K[0][1] = -E[1][0]; K[1][0] = -E[0][1]; K[1][1] = E[0][0];
      } else {
        cofactor(3, E, K);
        det = E[0][0] * K[0][0] + E[0][1] * K[0][1] + E[0][2] * K[0][2];
      }
      if (!(det > 0)) {
        if (nk == 1)
          snprintf(err, MESH_ERRLEN, "cell %d of the reference is %s: reference shapes must be valid cells", c + 1,
                   det < 0 ? "inverted" : "degenerate");
        else
          snprintf(err, MESH_ERRLEN, "cell %d of the reference has %s corner (at its vertex %d): reference shapes must be "
                   "valid cells", c + 1, det < 0 ? "an inverted" : "a degenerate", ct[0] + 1);
        free(w);
        return NULL;
      }
      double *wc = w + ((size_t)c * nk + kc) * d * d;
      for (int a = 0; a < d; a++)
        for (int b = 0; b < d; b++) wc[a * d + b] = K[b][a] / det;
    }
  }
  return w;
}

void ut_relative_mean_ratio(const ctx *C, const double *cwinv, double *out) {
  const mesh *m = C->m;
  int d = C->d, nk = C->ncorner;
  for (int c = 0; c < m->ncell; c++) {
    /* a quadrilateral's or hexahedron's: the worst of its corners' */
    double q = INFINITY;
    for (int kc = 0; kc < nk; kc++) {
      double J[3][3], A = 0;
      const int *v;
      double D = cell_map(C, m->x, c, kc, cwinv + ((size_t)c * nk + kc) * d * d, J, &v);
      for (int a = 0; a < d; a++)
        for (int b = 0; b < d; b++) A += J[a][b] * J[a][b];
      q = fmin(q, D > 0 && A > 0 ? d * pow(D, 2.0 / d) / A : 0);
    }
    out[c] = q;
  }
}

/* One corner's energy (a simplex has one corner), and with gk its gradient in each of the
 * corner's d + 1 vertices (C->ct[kc] order, d each); +∞ for an invalid corner at ε = 0 */
static double corner_energy(const objective *o, const double *x, int i, int kc, double *gk) {
  const ctx *C = o->C;
  int d = C->d, c = o->cells[i];
  double theta = o->theta, eps = o->eps;
  double J[3][3], K[3][3];
  const int *v;
  /* reference shapes per corner (a simplex has one); without them a quadrilateral's or
   * hexahedron's corners aim at a square's or cube's */
  const double *winv = o->cwinv ? o->cwinv + ((size_t)c * C->ncorner + kc) * d * d : o->winv;
  double D = cell_map(C, x, c, kc, winv, J, &v), A = 0;
  for (int a = 0; a < d; a++)
    for (int b = 0; b < d; b++) A += J[a][b] * J[a][b];
  if (eps == 0 && !(D > 0)) return INFINITY; /* ε = 0: the pure barrier (smoothing a valid mesh) */
  double ch = chi(D, eps), chp = dchi(D, eps), cs = pow(ch, -2.0 / d);
  double f = (1 - theta) * A * cs + theta * (D * D + 1) / ch;
  if (!gk) return f;
  /* ∂f/∂J = (1-θ)(2 J cs - (2/d) A cs/χ χ' K) + θ (2 D χ - (D² + 1) χ')/χ² K */
  cofactor(d, J, K);
  double kd = -(1 - theta) * (2.0 / d) * A * cs / ch * chp + theta * (2 * D * ch - (D * D + 1) * chp) / (ch * ch);
  double G[3][3], GE[3][3];
  for (int a = 0; a < d; a++)
    for (int b = 0; b < d; b++) G[a][b] = (1 - theta) * 2 * J[a][b] * cs + kd * K[a][b];
  /* ∂f/∂E = G W⁻ᵀ: column k is the gradient in vertex k + 1, minus their sum vertex 0's */
  for (int a = 0; a < d; a++)
    for (int k = 0; k < d; k++) {
      double s2 = 0;
      for (int l = 0; l < d; l++) s2 += G[a][l] * winv[k * d + l];
      GE[a][k] = s2;
    }
  for (int k = 0; k <= d; k++)
    for (int a = 0; a < d; a++) {
      double g = 0;
      if (k) g = GE[a][k - 1];
      else
        for (int l = 0; l < d; l++) g -= GE[a][l];
      gk[k * d + a] = g;
    }
  return f;
}

/* the buffered evaluation's memory limit: per corner its value and (d + 1) d gradient
 * entries, per free vertex its slots (a million hexahedra would need 1 GB); above it the
 * evaluation runs on one thread, accumulating directly, with the same result */
#define ENERGY_BUF_MAX ((size_t)512 << 20)

/* the per-corner buffers and each free vertex's (cell, corner, vertex) slots, in that order */
static int energy_prepare(const objective *o, int nfree) {
  ut_energy_buf *b = o->eb;
  if (b->ready) return b->ready < 0;
  const ctx *C = o->C;
  int d = C->d, nk = C->ncorner;
  size_t nc = (size_t)o->ncell * nk, ns = nc * (size_t)(d + 1);
  if (sizeof(double) * (nc + ns * d) + sizeof(int) * ns > ENERGY_BUF_MAX) { b->ready = -1; return 1; }
  b->fc = malloc(sizeof(double) * (nc + 1));
  b->gc = malloc(sizeof(double) * (ns * d + 1));
  b->off = calloc((size_t)nfree + 2, sizeof(int));
  b->slot = malloc(sizeof(int) * (ns + 1));
  if (!b->fc || !b->gc || !b->off || !b->slot) {
    ut_energy_release(b);
    b->ready = -1;
    return 1;
  }
  for (int pass = 0; pass < 2; pass++) {
    for (int i = 0; i < o->ncell; i++) {
      const int *v = cell_of(C, o->cells[i]);
      for (int kc = 0; kc < nk; kc++)
        for (int k = 0; k <= d; k++) {
          int fi = o->fidx[v[C->ct[kc][k]]];
          if (fi < 0) continue;
          if (pass) b->slot[b->off[fi + 1]++] = (int)(((size_t)i * nk + kc) * (d + 1) + k);
          else b->off[fi + 2]++;
        }
    }
    if (!pass)
      for (int f = 0; f < nfree; f++) b->off[f + 2] += b->off[f + 1];
  }
  b->ready = 1;
  return 0;
}

void ut_energy_release(ut_energy_buf *b) {
  if (!b) return;
  free(b->fc);
  free(b->gc);
  free(b->off);
  free(b->slot);
  memset(b, 0, sizeof *b);
}

/* The energy and its gradient. With OpenMP, threads over the cells: each corner writes its
 * value and vertex gradients, then the sum and each free vertex's gradient are taken in
 * (cell, corner, vertex) order, the order of the one-thread loop below, so that the result
 * is the same to the bit for any number of threads (OMP_NUM_THREADS) and without them. */
double ut_energy_eval(const objective *o, const double *x, double *grad, int nfree) {
  const ctx *C = o->C;
  int d = C->d, nk = C->ncorner, n = o->ncell;
  if (o->eb && !energy_prepare(o, nfree)) {
    ut_energy_buf *b = o->eb;
    int bad = 0;
#ifdef _OPENMP
#pragma omp parallel for schedule(static) reduction(|| : bad) if (n > 2048)
#endif
    for (int i = 0; i < n; i++)
      for (int kc = 0; kc < nk; kc++) {
        size_t q = (size_t)i * nk + kc;
        b->fc[q] = corner_energy(o, x, i, kc, grad ? b->gc + q * (size_t)(d + 1) * d : NULL);
        bad = bad || isinf(b->fc[q]);
      }
    if (bad) return INFINITY;
    double f = 0;
    for (size_t q = 0; q < (size_t)n * nk; q++) f += b->fc[q];
    if (!grad) return f;
#ifdef _OPENMP
#pragma omp parallel for schedule(static) if (nfree > 2048)
#endif
    for (int fi = 0; fi < nfree; fi++)
      for (int a = 0; a < d; a++) {
        double g = 0;
        for (int q = b->off[fi]; q < b->off[fi + 1]; q++) g += b->gc[(size_t)b->slot[q] * d + a];
        grad[(size_t)fi * d + a] = g;
      }
    return f;
  }
  double f = 0, gk[12];
  if (grad) memset(grad, 0, sizeof(double) * (size_t)nfree * d);
  for (int i = 0; i < n; i++) {
    const int *v = cell_of(C, o->cells[i]);
    for (int kc = 0; kc < nk; kc++) {
      double e = corner_energy(o, x, i, kc, grad ? gk : NULL);
      if (isinf(e)) return INFINITY;
      f += e;
      for (int k = 0; grad && k <= d; k++) {
        int fi = o->fidx[v[C->ct[kc][k]]];
        if (fi < 0) continue;
        for (int a = 0; a < d; a++) grad[(size_t)fi * d + a] += gk[k * d + a];
      }
    }
  }
  return f;
}

int ut_untangle_global(ctx *C, work *W, double *x, int maxit, const double *cwinv, const unsigned char *only,
                       int *iters, int *moved_count, unsigned char *moved) {
  mesh *m = C->m;
  int d = C->d;
  *iters = 0;
  if (m->type == CELL_INTERVAL) return 0;
  int simplex = C->ncorner == 1;
  int nfree = 0;
  int *freev = malloc(sizeof(int) * ((size_t)m->nvert + 1));
  double *x0 = malloc(sizeof(double) * ((size_t)m->nvert * d + 1));
  if (!freev || !x0) { free(freev); free(x0); return -1; }
  memcpy(x0, x, sizeof(double) * (size_t)m->nvert * d);
  for (int v = 0; v < m->nvert; v++)
    if (!C->bnd[v] && (!only || only[v])) { W->fidx[v] = nfree; freev[nfree++] = v; }
  int ncell = ut_cells_around(C, W, freev, nfree);
  /* the reference: a regular simplex whose edge-matrix determinant is the mean of the cells'
   * (their signed sum does not change when interior vertices move); for quadrilaterals and
   * hexahedra a square's or cube's corner of the mean cell measure (whose signed sum does
   * not change either) */
  double sum = 0;
  for (int c = 0; c < m->ncell; c++) {
    if (!simplex) { sum += mesh_cell_signed_measure(m, c); continue; }
    const int *v = m->cells + (size_t)c * (size_t)C->nvc;
    double E[3][3];
    for (int i = 0; i < d; i++)
      for (int k = 0; k < d; k++) E[i][k] = x[(size_t)v[k + 1] * d + i] - x[(size_t)v[0] * d + i];
    sum += d == 2 ? E[0][0] * E[1][1] - E[0][1] * E[1][0]
                  : E[0][0] * (E[1][1] * E[2][2] - E[1][2] * E[2][1]) - E[0][1] * (E[1][0] * E[2][2] - E[1][2] * E[2][0]) +
                        E[0][2] * (E[1][0] * E[2][1] - E[1][1] * E[2][0]);
  }
  double mean = sum / m->ncell;
  objective o;
  memset(&o, 0, sizeof o);
  o.C = C;
  o.S = C->jscale;
  o.ncell = ncell;
  o.cells = W->cells;
  o.fidx = W->fidx;
  o.smooth = 2;
  o.freev = freev;
  ut_energy_buf eb = {0};
  o.eb = &eb;
  o.theta = 0.5; /* shape and size alike (0.1 and 0.9 untangled the same spirals) */
  o.cwinv = cwinv; /* reference shapes, or the regular simplex below */
  if (mean > 0 && nfree) {
    if (simplex) ut_regular_winv(d, mean, o.winv);
    else {
      double h = d == 2 ? sqrt(mean) : cbrt(mean);
      memset(o.winv, 0, sizeof o.winv);
      for (int i = 0; i < d; i++) o.winv[i * d + i] = 1 / h;
    }
    int valid_rounds = 0, best_inv = INT_MAX, since_best = 0;
    for (int outer = 0; outer < 100; outer++) {
      double dmin = INFINITY, J[3][3];
      const int *v;
      for (int i = 0; i < ncell; i++)
        for (int kc = 0; kc < C->ncorner; kc++) {
          int c = W->cells[i];
          dmin = fmin(dmin, cell_map(C, x, c, kc, cwinv ? cwinv + ((size_t)c * C->ncorner + kc) * d * d : o.winv, J, &v));
        }
      int ninv;
      ut_count_cells(C, x, 0, &ninv, NULL);
      /* no new fewest invalid cells for GLOBAL_PATIENCE rounds: a mesh with no valid embedding
       * (a fuzzed one spent 100 rounds of 1000 iterations here); repairable tangles improved
       * at every round (the spirals: 2-5 rounds, at most 3 at the same count before valid) */
      if (ninv < best_inv) { best_inv = ninv; since_best = 0; }
      else if (++since_best >= GLOBAL_PATIENCE) break;
      /* valid: done, or with reference shapes one more minimization at the small ε that
       * validity gives, towards those shapes (the point of giving them) */
      if (!ninv && outer > 0 && (!cwinv || valid_rounds++)) break;
      o.eps = sqrt(1e-8 + 0.04 * pow(fmin(dmin, 0), 2));
      /* while cells are invalid, a round of the ε schedule ends when a step gains less than
       * 1e-4 of the energy (was 1e-9): the next round re-solves at a smaller ε anyway, as
       * foldover-free maps' inner solves stop at a 1e-4 gradient (spirals untangle 1.2-5x
       * faster, every hard case still valid, bench/RESULTS.md). With reference shapes every
       * round converges fully (0: 1e-9), or the valid state reached early leaves the last
       * round, towards those shapes, short of them (a quadrilateral spiral: 0.97 against 0.99) */
      o.ftol = ninv && !cwinv ? 1e-4 : 0;
      double f;
      int it = ut_lbfgs(&o, x, freev, nfree, maxit, &f);
      if (it < 0) break;
      *iters += it;
      if (!it) break;
    }
  }
  ut_energy_release(&eb);
  int total = 0;
  for (int i = 0; i < nfree; i++) {
    int v = freev[i], ch = 0;
    W->fidx[v] = -1;
    for (int j = 0; j < d; j++) ch |= x[(size_t)v * d + j] != x0[(size_t)v * d + j];
    if (ch && !moved[v]) { moved[v] = 1; total++; }
  }
  *moved_count += total;
  free(freev);
  free(x0);
  return 0;
}
