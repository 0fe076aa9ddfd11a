/* test_vmath.c — the kernels' vector math routine (src/assemble/kernel/vmath.c): every function
 * within a few ulp of libm's over its domain, a value independent of its place in the
 * array (whole vectors and padded tails give the same bits), and the scalar path exact. */
#include "../../src/assemble/kernel/vmath.h"
#include "../../src/expr/expr.h"
#include "check.h"

#include <math.h>
#include <stdint.h>
#include <string.h>

static double ulps(double a, double b) {
  if (a == b) return 0;
  double s = fabs(nextafter(b, INFINITY) - b);
  return fabs(a - b) / s;
}

int main(void) {
  static const struct { int fn; double (*f)(double); double lo, hi; const char *name; } fs[] = {
      {FN_SIN, sin, -50, 50, "sin"},     {FN_COS, cos, -50, 50, "cos"},     {FN_TAN, tan, -1.5, 1.5, "tan"},
      {FN_EXP, exp, -700, 700, "exp"},   {FN_LOG, log, 1e-300, 1e300, "log"}, {FN_TANH, tanh, -20, 20, "tanh"},
      {FN_SINH, sinh, -700, 700, "sinh"}, {FN_COSH, cosh, -700, 700, "cosh"}, {FN_ATAN, atan, -1e6, 1e6, "atan"},
      {FN_ASIN, asin, -1, 1, "asin"},    {FN_ACOS, acos, -1, 1, "acos"}};
  enum { N = 4099 };
  static double x[N], v[N], w[16];
  for (size_t k = 0; k < sizeof fs / sizeof fs[0]; k++) {
    for (int i = 0; i < N; i++) {
      double t = (double)i / (N - 1);
      x[i] = fs[k].fn == FN_LOG ? exp(log(fs[k].lo) + t * (log(fs[k].hi) - log(fs[k].lo))) : fs[k].lo + t * (fs[k].hi - fs[k].lo);
    }
    memcpy(v, x, sizeof v);
    lg_vmath(fs[k].fn, v, N);
    double worst = 0;
    for (int i = 0; i < N; i++) {
      double u = ulps(v[i], fs[k].f(x[i]));
      if (u > worst) worst = u;
    }
    CHECK(worst <= 4, "%s: %g ulp from libm (simd %d)", fs[k].name, worst, lg_vmath_simd());
    /* the same value wherever it falls: arrays of 1..9 values against the long run */
    int same = 1;
    for (int n = 1; n <= 9; n++)
      for (int off = 0; off < 3; off++) {
        memcpy(w, x + 1000 + off, sizeof(double) * (size_t)n);
        lg_vmath(fs[k].fn, w, n);
        for (int i = 0; i < n; i++) same &= w[i] == v[1000 + off + i];
      }
    CHECK(same, "%s: a value depends on its place in the array", fs[k].name);
  }
  /* special values pass through as libm's: NaN, infinities, out of the domain */
  double sp[6] = {NAN, INFINITY, -INFINITY, 2.0, -2.0, 0.0};
  memcpy(w, sp, sizeof sp);
  lg_vmath(FN_ASIN, w, 6);
  CHECK(isnan(w[0]) && isnan(w[1]) && isnan(w[3]) && isnan(w[4]) && w[5] == 0, "asin of special values");
  memcpy(w, sp, sizeof sp);
  lg_vmath(FN_EXP, w, 6);
  CHECK(isnan(w[0]) && w[1] == INFINITY && w[2] == 0 && w[5] == 1, "exp of special values");
  return CHECK_DONE();
}
