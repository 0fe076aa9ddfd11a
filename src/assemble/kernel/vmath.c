/* vmath.c — the vector math routine of generated kernels: a transcendental function of the
 * coordinates evaluated at all quadrature points of an item at once (kernel.c,
 * expr_tape_vector_calls). With AVX2 it calls glibc's libmvec, four points per call, about
 * six times the throughput of scalar libm's sin here (1.6 against 10 ns); otherwise, or with
 * -lugal_vector_math 0 (which generates scalar calls instead), libm per point. Both JIT tiers
 * call this one routine, so libtcc's and the system compiler's kernels agree to the last
 * bit. libmvec's results are within 4 ulp of the correctly rounded value, as scalar libm's
 * are within 1: the same kernel may differ in its last bits between machines with and
 * without AVX2, and from lg.interpolate's pointwise values. */
#include "vmath.h"

#include "../../config.h"
#include "../../expr/expr.h"

#include <math.h>
#include <string.h>

#if defined(__x86_64__) && defined(__GNUC__) && LUGAL_HAVE_MVEC
#define LG_MVEC 1
#pragma GCC push_options
#pragma GCC target("avx2,fma")
#include <immintrin.h>
typedef __m256d (*vfn4)(__m256d);
__m256d _ZGVdN4v_sin(__m256d);
__m256d _ZGVdN4v_cos(__m256d);
__m256d _ZGVdN4v_tan(__m256d);
__m256d _ZGVdN4v_exp(__m256d);
__m256d _ZGVdN4v_log(__m256d);
__m256d _ZGVdN4v_tanh(__m256d);
__m256d _ZGVdN4v_sinh(__m256d);
__m256d _ZGVdN4v_cosh(__m256d);
__m256d _ZGVdN4v_atan(__m256d);
__m256d _ZGVdN4v_asin(__m256d);
__m256d _ZGVdN4v_acos(__m256d);

static vfn4 vec4(int fn) {
  switch (fn) {
  case FN_SIN: return _ZGVdN4v_sin;
  case FN_COS: return _ZGVdN4v_cos;
  case FN_TAN: return _ZGVdN4v_tan;
  case FN_EXP: return _ZGVdN4v_exp;
  case FN_LOG: return _ZGVdN4v_log;
  case FN_TANH: return _ZGVdN4v_tanh;
  case FN_SINH: return _ZGVdN4v_sinh;
  case FN_COSH: return _ZGVdN4v_cosh;
  case FN_ATAN: return _ZGVdN4v_atan;
  case FN_ASIN: return _ZGVdN4v_asin;
  case FN_ACOS: return _ZGVdN4v_acos;
  default: return NULL;
  }
}

/* whole vectors, then the tail padded in a vector of its own (lanes are independent, so a
 * point's value does not depend on where it falls) */
static void vmath_avx2(vfn4 f, double *v, int n) {
  int i = 0;
  for (; i + 4 <= n; i += 4) _mm256_storeu_pd(v + i, f(_mm256_loadu_pd(v + i)));
  if (i < n) {
    double t[4] = {0.5, 0.5, 0.5, 0.5};
    memcpy(t, v + i, sizeof(double) * (size_t)(n - i));
    _mm256_storeu_pd(t, f(_mm256_loadu_pd(t)));
    memcpy(v + i, t, sizeof(double) * (size_t)(n - i));
  }
}
#pragma GCC pop_options
#endif

static double scalar(int fn, double x) {
  switch (fn) {
  case FN_SIN: return sin(x);
  case FN_COS: return cos(x);
  case FN_TAN: return tan(x);
  case FN_EXP: return exp(x);
  case FN_LOG: return log(x);
  case FN_TANH: return tanh(x);
  case FN_SINH: return sinh(x);
  case FN_COSH: return cosh(x);
  case FN_ATAN: return atan(x);
  case FN_ASIN: return asin(x);
  case FN_ACOS: return acos(x);
  default: return NAN;
  }
}

int lg_vmath_simd(void) {
#ifdef LG_MVEC
  static int have = -1;
  if (have < 0) {
    __builtin_cpu_init();
    have = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
  }
  return have;
#else
  return 0;
#endif
}

void lg_vmath(int fn, double *v, int n) {
#ifdef LG_MVEC
  if (lg_vmath_simd()) {
    vfn4 f = vec4(fn);
    if (f) { vmath_avx2(f, v, n); return; }
  }
#endif
  for (int i = 0; i < n; i++) v[i] = scalar(fn, v[i]);
}
