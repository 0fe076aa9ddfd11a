/* untangle_place.c — stages 1 and 3 of the untangler (seed, untangling paper, sections 2–3):
 * each violated vertex moved into the feasible set of its corners' linearized Jacobian
 * constraints {δ : J_k + g_k·δ >= target}, at the set's Chebyshev centre or the mean of
 * its extreme points along the axes, found by small dense linear programs. */
#include "untangle_int.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

/* ---------------------------------------------------------------- small linear programs */

/* maximize c·z subject to A z <= b, z >= 0, where b >= 0 so that the slack basis is
 * feasible; Bland's rule (no cycling). m rows, n columns. Returns 0 with the optimum in z, 1
 * when unbounded or out of iterations. A condensed (Tucker) tableau: one column per nonbasic
 * variable, a pivot exchanges the labels of a row and a column, (m + 1)(n + 1) entries where
 * the full tableau's slack columns made it (m + 1)(n + m + 1). The pivots and the arithmetic on
 * the entries kept are the full tableau's, so the results are the same to the bit; a vertex's
 * Chebyshev centre (some 30 rows, 7 columns) took a quarter of the million-tetrahedron bar's
 * untangling in the full tableau's row updates. */
static int lp_max(int m, int n, const double *A, const double *b, const double *c, double *z) {
  int W = n + 1;
  double tbuf[65 * 8], *T = (size_t)(m + 1) * W <= sizeof tbuf / sizeof tbuf[0] ? tbuf : malloc(sizeof(double) * (size_t)(m + 1) * W);
  int lbuf[72], *label = m + n <= 72 ? lbuf : malloc(sizeof(int) * (size_t)(m + n)); /* rows' basic, then columns' nonbasic */
  if (!T || !label) {
    if (T != tbuf) free(T);
    if (label != lbuf) free(label);
    return 1;
  }
  int *basis = label, *nonbasic = label + m;
  for (int i = 0; i < m; i++) {
    for (int j = 0; j < n; j++) T[i * W + j] = A[i * n + j];
    T[i * W + n] = b[i];
    basis[i] = n + i;
  }
  for (int j = 0; j < n; j++) {
    T[m * W + j] = -c[j];
    nonbasic[j] = j;
  }
  T[m * W + n] = 0;
  int status = 1;
  for (int it = 0; it < 50 * (m + n); it++) {
    int e = -1; /* the entering variable: the lowest label with a negative reduced cost */
    for (int j = 0; j < n; j++)
      if (T[m * W + j] < -1e-12 && (e < 0 || nonbasic[j] < nonbasic[e])) e = j;
    if (e < 0) { status = 0; break; }
    int r = -1;
    double best = INFINITY;
    for (int i = 0; i < m; i++) {
      double a = T[i * W + e];
      if (a <= 1e-12) continue;
      double q = T[i * W + n] / a;
      if (q < best || (q == best && basis[i] < basis[r])) { best = q; r = i; }
    }
    if (r < 0) break; /* unbounded */
    /* the exchange: column e becomes the leaving variable's, whose full-tableau column was
     * the unit vector of row r */
    double pv = T[r * W + e];
    T[r * W + e] = 1;
    for (int j = 0; j < W; j++) T[r * W + j] /= pv;
    for (int i = 0; i <= m; i++) {
      if (i == r) continue;
      double f = T[i * W + e];
      if (f == 0) continue;
      T[i * W + e] = 0;
      for (int j = 0; j < W; j++) T[i * W + j] -= f * T[r * W + j];
    }
    int t = basis[r];
    basis[r] = nonbasic[e];
    nonbasic[e] = t;
  }
  if (!status) {
    for (int j = 0; j < n; j++) z[j] = 0;
    for (int i = 0; i < m; i++)
      if (basis[i] < n) z[basis[i]] = T[i * W + n];
  }
  if (T != tbuf) free(T);
  if (label != lbuf) free(label);
  return status;
}

/* the constraints of vertex v: every corner of every cell around v that v takes part in,
 * J_k + g_k·δ >= target (at most MAXCON); without grad the Jacobians J_k alone (a scan for
 * violated corners needs no gradients) */
#define MAXCON 512
typedef struct {
  int n;
  double g[MAXCON][3], J[MAXCON];
} constraints;

static void vertex_constraints(const ctx *C, const double *x, int v, int grad, constraints *K) {
  K->n = 0;
  for (int p = C->vc_off[v]; p < C->vc_off[v + 1]; p++) {
    const int *cell = cell_of(C, C->vc[p]);
    for (int k = 0; k < C->ncorner; k++) {
      int who = -1;
      for (int i = 0; i <= C->d; i++)
        if (cell[C->ct[k][i]] == v) who = i;
      if (who < 0 || K->n >= MAXCON) continue;
      double g[4][3];
      K->J[K->n] = ut_corner_jac(C, x, cell, k, grad ? g : NULL);
      for (int j = 0; grad && j < C->d; j++) K->g[K->n][j] = g[who][j];
      K->n++;
    }
  }
}

/* the violated corners of v: J <= jtol, or J < target in stage 3 */
static int vertex_violations(const ctx *C, const double *x, int v, double target, int stage3) {
  constraints K;
  vertex_constraints(C, x, v, 0, &K);
  int bad = 0;
  for (int k = 0; k < K.n; k++) bad += stage3 ? K.J[k] < target : !(K.J[k] > C->jtol);
  return bad;
}

/* a new position for v inside {δ : J_k + g_k·δ >= target for all k}, or 0 when that set has
 * no interior. placement 0: the Chebyshev centre (the point farthest from the nearest
 * constraint, within a box of half-width R); 1: the mean of 2d−1 corners found by linear
 * objectives (x, −x, y[, −y, z]), as in section 2 of the paper. */
static int feasible_position(const ctx *C, const double *x, int v, double target, int placement, double *out) {
  constraints K;
  vertex_constraints(C, x, v, 1, &K);
  int d = C->d;
  const double *p = x + (size_t)d * v;
  double R = 0;
  for (int q = C->vc_off[v]; q < C->vc_off[v + 1]; q++) {
    const int *cell = cell_of(C, C->vc[q]);
    for (int i = 0; i < C->nvc; i++) {
      double s = 0;
      for (int j = 0; j < d; j++) s += (x[(size_t)d * cell[i] + j] - p[j]) * (x[(size_t)d * cell[i] + j] - p[j]);
      R = fmax(R, sqrt(s));
    }
  }
  R *= 2;
  if (!(R > 0) || K.n == 0) return 0;
  int m = K.n + 2 * d + 1, n = 2 * d + 1;
  double *A = calloc((size_t)m * n, sizeof(double)), *b = malloc(sizeof(double) * m), c[7] = {0}, z[7];
  if (!A || !b) { free(A); free(b); return 0; }
  double T0 = 0, ng[MAXCON];
  for (int k = 0; k < K.n; k++) {
    double s = 0;
    for (int j = 0; j < d; j++) s += K.g[k][j] * K.g[k][j];
    ng[k] = sqrt(s);
    if (ng[k] == 0) { /* a corner v cannot change: it decides alone */
      if (!(K.J[k] > target)) { free(A); free(b); return 0; }
      continue;
    }
    T0 = fmax(T0, (target - K.J[k]) / ng[k]);
  }
  /* variables δ⁺ (d), δ⁻ (d), s with t = s − T0; rows: −a·δ⁺ + a·δ⁻ + s <= (J − target)/|g| + T0 */
  for (int k = 0; k < K.n; k++) {
    if (ng[k] == 0) { b[k] = 1; continue; }
    for (int j = 0; j < d; j++) {
      A[k * n + j] = -K.g[k][j] / ng[k];
      A[k * n + d + j] = K.g[k][j] / ng[k];
    }
    A[k * n + 2 * d] = 1;
    b[k] = fmax(0, (K.J[k] - target) / ng[k] + T0);
  }
  for (int j = 0; j < 2 * d; j++) {
    A[(K.n + j) * n + j] = 1;
    b[K.n + j] = R;
  }
  A[(K.n + 2 * d) * n + 2 * d] = 1;
  b[K.n + 2 * d] = T0 + R;
  c[2 * d] = 1;
  int ok = 0;
  if (!lp_max(m, n, A, b, c, z)) {
    double t = z[2 * d] - T0;
    if (t > 1e-10 * R) {
      double delta[3];
      for (int j = 0; j < d; j++) delta[j] = z[j] - z[d + j];
      ok = 1;
      if (placement == 1) {
        /* corners of the feasible set, from the interior point δ: rows −g·δ⁺ + g·δ⁻ <= J + g·δ − target */
        double mean[3] = {0, 0, 0};
        int ncorner = 0;
        for (int o = 0; o < 2 * d - 1; o++) {
          double *A2 = calloc((size_t)(K.n + 2 * d) * 2 * d, sizeof(double)), *b2 = malloc(sizeof(double) * (K.n + 2 * d));
          double c2[6] = {0}, z2[6];
          if (!A2 || !b2) { free(A2); free(b2); break; }
          for (int k = 0; k < K.n; k++) {
            double s = K.J[k] - target;
            for (int j = 0; j < d; j++) {
              s += K.g[k][j] * delta[j];
              A2[k * 2 * d + j] = -K.g[k][j];
              A2[k * 2 * d + d + j] = K.g[k][j];
            }
            b2[k] = fmax(0, s);
          }
          for (int j = 0; j < 2 * d; j++) {
            A2[(K.n + j) * 2 * d + j] = 1;
            b2[K.n + j] = R;
          }
          int axis = (o + 1) / 2, sign = o == 0 ? 1 : (o % 2 ? -1 : 1);
          /* minimize sign·δ_axis: maximize −sign·(δ⁺ − δ⁻) */
          c2[axis] = -sign;
          c2[d + axis] = sign;
          if (!lp_max(K.n + 2 * d, 2 * d, A2, b2, c2, z2)) {
            for (int j = 0; j < d; j++) mean[j] += delta[j] + z2[j] - z2[d + j];
            ncorner++;
          }
          free(A2);
          free(b2);
        }
        if (ncorner == 2 * d - 1) {
          /* keep the mean only when it is strictly inside (corners may coincide) */
          int inside = 1;
          for (int j = 0; j < d; j++) mean[j] /= ncorner;
          for (int k = 0; k < K.n && inside; k++) {
            double s = K.J[k] - target;
            for (int j = 0; j < d; j++) s += K.g[k][j] * mean[j];
            inside = s > 1e-10 * R * ng[k];
          }
          if (inside)
            for (int j = 0; j < d; j++) delta[j] = mean[j];
        }
      }
      for (int j = 0; j < d; j++) out[j] = p[j] + delta[j];
    }
  }
  free(A);
  free(b);
  return ok;
}

/* stages 1 and 3: repeated passes over the free vertices of `active` cells whose constraints
 * are violated (J <= jtol in stage 1, J < β in stage 3); a pass that moves nothing ends them,
 * and so do PASS_PATIENCE passes without fewer violated corners than the best pass before
 * (moves that trade one violation for another: a twisted bar of 1 152 tetrahedra spent 100
 * passes, 32 ms, going from 212 inverted cells to 193, which stage 2 then repaired in 2 ms) */
#define PASS_PATIENCE 5
typedef struct {
  int v, bad;
} cand;
static int cand_cmp(const void *a, const void *b) {
  const cand *x = a, *y = b;
  return x->bad != y->bad ? y->bad - x->bad : x->v - y->v;
}

/* a vertex of v's star (the vertices of its cells) moved in this pass (stamp == mark) */
static int star_moved(const ctx *C, int v, const int *stamp, int mark) {
  for (int p = C->vc_off[v]; p < C->vc_off[v + 1]; p++) {
    const int *cell = cell_of(C, C->vc[p]);
    for (int i = 0; i < C->nvc; i++)
      if (stamp[cell[i]] == mark) return 1;
  }
  return 0;
}

/* above this many candidates a pass computes their feasible positions on threads first */
#define PASS_PAR_CANDIDATES 256

int ut_feasible_passes(ctx *C, double *x, double target, int stage3, const unsigned char *region, int placement,
                           int maxpass, unsigned char *moved, int *npass) {
  int d = C->d, total = 0, pass;
  mesh *m = C->m;
  cand *list = malloc(sizeof(cand) * ((size_t)m->nvert + 1));
  int *nbad = malloc(sizeof(int) * ((size_t)m->nvert + 1));
  /* the vertices a pass moved, then those whose stars they are in (their counts change) */
  int *mv = malloc(sizeof(int) * ((size_t)m->nvert + 1)), *dl = malloc(sizeof(int) * ((size_t)m->nvert + 1)), ndl = -1;
  unsigned char *dirty = calloc((size_t)m->nvert + 1, 1);
  if (!list || !nbad || !mv || !dl || !dirty) { free(list); free(nbad); free(mv); free(dl); free(dirty); return 0; }
  /* the threaded placement's buffers, per vertex: a position, whether it has one, whether
   * those are known (below), and the pass in which it moved */
  double *pos = NULL;
  unsigned char *has = NULL, *known = NULL; /* known: pos and has hold the vertex's answer */
  int *stamp = NULL;
  long best = -1;
  int since = 0, ran = 0; /* ran: the passes that tried moves */
  for (pass = 0; pass < maxpass; pass++) {
    /* the vertices with violated corners, the most violated first: a vertex pulled out of
     * its patch is put back before its neighbours react to it. The counts read the mesh
     * only: on OpenMP threads, the list then made in vertex order */
    int n = 0, nv = m->nvert;
#define PASS_COUNT(v) (C->fixed[v] || C->bnd[v] || (region && !region[v]) ? 0 : vertex_violations(C, x, v, target, stage3))
    if (ndl < 0) {
#ifdef _OPENMP
#pragma omp parallel for schedule(static) if (nv > 4096)
#endif
      for (int v = 0; v < nv; v++) nbad[v] = PASS_COUNT(v);
    } else { /* after the first pass only the stars the last pass changed: the stage 3 of the
              * million-triangle spiral's untangle recounted its 170 000 vertices 58 times to
              * move 22 (0.3 s) */
#ifdef _OPENMP
#pragma omp parallel for schedule(static) if (ndl > 4096)
#endif
      for (int i = 0; i < ndl; i++) nbad[dl[i]] = PASS_COUNT(dl[i]);
      for (int i = 0; i < ndl; i++) dirty[dl[i]] = 0;
    }
#undef PASS_COUNT
    long violated = 0;
    for (int v = 0; v < nv; v++)
      if (nbad[v]) list[n++] = (cand){v, nbad[v]}, violated += nbad[v];
    if (best < 0 || violated < best) { best = violated; since = 0; }
    else if (++since >= PASS_PATIENCE) break;
    ran++;
    qsort(list, (size_t)n, sizeof(cand), cand_cmp);
    /* Many candidates: each one's feasible position from the mesh as the pass found it, on
     * threads (each an LP over its own star: a million-cell twisted bar's stage 2 spent most
     * of its time in these LPs, on one thread). Then the moves in the list's order as
     * before: a vertex none of whose star has moved yet in this pass sees the mesh the pass
     * started from, so its precomputed answer is the one the loop would compute; the others
     * compute theirs at their turn. Same moves, same bits, for any thread count.
     * An answer depends on the vertex's star alone: it stays known until a move changes
     * that star (the vertices that stay violated without a feasible position were solved
     * again every pass: the million-triangle spiral's stage 3, 58 passes over 40 000
     * candidates to move 22 vertices) */
    int par = n > PASS_PAR_CANDIDATES;
    if (par && !pos) {
      pos = malloc(sizeof(double) * ((size_t)m->nvert * d + 1));
      has = malloc((size_t)m->nvert + 1);
      known = calloc((size_t)m->nvert + 1, 1);
      stamp = malloc(sizeof(int) * ((size_t)m->nvert + 1));
      if (stamp)
        for (int v = 0; v < nv; v++) stamp[v] = -1;
    }
    if (par && (!pos || !has || !known || !stamp)) par = 0;
    if (par) {
#ifdef _OPENMP
#pragma omp parallel for schedule(dynamic, 64)
#endif
      for (int i = 0; i < n; i++) {
        int v = list[i].v;
        if (!known[v]) has[v] = (unsigned char)feasible_position(C, x, v, stage3 ? target : 0, placement, pos + (size_t)v * d);
        known[v] = 1;
      }
    }
    int changed = 0;
    for (int i = 0; i < n; i++) {
      int v = list[i].v;
      double np[3];
      if (par && !star_moved(C, v, stamp, pass)) { /* its star as at the pass's start: violated (nbad) */
        if (!has[v]) continue;
        memcpy(np, pos + (size_t)v * d, sizeof(double) * (size_t)d);
      } else {
        if (!vertex_violations(C, x, v, target, stage3)) continue; /* fixed by an earlier move in this pass */
        if (!feasible_position(C, x, v, stage3 ? target : 0, placement, np)) continue;
      }
      for (int j = 0; j < d; j++) x[(size_t)d * v + j] = np[j];
      if (stamp) stamp[v] = pass;
      if (!moved[v]) total++;
      moved[v] = 1;
      mv[changed++] = v;
    }
    if (!changed) break;
    ndl = 0;
    for (int i = 0; i < changed; i++)
      for (int p = C->vc_off[mv[i]]; p < C->vc_off[mv[i] + 1]; p++) {
        const int *cell = cell_of(C, C->vc[p]);
        for (int k = 0; k < C->nvc; k++)
          if (!dirty[cell[k]]) {
            dirty[cell[k]] = 1;
            dl[ndl++] = cell[k];
            if (known) known[cell[k]] = 0;
          }
      }
  }
  free(list);
  free(nbad);
  free(mv);
  free(dl);
  free(dirty);
  free(pos);
  free(has);
  free(known);
  free(stamp);
  *npass = ran;
  return total;
}
