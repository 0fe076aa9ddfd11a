/* dense.c — small dense symmetric matrices: see dense.h. */
#include "dense.h"

#include <math.h>

/* the method for any n; inlined below with a constant n = 3 too, whose loops the compiler
 * unrolls (the projected Newton smoother's 3D corner Hessians take two 3×3 eigensystems per
 * corner: 5–10% of its Hessian time), with the same result */
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
        double theta = (a[q * n + q] - a[p * n + p]) / (2 * apq);
        double t = (theta >= 0 ? 1 : -1) / (fabs(theta) + sqrt(theta * theta + 1));
        double c = 1 / sqrt(t * t + 1), s = t * c;
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
  if (n == 3) sym_eigen_jacobi(3, a, v, off_abs, off_rel);
  else sym_eigen_jacobi(n, a, v, off_abs, off_rel);
}
