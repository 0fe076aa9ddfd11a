/* smooth.c — quality-guarded smoothing (seed, simplex and quadrilateral shape measures):
 * local, a vertex at a time, never lowering the smallest quality of its star, or global,
 * L-BFGS on the sum of 1/q with a floor, or the energy method: the same sum as a barrier
 * alone, by projected Newton (untangle_newton.c, 2D) or L-BFGS (3D). The corner context
 * and L-BFGS are untangle.c's (untangle_int.h). See untangle.h. */
#include "untangle_int.h"

#include "../quality/quality.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---------------------------------------------------------------- smoothing */

/* Σ 1/q over the cells of v, +∞ when one is invalid; the smallest q in *qmin */
double ut_star_objective(const ctx *C, int v, int q, double *qmin) {
  double s = 0, mn = INFINITY;
  for (int p = C->vc_off[v]; p < C->vc_off[v + 1]; p++) {
    int c = C->vc[p];
    if (!(ut_cell_min_jac(C, C->m->x, c) > C->jtol)) { *qmin = -INFINITY; return INFINITY; }
    double val = mesh_cell_quality(C->m, c, q);
    if (!(val > 0)) { *qmin = -INFINITY; return INFINITY; }
    s += 1 / val;
    mn = fmin(mn, val);
  }
  *qmin = mn;
  return s;
}


/* one local step at v (interior: along minus the central-difference gradient of Σ 1/q over
 * its star; 2D sliding boundary vertex: along the better boundary edge); 1 if v moved */
typedef struct {
  int measure;
  double qmin0;
  const objective *ob; /* the energy whose gradient is d Σ 1/q (tetrahedra, the mean ratio), or NULL */
} smooth_arg;
static double smooth_penalty(const ctx *C, int v, const void *arg, int probe) {
  const smooth_arg *a = arg;
  double qmin, f = ut_star_objective(C, v, a->measure, &qmin);
  return probe || qmin >= a->qmin0 ? f : INFINITY;
}

/* the analytic gradient of the energy, a multiple of Σ 1/q's: one evaluation of the star
 * instead of four (the central differences), which were most of a sliding 3D round's slides */
static int smooth_gradient(const ctx *C, int v, const void *arg, double *g) {
  const smooth_arg *a = arg;
  return !isfinite(ut_energy_vertex(a->ob, C->m->x, v, g));
}

static int smooth_vertex_step(ctx *C, int v, int measure, const objective *ob) {
  mesh *m = C->m;
  int d = m->dim;
  if (C->fixed[v]) return 0;
  double *p = m->x + (size_t)v * d, p0[3], qmin0, f0 = ut_star_objective(C, v, measure, &qmin0);
  if (C->bnd[v] && d == 3) { /* along the flat face or straight edge, never lowering the star's minimum */
    smooth_arg a = {measure, qmin0, ob};
    return ut_slide_3d(C, m->x, v, smooth_penalty, ob ? smooth_gradient : NULL, &a);
  }
  for (int j = 0; j < d; j++) p0[j] = p[j];
  double h = ut_star_h(C, v), dir[3] = {0, 0, 0};
  if (C->bnd[v]) { /* 2D sliding: the better of the two boundary edges, by a probe */
    double best = f0, bq;
    for (int side = 0; side < 2; side++) {
      const double *a = m->x + 2 * C->bnb[2 * v + side];
      for (int j = 0; j < 2; j++) p[j] = p0[j] + 1e-3 * (a[j] - p0[j]);
      double f = ut_star_objective(C, v, measure, &bq);
      if (f < best) { best = f; for (int j = 0; j < 2; j++) dir[j] = a[j] - p0[j]; }
    }
    for (int j = 0; j < 2; j++) p[j] = p0[j];
    if (best == f0) return 0;
  } else { /* interior: minus the central-difference gradient, scaled to the star's size */
    double e = 1e-6 * h, gn = 0, qq;
    for (int j = 0; j < d; j++) {
      p[j] = p0[j] + e;
      double fp = ut_star_objective(C, v, measure, &qq);
      p[j] = p0[j] - e;
      double fm = ut_star_objective(C, v, measure, &qq);
      p[j] = p0[j];
      dir[j] = isfinite(fp) && isfinite(fm) ? -(fp - fm) / (2 * e) : 0;
      gn += dir[j] * dir[j];
    }
    gn = sqrt(gn);
    if (!(gn > 0)) return 0;
    for (int j = 0; j < d; j++) dir[j] *= 0.5 * h / gn;
  }
  /* backtracking: accept only a step that keeps every cell valid, lowers Σ 1/q and does
   * not lower the smallest q around v — so the mesh minimum never decreases */
  for (double t = C->bnd[v] ? 0.5 : 1; t > 1e-4; t *= 0.5) {
    for (int j = 0; j < d; j++) p[j] = p0[j] + t * dir[j];
    double qmin, f = ut_star_objective(C, v, measure, &qmin);
    if (f < f0 && qmin >= qmin0) return 1;
  }
  for (int j = 0; j < d; j++) p[j] = p0[j];
  return 0;
}

/* the step, and what it gained: f0 − f of the star is the change of Σ 1/q over the mesh */
static int smooth_vertex(ctx *C, int v, int measure, const objective *ob, double *gain) {
  if (C->fixed[v]) return 0;
  double q0, q1, f0 = ut_star_objective(C, v, measure, &q0);
  if (!smooth_vertex_step(C, v, measure, ob)) return 0;
  *gain += f0 - ut_star_objective(C, v, measure, &q1);
  return 1;
}

int smooth_energy_measure(int cell_type) {
  return cell_type == CELL_TRIANGLE || cell_type == CELL_TETRAHEDRON ? QM_MEAN_RATIO : QM_CORNER_CONDITION;
}

int smooth_has_sliding_passes(const mesh *m, const smooth_opts *o) {
  return o->energy && o->slide && !o->xref && o->measure == smooth_energy_measure(m->type);
}

/* 3D energy smoothing by L-BFGS on this many cells or more may hand over to Newton (smooth_pass) */
#define HANDOVER_CELLS 500000

/* global smoothing: L-BFGS on Σ 1/q over all interior vertices together (Mesquite's
 * inverse-mean-ratio objective when q is the mean ratio), rounds of up to 20 iterations;
 * a step is taken only when every cell stays valid and no q falls below the mesh's
 * smallest q before smoothing (a floor that rises with every round blocks the steps
 * once many cells share the minimum). 2D sliding boundary vertices take one local step
 * each between rounds. Stops when a round lowers Σ 1/q by less than 1e-4 (relative; the energy method 1e-3). */
/* one pass of up to `rounds` rounds; slide: the boundary stays (SMOOTH_SLIDE_NONE), takes
 * local steps between rounds (SMOOTH_SLIDE_LOCAL), or slides inside the optimizer
 * (SMOOTH_SLIDE_INNER, the energy method with its own measure: the sliding boundary vertices
 * are free vertices that move along their line or plane, ob.slide) */
static int smooth_pass(ctx *C, const smooth_opts *o, const double *cwinv, int slide, int rounds, smooth_report *r,
                       char *err) {
  mesh *m = C->m;
  int nfree = 0, inner = slide == SMOOTH_SLIDE_INNER;
  int *freev = malloc(sizeof(int) * ((size_t)m->nvert + 1)), *fidx = malloc(sizeof(int) * ((size_t)m->nvert + 1)),
      *cells = malloc(sizeof(int) * ((size_t)m->ncell + 1));
  unsigned char *cmark = calloc((size_t)m->ncell + 1, 1);
  double *hv = malloc(sizeof(double) * ((size_t)m->nvert + 1));
  if (!freev || !fidx || !cells || !cmark || !hv) {
    free(freev); free(fidx); free(cells); free(cmark); free(hv);
    snprintf(err, MESH_ERRLEN, "out of memory");
    return 1;
  }
  int simplex = m->type == CELL_TRIANGLE || m->type == CELL_TETRAHEDRON;
  for (int v = 0; v < m->nvert; v++) {
    fidx[v] = -1;
    if (!C->bnd[v] || (inner && !C->fixed[v])) { fidx[v] = nfree; hv[nfree] = ut_star_h(C, v); freev[nfree++] = v; }
  }
  work W = {fidx, cmark, cells};
  int ncell = ut_cells_around(C, &W, freev, nfree), status = 0;
  objective ob = {.C = C, .S = C->jscale, .ncell = ncell, .cells = cells, .fidx = fidx, .smooth = 1, .measure = o->measure,
                  .freev = freev, .hv = hv, .cwinv = cwinv, .amg_used = &r->multigrid};
  ut_energy_buf eb = {0};
  double fprev = INFINITY;
  int handover = 0;
  ob.qfloor = INFINITY;
  if (o->energy) ob.qfloor = 0; /* the barrier alone: 1/q is infinite on degenerate cells */
  else
    for (int i = 0; i < ncell && !cwinv; i++) ob.qfloor = fmin(ob.qfloor, mesh_cell_quality(m, cells[i], o->measure));
  if (o->energy && (cwinv || o->measure == smooth_energy_measure(m->type))) {
    /* Σ 1/q of the mean ratio is (1/d) Σ |J|²/det(J)^(2/d), J relative to a regular simplex:
     * the untangling energy's shape term at ε = 0 (a strict barrier), with its analytic
     * gradient instead of 2d star evaluations per vertex. On quadrilaterals and hexahedra
     * the same term over the corners, J relative to a square's or cube's corner: each is the
     * inverse mean ratio of a corner's map, which the corner condition measures too */
    ob.smooth = 2;
    ob.slide = inner;
    /* the window that ends an L-BFGS round: 20 iterations; 5 when the boundary slides
     * between rounds. There a round's interior only has to follow the boundary's last
     * slides, which the next round moves again: the 3D rounds spent their second 20
     * iterations on a 0.01% gain (perturbed 24³ tetrahedral box: 712 L-BFGS iterations in
     * 18 rounds, 335 with the short window, the same rounds and minimum, bench/RESULTS.md) */
    ob.stall = slide == SMOOTH_SLIDE_LOCAL && !cwinv ? 5 : 20;
    ob.eb = &eb;
    ob.theta = 0;
    ob.eps = 0;
    /* the iterate kept by Newton when the optimum lowers the minimum: its corner quality is
     * the measure's (the mean ratio of simplices and reference maps, a quadrilateral's corner
     * condition 2 det/|J|²); a hexahedron's corner condition 3 det/(|J| |adj J|) is not the
     * corners' mean ratio, so there the final check alone keeps the minimum */
    ob.keepq = cwinv || simplex || m->dim == 2 ? r->min_before : 0;
    /* projected Newton where it is faster: in 2D, 2.5-10x on the hard tangles' smoothing
     * (a random star's 1 200 L-BFGS iterations become 11 Newton steps), 1.2-1.8x on
     * perturbed grids; in 3D L-BFGS converges in few iterations on the meshes measured and
     * a Newton step's corner Hessians (12×12 per tetrahedron corner) cost more than they
     * save (bench/RESULTS.md). The sliding pass on tetrahedra takes Newton: L-BFGS needed
     * 459 iterations on the perturbed 32³ box (11.8 s), Newton 49 steps (4.4 s) */
    r->optimizer = o->optimizer                                           ? o->optimizer
                   : m->dim == 2 || (inner && m->type == CELL_TETRAHEDRON) ? SMOOTH_NEWTON
                                                                            : SMOOTH_LBFGS;
    /* Newton ends at a 1e-5 gain: its last steps, at linear speed (the projected Hessian
     * is not the true one), changed the minimum by less than 1e-4 */
    if (r->optimizer == SMOOTH_NEWTON) ob.ftol = 1e-5;
    /* 3D on HANDOVER_CELLS cells or more, the optimizer not asked for: L-BFGS hands over to
     * Newton when its iterations 10–19 still descend steadily (ut_lbfgs). L-BFGS is the
     * faster on perturbed grids, whose error is local (a perturbed tetrahedral box of a
     * million cells: 3.1 s in 40 iterations against 10.9 s by Newton), Newton on the
     * untangled twisted bars, whose error spans the bar, from about half a million cells
     * (bar 32, 589 824 tetrahedra: 9.2 s against 6.7 s; bar 40, 1 152 000: 16.1 against 7.9 s;
     * bar 24, 248 832: 0.88 against 1.29 s), bench/RESULTS.md */
    if (o->optimizer == SMOOTH_AUTO && r->optimizer == SMOOTH_LBFGS && m->dim == 3 && ncell >= HANDOVER_CELLS)
      ob.handover = &handover;
    if (simplex) ut_regular_winv(m->dim, 1.0, ob.winv);
    else
      for (int i = 0; i < m->dim; i++) ob.winv[i * m->dim + i] = 1;
  } else if (o->energy) { /* another measure: Σ 1/q from central differences, by L-BFGS */
    if (o->optimizer == SMOOTH_NEWTON) {
      snprintf(err, MESH_ERRLEN, "the Newton optimizer needs the energy's measure: %s",
               simplex ? "mean_ratio on simplices" : "corner_condition on quadrilaterals and hexahedra");
      free(freev); free(fidx); free(cells); free(cmark); free(hv);
      return 1;
    }
    r->optimizer = SMOOTH_LBFGS;
  }
  /* the slides' gradient from the energy where it is d Σ 1/q: tetrahedra and the mean ratio
   * (a hexahedron's corner condition is not its corners' mean ratio; 2D slides probe the
   * two boundary edges) */
  const objective *slide_ob = ob.smooth == 2 && m->type == CELL_TETRAHEDRON && !cwinv ? &ob : NULL;
  for (int round = 0; round < rounds; round++) {
    double f0 = 0;
    if (ob.smooth == 2) f0 = ut_energy_eval(&ob, m->x, NULL, nfree);
    else
      for (int i = 0; i < ncell; i++) f0 += 1 / mesh_cell_quality(m, cells[i], o->measure);
    /* the last round (optimization and sliding together) gained less than 1e-4 (the energy
     * method by L-BFGS: 1e-3; by Newton: 1e-5, below) of Σ 1/q: done. The energy method's rounds past 1e-3 changed the minimum
     * by 0.1% and cost a fifth of the time (spiral 200x30 0.51 -> 0.28 s, star 40x200 2.39
     * -> 1.19 s); the floored global method still gained there (spiral 100x20 0.289 ->
     * 0.327), bench/RESULTS.md */
    /* Newton's rounds go on to a 1e-5 gain: after the first its rounds cost one to three
     * steps, and the boundary slides one step per round (spiral 200x30, sliding: 2 rounds
     * and a minimum of 0.395 at 1e-3, 22 rounds and 0.436 in twice the time at 1e-5; L-BFGS
     * 0.418) */
    double round_tol = r->optimizer == SMOOTH_NEWTON ? 1e-5 : ob.smooth == 2 ? 1e-3 : 1e-4;
    if (!(f0 < fprev * (1 - round_tol))) break;
    fprev = f0;
    double f = f0;
    /* rounds of 20 iterations; 100 with the analytic gradient of the energy method */
    int maxit = ob.smooth == 2 ? 100 : 20;
    /* the softened first steps (ut_newton) in the smoothing's first Newton run only: later
     * rounds and passes start near their optimum, where they spent steps for nothing (the
     * sliding rounds of the Tutte-started 30 x 10 spiral: 29 -> 52 Newton steps) */
    ob.soft_start = !r->iterations;
    int its = !nfree ? 0
              : r->optimizer == SMOOTH_NEWTON ? ut_newton(&ob, m->x, freev, nfree, maxit, &f)
                                              : ut_lbfgs(&ob, m->x, freev, nfree, maxit, &f),
        slid = 0;
    double gain = 0;
    if (its < 0) { snprintf(err, MESH_ERRLEN, "out of memory"); status = 1; break; }
    const char *used = r->optimizer == SMOOTH_NEWTON ? "Newton" : "L-BFGS";
    int handed = handover && r->optimizer == SMOOTH_LBFGS;
    if (handed) { /* Newton from the next round on */
      r->optimizer = SMOOTH_NEWTON;
      ob.ftol = 1e-5;
      ob.handover = NULL;
    }
    if (slide == SMOOTH_SLIDE_LOCAL)
      for (int v = 0; v < m->nvert; v++)
        if (C->bnd[v]) slid += smooth_vertex(C, v, o->measure, slide_ob, &gain);
    r->sweeps++;
    if (its > 0) r->iterations += its;
    if (o->verbose) printf("smooth: round %d, %d %s iterations, sum 1/q %.6g -> %.6g, %d boundary vertices slid\n",
                           round + 1, its, used, f0, f, slid);
    if (!its && !slid) break;
    /* the energy method's optimizer stopped by its own test and nothing slid since: a new
     * round would restart it where it converged (the twisted bars' second rounds: 20 more
     * L-BFGS iterations or one more Newton step, 15% of the million-cell bar's smoothing) */
    if (ob.smooth == 2 && !slid && its < maxit && !handed) break;
  }
  ut_energy_release(&eb);
  free(freev); free(fidx); free(cells); free(cmark); free(hv);
  return status;
}

/* global smoothing. The energy method with its own measure and a sliding boundary starts
 * with one round with the boundary fixed, then from there runs two passes and keeps the one
 * with the higher minimum (the higher mean when they are within 1e-4): the boundary sliding
 * inside the optimizer, and the guarded local slides between rounds (o->sliding: one of them
 * alone). Neither wins everywhere (bench/RESULTS.md, "Two sliding passes"): the first
 * reaches higher means and is 3-4x faster where the boundary
 * must slide far (perturbed grids: 256² triangles 0.785 -> 0.866, hexahedral boxes 0.98 -> 1),
 * but it trades the minimum for the sum where the boundary's cells cannot all be good (the
 * spiral strips' ends: 30x10 0.203 against 0.182; the tetrahedral boxes' edges, whose vertices
 * it grades: 32³ 0.667 against 0.581); the local slides never lower a star's minimum, one step
 * per round. Other methods and reference shapes: one pass (with reference shapes the boundary
 * stays) */
static int smooth_global(ctx *C, const smooth_opts *o, const double *cwinv, double *q, smooth_report *r, char *err) {
  mesh *m = C->m;
  int nslide = 0;
  for (int v = 0; v < m->nvert; v++) nslide += C->bnd[v] && !C->fixed[v];
  if (!(smooth_has_sliding_passes(m, o) && nslide))
    return smooth_pass(C, o, cwinv, o->slide && !cwinv ? SMOOTH_SLIDE_LOCAL : SMOOTH_SLIDE_NONE, o->iterations, r, err);
  /* the fixed round is the passes' common start. One round only: a round that ends at the
   * iteration cap leaves a cell the fixed boundary pins near degenerate (the Tutte-started
   * 40x16 quadrilateral spiral after a sliding untangle: corner condition 2e-6, then 20
   * rounds of 100 Newton steps, each gaining 0.3% of Σ 1/q, 2.7 s; sliding repairs it) */
  if (smooth_pass(C, o, cwinv, SMOOTH_SLIDE_NONE, 1, r, err)) return 1;
  r->sliding = o->sliding ? o->sliding : SMOOTH_SLIDE_INNER;
  if (o->sliding == SMOOTH_SLIDE_LOCAL) return smooth_pass(C, o, cwinv, SMOOTH_SLIDE_LOCAL, o->iterations, r, err);
  if (o->sliding == SMOOTH_SLIDE_INNER) return smooth_pass(C, o, cwinv, SMOOTH_SLIDE_INNER, o->iterations, r, err);
  size_t nx = (size_t)m->nvert * m->dim;
  double *x1 = malloc(sizeof(double) * (nx + 1)), *x2 = malloc(sizeof(double) * (nx + 1));
  quality_stats s2, s3;
  if (!x1 || !x2) { free(x1); free(x2); snprintf(err, MESH_ERRLEN, "out of memory"); return 1; }
  memcpy(x1, m->x, sizeof(double) * nx);
  /* the report's optimizer and preconditioner are the kept pass's (and the fixed round's) */
  int mg1 = r->multigrid;
  int rc = smooth_pass(C, o, cwinv, SMOOTH_SLIDE_INNER, o->iterations, r, err) || mesh_quality(m, o->measure, NULL, q, err);
  int opt2 = r->optimizer, mg2 = r->multigrid;
  if (!rc) quality_stats_compute(q, m->ncell, &s2);
  /* a minimum of 1 (to 1e-4) is every cell's best shape: the local pass cannot beat it
   * (the hexahedral boxes and the quadrilateral grid, whose local passes cost 1.5x more) */
  if (!rc && s2.min < 1 - 1e-4) {
    memcpy(x2, m->x, sizeof(double) * nx);
    memcpy(m->x, x1, sizeof(double) * nx);
    r->multigrid = mg1;
    rc = smooth_pass(C, o, cwinv, SMOOTH_SLIDE_LOCAL, o->iterations, r, err) || mesh_quality(m, o->measure, NULL, q, err);
    if (!rc) {
      quality_stats_compute(q, m->ncell, &s3);
      r->sliding = SMOOTH_SLIDE_LOCAL;
      /* minima within 1e-4 of each other tie (both passes reach the 256² grid's 0.866 to 1e-12) */
      int tie = fabs(s2.min - s3.min) <= 1e-4 * fmax(s2.min, s3.min);
      if (tie ? s2.mean > s3.mean : s2.min > s3.min) {
        memcpy(m->x, x2, sizeof(double) * nx);
        r->sliding = SMOOTH_SLIDE_INNER;
        r->optimizer = opt2;
        r->multigrid = mg2;
      }
    }
  }
  free(x1);
  free(x2);
  return rc;
}

static int smooth_run(mesh *m, const smooth_opts *o, smooth_report *r, char *err) {
  double t0 = ut_now();
  memset(r, 0, sizeof *r);
  r->measure = o->measure;
  if (o->measure < 0 || o->measure >= QM_COUNT || !quality_applies(o->measure, m->type) ||
      !quality_larger_is_better(o->measure) || quality_is_deformation(o->measure) || o->measure == QM_SIGNED_MEASURE ||
      o->measure == QM_MIN_CORNER_JACOBIAN || o->measure == QM_MIN_EDGE || o->measure == QM_MAX_EDGE ||
      o->measure == QM_MIN_ANGLE || (o->measure >= QM_V_AREA && o->measure != QM_V_SHAPE && o->measure != QM_V_SCALED_JACOBIAN)) {
    snprintf(err, MESH_ERRLEN, "smoothing needs a shape measure in (0, 1] that applies to %s (e.g. %s)",
             cell_plural(m->type), m->type == CELL_TRIANGLE || m->type == CELL_TETRAHEDRON ? "mean_ratio" : "corner_condition");
    return 1;
  }
  ctx C;
  if (ut_ctx_init(&C, m, o->slide, err)) { ut_ctx_free(&C); return 1; }
  ut_progress pg = {o->progress, "smooth", o->energy ? "energy" : o->global ? "global" : "local", t0, t0};
  C.progress = &pg;
  int ninv;
  ut_count_cells(&C, m->x, 0, &ninv, NULL);
  if (ninv) {
    snprintf(err, MESH_ERRLEN, "the mesh has %d invalid cell%s: untangle it first (mesh:untangle())", ninv,
             ninv == 1 ? "" : "s");
    ut_ctx_free(&C);
    return 1;
  }
  double *cwinv = NULL;
  if (o->xref) {
    if (!o->energy || m->type == CELL_INTERVAL || o->measure != smooth_energy_measure(m->type)) {
      snprintf(err, MESH_ERRLEN, "reference shapes need method \"energy\" and the mean ratio (triangles, tetrahedra) or "
                                 "the corner condition (quadrilaterals, hexahedra)");
      ut_ctx_free(&C);
      return 1;
    }
    if (!(cwinv = ut_reference_winv(&C, o->xref, err))) { ut_ctx_free(&C); return 1; }
  }
  double *q = mesh_big_alloc(sizeof(double) * ((size_t)m->ncell + 1));
  unsigned char *moved = calloc((size_t)m->nvert + 1, 1);
  if (!q || !moved) { mesh_big_free(q); free(moved); free(cwinv); ut_ctx_free(&C); snprintf(err, MESH_ERRLEN, "out of memory"); return 1; }
  quality_stats st;
#define QUALITY() (cwinv ? (ut_relative_mean_ratio(&C, cwinv, q), 0) : mesh_quality(m, o->measure, NULL, q, err))
  QUALITY();
  quality_stats_compute(q, m->ncell, &st);
  r->min_before = st.min;
  r->mean_before = st.mean;
  int d = m->dim;
  double *x0 = malloc(sizeof(double) * ((size_t)m->nvert * d + 1));
  if (!x0) { mesh_big_free(q); free(moved); ut_ctx_free(&C); snprintf(err, MESH_ERRLEN, "out of memory"); return 1; }
  memcpy(x0, m->x, sizeof(double) * (size_t)m->nvert * d);
  if (!o->global)
    for (int sweep = 0; sweep < o->iterations; sweep++) {
      int changed = 0;
      double total = 0, gain = 0;
      for (int c = 0; c < m->ncell; c++) total += 1 / mesh_cell_quality(m, c, o->measure);
      for (int v = 0; v < m->nvert; v++) changed += smooth_vertex(&C, v, o->measure, NULL, &gain);
      r->sweeps = sweep + 1;
      ut_progress_tick(&pg, "sweep", sweep + 1, total - gain, 0);
      if (o->verbose) printf("smooth: sweep %d moved %d vertices, sum 1/q %.6g -> %.6g\n", sweep + 1, changed, total,
                             total - gain);
      /* converged: the sweep lowered Σ 1/q by less than 1e-4 of it */
      if (!changed || gain < 1e-4 * total) break;
    }
  else if (smooth_global(&C, o, cwinv, q, r, err)) {
    memcpy(m->x, x0, sizeof(double) * (size_t)m->nvert * d);
    free(x0); mesh_big_free(q); free(moved); free(cwinv); ut_ctx_free(&C);
    return 1;
  }
  QUALITY();
  quality_stats_compute(q, m->ncell, &st);
  if (o->global && o->energy && !(st.min > r->min_before || (st.min == r->min_before && st.mean > r->mean_before))) {
    /* the energy's descent lowered the minimum, or kept it and not raised the mean: the
     * input stays (never worse than it). A minimum the smoother cannot move (a cell with
     * every vertex on a fixed boundary, as in a twisted bar) keeps the mean's gain */
    memcpy(m->x, x0, sizeof(double) * (size_t)m->nvert * d);
    r->sliding = SMOOTH_SLIDE_NONE; /* no pass kept */
    QUALITY();
    quality_stats_compute(q, m->ncell, &st);
  }
#undef QUALITY
  for (int v = 0; v < m->nvert; v++) {
    int ch = 0;
    for (int j = 0; j < d; j++) ch |= m->x[(size_t)v * d + j] != x0[(size_t)v * d + j];
    r->moved += ch;
  }
  free(x0);
  r->min_after = st.min;
  r->mean_after = st.mean;
  r->seconds = ut_now() - t0;
  mesh_big_free(q);
  free(moved);
  free(cwinv);
  ut_ctx_free(&C);
  return 0;
}

const char *smooth_method_label(const smooth_opts *o, const smooth_report *r) {
  if (r->then_energy) {
    if (r->optimizer != SMOOTH_NEWTON) return "local, then energy, L-BFGS";
    return r->multigrid ? "local, then energy, Newton, multigrid" : "local, then energy, Newton";
  }
  if (!o->energy) return o->global ? "global" : "local";
  if (r->optimizer != SMOOTH_NEWTON) return "energy, L-BFGS";
  return r->multigrid ? "energy, Newton, multigrid" : "energy, Newton";
}

/* "auto": the energy method from where the local one left the mesh, when its minimum stayed
 * below SMOOTH_AUTO_MIN; one report for both (the energy run keeps its result only when it
 * raises the minimum) */
static int smooth_then_energy(mesh *m, const smooth_opts *o, const double *x0, smooth_report *r, char *err) {
  if (!o->then_energy || o->energy || o->xref || m->type == CELL_INTERVAL || !(r->min_after < SMOOTH_AUTO_MIN)) return 0;
  smooth_opts e = *o;
  e.global = e.energy = 1;
  e.then_energy = 0;
  smooth_report re;
  if (smooth_run(m, &e, &re, err)) return 1;
  re.then_energy = 1;
  re.min_local = r->min_after;
  re.min_before = r->min_before;
  re.mean_before = r->mean_before;
  re.seconds += r->seconds;
  re.sweeps = r->sweeps;
  re.moved = 0;
  size_t d = (size_t)m->dim;
  for (int v = 0; v < m->nvert; v++) {
    int ch = 0;
    for (size_t j = 0; j < d; j++) ch |= m->x[(size_t)v * d + j] != x0[(size_t)v * d + j];
    re.moved += ch;
  }
  *r = re;
  return 0;
}

static const char *const optimizer_names[] = {"auto", "newton", "lbfgs"}; /* SMOOTH_AUTO, _NEWTON, _LBFGS */

int smooth_optimizer_from_name(const char *name) {
  for (int i = SMOOTH_AUTO; i <= SMOOTH_LBFGS; i++)
    if (!strcmp(name, optimizer_names[i])) return i;
  return -1;
}

const char *smooth_optimizer_name(int optimizer) {
  return optimizer >= SMOOTH_AUTO && optimizer <= SMOOTH_LBFGS ? optimizer_names[optimizer] : NULL;
}

static const char *const sliding_names[] = {"best", "local", "optimizer"}; /* SMOOTH_SLIDE_* order */

int smooth_sliding_from_name(const char *name) {
  for (int i = SMOOTH_SLIDE_NONE; i <= SMOOTH_SLIDE_INNER; i++)
    if (!strcmp(name, sliding_names[i])) return i;
  return -1;
}

const char *smooth_sliding_name(int sliding) {
  return sliding > SMOOTH_SLIDE_NONE && sliding <= SMOOTH_SLIDE_INNER ? sliding_names[sliding] : NULL;
}

const char *smooth_sliding_label(const smooth_report *r) {
  return r->sliding == SMOOTH_SLIDE_INNER   ? ", boundary slid in the optimizer"
         : r->sliding == SMOOTH_SLIDE_LOCAL ? ", boundary slid by local steps"
                                            : "";
}

int mesh_smooth(mesh *m, const smooth_opts *o, smooth_report *r, char *err) {
  memset(r, 0, sizeof *r);
  if (ut_check_finite(m, "smoothing", err)) return 1;
  if (o->optimizer < SMOOTH_AUTO || o->optimizer > SMOOTH_LBFGS) {
    snprintf(err, MESH_ERRLEN, "unknown optimizer %d (SMOOTH_AUTO, SMOOTH_NEWTON or SMOOTH_LBFGS)", o->optimizer);
    return 1;
  }
  if (o->sliding < SMOOTH_SLIDE_NONE || o->sliding > SMOOTH_SLIDE_INNER) {
    snprintf(err, MESH_ERRLEN, "unknown sliding pass %d (SMOOTH_SLIDE_NONE for both, SMOOTH_SLIDE_LOCAL or SMOOTH_SLIDE_INNER)",
             o->sliding);
    return 1;
  }
  if (o->iterations < 1 || o->iterations > 1000000) {
    snprintf(err, MESH_ERRLEN, "iterations must be 1 to 1000000, got %d", o->iterations);
    return 1;
  }
  size_t nx = (size_t)m->nvert * m->dim;
  double *keep = malloc(sizeof(double) * (nx + 1));
  if (!keep) { snprintf(err, MESH_ERRLEN, "out of memory"); return 1; }
  memcpy(keep, m->x, sizeof(double) * nx);
  unit_frame f;
  if (ut_frame_enter(m, &f, 0, err)) { free(keep); return 1; }
  /* the input in the unit frame, for "auto"'s count of the vertices either method moved */
  double *xin = o->then_energy ? malloc(sizeof(double) * (nx + 1)) : NULL;
  if (xin) memcpy(xin, m->x, sizeof(double) * nx);
  int rc = smooth_run(m, o, r, err) || (xin && smooth_then_energy(m, o, xin, r, err));
  free(xin);
  ut_frame_leave(m, &f);
  if (!rc && !ut_finite_or_restore(m, keep)) {
    r->moved = 0;
    r->min_after = r->min_before;
    r->mean_after = r->mean_before;
  }
  free(keep);
  return rc;
}
