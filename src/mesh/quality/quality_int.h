/* quality_int.h — what quality.c and quality_verdict.c share: small vector algebra and the
 * Verdict metrics of each cell type. Not part of the API. */
#ifndef LUGAL_QUALITY_INT_H
#define LUGAL_QUALITY_INT_H

#include "quality.h"

#include <math.h>

static inline void sub(int d, const double *a, const double *b, double *r) {
  for (int i = 0; i < d; i++) r[i] = a[i] - b[i];
}
static inline double dot(int d, const double *a, const double *b) {
  double s = 0;
  for (int i = 0; i < d; i++) s += a[i] * b[i];
  return s;
}
static inline double norm(int d, const double *a) { return sqrt(dot(d, a, a)); }
static inline double cross2(const double *a, const double *b) { return a[0] * b[1] - a[1] * b[0]; }
static inline void cross3(const double *a, const double *b, double *r) {
  r[0] = a[1] * b[2] - a[2] * b[1];
  r[1] = a[2] * b[0] - a[0] * b[2];
  r[2] = a[0] * b[1] - a[1] * b[0];
}
static inline double det3(const double *a, const double *b, const double *c) {
  double r[3];
  cross3(b, c, r);
  return dot(3, a, r);
}


/* Verdict's metrics (as in VTK 9.1) of one cell: q one of the QM_V_* measures; x the
 * vertices (2D or 3D coordinates as each function says) */
double verdict_tri(const double *x, int q);
double verdict_tet(const double *x, int q);
double verdict_quad(const double *x2, int q);
double verdict_hex(const double *P, int q);

#endif
