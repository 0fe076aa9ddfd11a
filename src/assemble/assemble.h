/* assemble.h — the assembly layer's public API, used by src/lua: the environment (symbolic
 * context + JIT), meshes with their dof maps, discrete functions, interpolation,
 * integration of functionals, and linear / nonlinear problems solved with PETSc.
 * Every fallible function returns 0 on success, nonzero on failure with env->err set. */
#ifndef LUGAL_ASSEMBLE_H
#define LUGAL_ASSEMBLE_H

#include "../expr/expr.h"
#include "../mesh/io/io.h"
#include "../mesh/quality/quality.h"
#include "fem.h"
#include "kernel.h"

#define LG_ERRLEN 1024

/* the kernels of lg.integrate, kept for the next call with the same integrand (their point
 * caches with them): an integrand is an interned node, so its address names it */
#define LG_INTEGRATE_KEEP 16
typedef struct {
  const expr *e;
  int cell, facet, qdeg;
  unsigned long used;
  lg_kernel k;
} lg_kept_kernel;

typedef struct {
  expr_ctx *c;
  lg_jit *jit;
  lg_kept_kernel kept[LG_INTEGRATE_KEEP];
  unsigned long nuse;
  int verbose;          /* -lugal_verbose: timings and kernel statistics on stderr */
  double kernel_ms;     /* total JIT time */
  int nkernels;
  int no_point_cache;   /* -lugal_point_cache 0: kernels recompute their cached values */
  int no_vector_math;   /* -lugal_vector_math 0: transcendental calls per point through libm (vmath.c) */
  int no_keep_factor;   /* -lugal_keep_factor 0: refactor a linear problem's matrix at every change (solver.h) */
  kernel_pcache_group pcache; /* the point caches' groups (kernel.h): the list's sentinel */
  unsigned long pcache_uses[3]; /* assemblies with a point cache by mode: computed, stored, read */
  unsigned long gc_points;      /* the Lua module's collection points passed (largs.c, gc_point) */
  unsigned long collective_seq; /* the Lua module's collective calls so far (lparallel.c) */
  int collective_wait_s;        /* -lugal_collective_wait: seconds a rank waits at one before it says so */
  char err[LG_ERRLEN];
} lg_env;

typedef struct lg_locator lg_locator; /* locate.c */

typedef struct {
  mesh *m;
  lg_locator *locator;  /* which cell holds a point, built on demand for one geometry */
  dofmap *dm[2][4][FEM_MAXBS]; /* by continuity (0 Lagrange, 1 discontinuous), degree and number of components - 1 */
  int validated;        /* the validity check passed for the current geometry */
  unsigned long geometry; /* counts geometry changes (lg_mesh_changed) */
  int *part, nparts;    /* the cells' parts for a run of nparts ranks (partition.c), or NULL */
  int part_runs;        /* they are the numbering's runs (the vertex order splits well) */
  /* a distributed mesh (distribute.c, -lugal_distribute): this rank's part, its owned cells
   * and their ghost layer, whose local mesh m is; NULL when every rank holds the whole */
  mesh_part *dist;
  struct lg_dist_dofs *ddofs; /* its dof maps' layouts (distribute.c), built on first use */
} lg_mesh;

typedef struct {
  lg_mesh *mesh;
  dofmap *dm;
  int degree;
  double *x;            /* ndof values */
  int fid;              /* expr function id (FK_DISCRETE) */
} lg_function;

lg_env *lg_env_new(const char *tcc_libdir);
void lg_env_free(lg_env *env);
void lg_seterr(lg_env *env, const char *fmt, ...);

lg_mesh *lg_mesh_wrap(mesh *m);
void lg_mesh_free(lg_mesh *lm);
/* drop dof maps and the validity flag after the mesh changed */
void lg_mesh_changed(lg_mesh *lm);
/* the dof map of Lagrange degree `degree` (0..3) with ncomp components (1..3), continuous or
 * discontinuous (disc = 1: every cell owns its nodes) */
dofmap *lg_mesh_dofmap(lg_env *env, lg_mesh *lm, int degree, int ncomp, int disc);
/* partition.c: the part (0 .. nparts - 1) of every cell for a run of nparts ranks, kept with
 * the mesh (its topology does not change): by -lugal_partitioner (a MatPartitioningType,
 * "auto" by default: the numbering's runs where they split well, else PTScotch; or
 * "natural"), rank 0's result on every rank. *part is NULL when the rows stay in the
 * problems' order (natural, one part, or fewer than 8 cells per part) */
int lg_mesh_partition(lg_env *env, lg_mesh *lm, int nparts, const int **part);
/* the same on the calling rank alone, into pt (ncell values), *runs = 1 where they are the
 * numbering's runs; returns -1 where the cells' order is kept (no partition), 1 on error */
int lg_partition_cells(lg_env *env, mesh *m, int nparts, int *pt, int *runs);
/* auto's test of the numbering's runs (mesh_runs_interface, mesh_vertex_runs): do they cut
 * about as little as compact parts would (have: the vertices on their cuts), and are they
 * kept (also: no part under half its share of the cells; fewest, the smallest part's
 * cells, or -1 when not counted); lg_runs_kept prints the choice with -lugal_verbose */
int lg_runs_cut_little(long have, long nvert, int d, int nparts);
int lg_runs_kept(lg_env *env, long have, long fewest, long nvert, long ncell, int d, int nparts);
/* the validity check run before assembly */
int lg_mesh_check(lg_env *env, lg_mesh *lm);

/* distribute.c: distributed meshes. Are meshes distributed in this run: several ranks and
 * not -lugal_distribute 0 */
int lg_distribute_wanted(void);
/* the ghost layers a distributed mesh gets (-lugal_ghost_layers, default 1; 2 for interior
 * facet terms with a continuous test function); -1 when the option is not 1 to
 * LG_MAX_GHOST_LAYERS */
#define LG_MAX_GHOST_LAYERS 8
int lg_ghost_layers(void);
/* the mesh `whole` (rank 0's; other ranks pass NULL, or their own copy, which is freed)
 * cut into one part per rank (the partition of lg_partition_cells, rank 0's work), each
 * rank getting its part with one layer of ghost cells (mesh_part); collective. NULL and the
 * reason in env->err on every rank when any failed */
lg_mesh *lg_mesh_distribute(lg_env *env, mesh *whole);
/* a generated box or rectangle (o) distributed without a whole mesh anywhere: each rank
 * generates the window of cell layers that holds its part (the numbering's runs), its ghost
 * layers and the cells around their vertices, and extracts from it the part
 * lg_mesh_distribute would send it (the same to the byte); collective. Where the runs are not
 * the partition (PTScotch's choice, -lugal_partitioner, crossed diagonals, refused options)
 * NULL with *whole = 1 on every rank: rank 0 then generates the whole mesh for
 * lg_mesh_distribute. NULL with *whole = 0 and the reason in env->err on failure */
lg_mesh *lg_mesh_generate_part(lg_env *env, const mesh_box_opts *o, int *whole);
/* read_dist.c: a Gmsh file read in parallel, no rank reading the whole file or holding the
 * whole mesh: each rank's part, the one lg_mesh_distribute would send it with the same
 * partition (to the byte; PTScotch's partition is computed in parallel, so it may differ);
 * collective. NULL on every rank where this path cannot take the file (its layout, its
 * contents, -lugal_read_parts 0): rank 0 then reads it whole for lg_mesh_distribute, which
 * reads what can be read and gives the whole reader's messages */
lg_mesh *lg_mesh_read_parts(lg_env *env, const char *path);
/* a generated box or rectangle partitioned by a graph partitioner on every rank: each rank
 * passes its window m of the mesh (its run's cells and every cell around their vertices: the
 * window lg_mesh_generate_part makes) with global numbers vglob, cglob of nvg vertices and ncg
 * cells; the run's cells enter the reader's pipeline (partition, ghost layers, facets, part)
 * as if read from a file. Collective; NULL on every rank where any failed */
lg_mesh *lg_mesh_parts_from_window(lg_env *env, mesh *m, const int *vglob, const int *cglob, int nvg, int ncg, int layers);
/* -lugal_read_parts (default 1): 0 keeps the whole-file read on rank 0 */
int lg_read_parts_wanted(void);
/* the whole mesh and the fields' whole arrays (point or cell data of fl) on rank 0, from
 * every rank's owned cells and vertices (for output); other ranks get NULLs; collective */
int lg_dist_gather(lg_env *env, lg_mesh *lm, int nf, const mesh_field *fl, mesh **whole, double ***vals);
/* a discrete function's dofs in all (its dof map's on a whole mesh); -1 on failure */
long lg_function_global_ndof(lg_env *env, const lg_function *f);
/* a distributed function's values (coords = 0) or its dofs' coordinates (coords = 1: dim
 * per dof) over the whole mesh, on every rank, in one order for any number of ranks: by
 * the entity holding each node (vertices by their global number first, then edges, faces,
 * cells by their sorted global vertices), the node's place there, the component. For P1
 * and Q1 fields that is the whole mesh's own dof order. Collective; *out malloc'ed */
int lg_function_gather(lg_env *env, const lg_function *f, int coords, double **out, long *n);
/* the n values v in that order into a distributed function's local dofs; collective */
int lg_function_assign_whole(lg_env *env, lg_function *f, const double *v, long n);
/* per-cell values of a distributed mesh, each rank's n values v of its cells with global
 * numbers gid (collective): all ncell of them in the global order on every rank (NaN where
 * none came); their statistics as quality_stats_compute gives them on the whole mesh
 * (argmin/argmax global cells, quality.h); the k worst (quality_worst) into gids and vals,
 * returning how many (-1 on failure) */
int lg_dist_cell_values(lg_env *env, const double *v, const int *gid, int n, long ncell, double *out);
int lg_dist_stats(lg_env *env, const double *v, const int *gid, int n, quality_stats *st);
int lg_dist_worst(lg_env *env, const double *v, const int *gid, int n, int k, int larger_is_better, int *gids, double *vals);
/* the whole mesh (cells, tags, tagged boundary facets, names) on rank 0 (NULL elsewhere),
 * and the coordinates of rank 0's whole mesh back to every rank's local vertices: how a
 * distributed mesh is repaired (untangled, smoothed) on one rank; collective */
int lg_dist_gather_mesh(lg_env *env, lg_mesh *lm, mesh **whole);
int lg_dist_scatter_coords(lg_env *env, lg_mesh *lm, const mesh *whole);
/* a dof map's dofs on a distributed mesh as one distributed vector (built on first use,
 * kept with the mesh; the first call is collective): own[d] = 1 for the local dofs this
 * rank owns (*nown of them; a node is owned where most of its cells are), NULL on failure;
 * lg_dist_ghosts gives every local dof of x (dm->ndof values) its owner's value
 * (collective); lg_dist_dot sums a[d] b[d] over the owned dofs (this rank's share) */
typedef struct lg_dist_dofs lg_dist_dofs;
const char *lg_dist_owned(lg_env *env, lg_mesh *lm, const dofmap *dm, int *nown);
int lg_dist_ghosts(lg_env *env, lg_mesh *lm, const dofmap *dm, double *x);
double lg_dist_dot(const char *own, int n, const double *a, const double *b);
void lg_dist_dofs_free(lg_dist_dofs *D);
/* an lg_mesh over a rank's part (it owns the part) */
lg_mesh *lg_mesh_wrap_part(mesh_part *P);
/* the number of owned cells / vertices summed over the ranks (the whole mesh's counts) */
long lg_mesh_global_cells(const lg_mesh *lm);
long lg_mesh_global_vertices(const lg_mesh *lm);

/* a discrete function on the dof map dm of lm (lg_mesh_dofmap), all zero */
lg_function *lg_function_new(lg_env *env, lg_mesh *lm, dofmap *dm, const char *name);
void lg_function_free(lg_function *f);

/* items (cell, local facet) of a region */
int lg_region_items(lg_env *env, lg_mesh *lm, const region *r, int *n, int **cells, int **facets);

/* coefficient bindings: where the dof values of a function come from */
typedef struct {
  int func;
  const dofmap *dm;
  const double *vals;
} coef_binding;

/* run kernel k over items a chunk at a time into two buffers: chunk c (items c*chunk ..) goes
 * into buf[c % 2] and is handed to use(ud, first, n, tensors) in item order on one thread
 * while the other OpenMP threads compute chunk c + 1. A non-zero return from use stops the
 * loop (its message in env). Arity 1 and 2. */
typedef int (*lg_chunk_use)(void *ud, int first, int n, const double *tensors);
int lg_assemble_chunks(lg_env *env, lg_mesh *lm, const lg_kernel *k, int total, const int *cells, const int *facets,
                       const coef_binding *bind, int chunk, double *const buf[2], lg_chunk_use use, void *ud);
/* items per chunk for element tensors of size values: buffers of LG_CHUNK_VALUES doubles
 * (256 KiB, in the cache while one thread adds them into the matrix) */
#define LG_CHUNK_VALUES 32768
int lg_chunk_items(int size);
/* the two chunk buffers of a loop, kept between assemblies and grown for larger tensors */
typedef struct {
  double *b[2];
  size_t cap;
} lg_chunk_bufs;
int lg_chunk_bufs_reserve(lg_env *env, lg_chunk_bufs *cb, int size);
void lg_chunk_bufs_free(lg_chunk_bufs *cb);
/* the terms of a sum over the ranks of a parallel run (functionals, arity 0, into out[0];
 * their derivatives, arity 1, through use): each rank runs its share of the items, a
 * contiguous slice from *first (interior facet terms: all of them on rank 0, none elsewhere);
 * a serial run all of them. lg_sum_ranks then sums out[0..n) over the ranks, once for all
 * the terms, with the error of any rank. On a distributed mesh a number takes the items of
 * the rank's owned cells, a vector every local item (its owned dofs' entries are then
 * complete; lg_dist_ghosts gives the ghost dofs theirs) */
int lg_assemble_share(lg_env *env, lg_mesh *lm, const lg_kernel *k, int nitems, const int *cells, const int *facets,
                      const coef_binding *bind, double *out, lg_chunk_bufs *cb, lg_chunk_use use, void *ud, int *first);
int lg_sum_ranks(lg_env *env, double *out, size_t n, int rc);
/* bindings for every discrete function the kernel uses (unknowns need extra bindings) */
int lg_bind_discrete(lg_env *env, lg_mesh *lm, const lg_kernel *k, int nextra,
                     const coef_binding *extra, coef_binding *out);

/* every value of v (dm->ndof) finite, or a message "<what> is not finite (nan) at dof 7 (x, y)" */
int lg_check_finite(lg_env *env, const dofmap *dm, const double *v, const char *what);
/* component comp of the function with dof map dm and values vals, or its derivative in
 * direction dir (-1: the value), at reference point xi of cell c, K the inverse Jacobian */
double lg_eval_at(const dofmap *dm, const double *vals, int c, const double *xi, const double K[3][3], int comp, int dir);
/* the same for a field leaf (its component and first derivative) */
double lg_eval_leaf(const dofmap *dm, const double *vals, int c, const double *xi, const double K[3][3], const expr *e);
/* point location (locate.c): the cell holding x and x's reference coordinates there:
 * 0, 1 when x is outside the mesh, -1 on failure (env->err) */
int lg_locate(lg_env *env, lg_mesh *lm, const double *x, int *cell, double *xi);
void lg_locator_free(lg_locator *L);
/* the value of f (its components: out[bs]) at the point x; outside the mesh an error */
int lg_eval_point(lg_env *env, lg_function *f, const double *x, double *out);
/* f = e at f's nodes; e a scalar, or a list of f's number of components */
int lg_interpolate(lg_env *env, lg_function *f, expr *e);
/* integrate a scalar expression over a region (cells or boundary) */
int lg_integrate(lg_env *env, lg_mesh *lm, const region *r, expr *e, int order, double *result);
/* quadrature degree for an integrand */
int lg_quad_degree(lg_env *env, expr *e, int order, cell_type ct);
/* the degree of a linearized form's products (coefficient + test + trial degrees), capped as
 * lg_quad_degree; arity 2 reads the Jacobian entries, arity 1 the residual entries */
int lg_table_degree(lg_env *env, const coef_table *t, int arity, cell_type ct);

/* ---- problems */
typedef struct lg_problem lg_problem;

typedef struct {
  lg_mesh *mesh;
  const form *eqn;
  const form *bc;        /* may be NULL */
  int nfield;
  const int *test;       /* expr function ids */
  const int *unknown;
  int nonlinear;
  int bc_symmetric;      /* eliminate BC columns too (keeps a symmetric operator symmetric) */
  const char *prefix;    /* PETSc options prefix, may be NULL */
  /* a singular problem's null space (nullspace=): the constants of these unknowns (one
   * vector per component; the solution's mean is set to zero), or the rigid body modes of
   * the single vector unknown (null_rigid) */
  int nnull;
  const int *null_fields;
  int null_rigid;
} lg_problem_spec;

lg_problem *lg_problem_new(lg_env *env, const lg_problem_spec *s);
void lg_problem_free(lg_problem *p);
/* solve; out[i] receives a new discrete function for unknown i (caller owns).
 * initial: optional initial guesses (nonlinear), one per unknown (may contain NULL) */
typedef struct {
  int iterations;        /* SNES (nonlinear) or KSP iterations */
  int linear_iterations;
  int nres;
  double res[128];       /* residual norm history (nonlinear) */
  char reason[64];
  char solver[64];       /* "lu/petsc", "lu/mumps", or the KSP and PC types ("cg/gamg") */
  double assemble_ms, solve_ms, setup_ms;
} lg_solve_info;
int lg_problem_solve(lg_env *env, lg_problem *p, lg_function **initial, lg_function **out,
                     lg_solve_info *info);
/* the length of the problem's arrays (its dofs; a distributed mesh's: the local nodes'),
 * and the whole problem's dofs */
int lg_problem_size(const lg_problem *p);
int lg_problem_global_size(const lg_problem *p);
/* this rank's share of the problem's matrix: its rows, and the columns its rows read that
 * other ranks own (the values a product with the matrix receives), -1 before the matrix */
void lg_problem_ownership(const lg_problem *p, int *rows, long *ghosts);
/* out[i] may be NULL: the solution is kept in the problem (lg_problem_solution) either way */

/* ---- what derived operators (adjoints, sensitivities) need of a problem */
typedef struct {
  int test, unknown;   /* expr function ids */
  const dofmap *dm;
  int offset;          /* of the field in the problem's vector */
} lg_field_info;
int lg_problem_fields(const lg_problem *p, lg_field_info *f); /* returns the number of fields */
const form *lg_problem_equation(const lg_problem *p);
const form *lg_problem_bcs(const lg_problem *p);   /* the essential conditions (maybe empty) */
/* solve again (after a control changed), a nonlinear problem from its last solution */
int lg_problem_resolve(lg_env *env, lg_problem *p, lg_solve_info *info);
lg_mesh *lg_problem_mesh(const lg_problem *p);
int lg_problem_is_nonlinear(const lg_problem *p);
/* the last solution (N values), NULL before the first solve */
const double *lg_problem_solution(const lg_problem *p);
/* the rows of the essential conditions at the last solve (in the problem's numbering) */
int lg_problem_essential_rows(const lg_problem *p, int *rows, int max); /* returns how many; writes up to max */
/* essential values g_r that depend on a control (a discrete function fid, or the parameter
 * param when fid < 0): 0 not at all, 1 linearly, 2 nonlinearly, -1 error (a derivative of
 * the control in a condition) */
int lg_problem_bc_dependence(lg_env *env, const lg_problem *p, int fid, int param);
int lg_problem_bc_symmetric(const lg_problem *p);
/* is the second derivative of some essential value with respect to two controls nonzero?
 * (1 yes, 0 no, -1 error) */
int lg_problem_bc_mixed(lg_env *env, const lg_problem *p, int fid1, int param1, int fid2, int param2); /* the columns of the essential rows are eliminated too */
/* their derivatives dg_r/dm_j at the last solve: triplets (problem row, control dof (0 for a
 * parameter), value), allocated; returns how many, -1 on failure */
int lg_problem_bc_derivative(lg_env *env, lg_problem *p, int fid, int param, int **rows, int **cols, double **vals);
/* is row r of the problem's arrays one this rank owns in PETSc's matrix (always, serially) */
int lg_problem_row_owned(const lg_problem *p, int r);
/* bindings of the unknowns (and of their '-' side copies, interior facets) to the last solution:
 * up to 2 per unknown; returns how many */
int lg_problem_bind_state(const lg_problem *p, coef_binding *b);
/* the adjoint: (dR/du)^T lam = rhs at the last solution (N values each), R the discrete
 * residual whose essential rows are u_i - g_i */
int lg_problem_adjoint(lg_env *env, lg_problem *p, const double *rhs, double *lam);
/* the tangent-linear solve: (dR/du) du = rhs at the last solution */
int lg_problem_tangent(lg_env *env, lg_problem *p, const double *rhs, double *du);
/* x = A^-1 rhs for the problem's matrix at u = 0 with homogeneous essential rows (Riesz
 * maps); the factorization is kept */
int lg_problem_solve_vector(lg_env *env, lg_problem *p, const double *rhs, double *x);
/* y = A x with that matrix (N values each), and its Frobenius norm */
int lg_problem_matrix_mult(lg_env *env, lg_problem *p, const double *x, double *y);
/* the diagonal and the row sums of the problem's matrix (assembled at u = 0, essential rows
 * identity), N values each */
int lg_problem_matrix_diagonal(lg_env *env, lg_problem *p, double *diag, double *rowsum);
int lg_problem_matrix_norm(lg_env *env, lg_problem *p, double *norm);

/* assembled operators for tests and benchmarks: the matrix (values into a dense n*n array
 * when n is small) */
int lg_problem_dense_matrix(lg_env *env, lg_problem *p, double *dense, int n);
/* reassemble the matrix only (benchmarks); returns milliseconds */
int lg_problem_assemble_matrix(lg_env *env, lg_problem *p, double *ms);
long lg_problem_nnz(const lg_problem *p);

/* ---- functionals, adjoints, reduced functionals (functional.c) */

/* the compiled kernels of a form, for a number (func < 0) or the vector of its gradient
 * with respect to function func in the space dm (func need not enter linearly) */
typedef struct lg_form_kernels lg_form_kernels;
lg_form_kernels *lg_form_kernels_new(lg_env *env, lg_mesh *lm, const form *F, int func, const dofmap *dm);
void lg_form_kernels_free(lg_form_kernels *K);
int lg_form_kernels_empty(const lg_form_kernels *K);
/* evaluate with the given extra bindings (unknowns bound to values): out[0], or out[dm->ndof] */
int lg_form_kernels_eval(lg_env *env, lg_mesh *lm, lg_form_kernels *K, int nextra, const coef_binding *extra, double *out);

#define LG_MAXCONTROL 8
enum { LG_CONTROL_FIELD, LG_CONTROL_PARAM };
enum { LG_RIESZ_NONE, LG_RIESZ_L2, LG_RIESZ_H1 };
typedef struct {
  int kind;
  lg_function *f;   /* a field control: a discrete function the problem's forms use */
  int param;        /* a parameter control: its index */
} lg_control;

/* j(m) = J(u(m), m) for a state problem and a functional (a form without test functions);
 * the controls must appear in the problem or the functional, not (yet) in its essential
 * conditions */
typedef struct lg_reduced lg_reduced;
lg_reduced *lg_reduced_new(lg_env *env, lg_problem *p, const form *J, int nc, const lg_control *c);
void lg_reduced_free(lg_reduced *rf);
int lg_reduced_ncontrols(const lg_reduced *rf);
const lg_control *lg_reduced_control(const lg_reduced *rf, int i);
int lg_reduced_control_size(const lg_reduced *rf, int i); /* dofs of a field, 1 for a parameter */
lg_problem *lg_reduced_problem(const lg_reduced *rf);
/* a control's values changed: the next value or gradient solves the state again */
void lg_reduced_changed(lg_reduced *rf);
/* rf and from have the same state problem and from's state is that of the current controls
 * (which both see): rf takes it without solving again; returns 1 if it did */
int lg_reduced_share_state(lg_reduced *rf, const lg_reduced *from);
int lg_reduced_value(lg_env *env, lg_reduced *rf, double *J);
/* the gradient dj/dm_i as dual vectors (g[i] has lg_reduced_control_size values): one
 * adjoint solve with the state's factorization */
int lg_reduced_gradient(lg_env *env, lg_reduced *rf, double **g);
/* sum_i <a_i, b_i> over the controls' vectors (dual against primal: dofs paired one to one;
 * a distributed mesh's owned dofs summed over the ranks, collective) */
int lg_reduced_dot(lg_env *env, lg_reduced *rf, double **a, double **b, double *out);
/* the Hessian action H dm (dual vectors, like the gradient) at the current controls: a
 * tangent-linear and a second-order adjoint solve with the state's factorization */
int lg_reduced_hessian(lg_env *env, lg_reduced *rf, double **dm, double **out);
/* the Riesz representative of a dual vector of control i: none, L2 (mass) or H1 */
int lg_reduced_riesz(lg_env *env, lg_reduced *rf, int i, int kind, const double *dual, double *out);
/* the Gram matrix problem of field control i (L2: mass; H1: mass + stiffness) */
lg_problem *lg_reduced_gram(lg_env *env, lg_reduced *rf, int i, int h1);

/* du/da at the last solution of p, for a parameter a of its equation (not of its essential
 * conditions): one tangent-linear solve with the state's factorization; du has N values */
int lg_sensitivity(lg_env *env, lg_problem *p, int param, double *du);

/* ---- minimization through TAO (optimize.c) */
#define LG_MAXCONS 16
enum { LG_CON_LE, LG_CON_GE, LG_CON_EQ };
typedef struct {
  const char *method;          /* quasi-Newton "lmvm", "blmvm" (bounds); Newton-Krylov with Hessian
                                * actions "nls", "ntr", "bnls", "bntr" (bounds); "almm" (constraints) */
  int maxit;                   /* 0: TAO's default */
  double gatol, grtol, gttol;  /* TAO's: |g| < gatol, |g|/|J| < grtol, |g|/|g0| < gttol; < 0: TAO's defaults */
  int monitor;                 /* a line per iteration on stdout */
  int riesz;                   /* the inner product of field controls: LG_RIESZ_L2 (default) or NONE */
  const double *lower[LG_MAXCONTROL], *upper[LG_MAXCONTROL]; /* per control, NULL: none */
  const char *series;          /* a .pvd of the field controls per iteration, or NULL */
  /* functional constraints g_j(m) <= c_j, >= c_j or == c_j ("almm": TAO's augmented
   * Lagrangian); each g_j a reduced functional of the same controls */
  int ncons;
  struct { lg_reduced *rf; int kind; double c; } cons[LG_MAXCONS];
} lg_minimize_opts;
typedef struct {
  int iterations, evaluations, hessian_products;
  double J, gnorm, cnorm;
  char reason[64];
  int converged;
  double g[LG_MAXCONS];        /* the constraints' values g_j at the minimizer */
  double lambda[LG_MAXCONS];   /* multipliers: grad J + sum_j lambda_j grad g_j = 0 */
} lg_minimize_info;
/* minimize the reduced functional over its controls, from their current values; they hold
 * the minimizer on return. Fails (with a message) on a state solve that fails, a non-finite
 * functional, or TAO not converging. */
int lg_minimize(lg_env *env, lg_reduced *rf, const lg_minimize_opts *o, lg_minimize_info *info);

/* PETSc start-up and shutdown with lugal's defaults (see the runner) */
int lg_petsc_init(int *argc, char ***argv);
void lg_petsc_finalize(void);
/* PETSc options that nothing used (a mistyped -ksp_tpye), one warning each on stderr, as
 * -options_left does; returns how many */
int lg_petsc_report_unused_options(void);

/* parallel.c: the ranks of a run (1 and 0 before MPI starts or after it ends) */
int lg_mpi_size(void);
int lg_mpi_rank(void);
typedef enum { LG_SUM, LG_MAX, LG_MIN } lg_reduce_op;
/* x[0..n) reduced over the ranks, the result on every rank */
int lg_allreduce(double *x, int n, lg_reduce_op op);
/* rank 0's rc (and, when it is non-zero, its message in msg) on every rank: the outcome of
 * work that rank 0 alone does for all (file output) */
int lg_root_result(int rc, char *msg, size_t len);
/* the outcome of work every rank does for its part (each rank's rc, its message in msg):
 * non-zero on every rank when any failed, with the message of the lowest failing rank */
int lg_any_result(int rc, char *msg, size_t len);
/* rank 0's *len bytes at *buf to every rank: the others get a malloc'ed copy in *buf (free
 * it); 1 when out of memory or the broadcast failed (on every rank) */
int lg_bcast_bytes(char **buf, size_t *len);
/* the fields on a mesh that every rank holds whole, written for ParaView: npiece 0, a .vtu
 * that rank 0 writes; else a .pvtu of npiece pieces <stem>_p<k>.vtu beside it (k = 0 ..
 * npiece - 1: the parts of the mesh's partition into npiece, lg_mesh_partition, or where it
 * keeps the problems' order mesh_vertex_runs), rank r writing the pieces k = r mod size
 * and rank 0 the collection. Every rank gets the outcome, and the message (MESH_ERRLEN) in
 * err */
int lg_write_vtu(lg_env *env, lg_mesh *lm, const char *path, int nf, const mesh_field *fl, int format, int npiece, char *err);
/* the end of the whole run from one rank: the message, with the rank, on stderr, then
 * MPI_Abort so that no rank waits for this one (a single process only prints) */
void lg_abort_run(const char *msg);

#endif
