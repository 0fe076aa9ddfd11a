/* dense.c — small dense symmetric matrices: see dense.h. */
#include "dense.h"

#include <math.h>

/* the rotation (c, s) that zeroes the off-diagonal entry apq of the symmetric 2×2
 * [app apq; apq aqq] (the smaller angle), as the cyclic method takes it */
static inline void jacobi_rotation(double app, double aqq, double apq, double *c, double *s) {
  double theta = (aqq - app) / (2 * apq);
  double t = (theta >= 0 ? 1 : -1) / (fabs(theta) + sqrt(theta * theta + 1));
  *c = 1 / sqrt(t * t + 1);
  *s = t * *c;
}

/* the cyclic Jacobi method for any n (the 3×3 closed form below falls back on it) */
static inline void sym_eigen_jacobi(int n, double *a, double *v, double off_abs, double off_rel) {
  for (int i = 0; i < n; i++)
    for (int j = 0; j < n; j++) v[i * n + j] = i == j;
  for (int sweep = 0; sweep < 100; sweep++) {
    double off = 0, diag = 0;
    for (int i = 0; i < n; i++) {
      diag += a[i * n + i] * a[i * n + i];
      for (int j = i + 1; j < n; j++) off += a[i * n + j] * a[i * n + j];
    }
    if (off < off_abs || !(off > off_rel * diag)) break;
    for (int p = 0; p < n; p++)
      for (int q = p + 1; q < n; q++) {
        double apq = a[p * n + q];
        if (fabs(apq) < 1e-300) continue;
        double c, s;
        jacobi_rotation(a[p * n + p], a[q * n + q], apq, &c, &s);
        for (int k = 0; k < n; k++) { /* a P, then Pᵀ (a P), and V P */
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

void dense_sym_eigen(int n, double *a, double *v, double off_abs, double off_rel) {
  sym_eigen_jacobi(n, a, v, off_abs, off_rel);
}

/* ---------------------------------------------------------------- 3×3 in closed form */

static void cross3(const double *a, const double *b, double *c) {
  c[0] = a[1] * b[2] - a[2] * b[1];
  c[1] = a[2] * b[0] - a[0] * b[2];
  c[2] = a[0] * b[1] - a[1] * b[0];
}

/* the eigenvalues (Rayleigh quotients of a) of the orthonormal vectors e[0..2], in
 * ascending order into w with their vectors as the columns of v */
static void eigen3_sorted(const double *a, double e[3][3], double *w, double *v) {
  int o[3] = {0, 1, 2};
  double q[3];
  for (int k = 0; k < 3; k++) {
    q[k] = 0;
    for (int i = 0; i < 3; i++) q[k] += e[k][i] * (a[i * 3 + 0] * e[k][0] + a[i * 3 + 1] * e[k][1] + a[i * 3 + 2] * e[k][2]);
  }
  for (int k = 1; k < 3; k++)
    for (int j = k; j > 0 && q[o[j]] < q[o[j - 1]]; j--) { int t = o[j]; o[j] = o[j - 1]; o[j - 1] = t; }
  for (int k = 0; k < 3; k++) {
    w[k] = q[o[k]];
    for (int i = 0; i < 3; i++) v[i * 3 + k] = e[o[k]][i];
  }
}

void dense_sym_eigen3(const double *a, double *w, double *v) {
  double mx = 0, e[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  for (int i = 0; i < 3; i++)
    for (int j = i; j < 3; j++) mx = fmax(mx, fabs(a[i * 3 + j]));
  if (!isfinite(mx)) { /* not finite: what the cyclic method makes of it */
    double t[9], vt[9];
    for (int i = 0; i < 9; i++) t[i] = a[i];
    sym_eigen_jacobi(3, t, vt, 0, 1e-30);
    for (int i = 0; i < 9; i++) v[i] = vt[i];
    for (int i = 0; i < 3; i++) w[i] = t[i * 3 + i];
    return;
  }
  /* scaled to entries in [−1, 1]; q the mean eigenvalue, c = b − q I, p² = |c|²/6 */
  double sc = mx > 0 ? 1 / mx : 0, b01 = a[1] * sc, b02 = a[2] * sc, b12 = a[5] * sc;
  double q = (a[0] + a[4] + a[8]) * sc / 3, c00 = a[0] * sc - q, c11 = a[4] * sc - q, c22 = a[8] * sc - q;
  double p = sqrt((c00 * c00 + c11 * c11 + c22 * c22 + 2 * (b01 * b01 + b02 * b02 + b12 * b12)) / 6);
  /* a multiple of I to rounding (or 0): the axes */
  if (!(p > 1e-14)) { eigen3_sorted(a, e, w, v); return; }
  /* the eigenvalues q + p β of (c/p)'s characteristic equation β³ − 3β − 2r = 0,
   * r = det(c/p)/2 = cos 3φ: β = 2 cos φ, 2 cos(φ ± 2π/3) */
  double det = c00 * (c11 * c22 - b12 * b12) - b01 * (b01 * c22 - b12 * b02) + b02 * (b01 * b12 - c11 * b02);
  double r = fmax(-1, fmin(1, det / (2 * p * p * p))), phi = acos(r) / 3, cf = cos(phi), sf = sin(phi);
  /* first the eigenvector of the eigenvalue farthest from the other two, the largest
   * 2 cos φ where r ≥ 0, else the smallest 2 cos(φ + 2π/3) (where acos is least accurate, at
   * r = ±1, φ = 0 or π/3, these are stationary in φ): the largest cross product of two rows
   * of c − pβ I, which has rank 2 with its other two eigenvalues at least p √3 from 0 */
  double l0 = r >= 0 ? 2 * p * cf : p * (-cf - sqrt(3.0) * sf);
  double r0[3] = {c00 - l0, b01, b02}, r1[3] = {b01, c11 - l0, b12}, r2[3] = {b02, b12, c22 - l0};
  double x[3][3], n[3];
  cross3(r0, r1, x[0]);
  cross3(r0, r2, x[1]);
  cross3(r1, r2, x[2]);
  int best = 0;
  for (int i = 0; i < 3; i++) {
    n[i] = x[i][0] * x[i][0] + x[i][1] * x[i][1] + x[i][2] * x[i][2];
    if (n[i] > n[best]) best = i;
  }
  if (!(n[best] > 0)) { eigen3_sorted(a, e, w, v); return; } /* cannot happen for p > 0 */
  double inv = 1 / sqrt(n[best]);
  for (int i = 0; i < 3; i++) e[0][i] = x[best][i] * inv;
  /* an orthonormal basis (u, t) of e0's complement, where the other two eigenvectors are
   * those of the 2×2 matrix of c, by one rotation (as in the cyclic method): not from their
   * eigenvalues above, which acos gives to √ε only where they are close (r near ±1) */
  const double *e0 = e[0];
  double u[3], t[3];
  if (fabs(e0[0]) > fabs(e0[1])) {
    double s = 1 / sqrt(e0[0] * e0[0] + e0[2] * e0[2]);
    u[0] = -e0[2] * s; u[1] = 0; u[2] = e0[0] * s;
  } else {
    double s = 1 / sqrt(e0[1] * e0[1] + e0[2] * e0[2]);
    u[0] = 0; u[1] = e0[2] * s; u[2] = -e0[1] * s;
  }
  cross3(e0, u, t);
  double cu[3], ct[3];
  cu[0] = c00 * u[0] + b01 * u[1] + b02 * u[2];
  cu[1] = b01 * u[0] + c11 * u[1] + b12 * u[2];
  cu[2] = b02 * u[0] + b12 * u[1] + c22 * u[2];
  ct[0] = c00 * t[0] + b01 * t[1] + b02 * t[2];
  ct[1] = b01 * t[0] + c11 * t[1] + b12 * t[2];
  ct[2] = b02 * t[0] + b12 * t[1] + c22 * t[2];
  double m00 = u[0] * cu[0] + u[1] * cu[1] + u[2] * cu[2],
         m01 = 0.5 * (u[0] * ct[0] + u[1] * ct[1] + u[2] * ct[2] + t[0] * cu[0] + t[1] * cu[1] + t[2] * cu[2]),
         m11 = t[0] * ct[0] + t[1] * ct[1] + t[2] * ct[2], rc = 1, rs = 0;
  if (m01 != 0) jacobi_rotation(m00, m11, m01, &rc, &rs);
  for (int i = 0; i < 3; i++) {
    e[1][i] = rc * u[i] - rs * t[i];
    e[2][i] = rs * u[i] + rc * t[i];
  }
  /* the eigenvalues as Rayleigh quotients of a: accurate where acos is not */
  eigen3_sorted(a, e, w, v);
}
