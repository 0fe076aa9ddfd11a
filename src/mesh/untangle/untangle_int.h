/* untangle_int.h — what untangle.c (untangling's driver and stage 2, mesh motion),
 * untangle_ctx.c (the context), untangle_place.c (stages 1 and 3), untangle_global.c (the
 * global stage's energy, its gradient and projected Hessian), untangle_newton.c (projected
 * Newton on it), untangle_lbfgs.c (the objective's evaluation and L-BFGS) and smooth.c
 * (smoothing) share inside src/mesh: the corner and adjacency context, the L-BFGS and Newton
 * objective, the unit frame for meshes far from unit size.
 * Not an interface of the mesh layer: see untangle.h. */
#ifndef LUGAL_UNTANGLE_INT_H
#define LUGAL_UNTANGLE_INT_H

#include "untangle.h"

/* The corners of a cell (section 1: "an element is valid if each corner is valid"): the
 * corner vertex, then its d neighbours in right-handed order. A simplex has one corner (its
 * Jacobian is d! times the signed measure). */
/* progress lines of a long run (untangle_opts.progress, smooth_opts.progress: every so many
 * seconds, 0 none): one line on stderr at most every `every` seconds, the first after as many
 * (a short run prints nothing): what runs, its iteration, the objective and the minimum
 * quality when known, the seconds so far. A 180 000-triangle smoothing ran 128 s printing
 * nothing */
typedef struct {
  double every;
  const char *task;     /* "untangle" or "smooth" */
  const char *stage;    /* "stage 2", "energy round 1", ... */
  double t0, last;
} ut_progress;
void ut_progress_tick(ut_progress *p, const char *what, int it, double f, double qmin);

typedef struct {
  mesh *m;
  ut_progress *progress; /* the run's progress lines, or NULL */
  int d, nvc, ncorner;
  int ct[8][4];
  int *vc_off, *vc; /* vertex -> cells */
  unsigned char *bnd;   /* on the topological boundary */
  unsigned char *fixed; /* may not move: boundary corners, or every boundary vertex */
  int *bnb;             /* 2D: the two boundary neighbours of a boundary vertex */
  int *bf_off, *bf;     /* 3D: vertex -> its boundary facets (cell * nfacets + facet) */
  unsigned char *ntan;  /* sliding boundaries: the directions a boundary vertex may slide in,
                         * 3D: 2 on a flat face, 1 on a straight edge between two flat faces;
                         * 2D: 1 on a straight piece of the boundary; 0 elsewhere (NULL: fixed) */
  double *tan;          /* those directions, 2 unit vectors of d per vertex (ut_tangents) */
  double jtol;          /* corner Jacobians <= jtol count as invalid */
  double jscale;        /* a typical corner Jacobian, to scale the objective */
  const double *x0;     /* motion_weight: where the run started (nvert*d), or NULL */
  double anchor;        /* motion_weight / h²: the weight of |x − x0|² in the objectives */
  int escape;           /* untangle_opts.reference_escape with a reference: its shapes are only a
                         * way out of a tangle (the Tutte-disk run); the global stage minimizes by
                         * projected Newton and stops once every cell is valid */
} ctx;

/* v's slide directions (C->ntan[v] unit vectors of C->d) */
static inline double *ut_tangents(const ctx *C, int v) { return C->tan + (size_t)v * 2 * C->d; }
/* g (d entries at v) projected on v's slide directions: Σ t (t·g), orthonormal t */
static inline void ut_tangent_project(const ctx *C, int v, double *g) {
  int d = C->d, nt = C->ntan[v];
  const double *t = ut_tangents(C, v);
  double out[3] = {0, 0, 0};
  for (int k = 0; k < nt; k++) {
    double a = 0;
    for (int j = 0; j < d; j++) a += t[k * d + j] * g[j];
    for (int j = 0; j < d; j++) out[j] += a * t[k * d + j];
  }
  for (int j = 0; j < d; j++) g[j] = out[j];
}

typedef double (*vertex_penalty)(const ctx *C, int v, const void *arg, int probe); /* probe: for the gradient, no guard */
/* the gradient in v of what a vertex_penalty measures (without its guard), into g[0..d); 1 where
 * it is not finite */
typedef int (*vertex_gradient)(const ctx *C, int v, const void *arg, double *g);

/* f = Σ ((|J − β| − (J − β)) / (2 S))² = Σ (max(0, β − J)/S)² over the corners of cells,
 * the quadratic objective (3.3) scaled by a typical corner Jacobian S */
typedef struct {
  ctx *C;
  double beta, S;
  int ncell;
  const int *cells; /* cells whose corners enter f */
  const int *fidx;  /* vertex -> free index or -1 */
  int lift;         /* a cell counts as bad when below β (stage 3), else when invalid */
  /* global smoothing instead of (3.3): f = Σ 1/q over the cells, +∞ when a cell is invalid
   * or the smallest q falls below qfloor; gradient by central differences over each free
   * vertex's star (exact up to O(e²): only the star's cells depend on the vertex) */
  int smooth, measure;
  double qfloor;
  const int *freev;
  const double *hv; /* per free vertex: its shortest edge, for the difference step */
  /* smooth == 2: the global untangling energy (untangle_global.c), analytic gradient */
  double eps, theta, winv[9];
  /* smoothing's first Newton steps (ut_newton): per corner (cell * ncorner + corner) the ε of a
   * softened barrier χ(D, ε) in place of D, every corner still kept valid; NULL: eps */
  const double *soft_eps;
  int soft_start; /* smoothing's first Newton run: it may begin with the softened steps */
  const double *cwinv; /* per corner W⁻¹ (ncell*ncorner*d*d) of its reference shape, or NULL: winv */
  struct ut_energy_buf *eb; /* smooth == 2: the threaded evaluation's buffers (ut_energy_eval) */
  int stall;        /* smooth == 2 (the energy smoother): a window of this many iterations that
                     * gains less than 5e-6 of f per iteration ends the run (0: no window) */
  double ftol;      /* smooth: a step that lowers f by at most ftol·f ends the run (0: 1e-9) */
  double keepq;     /* ut_newton: an end whose smallest corner quality is below keepq gives way to
                     * the last iterate that was not (the smoother never lowers the minimum) */
  int slide;        /* smooth == 2: the free vertices on the boundary (C->bnd) slide along their
                     * tangents (C->tan) inside the optimizer: ut_eval projects their gradients,
                     * ut_energy_hessian their rows and columns, ut_newton and ut_lbfgs their steps */
  int *amg_used;    /* ut_newton sets *amg_used when it takes the multigrid (NULL: not asked) */
  int *handover;    /* smooth == 2, ut_lbfgs: set, and the run ended, when its iterations 10–19
                     * still gained over 1e-4 of f each on average (NULL: not asked; smooth.c) */
  int no_multigrid; /* ut_newton: block Jacobi throughout. Plain aggregation follows the graph,
                     * not the anisotropy: on the Tutte-disk run of a 160 000-triangle strip it
                     * made the run take twice as long (128 s against 64 s), and forced on a
                     * 40 000-triangle one it needed 200–440 iterations per step and more steps */
} objective;

/* per cell: its energy and vertex gradients; per free vertex: its (cell, vertex) slots */
typedef struct ut_energy_buf {
  int ready;
  double *fc, *gc;
  double *hc; /* a chunk of cells' corner Hessians (ut_energy_hessian), or NULL */
  int *off, *slot;
  int *touch_off, *touch; /* per chunk of hc: the free vertices with slots in it, ascending */
  /* per slot q (off/slot order) and vertex m of its corner: the block of the Hessian's row
   * (the slot's free vertex) and column (vertex m's) on the pattern of the Newton run that
   * built it, −1 for a fixed vertex; NULL when over the memory limit. ut_newton frees it with
   * its pattern (ut_energy_release_blocks) */
  int *bpos;
} ut_energy_buf;
/* frees b->bpos: the pattern it refers to goes */
void ut_energy_release_blocks(ut_energy_buf *b);
/* frees what ut_energy_eval allocated in b (the struct itself is the caller's) */
void ut_energy_release(ut_energy_buf *b);

/* the block pattern of the energy's Hessian: row i (free vertex i) has d×d blocks in the
 * columns col[off[i] .. off[i+1]), sorted: the free vertices that share a cell with it */
typedef struct {
  int *off, *col;
} ut_bsr;
/* the block of (row, col), which the pattern holds (every pair of free vertices sharing a cell) */
static inline size_t ut_bsr_find(const ut_bsr *P, int row, int col) {
  int lo = P->off[row], hi = P->off[row + 1] - 1;
  while (lo < hi) {
    int mid = (lo + hi) / 2;
    if (P->col[mid] < col) lo = mid + 1;
    else hi = mid;
  }
  return (size_t)lo;
}
/* the energy's Hessian (smooth == 2 objectives) at x with each corner's part projected to
 * be positive semidefinite, into val (off[nfree] blocks of d×d, row-major); 1 where the
 * energy is infinite (untangle_global.c) */
int ut_energy_hessian(const objective *o, const double *x, const ut_bsr *P, double *val, int nfree);
/* the smallest corner quality d det(J)^(2/d) / |J|² of a smooth == 2 objective's cells
 * (0 where a corner is invalid): the mean ratio, relative to the reference shapes if any */
double ut_energy_qmin(const objective *o, const double *x);
/* soft_eps for the cells of o at x: per corner (c |J|²/d)^(d/2), the determinant a corner of J's
 * size has at mean ratio c (the corners below mean ratio c see a softened barrier) */
void ut_energy_soft_eps(const objective *o, const double *x, double c, double *soft_eps);
/* the energy of a smooth == 2 objective over the corners of v's cells (all of them, not only
 * o->cells), and into gv its gradient in v; +∞ where a corner is invalid */
double ut_energy_vertex(const objective *o, const double *x, int v, double *gv);
/* projected Newton on a smooth == 2 objective (untangle_newton.c): as ut_lbfgs, each step
 * from the preconditioned conjugate gradients on the projected Hessian, Armijo backtracking;
 * stops when a step lowers f by at most ftol·f (0: 1e-9). Iterations, or -1 out of memory */
int ut_newton(const objective *o, double *x, const int *freev, int nfree, int maxit, double *fout);
/* the block-sparse algebra (untangle_amg.c): y = H x on the pattern (nrow block rows); the
 * inverse diagonal blocks (made positive definite by a relative shift of 1e-10 of their
 * trace, which is added to val's diagonal; dpos: each row's diagonal block); z = D⁻¹ r */
void ut_bsr_mult(const ut_bsr *P, const double *val, int nrow, int d, const double *x, double *y);
void ut_block_jacobi(double *val, const int *dpos, int nrow, int d, double *dinv);
void ut_block_apply(const double *dinv, int nrow, int d, const double *r, double *z);
/* the aggregation multigrid for the Newton smoother's conjugate gradients: one level per
 * coarsening, the finest on the Hessian's own pattern and values (not owned) */
#define UT_AMG_MAXLEV 16
typedef struct {
  int n;              /* block rows */
  ut_bsr P;           /* pattern */
  double *val, *dinv; /* blocks and inverse diagonal blocks */
  float *valf;        /* val in single precision for the cycle's products (owned; NULL: val) */
  int *dpos, owns;    /* each row's diagonal block; val and dinv are this level's */
  double omega;       /* the Jacobi smoother's damping */
  int *agg;           /* row -> the next level's row (its aggregate) */
  int *mem_off, *mem; /* the next level's rows: their members here, in row order */
  size_t *cpos;       /* per block here: the next level's block it adds into */
  double *t, *v1, *w1, *v2, *w2, *r1, *in, *out; /* work vectors */
} ut_amg_level;
typedef struct {
  int nlev, d;
  ut_amg_level L[UT_AMG_MAXLEV];
  double *chol, *part; /* the coarsest level's Cholesky factor; ut_dot's partial sums */
} ut_amg;
/* the hierarchy's patterns from the Hessian's (n block rows of d), its aggregates through
 * the strong couplings of the values val (NULL: through every coupling); 1 out of memory or
 * a stalled coarsening (then ut_amg_free); ut_amg_values: the values for one Newton step (val: the Hessian's, dinv:
 * its inverse diagonal blocks, both kept by pointer); ut_amg_apply: z from one cycle on r */
int ut_amg_build(ut_amg *A, const ut_bsr *P, const double *val, int n, int d);
void ut_amg_values(ut_amg *A, double *val, const double *dinv);
void ut_amg_apply(ut_amg *A, const double *r, double *z);
void ut_amg_free(ut_amg *A);
/* the multigrid above this many block rows, block Jacobi (or Jacobi) below */
#define UT_AMG_MIN_ROWS 32768
/* A x = b on pattern P (n block rows of d = 1, 2 or 3; val: its blocks, whose diagonal gets
 * block Jacobi's shift) for nrhs right sides (bs and xs: nrhs vectors of n d, one after the
 * other) by flexible conjugate gradients on one multigrid hierarchy, from x, until the
 * residual is at most tol |b|: 0 solved, 1 out of memory or no hierarchy (x unchanged), 2 one
 * not converged in maxit iterations (x the last iterate); iters (the most) and res (the
 * largest |r| / |b|) reported */
int ut_amg_pcg(const ut_bsr *P, double *val, int n, int d, int nrhs, const double *bs, double *xs, int maxit, double tol,
               int *iters, double *res);
/* the conjugate gradients of ut_amg_pcg and the Newton smoother: A x = b (pattern P, blocks
 * val, n rows of d; its products with valf, the same in single precision, where not NULL)
 * preconditioned by the multigrid M (flexible) or, M NULL, by block Jacobi
 * (dinv), from x (x0: from x = 0, without a product), until |r|² ≤ lim2, at most maxit
 * iterations, stopping where pᵀAp ≤ 0; w: four work vectors of n d (w[0] ends as the residual),
 * part: 2 (n d / UT_DOT_CHUNK + 2) doubles (two of ut_dot's). Returns the iterations done;
 * *conv 1 where |r|² ≤ lim2 */
int ut_fcg(const ut_bsr *P, const double *val, const float *valf, int n, int d, ut_amg *M, const double *dinv,
           const double *b, double *x, int x0, int maxit, double lim2, double *part, double *w[4], int *conv);
/* f = v in single precision (n entries): ut_fcg's valf, for Newton's inexact directions (not
 * for the harmonic solves' 1e-8 to 1e-12 residuals) */
void ut_to_single(const double *v, float *f, long n);
/* a · b in fixed chunks of UT_DOT_CHUNK entries summed in order (threads over the chunks
 * when n is large): the same bits for any thread count; part holds n / UT_DOT_CHUNK + 1 */
#define UT_DOT_CHUNK 4096
double ut_dot(const double *a, const double *b, long n, double *part);
/* loops fused with sums in ut_dot's chunks (threads over the chunks c of n entries, each
 * from c·UT_DOT_CHUNK to UT_CHUNK_END(c), summed by ut_chunk_sum in order): the same bits */
#ifdef _OPENMP
#define UT_PAR_CHUNKS _Pragma("omp parallel for schedule(static) if (n > 4 * UT_DOT_CHUNK)")
#else
#define UT_PAR_CHUNKS
#endif
#define UT_CHUNK_END(c) ((c) * UT_DOT_CHUNK + UT_DOT_CHUNK < n ? (c) * UT_DOT_CHUNK + UT_DOT_CHUNK : n)
static inline double ut_chunk_sum(const double *part, long nch) {
  double s = 0;
  for (long c = 0; c < nch; c++) s += part[c];
  return s;
}

/* an element-wise loop over n entries, on threads when n is large (each entry on its own:
 * the same bits for any thread count) */
#ifdef _OPENMP
#define UT_PAR_FOR _Pragma("omp parallel for schedule(static) if (n > 4 * UT_DOT_CHUNK)")
#else
#define UT_PAR_FOR
#endif

/* the free vertices' coordinates (freev, d each) copied out of x into buf, in free-vertex
 * order; on threads for many (each entry on its own: the million-triangle spiral's line
 * searches gathered and placed 500 000 vertices five times a Newton step on one thread) */
static inline void ut_gather(double *buf, const double *x, const int *freev, int nfree, int d) {
  long n = (long)nfree * d;
  UT_PAR_FOR
  for (int i = 0; i < nfree; i++)
    for (int a = 0; a < d; a++) buf[(size_t)i * d + a] = x[(size_t)freev[i] * d + a];
}

/* the free vertices placed at x0 + t s (x0 and s in free-vertex order; s NULL: at x0), the
 * line searches' trial points and restores */
static inline void ut_place(double *x, const double *x0, const double *s, double t, const int *freev, int nfree, int d) {
  long n = (long)nfree * d;
  UT_PAR_FOR
  for (int i = 0; i < nfree; i++)
    for (int a = 0; a < d; a++)
      x[(size_t)freev[i] * d + a] = s ? x0[(size_t)i * d + a] + t * s[(size_t)i * d + a] : x0[(size_t)i * d + a];
}

/* the objective that ut_lbfgs and ut_newton minimize, with the motion weight's term; with
 * o->slide the sliding vertices' gradients projected on their tangents */
double ut_eval(const objective *o, const double *x, double *grad, int nfree);
/* with o->slide: the sliding free vertices' parts of vec (nfree × d) projected on their tangents */
void ut_slide_project(const objective *o, double *vec, int nfree);

/* reusable per-vertex / per-cell marks, kept at their rest values (-1 / 0) between uses */
typedef struct {
  int *fidx;            /* vertex -> free index, -1 */
  unsigned char *cmark; /* cell taken, 0 */
  int *cells;
} work;

/* A mesh far from unit size (bounding box below 1e-100 or above 1e100) is worked on in
 * coordinates translated to its box centre and scaled by a power of two, then mapped back:
 * corner Jacobians (lengths to the power d) and the tolerances would underflow or overflow.
 * Vertices that did not move get their original coordinates back bit for bit. */
typedef struct {
  int e;          /* true = unit * 2^e + c */
  double c[3];    /* the centre, scaled by 2^-e */
  double *orig;   /* NULL: not active */
} unit_frame;

static inline const int *cell_of(const ctx *C, int c) { return C->m->cells + (size_t)c * C->nvc; }

/* corner k's Jacobian determinant alone: ut_corner_jac without the gradient, the same
 * operations in the same order (the same bits), inlined with d's two cases written out, for
 * the loops that only need its value (the sign tests of (3.3) and the cell counts: a third
 * of a twisted bar's untangling was spent in the out-of-line call) */
static inline double ut_corner_det(const ctx *C, const double *x, const int *cell, int k) {
  const int *t = C->ct[k];
  if (C->d == 2) {
    const double *p = x + 2 * (size_t)cell[t[0]], *a = x + 2 * (size_t)cell[t[1]], *b = x + 2 * (size_t)cell[t[2]];
    double e00 = a[0] - p[0], e01 = a[1] - p[1], e10 = b[0] - p[0], e11 = b[1] - p[1];
    return e00 * e11 - e01 * e10;
  }
  const double *p = x + 3 * (size_t)cell[t[0]], *a = x + 3 * (size_t)cell[t[1]], *b = x + 3 * (size_t)cell[t[2]],
               *c = x + 3 * (size_t)cell[t[3]];
  double e0[3] = {a[0] - p[0], a[1] - p[1], a[2] - p[2]}, e1[3] = {b[0] - p[0], b[1] - p[1], b[2] - p[2]},
         e2[3] = {c[0] - p[0], c[1] - p[1], c[2] - p[2]};
  double c0 = e1[1] * e2[2] - e1[2] * e2[1], c1 = e1[2] * e2[0] - e1[0] * e2[2], c2 = e1[0] * e2[1] - e1[1] * e2[0];
  return e0[0] * c0 + e0[1] * c1 + e0[2] * c2;
}

/* corner k of cell (global vertex ids) at coordinates x: its Jacobian determinant, and, when
 * g is given, its gradient with respect to each of the corner's d + 1 vertices */
double ut_corner_jac(const ctx *C, const double *x, const int *cell, int k, double g[4][3]);

/* stages 1 and 3 (untangle_place.c): passes over the free vertices (of region, when given)
 * whose corners are violated (J <= jtol, or J < target with stage3), each moved into the
 * feasible set of its linearized constraints by placement (0 Chebyshev centre, 1 corners);
 * at most maxpass passes, a pass that moves nothing ends them. Returns the vertices moved
 * for the first time (marked in moved); *npass the passes made. */
int ut_feasible_passes(ctx *C, double *x, double target, int stage3, const unsigned char *region, int placement,
                       int maxpass, unsigned char *moved, int *npass);

double ut_now(void);
int ut_ctx_init(ctx *C, mesh *m, int slide, char *err);
void ut_ctx_free(ctx *C);
/* the shortest edge at v */
double ut_star_h(const ctx *C, int v);
double ut_cell_min_jac(const ctx *C, const double *x, int c);
void ut_count_cells(const ctx *C, const double *x, double beta, int *ninv, int *nbelow);
/* 3D: one boundary vertex descends pen along its slide directions (the gradient from grad, or
 * by central differences of pen when grad is NULL); 1 if it moved */
int ut_slide_3d(const ctx *C, double *x, int v, vertex_penalty pen, vertex_gradient grad, const void *arg);
int ut_lbfgs(const objective *o, double *x, const int *freev, int nfree, int maxit, double *fout);
/* the cells around the free vertices (each once) */
int ut_cells_around(const ctx *C, work *W, const int *freev, int nfree);
/* the smoothing objective of the cells around v: sum 1/q (smooth.c) */
double ut_star_objective(const ctx *C, int v, int q, double *qmin);
/* the global untangling stage (untangle_global.c): its energy, and the stage on every
 * interior vertex of a triangle or tetrahedron mesh (0, or -1 out of memory) */
double ut_energy_eval(const objective *o, const double *x, double *grad, int nfree);
/* W⁻¹ (d×d, row-major) of a regular simplex whose edge matrix has determinant mean > 0 */
void ut_regular_winv(int d, double mean, double *winv);
/* per corner of each cell W⁻¹ of its shape in the configuration xref (ncell*ncorner*d*d,
 * malloc'd; a simplex has one corner), NULL with a message in err when a reference corner
 * is degenerate or inverted (or out of memory) */
double *ut_reference_winv(const ctx *C, const double *xref, char *err);
/* the mean ratio of each cell's map J = E W⁻¹ from its reference shape, d det(J)^(2/d) / |J|²
 * (the smallest over a quadrilateral's or hexahedron's corners) */
void ut_relative_mean_ratio(const ctx *C, const double *cwinv, double *out);
/* the global stage: the interior vertices (those marked in only, when given) minimize the
 * barrier energy together (untangle_global.c); with reference shapes cwinv one more
 * minimization follows validity. Marks what moved; 0, or -1 out of memory */
int ut_untangle_global(ctx *C, work *W, double *x, int maxit, const double *cwinv, const unsigned char *only,
                       int *iters, int *moved_count, unsigned char *moved);
int ut_frame_enter(mesh *m, unit_frame *f, double extra, char *err);
void ut_frame_leave(mesh *m, unit_frame *f);
/* every vertex coordinate finite, or a message naming the first that is not */
/* what ("untangling", ...) can run on m: a 2D or 3D mesh with finite coordinates */
int ut_check_finite(const mesh *m, const char *what, char *err);
/* a non-finite result is replaced by the input (keep); 0 when that happened */
int ut_finite_or_restore(mesh *m, const double *keep);

#endif
