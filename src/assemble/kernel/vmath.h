/* vmath.h — the vector math routine generated kernels call (vmath.c) */
#ifndef LUGAL_VMATH_H
#define LUGAL_VMATH_H

/* v[i] = f(v[i]) for i < n, f the expr_fn fn (sin, cos, tan, exp, log, tanh, sinh, cosh,
 * atan, asin, acos) */
void lg_vmath(int fn, double *v, int n);
/* 1 when it runs libmvec's AVX2 routines, 0 when libm per value */
int lg_vmath_simd(void);

#endif
