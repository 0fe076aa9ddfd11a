/* quality_verdict.c — the Verdict library's cell metrics as VTK 9.1's vtkMeshQuality
 * computes them (triangles, tetrahedra, quadrilaterals, hexahedra), written from their
 * definitions, so that lugal's quality tables can be compared with VTK's value for value
 * (tests/data/verdict_*.txt). lugal's own measures are in quality.c. */
#include "quality_int.h"

#include <stdio.h>
#include <string.h>

/* Verdict's triangle metrics (as in VTK 9.1), from their definitions. Verdict works in 3D
 * and takes |cross products|, so its area and scaled Jacobian are unsigned (an inverted
 * triangle looks like a valid one), unlike signed_measure and scaled_jacobian above.
 * Degenerate triangles give Verdict's sentinel 1e30 where it does. */
#define VERDICT_MAX 1e30
double verdict_tri(const double *x, int q) {
  double a[2], b[2], c[2], v2[2];
  sub(2, x + 2, x, a);     /* P0 → P1 */
  sub(2, x + 4, x + 2, b); /* P1 → P2 */
  sub(2, x, x + 4, c);     /* P2 → P0 */
  sub(2, x + 4, x, v2);    /* P0 → P2 */
  double la = norm(2, a), lb = norm(2, b), lc = norm(2, c);
  double a2 = la * la, b2 = lb * lb, c2 = lc * lc;
  double twoA = fabs(cross2(a, v2)); /* |a × b| = |a × (P2 − P0)| = 2 area */
  double hmax = fmax(la, fmax(lb, lc)), hmin = fmin(la, fmin(lb, lc));
  double cond = twoA > 0 ? (a2 + dot(2, v2, v2) - dot(2, a, v2)) / (twoA * sqrt(3.0)) : VERDICT_MAX;
  switch (q) {
  case QM_V_AREA: return 0.5 * twoA;
  case QM_V_ASPECT_FROBENIUS: return twoA > 0 ? (a2 + b2 + c2) / (2 * sqrt(3.0) * twoA) : VERDICT_MAX;
  case QM_V_ASPECT_RATIO: return twoA > 0 ? sqrt(3.0) / 6 * hmax * (la + lb + lc) / twoA : VERDICT_MAX;
  case QM_V_RADIUS_RATIO: return twoA > 0 ? 0.25 * la * lb * lc * (la + lb + lc) / (twoA * twoA) : VERDICT_MAX;
  case QM_V_CONDITION: return fmin(cond, VERDICT_MAX);
  case QM_V_SHAPE: return cond > 0 && cond < VERDICT_MAX ? 1 / cond : 0;
  case QM_V_DISTORTION: return 1; /* linear triangles */
  case QM_V_EDGE_RATIO: return hmin > 0 ? hmax / hmin : VERDICT_MAX;
  case QM_V_MAX_ANGLE: case QM_V_MIN_ANGLE: {
    if (hmin == 0) return 0;
    double th[3], s0[2], s1[2];
    for (int i = 0; i < 3; i++) {
      sub(2, x + 2 * ((i + 1) % 3), x + 2 * i, s0);
      sub(2, x + 2 * ((i + 2) % 3), x + 2 * i, s1);
      th[i] = atan2(fabs(cross2(s0, s1)), dot(2, s0, s1));
    }
    double v = q == QM_V_MAX_ANGLE ? fmax(th[0], fmax(th[1], th[2])) : fmin(th[0], fmin(th[1], th[2]));
    return v * 180 / M_PI;
  }
  case QM_V_SCALED_JACOBIAN: {
    double m = fmax(la * lc, fmax(lc * lb, la * lb));
    return m > 0 ? twoA * (2 / sqrt(3.0)) / m : 0;
  }
  default: return NAN;
  }
}

/* Verdict's tetrahedron metrics (as in VTK 9.1), from their definitions; sides follow
 * Verdict's numbering: s0 = P1−P0, s1 = P2−P1, s2 = P0−P2, s3 = P3−P0, s4 = P3−P1,
 * s5 = P3−P2. Verdict's values are signed where it uses the signed Jacobian. */
double verdict_tet(const double *x, int q) {
  const double *P[4] = {x, x + 3, x + 6, x + 9};
  double s[6][3], e2[3];
  sub(3, P[1], P[0], s[0]);
  sub(3, P[2], P[1], s[1]);
  sub(3, P[0], P[2], s[2]);
  sub(3, P[3], P[0], s[3]);
  sub(3, P[3], P[1], s[4]);
  sub(3, P[3], P[2], s[5]);
  sub(3, P[2], P[0], e2); /* ac */
  double l2[6], hmax2 = 0, hmin2 = INFINITY;
  for (int i = 0; i < 6; i++) {
    l2[i] = dot(3, s[i], s[i]);
    hmax2 = fmax(hmax2, l2[i]);
    hmin2 = fmin(hmin2, l2[i]);
  }
  double det = det3(s[0], e2, s[3]); /* ab · (ac × ad) = 6 V */
  double V = det / 6;
  double c[3];
  switch (q) {
  case QM_V_VOLUME: return V;
  case QM_V_JACOBIAN: return det;
  case QM_V_EDGE_RATIO: return hmin2 > 0 ? sqrt(hmax2 / hmin2) : VERDICT_MAX;
  case QM_V_DISTORTION: return 1; /* linear tetrahedra */
  case QM_V_SCALED_JACOBIAN: {
    double lp[4] = {l2[0] * l2[2] * l2[3], l2[0] * l2[1] * l2[4], l2[1] * l2[2] * l2[5], l2[3] * l2[4] * l2[5]};
    double m = sqrt(fmax(fmax(lp[0], lp[1]), fmax(lp[2], lp[3])));
    if (m < fabs(det)) m = fabs(det);
    return m > 0 ? sqrt(2.0) * det / m : VERDICT_MAX;
  }
  case QM_V_RADIUS_RATIO: case QM_V_ASPECT_BETA: {
    /* circumradius numerator and the four face areas */
    double a[3], b[3], d[3], n[3];
    cross3(s[2], s[0], a);
    cross3(s[3], s[0], b);
    cross3(s[3], s[2], d);
    for (int i = 0; i < 3; i++) n[i] = l2[3] * a[i] + l2[2] * b[i] + l2[0] * d[i];
    double f[3];
    cross3(s[4], s[1], f);
    double area = 0.5 * (norm(3, a) + norm(3, b) + norm(3, f) + norm(3, d));
    /* VTK 9.1's Verdict gives aspect beta the radius ratio's value also for inverted cells
     * (newer Verdict documents 1e30 there); lugal follows VTK 9.1, as ParaView shows it */
    if (fabs(V) < 1e-300) return VERDICT_MAX;
    return norm(3, n) * area / (108 * V * V);
  }
  case QM_V_ASPECT_RATIO: {
    if (fabs(det) < 1e-300) return VERDICT_MAX;
    double bc[3], cd[3], t[3], A, B, C, D;
    sub(3, P[2], P[1], bc);
    sub(3, P[3], P[2], cd);
    cross3(s[0], bc, t); A = norm(3, t);
    cross3(s[0], s[3], t); B = norm(3, t);
    cross3(e2, s[3], t); C = norm(3, t);
    cross3(bc, cd, t); D = norm(3, t);
    return sqrt(6.0) / 12 * sqrt(hmax2) * (A + B + C + D) / fabs(det);
  }
  case QM_V_ASPECT_GAMMA: {
    if (fabs(V) < 1e-300) return VERDICT_MAX;
    double srms = sqrt((l2[0] + l2[1] + l2[2] + l2[3] + l2[4] + l2[5]) / 6);
    return srms * srms * srms / (8.48528137423857 * fabs(V));
  }
  case QM_V_ASPECT_FROBENIUS: {
    double den = 3 * cbrt(2 * det * det);
    if (den < 1e-300) return VERDICT_MAX;
    const double *u = s[0], *v = e2, *w = s[3];
    double num = 1.5 * (dot(3, u, u) + dot(3, v, v) + dot(3, w, w)) - dot(3, u, v) - dot(3, u, w) - dot(3, v, w);
    return num / den;
  }
  case QM_V_MIN_ANGLE: {
    /* nonoriented dihedral angles between the face normals */
    double bc[3], cd[3], abc[3], abd[3], acd[3], bcd[3];
    sub(3, P[2], P[1], bc);
    sub(3, P[3], P[2], cd);
    cross3(s[0], bc, abc);
    cross3(s[0], s[3], abd);
    cross3(s[3], cd, acd);
    cross3(bc, cd, bcd);
    const double *nv[4] = {abc, abd, acd, bcd};
    double mn = INFINITY;
    for (int i = 0; i < 4; i++)
      for (int j = i + 1; j < 4; j++) {
        double cc = dot(3, nv[i], nv[j]) / (norm(3, nv[i]) * norm(3, nv[j]));
        mn = fmin(mn, acos(fmax(-1, fmin(1, cc))));
      }
    return mn * 180 / M_PI;
  }
  case QM_V_COLLAPSE_RATIO: {
    double e01[3], e02[3], e03[3], e12[3], e13[3], e23[3], N[3];
    sub(3, P[1], P[0], e01); sub(3, P[2], P[0], e02); sub(3, P[3], P[0], e03);
    sub(3, P[2], P[1], e12); sub(3, P[3], P[1], e13); sub(3, P[3], P[2], e23);
    double l[6] = {norm(3, e01), norm(3, e02), norm(3, e03), norm(3, e12), norm(3, e13), norm(3, e23)};
    double l012 = fmax(l[1], fmax(l[4], l[0])), l031 = fmax(l[3], fmax(l[0], l[2]));
    double l023 = fmax(l[5], fmax(l[2], l[1])), l132 = fmax(l[5], fmax(l[4], l[3]));
    /* height of each vertex above the opposite face over that face's longest edge */
    cross3(e01, e02, N);
    double cr = dot(3, e03, N) / norm(3, N) / l012;
    cross3(e03, e01, N);
    cr = fmin(cr, dot(3, e02, N) / norm(3, N) / l031);
    cross3(e02, e03, N);
    cr = fmin(cr, dot(3, e01, N) / norm(3, N) / l023);
    cross3(e12, e13, N);
    cr = fmin(cr, dot(3, e01, N) / norm(3, N) / l132);
    return isnan(cr) ? VERDICT_MAX : cr;
  }
  case QM_V_CONDITION: {
    double c1[3], c2[3], c3[3], t[3];
    for (int i = 0; i < 3; i++) {
      c1[i] = s[0][i];
      c2[i] = (-2 * s[2][i] - s[0][i]) / sqrt(3.0);
      c3[i] = (3 * s[3][i] + s[2][i] - s[0][i]) / sqrt(6.0);
    }
    double term1 = dot(3, c1, c1) + dot(3, c2, c2) + dot(3, c3, c3), term2 = 0;
    cross3(c1, c2, t); term2 += dot(3, t, t);
    cross3(c2, c3, t); term2 += dot(3, t, t);
    cross3(c1, c3, t); term2 += dot(3, t, t);
    double dd = det3(c1, c2, c3);
    return fabs(dd) <= 1e-300 ? VERDICT_MAX : sqrt(term1 * term2) / (3 * dd);
  }
  case QM_V_SHAPE: {
    cross3(s[2], s[0], c); /* edge3 · (edge2 × edge0) with edge2 = P0 − P2 */
    double jac = dot(3, s[3], c);
    if (jac <= 0) return 0;
    double num = 3 * pow(sqrt(2.0) * jac, 2.0 / 3);
    double m2[3] = {-s[2][0], -s[2][1], -s[2][2]};
    double den = 1.5 * (l2[0] + l2[2] + l2[3]) - (dot(3, s[0], m2) + dot(3, m2, s[3]) + dot(3, s[3], s[0]));
    return den > 0 ? num / den : 0;
  }
  default: return NAN;
  }
}

/* Verdict's quadrilateral and hexahedron metrics (as in VTK 9.1), from their definitions,
 * with Verdict's conventions kept where they matter for the value a user compares with
 * ParaView: std::min/std::max semantics (a NaN argument is not skipped), results clamped
 * to ±1e30, 1e30 or 0 for degenerate cells as Verdict returns them, and a quadrilateral
 * whose last two vertices coincide evaluated as the triangle of its first three. */
#define VERDICT_MIN 1e-30
#define VMIN(a, b) ((b) < (a) ? (b) : (a))
#define VMAX(a, b) ((a) < (b) ? (b) : (a))
static double vclamp(double v) { return v > 0 ? VMIN(v, VERDICT_MAX) : VMAX(v, -VERDICT_MAX); }
/* normalize in place, return the length (a zero vector stays zero) */
static double vnormalize(double *a) {
  double l = norm(3, a);
  if (l != 0)
    for (int i = 0; i < 3; i++) a[i] /= l;
  return l;
}
/* Σ s_i P_i over the corners with signs s (the "principal axes" of Verdict) */
static void signed_sum(int n, const double *P, const int *s, double *r) {
  r[0] = r[1] = r[2] = 0;
  for (int i = 0; i < n; i++)
    for (int k = 0; k < 3; k++) r[k] += s[i] * P[3 * i + k];
}

/* the quadrilateral's unit normal from its corner triangles (Verdict's quad_normal: the
 * normal at P0, confirmed or overruled by those at P2 and P1) */
static void quad_face_normal(const double *P, double *n) {
  double a[3], b[3], n0[3], n1[3], n2[3];
  sub(3, P + 3, P, a); sub(3, P + 9, P, b); cross3(a, b, n0); vnormalize(n0);
  sub(3, P + 9, P + 6, a); sub(3, P + 3, P + 6, b); cross3(a, b, n2); vnormalize(n2);
  if (dot(3, n0, n2) > 0) {
    for (int k = 0; k < 3; k++) n[k] = 0.5 * (n0[k] + n2[k]);
    return;
  }
  sub(3, P + 6, P + 3, a); sub(3, P, P + 3, b); cross3(a, b, n1); vnormalize(n1);
  const double *o = dot(3, n0, n1) > 0 ? n0 : n2;
  for (int k = 0; k < 3; k++) n[k] = 0.5 * (o[k] + n1[k]);
}

/* Verdict's quad distortion: min |J| over the 2×2 Gauss points and the corners of a shell
 * of thickness 0.001 √A, relative to the area (1 for parallelograms) */
static double verdict_quad_distortion(const double *P) {
  double fn[3];
  quad_face_normal(P, fn);
  static const double xi[4] = {-1, 1, 1, -1}, eta[4] = {-1, -1, 1, 1};
  double dist = VERDICT_MAX;
  if (P[9] == P[6] && P[10] == P[7] && P[11] == P[8]) { /* collapsed: the triangle P0 P1 P2 */
    double f[3], s[3], c[3];
    for (int i = 0; i < 3; i++) {
      sub(3, P + 3 * i, P + 3 * ((i + 1) % 3), f);
      sub(3, P + 3 * i, P + 3 * ((i + 2) % 3), s);
      cross3(f, s, c);
      double cur = (dot(3, fn, c) > 0 ? 1 : -1) * norm(3, c);
      dist = VMIN(dist, cur);
    }
    return dist / (norm(3, c) / 2);
  }
  /* shape function derivatives at the Gauss points and at the nodes */
  double g = 1 / sqrt(3.0), gp[4][2] = {{-g, -g}, {g, -g}, {g, g}, {-g, g}};
  double N[4][4], d1[4][4], d2[4][4], n1[4][4], n2[4][4];
  for (int p = 0; p < 4; p++)
    for (int a = 0; a < 4; a++) {
      N[p][a] = 0.25 * (1 + xi[a] * gp[p][0]) * (1 + eta[a] * gp[p][1]);
      d1[p][a] = 0.25 * xi[a] * (1 + eta[a] * gp[p][1]);
      d2[p][a] = 0.25 * eta[a] * (1 + xi[a] * gp[p][0]);
      n1[p][a] = 0.25 * xi[a] * (1 + eta[a] * eta[p]);
      n2[p][a] = 0.25 * eta[a] * (1 + xi[a] * xi[p]);
    }
  double area = 0, aa[3], bb[3], cc[3], nrm[3], nn[4][3];
  for (int p = 0; p < 4; p++) {
    aa[0] = aa[1] = aa[2] = bb[0] = bb[1] = bb[2] = 0;
    for (int a = 0; a < 4; a++)
      for (int k = 0; k < 3; k++) { aa[k] += d1[p][a] * P[3 * a + k]; bb[k] += d2[p][a] * P[3 * a + k]; }
    cross3(aa, bb, nrm);
    area += norm(3, nrm);
  }
  for (int p = 0; p < 4; p++) {
    aa[0] = aa[1] = aa[2] = bb[0] = bb[1] = bb[2] = 0;
    for (int a = 0; a < 4; a++)
      for (int k = 0; k < 3; k++) { aa[k] += n1[p][a] * P[3 * a + k]; bb[k] += n2[p][a] * P[3 * a + k]; }
    cross3(aa, bb, nn[p]);
    vnormalize(nn[p]);
  }
  int flat = 1;
  for (int p = 0; p < 4; p++)
    if (fabs(dot(3, nn[0], nn[p])) < 0.99) { flat = 0; break; }
  double th = 0.001 * sqrt(area), zl = flat ? 0 : 0.5773502691896;
  int nz = flat ? 1 : 2;
  for (int p = 0; p < 4; p++)
    for (int z = 0; z < nz; z++) {
      zl = -zl;
      double tz = zl * th / 2;
      for (int k = 0; k < 3; k++) aa[k] = bb[k] = cc[k] = 0;
      for (int a = 0; a < 4; a++)
        for (int k = 0; k < 3; k++) {
          double xa = P[3 * a + k] + tz * nn[a][k];
          aa[k] += d1[p][a] * xa;
          bb[k] += d2[p][a] * xa;
          cc[k] += N[p][a] * th / 2 * nn[a][k];
        }
      cross3(aa, bb, nrm);
      double d = dot(3, cc, nrm);
      if (d < dist) dist = d;
    }
  for (int p = 0; p < 4; p++) {
    for (int z = 0; z < nz; z++) {
      zl = -zl;
      double tz = zl * th / 2;
      for (int k = 0; k < 3; k++) { aa[k] = bb[k] = 0; cc[k] = th / 2 * nn[p][k]; }
      for (int a = 0; a < 4; a++)
        for (int k = 0; k < 3; k++) {
          double xa = P[3 * a + k] + tz * nn[p][k];
          aa[k] += n1[p][a] * xa;
          bb[k] += n2[p][a] * xa;
        }
    }
    cross3(aa, bb, nrm);
    double d = (dot(3, fn, nrm) > 0 ? 1 : -1) * dot(3, cc, nrm);
    if (d < dist) dist = d;
  }
  return area * th != 0 ? dist * 8 / (area * th) : dist * 8;
}

/* Verdict's quadrilateral metrics. Like verdict_tet and verdict_hex, one switch over the
 * metrics, each case its few lines of Verdict's definition, in the order VTK lists them:
 * about 150 lines that a reader checks case by case against VTK's, which splitting would
 * only scatter */
double verdict_quad(const double *x2, int q) {
  double P[12], tri[6];
  for (int i = 0; i < 4; i++) { P[3 * i] = x2[2 * i]; P[3 * i + 1] = x2[2 * i + 1]; P[3 * i + 2] = 0; }
  for (int i = 0; i < 6; i++) tri[i] = x2[i];
  int collapsed = x2[6] == x2[4] && x2[7] == x2[5];
  double e[4][3], l2[4], l[4], cn[4][3], cl[4], A[4], u[3], t1[3], t2[3];
  for (int i = 0; i < 4; i++) sub(3, P + 3 * ((i + 1) % 4), P + 3 * i, e[i]);
  for (int i = 0; i < 4; i++) {
    l2[i] = dot(3, e[i], e[i]);
    l[i] = sqrt(l2[i]);
    cross3(e[(i + 3) % 4], e[i], cn[i]); /* corner i: e_{i-1} × e_i */
    cl[i] = norm(3, cn[i]);
  }
  /* signed corner areas against the unit normal of the principal axes */
  for (int k = 0; k < 3; k++) { t1[k] = e[0][k] - e[2][k]; t2[k] = e[1][k] - e[3][k]; }
  cross3(t1, t2, u);
  vnormalize(u);
  for (int i = 0; i < 4; i++) A[i] = dot(3, u, cn[i]);
  static const int sX1[4] = {-1, 1, 1, -1}, sX2[4] = {-1, -1, 1, 1}, sX12[4] = {1, -1, 1, -1};
  double X1[3], X2[3];
  signed_sum(4, P, sX1, X1);
  signed_sum(4, P, sX2, X2);
  switch (q) {
  case QM_V_AREA: return vclamp(0.25 * (A[0] + A[1] + A[2] + A[3]));
  case QM_V_ASPECT_RATIO: {
    /* VTK 9.1's Verdict: the longest edge times the perimeter over twice the two corner
     * areas at P1 and P3 (unsigned; newer Verdict uses the four signed corner areas) */
    double hm = VMAX(VMAX(l[0], l[1]), VMAX(l[2], l[3])), den = cl[1] + cl[3];
    if (den < VERDICT_MIN) return VERDICT_MAX;
    return vclamp(0.5 * hm * (l[0] + l[1] + l[2] + l[3]) / den);
  }
  case QM_V_CONDITION: {
    if (collapsed) return verdict_tri(tri, QM_V_CONDITION);
    double mx = 0;
    for (int i = 0; i < 4; i++) {
      /* |x_ξ|² + |x_η|² at corner i over its signed area */
      double c = A[i] < VERDICT_MIN ? VERDICT_MAX : (l2[i] + l2[(i + 3) % 4]) / A[i];
      mx = VMAX(mx, c);
    }
    return vclamp(mx) / 2;
  }
  case QM_V_DISTORTION: return verdict_quad_distortion(P);
  case QM_V_EDGE_RATIO: {
    double m2 = VMIN(VMIN(l2[0], l2[1]), VMIN(l2[2], l2[3])), M2 = VMAX(VMAX(l2[0], l2[1]), VMAX(l2[2], l2[3]));
    return m2 < VERDICT_MIN ? VERDICT_MAX : vclamp(sqrt(M2 / m2));
  }
  case QM_V_JACOBIAN:
    if (collapsed) return 2 * verdict_tri(tri, QM_V_AREA);
    return vclamp(VMIN(VMIN(A[0], A[1]), VMIN(A[2], A[3])));
  case QM_V_MAX_ANGLE: case QM_V_MIN_ANGLE: {
    if (collapsed) return verdict_tri(tri, q);
    int mx = q == QM_V_MAX_ANGLE;
    if (l[0] <= VERDICT_MIN || l[1] <= VERDICT_MIN || l[2] <= VERDICT_MIN || l[3] <= VERDICT_MIN) return mx ? 0 : 360;
    double amax = 0, amin = 360;
    for (int i = 0; i < 4; i++) {
      double a = acos(-dot(3, e[i], e[(i + 1) % 4]) / (l[i] * l[(i + 1) % 4]));
      amax = VMAX(a, amax);
      amin = VMIN(a, amin);
    }
    if (!mx) return vclamp(amin * 180 / M_PI);
    amax = amax * 180 / M_PI;
    if (A[0] < 0 || A[1] < 0 || A[2] < 0 || A[3] < 0) amax = 360 - amax; /* a reflex corner */
    return vclamp(amax);
  }
  case QM_V_MAX_ASPECT_FROBENIUS: case QM_V_MED_ASPECT_FROBENIUS: {
    if (cl[0] < VERDICT_MIN || cl[1] < VERDICT_MIN || cl[2] < VERDICT_MIN || cl[3] < VERDICT_MIN) return VERDICT_MAX;
    double s = 0, m = 0;
    for (int i = 0; i < 4; i++) {
      /* corner i+1 of Verdict's loop: edges i and i+1 */
      double f = (l2[i] + l2[(i + 1) % 4]) / cl[(i + 1) % 4];
      s += f;
      m = VMAX(m, f);
    }
    return vclamp(q == QM_V_MAX_ASPECT_FROBENIUS ? 0.5 * m : 0.125 * s);
  }
  case QM_V_MAX_EDGE_RATIOS: {
    double a = norm(3, X1), b = norm(3, X2);
    if (a < VERDICT_MIN || b < VERDICT_MIN) return VERDICT_MAX;
    return vclamp(VMAX(a / b, b / a));
  }
  case QM_V_ODDY: {
    double mx = 0;
    for (int i = 0; i < 4; i++) {
      double f[3], s[3];
      sub(3, P + 3 * i, P + 3 * ((i + 1) % 4), f);
      sub(3, P + 3 * i, P + 3 * ((i + 3) % 4), s);
      double g11 = dot(3, f, f), g12 = dot(3, f, s), g22 = dot(3, s, s), g = g11 * g22 - g12 * g12;
      double o = g < VERDICT_MIN ? VERDICT_MAX : ((g11 - g22) * (g11 - g22) + 4 * g12 * g12) / 2 / g;
      mx = VMAX(mx, o);
    }
    return vclamp(mx);
  }
  case QM_V_RADIUS_RATIO: {
    double d1[3], d2[3];
    sub(3, P + 6, P, d1);
    sub(3, P + 9, P + 3, d2);
    double h2 = VMAX(VMAX(VMAX(l2[0], l2[1]), VMAX(l2[2], l2[3])), VMAX(dot(3, d1, d1), dot(3, d2, d2)));
    double t0 = VMIN(VMIN(cl[0], cl[1]), VMIN(cl[2], cl[3]));
    if (t0 < VERDICT_MIN) return VERDICT_MAX;
    return vclamp(1 / (2 * sqrt(2.0)) * sqrt((l2[0] + l2[1] + l2[2] + l2[3]) * h2) / t0);
  }
  case QM_V_SCALED_JACOBIAN: case QM_V_SHEAR: {
    double sj;
    if (collapsed) sj = verdict_tri(tri, QM_V_SCALED_JACOBIAN);
    else if (l[0] < VERDICT_MIN || l[1] < VERDICT_MIN || l[2] < VERDICT_MIN || l[3] < VERDICT_MIN) sj = 0;
    else {
      sj = VERDICT_MAX;
      for (int i = 0; i < 4; i++) sj = VMIN(A[i] / (l[i] * l[(i + 3) % 4]), sj);
      sj = vclamp(sj);
    }
    if (q == QM_V_SHEAR) return sj <= VERDICT_MIN ? 0 : VMIN(sj, VERDICT_MAX);
    return sj;
  }
  case QM_V_SHAPE: {
    if (l2[0] <= VERDICT_MIN || l2[1] <= VERDICT_MIN || l2[2] <= VERDICT_MIN || l2[3] <= VERDICT_MIN) return 0;
    double s = VERDICT_MAX;
    for (int i = 0; i < 4; i++) s = VMIN(A[i] / (l2[i] + l2[(i + 3) % 4]), s);
    s *= 2;
    return s < VERDICT_MIN ? 0 : vclamp(s);
  }
  case QM_V_SKEW: {
    if (vnormalize(X1) < VERDICT_MIN || vnormalize(X2) < VERDICT_MIN) return 0;
    return VMIN(fabs(dot(3, X1, X2)), VERDICT_MAX);
  }
  case QM_V_STRETCH: {
    double d1[3], d2[3];
    sub(3, P + 6, P, d1);
    sub(3, P + 9, P + 3, d2);
    double dm = VMAX(dot(3, d1, d1), dot(3, d2, d2));
    if (dm < VERDICT_MIN) return VERDICT_MAX;
    return VMIN(sqrt(2.0) * sqrt(VMIN(VMIN(l2[0], l2[1]), VMIN(l2[2], l2[3])) / dm), VERDICT_MAX);
  }
  case QM_V_TAPER: {
    double X12[3];
    signed_sum(4, P, sX12, X12);
    double m = VMIN(norm(3, X1), norm(3, X2));
    if (m < VERDICT_MIN) return VERDICT_MAX;
    return VMIN(norm(3, X12) / m, VERDICT_MAX);
  }
  case QM_V_WARPAGE: {
    for (int i = 0; i < 4; i++)
      if (vnormalize(cn[i]) < VERDICT_MIN) return VERDICT_MIN;
    return vclamp(pow(VMIN(dot(3, cn[0], cn[2]), dot(3, cn[1], cn[3])), 3));
  }
  default: return NAN;
  }
}

/* Verdict's ratio with its guards: 1e30 when the denominator vanishes */
static double safe_ratio(double n, double d) {
  return fabs(n) <= VERDICT_MAX && fabs(d) >= VERDICT_MIN ? n / d : VERDICT_MAX;
}

/* Pronto's characteristic length V / (2 |∇V|) (Verdict's hex dimension): ∂V/∂x_I of the
 * trilinear volume V = ∫ det(∇x, ∇y, ∇z), integrated exactly by 2×2×2 Gauss points */
static double verdict_hex_dimension(const double *P) {
  static const double s[8][3] = {{-1, -1, -1}, {1, -1, -1}, {1, 1, -1}, {-1, 1, -1},
                                 {-1, -1, 1},  {1, -1, 1},  {1, 1, 1},  {-1, 1, 1}};
  double grad[8][3] = {{0}}, g = 1 / sqrt(3.0);
  for (int p = 0; p < 8; p++) {
    double r[3] = {s[p][0] * g, s[p][1] * g, s[p][2] * g}, dN[8][3], J[3][3] = {{0}};
    for (int a = 0; a < 8; a++) {
      double f[3] = {1 + s[a][0] * r[0], 1 + s[a][1] * r[1], 1 + s[a][2] * r[2]};
      dN[a][0] = s[a][0] * f[1] * f[2] / 8;
      dN[a][1] = s[a][1] * f[0] * f[2] / 8;
      dN[a][2] = s[a][2] * f[0] * f[1] / 8;
      for (int c = 0; c < 3; c++)
        for (int k = 0; k < 3; k++) J[c][k] += P[3 * a + c] * dN[a][k]; /* J[c] = ∇_ξ x_c */
    }
    double cof[3][3]; /* ∂ det / ∂(∇x_c) = ∇x_{c+1} × ∇x_{c+2} */
    for (int c = 0; c < 3; c++) cross3(J[(c + 1) % 3], J[(c + 2) % 3], cof[c]);
    for (int a = 0; a < 8; a++)
      for (int c = 0; c < 3; c++) grad[a][c] += dot(3, dN[a], cof[c]);
  }
  double V = 0, G = 0;
  for (int a = 0; a < 8; a++) {
    V += P[3 * a] * grad[a][0];
    G += dot(3, grad[a], grad[a]);
  }
  return sqrt(0.5 * V * V / G);
}

/* Verdict's hex distortion: min J over the 2×2×2 Gauss points and the corners, times 8,
 * over the volume (1 for parallelepipeds) */
static double verdict_hex_distortion(const double *P) {
  static const double s[8][3] = {{-1, -1, -1}, {1, -1, -1}, {1, 1, -1}, {-1, 1, -1},
                                 {-1, -1, 1},  {1, -1, 1},  {1, 1, 1},  {-1, 1, 1}};
  double g = 1 / sqrt(3.0), minJ = VERDICT_MAX, vol = 0;
  for (int pass = 0; pass < 2; pass++)
    for (int p = 0; p < 8; p++) {
      double w = pass ? 1 : g, r[3] = {s[p][0] * w, s[p][1] * w, s[p][2] * w}, J[3][3] = {{0}};
      for (int a = 0; a < 8; a++) {
        double f[3] = {1 + s[a][0] * r[0], 1 + s[a][1] * r[1], 1 + s[a][2] * r[2]};
        double dN[3] = {s[a][0] * f[1] * f[2] / 8, s[a][1] * f[0] * f[2] / 8, s[a][2] * f[0] * f[1] / 8};
        for (int k = 0; k < 3; k++)
          for (int c = 0; c < 3; c++) J[k][c] += dN[k] * P[3 * a + c]; /* J[k] = ∂x/∂ξ_k */
      }
      double det = det3(J[0], J[1], J[2]);
      if (minJ > det) minJ = det;
      if (!pass) vol += det;
    }
  double d = fabs(vol) > 0 ? minJ / vol * 8 : VERDICT_MAX;
  if (d > VERDICT_MAX) return VERDICT_MAX;
  if (d < -VERDICT_MAX) return -VERDICT_MAX;
  return isnan(d) ? VERDICT_MAX : d;
}

/* Verdict's hexahedron metrics: one switch over the metrics as verdict_quad (its comment) */
double verdict_hex(const double *P, int q) {
  static const int edges[12][2] = {{0, 1}, {1, 2}, {2, 3}, {3, 0}, {4, 5}, {5, 6},
                                   {6, 7}, {7, 4}, {0, 4}, {1, 5}, {2, 6}, {3, 7}};
  static const int diags[4][2] = {{0, 6}, {2, 4}, {1, 7}, {3, 5}};
  /* the three principal axes and the three cross derivatives (Verdict's efg) */
  static const int sg[6][8] = {{-1, 1, 1, -1, -1, 1, 1, -1}, {-1, -1, 1, 1, -1, -1, 1, 1},
                               {-1, -1, -1, -1, 1, 1, 1, 1}, {1, -1, 1, -1, 1, -1, 1, -1},
                               {1, -1, -1, 1, -1, 1, 1, -1}, {1, 1, -1, -1, -1, -1, 1, 1}};
  double el2[12], dl[4], X[6][3], Xl[6];
  for (int i = 0; i < 12; i++) {
    double t[3];
    sub(3, P + 3 * edges[i][1], P + 3 * edges[i][0], t);
    el2[i] = dot(3, t, t);
  }
  for (int i = 0; i < 4; i++) {
    double t[3];
    sub(3, P + 3 * diags[i][1], P + 3 * diags[i][0], t);
    dl[i] = norm(3, t);
  }
  for (int i = 0; i < 6; i++) {
    signed_sum(8, P, sg[i], X[i]);
    Xl[i] = norm(3, X[i]);
  }
  /* the corner matrices: edges to the three neighbours, right-handed (hex_corner_neighbors) */
  double C[8][3][3], det[8], cl2[8][3];
  for (int i = 0; i < 8; i++) {
    const int *nb = hex_corner_neighbors(i);
    for (int k = 0; k < 3; k++) {
      sub(3, P + 3 * nb[k], P + 3 * i, C[i][k]);
      cl2[i][k] = dot(3, C[i][k], C[i][k]);
    }
    det[i] = det3(C[i][0], C[i][1], C[i][2]);
  }
  switch (q) {
  case QM_V_CONDITION: case QM_V_MAX_ASPECT_FROBENIUS: case QM_V_MED_ASPECT_FROBENIUS: {
    double mx = 0, sum = 0;
    for (int i = 0; i < 8; i++) {
      double c;
      if (det[i] <= VERDICT_MIN) c = VERDICT_MAX;
      else {
        double t[3], t2 = 0;
        for (int k = 0; k < 3; k++) {
          cross3(C[i][k], C[i][(k + 1) % 3], t);
          t2 += dot(3, t, t);
        }
        c = sqrt((cl2[i][0] + cl2[i][1] + cl2[i][2]) * t2) / det[i];
      }
      mx = i ? VMAX(mx, c) : c;
      sum += c;
    }
    /* VTK 9.1 divides also the 1e30 of a degenerate corner (newer Verdict returns 1e30) */
    return q == QM_V_MED_ASPECT_FROBENIUS ? sum / 24 : mx / 3;
  }
  case QM_V_DIAGONAL: {
    double mn = VMIN(VMIN(dl[0], dl[1]), VMIN(dl[2], dl[3])), mx = VMAX(VMAX(dl[0], dl[1]), VMAX(dl[2], dl[3]));
    return vclamp(safe_ratio(mn, mx));
  }
  case QM_V_DIMENSION: return verdict_hex_dimension(P);
  case QM_V_DISTORTION: return verdict_hex_distortion(P);
  case QM_V_EDGE_RATIO: {
    double m2 = el2[0], M2 = el2[0];
    for (int i = 1; i < 12; i++) m2 = VMIN(m2, el2[i]);
    /* Verdict takes the longest of the first six edges only (see docs/mesh.md) */
    for (int i = 1; i < 6; i++) M2 = VMAX(M2, el2[i]);
    return m2 < VERDICT_MIN ? VERDICT_MAX : vclamp(sqrt(M2 / m2));
  }
  case QM_V_JACOBIAN: {
    double j = det3(X[0], X[1], X[2]) / 64;
    for (int i = 0; i < 8; i++) j = VMIN(j, det[i]);
    return vclamp(j);
  }
  case QM_V_MAX_EDGE_RATIOS: {
    double a = 0;
    for (int i = 0; i < 3; i++) {
      int k = (i + 1) % 3;
      a = VMAX(a, safe_ratio(VMAX(Xl[i], Xl[k]), VMIN(Xl[i], Xl[k])));
    }
    return vclamp(a);
  }
  case QM_V_ODDY: {
    double mx = 0;
    for (int i = -1; i < 8; i++) {
      const double *a = i < 0 ? X[0] : C[i][0], *b = i < 0 ? X[1] : C[i][1], *c = i < 0 ? X[2] : C[i][2];
      double dd = det3(a, b, c), o = VERDICT_MAX;
      if (dd > VERDICT_MIN) {
        double g11 = dot(3, a, a), g12 = dot(3, a, b), g13 = dot(3, a, c), g22 = dot(3, b, b), g23 = dot(3, b, c),
               g33 = dot(3, c, c);
        double G2 = g11 * g11 + 2 * g12 * g12 + 2 * g13 * g13 + g22 * g22 + 2 * g23 * g23 + g33 * g33;
        double tr = g11 + g22 + g33;
        o = (G2 - tr * tr / 3) / pow(dd, 4.0 / 3);
      }
      if (o > mx) mx = o;
    }
    return vclamp(mx);
  }
  case QM_V_SCALED_JACOBIAN: {
    double mn = VERDICT_MAX;
    for (int i = -1; i < 8; i++) {
      double a = i < 0 ? Xl[0] * Xl[0] : cl2[i][0], b = i < 0 ? Xl[1] * Xl[1] : cl2[i][1],
             c = i < 0 ? Xl[2] * Xl[2] : cl2[i][2];
      if (a <= VERDICT_MIN || b <= VERDICT_MIN || c <= VERDICT_MIN) return VERDICT_MAX;
      double j = (i < 0 ? det3(X[0], X[1], X[2]) : det[i]) / sqrt(a * b * c);
      if (j < mn) mn = j;
    }
    return vclamp(mn);
  }
  case QM_V_SHEAR: case QM_V_SHAPE: {
    double mn = 1;
    for (int i = 0; i < 8; i++) {
      double s2 = cl2[i][0] + cl2[i][1] + cl2[i][2], v;
      if (q == QM_V_SHEAR) {
        if (cl2[i][0] <= VERDICT_MIN || cl2[i][1] <= VERDICT_MIN || cl2[i][2] <= VERDICT_MIN) return 0;
        if (det[i] < VERDICT_MIN) return 0;
        v = det[i] / sqrt(cl2[i][0] * cl2[i][1] * cl2[i][2]);
      } else {
        if (!(det[i] > VERDICT_MIN)) return 0;
        v = 3 * pow(det[i], 2.0 / 3) / s2;
      }
      mn = VMIN(v, mn);
    }
    return mn <= VERDICT_MIN ? 0 : vclamp(mn);
  }
  case QM_V_SKEW: {
    double u[3][3];
    for (int i = 0; i < 3; i++) {
      for (int k = 0; k < 3; k++) u[i][k] = X[i][k];
      if (vnormalize(u[i]) <= VERDICT_MIN) return VERDICT_MAX;
    }
    double s = VMAX(VMAX(fabs(dot(3, u[0], u[1])), fabs(dot(3, u[0], u[2]))), fabs(dot(3, u[1], u[2])));
    return vclamp(s);
  }
  case QM_V_STRETCH: {
    double mn = sqrt(el2[0]);
    for (int i = 1; i < 12; i++) mn = VMIN(mn, sqrt(el2[i]));
    double mx = VMAX(VMAX(dl[0], dl[1]), VMAX(dl[2], dl[3]));
    return vclamp(sqrt(3.0) * safe_ratio(mn, mx));
  }
  case QM_V_TAPER: {
    /* cross derivative over the shorter of the two principal axes it joins */
    double t = 0;
    static const int pr[3][2] = {{0, 1}, {0, 2}, {1, 2}};
    for (int i = 0; i < 3; i++) t = VMAX(t, fabs(safe_ratio(Xl[3 + i], VMIN(Xl[pr[i][0]], Xl[pr[i][1]]))));
    return vclamp(t);
  }
  case QM_V_VOLUME:
    /* VTK 9.1's Verdict: 8 × the Jacobian at the centre, det(X1, X2, X3) / 64, exact for
     * parallelepipeds only (newer Verdict sums 24 tetrahedra; lugal's exact trilinear
     * volume is signed_measure) */
    return vclamp(det3(X[0], X[1], X[2]) / 64);
  default: return NAN;
  }
}

