/* test_amg.c — the aggregation multigrid of the Newton smoother (src/mesh/untangle_amg.c) as
 * the preconditioner of flexible conjugate gradients, against block Jacobi, on block
 * matrices like the smoother's Hessians: the 5-point Laplacian of an n×n grid (interior
 * vertices only, the boundary fixed) coupled into 2×2 blocks (an
 * elasticity-like operator: K ⊗ [[2, c], [c, 1]] plus a Laplacian stretched along x,
 * K_x ⊗ [[1, 0], [0, 3]]), in 2D, and in 3D the 7-point Laplacian of an n³ grid coupled into
 * 3×3 blocks (K ⊗ S, S symmetric positive definite).
 * Checks: the multigrid solves to a 1e-8 relative residual in a count of iterations that
 * grows little with n, where block Jacobi's grows about in proportion to n; the solution solves the system
 * (its residual recomputed); coarse levels are built; the result has the same bits on 1, 2
 * and 3 threads. ut_amg_pcg, the same solve with its own hierarchy, on fresh matrices. */
#include "../../src/mesh/untangle/untangle_int.h"

#include "check.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#ifdef _OPENMP
#include <omp.h>
#endif

/* the block matrix on the interior vertices of an n×n (n³) grid: the 5-point (7-point)
 * Laplacian in d×d blocks */
typedef struct {
  ut_bsr P;
  double *val;
  int nrow, d;
} bmat;

static void bmat_free(bmat *A) { free(A->P.off); free(A->P.col); free(A->val); }

static void build(bmat *A, int n, int d) {
  int m = n - 1, nrow = d == 2 ? m * m : m * m * m, nbmax = 7 * nrow;
  A->nrow = nrow;
  A->d = d;
  A->P.off = calloc((size_t)nrow + 1, sizeof(int));
  A->P.col = malloc(sizeof(int) * (size_t)nbmax);
  A->val = calloc((size_t)nbmax * d * d, sizeof(double));
  int nb = 0;
  for (int r = 0; r < nrow; r++) {
    int i = r % m, j = (r / m) % m, k = d == 3 ? r / (m * m) : 0;
    /* neighbours in sorted order: −z, −y, −x, self, +x, +y, +z */
    int cand[7][3] = {{0, 0, -1}, {0, -1, 0}, {-1, 0, 0}, {0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    for (int c = 0; c < 7; c++) {
      int ii = i + cand[c][0], jj = j + cand[c][1], kk = k + cand[c][2];
      if (d == 2 && cand[c][2]) continue;
      if (ii < 0 || jj < 0 || kk < 0 || ii >= m || jj >= m || (d == 3 && kk >= m)) continue;
      int col = d == 2 ? jj * m + ii : (kk * m + jj) * m + ii;
      A->P.col[nb] = col;
      double *b = A->val + (size_t)nb * d * d;
      double kxy = c == 3 ? 0 : -1, kx = cand[c][0] ? -1 : 0; /* off-diagonal weights */
      if (c == 3) { kxy = 2 * d; kx = 2; }
      if (d == 2) { /* K ⊗ [[2, .5], [.5, 1]] + 4 K_x ⊗ diag(1, 3) */
        b[0] = 2 * kxy + 4 * kx; b[1] = 0.5 * kxy; b[2] = 0.5 * kxy; b[3] = kxy + 12 * kx;
      } else { /* K ⊗ [[2, .5, 0], [.5, 1, .3], [0, .3, 1]] */
        double S[9] = {2, 0.5, 0, 0.5, 1, 0.3, 0, 0.3, 1};
        for (int e = 0; e < 9; e++) b[e] = kxy * S[e];
      }
      nb++;
    }
    A->P.off[r + 1] = nb;
  }
}

/* ut_fcg on A x = b from x = 0 to |r| ≤ 1e-8 |b|; iterations (−1: none converged) */
static int fcg(bmat *A, ut_amg *M, const float *valf, const double *dinv, const double *b, double *x) {
  long n = (long)A->nrow * A->d;
  double *w[4], *part = malloc(sizeof(double) * (2 * (n / UT_DOT_CHUNK) + 4));
  for (int k = 0; k < 4; k++) w[k] = malloc(sizeof(double) * n);
  int conv, its = ut_fcg(&A->P, A->val, valf, A->nrow, A->d, M, dinv, b, x, 1, 5000, 1e-16 * ut_dot(b, b, n, part), part, w, &conv);
  for (int k = 0; k < 4; k++) free(w[k]);
  free(part);
  return conv ? its : -1;
}

/* |b − A x| / |b| */
static double residual(bmat *A, const double *b, const double *x) {
  long n = (long)A->nrow * A->d;
  double *y = malloc(sizeof(double) * n), s = 0, t = 0;
  ut_bsr_mult(&A->P, A->val, A->nrow, A->d, x, y);
  for (long i = 0; i < n; i++) { s += (b[i] - y[i]) * (b[i] - y[i]); t += b[i] * b[i]; }
  free(y);
  return sqrt(s / t);
}

static void run(int n, int d, int *its_amg, int *its_bj, int *levels) {
  bmat A;
  build(&A, n, d);
  long nn = (long)A.nrow * A.d;
  double *b = malloc(sizeof(double) * nn), *x = malloc(sizeof(double) * nn), *x2 = malloc(sizeof(double) * nn);
  unsigned s = 7;
  for (long i = 0; i < nn; i++) { s = s * 1103515245u + 12345u; b[i] = (double)((s >> 8) & 0xffff) / 65536.0 - 0.5; }
  /* the inverse diagonal blocks (their shift goes into the matrix once), then the hierarchy */
  double *dinv = malloc(sizeof(double) * nn * d);
  int *dpos = malloc(sizeof(int) * A.nrow);
  for (int i = 0; i < A.nrow; i++) {
    int q = A.P.off[i];
    while (A.P.col[q] != i) q++;
    dpos[i] = q;
  }
  ut_block_jacobi(A.val, dpos, A.nrow, d, dinv);
  ut_amg M;
  int bad = ut_amg_build(&M, &A.P, NULL, A.nrow, d);
  CHECK(!bad, "n %d d %d: hierarchy built", n, d);
  ut_amg_values(&M, A.val, dinv);
  *levels = M.nlev;
  *its_amg = fcg(&A, &M, NULL, dinv, b, x);
  CHECK(*its_amg > 0 && residual(&A, b, x) <= 1.01e-8, "n %d d %d: multigrid residual %.3g after %d iterations", n, d,
        residual(&A, b, x), *its_amg);
  /* the same bits again, and on 1, 2 and 3 threads */
  for (int th = 0; th <= 3; th++) {
#ifdef _OPENMP
    int keep = omp_get_max_threads();
    if (th) omp_set_num_threads(th);
#endif
    int again = fcg(&A, &M, NULL, dinv, b, x2);
#ifdef _OPENMP
    omp_set_num_threads(keep);
#endif
    CHECK(again == *its_amg && !memcmp(x, x2, sizeof(double) * nn), "n %d d %d: the same bits (threads %d)", n, d, th);
  }
  ut_amg_free(&M);
  *its_bj = fcg(&A, NULL, NULL, dinv, b, x2);
  CHECK(*its_bj > 0 && residual(&A, b, x2) <= 1.01e-8, "n %d d %d: block Jacobi residual %.3g", n, d, residual(&A, b, x2));
  free(b); free(x); free(x2); free(dinv); free(dpos);
  bmat_free(&A);
}

/* ut_amg_pcg (the untangler's harmonic restarts of large pieces): from x = 0 to a 1e-8
 * relative residual, recomputed here, in few iterations; with too few it says so */
static void run_pcg(int n, int d, int maxits) {
  bmat A;
  build(&A, n, d);
  long nn = (long)A.nrow * A.d;
  double *b = malloc(sizeof(double) * nn), *x = calloc(nn, sizeof(double)), res;
  unsigned s = 11;
  for (long i = 0; i < nn; i++) { s = s * 1103515245u + 12345u; b[i] = (double)((s >> 8) & 0xffff) / 65536.0 - 0.5; }
  int its, st = ut_amg_pcg(&A.P, A.val, A.nrow, d, 1, b, x, 1000, 1e-8, &its, &res);
  printf("ut_amg_pcg n %d d %d: status %d, %d iterations, residual %.3g\n", n, d, st, its, res);
  CHECK(st == 0 && its > 0 && its <= maxits && res <= 1e-8 && residual(&A, b, x) <= 1.01e-8,
        "ut_amg_pcg n %d d %d: status %d, %d iterations (at most %d), residual %.3g", n, d, st, its, maxits, residual(&A, b, x));
  memset(x, 0, sizeof(double) * nn);
  st = ut_amg_pcg(&A.P, A.val, A.nrow, d, 1, b, x, 3, 1e-8, &its, &res);
  CHECK(st == 2 && its == 3 && res > 1e-8 && res < 1, "ut_amg_pcg n %d d %d, 3 iterations: status %d, %d, residual %.3g", n, d,
        st, its, res);
  free(b); free(x);
  bmat_free(&A);
}

/* the scalar operator (d = 1: each 2×2 block's first entry, an anisotropic 5-point
 * Laplacian) with two right sides on one hierarchy, as the untangler's harmonic systems */
static void run_pcg_scalar(int n, int maxits) {
  bmat A;
  build(&A, n, 2);
  int nrow = A.nrow, nb = A.P.off[nrow];
  double *v = malloc(sizeof(double) * nb), *b = malloc(sizeof(double) * 2 * nrow), *x = calloc(2 * (size_t)nrow, sizeof(double)),
         *y = malloc(sizeof(double) * nrow), res;
  for (int q = 0; q < nb; q++) v[q] = A.val[(size_t)q * 4];
  unsigned s = 5;
  for (int i = 0; i < 2 * nrow; i++) { s = s * 1103515245u + 12345u; b[i] = (double)((s >> 8) & 0xffff) / 65536.0 - 0.5; }
  int its, st = ut_amg_pcg(&A.P, v, nrow, 1, 2, b, x, 1000, 1e-8, &its, &res);
  printf("ut_amg_pcg n %d d 1, two right sides: status %d, at most %d iterations, residual %.3g\n", n, st, its, res);
  CHECK(st == 0 && its > 0 && its <= maxits && res <= 1e-8, "scalar n %d: status %d, %d iterations, residual %.3g", n, st, its, res);
  for (int k = 0; k < 2; k++) {
    double rr = 0, bb = 0;
    ut_bsr_mult(&A.P, v, nrow, 1, x + (size_t)k * nrow, y);
    for (int i = 0; i < nrow; i++) {
      double e = b[(size_t)k * nrow + i] - y[i];
      rr += e * e;
      bb += b[(size_t)k * nrow + i] * b[(size_t)k * nrow + i];
    }
    CHECK(sqrt(rr / bb) <= 1.01e-8, "scalar n %d, right side %d: residual recomputed %.3g", n, k, sqrt(rr / bb));
  }
  free(v); free(b); free(x); free(y);
  bmat_free(&A);
}

/* the 5-point operator of an n×n grid (interior vertices) whose y couplings are wy times
 * the x ones, in 1×1 blocks; its multigrid from the pattern alone (plain aggregation) and
 * from the values (aggregates through the strong couplings only, the x lines when wy is
 * small): iterations of each to a 1e-8 residual; levels of the second */
static void run_strength(int n, double wy, int *its_plain, int *its_strong, int *levels) {
  int m = n - 1, nrow = m * m;
  bmat A = {{calloc((size_t)nrow + 1, sizeof(int)), malloc(sizeof(int) * 5 * (size_t)nrow)}, malloc(sizeof(double) * 5 * (size_t)nrow), nrow, 1};
  int nb = 0;
  for (int r = 0; r < nrow; r++) {
    int i = r % m, j = r / m;
    int cand[5][2] = {{0, -1}, {-1, 0}, {0, 0}, {1, 0}, {0, 1}};
    for (int c = 0; c < 5; c++) {
      int ii = i + cand[c][0], jj = j + cand[c][1];
      if (ii < 0 || jj < 0 || ii >= m || jj >= m) continue;
      A.P.col[nb] = jj * m + ii;
      A.val[nb++] = c == 2 ? 2 + 2 * wy : cand[c][0] ? -1 : -wy;
    }
    A.P.off[r + 1] = nb;
  }
  double *b = malloc(sizeof(double) * nrow), *x = malloc(sizeof(double) * nrow), *dinv = malloc(sizeof(double) * nrow);
  int *dpos = malloc(sizeof(int) * nrow);
  unsigned s = 3;
  for (int i = 0; i < nrow; i++) { s = s * 1103515245u + 12345u; b[i] = (double)((s >> 8) & 0xffff) / 65536.0 - 0.5; }
  for (int i = 0; i < nrow; i++) {
    int q = A.P.off[i];
    while (A.P.col[q] != i) q++;
    dpos[i] = q;
  }
  ut_block_jacobi(A.val, dpos, nrow, 1, dinv);
  for (int strong = 0; strong < 2; strong++) {
    ut_amg M;
    int bad = ut_amg_build(&M, &A.P, strong ? A.val : NULL, nrow, 1);
    CHECK(!bad, "n %d, y couplings %g, %s: hierarchy built", n, wy, strong ? "strong couplings" : "plain");
    if (bad) { ut_amg_free(&M); continue; }
    ut_amg_values(&M, A.val, dinv);
    int its = fcg(&A, &M, NULL, dinv, b, x);
    CHECK(its > 0 && residual(&A, b, x) <= 1.01e-8, "n %d, y couplings %g: residual %.3g", n, wy, residual(&A, b, x));
    if (strong) { *its_strong = its; *levels = M.nlev; }
    else *its_plain = its;
    ut_amg_free(&M);
  }
  free(b); free(x); free(dinv); free(dpos);
  bmat_free(&A);
}

/* the Newton smoother's products in single precision (M->single): its inexact directions
 * need no more; the same count of iterations to within two, a residual recomputed in double
 * of at most 1e-6 */
static void run_single(int n) {
  bmat A;
  build(&A, n, 2);
  long nn = (long)A.nrow * 2;
  double *b = malloc(sizeof(double) * nn), *x = malloc(sizeof(double) * nn), *dinv = malloc(sizeof(double) * nn * 2);
  int *dpos = malloc(sizeof(int) * A.nrow), its[2];
  unsigned s = 9;
  for (long i = 0; i < nn; i++) { s = s * 1103515245u + 12345u; b[i] = (double)((s >> 8) & 0xffff) / 65536.0 - 0.5; }
  for (int i = 0; i < A.nrow; i++) {
    int q = A.P.off[i];
    while (A.P.col[q] != i) q++;
    dpos[i] = q;
  }
  ut_block_jacobi(A.val, dpos, A.nrow, 2, dinv);
  ut_amg M;
  CHECK(!ut_amg_build(&M, &A.P, A.val, A.nrow, 2), "n %d: hierarchy built", n);
  ut_amg_values(&M, A.val, dinv);
  for (int single = 0; single < 2; single++) {
    its[single] = fcg(&A, &M, single ? M.L[0].valf : NULL, dinv, b, x);
    double res = residual(&A, b, x);
    CHECK(its[single] > 0 && res <= (single ? 1e-6 : 1.01e-8), "n %d, single %d: %d iterations, residual %.3g", n, single,
          its[single], res);
  }
  printf("single-precision products, n %d: %d iterations (double: %d)\n", n, its[1], its[0]);
  CHECK(abs(its[1] - its[0]) <= 2, "n %d: single %d against double %d iterations", n, its[1], its[0]);
  /* block Jacobi with a copy of its own (ut_to_single), to a 1e-6 residual: the same count
   * within 2% */
  long nv = (long)A.P.off[A.nrow] * 4;
  float *vf = malloc(sizeof(float) * nv);
  ut_to_single(A.val, vf, nv);
  long nn2 = nn;
  double *part = malloc(sizeof(double) * (2 * (nn2 / UT_DOT_CHUNK) + 4)), *w[4], lim = 1e-12 * ut_dot(b, b, nn2, part);
  for (int k = 0; k < 4; k++) w[k] = malloc(sizeof(double) * nn2);
  int conv[2];
  for (int single = 0; single < 2; single++) {
    its[single] = ut_fcg(&A.P, A.val, single ? vf : NULL, A.nrow, 2, NULL, dinv, b, x, 1, 5000, lim, part, w, &conv[single]);
    double res = residual(&A, b, x);
    CHECK(conv[single] && res <= 1.01e-6, "block Jacobi n %d, single %d: %d iterations, residual %.3g", n, single, its[single], res);
  }
  printf("block Jacobi, single-precision products, n %d: %d iterations (double: %d)\n", n, its[1], its[0]);
  CHECK(abs(its[1] - its[0]) <= its[0] / 50 + 1, "block Jacobi n %d: single %d against double %d iterations", n, its[1], its[0]);
  for (int k = 0; k < 4; k++) free(w[k]);
  free(vf); free(part);
  ut_amg_free(&M);
  free(b); free(x); free(dinv); free(dpos);
  bmat_free(&A);
}

int main(void) {
  int a1, j1, l1, a2, j2, l2;
  run_pcg(256, 2, 60);
  run_pcg(40, 3, 25);
  run_pcg_scalar(256, 60);
  run(64, 2, &a1, &j1, &l1);
  run(256, 2, &a2, &j2, &l2);
  printf("2D: n 64: multigrid %d iterations (%d levels), block Jacobi %d; n 256: %d (%d levels), %d\n", a1, l1, j1, a2, l2, j2);
  CHECK(l1 >= 2 && l2 > l1, "coarse levels: %d, %d", l1, l2);
  /* the anisotropic term (13:1) costs plain aggregation iterations, but not growth with n */
  CHECK(a2 <= 60 && 2 * a2 <= 3 * a1, "2D multigrid iterations %d (n 64: %d)", a2, a1);
  CHECK(j2 >= 10 * a2 && j2 >= 3 * j1, "2D block Jacobi iterations %d (n 64: %d), multigrid %d", j2, j1, a2);
  run(16, 3, &a1, &j1, &l1);
  run(40, 3, &a2, &j2, &l2);
  printf("3D: n 16: multigrid %d iterations (%d levels), block Jacobi %d; n 40: %d (%d levels), %d\n", a1, l1, j1, a2, l2, j2);
  CHECK(a2 <= 25 && 2 * a2 <= 3 * a1, "3D multigrid iterations %d (n 16: %d)", a2, a1);
  CHECK(j2 >= 5 * a2 && j2 >= 2 * j1, "3D block Jacobi iterations %d (n 16: %d), multigrid %d", j2, j1, a2);
  /* strongly anisotropic couplings: aggregates across the weak ones stall plain aggregation */
  int p1, s1, lv;
  run_strength(128, 1e-3, &p1, &s1, &lv);
  printf("y couplings 1e-3, n 128: plain aggregation %d iterations, strong couplings %d (%d levels)\n", p1, s1, lv);
  CHECK(lv >= 3 && 3 * s1 <= p1, "strong couplings %d iterations (%d levels), plain %d", s1, lv, p1);
  run_single(256);
  return CHECK_DONE();
}
