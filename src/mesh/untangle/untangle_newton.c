/* untangle_newton.c — projected Newton on the corner energy of untangle_global.c (the
 * energy smoother, smooth.c, and the untangler's Tutte-disk run, whose ε > 0 keeps inverted
 * corners finite): each step solves H p = −g, H the energy's Hessian in the free
 * vertices with every corner's part made positive semidefinite (ut_energy_hessian), by
 * conjugate gradients preconditioned with H's diagonal d×d blocks (block Jacobi) or, once
 * those need more than AMG_SWITCH_ITS iterations on a mesh of UT_AMG_MIN_ROWS free vertices or
 * more (from the first step where softened steps start), with the aggregation multigrid of
 * untangle_amg.c, to the relative residual min(1/2, max(1/10, sqrt(|g|/|g₀|))) (an inexact
 * Newton method's forcing term, Eisenstat and Walker 1996; at most 1/5 near the barrier with
 * the multigrid), then backtracks on the energy (Armijo; at ε = 0 the barrier makes every
 * inverted trial infinite), or doubles a full step that the energy's curvature along it
 * shows to be too short (below). On anisotropic meshes the energy's condition number is what
 * slows L-BFGS: the Tutte-started spiral strip took 360 L-BFGS iterations, a random star 1 200
 * without converging. Results do not depend on the number of threads: sums are taken in
 * fixed chunks, in order. */
#include "untangle_int.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* a · b over n entries: fixed chunks (UT_DOT_CHUNK) summed in order, whatever the thread
 * count (up to UT_DOT_CHUNK entries: the plain loop's order and bits) */
double ut_dot(const double *a, const double *b, long n, double *part) {
  long nch = (n + UT_DOT_CHUNK - 1) / UT_DOT_CHUNK;
#ifdef _OPENMP
#pragma omp parallel for schedule(static) if (n > 4 * UT_DOT_CHUNK)
#endif
  for (long c = 0; c < nch; c++) {
    long hi = c * UT_DOT_CHUNK + UT_DOT_CHUNK < n ? c * UT_DOT_CHUNK + UT_DOT_CHUNK : n;
    double s = 0;
    for (long i = c * UT_DOT_CHUNK; i < hi; i++) s += a[i] * b[i];
    part[c] = s;
  }
  return ut_chunk_sum(part, nch);
}

/* the conjugate gradients' element-wise updates run on threads (UT_PAR_FOR): on one
 * thread they left the other spinning until the next parallel product, and the smoother
 * took 1.3x as long on a 250 000-triangle strip */

/* the pattern: each free vertex's row holds itself and the free vertices of its cells, sorted */
static int build_pattern(const ctx *C, const int *fidx, const int *freev, int nfree, ut_bsr *P) {
  int *mark = malloc(sizeof(int) * ((size_t)nfree + 1));
  P->off = calloc((size_t)nfree + 1, sizeof(int));
  P->col = NULL;
  if (!mark || !P->off) { free(mark); return 1; }
  for (int pass = 0; pass < 2; pass++) {
    for (int f = 0; f < nfree; f++) mark[f] = -1;
    for (int fi = 0; fi < nfree; fi++) {
      int v = freev[fi], cnt = 1, *row = pass ? P->col + P->off[fi] : NULL;
      mark[fi] = fi;
      if (pass) row[0] = fi;
      for (int p = C->vc_off[v]; p < C->vc_off[v + 1]; p++) {
        const int *cell = cell_of(C, C->vc[p]);
        for (int k = 0; k < C->nvc; k++) {
          int fu = fidx[cell[k]];
          if (fu < 0 || mark[fu] == fi) continue;
          mark[fu] = fi;
          if (pass) row[cnt] = fu;
          cnt++;
        }
      }
      if (!pass) P->off[fi + 1] = cnt;
      else
        for (int i = 1; i < cnt; i++) { /* insertion sort: rows are short */
          int t = row[i], j = i - 1;
          while (j >= 0 && row[j] > t) { row[j + 1] = row[j]; j--; }
          row[j + 1] = t;
        }
    }
    if (!pass) {
      for (int fi = 0; fi < nfree; fi++) P->off[fi + 1] += P->off[fi];
      if (!(P->col = malloc(sizeof(int) * ((size_t)P->off[nfree] + 1)))) { free(mark); return 1; }
    }
  }
  free(mark);
  return 0;
}

/* the preconditioner: the multigrid above this many free vertices, block Jacobi below */
#define AMG_SWITCH_ITS 40
/* the relative rise of the minimum quality per step below which the multigrid's run ends at
 * block Jacobi's tolerance (below) */
#define QMIN_RISE 1e-3
/* smoothing's softened first steps (ut_newton): how many, and the mean ratio below which a
 * corner's barrier is softened. 2 and 0.2 measured on the million-triangle spiral (12 Newton
 * steps before): 0.1 took 9, 0.2 and 0.3 took 7; one softened step 10, three 7 */
#define SOFT_STEPS 2
#define SOFT_Q 0.2
/* the forcing term's cap on the barrier (ε = 0) with the multigrid (below) */
#define ETA_AMG 0.2

/* a Newton run's work arrays: the Hessian's pattern and values, its block inverses, the
 * gradient (g; gn the trial point's, q a second trial's, swapped as points are accepted),
 * the step s, the conjugate gradients' vectors (r, z, pd, q), the free vertices' start x0,
 * the dot products' partial sums, and the preconditioner's state (block Jacobi's single
 * precision copy, the multigrid once built) */
typedef struct {
  ut_bsr P;
  double *val, *dinv, *g, *gn, *s, *r, *z, *pd, *q, *x0, *part;
  int *dpos;
  float *bjf;
  ut_amg amg;
  int use_amg, amg_failed;
} newton_ws;

/* the Newton direction w->s at x (the gradient in w->g, gg = |g|², g0 = |g| at the first
 * step): the projected Hessian and its preconditioner (block Jacobi, the multigrid when
 * want_amg or when block Jacobi needs many iterations), then inexact preconditioned
 * conjugate gradients; *gp_out = g·s < 0. 1 when there is no direction (the Hessian
 * failed, or neither the Newton step nor the preconditioned gradient descends). near: the
 * forcing term's cap applies (below) */
static int newton_direction(const objective *o, newton_ws *w, const double *x, int nfree, int want_amg, double gg, double g0,
                            int near, double *gp_out) {
  const ctx *C = o->C;
  int d = C->d, dd = d * d;
  long n = (long)nfree * d;
  if (ut_energy_hessian(o, x, &w->P, w->val, nfree)) return 1;
  if (C->anchor > 0 && C->x0) /* the motion weight's w |x − x0|² */
    for (int fi = 0; fi < nfree; fi++)
      for (int a = 0; a < d; a++) w->val[(size_t)w->dpos[fi] * dd + a * d + a] += 2 * C->anchor;
  ut_block_jacobi(w->val, w->dpos, nfree, d, w->dinv);
  if (want_amg && !w->use_amg && !w->amg_failed) {
    if (ut_amg_build(&w->amg, &w->P, w->val, nfree, d)) { ut_amg_free(&w->amg); w->amg_failed = 1; }
    else {
      w->use_amg = 1;
      if (o->amg_used) *o->amg_used = 1;
    }
  }
  if (w->use_amg) ut_amg_values(&w->amg, w->val, w->dinv);
  /* preconditioned conjugate gradients for H s' = g from s' = 0, then s = −s' (the same
   * bits as solving for −g: every operation is odd in the right side) */
  /* the forcing term: at least 0.1 (0.01 cost the star 40x200 twice the CG iterations for
   * the same Newton steps) */
  /* on the barrier with the multigrid while the minimum quality is below SOFT_Q, at most
   * ETA_AMG: the multigrid's count grows slowly with the tolerance (the random star's
   * steps: 4–12 iterations at 0.2, 3–8 at 0.5), and the closer steps end the halved steps
   * whose full steps crossed the barrier. Not above SOFT_Q, far from the barrier, where the
   * steps were the same at more iterations (the 100 000-vertex quadrilateral spiral,
   * minimum 0.27: 5 a step instead of 3). A softened step, whose minimum is checked, is
   * solved at 0.5 first and, when not kept, once more from its start at ETA_AMG, as are the
   * softened steps after it: the random star's first is kept only at 0.2 (17 -> 13 steps
   * with the cap), and the million-triangle spiral's are kept at 0.5 (7 + 5 iterations,
   * 10 + 7 at 0.2; bench/RESULTS.md) */
  double eta = fmin(w->use_amg && o->eps == 0 && near ? ETA_AMG : 0.5, fmax(0.1, sqrt(sqrt(gg) / g0))), *cw[4] = {w->r, w->z, w->pd, w->q};
  /* the products in single precision: the multigrid's finest copy, or on a mesh where block
   * Jacobi's conjugate gradients may take dozens of iterations (the multigrid's size) a copy
   * of its own (the 100 000-vertex spiral's smoothing took 137 of them before the switch) */
  const float *valf = NULL;
  if (w->use_amg) valf = w->amg.L[0].valf;
  else if (nfree >= UT_AMG_MIN_ROWS && (w->bjf || (w->bjf = malloc(sizeof(float) * ((size_t)w->P.off[nfree] * dd + 1))))) {
    ut_to_single(w->val, w->bjf, (long)w->P.off[nfree] * dd);
    valf = w->bjf;
  }
  int conv, k = ut_fcg(&w->P, w->val, valf, nfree, d, w->use_amg ? &w->amg : NULL, w->dinv, w->g, w->s, 1, 1000, eta * eta * gg, w->part, cw, &conv);
  UT_PAR_FOR
  for (long i = 0; i < n; i++) w->s[i] = -w->s[i];
  /* block Jacobi needed many iterations on a large mesh: the multigrid from the next step
   * on (its hierarchy is built from this step's Hessian: its pattern and strong couplings;
   * out of memory or a stalled coarsening: block Jacobi stays).
   * Block Jacobi's count grows with the mesh where the error is smooth (a million-triangle
   * spiral: 50–240 per step), while perturbed grids, whose error is local, need few and
   * were faster without the multigrid's five products per cycle (k − conv: the count
   * before the converging iteration, as the rule was measured) */
  if (!w->use_amg && !w->amg_failed && k - conv > AMG_SWITCH_ITS && nfree >= UT_AMG_MIN_ROWS && !o->no_multigrid) {
    if (ut_amg_build(&w->amg, &w->P, w->val, nfree, d)) { ut_amg_free(&w->amg); w->amg_failed = 1; }
    else {
      w->use_amg = 1;
      if (o->amg_used) *o->amg_used = 1;
      free(w->bjf); /* the multigrid's finest level has its own copy */
      w->bjf = NULL;
    }
  }
  /* sliding vertices: the multigrid's coarse corrections leave the normal components of an
   * inexact solve nonzero (the exact solution has none); g·s is unchanged, g being tangent */
  ut_slide_project(o, w->s, nfree);
  double gp = ut_dot(w->g, w->s, n, w->part);
  if (!(gp < 0)) { /* no descent (a breakdown at the first step): the preconditioned gradient */
    ut_block_apply(w->dinv, nfree, d, w->g, w->s);
    for (long i = 0; i < n; i++) w->s[i] = -w->s[i];
    ut_slide_project(o, w->s, nfree);
    gp = ut_dot(w->g, w->s, n, w->part);
    if (!(gp < 0)) return 1;
  }
  *gp_out = gp;
  return 0;
}

/* the step along w->s from x (f, g·s = gp there): backtracking, then a longer step where
 * the energy along s is flatter than its model. x at the accepted point, *fn_out its energy,
 * w->gn its gradient; returns the backtracking count, 50 when nothing decreased f (x then
 * restored) */
static int newton_step(const objective *o, const objective *real, newton_ws *w, double *x, const int *freev, int nfree, double f,
                       double gp, double *fn_out) {
  int d = o->C->d;
  ut_gather(w->x0, x, freev, nfree, d);
  double t = 1, fn = f;
  int ls;
  for (ls = 0; ls < 50; ls++) {
    ut_place(x, w->x0, w->s, t, freev, nfree, d);
    fn = ut_eval(o, x, w->gn, nfree);
    if (fn <= f + 1e-4 * t * gp) break;
    t *= 0.5;
  }
  /* the full step lowered f by more than 3/4 of g·s, where the model ½ sᵀHs + g·s predicts
   * ½ g·s at its minimum: along s the energy is nearly linear, and the projected Hessian
   * (every corner's negative curvature set to 0) is far stiffer than the energy itself.
   * Double the step while it gains that much (at ε = 0 an inverted trial is infinite and
   * stops it). The Tutte-started 80 × 250 strip's smoothing took 581 steps of t = 1 whose
   * gains were as g·s predicted, each 1e-5 of f: steps of 2–32 took 267–290, 11.6 → 3.9–5.2 s, the
   * same minimum (bench/RESULTS.md) */
  if (ls == 0 && f - fn > 0.75 * -gp) {
    for (int e = 0; e < 10; e++) {
      double t2 = 2 * t, f2;
      ut_place(x, w->x0, w->s, t2, freev, nfree, d);
      f2 = ut_eval(o, x, w->q, nfree);
      if (!(f2 < fn)) break;
      t = t2;
      fn = f2;
      double *tq = w->gn; /* q holds the trial's gradient: it becomes the accepted point's */
      w->gn = w->q;
      w->q = tq;
      if (!(f - fn > 0.75 * t * -gp)) break;
    }
    ut_place(x, w->x0, w->s, t, freev, nfree, d);
  }
  /* one more trial at tt, kept when lower, in two cases (else tt = 0):
   * a full step that lowered f by 0.55–0.75 of g·s: the energy along s is flatter than the
   * model (at its minimum ½ g·s) and its minimum lies past t = 1. With the barrier alone
   * (ε = 0: smoothing) the trial at the minimum of the parabola through f, g·s and
   * the full step's value (t* = −g·s / (2 (f(1) − f − g·s)), up to 2).
   * The million-triangle spiral's smoothing: 15 → 12 steps, 9.5–11.6 → 7.8 s, the same
   * minimum (its steps gained two thirds of g·s at t = 1, t* 1.4–1.5). Not with ε > 0: the
   * untangler's global energy then zigzagged (the 100 000-vertex Tutte spiral 9 → 14 steps);
   * a backtracked step on the barrier (the longer trial crossed it or gained too little):
   * the trial half-way to that longer one. The random star's smoothing: its steps at
   * t = 1/2 after an inverted full step, each halving g·s, became steps at 3/4 (13 -> 12
   * steps, bench/RESULTS.md). Not in the softened steps, which are judged by the minimum
   * they leave: the first of a 300 × 45 spiral's (Gauss-Seidel start), backtracked to 1/2,
   * left it at 0.0056, and at 3/4 at 0.0005 */
  else {
    double tt = 0;
    if (o->eps == 0 && ls == 0 && f - fn > 0.55 * -gp) {
      double c = 2 * (fn - f - gp), ts = c > 0 ? fmin(2, -gp / c) : 2;
      if (ts > 1.15) tt = ts;
    } else if (o == real && o->eps == 0 && ls > 0 && ls < 50)
      tt = 1.5 * t;
    if (tt > 0) {
      ut_place(x, w->x0, w->s, tt, freev, nfree, d);
      double f2 = ut_eval(o, x, w->q, nfree);
      if (f2 < fn) {
        t = tt;
        fn = f2;
        double *tq = w->gn; /* q holds the trial's gradient: it becomes the accepted point's */
        w->gn = w->q;
        w->q = tq;
      } else
        ut_place(x, w->x0, w->s, t, freev, nfree, d);
    }
  }
  if (ls == 50) ut_place(x, w->x0, NULL, 0, freev, nfree, d); /* no decrease: restore */
  *fn_out = fn;
  return ls;
}

/* (untangle_int.h) The loop keeps the softened first steps' bookkeeping and the end test
 * with the steps (direction and step length are newton_direction and newton_step): about
 * 180 lines, half of them the measurements behind each rule, which belong beside it */
int ut_newton(const objective *o, double *x, const int *freev, int nfree, int maxit, double *fout) {
  const ctx *C = o->C;
  int d = C->d, dd = d * d, it;
  long n = (long)nfree * d;
  newton_ws w;
  memset(&w, 0, sizeof w);
  if (build_pattern(C, o->fidx, freev, nfree, &w.P)) { free(w.P.off); return -1; }
  size_t nb = (size_t)w.P.off[nfree];
  w.val = malloc(sizeof(double) * (nb * dd + 1));
  w.dinv = malloc(sizeof(double) * ((size_t)nfree * dd + 1));
  double **vec[] = {&w.g, &w.gn, &w.s, &w.r, &w.z, &w.pd, &w.q, &w.x0};
  for (size_t i = 0; i < sizeof vec / sizeof vec[0]; i++) *vec[i] = malloc(sizeof(double) * (n + 1));
  w.part = malloc(sizeof(double) * (2 * ((size_t)n / UT_DOT_CHUNK) + 4)); /* ut_fcg's two */
  w.dpos = malloc(sizeof(int) * ((size_t)nfree + 1));
  double *xkeep = o->keepq > 0 ? malloc(sizeof(double) * (n + 1)) : NULL;
  double *soft_eps = NULL, *xsoft = NULL; /* the softened barrier's first steps (below) */
  int ok = w.val && w.dinv && w.g && w.gn && w.s && w.r && w.z && w.pd && w.q && w.x0 && w.part && w.dpos && (xkeep || !(o->keepq > 0)), below = 0;
  double f = INFINITY, g0 = 0, qmin = 0;
  if (!ok) { it = -1; goto done; }
  for (int fi = 0; fi < nfree; fi++) {
    int lo = w.P.off[fi];
    while (w.P.col[lo] != fi) lo++; /* every row holds its own vertex */
    w.dpos[fi] = lo;
  }
  f = ut_eval(o, x, w.g, nfree);
  if (xkeep)
    ut_gather(xkeep, x, freev, nfree, d);
  /* smoothing's barrier (ε = 0) and corners far below the good shapes: Newton on 1/D moves a
   * corner's D by half of itself per unit step (f = 1/D: −f'/f'' = D/2), so a corner that
   * starts at mean ratio 0.006 took a step for every doubling of its quality while the rest of
   * the mesh had converged (the million-triangle spiral's smoothing: 12 steps, its minimum
   * 0.0056 -> 0.0116 -> 0.020 -> 0.041 -> 0.072 -> 0.15 -> 0.26 -> 0.35 -> 0.42 -> 0.445; its
   * first two steps' full steps inverted cells). The first SOFT_STEPS steps minimize the energy
   * with each corner's barrier softened, χ(D, ε) in place of D as the untangler's global
   * energy (foldover-free maps') does, ε the D of a corner of its size at mean ratio SOFT_Q
   * (ut_energy_soft_eps), every corner still kept valid: the corners far below SOFT_Q move as
   * far as their shapes ask in one step. Each softened step is kept when it lowered the
   * barrier's energy and left the minimum quality at least the start's times the barrier
   * energy's ratio to the start's (capped at 1); at the first that does not, the barrier's
   * steps go on from the last kept state. A random star's smoothing, its minimum held by the
   * fixed boundary's cells: its first softened step had let those fall from 0.0080 to 0.0011
   * and lowered the barrier's energy by 1.3%, a step for nothing. The 400 × 60 spiral's
   * (boundary fixed) let its minimum fall from 0.0071 to 0.0065 and lowered the energy 2.3
   * times: kept since, its smoothing took 18 -> 10 steps, and the sliding one 51 -> 42. The
   * minimum may then be below the start's: the steps after restore it (xkeep keeps the last
   * iterate at keepq or above, the start's until then). Measured (bench/RESULTS.md): the
   * spiral 12 -> 7 steps, 0.0056 -> 0.125 in the two softened steps */
  const objective *real = o;
  objective soft;
  /* the start's minimum and barrier energy; the last kept state's minimum and energy */
  double qstart = 0, fstart = f, qgood = 0, fgood = f;
  int soft_left = 0, soft_close = 0; /* soft_close: the softened steps solved at ETA_AMG (below) */
  if (o->soft_start && o->smooth == 2 && o->eps == 0 && !o->soft_eps && isfinite(f) && (qstart = ut_energy_qmin(o, x)) < SOFT_Q &&
      (soft_eps = calloc((size_t)C->m->ncell * C->ncorner + 1, sizeof(double))) && /* 0: the cells not in o */
      (xsoft = malloc(sizeof(double) * (n + 1)))) {
    ut_energy_soft_eps(o, x, SOFT_Q, soft_eps);
    ut_gather(xsoft, x, freev, nfree, d);
    qgood = qstart;
    soft = *o;
    soft.soft_eps = soft_eps;
    o = &soft;
    soft_left = SOFT_STEPS;
    f = ut_eval(o, x, w.g, nfree);
  }
  double tol = o->ftol > 0 ? o->ftol : 1e-9;
  /* with the multigrid, a tenth of that: its steps resolve every scale alike where block
   * Jacobi's resolve the local ones first, and at the same gain its runs had left the
   * worst cells behind (multigrid from the first step: a 250 000-triangle spiral's minimum
   * 0.4354 at 1e-5, 0.4411 at 1e-6, block Jacobi's 0.4452; the million-triangle spiral
   * 0.4443 and 0.4455, block Jacobi's 0.4452). Smoothing's barrier only: the untangler's
   * rounds at ε > 0 end at their own tolerance, the next round re-solving at a smaller ε
   * (the 640 × 160 Tutte-solved spiral's global stage: 10 -> 8 steps, minimum 0.0852 ->
   * 0.0850, the same smoothed mesh's minimum) */
  double tol_amg = 0.1 * tol, gain[3] = {0, 0, 0};
  /* a later round of the same smoothing takes the multigrid from its first step when an
   * earlier one took it: the same mesh and pattern, and the same (tenfold) tolerance, which
   * block Jacobi's first steps, back at 1e-5, had met on the Tutte-started 160 × 500 strip
   * (160 000 triangles) with its minimum at 0.0131 instead of 0.0197 (bench/RESULTS.md).
   * Built at that step, from its Hessian (the strong couplings, untangle_amg.c) */
  /* so does a run that starts with softened steps (on UT_AMG_MIN_ROWS free vertices or more):
   * block Jacobi's first step there needs more than AMG_SWITCH_ITS iterations, its count
   * growing with the mesh (the million-triangle spiral's: 67 iterations and 0.45 s, then
   * the hierarchy built anyway, 0.27 s), and the multigrid's softened steps also took the
   * Tutte-solved spirals of 500 000 and a million triangles 7 -> 6 Newton steps. On the
   * 100 000-vertex random star, with the forcing term's cap below, its softened steps are
   * kept where block Jacobi's were not (bench/RESULTS.md) */
  int want_amg = ((o->amg_used && *o->amg_used) || soft_left) && nfree >= UT_AMG_MIN_ROWS && !o->no_multigrid;
  for (it = 0; it < maxit && isfinite(f) && f > 0; it++) {
    ut_progress_tick(C->progress, "Newton step", it, f, qmin);
    double gg = ut_dot(w.g, w.g, n, w.part);
    if (!it) g0 = sqrt(gg);
    int near = o != real ? soft_close : xkeep && qmin > 0 && qmin < SOFT_Q;
    double gp;
    if (!(gg > 0) || newton_direction(o, &w, x, nfree, want_amg, gg, g0, near, &gp)) break;
    double fn;
    if (newton_step(o, real, &w, x, freev, nfree, f, gp, &fn) == 50) break; /* no decrease: x restored */
    double fprev = f;
    f = fn;
    double *gt = w.g; /* the accepted point's gradient becomes the current one */
    w.g = w.gn;
    w.gn = gt;
    double qlast = qmin;
    if (xkeep) { /* the last iterate that keeps the smallest quality (to rounding: a minimum
                  * no vertex can move, measured by the caller in other arithmetic, is kept) */
      qmin = ut_energy_qmin(o, x);
      below = qmin < o->keepq * (1 - 1e-12);
      if (!below)
        ut_gather(xkeep, x, freev, nfree, d);
    }
    /* the end: a step that gains at most tol·f where the gradient has fallen to a tenth of
     * the first step's (Newton near its minimum). Where it has not, a step's small gain says
     * little: the strip's steps after the first round gained 1e-5, 5e-6, then 7e-5 of f,
     * zigzagging with |g| at 0.7–1.3 of the round's first; there the last three steps'
     * gains together (those there are) must be at most 3 tol·f. The multigrid's tenfold
     * smaller tolerance (above: for the worst cells) only while the minimum quality still
     * rises by more than QMIN_RISE a step: a random star's smoothing, its minimum held by the
     * fixed boundary's cells, spent its last seven steps (a quarter of its time) on gains of
     * 1e-5 to 1e-6 that moved the minimum by 1e-4 of itself (bench/RESULTS.md) */
    double tl = w.use_amg && o->eps == 0 && !(xkeep && qlast > 0 && qmin <= (1 + QMIN_RISE) * qlast) ? tol_amg : tol;
    gain[it % 3] = (fprev - f) / fprev;
    if (o != real) { /* a softened step: kept (in xsoft) when it lowered the barrier's energy and
                      * left the minimum quality at least the start's times the energy's ratio
                      * to the start's (above) */
      /* (the quality does not depend on ε: xkeep's pass above measured it; gn, the last
       * point's gradient, is free) */
      double qs = xkeep ? qmin : ut_energy_qmin(real, x), fr = qs > 0 ? ut_eval(real, x, w.gn, nfree) : INFINITY;
      int kept = qs >= qstart * fmin(1, fr / fstart) && fr < fgood;
      if (kept) {
        ut_gather(xsoft, x, freev, nfree, d);
        qgood = qs;
        fgood = fr;
      } else if (w.use_amg && !soft_close) { /* solved again from its start, closer (above) */
        soft_close = 1;
        ut_place(x, xsoft, NULL, 0, freev, nfree, d);
        f = ut_eval(o, x, w.g, nfree);
        qmin = qgood;
        below = xkeep && qmin < o->keepq * (1 - 1e-12);
        continue;
      }
      if (--soft_left > 0 && kept) continue;
      o = real; /* back to the barrier, from the last kept state */
      if (kept) { /* here: the barrier's energy and gradient just evaluated */
        double *gt = w.g;
        w.g = w.gn;
        w.gn = gt;
        f = fr;
      } else {
        ut_place(x, xsoft, NULL, 0, freev, nfree, d);
        f = ut_eval(o, x, w.g, nfree);
      }
      qmin = qgood;
      below = xkeep && qmin < o->keepq * (1 - 1e-12);
      if (xkeep && !below) ut_gather(xkeep, x, freev, nfree, d);
      g0 = sqrt(ut_dot(w.g, w.g, n, w.part)); /* the end test's and the forcing term's reference */
      gain[0] = gain[1] = gain[2] = 1;
      continue;
    }
    if (gain[it % 3] <= tl && (ut_dot(w.g, w.g, n, w.part) <= 0.01 * g0 * g0 || gain[0] + gain[1] + gain[2] <= 3 * tl)) {
      it++;
      break;
    }
  }
  if (o != real) { /* stopped within the softened steps: their last kept state */
    o = real;
    ut_place(x, xsoft, NULL, 0, freev, nfree, d);
    f = ut_eval(o, x, NULL, nfree);
    below = xkeep && qgood < o->keepq * (1 - 1e-12);
  }
  if (below) {
    ut_place(x, xkeep, NULL, 0, freev, nfree, d);
    f = ut_eval(o, x, NULL, nfree);
  }
done:
  free(soft_eps); free(xsoft);
  ut_amg_free(&w.amg);
  ut_energy_release_blocks(o->eb); /* its positions are on P */
  *fout = f;
  free(w.P.off); free(w.P.col); free(w.val); free(w.dinv); free(w.g); free(w.gn); free(w.s); free(w.r); free(w.z); free(w.pd); free(w.q);
  free(w.x0); free(w.part); free(w.dpos); free(xkeep); free(w.bjf);
  return it;
}
