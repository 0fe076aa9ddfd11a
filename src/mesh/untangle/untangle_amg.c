/* untangle_amg.c — the block-sparse algebra of the projected Newton smoother
 * (untangle_newton.c): products with the Hessian's d×d blocks, its block Jacobi
 * preconditioner, and an aggregation multigrid for its conjugate gradients on large meshes.
 *
 * Block Jacobi's conjugate gradients need more iterations as the mesh grows (50–240 per
 * Newton step on a million-triangle spiral, three quarters of the smoother's time). The
 * multigrid keeps the count nearly flat: aggregates of a vertex and its strongly coupled
 * neighbours (Vaněk's plain aggregation on the Hessian's block graph, its weak couplings
 * dropped, built once per Newton run from the values of the step that builds it: the pattern
 * does not change between steps, and the couplings' strengths little), coarse matrices as sums of the fine
 * blocks (the Galerkin product with piecewise constant prolongation, d×d identity blocks),
 * one damped block Jacobi sweep before and after each coarse correction, and on every coarse
 * level two flexible conjugate-gradient steps preconditioned by the next (Notay and
 * Vassilevski's K-cycle, which makes plain aggregation converge independently of the number
 * of levels), down to a level small enough for a dense Cholesky factor. The outer conjugate
 * gradients are the flexible variant (the K-cycle is not a fixed linear operator).
 * Every sum is in a fixed order and every threaded loop element-wise, so the result has the
 * same bits for any number of threads. */
#include "untangle_int.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* y = H x on the pattern, rows on threads, blocks of type T: double, or float for the
 * cycle's products (a preconditioner needs no more, and these products were most of the
 * Newton smoother's memory traffic). Each output sums its row's products in D chains, one
 * per column of the blocks, added at the end: a single chain in the row's order waited on
 * the adder's latency (two dependent additions per 2×2 block). The order is fixed, so the
 * bits do not depend on the number of threads. D is a constant in the loop itself (OpenMP's
 * outlined body takes a function's parameter d as a variable, and unrolls nothing) */
#ifdef _OPENMP
#define UT_PAR_ROWS _Pragma("omp parallel for schedule(static) if (nrow > 2048)")
#else
#define UT_PAR_ROWS
#endif
#define BSR_MULT_D(name, T, D)                                                                       \
  static void name(const ut_bsr *P, const T *val, int nrow, const double *b, const double *x, double *y) { \
    UT_PAR_ROWS for (int fi = 0; fi < nrow; fi++) {                                                  \
      double s[D][D];                                                                                \
      for (int a = 0; a < D; a++)                                                                    \
        for (int e = 0; e < D; e++) s[a][e] = 0;                                                     \
      for (int q = P->off[fi]; q < P->off[fi + 1]; q++) {                                            \
        const T *bl = val + (size_t)q * (D * D);                                                     \
        const double *xc = x + (size_t)P->col[q] * D;                                                \
        for (int a = 0; a < D; a++)                                                                  \
          for (int e = 0; e < D; e++) s[a][e] += (double)bl[a * D + e] * xc[e];                      \
      }                                                                                              \
      for (int a = 0; a < D; a++) {                                                                  \
        double t = s[a][0];                                                                          \
        for (int e = 1; e < D; e++) t += s[a][e];                                                    \
        y[(size_t)fi * D + a] = b ? b[(size_t)fi * D + a] - t : t;                                   \
      }                                                                                              \
    }                                                                                                \
  }
BSR_MULT_D(bsr_mult_1, double, 1)
BSR_MULT_D(bsr_mult_2, double, 2)
BSR_MULT_D(bsr_mult_3, double, 3)
BSR_MULT_D(bsr_mult_f1, float, 1)
BSR_MULT_D(bsr_mult_f2, float, 2)
BSR_MULT_D(bsr_mult_f3, float, 3)

/* y = H x, or with b the residual y = b − H x in the same pass (the same bits as the product
 * followed by the subtraction, one pass less over memory); with valf, H's single-precision
 * copy, the products in single precision (a preconditioner's or Newton's inexact solves need
 * no more, and these products were most of the Newton smoother's memory traffic). d is 1
 * (the untangler's harmonic systems), 2 or 3 (the smoother's Hessians) */
static void bsr_mult(const ut_bsr *P, const double *val, const float *valf, int nrow, int d, const double *b,
                     const double *x, double *y) {
  if (valf) {
    if (d == 1) bsr_mult_f1(P, valf, nrow, b, x, y);
    else if (d == 2) bsr_mult_f2(P, valf, nrow, b, x, y);
    else bsr_mult_f3(P, valf, nrow, b, x, y);
  } else if (d == 1) bsr_mult_1(P, val, nrow, b, x, y);
  else if (d == 2) bsr_mult_2(P, val, nrow, b, x, y);
  else bsr_mult_3(P, val, nrow, b, x, y);
}

void ut_bsr_mult(const ut_bsr *P, const double *val, int nrow, int d, const double *x, double *y) {
  bsr_mult(P, val, NULL, nrow, d, NULL, x, y);
}

/* a level's product in the cycle (b: the residual b − A x), with its single-precision copy
 * where there is one */
static void level_mult(const ut_amg_level *L, int d, const double *b, const double *x, double *y) {
  bsr_mult(&L->P, L->val, L->valf, L->n, d, b, x, y);
}

void ut_block_jacobi(double *val, const int *dpos, int nrow, int d, double *dinv) {
  int dd = d * d;
#ifdef _OPENMP
#pragma omp parallel for schedule(static) if (nrow > 2048)
#endif
  for (int fi = 0; fi < nrow; fi++) {
    double *b = val + (size_t)dpos[fi] * dd, *w = dinv + (size_t)fi * dd, tr = 0;
    for (int a = 0; a < d; a++) tr += b[a * d + a];
    double mu = tr > 0 ? 1e-10 * tr / d : 1e-300;
    for (int a = 0; a < d; a++) b[a * d + a] += mu;
    double det;
    if (d == 1) {
      det = b[0];
      w[0] = 1 / det;
    } else if (d == 2) {
      det = b[0] * b[3] - b[1] * b[2];
      w[0] = b[3] / det; w[1] = -b[1] / det; w[2] = -b[2] / det; w[3] = b[0] / det;
    } else {
      w[0] = b[4] * b[8] - b[5] * b[7]; w[1] = b[2] * b[7] - b[1] * b[8]; w[2] = b[1] * b[5] - b[2] * b[4];
      w[3] = b[5] * b[6] - b[3] * b[8]; w[4] = b[0] * b[8] - b[2] * b[6]; w[5] = b[2] * b[3] - b[0] * b[5];
      w[6] = b[3] * b[7] - b[4] * b[6]; w[7] = b[1] * b[6] - b[0] * b[7]; w[8] = b[0] * b[4] - b[1] * b[3];
      det = b[0] * w[0] + b[1] * w[3] + b[2] * w[6];
      for (int k = 0; k < 9; k++) w[k] /= det;
    }
    if (!(det > 0) || !isfinite(det)) { /* not positive definite: the diagonal's scale */
      memset(w, 0, sizeof(double) * dd);
      for (int a = 0; a < d; a++) w[a * d + a] = tr > 0 ? d / tr : 1;
    }
  }
}

/* z = D⁻¹ r row by row, for a constant D (a variable d's loops were not unrolled: 8% of a
 * 200 000-triangle spiral's smoothing in instructions); the smoother's z = ω D⁻¹ r (acc 0)
 * and z += ω D⁻¹ r (acc 1) in the same pass, with the same roundings as the separate ones */
#define BLOCK_APPLY_D(name, D)                                                                    \
  static void name(const double *dinv, int nrow, const double *r, double *z, double om, int acc) { \
    UT_PAR_ROWS for (int fi = 0; fi < nrow; fi++) {                                               \
      const double *w = dinv + (size_t)fi * (D * D), *rr = r + (size_t)fi * D;                     \
      for (int a = 0; a < D; a++) {                                                               \
        double s = 0;                                                                             \
        for (int e = 0; e < D; e++) s += w[a * D + e] * rr[e];                                    \
        double *zz = z + (size_t)fi * D + a;                                                      \
        if (acc) *zz += om * s;                                                                   \
        else *zz = s * om; /* om 1: s itself */                                                   \
      }                                                                                           \
    }                                                                                             \
  }
BLOCK_APPLY_D(block_apply_1, 1)
BLOCK_APPLY_D(block_apply_2, 2)
BLOCK_APPLY_D(block_apply_3, 3)

static void block_apply(const double *dinv, int nrow, int d, const double *r, double *z, double om, int acc) {
  if (d == 1) block_apply_1(dinv, nrow, r, z, om, acc);
  else if (d == 2) block_apply_2(dinv, nrow, r, z, om, acc);
  else block_apply_3(dinv, nrow, r, z, om, acc);
}

void ut_block_apply(const double *dinv, int nrow, int d, const double *r, double *z) { block_apply(dinv, nrow, d, r, z, 1, 0); }

/* ---------------------------------------------------------------- the hierarchy */

/* the coarsest level: at most this many block rows, solved by a dense Cholesky factor */
#define AMG_COARSEST 200

/* the strong couplings of a level's values: block q of row i, column j, is strong when its
 * Frobenius norm is at least θ √(|A_ii| |A_jj|) (Vaněk, Mandel and Brezina's strength of
 * connection, their θ = 0.08). A barrier's Hessian grows as 1/h² in a cell of size h, and a
 * random star's untangled mesh mixes sizes: there aggregates across the weak couplings made
 * the multigrid's conjugate gradients take 50–90 iterations per Newton step, 4–19 without
 * them (bench/RESULTS.md); on the spirals' even cells every coupling is strong. A stronger
 * θ = 0.25 left the star's coarsening stalled above the dense solve (block Jacobi kept) */
#define AMG_STRENGTH 0.08
/* the strength, and coarsen's block positions below, row by row on threads (UT_PAR_FOR: each
 * row writes its own entries, the same result for any thread count; the million-triangle
 * spiral's took 0.04 and 0.07 s of its 0.41 s build on one) */
static unsigned char *strength(const ut_bsr *P, const double *val, int n, int d, const int *dpos, double theta) {
  size_t nb = (size_t)P->off[n];
  int dd = d * d;
  unsigned char *st = malloc(nb + 1);
  double *nd = malloc(sizeof(double) * ((size_t)n + 1));
  if (!st || !nd) { free(st); free(nd); return NULL; }
  UT_PAR_FOR for (int i = 0; i < n; i++) {
    const double *b = val + (size_t)dpos[i] * dd;
    double t = 0;
    for (int e = 0; e < dd; e++) t += b[e] * b[e];
    nd[i] = sqrt(t);
  }
  UT_PAR_FOR for (int i = 0; i < n; i++)
    for (int q = P->off[i]; q < P->off[i + 1]; q++) {
      const double *b = val + (size_t)q * dd;
      double t = 0;
      for (int e = 0; e < dd; e++) t += b[e] * b[e];
      st[q] = P->col[q] == i || t >= theta * theta * nd[i] * nd[P->col[q]];
    }
  free(nd);
  return st;
}

/* aggregates of the block graph P (n rows), through its strong couplings (st; NULL: all):
 * a row with a strong neighbour none of whose strong neighbours is taken yet starts an
 * aggregate with all of them; a row left over joins the first strongly coupled aggregate of
 * that first pass (a row without strong neighbours: the first coupled one); what remains
 * groups with its untaken strong neighbours. Returns the number of aggregates */
static int aggregate(const ut_bsr *P, int n, const unsigned char *st, int *agg, int *first) {
  int nc = 0;
#define STRONG(q) (!st || st[q])
  for (int i = 0; i < n; i++) agg[i] = -1;
  for (int i = 0; i < n; i++) {
    if (agg[i] >= 0) continue;
    int free = 1, nstrong = 0;
    for (int q = P->off[i]; q < P->off[i + 1] && free; q++)
      if (STRONG(q)) { free = agg[P->col[q]] < 0; nstrong++; }
    if (!free || nstrong < 2) continue;
    for (int q = P->off[i]; q < P->off[i + 1]; q++)
      if (STRONG(q)) agg[P->col[q]] = nc;
    agg[i] = nc++;
  }
  memcpy(first, agg, sizeof(int) * (size_t)n);
  for (int i = 0; i < n; i++) {
    if (agg[i] >= 0) continue;
    int any = -1;
    for (int q = P->off[i]; q < P->off[i + 1]; q++)
      if (first[P->col[q]] >= 0) {
        if (STRONG(q)) { agg[i] = first[P->col[q]]; break; }
        if (any < 0) any = first[P->col[q]];
      }
    if (agg[i] < 0) {
      int isolated = 1;
      for (int q = P->off[i]; q < P->off[i + 1] && isolated; q++) isolated = P->col[q] == i || !STRONG(q);
      if (isolated) agg[i] = any;
    }
  }
  for (int i = 0; i < n; i++) {
    if (agg[i] >= 0) continue;
    for (int q = P->off[i]; q < P->off[i + 1]; q++)
      if (STRONG(q) && agg[P->col[q]] < 0) agg[P->col[q]] = nc;
    agg[i] = nc++;
  }
#undef STRONG
  return nc;
}

static int int_cmp(const void *a, const void *b) { return (*(const int *)a > *(const int *)b) - (*(const int *)a < *(const int *)b); }

/* level l + 1 from level l's pattern: its aggregates, their members, the coarse pattern and
 * where each fine block adds in it */
static int coarsen(ut_amg *A, int l, const double *val) {
  ut_amg_level *F = &A->L[l], *Cl = &A->L[l + 1];
  int n = F->n;
  int *first = malloc(sizeof(int) * ((size_t)n + 1));
  F->agg = malloc(sizeof(int) * ((size_t)n + 1));
  unsigned char *st = val ? strength(&F->P, val, n, A->d, F->dpos, AMG_STRENGTH) : NULL;
  if (!first || !F->agg) { free(first); free(st); return 1; }
  int nc = aggregate(&F->P, n, st, F->agg, first);
  free(first);
  free(st);
  Cl->n = nc;
  F->mem_off = calloc((size_t)nc + 1, sizeof(int));
  F->mem = malloc(sizeof(int) * ((size_t)n + 1));
  Cl->P.off = calloc((size_t)nc + 1, sizeof(int));
  int *mark = malloc(sizeof(int) * ((size_t)nc + 1)), *row = NULL;
  if (!F->mem_off || !F->mem || !Cl->P.off || !mark) { free(mark); return 1; }
  for (int i = 0; i < n; i++) F->mem_off[F->agg[i] + 1]++;
  for (int c = 0; c < nc; c++) F->mem_off[c + 1] += F->mem_off[c];
  int *pos = malloc(sizeof(int) * ((size_t)nc + 1));
  if (!pos) { free(mark); return 1; }
  memcpy(pos, F->mem_off, sizeof(int) * (size_t)nc);
  for (int i = 0; i < n; i++) F->mem[pos[F->agg[i]]++] = i; /* members in row order */
  free(pos);
  /* the coarse pattern: counted, then filled and sorted row by row */
  for (int c = 0; c < nc; c++) mark[c] = -1;
  for (int pass = 0; pass < 2; pass++) {
    for (int c = 0; c < nc; c++) {
      int cnt = 0;
      if (pass) row = Cl->P.col + Cl->P.off[c];
      for (int k = F->mem_off[c]; k < F->mem_off[c + 1]; k++) {
        int i = F->mem[k];
        for (int q = F->P.off[i]; q < F->P.off[i + 1]; q++) {
          int cc = F->agg[F->P.col[q]];
          if (mark[cc] == 2 * c + pass) continue;
          mark[cc] = 2 * c + pass;
          if (pass) row[cnt] = cc;
          cnt++;
        }
      }
      if (!pass) Cl->P.off[c + 1] = cnt;
      else qsort(row, (size_t)cnt, sizeof(int), int_cmp);
    }
    if (!pass) {
      for (int c = 0; c < nc; c++) Cl->P.off[c + 1] += Cl->P.off[c];
      if (!(Cl->P.col = malloc(sizeof(int) * ((size_t)Cl->P.off[nc] + 1)))) { free(mark); return 1; }
    }
  }
  free(mark);
  size_t nb = (size_t)F->P.off[n];
  if (!(F->cpos = malloc(sizeof(size_t) * (nb + 1)))) return 1;
  UT_PAR_FOR for (int i = 0; i < n; i++)
    for (int q = F->P.off[i]; q < F->P.off[i + 1]; q++) F->cpos[q] = ut_bsr_find(&Cl->P, F->agg[i], F->agg[F->P.col[q]]);
  return 0;
}

/* the coarse level's blocks from the fine values fv: coarse row by coarse row on threads,
 * each the sum of its members' rows' blocks, the members in row order, so every coarse block
 * receives its terms in the order of one loop over the fine blocks (the same bits for any
 * number of threads) */
static void coarse_sums(const ut_amg_level *F, ut_amg_level *Cl, const double *fv, int dd) {
  int nc = Cl->n;
#ifdef _OPENMP
#pragma omp parallel for schedule(static) if (nc > 2048)
#endif
  for (int c = 0; c < nc; c++) {
    memset(Cl->val + (size_t)Cl->P.off[c] * dd, 0, sizeof(double) * (size_t)(Cl->P.off[c + 1] - Cl->P.off[c]) * dd);
    for (int k = F->mem_off[c]; k < F->mem_off[c + 1]; k++) {
      int i = F->mem[k];
      for (int q = F->P.off[i]; q < F->P.off[i + 1]; q++) {
        double *t = Cl->val + F->cpos[q] * dd;
        const double *s = fv + (size_t)q * dd;
        for (int e = 0; e < dd; e++) t[e] += s[e];
      }
    }
  }
}

static int level_buffers(ut_amg_level *L, int d, int owns_values) {
  size_t n = (size_t)L->n * d + 1, nb = (size_t)L->P.off[L->n];
  L->owns = owns_values;
  if (owns_values && !(L->val = malloc(sizeof(double) * (nb * d * d + 1)))) return 1;
  L->valf = malloc(sizeof(float) * (nb * d * d + 1)); /* NULL: the products in double */
  L->dpos = malloc(sizeof(int) * ((size_t)L->n + 1));
  if (owns_values) L->dinv = malloc(sizeof(double) * ((size_t)L->n * d * d + 1));
  /* every level smooths in t and v1; the K-cycle's four and the restricted residual and
   * correction (in, out) live on the coarse levels only */
  double **bufs[] = {&L->t, &L->v1, &L->w1, &L->v2, &L->w2, &L->r1, &L->in, &L->out};
  for (size_t k = 0; k < (owns_values ? sizeof bufs / sizeof *bufs : 2); k++)
    if (!(*bufs[k] = malloc(sizeof(double) * n))) return 1;
  if (!L->dpos || (owns_values && !L->dinv)) return 1;
  for (int i = 0; i < L->n; i++) {
    int q = L->P.off[i];
    while (q < L->P.off[i + 1] && L->P.col[q] != i) q++;
    if (q == L->P.off[i + 1]) return 1; /* every row holds its diagonal */
    L->dpos[i] = q;
  }
  return 0;
}

int ut_amg_build(ut_amg *A, const ut_bsr *P, const double *val, int n, int d) {
  memset(A, 0, sizeof *A);
  A->d = d;
  A->L[0].n = n;
  A->L[0].P = *P; /* the Hessian's pattern: not owned */
  if (level_buffers(&A->L[0], d, 0)) return 1;
  int l = 0;
  while (A->L[l].n > AMG_COARSEST && l + 1 < UT_AMG_MAXLEV) {
    A->nlev = l + 2; /* ut_amg_free releases level l + 1 from here on */
    if (coarsen(A, l, val)) return 1;
    if (level_buffers(&A->L[l + 1], d, 1)) return 1;
    if (val) { /* the coarse values, for the next level's strong couplings */
      coarse_sums(&A->L[l], &A->L[l + 1], val, d * d);
      val = A->L[l + 1].val;
    }
    l++;
    if (A->L[l].n * 10 > A->L[l - 1].n * 9) break; /* no longer coarsening */
  }
  A->nlev = l + 1;
  /* coarsening stalled above the dense solve's size (its factor, m³/3 per Newton step,
   * would cost more than it saves): the caller keeps block Jacobi */
  if (A->L[l].n > 2 * AMG_COARSEST) return 1;
  size_t m = (size_t)A->L[l].n * d;
  if (!(A->chol = malloc(sizeof(double) * (m * m + 1)))) return 1;
  if (!(A->part = malloc(sizeof(double) * ((size_t)n * d / UT_DOT_CHUNK + 2)))) return 1;
  return 0;
}

void ut_amg_free(ut_amg *A) {
  for (int l = 0; l < (A->nlev > 0 ? A->nlev : 1); l++) { /* level 0 even when building it failed */
    ut_amg_level *L = &A->L[l];
    if (l) { free(L->P.off); free(L->P.col); }
    if (L->owns) { free(L->val); free(L->dinv); }
    free(L->valf); free(L->dpos); free(L->agg); free(L->mem_off); free(L->mem); free(L->cpos);
    free(L->t); free(L->v1); free(L->w1); free(L->v2); free(L->w2); free(L->r1); free(L->in); free(L->out);
  }
  free(A->chol);
  free(A->part);
  memset(A, 0, sizeof *A);
}

/* a bound of the largest eigenvalue of D⁻¹A (Gershgorin on the block rows of D⁻¹A) and the
 * smoother's damping 4/(3 λ) */
#ifdef _OPENMP
#define UT_PAR_ROWS_MAX _Pragma("omp parallel for schedule(static) reduction(max : lam) if (nr > 2048)")
#else
#define UT_PAR_ROWS_MAX
#endif
/* for a constant D (see BSR_MULT_D); the maximum over the rows (lam): the same for any
 * thread count */
#define JACOBI_DAMPING_D(name, D)                                                \
  static double name(const ut_amg_level *L) {                                    \
    double lam = 0;                                                              \
    int nr = L->n;                                                               \
    UT_PAR_ROWS_MAX for (int i = 0; i < nr; i++) {                          \
      const double *w = L->dinv + (size_t)i * (D * D);                           \
      double rs[D];                                                              \
      for (int a = 0; a < D; a++) rs[a] = 0;                                     \
      for (int q = L->P.off[i]; q < L->P.off[i + 1]; q++) {                      \
        const double *b = L->val + (size_t)q * (D * D);                          \
        for (int a = 0; a < D; a++)                                              \
          for (int c = 0; c < D; c++) {                                          \
            double s = 0;                                                        \
            for (int e = 0; e < D; e++) s += w[a * D + e] * b[e * D + c];        \
            rs[a] += fabs(s);                                                    \
          }                                                                      \
      }                                                                          \
      for (int a = 0; a < D; a++) lam = fmax(lam, rs[a]);                        \
    }                                                                            \
    return lam > 0 && isfinite(lam) ? 4.0 / (3.0 * lam) : 0.5;                   \
  }
JACOBI_DAMPING_D(jacobi_damping_1, 1)
JACOBI_DAMPING_D(jacobi_damping_2, 2)
JACOBI_DAMPING_D(jacobi_damping_3, 3)

static double jacobi_damping(const ut_amg_level *L, int d) {
  return d == 1 ? jacobi_damping_1(L) : d == 2 ? jacobi_damping_2(L) : jacobi_damping_3(L);
}

/* the coarsest level's matrix, dense, factored by Cholesky with a growing diagonal shift
 * when it is not positive definite (a projected Hessian may be singular) */
static void coarsest_factor(ut_amg *A) {
  ut_amg_level *L = &A->L[A->nlev - 1];
  int d = A->d, m = L->n * d, dd = d * d;
  double *c = A->chol, tr = 0;
  for (int attempt = 0; attempt < 12; attempt++) {
    memset(c, 0, sizeof(double) * (size_t)m * m);
    for (int i = 0; i < L->n; i++)
      for (int q = L->P.off[i]; q < L->P.off[i + 1]; q++)
        for (int a = 0; a < d; a++)
          for (int b = 0; b < d; b++) c[(size_t)(i * d + a) * m + L->P.col[q] * d + b] = L->val[(size_t)q * dd + a * d + b];
    if (!attempt)
      for (int k = 0; k < m; k++) tr += fabs(c[(size_t)k * m + k]);
    double shift = (tr > 0 ? tr / m : 1) * 1e-12 * pow(100, attempt);
    for (int k = 0; k < m; k++) c[(size_t)k * m + k] += shift;
    int ok = 1;
    for (int j = 0; j < m && ok; j++) {
      double s = c[(size_t)j * m + j];
      for (int k = 0; k < j; k++) s -= c[(size_t)j * m + k] * c[(size_t)j * m + k];
      if (!(s > 0) || !isfinite(s)) { ok = 0; break; }
      double ljj = sqrt(s);
      c[(size_t)j * m + j] = ljj;
      for (int i = j + 1; i < m; i++) {
        double t = c[(size_t)i * m + j];
        for (int k = 0; k < j; k++) t -= c[(size_t)i * m + k] * c[(size_t)j * m + k];
        c[(size_t)i * m + j] = t / ljj;
      }
    }
    if (ok) return;
  }
  /* never positive definite: the identity scaled to the diagonal (a weak but safe solve) */
  memset(c, 0, sizeof(double) * (size_t)m * m);
  for (int k = 0; k < m; k++) c[(size_t)k * m + k] = tr > 0 ? sqrt(tr / m) : 1;
}

void ut_to_single(const double *v, float *f, long n) {
  UT_PAR_FOR
  for (long i = 0; i < n; i++) f[i] = (float)v[i];
}

/* the level's values in single precision (after block Jacobi's shift of the diagonal) */
static void single_copy(ut_amg_level *L, int dd) {
  if (L->valf) ut_to_single(L->val, L->valf, (long)L->P.off[L->n] * dd);
}

void ut_amg_values(ut_amg *A, double *val, const double *dinv) {
  int d = A->d, dd = d * d;
  A->L[0].val = val;
  A->L[0].dinv = (double *)dinv;
  A->L[0].omega = jacobi_damping(&A->L[0], d);
  single_copy(&A->L[0], dd);
  for (int l = 0; l + 1 < A->nlev; l++) {
    ut_amg_level *F = &A->L[l], *Cl = &A->L[l + 1];
    /* coarse row by coarse row on threads: its blocks are the sums of its members' rows'
     * blocks, the members in row order, so every coarse block receives its terms in the
     * order of one loop over the fine blocks (the same bits for any number of threads) */
    coarse_sums(F, Cl, F->val, dd);
    if (l + 2 < A->nlev) {
      ut_block_jacobi(Cl->val, Cl->dpos, Cl->n, d, Cl->dinv);
      Cl->omega = jacobi_damping(Cl, d);
      single_copy(Cl, dd);
    }
  }
  coarsest_factor(A);
}

static void coarsest_solve(const ut_amg *A, const double *b, double *x) {
  const ut_amg_level *L = &A->L[A->nlev - 1];
  int m = L->n * A->d;
  const double *c = A->chol;
  for (int i = 0; i < m; i++) {
    double s = b[i];
    for (int k = 0; k < i; k++) s -= c[(size_t)i * m + k] * x[k];
    x[i] = s / c[(size_t)i * m + i];
  }
  for (int i = m - 1; i >= 0; i--) {
    double s = x[i];
    for (int k = i + 1; k < m; k++) s -= c[(size_t)k * m + i] * x[k];
    x[i] = s / c[(size_t)i * m + i];
  }
}

static void kcycle(ut_amg *A, int l, const double *b, double *x);

/* one cycle at level l < nlev − 1: z ≈ A_l⁻¹ r, a Jacobi sweep, the coarse correction, a
 * Jacobi sweep (the same damping both ways) */
static void vcycle(ut_amg *A, int l, const double *r, double *z) {
  ut_amg_level *L = &A->L[l], *Cl = &A->L[l + 1];
  int d = A->d;
  double om = L->omega, *t = L->t;
  block_apply(L->dinv, L->n, d, r, z, om, 0);
  level_mult(L, d, r, z, t);
  /* restriction: each aggregate sums its members' residuals, in row order */
  int nc = Cl->n;
#ifdef _OPENMP
#pragma omp parallel for schedule(static) if (nc > 2048)
#endif
  for (int c = 0; c < nc; c++)
    for (int a = 0; a < d; a++) {
      double s = 0;
      for (int k = L->mem_off[c]; k < L->mem_off[c + 1]; k++) s += t[(size_t)L->mem[k] * d + a];
      Cl->in[(size_t)c * d + a] = s;
    }
  if (l + 1 == A->nlev - 1) coarsest_solve(A, Cl->in, Cl->out);
  else kcycle(A, l + 1, Cl->in, Cl->out);
  int nr = L->n;
#ifdef _OPENMP
#pragma omp parallel for schedule(static) if (nr > 2048)
#endif
  for (int i = 0; i < nr; i++)
    for (int a = 0; a < d; a++) z[(size_t)i * d + a] += Cl->out[(size_t)L->agg[i] * d + a];
  level_mult(L, d, r, z, t);
  block_apply(L->dinv, L->n, d, t, z, om, 1);
}

/* level l ≥ 1: x ≈ A_l⁻¹ b by two flexible conjugate-gradient steps preconditioned with the
 * cycle (the second only when the first left more than a quarter of the residual) */
static void kcycle(ut_amg *A, int l, const double *b, double *x) {
  ut_amg_level *L = &A->L[l];
  int d = A->d;
  long n = (long)L->n * d;
  /* vcycle(l) works in L->t and L->v1: these two steps use the other buffers */
  double *v1 = L->v2, *w1 = L->w1, *v2 = L->r1, *w2 = L->w2;
  vcycle(A, l, b, v1);
  level_mult(L, d, NULL, v1, w1);
  double rho1 = ut_dot(v1, w1, n, A->part), a1 = ut_dot(v1, b, n, A->part);
  if (!(rho1 > 0)) {
    memcpy(x, v1, sizeof(double) * n);
    return;
  }
  double c1 = a1 / rho1, bb = ut_dot(b, b, n, A->part);
  /* the residual b − c1 w1 into x for now (x is written last) */
  UT_PAR_FOR
  for (long i = 0; i < n; i++) x[i] = b[i] - c1 * w1[i];
  if (ut_dot(x, x, n, A->part) <= 0.0625 * bb) {
    UT_PAR_FOR
    for (long i = 0; i < n; i++) x[i] = c1 * v1[i];
    return;
  }
  vcycle(A, l, x, v2);
  level_mult(L, d, NULL, v2, w2);
  double g = ut_dot(v2, w1, n, A->part), be = ut_dot(v2, w2, n, A->part), a2 = ut_dot(v2, x, n, A->part);
  double rho2 = be - g * g / rho1;
  if (!(rho2 > 0)) {
    UT_PAR_FOR
    for (long i = 0; i < n; i++) x[i] = c1 * v1[i];
    return;
  }
  double k1 = c1 - g * a2 / (rho1 * rho2), k2 = a2 / rho2;
  UT_PAR_FOR
  for (long i = 0; i < n; i++) x[i] = k1 * v1[i] + k2 * v2[i];
}

void ut_amg_apply(ut_amg *A, const double *r, double *z) {
  if (A->nlev == 1) { coarsest_solve(A, r, z); return; }
  vcycle(A, 0, r, z);
}

/* ut_fcg's vector passes fused, each sum in ut_dot's chunks and order (the same bits as the
 * separate loops; a million-triangle spiral's conjugate gradients are bound by memory) */

/* x += al p, r −= al q; returns the new r · r */
static double update_dot(double *x, double *r, const double *p, const double *q, double al, long n, double *part) {
  long nch = (n + UT_DOT_CHUNK - 1) / UT_DOT_CHUNK;
  UT_PAR_CHUNKS
  for (long c = 0; c < nch; c++) {
    double s = 0;
    for (long i = c * UT_DOT_CHUNK; i < UT_CHUNK_END(c); i++) {
      x[i] += al * p[i];
      r[i] -= al * q[i];
      s += r[i] * r[i];
    }
    part[c] = s;
  }
  return ut_chunk_sum(part, nch);
}

/* r · z and z · q in one pass (part: two chunk arrays) */
static void dot2(const double *r, const double *z, const double *q, long n, double *part, double *rz, double *zq) {
  long nch = (n + UT_DOT_CHUNK - 1) / UT_DOT_CHUNK;
  UT_PAR_CHUNKS
  for (long c = 0; c < nch; c++) {
    double s = 0, t = 0;
    for (long i = c * UT_DOT_CHUNK; i < UT_CHUNK_END(c); i++) {
      s += r[i] * z[i];
      t += z[i] * q[i];
    }
    part[c] = s;
    part[nch + c] = t;
  }
  *rz = ut_chunk_sum(part, nch);
  *zq = ut_chunk_sum(part + nch, nch);
}

int ut_fcg(const ut_bsr *P, const double *val, const float *valf, int n, int d, ut_amg *M, const double *dinv,
           const double *b, double *x, int x0, int maxit, double lim2, double *part, double *w[4], int *conv) {
  long m = (long)n * d;
  double *r = w[0], *z = w[1], *p = w[2], *q = w[3], rz;
  int it = 0;
  if (x0) {
    UT_PAR_FOR
    for (long i = 0; i < m; i++) { x[i] = 0; r[i] = b[i]; }
  } else
    bsr_mult(P, val, valf, n, d, b, x, r);
  if ((*conv = ut_dot(r, r, m, part) <= lim2)) return 0;
#define PRECOND(rr, zz) (M ? ut_amg_apply(M, rr, zz) : ut_block_apply(dinv, n, d, rr, zz))
  PRECOND(r, z);
  memcpy(p, z, sizeof(double) * (size_t)m);
  rz = ut_dot(r, z, m, part);
  /* the products in single precision where the caller gives the copy (valf): they read half
   * the bytes, and were a tenth of a random star's smoothing; the same steps */
  while (it < maxit) {
    bsr_mult(P, val, valf, n, d, NULL, p, q);
    double pq = ut_dot(p, q, m, part);
    if (!(pq > 0)) break;
    double al = rz / pq;
    it++;
    if ((*conv = update_dot(x, r, p, q, al, m, part) <= lim2)) break;
    PRECOND(r, z);
    /* flexible with the multigrid (its K-cycle is not a fixed linear map): β from
     * z·(r_new − r_old) = −α z·q */
    double rz1, zq = 0;
    if (M) dot2(r, z, q, m, part, &rz1, &zq);
    else rz1 = ut_dot(r, z, m, part);
    double be = M ? -al * zq / rz : rz1 / rz;
    rz = rz1;
    UT_PAR_FOR
    for (long i = 0; i < m; i++) p[i] = z[i] + be * p[i];
  }
#undef PRECOND
  return it;
}

int ut_amg_pcg(const ut_bsr *P, double *val, int n, int d, int nrhs, const double *bs, double *xs, int maxit, double tol,
               int *iters, double *res) {
  long m = (long)n * d;
  int status = 1;
  ut_amg A;
  memset(&A, 0, sizeof A);
  double *dinv = malloc(sizeof(double) * ((size_t)n * d * d + 1)), *w[4],
         *part = malloc(sizeof(double) * (2 * ((size_t)m / UT_DOT_CHUNK) + 4));
  int nw = 0;
  for (; nw < 4 && (w[nw] = malloc(sizeof(double) * (m + 1))); nw++) {}
  *iters = 0;
  *res = 0;
  /* the hierarchy first: its finest level finds each row's diagonal block (or fails) */
  if (!dinv || !part || nw < 4 || ut_amg_build(&A, P, NULL, n, d)) goto done;
  ut_block_jacobi(val, A.L[0].dpos, n, d, dinv);
  ut_amg_values(&A, val, dinv);
  status = 0;
  for (int k = 0; k < nrhs; k++) { /* one hierarchy for every right side */
    const double *b = bs + (size_t)k * m;
    double bn = sqrt(ut_dot(b, b, m, part)), lim = tol * fmax(bn, 1e-300);
    int conv, its = ut_fcg(P, val, NULL, n, d, &A, dinv, b, xs + (size_t)k * m, 0, maxit, lim * lim, part, w, &conv);
    double rn = sqrt(ut_dot(w[0], w[0], m, part));
    if (!conv) status = 2;
    if (its > *iters) *iters = its;
    *res = fmax(*res, bn > 0 ? rn / bn : rn);
  }
done:
  ut_amg_free(&A);
  for (int k = 0; k < nw; k++) free(w[k]);
  free(dinv); free(part);
  return status;
}
