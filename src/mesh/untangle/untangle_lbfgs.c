/* untangle_lbfgs.c — the objective that stage 2 of untangling (seed: "Untangling of 2D
 * triangular and quadrilateral meshes in ALE simulations", the penalty (3.3)), the global stage
 * and the smoother minimize, its evaluation on threads, and its L-BFGS minimizer. Shared by
 * untangle.c, untangle_global.c, untangle_newton.c and smooth.c; declared in untangle_int.h. */
#include "untangle_int.h"

#include "../quality/quality.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* ---------------------------------------------------------------- stage 2: optimization */

/* above this many cells the objective's corner Jacobians are taken on threads (below it the
 * threads' start costs more than the loop) */
#define OBJ_PAR_CELLS 16384

static int obj_bad(const objective *o, const double *x) {
  int bad = 0;
#ifdef _OPENMP
#pragma omp parallel for schedule(static) reduction(+ : bad) if (o->ncell > OBJ_PAR_CELLS)
#endif
  for (int i = 0; i < o->ncell; i++) {
    double J = ut_cell_min_jac(o->C, x, o->cells[i]);
    bad += o->lift ? !(J >= o->beta) : !(J > o->C->jtol);
  }
  return bad;
}

/* corner k of the objective's cell i into f and grad (the order of the sums is the caller's) */
static void obj_corner(const objective *o, const double *x, int i, int k, double *f, double *grad) {
  const ctx *C = o->C;
  int d = C->d;
  const int *cell = cell_of(C, o->cells[i]);
  double g[4][3];
  double J = ut_corner_jac(C, x, cell, k, grad ? g : NULL);
  double r = (o->beta - J) / o->S;
  if (!(r > 0)) return;
  *f += r * r;
  if (!grad) return;
  for (int a = 0; a <= d; a++) {
    int fi = o->fidx[cell[C->ct[k][a]]];
    if (fi < 0) continue;
    for (int j = 0; j < d; j++) grad[(size_t)fi * d + j] -= 2 * r / o->S * g[a][j];
  }
}

/* (3.3) and its gradient. On many cells the corner Jacobians are taken on threads first and
 * only the corners below β (few: the tangle's) are then added, one after another in the
 * one-thread loop's order: the same bits for any thread count (a twisted bar's stage 2 over
 * a million cells spent its time here, on one thread) */
static double obj_eval(const objective *o, const double *x, double *grad, int nfree) {
  const ctx *C = o->C;
  int d = C->d, nk = C->ncorner;
  double f = 0;
  if (grad) memset(grad, 0, sizeof(double) * (size_t)nfree * d);
  size_t nc = (size_t)o->ncell * nk;
  unsigned char *below = o->ncell > OBJ_PAR_CELLS ? malloc(nc) : NULL;
  if (below) {
#ifdef _OPENMP
#pragma omp parallel for schedule(static)
#endif
    for (int i = 0; i < o->ncell; i++) {
      const int *cell = cell_of(C, o->cells[i]);
      for (int k = 0; k < nk; k++) below[(size_t)i * nk + k] = (o->beta - ut_corner_det(C, x, cell, k)) / o->S > 0;
    }
    for (size_t q = 0; q < nc; q++)
      if (below[q]) obj_corner(o, x, (int)(q / nk), (int)(q % nk), &f, grad);
    free(below);
    return f;
  }
  for (int i = 0; i < o->ncell; i++)
    for (int k = 0; k < nk; k++) obj_corner(o, x, i, k, &f, grad);
  return f;
}


static double smooth_eval(const objective *o, const double *x, double *grad, int nfree) {
  const ctx *C = o->C;
  mesh *m = C->m; /* x is m->x: the quality measures read the mesh */
  int d = C->d;
  double f = 0, mn = INFINITY, qq;
  (void)x;
  for (int i = 0; i < o->ncell; i++) {
    int c = o->cells[i];
    if (!(ut_cell_min_jac(C, m->x, c) > C->jtol)) return INFINITY;
    double val = mesh_cell_quality(m, c, o->measure);
    if (!(val > 0)) return INFINITY;
    f += 1 / val;
    mn = fmin(mn, val);
  }
  if (mn < o->qfloor) return INFINITY;
  if (grad)
    for (int i = 0; i < nfree; i++) {
      int v = o->freev[i];
      double e = 1e-6 * o->hv[i];
      for (int j = 0; j < d; j++) {
        double *p = m->x + (size_t)v * d + j, p0 = *p;
        *p = p0 + e;
        double fp = ut_star_objective(C, v, o->measure, &qq);
        *p = p0 - e;
        double fm = ut_star_objective(C, v, o->measure, &qq);
        *p = p0;
        grad[(size_t)i * d + j] = isfinite(fp) && isfinite(fm) ? (fp - fm) / (2 * e) : 0;
      }
    }
  return f;
}

/* the untangling objectives (3.3) and the global energy, plus with motion_weight w the
 * distance to where the run started, w Σ |x_v − x0_v|² / h² over the free vertices (h a
 * typical edge), for an ALE remap that wants the smallest motion */
void ut_slide_project(const objective *o, double *vec, int nfree) {
  if (!o->slide) return;
  const ctx *C = o->C;
  for (int fi = 0; fi < nfree; fi++)
    if (C->bnd[o->freev[fi]]) ut_tangent_project(C, o->freev[fi], vec + (size_t)fi * C->d);
}

double ut_eval(const objective *o, const double *x, double *grad, int nfree) {
  double f = o->smooth == 2 ? ut_energy_eval(o, x, grad, nfree)
             : o->smooth   ? smooth_eval(o, x, grad, nfree)
                           : obj_eval(o, x, grad, nfree);
  const ctx *C = o->C;
  if (!isfinite(f)) return f;
  if (o->smooth != 1 && C->anchor > 0 && C->x0 && o->freev) {
    int d = C->d;
    for (int i = 0; i < nfree; i++)
      for (int j = 0; j < d; j++) {
        size_t k = (size_t)o->freev[i] * d + j;
        double e = x[k] - C->x0[k];
        f += C->anchor * e * e;
        if (grad) grad[(size_t)i * d + j] += 2 * C->anchor * e;
      }
  }
  if (grad) ut_slide_project(o, grad, nfree);
  return f;
}

/* L-BFGS's two-loop recursion in one pass over the direction p per pair (below), each sum in
 * ut_dot's chunks and order: the same bits as the separate loops and sums. On the
 * million-triangle spiral the recursion's updates and sums, a pass each, had cost more than
 * the energy itself (L-BFGS 43% of the untangling: ut_dot 13%, the updates 8%, the
 * evaluations 16%); on the random star they were 20% of the untangling's instructions, 13%
 * after (callgrind) */

/* p = −g sc; returns v · p, and with S (then Y) S · Y and Y · Y (sc 1: p = −g, the same bits) */
static double two_loop_first(double *p, const double *g, double sc, const double *v, const double *S, const double *Y,
                             double *sy, double *yy, long n, double *part) {
  long nch = (n + UT_DOT_CHUNK - 1) / UT_DOT_CHUNK;
  UT_PAR_CHUNKS
  for (long c = 0; c < nch; c++) {
    double s1 = 0, s2 = 0, s3 = 0;
    if (S)
      for (long i = c * UT_DOT_CHUNK; i < UT_CHUNK_END(c); i++) {
        double pi = -g[i] * sc;
        p[i] = pi;
        s1 += v[i] * pi;
        s2 += S[i] * Y[i];
        s3 += Y[i] * Y[i];
      }
    else
      for (long i = c * UT_DOT_CHUNK; i < UT_CHUNK_END(c); i++) {
        double pi = -g[i] * sc;
        p[i] = pi;
        s1 += v[i] * pi;
      }
    part[c] = s1;
    part[nch + c] = s2;
    part[2 * nch + c] = s3;
  }
  if (S) {
    *sy = ut_chunk_sum(part + nch, nch);
    *yy = ut_chunk_sum(part + 2 * nch, nch);
  }
  return ut_chunk_sum(part, nch);
}

/* p = (p + a u) sc; returns v · p (sc 1: no scaling, the same bits) */
static double two_loop_update(double *p, const double *u, double a, double sc, const double *v, long n, double *part) {
  long nch = (n + UT_DOT_CHUNK - 1) / UT_DOT_CHUNK;
  UT_PAR_CHUNKS
  for (long c = 0; c < nch; c++) {
    double s1 = 0;
    for (long i = c * UT_DOT_CHUNK; i < UT_CHUNK_END(c); i++) {
      double pi = (p[i] + u[i] * a) * sc;
      p[i] = pi;
      s1 += v[i] * pi;
    }
    part[c] = s1;
  }
  return ut_chunk_sum(part, nch);
}

/* the energy smoother's handover to Newton (o->handover): L-BFGS's iterations 10–19 gaining
 * more than this fraction of f each on average. On a perturbed box the gains have fallen below
 * 1e-5 by then (tetrahedral box 32: 8e-6 to 1e-7, converged in 40 iterations); on the
 * untangled twisted bars they stay at 1e-4 to 1e-3 with many steps shortened (bar 32:
 * 3e-4 to 1.5e-3, and the 100-iteration round ends at its cap twice) */
#define HANDOVER_GAIN 1e-4

/* L-BFGS (memory 8, Armijo backtracking) on the free vertices' coordinates */
int ut_lbfgs(const objective *o, double *x, const int *freev, int nfree, int maxit, double *fout) {
  int d = o->C->d, M = 8, it;
  /* the vector loops and sums on threads when n is large (UT_PAR_FOR, ut_dot: the same bits
   * for any thread count): on one thread they were a sixth of a twisted bar's stage 2 */
  long n = (long)nfree * d;
  double *g = malloc(sizeof(double) * n), *gn = malloc(sizeof(double) * n), *p = malloc(sizeof(double) * n),
         *x0 = malloc(sizeof(double) * n), *S = malloc(sizeof(double) * n * M), *Y = malloc(sizeof(double) * n * M),
         *part = malloc(sizeof(double) * 3 * ((size_t)n / UT_DOT_CHUNK + 2)), rho[8], alpha[8];
  if (!g || !gn || !p || !x0 || !S || !Y || !part) {
    free(g); free(gn); free(p); free(x0); free(S); free(Y); free(part);
    return -1;
  }
  int mem = 0, head = 0, best_bad = o->smooth ? 0 : obj_bad(o, x), start_bad = best_bad, stale = 0, worse = 0;
  double f = ut_eval(o, x, g, nfree), h0 = pow(o->S, 1.0 / d), fmark = f, f10 = f;
  for (it = 0; it < maxit && f > 0; it++) {
    ut_progress_tick(o->C->progress, "L-BFGS iteration", it, f, 0);
    /* the two-loop recursion in one pass per pair, each sum in ut_dot's chunks and order (the
     * same bits as a pass for each update and each sum): the first pair's sum in p = −g's
     * pass, each pair's update with the next pair's sum, γ's scaling with the first sum of
     * the second loop, the last update with g · p. The updates and sums, a pass each, had
     * been a quarter of the random star's untangling instructions (callgrind) */
    double gp;
    if (mem) {
      int k0 = (head - 1 + M) % M;
      double sy, yy, vp = two_loop_first(p, g, 1, S + k0 * n, S + k0 * n, Y + k0 * n, &sy, &yy, n, part);
      double gamma = sy / yy;
      for (int q = 0; q < mem; q++) {
        int k = (head - 1 - q + M) % M, last = q + 1 == mem;
        alpha[k] = rho[k] * vp;
        /* the last pair: its update, γ's scaling, and the second loop's first sum (the oldest
         * pair, this one) */
        vp = two_loop_update(p, Y + k * n, -alpha[k], last ? gamma : 1, last ? Y + k * n : S + ((head - 2 - q + M) % M) * n, n,
                             part);
      }
      for (int q = mem - 1; q >= 0; q--) {
        int k = (head - 1 - q + M) % M;
        double bb = vp * rho[k];
        vp = two_loop_update(p, S + k * n, alpha[k] - bb, 1, q ? Y + ((head - q + M) % M) * n : g, n, part);
      }
      gp = vp;
    } else {
      double gi = 0;
      for (long i = 0; i < n; i++) gi = fmax(gi, fabs(g[i]));
      gp = two_loop_first(p, g, 0.1 * h0 / gi, g, NULL, NULL, NULL, NULL, n, part);
    }
    if (!(gp < 0)) { /* not a descent direction: restart from the gradient */
      mem = 0;
      double gi = 0;
      for (long i = 0; i < n; i++) gi = fmax(gi, fabs(g[i]));
      for (long i = 0; i < n; i++) p[i] = -0.1 * h0 / gi * g[i];
      gp = ut_dot(g, p, n, part);
    }
    ut_slide_project(o, p, nfree); /* exactly on the tangents (g is: p is to rounding) */
    ut_gather(x0, x, freev, nfree, d);
    double t = 1, fn = f;
    int ls;
    for (ls = 0; ls < 50; ls++) {
      ut_place(x, x0, p, t, freev, nfree, d);
      fn = ut_eval(o, x, gn, nfree); /* with the gradient: the first step is usually taken */
      if (fn <= f + 1e-4 * t * gp) break;
      t *= 0.5;
    }
    if (ls == 50) { /* no decrease: restore and stop */
      ut_place(x, x0, NULL, 0, freev, nfree, d);
      break;
    }
    double *Sh = S + head * n, *Yh = Y + head * n;
    UT_PAR_FOR
    for (long i = 0; i < n; i++) {
      Sh[i] = t * p[i];
      Yh[i] = gn[i] - g[i];
    }
    double sy = ut_dot(Sh, Yh, n, part);
    if (sy > 0) {
      rho[head] = 1 / sy;
      head = (head + 1) % M;
      if (mem < M) mem++;
    }
    double *gt = g; /* the accepted point's gradient becomes the current one */
    g = gn;
    gn = gt;
    double fprev = f;
    f = fn;
    if (o->smooth) {
      if (fprev - f <= (o->ftol > 0 ? o->ftol : 1e-9) * fprev) break;
      /* the energy smoother: a window of o->stall iterations (20: 1e-4 of f in all) that
       * gained less than 5e-6 of f per iteration ends the round (its rounds stop at a 1e-3
       * gain; a mesh the untangler's global energy left near the smoother's optimum
       * otherwise spends a round of 100 iterations on nothing) */
      if (o->stall) {
        if (it % o->stall == 0) fmark = fprev;
        else if (it % o->stall == o->stall - 1 && fmark - f < 5e-6 * o->stall * fmark) { it++; break; }
      }
      /* a steady descent (handover, below) */
      if (o->handover && it == 9) f10 = f;
      if (o->handover && it == 19 && f10 - f > 10 * HANDOVER_GAIN * f10) { *o->handover = 1; it++; break; }
      continue;
    }
    if (it % 10 == 9) { /* every cell valid (stage 2) or at least β (stage 3): stop here */
      int bad = obj_bad(o, x);
      if (!bad) { it++; break; }
      /* stagnation — the number of bad cells has not dropped by 10% for five checks, or
       * has been above its start for two (stage 2 only): a local minimum of (3.3) the caller escapes by
       * growing the region or restarting from the harmonic position */
      if (bad <= 0.9 * best_bad) { best_bad = bad; stale = 0; }
      else if (++stale >= 5 || (!o->lift && bad > start_bad && ++worse >= 2)) { it++; break; }
    }
    if (f < 1e-28 || fprev - f <= 1e-15 * fprev) {
      if (f < 1e-28 || fprev - f <= 0) break;
    }
  }
  *fout = f;
  free(g); free(gn); free(p); free(x0); free(S); free(Y); free(part);
  return it;
}
