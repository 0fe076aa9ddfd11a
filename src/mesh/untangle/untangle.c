/* untangle.c — untangling (seed: "Untangling of 2D triangular and quadrilateral meshes in ALE
 * simulations", sections 1–4): the driver of its stages, stage 2 (the local penalty
 * optimization over grown regions) and the Laplacian lift; and Laplacian
 * mesh motion (seed: "Morphing and modification of unstructured meshes", eqs. 1.1–1.3).
 * The context is in untangle_ctx.c, stages 1 and 3 in untangle_place.c, the global stage in
 * untangle_global.c, the objective and its L-BFGS minimizer (shared with the smoother) in
 * untangle_lbfgs.c, all declared in untangle_int.h. See untangle.h. */
#include "untangle_int.h"

#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

/* ---------------------------------------------------------------- stage 2: local optimization */

/* 2D boundary vertex v slides along its boundary polyline: the best position on either
 * boundary edge for the objective restricted to v's corners (golden section on each side) */
static double local_penalty(const ctx *C, const double *x, int v, double beta, double S) {
  double f = 0;
  for (int p = C->vc_off[v]; p < C->vc_off[v + 1]; p++) {
    const int *cell = cell_of(C, C->vc[p]);
    for (int k = 0; k < C->ncorner; k++) {
      double r = (beta - ut_corner_det(C, x, cell, k)) / S;
      if (r > 0) f += r * r;
    }
  }
  return f;
}

typedef struct {
  const double *x;
  double beta;
} penalty_arg;
static double untangle_penalty(const ctx *C, int v, const void *arg, int probe) {
  const penalty_arg *a = arg;
  (void)probe;
  return local_penalty(C, a->x, v, a->beta, C->jscale);
}

/* none of the valid cells of v's star (the first 64; floor[p] > 0 for them) falls below its
 * floor: the smaller of β and its corner Jacobian before the slide */
static int keeps_valid(const ctx *C, const double *x, int v, const double *floor) {
  int ns = C->vc_off[v + 1] - C->vc_off[v];
  for (int p = 0; p < ns && p < 64; p++)
    if (floor[p] > 0 && !(ut_cell_min_jac(C, x, C->vc[C->vc_off[v] + p]) >= floor[p])) return 0;
  return 1;
}

static int slide_boundary(ctx *C, double *x, double beta, const unsigned char *region, unsigned char *moved) {
  int total = 0;
  mesh *m = C->m;
  penalty_arg pa = {x, beta};
  for (int pass = 0; pass < 10; pass++) {
    int changed = 0;
    for (int v = 0; v < m->nvert; v++) {
      if (!C->bnd[v] || C->fixed[v] || !region[v]) continue;
      if (C->d == 3) {
        if (ut_slide_3d(C, x, v, untangle_penalty, NULL, &pa)) {
          changed++;
          if (!moved[v]) total++;
          moved[v] = 1;
        }
        continue;
      }
      double f0 = local_penalty(C, x, v, beta, C->jscale);
      if (f0 == 0) continue;
      double p0[2] = {x[2 * v], x[2 * v + 1]}, best = f0, bp[2] = {p0[0], p0[1]};
      /* a slide may not invalidate a cell of v's star that is valid: the penalty would trade
       * a boundary cell for the tangle beside it, and repeated slides of 0.95 of the edge
       * put v onto its neighbour (a degenerate corner cell no interior vertex can repair);
       * nor bring one below β (or below its corner Jacobian, when that is smaller) */
      double floor[64];
      int ns = C->vc_off[v + 1] - C->vc_off[v];
      for (int p = 0; p < ns && p < 64; p++) {
        double j = ut_cell_min_jac(C, x, C->vc[C->vc_off[v] + p]);
        floor[p] = j > C->jtol ? fmin(j, beta > C->jtol ? beta : j) : 0;
      }
      for (int side = 0; side < 2; side++) {
        const double *a = x + 2 * C->bnb[2 * v + side];
        double lo = 0, hi = 0.95, gr = (sqrt(5.0) - 1) / 2;
        double s1 = hi - gr * (hi - lo), s2 = lo + gr * (hi - lo), f1, f2;
#define AT(s) (x[2 * v] = p0[0] + (s) * (a[0] - p0[0]), x[2 * v + 1] = p0[1] + (s) * (a[1] - p0[1]), \
               keeps_valid(C, x, v, floor) ? local_penalty(C, x, v, beta, C->jscale) : INFINITY)
        f1 = AT(s1);
        f2 = AT(s2);
        for (int it = 0; it < 60; it++) {
          if (f1 <= f2) { hi = s2; s2 = s1; f2 = f1; s1 = hi - gr * (hi - lo); f1 = AT(s1); }
          else { lo = s1; s1 = s2; f1 = f2; s2 = lo + gr * (hi - lo); f2 = AT(s2); }
        }
        double s = 0.5 * (lo + hi), f = AT(s);
#undef AT
        if (f < best) { best = f; bp[0] = x[2 * v]; bp[1] = x[2 * v + 1]; }
      }
      x[2 * v] = bp[0];
      x[2 * v + 1] = bp[1];
      if (best < f0) {
        changed++;
        if (!moved[v]) total++;
        moved[v] = 1;
      }
    }
    if (!changed) break;
  }
  return total;
}

/* the region of stage 2: the vertices of invalid cells grown by `rings` layers of cells, ring
 * by ring from the vertices the last ring added (a pass over every vertex per ring had been
 * 5% of the million-triangle spiral's untangling at 64 rings) */
static void grow_region(const ctx *C, const double *x, int rings, unsigned char *region) {
  mesh *m = C->m;
  memset(region, 0, (size_t)m->nvert);
  int *front = malloc(sizeof(int) * ((size_t)m->nvert + 1)), *added = malloc(sizeof(int) * ((size_t)m->nvert + 1)), nf = 0;
  for (int c = 0; c < m->ncell; c++)
    if (!(ut_cell_min_jac(C, x, c) > C->jtol))
      for (int i = 0; i < C->nvc; i++) {
        int v = cell_of(C, c)[i];
        if (!region[v] && front) front[nf++] = v;
        region[v] = 1;
      }
  for (int r = 0; r < rings && front && added && nf; r++) {
    int na = 0;
    for (int k = 0; k < nf; k++) {
      int v = front[k];
      for (int p = C->vc_off[v]; p < C->vc_off[v + 1]; p++)
        for (int i = 0; i < C->nvc; i++) {
          int u = cell_of(C, C->vc[p])[i];
          if (!region[u]) { region[u] = 1; added[na++] = u; }
        }
    }
    int *t = front;
    front = added;
    added = t;
    nf = na;
  }
  free(front);
  free(added);
}



/* the cells around the free vertices (each once) */
int ut_cells_around(const ctx *C, work *W, const int *freev, int nfree) {
  int n = 0;
  for (int i = 0; i < nfree; i++)
    for (int p = C->vc_off[freev[i]]; p < C->vc_off[freev[i] + 1]; p++)
      if (!W->cmark[C->vc[p]]) { W->cmark[C->vc[p]] = 1; W->cells[n++] = C->vc[p]; }
  for (int i = 0; i < n; i++) W->cmark[W->cells[i]] = 0;
  return n;
}

/* laplace_solve's system (rows rp/col/val off the diagonal dg; right sides b, d per row) by
 * ut_amg_pcg, one hierarchy of the scalar operator for the d coordinates, from z's values:
 * 0 done (z written, converged or not), 1 no multigrid */
static int laplace_multigrid(int d, int nfree, const int *rp, const int *col, const double *val, const double *dg,
                             const double *b, double *z, const int *freev, int maxit, double tol, int *iters, double *res) {
  int status = 1;
  size_t nb = (size_t)rp[nfree] + (size_t)nfree, n = (size_t)nfree;
  ut_bsr P = {malloc(sizeof(int) * (n + 1)), malloc(sizeof(int) * (nb + 1))};
  double *v = malloc(sizeof(double) * (nb + 1)), *bs = malloc(sizeof(double) * (n * d + 1)),
         *xs = malloc(sizeof(double) * (n * d + 1));
  if (!P.off || !P.col || !v || !bs || !xs) goto out;
  P.off[0] = 0;
  for (int i = 0; i < nfree; i++) { /* the row's entries and its diagonal, by column (rows are short) */
    int o = P.off[i], len = 0;
    for (int k = rp[i] - 1; k < rp[i + 1]; k++) {
      int c = k < rp[i] ? i : col[k], j = len++;
      double w = k < rp[i] ? dg[i] : val[k];
      for (; j > 0 && P.col[o + j - 1] > c; j--) {
        P.col[o + j] = P.col[o + j - 1];
        v[o + j] = v[o + j - 1];
      }
      P.col[o + j] = c;
      v[o + j] = w;
    }
    P.off[i + 1] = o + len;
  }
  for (size_t i = 0; i < n; i++)
    for (int a = 0; a < d; a++) {
      bs[(size_t)a * n + i] = b[i * d + a];
      xs[(size_t)a * n + i] = z[(size_t)freev[i] * d + a];
    }
  if (ut_amg_pcg(&P, v, nfree, 1, d, bs, xs, maxit, tol, iters, res) == 1) goto out;
  for (size_t i = 0; i < n; i++)
    for (int a = 0; a < d; a++) z[(size_t)freev[i] * d + a] = xs[(size_t)a * n + i];
  status = 0;
out:
  free(P.off); free(P.col); free(v); free(bs); free(xs);
  return status;
}

/* Σ_k σ_0k (z_k − z_0) = 0 at the free vertices (eq. 1.2 of the morphing paper), z given
 * elsewhere; σ_0k = Σ τ_j over the cells j that have the edge 0k (τ = 1 when tau is NULL).
 * The operator is assembled once (CSR over the free vertices, a row per vertex built from
 * its cells, so a shared edge is one entry), then Jacobi-preconditioned CG solves one
 * component at a time (on a piece of UT_AMG_MIN_ROWS free vertices or more, the multigrid's
 * conjugate gradients above); the fixed neighbours' values go into the right-hand sides. */
static int laplace_solve(const ctx *C, work *W, double *z, const int *freev, int nfree, const double *tau,
                         int maxit, double tol, int *iters, double *res) {
  int d = C->d, ne = cell_nedges(C->m->type), status = 0;
  *iters = 0;
  *res = 0;
  for (int i = 0; i < nfree; i++) W->fidx[freev[i]] = i;
  size_t cap = (size_t)nfree * 8 + 16, nnz = 0;
  int *rp = malloc(sizeof(int) * ((size_t)nfree + 1)), *col = malloc(sizeof(int) * cap),
      *pos = malloc(sizeof(int) * ((size_t)nfree + 1));
  double *val = malloc(sizeof(double) * cap), *b = calloc((size_t)nfree * d + 1, sizeof(double)),
         *dg = calloc((size_t)nfree + 1, sizeof(double)), *u = malloc(sizeof(double) * ((size_t)nfree + 1)),
         *r = malloc(sizeof(double) * ((size_t)nfree + 1)), *pp = malloc(sizeof(double) * ((size_t)nfree + 1)),
         *q = malloc(sizeof(double) * ((size_t)nfree + 1));
  if (!rp || !col || !pos || !val || !b || !dg || !u || !r || !pp || !q) { status = 1; goto done; }
  for (int i = 0; i < nfree; i++) pos[i] = -1;
  for (int i = 0; i < nfree; i++) {
    int v = freev[i];
    rp[i] = (int)nnz;
    for (int p = C->vc_off[v]; p < C->vc_off[v + 1]; p++) {
      int c = C->vc[p];
      const int *cell = cell_of(C, c);
      double w = tau ? tau[c] : 1;
      for (int e = 0; e < ne; e++) {
        const int *ev = cell_edge_verts(C->m->type, e);
        int o;
        if (cell[ev[0]] == v) o = cell[ev[1]];
        else if (cell[ev[1]] == v) o = cell[ev[0]];
        else continue;
        dg[i] += w;
        int j = W->fidx[o];
        if (j < 0) {
          for (int k = 0; k < d; k++) b[(size_t)i * d + k] += w * z[(size_t)o * d + k];
          continue;
        }
        if (pos[j] >= rp[i]) { val[pos[j]] -= w; continue; }
        if (nnz == cap) {
          cap *= 2;
          int *nc = realloc(col, sizeof(int) * cap);
          if (nc) col = nc;
          double *nv = realloc(val, sizeof(double) * cap);
          if (nv) val = nv;
          if (!nc || !nv) { status = 1; goto done; }
        }
        pos[j] = (int)nnz;
        col[nnz] = j;
        val[nnz++] = -w;
      }
    }
  }
  rp[nfree] = (int)nnz;
  /* large pieces on the multigrid of the scalar operator: Jacobi's iterations grow with the
   * piece (the random star's whole interior, 101 761 vertices: 710 iterations, 1.0 s of a
   * 1.6 s untangle). The operator ⊗ the d×d identity in d×d blocks cost 4–9 times the memory
   * traffic: the twisted million-tetrahedron bar's restarts took 4 s more than by Jacobi */
  if (nfree >= UT_AMG_MIN_ROWS && !laplace_multigrid(d, nfree, rp, col, val, dg, b, z, freev, maxit, tol, iters, res))
    goto done;
#define SPMV(in, out)                                              \
  for (int i = 0; i < nfree; i++) {                                \
    double acc = dg[i] * (in)[i];                                  \
    for (int k = rp[i]; k < rp[i + 1]; k++) acc += val[k] * (in)[col[k]]; \
    (out)[i] = acc;                                                \
  }
  for (int comp = 0; comp < d; comp++) {
    double bn = 0, rz = 0, rn = 0;
    for (int i = 0; i < nfree; i++) u[i] = z[(size_t)freev[i] * d + comp];
    SPMV(u, q);
    for (int i = 0; i < nfree; i++) {
      r[i] = b[(size_t)i * d + comp] - q[i];
      bn += b[(size_t)i * d + comp] * b[(size_t)i * d + comp];
      pp[i] = r[i] / dg[i];
      rz += r[i] * pp[i];
    }
    bn = sqrt(bn);
    int it;
    for (it = 0; it < maxit; it++) {
      rn = 0;
      for (int i = 0; i < nfree; i++) rn += r[i] * r[i];
      rn = sqrt(rn);
      if (rn <= tol * fmax(bn, 1e-300)) break;
      SPMV(pp, q);
      double pq = 0;
      for (int i = 0; i < nfree; i++) pq += pp[i] * q[i];
      if (!(pq > 0)) break;
      double al = rz / pq, rz2 = 0;
      for (int i = 0; i < nfree; i++) {
        u[i] += al * pp[i];
        r[i] -= al * q[i];
        rz2 += r[i] * r[i] / dg[i];
      }
      double be = rz2 / rz;
      rz = rz2;
      for (int i = 0; i < nfree; i++) pp[i] = r[i] / dg[i] + be * pp[i];
    }
#undef SPMV
    for (int i = 0; i < nfree; i++) z[(size_t)freev[i] * d + comp] = u[i];
    *iters = it > *iters ? it : *iters;
    *res = fmax(*res, bn > 0 ? rn / bn : rn);
  }
done:
  for (int i = 0; i < nfree; i++) W->fidx[freev[i]] = -1;
  free(rp); free(col); free(pos); free(val); free(b); free(dg); free(u); free(r); free(pp); free(q);
  return status;
}

/* L-BFGS on the interior vertices among verts (n); counts newly moved vertices */
static int optimize_vertices(ctx *C, work *W, double *x, double beta, int lift, const int *verts, int n, int maxit,
                             unsigned char *moved, int *iters) {
  int d = C->d, nfree = 0;
  int *freev = calloc((size_t)n + 1, sizeof(int));
  double *xs = malloc(sizeof(double) * ((size_t)n + 1) * d);
  if (!freev || !xs) { free(freev); free(xs); return -1; }
  for (int i = 0; i < n; i++)
    if (!C->bnd[verts[i]]) freev[nfree++] = verts[i];
  for (int i = 0; i < nfree; i++) {
    W->fidx[freev[i]] = i;
    for (int j = 0; j < d; j++) xs[i * d + j] = x[(size_t)freev[i] * d + j];
  }
  int ncell = ut_cells_around(C, W, freev, nfree);
  objective o = {.C = C, .beta = beta, .S = C->jscale, .ncell = ncell, .cells = W->cells, .fidx = W->fidx, .lift = lift, .freev = freev};
  double f = 0;
  int it = nfree ? ut_lbfgs(&o, x, freev, nfree, maxit, &f) : 0;
  int total = 0;
  for (int i = 0; i < nfree; i++) {
    int v = freev[i], ch = 0;
    W->fidx[v] = -1;
    for (int j = 0; j < d; j++) ch |= x[(size_t)v * d + j] != xs[i * d + j];
    if (ch && !moved[v]) { moved[v] = 1; total++; }
  }
  *iters += it > 0 ? it : 0;
  free(freev);
  free(xs);
  return total;
}

/* the connected pieces of the region (vertices joined through cells), as one list with
 * offsets; returns the number of pieces */
static int region_pieces(const ctx *C, const unsigned char *region, int *list, int *off) {
  mesh *m = C->m;
  int *seen = calloc((size_t)m->nvert + 1, sizeof(int)), np = 0, n = 0;
  if (!seen) return -1;
  for (int s = 0; s < m->nvert; s++) {
    if (!region[s] || seen[s]) continue;
    off[np] = n;
    seen[s] = 1;
    list[n++] = s;
    for (int h = off[np]; h < n; h++) {
      int v = list[h];
      for (int p = C->vc_off[v]; p < C->vc_off[v + 1]; p++) {
        const int *cell = cell_of(C, C->vc[p]);
        for (int i = 0; i < C->nvc; i++)
          if (region[cell[i]] && !seen[cell[i]]) { seen[cell[i]] = 1; list[n++] = cell[i]; }
      }
    }
    np++;
  }
  off[np] = n;
  free(seen);
  return np;
}

static int piece_invalid(const ctx *C, work *W, const double *x, const int *verts, int n) {
  int ncell = ut_cells_around(C, W, verts, n), bad = 0;
  for (int i = 0; i < ncell; i++) bad += !(ut_cell_min_jac(C, x, W->cells[i]) > C->jtol);
  return bad;
}

static double piece_min_jac(const ctx *C, work *W, const double *x, const int *verts, int n) {
  int ncell = ut_cells_around(C, W, verts, n);
  double mn = INFINITY;
  for (int i = 0; i < ncell; i++) mn = fmin(mn, ut_cell_min_jac(C, x, W->cells[i]));
  return mn;
}

void untangle_defaults(untangle_opts *o) {
  /* every field not named below is 0 (reference_escape was left unset: a Lua call's stack
   * garbage made mesh:untangle{reference = ...} now and then stop at the first valid state
   * without moving towards the reference shapes) */
  memset(o, 0, sizeof *o);
  o->beta = -1;
  o->max_iterations = 100;
  o->slide = 1;
  o->placement = 0;
  o->verbose = 0;
  o->xref = NULL;
  o->motion_weight = 0;
  o->no_global = 0;
}

static void stage_print(const untangle_stage *s) {
  printf("  %-28s invalid %d -> %d, below beta %d, moved %d vertices, %d %s, %.3f s\n", s->name, s->invalid_before,
         s->invalid_after, s->below_beta_after, s->moved, s->iterations,
         s->iterations == 1 ? "iteration" : "iterations", s->seconds);
}

/* a stage starts from the previous one's invalid count and ends with fresh counts */
static double stage_begin(ctx *C, untangle_stage *s, const char *name, int invalid_before) {
  if (C->progress) C->progress->stage = name;
  s->name = name;
  s->invalid_before = invalid_before;
  return ut_now();
}
static void stage_end(const ctx *C, const double *x, double beta, untangle_stage *s, double ts, int verbose) {
  ut_count_cells(C, x, beta, &s->invalid_after, &s->below_beta_after);
  s->seconds = ut_now() - ts;
  if (verbose) stage_print(s);
}

typedef struct {
  double *x;
  int ninv;
  double jmin;
  int stage; /* after which stage (0: the input) */
} best_state;

static void best_offer(const ctx *C, const double *x, best_state *b, size_t nx, int stage) {
  if (!b->x) return;
  for (size_t i = 0; i < nx; i++)
    if (!isfinite(x[i])) return; /* a state with a non-finite coordinate is never the best */
  int ninv = 0;
  double jmin = INFINITY;
  for (int c = 0; c < C->m->ncell; c++) {
    double j = ut_cell_min_jac(C, x, c);
    ninv += !(j > C->jtol);
    jmin = fmin(jmin, j);
  }
  if (isnan(jmin)) jmin = -INFINITY;
  if (ninv < b->ninv || (ninv == b->ninv && jmin >= b->jmin)) {
    memcpy(b->x, x, sizeof(double) * nx);
    b->ninv = ninv;
    b->jmin = jmin;
    b->stage = stage;
  }
}

/* every interior vertex together on the global barrier energy (untangle_global.c), kept
 * only if it leaves fewer than *ninv invalid cells (then *ninv is updated and the moved
 * vertices recorded in stage s): 1 if kept */
static int try_global(ctx *C, work *W, double *x, double *save, unsigned char *trial, unsigned char *moved,
                      unsigned char *touched, int maxit, const double *cwinv, double beta, int *ninv, untangle_stage *s) {
  mesh *m = C->m;
  size_t nx = (size_t)m->nvert * (size_t)C->d;
  if (!W->fidx || !W->cells || !save || !trial || m->type == CELL_INTERVAL) return 0;
  memcpy(save, x, sizeof(double) * nx);
  int its = 0, mv = 0, after, kept = 0;
  memset(trial, 0, (size_t)m->nvert);
  if (ut_untangle_global(C, W, x, maxit, cwinv, NULL, &its, &mv, trial) == 0) {
    ut_count_cells(C, x, beta, &after, NULL);
    if (after < *ninv) {
      s->iterations += its;
      for (int v = 0; v < m->nvert; v++)
        if (trial[v] && !moved[v]) { moved[v] = 1; touched[v] = 1; s->moved++; }
      *ninv = after;
      kept = 1;
    } else memcpy(x, save, sizeof(double) * nx);
  } else memcpy(x, save, sizeof(double) * nx);
  memset(trial, 0, (size_t)m->nvert);
  return kept;
}

/* one run of the three stages (untangle_run) and what its stages share: the context, the
 * input coordinates, the reference shapes' inverse Jacobians, the vertices moved and
 * touched, stage 2's work arrays (stage 3's lift reuses them) and the best state seen */
typedef struct {
  mesh *m;
  const untangle_opts *o;
  untangle_report *r;
  ctx C;
  work W;
  double beta;
  int maxit;
  size_t nx;
  double *x0, *cwinv, *save;
  unsigned char *moved, *region, *touched, *trial, *held;
  int *list, *off;
  best_state best;
} run;

static void run_free(run *R) {
  free(R->W.fidx); free(R->W.cmark); free(R->W.cells); free(R->list); free(R->off); free(R->save); free(R->trial); free(R->held);
  free(R->x0); free(R->moved); free(R->region); free(R->touched); free(R->cwinv); free(R->best.x);
  ut_ctx_free(&R->C);
}

/* the context, the input's copy, the reference shapes, the best state (the input's) */
static int run_init(run *R, mesh *m, const untangle_opts *o, untangle_report *r, double t0, ut_progress *pg, char *err) {
  memset(R, 0, sizeof *R);
  R->m = m;
  R->o = o;
  R->r = r;
  if (ut_ctx_init(&R->C, m, o->slide, err)) return 1;
  *pg = (ut_progress){o->progress, "untangle", NULL, t0, t0};
  R->C.progress = pg;
  R->beta = r->beta = o->beta < 0 ? untangle_default_beta(m) : o->beta;
  R->nx = (size_t)m->nvert * m->dim;
  R->x0 = malloc(sizeof(double) * R->nx);
  R->moved = calloc((size_t)m->nvert + 1, 1);
  R->region = calloc((size_t)m->nvert + 1, 1);
  R->touched = calloc((size_t)m->nvert + 1, 1);
  if (!R->x0 || !R->moved || !R->region || !R->touched) { snprintf(err, MESH_ERRLEN, "out of memory"); return 1; }
  memcpy(R->x0, m->x, sizeof(double) * R->nx);
  /* motion_weight: the stage 2 and global objectives weigh the distance to x0 (its scale a
   * typical edge, from the typical corner Jacobian) */
  if (o->motion_weight > 0) {
    R->C.x0 = R->x0;
    R->C.anchor = o->motion_weight / pow(R->C.jscale, 2.0 / m->dim);
  }
  R->C.escape = o->xref && o->reference_escape;
  /* reference shapes for the global stage */
  if (o->xref) {
    if (m->type == CELL_INTERVAL) { snprintf(err, MESH_ERRLEN, "reference shapes are for 2D and 3D cells"); return 1; }
    if (!(R->cwinv = ut_reference_winv(&R->C, o->xref, err))) return 1;
  }
  R->maxit = o->max_iterations > 0 ? o->max_iterations : 100;
  ut_count_cells(&R->C, m->x, R->beta, &r->invalid_before, NULL);
  /* the best state seen (fewest invalid cells, then the largest smallest corner Jacobian):
   * a mesh with no valid embedding may defeat the stages, but is never left worse */
  R->best = (best_state){malloc(sizeof(double) * (R->nx + 1)), INT_MAX, -INFINITY, -1};
  best_offer(&R->C, m->x, &R->best, R->nx, 0);
  if (o->verbose)
    printf("untangle: %d %s, %d invalid, beta %.3g, boundary %s\n", m->ncell, cell_plural(m->type), r->invalid_before,
           R->beta, o->slide ? "slides" : "fixed");
  return 0;
}

/* stage 1: feasible set, J > 0 */
static void stage_feasible(run *R) {
  mesh *m = R->m;
  untangle_report *r = R->r;
  untangle_stage *s = &r->stage[0];
  /* more than a quarter of the cells inverted is a scrambled knot (stage 2's rule for a
   * piece): vertex-by-vertex placement finds almost every feasible set empty there (100k
   * tetrahedra, all thrown: 1.5 s to move 4 vertices), so it is left to stage 2's harmonic
   * restart. Small tangles (up to 1000 invalid cells) keep the paper's stage 1: it is cheap
   * there and puts a single pulled vertex back exactly. */
  int knot = r->invalid_before > m->ncell / 4 && r->invalid_before > 1000;
  double ts = stage_begin(&R->C, s, knot ? "1 feasible set (knot: skip)" : "1 feasible set", r->invalid_before);
  s->moved = r->invalid_before && !knot
                 ? ut_feasible_passes(&R->C, m->x, 0, 0, NULL, R->o->placement, R->maxit, R->moved, &s->iterations) : 0;
  stage_end(&R->C, m->x, R->beta, s, ts, R->o->verbose);
  best_offer(&R->C, m->x, &R->best, R->nx, 1);
}

/* the optimizer is stuck in a local minimum of (3.3) or a knot on the piece's n vertices
 * pv (left invalid cells): restart the piece from the harmonic (Tutte) position of its
 * interior vertices — valid for triangles inside a convex boundary, and the way out of
 * knots in practice — and keep it when it leaves no more invalid cells than the optimizer
 * did; a knot's restart that gains nothing holds its vertices (*knot_stuck = 1) */
static void restart_piece(run *R, untangle_stage *s, int *pv, int n, int knot, int *knot_stuck) {
  ctx *C = &R->C;
  double *x = R->m->x, *save = R->save;
  int nf = 0, it;
  double res;
  for (int i = 0; i < n; i++)
    if (!C->bnd[pv[i]]) pv[nf++] = pv[i];
  for (int i = 0; i < nf; i++)
    for (int j = 0; j < C->d; j++) save[(size_t)i * C->d + j] = x[(size_t)pv[i] * C->d + j];
  int left = piece_invalid(C, &R->W, x, pv, nf);
  laplace_solve(C, &R->W, x, pv, nf, NULL, 10000, 1e-8, &it, &res);
  int its = 0;
  optimize_vertices(C, &R->W, x, R->beta, 0, pv, nf, 10 * R->maxit, R->trial, &its);
  int after_restart = piece_invalid(C, &R->W, x, pv, nf);
  if (knot && after_restart >= left) {
    *knot_stuck = 1;
    for (int i = 0; i < nf; i++) R->held[pv[i]] = 1;
  }
  if (after_restart <= left) {
    s->iterations += its;
    for (int i = 0; i < nf; i++) {
      int ch = 0;
      for (int j = 0; j < C->d; j++) ch |= x[(size_t)pv[i] * C->d + j] != save[(size_t)i * C->d + j];
      if (ch && !R->moved[pv[i]]) { R->moved[pv[i]] = 1; s->moved++; }
    }
  } else
    for (int i = 0; i < nf; i++)
      for (int j = 0; j < C->d; j++) x[(size_t)pv[i] * C->d + j] = save[(size_t)i * C->d + j];
  for (int i = 0; i < nf; i++) R->trial[pv[i]] = 0;
}

/* one connected piece of stage 2's region (its n vertices pv) on its own: small problems
 * converge fast. 0 when it had no invalid cell, -1 when the optimizer failed, else 1 */
static int repair_piece(run *R, untangle_stage *s, int *pv, int n, int *knot_stuck) {
  ctx *C = &R->C;
  double *x = R->m->x;
  int bad = piece_invalid(C, &R->W, x, pv, n);
  if (!bad) return 0;
  /* a piece where more than a quarter of the cells are inverted is a scrambled knot:
   * go straight to the harmonic restart below */
  int knot = bad > ut_cells_around(C, &R->W, pv, n) / 4;
  if (!knot) {
    int got = optimize_vertices(C, &R->W, x, R->beta, 0, pv, n, 10 * R->maxit, R->moved, &s->iterations);
    if (got < 0) return -1;
    s->moved += got;
  }
  int left = piece_invalid(C, &R->W, x, pv, n);
  /* a piece around a knot whose harmonic restart has failed (its vertices held) is not
   * restarted again: a knot waits until the rings have grown around it enough that it is
   * no longer one (a quarter of its piece's cells), and then the optimizer above takes it.
   * The million-triangle spiral's restarts at rings 4–64 each gave back more invalid cells
   * than they started from (0.5–0.7 s of its untangle, the same mesh to the bit without
   * them); on the 36 hard tangles of bench/untangle_sweep.lua the minima after smoothing
   * moved by -0.5% to +0.02% (a ring-4 restart that had repaired the Tutte spiral 200 x 25
   * is not tried: the optimizer repairs it at ring 8) */
  int around = 0;
  for (int i = 0; i < n && left && !around; i++) around = R->held[pv[i]];
  if (!around && left) restart_piece(R, s, pv, n, knot, knot_stuck);
  return 1;
}

/* stage 2: optimization of (3.3); boundary vertices one by one along the boundary, then
 * the interior vertices of a growing region around the invalid cells together. The cells
 * that may change: everything around the invalid cells (and, after stage 2, around what
 * moved) — the rest of the mesh keeps its coordinates bit for bit */
static void stage_optimize(run *R, char *err) {
  mesh *m = R->m;
  const untangle_opts *o = R->o;
  ctx *C = &R->C;
  double beta = R->beta;
  untangle_stage *s = &R->r->stage[1];
  double ts = stage_begin(C, s, "2 optimization", R->r->stage[0].invalid_after);
  int ninv = s->invalid_before;
  R->W.fidx = malloc(sizeof(int) * ((size_t)m->nvert + 1));
  R->W.cmark = calloc((size_t)m->ncell + 1, 1);
  R->W.cells = malloc(sizeof(int) * ((size_t)m->ncell + 1));
  R->list = malloc(sizeof(int) * ((size_t)m->nvert + 1));
  R->off = malloc(sizeof(int) * ((size_t)m->nvert + 2));
  R->save = malloc(sizeof(double) * (R->nx + 1));
  R->trial = calloc((size_t)m->nvert + 1, 1);
  /* the interior vertices of knots whose harmonic restart failed (restart_piece) */
  R->held = calloc((size_t)m->nvert + 1, 1);
  if (!R->W.fidx || !R->W.cmark || !R->W.cells || !R->list || !R->off || !R->save || !R->trial || !R->held) {
    snprintf(err, MESH_ERRLEN, "out of memory");
    ninv = 0;
  } else
    for (int v = 0; v < m->nvert; v++) R->W.fidx[v] = -1;
  int prev_inv = ninv, global_tried = 0, knot_stuck = 0;
  for (int rings = 2; ninv > 0 && rings <= 1 << 20; rings *= 2) {
    grow_region(C, m->x, rings, R->region);
    int whole = 1;
    for (int v = 0; v < m->nvert; v++) {
      R->touched[v] |= R->region[v];
      whole &= R->region[v];
    }
    /* the tangle's neighbourhood already holds half the interior vertices, or 40% in one
     * connected piece, and it is not a scrambled knot (over a quarter of the cells inverted:
     * those go to the pieces' harmonic restart, which gives a scrambled grid back exactly):
     * a twisted bar, every interior vertex out of place. Little is left to keep in place, and
     * the global energy, which moves every interior vertex together, is the faster way (bar of
     * 73 728 tetrahedra: 0.56 s against 1.79 s for the pieces' optimization, and a mesh the
     * energy smoother no longer improves). The local rounds go on from its result if it
     * leaves cells invalid.
     * The 40% in one piece: the twisted bars of 144 000 and 248 832 tetrahedra (49% and 41%)
     * took 4.5 and 5.2 s to untangle by the pieces' optimization and left minima of 0.007
     * and 0.09 that cost the energy smoother 5.9 and 2.6 s; by the global energy 1.7 and
     * 3.6 s, minima 0.31 and 0.25, smoothing 0.9 and 1.9 s. Scattered tangles (a 5% random
     * perturbation of 546 750 tetrahedra: 40-50% of the vertices in many pieces) stay local:
     * there the global energy moved every vertex */
    int nin = 0, nreg = 0; /* interior vertices, those in the region */
    for (int v = 0; v < m->nvert; v++) { nin += !C->bnd[v]; nreg += R->region[v] && !C->bnd[v]; }
    int np = region_pieces(C, R->region, R->list, R->off), all = 1; /* the region's pieces, below too */
    if (rings == 2 && (2 * nreg >= nin || (5 * nreg >= 2 * nin && np == 1)) && 4 * ninv <= m->ncell && !global_tried &&
        !o->no_global) {
      global_tried = 1;
      if (try_global(C, &R->W, m->x, R->save, R->trial, R->moved, R->touched, 10 * R->maxit, R->cwinv, beta, &ninv, s)) {
        ut_count_cells(C, m->x, beta, &ninv, NULL);
        prev_inv = ninv;
        if (!ninv) break;
      }
    }
    /* boundary vertices slide only once the interior alone has failed a round (the paper
     * slides them first; on 3D tangles that moved boundary vertices the interior did not
     * need moved and could leave a tangle that the fixed-boundary run undoes) */
    if (o->slide && rings > 2) s->moved += slide_boundary(C, m->x, beta, R->region, R->moved);
    for (int k = 0; k < np; k++) {
      int got = repair_piece(R, s, R->list + R->off[k], R->off[k + 1] - R->off[k], &knot_stuck);
      if (got < 0) break;
      if (got) all = 0;
    }
    /* a knot's harmonic restart gained nothing and over a quarter of the cells are inverted:
     * the rings would only grow to the whole mesh, repeating the restart (it gives a Tutte
     * embedding back: a Tutte-started spiral of 640 x 160 cells spent 5.7 s in eight rings),
     * so the global energy comes now (the spiral's stage 2: 23 -> 1.5 s with Newton steps) */
    if (knot_stuck && 4 * ninv > m->ncell && !global_tried && !o->no_global) break;
    /* the single-vertex placements over the region, unless its pieces left over a quarter
     * more cells invalid than the ring started with: the next ring, twice as wide, optimizes
     * all of their vertices again from this state (the million-triangle spiral's ring 64 went
     * 32 704 -> 44 323, then its passes took 1.3 s of the untangle's 4.7 for 42 106, and ring
     * 128 repaired everything either way). Below a quarter the passes mend what the pieces'
     * optimizer did: skipped after any increase, the random star's ring 16 (831 -> 885)
     * left a mesh whose smoothing took 29 Newton steps instead of 23 (bench/RESULTS.md) */
    int pass;
    ut_count_cells(C, m->x, beta, &ninv, NULL);
    if (4 * (long)ninv <= 5 * (long)prev_inv) {
      s->moved += ut_feasible_passes(C, m->x, 0, 0, R->region, o->placement, R->maxit, R->moved, &pass);
      ut_count_cells(C, m->x, beta, &ninv, NULL);
    }
    /* stop when there is nothing left to grow into and the last round did not help */
    if ((all && rings > 64) || (whole && ninv >= prev_inv)) break;
    prev_inv = ninv;
  }
  /* the local optimization left knots: every interior vertex together on the global
   * barrier energy (untangle_global.c), kept only if it leaves fewer invalid cells */
  if (ninv > 0 && !global_tried && !o->no_global)
    try_global(C, &R->W, m->x, R->save, R->trial, R->moved, R->touched, 10 * R->maxit, R->cwinv, beta, &ninv, s);
  stage_end(C, m->x, beta, s, ts, o->verbose);
  best_offer(C, m->x, &R->best, R->nx, 2);
}

/* stage 3's last step: what one vertex at a time cannot lift (neighbours below β together):
 * (3.3) once more over the vertices of the cells below β near the marked vertices t2,
 * stopping when every cell is at least β; kept only if no cell became invalid and the
 * smallest corner Jacobian grew */
static void lift_together(run *R, untangle_stage *s, const unsigned char *t2) {
  mesh *m = R->m;
  ctx *C = &R->C;
  double beta = R->beta, *save = R->save;
  unsigned char *trial = R->trial;
  int *list = R->list;
  int nlift = 0, ok = R->W.fidx && R->W.cmark && R->W.cells && list && save && trial && beta > 0;
  for (int c = 0; ok && c < m->ncell; c++) {
    const int *cell = cell_of(C, c);
    int near = 0;
    for (int i = 0; i < C->nvc; i++) near |= t2[cell[i]];
    if (!near || ut_cell_min_jac(C, m->x, c) >= beta) continue;
    for (int i = 0; i < C->nvc; i++)
      if (!C->bnd[cell[i]] && !trial[cell[i]]) { trial[cell[i]] = 1; list[nlift++] = cell[i]; }
  }
  if (nlift && !piece_invalid(C, &R->W, m->x, list, nlift)) {
    double jmin = piece_min_jac(C, &R->W, m->x, list, nlift);
    for (int i = 0; i < nlift; i++)
      for (int j = 0; j < C->d; j++) save[(size_t)i * C->d + j] = m->x[(size_t)list[i] * C->d + j];
    unsigned char *mv = trial; /* reused: cleared below */
    for (int i = 0; i < nlift; i++) mv[list[i]] = 0;
    int its = 0;
    optimize_vertices(C, &R->W, m->x, beta, 1, list, nlift, 10 * R->maxit, mv, &its);
    if (piece_invalid(C, &R->W, m->x, list, nlift) || piece_min_jac(C, &R->W, m->x, list, nlift) <= jmin)
      for (int i = 0; i < nlift; i++)
        for (int j = 0; j < C->d; j++) m->x[(size_t)list[i] * C->d + j] = save[(size_t)i * C->d + j];
    else {
      s->iterations += its;
      for (int i = 0; i < nlift; i++)
        if (mv[list[i]] && !R->moved[list[i]]) { R->moved[list[i]] = 1; s->moved++; }
    }
  }
  for (int i = 0; i < nlift; i++) trial[list[i]] = 0;
}

/* stage 3: feasible set with J >= β, around what stages 1–2 touched */
static void stage_lift(run *R) {
  mesh *m = R->m;
  ctx *C = &R->C;
  untangle_stage *s = &R->r->stage[2];
  double ts = stage_begin(C, s, "3 feasible set (J >= beta)", R->r->stage[1].invalid_after);
  for (int v = 0; v < m->nvert; v++) R->touched[v] |= R->moved[v];
  /* the neighbours of moved vertices too: their cells changed */
  size_t nvb = m->nvert > 0 ? (size_t)m->nvert : 0;
  unsigned char *t2 = malloc(nvb + 1);
  if (t2) {
    memcpy(t2, R->touched, nvb);
    for (int v = 0; v < m->nvert; v++)
      if (R->moved[v])
        for (int p = C->vc_off[v]; p < C->vc_off[v + 1]; p++)
          for (int i = 0; i < C->nvc; i++) t2[cell_of(C, C->vc[p])[i]] = 1;
    s->moved = R->beta > 0 ? ut_feasible_passes(C, m->x, R->beta, 1, t2, R->o->placement, R->maxit, R->moved, &s->iterations) : 0;
    lift_together(R, s, t2);
    free(t2);
  }
  stage_end(C, m->x, R->beta, s, ts, R->o->verbose);
  best_offer(C, m->x, &R->best, R->nx, 3);
}

/* reference shapes: the vertices the stages touched, now valid, minimize the energy
 * towards them (the local stages only aim at validity, and may have repaired the mesh
 * without the global stage); kept if every cell stays valid and the mean of the cells'
 * mean ratios relative to their shapes grows */
static void towards_reference(run *R) {
  mesh *m = R->m;
  ctx *C = &R->C;
  untangle_stage *s = &R->r->stage[2];
  if (!R->cwinv || s->invalid_after || !R->W.fidx || !R->W.cells || !R->save || !R->trial || R->o->no_global || C->escape) return;
  double *q = malloc(sizeof(double) * ((size_t)m->ncell + 1));
  if (!q) return;
  double q0 = 0, q1 = 0;
  ut_relative_mean_ratio(C, R->cwinv, q);
  for (int c = 0; c < m->ncell; c++) q0 += q[c];
  memcpy(R->save, m->x, sizeof(double) * R->nx);
  int its = 0, mv = 0, after = 1;
  memset(R->trial, 0, (size_t)m->nvert);
  for (int v = 0; v < m->nvert; v++) R->touched[v] |= R->moved[v];
  if (ut_untangle_global(C, &R->W, m->x, 10 * R->maxit, R->cwinv, R->touched, &its, &mv, R->trial) == 0)
    ut_count_cells(C, m->x, R->beta, &after, NULL);
  ut_relative_mean_ratio(C, R->cwinv, q);
  for (int c = 0; c < m->ncell; c++) q1 += q[c];
  if (!after && q1 > q0) {
    s->iterations += its;
    for (int v = 0; v < m->nvert; v++)
      if (R->trial[v] && !R->moved[v]) { R->moved[v] = 1; s->moved++; }
    if (R->o->verbose)
      printf("untangle: towards the reference shapes: mean relative mean ratio %.4f -> %.4f, %d iterations\n",
             q0 / m->ncell, q1 / m->ncell, its);
  } else memcpy(m->x, R->save, sizeof(double) * R->nx);
  memset(R->trial, 0, (size_t)m->nvert);
  free(q);
}

/* the vertices moved from x0 and their mean and largest displacement, into r */
static void displacement(const mesh *m, const double *x0, untangle_report *r) {
  double sum = 0;
  r->moved = 0;
  r->max_displacement = 0;
  for (int v = 0; v < m->nvert; v++) {
    double dd = 0;
    int ch = 0;
    for (int j = 0; j < m->dim; j++) {
      double e = m->x[(size_t)v * m->dim + j] - x0[(size_t)v * m->dim + j];
      ch |= m->x[(size_t)v * m->dim + j] != x0[(size_t)v * m->dim + j];
      dd += e * e;
    }
    if (!ch) continue;
    r->moved++;
    sum += sqrt(dd);
    r->max_displacement = fmax(r->max_displacement, sqrt(dd));
  }
  r->mean_displacement = r->moved ? sum / r->moved : 0;
}

/* the report: the best state seen kept when the stages did not end in it, the vertices
 * moved and their displacements */
static void run_report(run *R, double t0) {
  mesh *m = R->m;
  untangle_report *r = R->r;
  const untangle_stage *s = &r->stage[2];
  r->nstage = 3;
  r->invalid_after = s->invalid_after;
  if (R->best.x && R->best.stage >= 0 && R->best.stage < 3) {
    memcpy(m->x, R->best.x, sizeof(double) * R->nx);
    r->invalid_after = R->best.ninv;
    r->kept_stage = R->best.stage;
    if (R->o->verbose)
      printf("untangle: the stages did not end in the best state seen; kept the one after %s (%d invalid)\n",
             R->best.stage ? r->stage[R->best.stage - 1].name : "nothing (the input)", R->best.ninv);
  } else r->kept_stage = 3;
  displacement(m, R->x0, r);
  r->seconds = ut_now() - t0;
  if (R->o->verbose)
    printf("untangle: %s — %d invalid left, %d vertices moved (mean %.3g, max %.3g), %.3f s\n",
           r->invalid_after ? "FAILED" : "done", r->invalid_after, r->moved, r->mean_displacement,
           r->max_displacement, r->seconds);
}

/* the three stages of the seed's untangler, once */
static int untangle_run(mesh *m, const untangle_opts *o, untangle_report *r, char *err) {
  double t0 = ut_now();
  memset(r, 0, sizeof *r);
  if (m->ncell == 0) { snprintf(err, MESH_ERRLEN, "the mesh has no cells"); return 1; }
  run *R = malloc(sizeof *R);
  if (!R) { snprintf(err, MESH_ERRLEN, "out of memory"); return 1; }
  ut_progress pg;
  if (run_init(R, m, o, r, t0, &pg, err)) { run_free(R); free(R); return 1; }
  stage_feasible(R);
  stage_optimize(R, err);
  stage_lift(R);
  towards_reference(R);
  run_report(R, t0);
  run_free(R);
  free(R);
  return 0;
}

void untangle_report_print(const untangle_report *r, const mesh *m) {
  printf("untangle: %d %s, beta %.3g: invalid %d -> %d, %d vertices moved (mean %.3g, max %.3g), %.3f s\n",
         m->ncell, cell_plural(m->type), r->beta, r->invalid_before, r->invalid_after, r->moved,
         r->mean_displacement, r->max_displacement, r->seconds);
  for (int i = 0; i < r->nstage; i++) stage_print(&r->stage[i]);
  if (r->passes > 1) printf("  (%d passes of the three stages; the stages above are the first's)\n", r->passes);
  if (r->fallback_placement >= 0)
    printf("  (the %s placement stalled; passes with the %s placement repaired more)\n",
           r->fallback_placement ? "chebyshev" : "corners", r->fallback_placement ? "corners" : "chebyshev");
  else if (r->fallback_tried)
    printf("  (the other placement was tried from where the passes stalled, and did not repair more)\n");
  if (r->tutte_tried)
    printf("  (then a run aiming at the cells' shapes in the mesh's Tutte embedding on a circle%s)\n",
           r->tutte_kept ? " repaired more" : ", which did not repair more");
}

/* ---------------------------------------------------------------- Tutte reference */

/* A 2D mesh that is a topological disk (its boundary one loop, V − E + F = 1) embedded with
 * its boundary on a circle, in the boundary's arc-length proportions, the interior vertices
 * at the discrete harmonic positions (laplace_solve's edge weights): a convex-combination
 * map, valid for triangulations by Tutte's and Floater's theorems, which keeps the mesh's
 * combinatorial anisotropy (a strip of 12 x 30 cells about 40:1 becomes a disk of cells as
 * thin). Its cells are the reference shapes of the last fallback in mesh_untangle. The
 * circle's area is the mesh's (the sum of the signed cell measures, which moving interior
 * vertices does not change), and it runs in the boundary's orientation. NULL when the mesh
 * is not a disk, its signed measure is not positive, or out of memory. */
static double *tutte_reference(mesh *m) {
  if (m->dim != 2) return NULL;
  char err[MESH_ERRLEN];
  ctx C;
  if (ut_ctx_init(&C, m, 0, err)) { ut_ctx_free(&C); return NULL; }
  int nv = m->nvert, nbv = 0, nfree = 0, v0 = -1;
  double *z = malloc(sizeof(double) * 2 * (size_t)nv + 1), *cum = NULL, area = 0;
  int *loop = malloc(sizeof(int) * ((size_t)nv + 1)), *freev = malloc(sizeof(int) * ((size_t)nv + 1));
  work W = {malloc(sizeof(int) * ((size_t)nv + 1)), NULL, NULL};
  int ok = z && loop && freev && W.fidx;
  for (int v = 0; ok && v < nv; v++) {
    W.fidx[v] = -1;
    if (!C.bnd[v]) { freev[nfree++] = v; continue; }
    if (C.bnb[2 * v] < 0 || C.bnb[2 * v + 1] < 0) ok = 0;
    if (v0 < 0) v0 = v;
    nbv++;
  }
  for (int c = 0; ok && c < m->ncell; c++) area += mesh_cell_signed_measure(m, c);
  /* the loop from v0; every boundary vertex on it once */
  int len = 0, closed = 0;
  for (int prev = -1, cur = v0; ok && len < nbv;) {
    loop[len++] = cur;
    int next = C.bnb[2 * cur] != prev ? C.bnb[2 * cur] : C.bnb[2 * cur + 1];
    if (C.bnb[2 * next] != cur && C.bnb[2 * next + 1] != cur) ok = 0;
    prev = cur;
    cur = next;
    if (cur == v0) { closed = 1; break; }
  }
  /* V − E + F = 1, E = (edges per cell · F + B) / 2 with B = nbv boundary edges */
  long twice_e = (long)cell_nedges(m->type) * m->ncell + nbv;
  ok = ok && closed && len == nbv && nbv >= 3 && area > 0 && twice_e % 2 == 0 && (long)nv - twice_e / 2 + m->ncell == 1 &&
       (cum = malloc(sizeof(double) * ((size_t)nbv + 1)));
  if (ok) {
    double turn = 0; /* the loop's own orientation (shoelace), to run the circle the same way */
    cum[0] = 0;
    for (int k = 0; k < nbv; k++) {
      const double *a = m->x + 2 * (size_t)loop[k], *b = m->x + 2 * (size_t)loop[(k + 1) % nbv];
      cum[k + 1] = cum[k] + hypot(b[0] - a[0], b[1] - a[1]);
      turn += a[0] * b[1] - a[1] * b[0];
    }
    double R = sqrt(area / M_PI), sg = turn < 0 ? -1 : 1;
    ok = cum[nbv] > 0;
    for (int v = 0; ok && v < nv; v++) z[2 * v] = z[2 * v + 1] = 0;
    for (int k = 0; ok && k < nbv; k++) {
      double t = 2 * M_PI * cum[k] / cum[nbv];
      z[2 * (size_t)loop[k]] = R * cos(t);
      z[2 * (size_t)loop[k] + 1] = sg * R * sin(t);
    }
    int its;
    double res;
    if (ok && nfree && laplace_solve(&C, &W, z, freev, nfree, NULL, 20 * nv + 100, 1e-12, &its, &res)) ok = 0;
    /* every cell valid in it (a mesh outside the theorems' conditions, or an inexact solve,
     * may leave one degenerate): else no fallback, rather than the reference check's error */
    double *w = ok ? ut_reference_winv(&C, z, err) : NULL;
    if (!w) ok = 0;
    free(w);
  }
  free(cum); free(loop); free(freev); free(W.fidx);
  ut_ctx_free(&C);
  if (!ok) { free(z); return NULL; }
  return z;
}

/* ---------------------------------------------------------------- motion */

static int move_run(mesh *m, const double *disp, const unsigned char *fixed, move_report *r, char *err) {
  double t0 = ut_now();
  memset(r, 0, sizeof *r);
  ctx C;
  if (ut_ctx_init(&C, m, 0, err)) { ut_ctx_free(&C); return 1; }
  int d = m->dim, nfree = 0, status = 0;
  double *z = malloc(sizeof(double) * (size_t)m->nvert * d), *tau = malloc(sizeof(double) * ((size_t)m->ncell + 1));
  int *freev = malloc(sizeof(int) * ((size_t)m->nvert + 1));
  work W = {malloc(sizeof(int) * ((size_t)m->nvert + 1)), calloc((size_t)m->ncell + 1, 1),
            malloc(sizeof(int) * ((size_t)m->ncell + 1))};
  if (!z || !tau || !freev || !W.fidx || !W.cmark || !W.cells) {
    snprintf(err, MESH_ERRLEN, "out of memory");
    status = 1;
    goto done;
  }
  /* τ = 1 + (Vmax − Vmin)/V (eq. 1.1): stiff where cells are small */
  double vmin = INFINITY, vmax = 0;
  for (int c = 0; c < m->ncell; c++) {
    tau[c] = fabs(mesh_cell_signed_measure(m, c));
    vmin = fmin(vmin, tau[c]);
    vmax = fmax(vmax, tau[c]);
  }
  if (!(vmin > 0)) {
    snprintf(err, MESH_ERRLEN, "the mesh has zero-size cells: the diffusivity 1 + (Vmax - Vmin)/V is undefined");
    status = 1;
    goto done;
  }
  for (int c = 0; c < m->ncell; c++) {
    tau[c] = 1 + (vmax - vmin) / tau[c];
    r->tau_max = fmax(r->tau_max, tau[c]);
  }
  for (int v = 0; v < m->nvert; v++) {
    W.fidx[v] = -1;
    for (int j = 0; j < d; j++) z[(size_t)v * d + j] = fixed[v] ? disp[(size_t)v * d + j] : 0;
    if (!fixed[v]) freev[nfree++] = v;
  }
  if (nfree && laplace_solve(&C, &W, z, freev, nfree, tau, 20 * m->nvert + 100, 1e-10, &r->iterations, &r->residual)) {
    snprintf(err, MESH_ERRLEN, "out of memory");
    status = 1;
    goto done;
  }
  for (size_t i = 0; i < (size_t)m->nvert * d; i++) m->x[i] += z[i];
  ut_count_cells(&C, m->x, 0, &r->invalid_after, NULL);
done:
  r->seconds = ut_now() - t0;
  free(z); free(tau); free(freev); free(W.fidx); free(W.cmark); free(W.cells);
  ut_ctx_free(&C);
  return status;
}

/* ---------------------------------------------------------------- entry points */

/* every vertex coordinate finite, or a message naming the first that is not */
int ut_check_finite(const mesh *m, const char *what, char *err) {
  if (m->type == CELL_INTERVAL) { snprintf(err, MESH_ERRLEN, "%s is for 2D and 3D meshes, not intervals", what); return 1; }
  for (size_t i = 0; i < (size_t)m->nvert * m->dim; i++)
    if (!isfinite(m->x[i])) {
      snprintf(err, MESH_ERRLEN, "vertex %zu has a non-finite coordinate %c = %g: %s needs finite coordinates", i / m->dim + 1,
               "xyz"[i % m->dim], m->x[i], what);
      return 1;
    }
  return 0;
}



int ut_frame_enter(mesh *m, unit_frame *f, double extra, char *err) {
  memset(f, 0, sizeof *f);
  int d = m->dim;
  double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  for (int v = 0; v < m->nvert; v++)
    for (int j = 0; j < d; j++) {
      lo[j] = fmin(lo[j], m->x[(size_t)v * d + j]);
      hi[j] = fmax(hi[j], m->x[(size_t)v * d + j]);
    }
  double size = extra; /* a displacement to apply counts as a size too */
  for (int j = 0; j < d; j++) size = fmax(size, 0.5 * hi[j] - 0.5 * lo[j]);
  if (size == 0 || (size > 1e-100 && size < 1e100)) return 0;
  f->orig = malloc(sizeof(double) * ((size_t)m->nvert * d + 1));
  if (!f->orig) { snprintf(err, MESH_ERRLEN, "out of memory"); return 1; }
  memcpy(f->orig, m->x, sizeof(double) * (size_t)m->nvert * d);
  frexp(size, &f->e);
  for (int j = 0; j < d; j++) f->c[j] = 0.5 * ldexp(lo[j], -f->e) + 0.5 * ldexp(hi[j], -f->e);
  for (int v = 0; v < m->nvert; v++)
    for (int j = 0; j < d; j++) m->x[(size_t)v * d + j] = ldexp(f->orig[(size_t)v * d + j], -f->e) - f->c[j];
  return 0;
}

void ut_frame_leave(mesh *m, unit_frame *f) {
  if (!f->orig) return;
  int d = m->dim;
  for (int v = 0; v < m->nvert; v++) {
    int moved = 0;
    for (int j = 0; j < d; j++) moved |= m->x[(size_t)v * d + j] != ldexp(f->orig[(size_t)v * d + j], -f->e) - f->c[j];
    for (int j = 0; j < d; j++)
      m->x[(size_t)v * d + j] = moved ? ldexp(m->x[(size_t)v * d + j] + f->c[j], f->e) : f->orig[(size_t)v * d + j];
  }
  free(f->orig);
  f->orig = NULL;
}

static int check_opts(const untangle_opts *o, char *err) {
  if (!(o->beta < 0) && !(o->beta >= 0 && o->beta < INFINITY)) {
    snprintf(err, MESH_ERRLEN, "beta must be a finite number >= 0 (or negative for the default), got %g", o->beta);
    return 1;
  }
  if (o->max_iterations < 1 || o->max_iterations > 1000000) {
    snprintf(err, MESH_ERRLEN, "max_iterations must be 1 to 1000000, got %d", o->max_iterations);
    return 1;
  }
  if (o->placement != 0 && o->placement != 1) { snprintf(err, MESH_ERRLEN, "placement must be 0 or 1"); return 1; }
  if (!(o->motion_weight >= 0) || !isfinite(o->motion_weight)) {
    snprintf(err, MESH_ERRLEN, "motion_weight must be a finite number >= 0, got %g", o->motion_weight);
    return 1;
  }
  return 0;
}

/* a result with a non-finite coordinate (a mesh spanning 1e300 and 1: the way back from the
 * unit frame overflows) is never returned: the input is, unchanged */
int ut_finite_or_restore(mesh *m, const double *keep) {
  size_t nx = (size_t)m->nvert * m->dim;
  for (size_t i = 0; i < nx; i++)
    if (!isfinite(m->x[i])) {
      memcpy(m->x, keep, sizeof(double) * nx);
      return 0;
    }
  return 1;
}

/* the smallest relative validity of the cells around v (vc: vertex -> cells) */
static double star_min(const mesh *m, const int *vc_off, const int *vc, int v) {
  double q = INFINITY;
  for (int p = vc_off[v]; p < vc_off[v + 1]; p++) q = fmin(q, mesh_cell_relative_validity(m, vc[p]));
  return q;
}

/* Sliding boundary vertices back: a boundary vertex the stages moved returns to its input
 * place when the cells around it are at least as valid there (their smallest relative
 * validity), sweeps until none returns. The stages slide a boundary vertex where it helps
 * a neighbour at the time; once the interior is repaired the input boundary is often as
 * good, and the user's. (A Tutte-started quadrilateral spiral kept a boundary vertex slid
 * next to the strip's end, its corner cell at a corner condition of 0.008 against 0.20 with
 * the input boundary, which no smoother then raised.) Returns how many returned. */
static int restore_boundary(mesh *m, const double *keep) {
  int d = m->dim, nvc = m->nvc, total = 0;
  char err[MESH_ERRLEN];
  unsigned char *bnd = calloc((size_t)m->nvert + 1, 1);
  int *vc_off = calloc((size_t)m->nvert + 2, sizeof(int)), *vc = malloc(sizeof(int) * ((size_t)m->ncell * nvc + 1));
  if (!bnd || !vc_off || !vc || mesh_boundary_vertices(m, bnd, err)) { free(bnd); free(vc_off); free(vc); return 0; }
  for (size_t i = 0; i < (size_t)m->ncell * nvc; i++) vc_off[m->cells[i] + 2]++;
  for (int v = 0; v < m->nvert; v++) vc_off[v + 2] += vc_off[v + 1];
  for (int c = 0; c < m->ncell; c++)
    for (int i = 0; i < nvc; i++) vc[vc_off[m->cells[(size_t)c * nvc + i] + 1]++] = c;
  for (int sweep = 0; sweep < 10; sweep++) {
    int n = 0;
    for (int v = 0; v < m->nvert; v++) {
      double *x = m->x + (size_t)v * d, now[3];
      const double *x0 = keep + (size_t)v * d;
      int moved = 0;
      for (int j = 0; j < d; j++) moved |= x[j] != x0[j];
      if (!bnd[v] || !moved) continue;
      double before = star_min(m, vc_off, vc, v);
      if (!(before > 1e-13)) continue; /* an invalid star stays the stages' (the counts hold) */
      memcpy(now, x, sizeof(double) * (size_t)d);
      memcpy(x, x0, sizeof(double) * (size_t)d);
      double after = star_min(m, vc_off, vc, v);
      if (after > 1e-13 && after >= before) n++;
      else memcpy(x, now, sizeof(double) * (size_t)d);
    }
    total += n;
    if (!n) break;
  }
  free(bnd); free(vc_off); free(vc);
  return total;
}

/* a run whose global stage aims at the cells' shapes in the mesh's Tutte embedding on a
 * circle (tutte_reference) instead of regular ones, from where the runs stopped, kept if it
 * leaves fewer invalid cells: 2D disks with invalid cells left, not with reference shapes of
 * the user's own or without the global stage. Tutte-started strips whose cells are 20:1 to
 * 60:1 can stall with regular shapes, whose energy has no valid minimizer near that start (3
 * of 24 such spirals since the global energy takes Newton steps in 2D, 19 with L-BFGS,
 * bench/RESULTS.md); the disk's shapes carry the strip's anisotropy, and all of them
 * untangle. 0, or 1 with err (out of memory is not an error: the run is skipped) */
static int tutte_run(mesh *m, const untangle_opts *oo, untangle_report *r, char *err) {
  int rc = 0;
  size_t nx = (size_t)m->nvert * m->dim;
  if (!(r->invalid_after > 0 && m->dim == 2 && !oo->xref && !oo->no_global)) return 0;
  double *tref = tutte_reference(m), *before = tref ? malloc(sizeof(double) * (nx + 1)) : NULL;
  if (before) {
    memcpy(before, m->x, sizeof(double) * nx);
    if (oo->verbose)
      printf("untangle: %d invalid left; a run aiming at the cells' shapes in the mesh's Tutte embedding on a circle "
             "follows\n", r->invalid_after);
    untangle_opts to = *oo;
    to.xref = tref;
    to.reference_escape = 1;
    untangle_report r2;
    rc = untangle_run(m, &to, &r2, err);
    if (!rc) {
      r->seconds += r2.seconds;
      r->tutte_tried = 1;
      if (r2.invalid_after < r->invalid_after) {
        r->invalid_after = r2.invalid_after;
        r->passes++;
        r->tutte_kept = 1;
      } else memcpy(m->x, before, sizeof(double) * nx);
    }
  }
  free(before);
  free(tref);
  return rc;
}

int mesh_untangle(mesh *m, const untangle_opts *o, untangle_report *r, char *err) {
  memset(r, 0, sizeof *r);
  if (check_opts(o, err) || ut_check_finite(m, "untangling", err)) return 1;
  size_t nx = (size_t)m->nvert * m->dim;
  double *keep = malloc(sizeof(double) * (nx + 1));
  if (!keep) { snprintf(err, MESH_ERRLEN, "out of memory"); return 1; }
  memcpy(keep, m->x, sizeof(double) * nx);
  unit_frame f;
  if (ut_frame_enter(m, &f, 0, err)) { free(keep); return 1; }
  untangle_opts oo = *o;
  if (f.orig && oo.beta > 0) oo.beta = ldexp(oo.beta, -m->dim * f.e); /* beta is a length^d */
  int rc = untangle_run(m, &oo, r, err);
  r->passes = 1;
  /* a pass that left a few invalid cells (a quadrilateral spiral's corner cell, whose
   * boundary vertex slid where the interior alone cannot follow) is followed by another
   * from its result, while passes help (4 at most) and the last one kept a state past its
   * stage 1. A pass that kept its input or its stage 1's result (stages 2 and 3 only made
   * things worse) hands the next one a state that stage 1 has already finished with: the
   * next pass would repeat it to the bit (the anisotropic Tutte spiral 160x500, which no
   * pass repairs: its third pass was the second's copy, 12 of its 53 s) */
  int kept = r->kept_stage;
  /* more than 5% of the cells still invalid after the first pass in a 2D disk: its global
   * energy failed (the anisotropic Tutte-started strips, 20% and more; the other hard cases
   * leave none or a few), and the passes after it and the other placement restart that
   * energy from where it stopped and leave as many (80x250 strip: 8323 invalid after each,
   * 6 of its 13 s). The Tutte-disk run goes first; the other placement follows only if it
   * leaves invalid cells. Not for a few cells (under 50: the other placement's local moves
   * may do, where the Tutte run moves every vertex) nor with a motion weight (the smallest
   * motion asked for) */
  if (!rc && r->invalid_after > m->ncell / 20 && r->invalid_after >= 50 && !(oo.motion_weight > 0)) {
    rc = tutte_run(m, &oo, r, err);
    if (r->tutte_tried) kept = 0; /* no more passes */
  }
  for (int prev = r->invalid_before; !rc && r->passes < 4 && r->invalid_after > 0 && r->invalid_after < prev && kept >= 2;) {
    untangle_report r2;
    prev = r->invalid_after;
    rc = untangle_run(m, &oo, &r2, err);
    if (rc) break;
    r->invalid_after = r2.invalid_after;
    r->seconds += r2.seconds;
    r->passes++;
    kept = r2.kept_stage;
  }
  /* the passes stalled with invalid cells left: the other placement (the paper's LP corners
   * after the Chebyshev centre, or the reverse) from where they ended, with its own passes
   * while they help; kept only when it leaves fewer invalid cells (a tangle of the LIM
   * armadillo kept one inverted tetrahedron with the Chebyshev centre, none with corners) */
  r->fallback_placement = -1;
  if (!rc && r->invalid_after > 0) {
    double *before = malloc(sizeof(double) * (nx + 1));
    if (!before) { snprintf(err, MESH_ERRLEN, "out of memory"); rc = 1; }
    else {
      memcpy(before, m->x, sizeof(double) * nx);
      untangle_opts alt = oo;
      alt.placement = 1 - oo.placement;
      untangle_report r2;
      int left = r->invalid_after, npass = 0, alt_kept = 3; /* as if a pass had kept its stage 3 */
      double secs = 0;
      if (oo.verbose)
        printf("untangle: %d invalid left after %d pass%s; runs with the %s placement follow\n", left, r->passes,
               r->passes > 1 ? "es" : "", alt.placement ? "corners" : "chebyshev");
      for (int prev = left + 1; !rc && npass < 4 && left > 0 && left < prev && alt_kept >= 2; npass++) {
        prev = left;
        rc = untangle_run(m, &alt, &r2, err);
        if (!rc) { left = r2.invalid_after; secs += r2.seconds; alt_kept = r2.kept_stage; }
      }
      r->seconds += secs;
      if (!rc && left < r->invalid_after) {
        r->invalid_after = left;
        r->passes += npass;
        r->fallback_placement = alt.placement;
      } else if (!rc) memcpy(m->x, before, sizeof(double) * nx);
      if (!rc) r->fallback_tried = 1;
      free(before);
    }
  }
  /* still invalid cells in a 2D disk: the Tutte-disk run (tutte_run), unless it ran first */
  if (!rc && !r->tutte_tried) rc = tutte_run(m, &oo, r, err);
  if (f.orig) {
    r->beta = ldexp(r->beta, m->dim * f.e);
    r->mean_displacement = ldexp(r->mean_displacement, f.e);
    r->max_displacement = ldexp(r->max_displacement, f.e);
  }
  ut_frame_leave(m, &f);
  int back = 0;
  if (!rc && oo.slide) back = restore_boundary(m, keep);
  if (!rc && (r->passes > 1 || back > 0 || r->fallback_tried || r->tutte_tried)) {
    displacement(m, keep, r); /* the motion of all passes together, from the input */
  }
  if (!rc && !ut_finite_or_restore(m, keep)) {
    r->invalid_after = r->invalid_before;
    r->moved = 0;
    r->mean_displacement = r->max_displacement = 0;
    r->kept_stage = 0;
  }
  free(keep);
  return rc;
}

int mesh_move(mesh *m, const double *disp, const unsigned char *fixed, move_report *r, char *err) {
  memset(r, 0, sizeof *r);
  if (ut_check_finite(m, "mesh motion", err)) return 1;
  for (int v = 0; v < m->nvert; v++)
    for (int j = 0; fixed[v] && j < m->dim; j++)
      if (!isfinite(disp[(size_t)v * m->dim + j])) {
        snprintf(err, MESH_ERRLEN, "the displacement of vertex %d is not finite (%c = %g)", v + 1, "xyz"[j],
                 disp[(size_t)v * m->dim + j]);
        return 1;
      }
  double dmax = 0;
  for (int v = 0; v < m->nvert; v++)
    for (int j = 0; fixed[v] && j < m->dim; j++) dmax = fmax(dmax, fabs(disp[(size_t)v * m->dim + j]));
  size_t nx = (size_t)m->nvert * m->dim;
  double *keep = malloc(sizeof(double) * (nx + 1)); /* the true coordinates, to restore on failure */
  if (!keep) { snprintf(err, MESH_ERRLEN, "out of memory"); return 1; }
  memcpy(keep, m->x, sizeof(double) * nx);
  unit_frame f;
  if (ut_frame_enter(m, &f, dmax, err)) { free(keep); return 1; }
  double *ds = NULL;
  if (f.orig) {
    ds = malloc(sizeof(double) * (nx + 1));
    if (!ds) { ut_frame_leave(m, &f); free(keep); snprintf(err, MESH_ERRLEN, "out of memory"); return 1; }
    for (size_t i = 0; i < nx; i++) ds[i] = ldexp(disp[i], -f.e);
  }
  int rc = move_run(m, ds ? ds : disp, fixed, r, err);
  free(ds);
  ut_frame_leave(m, &f);
  for (size_t i = 0; !rc && i < nx; i++)
    if (!isfinite(m->x[i])) {
      snprintf(err, MESH_ERRLEN, "the motion makes vertex %zu's coordinates non-finite (the displacement is too large for "
                                 "floating point); the mesh is unchanged", i / m->dim + 1);
      rc = 1;
    }
  if (rc) memcpy(m->x, keep, sizeof(double) * nx);
  free(keep);
  if (!rc) {
    /* what the motion left, counted on the true coordinates */
    int n;
    mesh_count_invalid(m, 0, NULL, &n);
    if (n > r->invalid_after) r->invalid_after = n;
  }
  return rc;
}

