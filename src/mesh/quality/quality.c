/* quality.c — cell quality measures. Equation numbers refer to the seed paper "On simplex
 * shape measures with extension for anisotropic meshes" (Definition 2.1: 1 for the regular
 * simplex, 0 for every degenerate one; invariant under translation, rotation, reflection
 * and uniform scaling) and its Appendices B and C. Riemannian versions (2.10–2.12) map
 * the cell by N with N^T N = M (the Cholesky factor of the averaged metric), so lengths,
 * areas and volumes are the metric ones and every measure follows. The Verdict library's
 * metrics (for tables comparable with VTK's vtkMeshQuality) are in quality_verdict.c. */
#include "quality_int.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char *names[QM_COUNT] = {
    "mean_ratio", "radius_ratio", "condition", "frobenius_condition", "interpolation_coefficient",
    "min_solid_angle", "sigma_min", "min_dihedral_angle", "edge_ratio", "signed_measure",
    "min_angle", "max_angle", "min_edge", "max_edge", "min_corner_jacobian", "scaled_jacobian",
    "corner_condition", "stretching", "skewness", "zeta", "iota", "q", "kappa2_mean", "kappa2_max",
    "deformation_min_sv", "deformation_max_sv", "deformation_quality",
    "verdict.area", "verdict.aspect_frobenius", "verdict.aspect_ratio", "verdict.condition",
    "verdict.distortion", "verdict.edge_ratio", "verdict.max_angle", "verdict.min_angle",
    "verdict.radius_ratio", "verdict.scaled_jacobian", "verdict.shape", "verdict.aspect_beta",
    "verdict.aspect_gamma", "verdict.collapse_ratio", "verdict.jacobian", "verdict.volume",
    "verdict.max_aspect_frobenius", "verdict.max_edge_ratios", "verdict.med_aspect_frobenius", "verdict.oddy",
    "verdict.shear", "verdict.skew", "verdict.stretch", "verdict.taper", "verdict.warpage", "verdict.diagonal",
    "verdict.dimension"};

/* which cell types VTK 9.1's vtkMeshQuality offers each Verdict metric on */
#define T_ (1 << CELL_TRIANGLE)
#define Q_ (1 << CELL_QUADRILATERAL)
#define S_ (1 << CELL_TETRAHEDRON)
#define H_ (1 << CELL_HEXAHEDRON)
static const unsigned char verdict_types[QM_COUNT - QM_V_AREA] = {
    [QM_V_AREA - QM_V_AREA] = T_ | Q_,
    [QM_V_ASPECT_FROBENIUS - QM_V_AREA] = T_ | S_,
    [QM_V_ASPECT_RATIO - QM_V_AREA] = T_ | Q_ | S_,
    [QM_V_CONDITION - QM_V_AREA] = T_ | Q_ | S_ | H_,
    [QM_V_DISTORTION - QM_V_AREA] = T_ | Q_ | S_ | H_,
    [QM_V_EDGE_RATIO - QM_V_AREA] = T_ | Q_ | S_ | H_,
    [QM_V_MAX_ANGLE - QM_V_AREA] = T_ | Q_,
    [QM_V_MIN_ANGLE - QM_V_AREA] = T_ | Q_ | S_,
    [QM_V_RADIUS_RATIO - QM_V_AREA] = T_ | Q_ | S_,
    [QM_V_SCALED_JACOBIAN - QM_V_AREA] = T_ | Q_ | S_ | H_,
    [QM_V_SHAPE - QM_V_AREA] = T_ | Q_ | S_ | H_,
    [QM_V_ASPECT_BETA - QM_V_AREA] = S_,
    [QM_V_ASPECT_GAMMA - QM_V_AREA] = S_,
    [QM_V_COLLAPSE_RATIO - QM_V_AREA] = S_,
    [QM_V_JACOBIAN - QM_V_AREA] = Q_ | S_ | H_,
    [QM_V_VOLUME - QM_V_AREA] = S_ | H_,
    [QM_V_MAX_ASPECT_FROBENIUS - QM_V_AREA] = Q_ | H_,
    [QM_V_MAX_EDGE_RATIOS - QM_V_AREA] = Q_ | H_,
    [QM_V_MED_ASPECT_FROBENIUS - QM_V_AREA] = Q_ | H_,
    [QM_V_ODDY - QM_V_AREA] = Q_ | H_,
    [QM_V_SHEAR - QM_V_AREA] = Q_ | H_,
    [QM_V_SKEW - QM_V_AREA] = Q_ | H_,
    [QM_V_STRETCH - QM_V_AREA] = Q_ | H_,
    [QM_V_TAPER - QM_V_AREA] = Q_ | H_,
    [QM_V_WARPAGE - QM_V_AREA] = Q_,
    [QM_V_DIAGONAL - QM_V_AREA] = H_,
    [QM_V_DIMENSION - QM_V_AREA] = H_,
};

int quality_is_deformation(int q) { return q >= QM_DEFORMATION_MIN_SV && q <= QM_DEFORMATION_QUALITY; }

int quality_from_name(const char *name) {
  for (int i = 0; i < QM_COUNT; i++)
    if (!strcmp(names[i], name)) return i;
  return -1;
}
const char *quality_name(int q) { return q >= 0 && q < QM_COUNT ? names[q] : "?"; }

void quality_names(char *buf, size_t len) {
  size_t used = 0;
  buf[0] = 0;
  for (int i = 0; i < QM_COUNT && used < len; i++)
    used += (size_t)snprintf(buf + used, len - used, "%s%s", i ? ", " : "", names[i]);
}

int quality_applies(int q, cell_type t) {
  if (t == CELL_INTERVAL) return 0; /* the shape measures are of 2D and 3D cells */
  int simplex = t == CELL_TRIANGLE || t == CELL_TETRAHEDRON;
  switch (q) {
  case QM_MIN_DIHEDRAL_ANGLE: return t == CELL_TETRAHEDRON;
  case QM_EDGE_RATIO: return 1; /* hmin / hmax over all edges of every cell type */
  case QM_MIN_ANGLE: case QM_MAX_ANGLE: return t != CELL_HEXAHEDRON;
  case QM_STRETCHING: case QM_SKEWNESS: case QM_ZETA: case QM_IOTA: case QM_Q: case QM_KAPPA2_MEAN:
  case QM_KAPPA2_MAX:
    return t == CELL_QUADRILATERAL;
  case QM_SIGNED_MEASURE: case QM_MIN_EDGE: case QM_MAX_EDGE: case QM_MIN_CORNER_JACOBIAN:
  case QM_SCALED_JACOBIAN: case QM_CORNER_CONDITION: case QM_DEFORMATION_MIN_SV: case QM_DEFORMATION_MAX_SV:
  case QM_DEFORMATION_QUALITY:
    return 1;
  default:
    if (q >= QM_V_AREA && q < QM_COUNT) return (verdict_types[q - QM_V_AREA] >> t) & 1;
    return simplex;
  }
}

/* ---------------------------------------------------------------- small linear algebra */

/* eigenvalues of a symmetric 3×3 matrix, ascending, by cyclic Jacobi rotations: accurate to
 * round-off also for repeated eigenvalues, where the closed (trigonometric) form loses half
 * the digits */
static void eig_sym3(const double A[3][3], double *l) {
  double a[3][3];
  memcpy(a, A, sizeof a);
  for (int sweep = 0; sweep < 50; sweep++) {
    double off = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
    double diag = a[0][0] * a[0][0] + a[1][1] * a[1][1] + a[2][2] * a[2][2];
    if (off <= 1e-32 * diag || off == 0) break;
    for (int p = 0; p < 2; p++)
      for (int q = p + 1; q < 3; q++) {
        if (a[p][q] == 0) continue;
        double theta = (a[q][q] - a[p][p]) / (2 * a[p][q]);
        double t = (theta >= 0 ? 1 : -1) / (fabs(theta) + sqrt(theta * theta + 1));
        double c = 1 / sqrt(t * t + 1), sn = t * c;
        for (int k = 0; k < 3; k++) {
          double akp = a[k][p], akq = a[k][q];
          a[k][p] = c * akp - sn * akq;
          a[k][q] = sn * akp + c * akq;
        }
        for (int k = 0; k < 3; k++) {
          double apk = a[p][k], aqk = a[q][k];
          a[p][k] = c * apk - sn * aqk;
          a[q][k] = sn * apk + c * aqk;
        }
      }
  }
  l[0] = a[0][0];
  l[1] = a[1][1];
  l[2] = a[2][2];
  for (int i = 1; i < 3; i++)
    for (int j = i; j > 0 && l[j - 1] > l[j]; j--) { double t = l[j]; l[j] = l[j - 1]; l[j - 1] = t; }
}

/* G = S^T S with S = T W^-1, W the edge matrix of the unit regular simplex (2.2, 2.3) */
static void gram_regular(int d, const double *x, double G[3][3]) {
  double T[3][3], S[3][3];
  for (int k = 0; k < d; k++)
    for (int i = 0; i < d; i++) T[i][k] = x[(k + 1) * d + i] - x[i];
  if (d == 2) {
    static const double Wi[2][2] = {{1, -0.57735026918962576}, {0, 1.1547005383792515}};
    for (int i = 0; i < 2; i++)
      for (int j = 0; j < 2; j++) S[i][j] = T[i][0] * Wi[0][j] + T[i][1] * Wi[1][j];
  } else {
    /* W = [(1,0,0) (1/2,√3/2,0) (1/2,√3/6,√(2/3))]; its inverse: */
    static const double Wi[3][3] = {{1, -0.57735026918962576, -0.40824829046386302},
                                    {0, 1.1547005383792515, -0.40824829046386302},
                                    {0, 0, 1.2247448713915890}};
    for (int i = 0; i < 3; i++)
      for (int j = 0; j < 3; j++) S[i][j] = T[i][0] * Wi[0][j] + T[i][1] * Wi[1][j] + T[i][2] * Wi[2][j];
  }
  for (int i = 0; i < d; i++)
    for (int j = 0; j < d; j++) {
      double s = 0;
      for (int k = 0; k < d; k++) s += S[k][i] * S[k][j];
      G[i][j] = s;
    }
}

/* ---------------------------------------------------------------- simplices */

static double tri_quality(const double *x, int q) {
  const double *P[3] = {x, x + 2, x + 4};
  double e01[2], e02[2], e12[2];
  sub(2, P[1], P[0], e01);
  sub(2, P[2], P[0], e02);
  sub(2, P[2], P[1], e12);
  double L01 = norm(2, e01), L02 = norm(2, e02), L12 = norm(2, e12);
  double S = 0.5 * cross2(e01, e02), A = fabs(S);
  double hmin = fmin(L01, fmin(L02, L12)), hmax = fmax(L01, fmax(L02, L12));
  double sumL2 = L01 * L01 + L02 * L02 + L12 * L12;
  /* vertex angles (B.3), computed with atan2 to stay exact near π; only for the measures
   * made of them, as the tetrahedron's faces below (three atan2 calls per triangle were half
   * of a million-triangle mesh's mean ratio) */
  double th[3] = {0, 0, 0}, s0[2], s1[2];
  if (q == QM_MIN_SOLID_ANGLE || q == QM_SIGMA_MIN || q == QM_MIN_ANGLE || q == QM_MAX_ANGLE)
    for (int i = 0; i < 3; i++) {
      sub(2, P[(i + 1) % 3], P[i], s0);
      sub(2, P[(i + 2) % 3], P[i], s1);
      th[i] = atan2(fabs(cross2(s0, s1)), dot(2, s0, s1));
    }
  double thmin = fmin(th[0], fmin(th[1], th[2])), thmax = fmax(th[0], fmax(th[1], th[2]));
  double p = 0.5 * (L01 + L02 + L12);
  switch (q) {
  case QM_MEAN_RATIO: return sumL2 > 0 ? 4 * sqrt(3.0) * A / sumL2 : 0; /* (2.1) */
  case QM_RADIUS_RATIO: { /* (2.4): 2 ρ_K / r_K = 8 S² / (p L12 L13 L23) */
    double den = p * L01 * L02 * L12;
    return den > 0 ? 8 * A * A / den : 0;
  }
  case QM_CONDITION: case QM_FROBENIUS_CONDITION: {
    double G[3][3];
    gram_regular(2, x, G);
    double tr = G[0][0] + G[1][1], det = G[0][0] * G[1][1] - G[0][1] * G[1][0];
    if (det <= 0 || tr <= 0) return 0;
    if (q == QM_FROBENIUS_CONDITION) return 2 * sqrt(det) / tr; /* (2.3), ≡ η in 2D */
    double disc = sqrt(fmax(0, tr * tr / 4 - det));
    double lmax = tr / 2 + disc, lmin = det / lmax; /* (2.2) */
    return lmin / lmax;
  }
  case QM_INTERPOLATION_COEFF: return hmax > 0 && p > 0 ? 2 * sqrt(3.0) * (A / p) / hmax : 0; /* (2.7) */
  case QM_MIN_SOLID_ANGLE: return thmin / (M_PI / 3); /* (2.5) */
  case QM_SIGMA_MIN: /* (2.6): σ_i = sin θ_i, β = √3/2 */
    return fmin(sin(th[0]), fmin(sin(th[1]), sin(th[2]))) / (sqrt(3.0) / 2);
  case QM_EDGE_RATIO: return hmax > 0 ? hmin / hmax : 0; /* (2.9) */
  case QM_SIGNED_MEASURE: return S;
  case QM_MIN_ANGLE: return thmin * 180 / M_PI;
  case QM_MAX_ANGLE: return thmax * 180 / M_PI;
  case QM_MIN_EDGE: return hmin;
  case QM_MAX_EDGE: return hmax;
  case QM_MIN_CORNER_JACOBIAN: return 2 * S;
  case QM_SCALED_JACOBIAN: { /* 2S / (largest product of a corner's two edges), × 2/√3 */
    double m = fmax(L01 * L02, fmax(L01 * L12, L02 * L12));
    return m > 0 ? 2 * S / m * 2 / sqrt(3.0) : 0;
  }
  case QM_CORNER_CONDITION: {
    if (S <= 0) return 0;
    return tri_quality(x, QM_FROBENIUS_CONDITION);
  }
  default: return NAN;
  }
}

static double tet_quality(const double *x, int q) {
  const double *P[4] = {x, x + 3, x + 6, x + 9};
  double L[4][4];
  double hmin = INFINITY, hmax = 0, sumL2 = 0;
  for (int i = 0; i < 4; i++)
    for (int j = i + 1; j < 4; j++) {
      double e[3];
      sub(3, P[j], P[i], e);
      L[i][j] = L[j][i] = norm(3, e);
      hmin = fmin(hmin, L[i][j]);
      hmax = fmax(hmax, L[i][j]);
      sumL2 += L[i][j] * L[i][j];
    }
  double e1[3], e2[3], e3[3];
  sub(3, P[1], P[0], e1);
  sub(3, P[2], P[0], e2);
  sub(3, P[3], P[0], e3);
  double V = det3(e1, e2, e3) / 6, A = fabs(V);
  /* the measures that need only edges and volume return before the faces are computed */
  switch (q) {
  case QM_MEAN_RATIO: return sumL2 > 0 ? 12 * cbrt(9 * V * V) / sumL2 : 0; /* (2.1) */
  case QM_EDGE_RATIO: return hmax > 0 ? hmin / hmax : 0;
  case QM_SIGNED_MEASURE: return V;
  case QM_MIN_EDGE: return hmin;
  case QM_MAX_EDGE: return hmax;
  case QM_MIN_CORNER_JACOBIAN: return 6 * V;
  case QM_SCALED_JACOBIAN: { /* 6V / (largest product of a corner's three edges), × √2 */
    double m = 0;
    for (int i = 0; i < 4; i++) {
      double pr = 1;
      for (int j = 0; j < 4; j++)
        if (j != i) pr *= L[i][j];
      m = fmax(m, pr);
    }
    return m > 0 ? 6 * V / m * sqrt(2.0) : 0;
  }
  default: break;
  }
  /* face areas S_k (face opposite vertex k) and outward unit normals */
  double Sf[4], nrm[4][3], sumS = 0;
  for (int k = 0; k < 4; k++) {
    int a = (k + 1) % 4, b = (k + 2) % 4, c = (k + 3) % 4;
    double u[3], w[3], n[3], toK[3];
    sub(3, P[b], P[a], u);
    sub(3, P[c], P[a], w);
    cross3(u, w, n);
    double nn = norm(3, n);
    Sf[k] = 0.5 * nn;
    sumS += Sf[k];
    sub(3, P[k], P[a], toK);
    double sgn = dot(3, n, toK) > 0 ? -1 : 1; /* away from the opposite vertex */
    for (int i = 0; i < 3; i++) nrm[k][i] = nn > 0 ? sgn * n[i] / nn : 0;
  }
  switch (q) {
  case QM_RADIUS_RATIO: { /* (2.4) */
    double a = L[0][1] * L[2][3], b = L[0][2] * L[1][3], c = L[0][3] * L[1][2];
    double r = (a + b + c) * (a + b - c) * (a + c - b) * (b + c - a);
    double den = sqrt(fmax(0, r)) * sumS;
    return den > 0 ? 216 * V * V / den : 0;
  }
  case QM_CONDITION: case QM_FROBENIUS_CONDITION: {
    double G[3][3];
    gram_regular(3, x, G);
    double det = G[0][0] * (G[1][1] * G[2][2] - G[1][2] * G[2][1]) - G[0][1] * (G[1][0] * G[2][2] - G[1][2] * G[2][0]) +
                 G[0][2] * (G[1][0] * G[2][1] - G[1][1] * G[2][0]);
    double tr = G[0][0] + G[1][1] + G[2][2];
    if (det <= 0 || tr <= 0) return 0;
    if (q == QM_FROBENIUS_CONDITION) { /* (2.3): 3 / (|S| |S^-1|), tr G^-1 = tr adj G / det G */
      double tradj = (G[1][1] * G[2][2] - G[1][2] * G[2][1]) + (G[0][0] * G[2][2] - G[0][2] * G[2][0]) +
                     (G[0][0] * G[1][1] - G[0][1] * G[1][0]);
      return 3 * sqrt(det / (tr * tradj));
    }
    double l[3];
    eig_sym3((const double(*)[3])G, l); /* (2.2) */
    return l[2] > 0 ? fmax(0, l[0]) / l[2] : 0;
  }
  case QM_INTERPOLATION_COEFF: return hmax > 0 && sumS > 0 ? 2 * sqrt(6.0) * (3 * A / sumS) / hmax : 0; /* (2.7) */
  case QM_MIN_SOLID_ANGLE: case QM_SIGMA_MIN: {
    /* solid angles by the Van Oosterom–Strackee formula (exact on [0, 2π], unlike the
     * arcsine of (C.3)) */
    double mn = INFINITY, smn = INFINITY;
    for (int i = 0; i < 4; i++) {
      double a[3], b[3], c[3];
      sub(3, P[(i + 1) % 4], P[i], a);
      sub(3, P[(i + 2) % 4], P[i], b);
      sub(3, P[(i + 3) % 4], P[i], c);
      double la = norm(3, a), lb = norm(3, b), lc = norm(3, c);
      double num = fabs(det3(a, b, c));
      double den = la * lb * lc + dot(3, a, b) * lc + dot(3, a, c) * lb + dot(3, b, c) * la;
      double om = 2 * atan2(num, den);
      mn = fmin(mn, om);
      smn = fmin(smn, sin(om / 2));
    }
    if (q == QM_MIN_SOLID_ANGLE) return mn / (6 * asin(sqrt(3.0) / 3) - M_PI); /* (2.5) */
    return smn / (sqrt(6.0) / 9);                                             /* (2.6) */
  }
  case QM_MIN_DIHEDRAL_ANGLE: case QM_MIN_ANGLE: case QM_MAX_ANGLE: {
    /* dihedral angle at edge (i,j): π − angle between the outward normals of the two
     * faces that contain it, the faces opposite the other two vertices k, l (2.8) */
    double mn = INFINITY, mx = 0;
    for (int i = 0; i < 4; i++)
      for (int j = i + 1; j < 4; j++) {
        int k = -1, l = -1;
        for (int m = 0; m < 4; m++)
          if (m != i && m != j) { if (k < 0) k = m; else l = m; }
        double c = dot(3, nrm[k], nrm[l]);
        if (c > 1) c = 1;
        if (c < -1) c = -1;
        double phi = (Sf[k] > 0 && Sf[l] > 0) ? M_PI - acos(c) : 0;
        mn = fmin(mn, phi);
        mx = fmax(mx, phi);
      }
    if (q == QM_MIN_DIHEDRAL_ANGLE) return mn / acos(1.0 / 3);
    return (q == QM_MIN_ANGLE ? mn : mx) * 180 / M_PI;
  }
  case QM_CORNER_CONDITION: return V <= 0 ? 0 : tet_quality(x, QM_FROBENIUS_CONDITION);
  default: return NAN;
  }
}

double simplex_quality(int dim, const double *x, int q) {
  return dim == 2 ? tri_quality(x, q) : tet_quality(x, q);
}

/* ---------------------------------------------------------------- quads and hexes */

static double quad_quality(const double *x, int q) {
  double mnJ = INFINITY, mnS = INFINITY, mnC = INFINITY, mnA = INFINITY, mxA = 0, mnE = INFINITY, mxE = 0;
  for (int i = 0; i < 4; i++) {
    const double *p = x + 2 * i, *a = x + 2 * ((i + 1) % 4), *b = x + 2 * ((i + 3) % 4);
    double e1[2], e2[2];
    sub(2, a, p, e1);
    sub(2, b, p, e2);
    double det = cross2(e1, e2), l1 = norm(2, e1), l2 = norm(2, e2);
    mnJ = fmin(mnJ, det);
    mnS = fmin(mnS, l1 > 0 && l2 > 0 ? det / (l1 * l2) : 0);
    mnC = fmin(mnC, det > 0 ? 2 * det / (l1 * l1 + l2 * l2) : 0);
    double ang = atan2(det, dot(2, e1, e2)); /* interior angle, reflex when negative */
    if (ang < 0) ang += 2 * M_PI;
    mnA = fmin(mnA, ang);
    mxA = fmax(mxA, ang);
    mnE = fmin(mnE, l1);
    mxE = fmax(mxE, l1);
  }
  switch (q) {
  case QM_MIN_CORNER_JACOBIAN: return mnJ;
  case QM_SCALED_JACOBIAN: return mnS;
  case QM_CORNER_CONDITION: return mnC;
  case QM_MIN_ANGLE: return mnA * 180 / M_PI;
  case QM_MAX_ANGLE: return mxA * 180 / M_PI;
  case QM_MIN_EDGE: return mnE;
  case QM_MAX_EDGE: return mxE;
  case QM_EDGE_RATIO: return mxE > 0 ? mnE / mxE : 0;
  default: return NAN;
  }
}

double quad_corner_area(const double *x, quad_class *cls) {
  /* A_i: the triangle of the two edges at corner i; a convex quadrilateral has all four
   * positive and A = (A_A + A_B + A_C + A_D) / 2 (both diagonal splittings averaged) */
  double Ai[4];
  int neg = 0, zero = 0;
  for (int i = 0; i < 4; i++) {
    const double *p = x + 2 * i, *a = x + 2 * ((i + 1) % 4), *b = x + 2 * ((i + 3) % 4);
    double e1[2], e2[2];
    sub(2, a, p, e1);
    sub(2, b, p, e2);
    Ai[i] = 0.5 * cross2(e1, e2);
    neg += Ai[i] < 0;
    zero += Ai[i] == 0;
  }
  if (cls) *cls = zero ? QUAD_DEGENERATE : neg == 0 ? QUAD_CONVEX : neg == 1 || neg == 3 ? QUAD_NONCONVEX : QUAD_CROSSED;
  return 0.5 * (Ai[0] + Ai[1] + Ai[2] + Ai[3]);
}

double quad_quality_measure(const double *x, int q) {
  double len[4], ang[4], Ai[4];
  for (int i = 0; i < 4; i++) {
    const double *p = x + 2 * i, *a = x + 2 * ((i + 1) % 4), *b = x + 2 * ((i + 3) % 4);
    double e1[2], e2[2];
    sub(2, a, p, e1);
    sub(2, b, p, e2);
    len[i] = norm(2, e1); /* edge i runs from vertex i to vertex i+1: a = AB, b = BC, ... */
    Ai[i] = 0.5 * cross2(e1, e2);
    ang[i] = atan2(cross2(e1, e2), dot(2, e1, e2));
    if (ang[i] < 0) ang[i] += 2 * M_PI;
  }
  double A = quad_corner_area(x, NULL);
  double lmin = fmin(fmin(len[0], len[1]), fmin(len[2], len[3]));
  double lmax = fmax(fmax(len[0], len[1]), fmax(len[2], len[3]));
  double p = 0.5 * (len[0] + len[1] + len[2] + len[3]);
  switch (q) {
  case QM_STRETCHING: return lmin > 0 ? lmax / lmin : INFINITY; /* (3.1) */
  case QM_SKEWNESS: { /* (4.1), θ the mean of the angles at A and C (the torsion) */
    double th = 0.5 * (ang[0] + ang[2]);
    double den = 1 - fabs(1 - 2 * th / M_PI);
    return den > 0 ? 1 / den : INFINITY;
  }
  case QM_ZETA: return A > 0 ? p * p / A : INFINITY;    /* (5.2) */
  case QM_IOTA: return A > 0 ? p * lmax / A : INFINITY; /* (5.3) */
  case QM_Q: {                                           /* (6.1) */
    double ac[2], bd[2];
    sub(2, x + 4, x, ac);
    sub(2, x + 6, x + 2, bd);
    double hm = fmax(fmax(norm(2, ac), norm(2, bd)), lmax);
    double l2 = sqrt(len[0] * len[0] + len[1] * len[1] + len[2] * len[2] + len[3] * len[3]);
    double amin = fmin(fmin(Ai[0], Ai[1]), fmin(Ai[2], Ai[3]));
    return amin > 0 ? l2 * hm / amin : INFINITY;
  }
  case QM_KAPPA2_MEAN: case QM_KAPPA2_MAX: {
    /* (8.3, 8.4): κ₂⊥ of the corner triangle at vertex i, whose edges are edge i and
     * edge i-1: (l_i² + l_{i-1}²) / (2 A_i) */
    double s = 0, m = 0;
    for (int i = 0; i < 4; i++) {
      double la = len[i], lb = len[(i + 3) % 4];
      double k = Ai[i] > 0 ? (la * la + lb * lb) / (2 * Ai[i]) : INFINITY;
      s += k;
      m = fmax(m, k);
    }
    return q == QM_KAPPA2_MAX ? m : s / 4;
  }
  default: return quad_quality(x, q);
  }
}

static double hex_quality(const double *x, int q) {
  double mnJ = INFINITY, mnS = INFINITY, mnC = INFINITY;
  for (int i = 0; i < 8; i++) {
    const int *nb = hex_corner_neighbors(i);
    double e[3][3], ln[3];
    for (int k = 0; k < 3; k++) {
      sub(3, x + 3 * nb[k], x + 3 * i, e[k]);
      ln[k] = norm(3, e[k]);
    }
    double det = det3(e[0], e[1], e[2]);
    mnJ = fmin(mnJ, det);
    mnS = fmin(mnS, ln[0] > 0 && ln[1] > 0 && ln[2] > 0 ? det / (ln[0] * ln[1] * ln[2]) : 0);
    /* κ = |A| |A^-1| with |A^-1| = |adj A| / |det A|; adj rows are cross products */
    double c01[3], c12[3], c20[3];
    cross3(e[0], e[1], c01);
    cross3(e[1], e[2], c12);
    cross3(e[2], e[0], c20);
    double fa = sqrt(ln[0] * ln[0] + ln[1] * ln[1] + ln[2] * ln[2]);
    double fadj = sqrt(dot(3, c01, c01) + dot(3, c12, c12) + dot(3, c20, c20));
    mnC = fmin(mnC, det > 0 && fa > 0 && fadj > 0 ? 3 * det / (fa * fadj) : 0);
  }
  static const int edges[12][2] = {{0, 1}, {1, 2}, {2, 3}, {3, 0}, {4, 5}, {5, 6},
                                   {6, 7}, {7, 4}, {0, 4}, {1, 5}, {2, 6}, {3, 7}};
  double mnE = INFINITY, mxE = 0;
  for (int k = 0; k < 12; k++) {
    double e[3];
    sub(3, x + 3 * edges[k][1], x + 3 * edges[k][0], e);
    double l = norm(3, e);
    mnE = fmin(mnE, l);
    mxE = fmax(mxE, l);
  }
  switch (q) {
  case QM_MIN_CORNER_JACOBIAN: return mnJ;
  case QM_SCALED_JACOBIAN: return mnS;
  case QM_CORNER_CONDITION: return mnC;
  case QM_MIN_EDGE: return mnE;
  case QM_MAX_EDGE: return mxE;
  case QM_EDGE_RATIO: return mxE > 0 ? mnE / mxE : 0;
  default: return NAN;
  }
}

/* ---------------------------------------------------------------- meshes */

/* N with N^T N = M: the transpose of the Cholesky factor L (M = L L^T); 0 when M is not
 * symmetric positive definite */
static int metric_map(int d, const double *M, double N[3][3]) {
  double Lc[3][3] = {{0}};
  for (int i = 0; i < d; i++)
    for (int j = 0; j < d; j++)
      if (fabs(M[i * d + j] - M[j * d + i]) > 1e-12 * (fabs(M[i * d + j]) + fabs(M[j * d + i]) + 1e-300)) return 0;
  for (int j = 0; j < d; j++) {
    double s = M[j * d + j];
    for (int k = 0; k < j; k++) s -= Lc[j][k] * Lc[j][k];
    if (!(s > 0)) return 0;
    Lc[j][j] = sqrt(s);
    for (int i = j + 1; i < d; i++) {
      double t = M[i * d + j];
      for (int k = 0; k < j; k++) t -= Lc[i][k] * Lc[j][k];
      Lc[i][j] = t / Lc[j][j];
    }
  }
  for (int i = 0; i < d; i++)
    for (int j = 0; j < d; j++) N[i][j] = Lc[j][i];
  return 1;
}

/* cube root of x > 0 without a division: Newton's iteration for the inverse cube root
 * r = x^(-1/3), r ← r (4 − x r³) / 3, from an exponent bit trick (a few % off; each step
 * squares the relative error), then x^(1/3) = x r² */
static inline double cbrt_pos(double x) {
  uint64_t i;
  memcpy(&i, &x, sizeof i);
  i = 0x553ef0ff289dd796ull - i / 3;
  double r;
  memcpy(&r, &i, sizeof r);
  for (int k = 0; k < 5; k++) r = r * (4 - x * r * r * r) * (1.0 / 3);
  return x * r * r;
}

/* measure q of one cell of type t given its vertex coordinates */
static double coords_quality(cell_type t, const double *xc, int q) {
  if (t == CELL_TRIANGLE) return q >= QM_V_AREA ? verdict_tri(xc, q) : tri_quality(xc, q);
  if (t == CELL_TETRAHEDRON) return q >= QM_V_AREA ? verdict_tet(xc, q) : tet_quality(xc, q);
  if (q >= QM_V_AREA) return t == CELL_QUADRILATERAL ? verdict_quad(xc, q) : verdict_hex(xc, q);
  if (t == CELL_QUADRILATERAL) {
    if (q != QM_SIGNED_MEASURE) return quad_quality_measure(xc, q);
    double s = 0;
    for (int i = 0; i < 4; i++) s += cross2(xc + 2 * i, xc + 2 * ((i + 1) % 4));
    return 0.5 * s;
  }
  return q == QM_SIGNED_MEASURE ? hex_signed_volume(xc) : hex_quality(xc, q);
}

/* the power of length that measure q scales with (0 for the shape measures, which are
 * computed on coordinates scaled to unit size so that no scale overflows or underflows) */
static int length_power(int q, cell_type t) {
  int d = cell_dim(t);
  switch (q) {
  case QM_SIGNED_MEASURE: case QM_MIN_CORNER_JACOBIAN: case QM_V_JACOBIAN: return d;
  case QM_MIN_EDGE: case QM_MAX_EDGE: case QM_V_DIMENSION: return 1;
  case QM_V_AREA: return 2;
  case QM_V_VOLUME: return 3;
  default: return 0;
  }
}

/* measure q of a cell from its normalized coordinates (mesh_cell_normalized, exponent e) */
static double scaled_quality(cell_type t, const double *xn, int e, int q) {
  if (isnan(xn[0])) return NAN;
  double v = coords_quality(t, xn, q);
  int p = length_power(q, t);
  return p && e ? ldexp(v, p * e) : v;
}

static double scaled_cell_quality(const mesh *m, int c, int q) {
  double x[8 * 3];
  int e = mesh_cell_normalized(m, c, x);
  return scaled_quality(m->type, x, e, q);
}

/* the two measures people run on huge tetrahedral meshes, for one cell straight from its
 * coordinates: no square root for η (squared lengths, a determinant and one cube root), one
 * for the scaled Jacobian (the largest product of a corner's three squared edge lengths);
 * cells far from unit size take the normalized path */
static double tet_fast_cell(const mesh *m, int c, int q) {
  const double *X = m->x;
  const int *v = m->cells + 4 * (size_t)c;
  const double *p0 = X + 3 * (size_t)v[0], *p1 = X + 3 * (size_t)v[1], *p2 = X + 3 * (size_t)v[2],
               *p3 = X + 3 * (size_t)v[3];
  double a[3] = {p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]};
  double b[3] = {p2[0] - p0[0], p2[1] - p0[1], p2[2] - p0[2]};
  double d[3] = {p3[0] - p0[0], p3[1] - p0[1], p3[2] - p0[2]};
  double e[3] = {p2[0] - p1[0], p2[1] - p1[1], p2[2] - p1[2]};
  double f[3] = {p3[0] - p1[0], p3[1] - p1[1], p3[2] - p1[2]};
  double g[3] = {p3[0] - p2[0], p3[1] - p2[1], p3[2] - p2[2]};
  double det = a[0] * (b[1] * d[2] - b[2] * d[1]) - a[1] * (b[0] * d[2] - b[2] * d[0]) + a[2] * (b[0] * d[1] - b[1] * d[0]);
  double la = a[0] * a[0] + a[1] * a[1] + a[2] * a[2], lb = b[0] * b[0] + b[1] * b[1] + b[2] * b[2];
  double ld = d[0] * d[0] + d[1] * d[1] + d[2] * d[2], le = e[0] * e[0] + e[1] * e[1] + e[2] * e[2];
  double lf = f[0] * f[0] + f[1] * f[1] + f[2] * f[2], lg = g[0] * g[0] + g[1] * g[1] + g[2] * g[2];
  double s = la + lb + ld + le + lf + lg;
  if (!(s > 1e-60 && s < 1e60)) return scaled_cell_quality(m, c, q); /* far from unit size (or not finite) */
  if (q == QM_MEAN_RATIO) {
    /* (2.1): 12 (9 V²)^(1/3) / Σ L², V = det/6 → 12 (det²/4)^(1/3) / Σ L² */
    double t = 0.25 * det * det;
    return s > 0 && t > 0 ? 12 * cbrt_pos(t) / s : 0;
  }
  /* corners: 0 (a, b, d), 1 (a, e, f), 2 (b, e, g), 3 (d, f, g) */
  double m0 = la * lb * ld, m1 = la * le * lf, m2 = lb * le * lg, m3 = ld * lf * lg;
  double mx = fmax(fmax(m0, m1), fmax(m2, m3));
  return mx > 0 ? det / sqrt(mx) * sqrt(2.0) : 0;
}

/* mesh_quality without a metric takes this cell by cell, so the smoothers' star objectives
 * and guards see the reported values */
double mesh_cell_quality(const mesh *m, int c, int q) {
  if (m->type == CELL_TETRAHEDRON && (q == QM_MEAN_RATIO || q == QM_SCALED_JACOBIAN)) return tet_fast_cell(m, c, q);
  return scaled_cell_quality(m, c, q);
}

int mesh_quality(const mesh *m, int q, const quality_metric *metric, double *out, char *err) {
  if (q < 0 || q >= QM_COUNT) { snprintf(err, MESH_ERRLEN, "unknown quality measure"); return 1; }
  if (!quality_applies(q, m->type)) {
    snprintf(err, MESH_ERRLEN, "the measure %s does not apply to %s", names[q], cell_plural(m->type));
    return 1;
  }
  if (quality_is_deformation(q)) {
    snprintf(err, MESH_ERRLEN, "the measure %s compares two configurations: give a reference", names[q]);
    return 1;
  }
  int d = m->dim, nvc = m->nvc;
  double N[3][3];
  int kind = metric ? metric->kind : 0;
  if (!kind) { /* cells on threads, each writing its own: the smoother measures a million-triangle
                * mesh before and after, 0.06 s each on one thread */
#ifdef _OPENMP
#pragma omp parallel for schedule(static) if (m->ncell > 4096)
#endif
    for (int c = 0; c < m->ncell; c++) out[c] = mesh_cell_quality(m, c, q);
    return 0;
  }
  /* a metric: each cell mapped by N with N^T N = M (constant, or the vertices' tensors
   * averaged over the cell) and measured there */
  if (kind == 1 && !metric_map(d, metric->m, N)) {
    snprintf(err, MESH_ERRLEN, "the metric tensor is not symmetric positive definite");
    return 1;
  }
  double x[8 * 3], y[8 * 3];
  for (int c = 0; c < m->ncell; c++) {
    const int *v = m->cells + (size_t)c * (size_t)nvc;
    int e = mesh_cell_normalized(m, c, x);
    if (kind == 2) { /* the vertex tensors averaged over the cell (section 2.8) */
      double Mb[9] = {0};
      for (int i = 0; i < nvc; i++)
        for (int k = 0; k < d * d; k++) Mb[k] += metric->m[(size_t)v[i] * d * d + k] / nvc;
      if (!metric_map(d, Mb, N)) {
        snprintf(err, MESH_ERRLEN, "the metric tensor averaged over cell %d is not symmetric positive definite", c + 1);
        return 1;
      }
    }
    for (int i = 0; i < nvc; i++) /* the cell mapped by N (N^T N = M) */
      for (int r = 0; r < d; r++) {
        double s = 0;
        for (int k = 0; k < d; k++) s += N[r][k] * x[i * d + k];
        y[i * d + r] = s;
      }
    out[c] = scaled_quality(m->type, y, e, q);
  }
  return 0;
}

/* singular values of a d×d matrix (ascending) through the eigenvalues of B^T B */
static void singular_values(int d, const double B[3][3], double *sv) {
  double G[3][3] = {{0}};
  for (int i = 0; i < d; i++)
    for (int j = 0; j < d; j++) {
      double s = 0;
      for (int k = 0; k < d; k++) s += B[k][i] * B[k][j];
      G[i][j] = s;
    }
  double l[3];
  if (d == 2) {
    double tr = G[0][0] + G[1][1], det = G[0][0] * G[1][1] - G[0][1] * G[1][0];
    double disc = sqrt(fmax(0, tr * tr / 4 - det));
    l[1] = tr / 2 + disc;
    l[0] = l[1] > 0 ? det / l[1] : 0;
  } else eig_sym3((const double(*)[3])G, l);
  for (int i = 0; i < d; i++) sv[i] = sqrt(fmax(0, l[i]));
}

/* B = T̃ T⁻¹ for corner matrices with columns e_k (reference) and f_k (current) */
static int deformation_matrix(int d, double T[3][3], double Tt[3][3], double B[3][3], double *detB) {
  double det, inv[3][3];
  if (d == 2) {
    det = T[0][0] * T[1][1] - T[0][1] * T[1][0];
    if (det == 0) return 1;
    inv[0][0] = T[1][1] / det; inv[0][1] = -T[0][1] / det;
    inv[1][0] = -T[1][0] / det; inv[1][1] = T[0][0] / det;
  } else {
    double c[3][3];
    c[0][0] = T[1][1] * T[2][2] - T[1][2] * T[2][1];
    c[0][1] = T[0][2] * T[2][1] - T[0][1] * T[2][2];
    c[0][2] = T[0][1] * T[1][2] - T[0][2] * T[1][1];
    c[1][0] = T[1][2] * T[2][0] - T[1][0] * T[2][2];
    c[1][1] = T[0][0] * T[2][2] - T[0][2] * T[2][0];
    c[1][2] = T[0][2] * T[1][0] - T[0][0] * T[1][2];
    c[2][0] = T[1][0] * T[2][1] - T[1][1] * T[2][0];
    c[2][1] = T[0][1] * T[2][0] - T[0][0] * T[2][1];
    c[2][2] = T[0][0] * T[1][1] - T[0][1] * T[1][0];
    det = T[0][0] * c[0][0] + T[0][1] * c[1][0] + T[0][2] * c[2][0];
    if (det == 0) return 1;
    for (int i = 0; i < 3; i++)
      for (int j = 0; j < 3; j++) inv[i][j] = c[i][j] / det;
  }
  for (int i = 0; i < d; i++)
    for (int j = 0; j < d; j++) {
      double s = 0;
      for (int k = 0; k < d; k++) s += Tt[i][k] * inv[k][j];
      B[i][j] = s;
    }
  double dt = d == 2 ? Tt[0][0] * Tt[1][1] - Tt[0][1] * Tt[1][0]
                     : Tt[0][0] * (Tt[1][1] * Tt[2][2] - Tt[1][2] * Tt[2][1]) - Tt[0][1] * (Tt[1][0] * Tt[2][2] - Tt[1][2] * Tt[2][0]) +
                           Tt[0][2] * (Tt[1][0] * Tt[2][1] - Tt[1][1] * Tt[2][0]);
  *detB = dt / det;
  return 0;
}

int mesh_deformation(const mesh *m, const double *xref, int q, double p, double *out, char *err) {
  if (!quality_is_deformation(q)) {
    snprintf(err, MESH_ERRLEN, "%s is not a deformation measure", quality_name(q));
    return 1;
  }
  if (!(p >= 1)) { snprintf(err, MESH_ERRLEN, "the Schatten exponent p must be >= 1 (or infinity), got %g", p); return 1; }
  if (m->type == CELL_INTERVAL) { snprintf(err, MESH_ERRLEN, "deformation measures are of 2D and 3D meshes, not intervals"); return 1; }
  int d = m->dim, nvc = m->nvc;
  int simplex = m->type == CELL_TRIANGLE || m->type == CELL_TETRAHEDRON;
  int ncorner = simplex ? 1 : nvc;
  for (int c = 0; c < m->ncell; c++) {
    const int *v = m->cells + (size_t)c * (size_t)nvc;
    double mn = INFINITY, mx = 0, qual = INFINITY;
    int bad = 0;
    for (int corner = 0; corner < ncorner; corner++) {
      int nb[3];
      if (simplex) { nb[0] = 1; nb[1] = 2; nb[2] = 3; }
      else if (m->type == CELL_QUADRILATERAL) { nb[0] = (corner + 1) % 4; nb[1] = (corner + 3) % 4; }
      else memcpy(nb, hex_corner_neighbors(corner), sizeof nb);
      int o = simplex ? 0 : corner;
      /* the corner's edges in both configurations, each scaled to unit size (B is then off
       * by 2^(ec - er), which only the singular values feel) */
      double pr[4 * 3], pc[4 * 3], nr[4 * 3], nc[4 * 3];
      for (int i = 0; i < d; i++) {
        pr[i] = xref[(size_t)v[o] * d + i];
        pc[i] = m->x[(size_t)v[o] * d + i];
        for (int k = 0; k < d; k++) {
          pr[(k + 1) * d + i] = xref[(size_t)v[nb[k]] * d + i];
          pc[(k + 1) * d + i] = m->x[(size_t)v[nb[k]] * d + i];
        }
      }
      int er = points_normalized(d + 1, d, pr, nr), ec = points_normalized(d + 1, d, pc, nc);
      if (isnan(nr[0]) || isnan(nc[0])) { mn = mx = qual = NAN; break; }
      double T[3][3], Tt[3][3], B[3][3], detB;
      for (int k = 0; k < d; k++)
        for (int i = 0; i < d; i++) {
          T[i][k] = nr[(k + 1) * d + i];
          Tt[i][k] = nc[(k + 1) * d + i];
        }
      if (deformation_matrix(d, T, Tt, B, &detB)) { bad = 1; break; }
      double sv[3];
      singular_values(d, (const double(*)[3])B, sv);
      for (int i = 0; i < d; i++) sv[i] = ldexp(sv[i], ec - er);
      mn = fmin(mn, sv[0]);
      mx = fmax(mx, sv[d - 1]);
      double t;
      if (detB <= 0 || sv[0] <= 0) t = 0;
      else if (isinf(p)) t = sv[0] / sv[d - 1]; /* (4.18) */
      else {                                    /* d^(2/p) / κ_p, κ_p from (4.16) */
        double a = 0, b = 0;
        for (int i = 0; i < d; i++) { a += pow(sv[i], p); b += pow(sv[i], -p); }
        t = pow((double)d, 2 / p) / pow(a * b, 1 / p);
      }
      qual = fmin(qual, t);
    }
    if (bad) {
      snprintf(err, MESH_ERRLEN, "cell %d is degenerate in the reference configuration", c + 1);
      return 1;
    }
    out[c] = q == QM_DEFORMATION_MIN_SV ? mn : q == QM_DEFORMATION_MAX_SV ? mx : qual;
  }
  return 0;
}

void quality_stats_compute(const double *q, int n, quality_stats *s) {
  s->n = n;
  s->min = INFINITY;
  s->max = -INFINITY;
  s->mean = 0;
  s->argmin = s->argmax = -1;
  double sum = 0, comp = 0; /* compensated: 10 million equal values average to themselves */
  int pinf = 0, ninf = 0, nan = 0;
  for (int i = 0; i < n; i++) {
    double v = q[i];
    if (v < s->min || (s->argmin < 0 && v == s->min)) { s->min = v; s->argmin = i; }
    if (v > s->max || (s->argmax < 0 && v == s->max)) { s->max = v; s->argmax = i; }
    if (isnan(v)) { nan++; continue; }
    if (isinf(v)) { if (v > 0) pinf++; else ninf++; continue; }
    double y = v - comp, t = sum + y;
    comp = (t - sum) - y;
    sum = t;
  }
  /* infinities dominate the mean (+Inf and -Inf together have none); NaN propagates */
  if (!n || nan || (pinf && ninf)) s->mean = NAN;
  else if (pinf) s->mean = INFINITY;
  else if (ninf) s->mean = -INFINITY;
  else s->mean = sum / n;
  if (s->argmin < 0) s->min = NAN;
  if (s->argmax < 0) s->max = NAN;
}

void quality_histogram(const double *q, int n, int nbins, double lo, double hi, int *counts) {
  for (int b = 0; b < nbins; b++) counts[b] = 0;
  double w = (hi - lo) / nbins;
  for (int i = 0; i < n; i++) {
    if (isnan(q[i])) continue; /* a value that is not a number has no bin */
    double t = w > 0 && w < INFINITY ? (q[i] - lo) / w : 0;
    int b = !(t >= 0) ? 0 : t >= nbins ? nbins - 1 : (int)t;
    counts[b]++;
  }
}

/* ---------------------------------------------------------------- worst cells */

int quality_larger_is_better(int q) {
  switch (q) {
  case QM_MAX_ANGLE: case QM_STRETCHING: case QM_SKEWNESS: case QM_ZETA: case QM_IOTA: case QM_Q:
  case QM_KAPPA2_MEAN: case QM_KAPPA2_MAX:
  /* Verdict's ratios: 1 is best, larger is worse */
  case QM_V_ASPECT_FROBENIUS: case QM_V_ASPECT_RATIO: case QM_V_CONDITION: case QM_V_EDGE_RATIO:
  case QM_V_MAX_ANGLE: case QM_V_RADIUS_RATIO: case QM_V_ASPECT_BETA: case QM_V_ASPECT_GAMMA:
  case QM_V_MAX_ASPECT_FROBENIUS: case QM_V_MAX_EDGE_RATIOS: case QM_V_MED_ASPECT_FROBENIUS: case QM_V_ODDY:
  case QM_V_SKEW: case QM_V_TAPER:
    return 0;
  default: return 1;
  }
}

/* "a is worse than b" */
static int worse(double a, double b, int larger_is_better) { return larger_is_better ? a < b : a > b; }

void quality_worst(const double *q, int n, int k, int larger_is_better, int *ids) {
  /* a bounded insertion into the k worst: O(n k), fine for the small k users ask for */
  int m = 0;
  for (int i = 0; i < n; i++) {
    if (m == k && !worse(q[i], q[ids[m - 1]], larger_is_better)) continue;
    int j = m < k ? m++ : k - 1;
    while (j > 0 && worse(q[i], q[ids[j - 1]], larger_is_better)) { ids[j] = ids[j - 1]; j--; }
    ids[j] = i;
  }
}

int quality_worst_index(const double *q, int n, int larger_is_better) {
  int id = -1;
  if (n > 0) quality_worst(q, n, 1, larger_is_better, &id);
  return id;
}
