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

#include "../dense.h"

#include <limits.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* rounds of the ε schedule without fewer invalid cells after which the stage gives up */
#define GLOBAL_PATIENCE 8

static double chi(double D, double eps) { return 0.5 * (D + sqrt(eps * eps + D * D)); }
static double dchi(double D, double eps) { return 0.5 * (1 + D / sqrt(eps * eps + D * D)); }

/* J = E W⁻¹ of corner k of cell c (E: the edge vectors from the corner vertex to its d
 * neighbours as columns, C->ct), its determinant; *vout the cell's vertices. A simplex has
 * one corner, a quadrilateral 4 and a hexahedron 8: their energy sums the corners'. Inlined
 * with a constant d (cell_map below), whose loops are unrolled: with d a variable the loops
 * took 500 instructions a call, a quarter of the L-BFGS smoother's */
static inline double cell_map_d(int d, const ctx *C, const double *x, int c, int k, const double *winv, double J[3][3],
                                const int **vout) {
  const int *v = C->m->cells + (size_t)c * (size_t)C->nvc, *ct = C->ct[k];
  *vout = v;
  double E[3][3];
  const double *p = x + (size_t)v[ct[0]] * d;
#pragma GCC unroll 3
  for (int j = 0; j < d; j++) {
    const double *q = x + (size_t)v[ct[j + 1]] * d;
#pragma GCC unroll 3
    for (int i = 0; i < d; i++) E[i][j] = q[i] - p[i];
  }
#pragma GCC unroll 3
  for (int i = 0; i < d; i++)
#pragma GCC unroll 3
    for (int j = 0; j < d; j++) {
      double s = 0;
#pragma GCC unroll 3
      for (int l = 0; l < d; l++) s += E[i][l] * winv[l * d + j];
      J[i][j] = s;
    }
  if (d == 2) return J[0][0] * J[1][1] - J[0][1] * J[1][0];
  return J[0][0] * (J[1][1] * J[2][2] - J[1][2] * J[2][1]) - J[0][1] * (J[1][0] * J[2][2] - J[1][2] * J[2][0]) +
         J[0][2] * (J[1][0] * J[2][1] - J[1][1] * J[2][0]);
}

static double cell_map(const ctx *C, const double *x, int c, int k, const double *winv, double J[3][3], const int **vout) {
  return C->d == 3 ? cell_map_d(3, C, x, c, k, winv, J, vout) : cell_map_d(2, C, x, c, k, winv, J, vout);
}

/* ∂ det J / ∂ J_ik */
static inline void cofactor(int d, double J[3][3], double K[3][3]) {
  if (d == 2) {
    K[0][0] = J[1][1]; K[0][1] = -J[1][0];
    K[1][0] = -J[0][1]; K[1][1] = J[0][0];
    return;
  }
  K[0][0] = J[1][1] * J[2][2] - J[1][2] * J[2][1];
  K[0][1] = J[1][2] * J[2][0] - J[1][0] * J[2][2];
  K[0][2] = J[1][0] * J[2][1] - J[1][1] * J[2][0];
  K[1][0] = J[2][1] * J[0][2] - J[2][2] * J[0][1];
  K[1][1] = J[2][2] * J[0][0] - J[2][0] * J[0][2];
  K[1][2] = J[2][0] * J[0][1] - J[2][1] * J[0][0];
  K[2][0] = J[0][1] * J[1][2] - J[0][2] * J[1][1];
  K[2][1] = J[0][2] * J[1][0] - J[0][0] * J[1][2];
  K[2][2] = J[0][0] * J[1][1] - J[0][1] * J[1][0];
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

/* corner kc of cell c: W⁻¹ of its reference shape (cwinv, per corner), or the common one */
static const double *corner_winv(const ctx *C, const double *cwinv, const double *winv, int c, int kc) {
  return cwinv ? cwinv + ((size_t)c * C->ncorner + kc) * C->d * C->d : winv;
}

/* t^(−1/3) for t > 0: four Newton steps y ← y (4 − t y³)/3 from a guess by the exponent's
 * bits within 3.5%, to a few units in the last place (glibc's cbrt and pow were a sixth of
 * the L-BFGS smoother's time on a perturbed tetrahedral box); cbrt outside 2^±1000 */
static inline double inv_cbrt(double t) {
  if (!(t > 0x1p-1000 && t < 0x1p1000)) return 1 / cbrt(t);
  uint64_t i;
  double y;
  memcpy(&i, &t, sizeof i);
  i = 0x553ef0ff289dd796ULL - i / 3;
  memcpy(&y, &i, sizeof y);
  double t3 = t / 3;
  for (int k = 0; k < 4; k++) y = y * (4.0 / 3 - t3 * (y * y * y));
  return y;
}

/* t^(−2/d) for d = 2, 3 and t > 0 */
static inline double pow_m2d(double t, int d) {
  if (d == 2) return 1 / t;
  double y = inv_cbrt(t);
  return y * y;
}

/* the mean ratio d det(J)^(2/d) / |J|² of corner kc of cell c's map J = E W⁻¹ (0 if invalid) */
static double corner_mean_ratio(const ctx *C, const double *x, int c, int kc, const double *winv) {
  int d = C->d;
  double J[3][3], A = 0;
  const int *v;
  double D = cell_map(C, x, c, kc, winv, J, &v);
  for (int a = 0; a < d; a++)
    for (int b = 0; b < d; b++) A += J[a][b] * J[a][b];
  return D > 0 && A > 0 ? d * (d == 2 ? D : D * inv_cbrt(D)) / A : 0;
}

void ut_relative_mean_ratio(const ctx *C, const double *cwinv, double *out) {
  const mesh *m = C->m;
  for (int c = 0; c < m->ncell; c++) {
    /* a quadrilateral's or hexahedron's: the worst of its corners' */
    double q = INFINITY;
    for (int kc = 0; kc < C->ncorner; kc++)
      q = fmin(q, corner_mean_ratio(C, m->x, c, kc, corner_winv(C, cwinv, NULL, c, kc)));
    out[c] = q;
  }
}

/* corner kc of cell c's ε: the objective's, or the softened barrier's (o->soft_eps); *strict:
 * an invalid corner is infinite (ε = 0, and the softened barrier, which keeps every corner
 * valid) */
static inline double corner_eps(const objective *o, int c, int kc, int *strict) {
  double eps = o->soft_eps ? o->soft_eps[(size_t)c * o->C->ncorner + kc] : o->eps;
  *strict = eps == 0 || o->soft_eps;
  return eps;
}

/* One corner's energy (a simplex has one corner), and with gk its gradient in each of the
 * corner's d + 1 vertices (C->ct[kc] order, d each); +∞ for an invalid corner at ε = 0 */

static inline double corner_energy_d(int d, const objective *o, const double *x, int c, int kc, double *gk) {
  const ctx *C = o->C;
  int strict;
  double theta = o->theta, eps = corner_eps(o, c, kc, &strict);
  double J[3][3] = {{0}}, K[3][3] = {{0}}; /* zeros: d = 2 leaves row and column 2 unused */
  const int *v;
  /* reference shapes per corner (a simplex has one); without them a quadrilateral's or
   * hexahedron's corners aim at a square's or cube's */
  const double *winv = corner_winv(C, o->cwinv, o->winv, c, kc);
  double D = cell_map_d(d, C, x, c, kc, winv, J, &v), A = 0;
#pragma GCC unroll 4
  for (int a = 0; a < d; a++)
#pragma GCC unroll 4
    for (int b = 0; b < d; b++) A += J[a][b] * J[a][b];
  if (strict && !(D > 0)) return INFINITY; /* the barrier (smoothing a valid mesh) */
  double ch = chi(D, eps), chp = dchi(D, eps), cs = pow_m2d(ch, d);
  double f = (1 - theta) * A * cs + theta * (D * D + 1) / ch;
  if (!gk) return f;
  /* ∂f/∂J = (1-θ)(2 J cs - (2/d) A cs/χ χ' K) + θ (2 D χ - (D² + 1) χ')/χ² K */
  cofactor(d, J, K);
  double kd = -(1 - theta) * (2.0 / d) * A * cs / ch * chp + theta * (2 * D * ch - (D * D + 1) * chp) / (ch * ch);
  double G[3][3], GE[3][3];
#pragma GCC unroll 4
  for (int a = 0; a < d; a++)
#pragma GCC unroll 4
    for (int b = 0; b < d; b++) G[a][b] = (1 - theta) * 2 * J[a][b] * cs + kd * K[a][b];
  /* ∂f/∂E = G W⁻ᵀ: column k is the gradient in vertex k + 1, minus their sum vertex 0's */
#pragma GCC unroll 4
  for (int a = 0; a < d; a++)
#pragma GCC unroll 4
    for (int k = 0; k < d; k++) {
      double s2 = 0;
#pragma GCC unroll 4
      for (int l = 0; l < d; l++) s2 += G[a][l] * winv[k * d + l];
      GE[a][k] = s2;
    }
#pragma GCC unroll 4
  for (int a = 0; a < d; a++) {
    double g = 0;
#pragma GCC unroll 4
    for (int l = 0; l < d; l++) {
      g -= GE[a][l];
      gk[(l + 1) * d + a] = GE[a][l];
    }
    gk[a] = g;
  }
  return f;
}

static double corner_energy(const objective *o, const double *x, int c, int kc, double *gk) {
  return o->C->d == 3 ? corner_energy_d(3, o, x, c, kc, gk) : corner_energy_d(2, o, x, c, kc, gk);
}

/* ---------------------------------------------------------------- second derivatives */

/* a symmetric n×n matrix (n ≤ 9, row-major) is positive definite: its Cholesky pivots; L
 * (n×n, lower triangle) its factor when it is */
static int sym_pd(int n, const double *a, double *L) {
  for (int j = 0; j < n; j++) {
    double s = a[j * n + j];
    for (int k = 0; k < j; k++) s -= L[j * n + k] * L[j * n + k];
    if (!(s > 0)) return 0;
    L[j * n + j] = sqrt(s);
    for (int i = j + 1; i < n; i++) {
      double t = a[i * n + j];
      for (int k = 0; k < j; k++) t -= L[i * n + k] * L[j * n + k];
      L[i * n + j] = t / L[j * n + j];
    }
  }
  return 1;
}

/* the eigenvalues w and eigenvectors (the columns of v) of a symmetric n×n matrix a (n ≤ 9,
 * destroyed) */
static void sym_eigen(int n, double *a, double *w, double *v) {
  dense_sym_eigen(n, a, v, 0, 1e-30);
  for (int i = 0; i < n; i++) w[i] = a[i * n + i];
}

/* the modes of a symmetric n×n matrix a (n ≤ 9, destroyed) for its nearest positive
 * semidefinite one Σ_{λ_k > 0} λ_k m_k m_kᵀ: where a is positive definite the columns of its
 * Cholesky factor (λ = 1, no eigensystem), else its eigenvectors and eigenvalues (the negative
 * ones are the ones set to 0) */
static void sym_psd_modes(int n, double *a, double *lam, double m[9][9]) {
  double v[81];
  if (sym_pd(n, a, v))
    for (int k = 0; k < n; k++) {
      lam[k] = 1;
      for (int i = 0; i < n; i++) m[k][i] = i < k ? 0 : v[i * n + k];
    }
  else {
    sym_eigen(n, a, lam, v);
    for (int k = 0; k < n; k++)
      for (int i = 0; i < n; i++) m[k][i] = v[i * n + k];
  }
}

/* 3D: the eigensystem of the Hessian in J of an energy F(A, D), A = |J|², D = det J > 0, in
 * closed form from J's singular value decomposition J = U Σ Vᵀ (Smith, de Goes and Kim, ACM
 * TOG 2019): the twist and flip modes (u_i v_jᵀ ∓ u_j v_iᵀ)/√2 have the eigenvalues
 * 2F_A ± F_D σ_k ({i, j, k} = {1, 2, 3}); the scaling modes Σ c_i u_i v_iᵀ are the
 * eigenvectors c of the 3×3 Hessian in (σ1, σ2, σ3). The nine eigenvalues go to lam, and for
 * each mode M_e its gradient in the corner's vertices 1..3, g[(k − 1) 3 + a][e] = (M_e w_k)_a
 * (w_k row k − 1 of W⁻¹, winv), straight from u and z_ik = v_i · w_k without forming M_e: the
 * projected Hessian is Σ_{λ_e > 0} λ_e g_e g_eᵀ (corner_from_modes). 1 when J is too close
 * to singular for U = J V Σ⁻¹: the caller projects the 9×9 Hessian numerically. */
static int hessian_3d_modes(double J[3][3], double fA, double fD, double fAD, double fDD, const double *winv, double *lam,
                            double g[9][9]) {
  double S[9], V[9], ev[3], sg[3], U[3][3];
  for (int i = 0; i < 3; i++)
    for (int j = 0; j < 3; j++) S[i * 3 + j] = J[0][i] * J[0][j] + J[1][i] * J[1][j] + J[2][i] * J[2][j];
  /* in closed form (two Jacobi eigensystems per corner were a third of the Newton smoother's
   * time on a perturbed box); σ_i = |J v_i|, so that U's columns are unit vectors */
  dense_sym_eigen3(S, ev, V);
  double smax = 0;
  for (int r = 0; r < 3; r++)
    for (int i = 0; i < 3; i++) U[r][i] = J[r][0] * V[0 * 3 + i] + J[r][1] * V[1 * 3 + i] + J[r][2] * V[2 * 3 + i];
  for (int i = 0; i < 3; i++) {
    sg[i] = sqrt(U[0][i] * U[0][i] + U[1][i] * U[1][i] + U[2][i] * U[2][i]);
    smax = fmax(smax, sg[i]);
  }
  for (int i = 0; i < 3; i++)
    if (!(sg[i] > 1e-6 * smax)) return 1;
  for (int r = 0; r < 3; r++)
    for (int i = 0; i < 3; i++) U[r][i] /= sg[i];
  double kk[3] = {sg[1] * sg[2], sg[0] * sg[2], sg[0] * sg[1]}, Hs[9], cs[9];
  for (int i = 0; i < 3; i++)
    for (int j = 0; j < 3; j++)
      Hs[i * 3 + j] = (i == j ? 2 * fA : fD * sg[3 - i - j]) + 2 * fAD * (sg[i] * kk[j] + kk[i] * sg[j]) + fDD * kk[i] * kk[j];
  dense_sym_eigen3(Hs, lam, cs);
  double z[3][3]; /* z[i][k] = v_i · w_{k+1}, w_{k+1} row k of W⁻¹ */
  for (int i = 0; i < 3; i++)
    for (int k = 0; k < 3; k++) z[i][k] = V[0 * 3 + i] * winv[k * 3] + V[1 * 3 + i] * winv[k * 3 + 1] + V[2 * 3 + i] * winv[k * 3 + 2];
  for (int e = 0; e < 3; e++) { /* scaling: Σ_i c_i u_i (v_i · w_k) */
    double y[3][3];
    for (int i = 0; i < 3; i++)
      for (int k = 0; k < 3; k++) y[i][k] = cs[i * 3 + e] * z[i][k];
    for (int k = 0; k < 3; k++)
      for (int a = 0; a < 3; a++) g[k * 3 + a][e] = U[a][0] * y[0][k] + U[a][1] * y[1][k] + U[a][2] * y[2][k];
  }
  int e = 3;
  for (int i = 0; i < 3; i++)
    for (int j = i + 1; j < 3; j++) {
      int k = 3 - i - j;
      for (int sgn = -1; sgn <= 1; sgn += 2, e++) { /* twist (−), flip (+) */
        lam[e] = 2 * fA - sgn * fD * sg[k];
        for (int kk2 = 0; kk2 < 3; kk2++) {
          double zj = z[j][kk2] * M_SQRT1_2, zi = sgn * z[i][kk2] * M_SQRT1_2;
          for (int a = 0; a < 3; a++) g[kk2 * 3 + a][e] = U[a][i] * zj + U[a][j] * zi;
        }
      }
    }
  return 0;
}

/* 2D: the projected Hessian in J = [a b; c e] of an energy F(A, D), A = |J|², D = det J,
 * in closed form. With J = α + β, α = ((a + e)/2, (c − b)/2) its conformal and
 * β = ((a − e)/2, (b + c)/2) its anticonformal part, A = 2(r² + s²) and D = r² − s² for
 * r = |α|, s = |β|: F depends on r and s alone, so its Hessian in (α, β) has the eigenvectors
 * α⊥ and β⊥ (eigenvalues F_r/r = 4F_A + 2F_D and F_s/s = 4F_A − 2F_D) and two in the plane
 * of α̂ and β̂ (the 2×2 Hessian in (r, s)), as in Smith, de Goes and Kim's analytic
 * eigensystems (ACM TOG 2019). Each eigenvector e with eigenvalue λ adds λ/4 (Me)(Me)ᵀ,
 * M = ∂vec J/∂(α, β): the four modes Me go to m (row-major 2×2), the λ/4 to lam. */
static void hessian_2d_modes(double J[3][3], double fA, double fD, double fAD, double fDD, double *lam, double m[9][9]) {
  double a1 = 0.5 * (J[0][0] + J[1][1]), a2 = 0.5 * (J[1][0] - J[0][1]);
  double b1 = 0.5 * (J[0][0] - J[1][1]), b2 = 0.5 * (J[0][1] + J[1][0]);
  double r = sqrt(a1 * a1 + a2 * a2), s = sqrt(b1 * b1 + b2 * b2);
  double ah[2] = {1, 0}, bh[2] = {1, 0}; /* the unit directions (any, where a part is 0) */
  if (r > 0) { ah[0] = a1 / r; ah[1] = a2 / r; }
  if (s > 0) { bh[0] = b1 / s; bh[1] = b2 / s; }
  double frr = 4 * fA + 2 * fD + 16 * r * r * fAD + 4 * r * r * fDD, fss = 4 * fA - 2 * fD - 16 * s * s * fAD + 4 * s * s * fDD,
         frs = -4 * r * s * fDD;
  /* the 2×2 [frr frs; frs fss]: eigenvalues mid ± rad, (cp, sp) the eigenvector of mid + rad */
  double mid = 0.5 * (frr + fss), h = 0.5 * (frr - fss), rad = sqrt(h * h + frs * frs);
  double vx = h >= 0 ? h + rad : frs, vy = h >= 0 ? frs : rad - h, nv = sqrt(vx * vx + vy * vy);
  double cp = nv > 0 ? vx / nv : 1, sp = nv > 0 ? vy / nv : 0;
  double la[4] = {4 * fA + 2 * fD, 4 * fA - 2 * fD, mid + rad, mid - rad};
  double e[4][4] = {{-ah[1], ah[0], 0, 0}, {0, 0, -bh[1], bh[0]},
                    {cp * ah[0], cp * ah[1], sp * bh[0], sp * bh[1]}, {-sp * ah[0], -sp * ah[1], cp * bh[0], cp * bh[1]}};
  for (int k = 0; k < 4; k++) {
    const double *u = e[k];
    m[k][0] = u[0] + u[2];
    m[k][1] = -u[1] + u[3];
    m[k][2] = u[1] + u[3];
    m[k][3] = u[0] - u[2];
    lam[k] = 0.25 * la[k];
  }
}

/* 3D, numerically: the 9×9 Hessian in J of F(A, D),
 *     ∂²F/∂J² = 2 F_A I + 2 F_AD (J⊗K + K⊗J) + F_DD K⊗K + F_D ∂²D/∂J²,  K = ∂D/∂J,
 * as the modes of its nearest positive semidefinite matrix (for an inverted corner, or one
 * too close to singular for the closed form) */
static void hessian_3d_numeric(double J[3][3], double fA, double fD, double fAD, double fDD, double *lam, double m[9][9]) {
  double K[3][3], H[81];
  cofactor(3, J, K);
  for (int a = 0; a < 9; a++)
    for (int b = 0; b < 9; b++) {
      double ja = J[a / 3][a % 3], jb = J[b / 3][b % 3], ka = K[a / 3][a % 3], kb = K[b / 3][b % 3];
      H[a * 9 + b] = (a == b ? 2 * fA : 0) + 2 * fAD * (ja * kb + ka * jb) + fDD * ka * kb;
    }
  for (int a = 0; a < 3; a++) /* ∂K_ab/∂J: K_ab = J_a1b1 J_a2b2 − J_a1b2 J_a2b1 (indices + 1, + 2 mod 3) */
    for (int b = 0; b < 3; b++) {
      int a1 = (a + 1) % 3, a2 = (a + 2) % 3, b1 = (b + 1) % 3, b2 = (b + 2) % 3, row = (a * 3 + b) * 9;
      H[row + a1 * 3 + b1] += fD * J[a2][b2];
      H[row + a2 * 3 + b2] += fD * J[a1][b1];
      H[row + a1 * 3 + b2] -= fD * J[a2][b1];
      H[row + a2 * 3 + b1] -= fD * J[a1][b2];
    }
  sym_psd_modes(9, H, lam, m);
}

/* the gradients in the corner's vertices 1..d of the modes M_e of its Hessian in J (m,
 * row-major d×d): g[(k − 1) d + a][e] = Σ_b M_e[a][b] w_k[b], w_k row k − 1 of W⁻¹ (the 2D
 * closed form and the numeric 3D fallback; the 3D closed form writes g itself) */
static inline void modes_g(int d, int nm, double m[9][9], const double *winv, double g[9][9]) {
  for (int e = 0; e < nm; e++) {
    for (int k = 1; k <= d; k++)
      for (int a = 0; a < d; a++) {
        double t = 0;
        for (int b = 0; b < d; b++) t += m[e][a * d + b] * winv[(k - 1) * d + b];
        g[(k - 1) * d + a][e] = t;
      }
  }
}

/* a corner's Hessian in its d + 1 vertices (hk, (d+1)d square) from its modes' eigenvalues
 * and gradients in vertices 1..d (g, one row per coordinate, one column per mode):
 * Σ_{λ_e > 0} λ_e g_e g_eᵀ there (d² square), entry by entry as a sum over the modes (the
 * modes' rank-one updates one by one took twice the instructions), and vertex 0's rows and
 * columns from w_0 = −Σ_k w_k: its gradient is minus the sum of the others', so its blocks are
 * minus the sums of theirs (half the products of summing over all d + 1 vertices); called with
 * a constant d, whose loops the compiler unrolls (the upper triangle as a square loop that
 * skips c < r: a loop from r was not unrolled and kept g and gl in memory; 1 030 → 925
 * instructions per triangle, 7% fewer per tetrahedron) */
static inline void corner_from_modes(int d, int nm, const double *lam, double g[9][9], double *hk) {
  int n = d * d, nx = n + d;
  double lp[9], gl[9][9];
  for (int e = 0; e < nm; e++) lp[e] = lam[e] > 0 ? lam[e] : 0;
  for (int r = 0; r < n; r++)
#pragma GCC unroll 9
    for (int e = 0; e < nm; e++) gl[r][e] = lp[e] * g[r][e];
#pragma GCC unroll 9
  for (int r = 0; r < n; r++) /* vertices 1..d */
#pragma GCC unroll 9
    for (int c = 0; c < n; c++) {
      if (c < r) continue;
      double t = 0;
#pragma GCC unroll 9
      for (int e = 0; e < nm; e++) t += gl[r][e] * g[c][e];
      hk[(r + d) * nx + c + d] = hk[(c + d) * nx + r + d] = t;
    }
  for (int a = 0; a < d; a++) /* vertex 0 against vertices 1..d */
    for (int c = 0; c < n; c++) {
      double t = 0;
#pragma GCC unroll 3
      for (int k = 0; k < d; k++) t -= hk[(k * d + a + d) * nx + c + d];
      hk[a * nx + c + d] = hk[(c + d) * nx + a] = t;
    }
  for (int a = 0; a < d; a++) /* vertex 0 against itself */
    for (int b = a; b < d; b++) {
      double t = 0;
#pragma GCC unroll 3
      for (int l = 0; l < d; l++) t -= hk[a * nx + l * d + b + d];
      hk[a * nx + b] = hk[b * nx + a] = t;
    }
}

/* One corner's Hessian in its d + 1 vertices, hk ((d+1)d square, row (k d + a) for
 * coordinate a of the corner's vertex k, C->ct[kc] order), projected to be positive
 * semidefinite: the Hessian in J (d² square) with its negative eigenvalues set to 0, then
 * mapped through the linear J(x) ("projected Newton", Teran et al., SCA 2005). The energy
 * f = (1 − θ) A s(D) + θ t(D), A = |J|², D = det J, s = χ^(−2/d), t = (D² + 1)/χ, is a
 * function F(A, D): its derivatives F_A, F_D, F_AD, F_DD (F_AA = 0) are all the eigensystems
 * above need. 1 for a corner where the energy is infinite (ε = 0 and det J ≤ 0). */
static int corner_hessian(const objective *o, const double *x, int i, int kc, double *hk) {
  const ctx *C = o->C;
  int d = C->d, c = o->cells[i];
  int strict;
  double theta = o->theta, eps = corner_eps(o, c, kc, &strict);
  double J[3][3];
  const int *v;
  const double *winv = corner_winv(C, o->cwinv, o->winv, c, kc);
  double D = cell_map(C, x, c, kc, winv, J, &v), A = 0;
  for (int a = 0; a < d; a++)
    for (int b = 0; b < d; b++) A += J[a][b] * J[a][b];
  if (strict && !(D > 0)) return 1;
  /* χ and its derivatives in D; s, t and theirs */
  double r = sqrt(eps * eps + D * D), ch = 0.5 * (D + r), c1 = 0.5 * (1 + D / r), c2 = 0.5 * eps * eps / (r * r * r);
  double p = 2.0 / d, s = pow_m2d(ch, d), s1 = -p * s / ch * c1, s2 = p * (p + 1) * s / (ch * ch) * c1 * c1 - p * s / ch * c2;
  double N = D * D + 1, t1 = 2 * D / ch - N * c1 / (ch * ch),
         t2 = 2 / ch - 4 * D * c1 / (ch * ch) - N * c2 / (ch * ch) + 2 * N * c1 * c1 / (ch * ch * ch);
  double fA = (1 - theta) * s, fD = (1 - theta) * A * s1 + theta * t1, fAD = (1 - theta) * s1,
         fDD = (1 - theta) * A * s2 + theta * t2;
  /* ∂J_ab/∂x_kc = δ_ac w_k[b]: w_k row k − 1 of W⁻¹ for k ≥ 1, w_0 minus their sum (vertex 0
   * is derived in corner_from_modes) */
  /* the modes of the projected Hessian in J, mapped one by one to the corner's vertices: half
   * the operations of forming the d²×d² Hessian and mapping it (the twisted bar's Newton
   * steps spent a quarter of their time there: add_mode 7%, corner_hessian 16%) */
  double lam[9], m[9][9], g[9][9];
  if (d == 2) {
    hessian_2d_modes(J, fA, fD, fAD, fDD, lam, m);
    modes_g(2, 4, m, winv, g);
    corner_from_modes(2, 4, lam, g, hk);
  } else {
    if (!(D > 0) || hessian_3d_modes(J, fA, fD, fAD, fDD, winv, lam, g)) {
      hessian_3d_numeric(J, fA, fD, fAD, fDD, lam, m);
      modes_g(3, 9, m, winv, g);
    }
    corner_from_modes(3, 9, lam, g, hk);
  }
  return 0;
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
  free(b->hc);
  free(b->fc);
  free(b->gc);
  free(b->off);
  free(b->slot);
  free(b->touch_off);
  free(b->touch);
  free(b->bpos);
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
        b->fc[q] = corner_energy(o, x, o->cells[i], kc, grad ? b->gc + q * (size_t)(d + 1) * d : NULL);
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
      double e = corner_energy(o, x, o->cells[i], kc, grad ? gk : NULL);
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

double ut_energy_vertex(const objective *o, const double *x, int v, double *gv) {
  const ctx *C = o->C;
  int d = C->d;
  double f = 0, gk[12];
  for (int a = 0; a < d; a++) gv[a] = 0;
  for (int p = C->vc_off[v]; p < C->vc_off[v + 1]; p++) {
    int c = C->vc[p];
    const int *cell = cell_of(C, c);
    for (int kc = 0; kc < C->ncorner; kc++) {
      double e = corner_energy(o, x, c, kc, gk);
      if (isinf(e)) return INFINITY;
      f += e;
      for (int k = 0; k <= d; k++)
        if (cell[C->ct[kc][k]] == v)
          for (int a = 0; a < d; a++) gv[a] += gk[k * d + a];
    }
  }
  return f;
}

void ut_energy_soft_eps(const objective *o, const double *x, double c, double *soft_eps) {
  const ctx *C = o->C;
  int d = C->d, nk = C->ncorner, n = o->ncell;
#ifdef _OPENMP
#pragma omp parallel for schedule(static) if (n > 2048)
#endif
  for (int i = 0; i < n; i++)
    for (int kc = 0; kc < nk; kc++) {
      int cell = o->cells[i];
      double J[3][3], A = 0;
      const int *v;
      cell_map(C, x, cell, kc, corner_winv(C, o->cwinv, o->winv, cell, kc), J, &v);
      for (int a = 0; a < d; a++)
        for (int b = 0; b < d; b++) A += J[a][b] * J[a][b];
      soft_eps[(size_t)cell * nk + kc] = pow(c * A / d, 0.5 * d); /* D of mean ratio c: q = d D^(2/d) / |J|² */
    }
}

double ut_energy_qmin(const objective *o, const double *x) {
  const ctx *C = o->C;
  int nk = C->ncorner, n = o->ncell;
  double qmin = INFINITY;
#ifdef _OPENMP
#pragma omp parallel for schedule(static) reduction(min : qmin) if (n > 2048)
#endif
  for (int i = 0; i < n; i++)
    for (int kc = 0; kc < nk; kc++) {
      int c = o->cells[i];
      double q = corner_mean_ratio(C, x, c, kc, corner_winv(C, o->cwinv, o->winv, c, kc));
      if (q < qmin) qmin = q;
    }
  return qmin;
}

/* the corner Hessians are computed in chunks of cells whose Hessians fit this buffer (a
 * hexahedron's eight corners take 9 KB, a tetrahedron's one 1.1 KB): one core's L2 cache,
 * so that the gather that follows each chunk reads it from the cache. With 64 MB chunks
 * the gather's reads missed: the 590 000-tetrahedron bar's Hessian took 1.0–1.1 s per
 * Newton step, 0.6–0.7 s with 2 MB (512 KB to 8 MB within the noise of each other) */
#define HESS_CHUNK_BYTES ((size_t)2 << 20)

/* b->touch: for each chunk of `chunk` cells, the free vertices that have slots in it, in
 * ascending order (a vertex's slots ascend, so its chunks come in order): the gather after
 * a chunk visits those only (with small chunks, a pass over every free vertex per chunk
 * would cost more than the chunk) */
static int chunk_touch(ut_energy_buf *b, int nfree, int n, int chunk, int slots_per_cell) {
  int nch = (n + chunk - 1) / chunk;
  if (!(b->touch_off = calloc((size_t)nch + 2, sizeof(int)))) return 1;
  for (int pass = 0; pass < 2; pass++) {
    for (int fi = 0; fi < nfree; fi++) {
      int last = -1;
      for (int q = b->off[fi]; q < b->off[fi + 1]; q++) {
        int ch = b->slot[q] / slots_per_cell / chunk;
        if (ch == last) continue;
        last = ch;
        if (pass) b->touch[b->touch_off[ch + 1]++] = fi;
        else b->touch_off[ch + 2]++;
      }
    }
    if (!pass) {
      for (int ch = 0; ch < nch; ch++) b->touch_off[ch + 2] += b->touch_off[ch + 1];
      if (!(b->touch = malloc(sizeof(int) * ((size_t)b->touch_off[nch + 1] + 1)))) {
        free(b->touch_off);
        b->touch_off = NULL;
        return 1;
      }
    }
  }
  return 0;
}

/* the block positions' memory limit (b->bpos: (d + 1) per slot, 64 bytes per tetrahedron, a
 * hexahedron's 512); above it each term finds its block in the row */
#define BLOCKPOS_MAX ((size_t)256 << 20)
/* the longest row the Hessian's gather sums on the stack (blocks; a vertex's neighbours and
 * itself: 7 in a regular triangle grid, 15 in a tetrahedral box, 27 in a hexahedral one) */
#define ROW_BUF_BLOCKS 64

/* the blocks of row fk (a free vertex of corner kc of cell vertices v) against the corner's
 * vertices, in its row of P; −1 for a fixed vertex */
static void row_positions(const objective *o, const ut_bsr *P, const int *v, int kc, int fk, int *bp) {
  const ctx *C = o->C;
  for (int m = 0; m <= C->d; m++) {
    int fm = o->fidx[v[C->ct[kc][m]]];
    bp[m] = fm < 0 ? -1 : (int)ut_bsr_find(P, fk, fm);
  }
}

/* b->bpos for pattern P: the gather's search of each term's block in its row (a binary search
 * per block, mispredicted) cost more instructions than the corner Hessians themselves (a
 * 200 000-triangle spiral's smoothing: 3.6 G against 3.4 G) */
static void block_positions(ut_energy_buf *b, const objective *o, const ut_bsr *P, int nfree) {
  const ctx *C = o->C;
  int d = C->d, nk = C->ncorner;
  size_t ns = (size_t)b->off[nfree];
  if ((size_t)P->off[nfree] > (size_t)INT_MAX || sizeof(int) * ns * (size_t)(d + 1) > BLOCKPOS_MAX ||
      !(b->bpos = malloc(sizeof(int) * (ns * (size_t)(d + 1) + 1))))
    return;
#ifdef _OPENMP
#pragma omp parallel for schedule(static) if (nfree > 2048)
#endif
  for (int fi = 0; fi < nfree; fi++)
    for (int q = b->off[fi]; q < b->off[fi + 1]; q++) {
      size_t cq = (size_t)b->slot[q] / (size_t)(d + 1);
      int i = (int)(cq / (size_t)nk), kc = (int)(cq % (size_t)nk);
      row_positions(o, P, cell_of(C, o->cells[i]), kc, fi, b->bpos + (size_t)q * (d + 1));
    }
}

void ut_energy_release_blocks(ut_energy_buf *b) {
  if (!b) return;
  free(b->bpos);
  b->bpos = NULL;
}

/* add_row_blocks with the blocks' positions bp (b->bpos of the slot) less base, for a
 * constant d */
static inline void add_row_blocks_at(int d, double *val, const int *bp, int base, int k, const double *h) {
  int nx = (d + 1) * d, dd = d * d;
#pragma GCC unroll 4
  for (int m = 0; m <= d; m++) {
    if (bp[m] < 0) continue;
    double *blk = val + (size_t)(bp[m] - base) * dd;
#pragma GCC unroll 3
    for (int a = 0; a < d; a++)
#pragma GCC unroll 3
      for (int e = 0; e < d; e++) blk[a * d + e] += h[(k * d + a) * nx + m * d + e];
  }
}

/* row fk (the free vertex at corner kc's vertex k of cell vertices v) of the corner Hessian
 * h added into its blocks, found in the row (without b->bpos) */
static void add_row_blocks(const objective *o, const ut_bsr *P, double *val, const int *v, int kc, int k, int fk,
                           const double *h) {
  const ctx *C = o->C;
  int bp[4];
  row_positions(o, P, v, kc, fk, bp);
  if (C->d == 2) add_row_blocks_at(2, val, bp, 0, k, h);
  else add_row_blocks_at(3, val, bp, 0, k, h);
}

/* The projected Hessian of the energy in the free vertices' coordinates, d×d blocks on
 * pattern P. The cells go in chunks (HESS_CHUNK_BYTES): the chunk's corner Hessians are
 * computed on threads, then each free vertex with slots in the chunk (b->touch) gathers them
 * into its row (a cursor per row: the slots are in (cell, corner, vertex) order), so every
 * block receives its terms in the order of the one-thread loop below and the result does
 * not depend on the number of threads. Before the chunks, a million-tetrahedron bar's
 * Hessians (1.3 GB) did not fit a whole-mesh buffer and were assembled on one thread: 2 s
 * of each 2.2 s Newton step. 1 where the energy is infinite. */
static int hessian_assemble(const objective *o, const double *x, const ut_bsr *P, double *val, int nfree) {
  const ctx *C = o->C;
  int d = C->d, nk = C->ncorner, n = o->ncell, nx = (d + 1) * d, dd = d * d;
  size_t hs = (size_t)nx * nx, per_cell = sizeof(double) * hs * (size_t)nk;
  int chunk = HESS_CHUNK_BYTES / per_cell < (size_t)n ? (int)(HESS_CHUNK_BYTES / per_cell) : n;
  ut_energy_buf *b = o->eb;
  int *cur = NULL;
  if (b && chunk > 0 && !energy_prepare(o, nfree) && (b->hc || (b->hc = malloc(per_cell * (size_t)chunk + 1))) &&
      (b->touch || !chunk_touch(b, nfree, n, chunk, nk * (d + 1))) && (cur = malloc(sizeof(int) * ((size_t)nfree + 1)))) {
    int bad = 0;
    if (!b->bpos) block_positions(b, o, P, nfree);
    const int *bpos = b->bpos;
    memcpy(cur, b->off, sizeof(int) * (size_t)nfree);
    /* no zeroing of the whole matrix first (on one thread: a quarter of the million-triangle
     * spiral's Hessians): a row whose slots all lie in one chunk (nearly all) is summed in
     * a local buffer and stored once, another is zeroed where its first slot comes, on its
     * thread; a row without slots (a free vertex in no cell) here */
    for (int fi = 0; fi < nfree; fi++)
      if (b->off[fi] == b->off[fi + 1]) memset(val + (size_t)P->off[fi] * dd, 0, sizeof(double) * (size_t)(P->off[fi + 1] - P->off[fi]) * dd);
    for (int c0 = 0; c0 < n && !bad; c0 += chunk) {
      int c1 = n - c0 > chunk ? c0 + chunk : n, ch = c0 / chunk, t0 = b->touch_off[ch], t1 = b->touch_off[ch + 1];
      size_t send = (size_t)c1 * nk * (size_t)(d + 1); /* the first slot past the chunk */
#ifdef _OPENMP
#pragma omp parallel for schedule(static) reduction(|| : bad) if (n > 1024)
#endif
      for (int i = c0; i < c1; i++)
        for (int kc = 0; kc < nk; kc++) bad = corner_hessian(o, x, i, kc, b->hc + ((size_t)(i - c0) * nk + kc) * hs) || bad;
      if (bad) break;
#ifdef _OPENMP
#pragma omp parallel for schedule(static) if (n > 1024)
#endif
      for (int t = t0; t < t1; t++) {
        int fi = b->touch[t], q = cur[fi], r0 = P->off[fi], nbr = P->off[fi + 1] - r0;
        size_t rbytes = sizeof(double) * (size_t)nbr * dd;
        double acc[ROW_BUF_BLOCKS * 9];
        /* the whole row in this chunk: in acc, with the same additions in the same order */
        int local = bpos && q == b->off[fi] && nbr <= ROW_BUF_BLOCKS && (size_t)b->slot[b->off[fi + 1] - 1] < send;
        double *dst = local ? acc : val;
        int base = local ? r0 : 0;
        if (q == b->off[fi]) memset(local ? acc : val + (size_t)r0 * dd, 0, rbytes);
        for (; q < b->off[fi + 1] && (size_t)b->slot[q] < send; q++) {
          size_t sl = (size_t)b->slot[q], cq = sl / (size_t)(d + 1);
          int k = (int)(sl % (size_t)(d + 1)), i = (int)(cq / (size_t)nk), kc = (int)(cq % (size_t)nk);
          const double *h = b->hc + (cq - (size_t)c0 * nk) * hs;
          if (!bpos) add_row_blocks(o, P, val, cell_of(C, o->cells[i]), kc, k, fi, h);
          else if (d == 2) add_row_blocks_at(2, dst, bpos + (size_t)q * 3, base, k, h);
          else add_row_blocks_at(3, dst, bpos + (size_t)q * 4, base, k, h);
        }
        if (local) memcpy(val + (size_t)r0 * dd, acc, rbytes);
        cur[fi] = q;
      }
    }
    free(cur);
    return bad;
  }
  memset(val, 0, sizeof(double) * (size_t)P->off[nfree] * dd);
  double h[144];
  for (int i = 0; i < n; i++) {
    const int *v = cell_of(C, o->cells[i]);
    for (int kc = 0; kc < nk; kc++) {
      if (corner_hessian(o, x, i, kc, h)) return 1;
      for (int k = 0; k <= d; k++) {
        int fk = o->fidx[v[C->ct[kc][k]]];
        if (fk >= 0) add_row_blocks(o, P, val, v, kc, k, fk, h);
      }
    }
  }
  return 0;
}

/* P = Σ t tᵀ over v's slide directions */
static void slide_projector(const ctx *C, int v, double *Pm) {
  int d = C->d;
  const double *t = ut_tangents(C, v);
  for (int a = 0; a < d * d; a++) Pm[a] = 0;
  for (int k = 0; k < C->ntan[v]; k++)
    for (int a = 0; a < d; a++)
      for (int b = 0; b < d; b++) Pm[a * d + b] += t[k * d + a] * t[k * d + b];
}

/* a = l a r for d×d matrices (l, r NULL: the identity) */
static void mat_sandwich(int d, const double *l, double *a, const double *r) {
  double t[9];
  for (int i = 0; i < d; i++)
    for (int j = 0; j < d; j++) {
      double s = 0;
      for (int k = 0; k < d; k++) s += (l ? l[i * d + k] : (i == k)) * a[k * d + j];
      t[i * d + j] = s;
    }
  for (int i = 0; i < d; i++)
    for (int j = 0; j < d; j++) {
      double s = 0;
      for (int k = 0; k < d; k++) s += t[i * d + k] * (r ? r[k * d + j] : (k == j));
      a[i * d + j] = s;
    }
}

/* sliding vertices (o->slide): their rows and columns in their tangent directions, P H P with
 * P a vertex's projector (the identity off the boundary), and c (I − P) added to their
 * diagonal blocks, c the block's mean diagonal: the normal directions decouple, so a solve
 * whose right side is tangent (the projected gradient) has no normal component. Each row
 * changes its own blocks (threads, the same bits) */
static void hessian_slide(const objective *o, const ut_bsr *P, double *val, int nfree) {
  const ctx *C = o->C;
  int d = C->d, dd = d * d;
#ifdef _OPENMP
#pragma omp parallel for schedule(static) if (nfree > 2048)
#endif
  for (int fi = 0; fi < nfree; fi++) {
    int u = o->freev[fi], su = C->bnd[u];
    double Pu[9], Pw[9];
    if (su) slide_projector(C, u, Pu);
    for (int q = P->off[fi]; q < P->off[fi + 1]; q++) {
      int w = o->freev[P->col[q]], sw = C->bnd[w];
      if (!su && !sw) continue;
      double *blk = val + (size_t)q * dd;
      if (P->col[q] == fi) {
        double c = 0;
        for (int a = 0; a < d; a++) c += blk[a * d + a] / d;
        mat_sandwich(d, Pu, blk, Pu);
        for (int a = 0; a < dd; a++) blk[a] += c * ((a % (d + 1) == 0) - Pu[a]);
      } else {
        if (sw) slide_projector(C, w, Pw);
        mat_sandwich(d, su ? Pu : NULL, blk, sw ? Pw : NULL);
      }
    }
  }
}

int ut_energy_hessian(const objective *o, const double *x, const ut_bsr *P, double *val, int nfree) {
  if (hessian_assemble(o, x, P, val, nfree)) return 1;
  if (o->slide) hessian_slide(o, P, val, nfree);
  return 0;
}

/* the L-BFGS iterations after which a 3D round towards reference shapes takes Newton (below) */
#define REF_LBFGS_CAP 300

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
  /* Newton's conjugate gradients on aggregation multigrid, except in the escape run, whose
   * Tutte disk's cells are as thin as the strip's (a 640 x 160 Tutte-started spiral's global
   * energy: 9 Newton steps and 1.5 s with it, 14 and 2.6 s with block Jacobi) */
  o.no_multigrid = C->escape;
  if (mean > 0 && nfree) {
    if (simplex) ut_regular_winv(d, mean, o.winv);
    else {
      double h = d == 2 ? sqrt(mean) : cbrt(mean);
      memset(o.winv, 0, sizeof o.winv);
      for (int i = 0; i < d; i++) o.winv[i * d + i] = 1 / h;
    }
    int valid_rounds = 0, best_inv = INT_MAX, since_best = 0, newton3 = 0;
    for (int outer = 0; outer < 100; outer++) {
      double dmin = INFINITY, J[3][3];
      const int *v;
      for (int i = 0; i < ncell; i++)
        for (int kc = 0; kc < C->ncorner; kc++) {
          int c = W->cells[i];
          dmin = fmin(dmin, cell_map(C, x, c, kc, corner_winv(C, cwinv, o.winv, c, kc), J, &v));
        }
      int ninv;
      ut_count_cells(C, x, 0, &ninv, NULL);
      /* no new fewest invalid cells for GLOBAL_PATIENCE rounds: a mesh with no valid embedding
       * (a fuzzed one spent 100 rounds of 1000 iterations here); repairable tangles improved
       * at every round (the spirals: 2-5 rounds, at most 3 at the same count before valid) */
      if (ninv < best_inv) { best_inv = ninv; since_best = 0; }
      else if (++since_best >= GLOBAL_PATIENCE) break;
      /* valid: done, or with reference shapes one more minimization at the small ε that
       * validity gives, towards those shapes (the point of giving them); not when they are
       * only a way out (C->escape: the Tutte disk's shapes are not wanted ones) */
      if (!ninv && outer > 0 && (!cwinv || C->escape || valid_rounds++)) break;
      o.eps = sqrt(1e-8 + 0.04 * pow(fmin(dmin, 0), 2));
      /* while cells are invalid, a round of the ε schedule ends when a step gains less than
       * 1e-4 of the energy (was 1e-9): the next round re-solves at a smaller ε anyway, as
       * foldover-free maps' inner solves stop at a 1e-4 gradient (spirals untangle 1.2-5x
       * faster, every hard case still valid, bench/RESULTS.md). With reference shapes every
       * round converges fully (0: 1e-9), or the valid state reached early leaves the last
       * round, towards those shapes, short of them (a quadrilateral spiral: 0.97 against 0.99).
       * The escape run minimizes by projected Newton (at most a tenth as many steps as L-BFGS
       * iterations) and stops its rounds at the 1e-4 gain: its L-BFGS rounds had hit the
       * 1 000-iteration cap at every round on the Tutte-started strips (40 000 triangles: 15
       * rounds, 15 040 iterations, 39 s; 160 000: failed), and stopping them at 1e-4 had failed
       * even the smaller; Newton's rounds take 15–40 steps, and both are repaired (11 s, 75 s
       * in all, bench/RESULTS.md). In 2D every run does too: with reference shapes the fully
       * converged rounds took L-BFGS 4.5 s on the 48 000-triangle spiral, Newton 0.58 s (0.45
       * -> 0.085 s on a quadrilateral spiral, 0.43 -> 0.043 s on a random star), to the same or
       * a higher mean; with regular shapes L-BFGS took 1 530 iterations and 17.6 s on a
       * 205 000-triangle Tutte-started spiral, Newton 9 steps, and it repairs the anisotropic
       * 12 x 30 strip that L-BFGS left 142 cells inverted. On tetrahedra the 12×12 corner
       * Hessians cost more than they save (twisted bar 16: 0.61 s by L-BFGS, 1.6 s by Newton) */
      o.ftol = ninv && (!cwinv || C->escape) ? 1e-4 : 0;
      double f;
      /* in 3D with reference shapes, a round's L-BFGS run that reaches REF_LBFGS_CAP
       * iterations hands over to Newton, for that round's rest and the rounds after: the LIM
       * armadillo's rest shapes (minimum mean ratio 0.08) took L-BFGS 820, 224 and 350
       * iterations in its fully converged rounds; with the handover its untangle took
       * 2.1 -> 1.4 s, the same mean relative quality 0.8030. The twisted bars' rounds towards
       * their rest shapes stay below it up to bar 24 (220 iterations); bar 32's (516) hands
       * over, 30.9 -> 27.4 s, minimum 0.3580 -> 0.3578 (bench/RESULTS.md) */
      int cap = C->d == 3 && cwinv && !C->escape && !newton3 ? REF_LBFGS_CAP : maxit;
      int it = C->d == 2 || newton3 ? ut_newton(&o, x, freev, nfree, maxit / 10, &f) : ut_lbfgs(&o, x, freev, nfree, cap, &f);
      if (it == cap && cap < maxit) {
        newton3 = 1;
        int more = ut_newton(&o, x, freev, nfree, maxit / 10, &f);
        if (more > 0) it += more;
      }
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
