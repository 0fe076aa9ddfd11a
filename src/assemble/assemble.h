/* assemble.h — the assembly core's public API (the room src/assemble itself): meshes with
 * their dof maps (whole, or a rank's part of a distributed mesh), discrete functions,
 * regions, the element loop that runs generated kernels, point location and evaluation,
 * interpolation, integration of functionals, and output for ParaView. Below it: process/
 * (the environment, errors, ranks), fem/, kernel/ and parallel/; above it: problem/ and
 * optimize/. Every fallible function returns 0 on success, nonzero on failure with
 * env->err set. */
#ifndef LUGAL_ASSEMBLE_H
#define LUGAL_ASSEMBLE_H

#include "../expr/expr.h"
#include "../mesh/io/io.h"
#include "../mesh/quality/quality.h"
#include "fem/fem.h"
#include "kernel/kernel.h"
#include "parallel/parallel.h"
#include "process/process.h"

typedef struct lg_locator lg_locator; /* locate.c */

typedef struct {
  mesh *m;
  lg_locator *locator;  /* which cell holds a point, built on demand for one geometry */
  dofmap *dm[2][4][FEM_MAXBS]; /* by continuity (0 Lagrange, 1 discontinuous), degree and number of components - 1 */
  int validated;        /* the validity check passed for the current geometry */
  unsigned long geometry; /* counts geometry changes (lg_mesh_changed) */
  int *part, nparts;    /* the cells' parts for a run of nparts ranks (lg_mesh_partition), or NULL */
  int part_runs;        /* they are the numbering's runs (the vertex order splits well) */
  /* a distributed mesh (parallel/distribute.c, -lugal_distribute): this rank's part, its
   * owned cells and their ghost layer, whose local mesh m is; NULL when every rank holds
   * the whole */
  mesh_part *dist;
  struct lg_dist_dofs *ddofs; /* its dof maps' layouts (distributed.c), built on first use */
} lg_mesh;

typedef struct {
  lg_mesh *mesh;
  dofmap *dm;
  int degree;
  double *x;            /* ndof values */
  int fid;              /* expr function id (FK_DISCRETE) */
  int per_step;         /* a control with a value per step of a time-dependent problem (lg.control's option) */
  void *step_prev;      /* its companion holding the value of the step before (an lg_function), or NULL */
} lg_function;

lg_mesh *lg_mesh_wrap(mesh *m);
void lg_mesh_free(lg_mesh *lm);
/* drop dof maps and the validity flag after the mesh changed */
void lg_mesh_changed(lg_mesh *lm);
/* the dof map of Lagrange degree `degree` (0..3) with ncomp components (1..3), continuous or
 * discontinuous (disc = 1: every cell owns its nodes) */
dofmap *lg_mesh_dofmap(lg_env *env, lg_mesh *lm, int degree, int ncomp, int disc);
/* the validity check run before assembly */
int lg_mesh_check(lg_env *env, lg_mesh *lm);

/* ---- distributed meshes (distributed.c) */
/* the part of every cell for a run of nparts ranks (lg_partition_cells, parallel.h), kept
 * with the mesh (its topology does not change), rank 0's result on every rank. *part is
 * NULL when the rows stay in the problems' order (natural, one part, or fewer than 8 cells
 * per part) */
int lg_mesh_partition(lg_env *env, lg_mesh *lm, int nparts, const int **part);
/* a distributed mesh as an lg_mesh on every rank, its part cut and sent from rank 0's
 * whole mesh (lg_part_distribute), generated rank by rank (lg_part_generate) or read in
 * parallel (lg_part_read), with their conventions: collective, NULL on every rank where any
 * failed (or where the path cannot take the mesh) */
lg_mesh *lg_mesh_distribute(lg_env *env, mesh *whole);
lg_mesh *lg_mesh_generate_part(lg_env *env, const mesh_box_opts *o, int *whole);
lg_mesh *lg_mesh_read_parts(lg_env *env, const char *path);

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
/* that order's records: a dof's place (entity kind, its global vertices or cell, the
 * node's place on it, the component) and its value or coordinates; lg_function_records
 * gives every rank all owned dofs' records of f, sorted (collective, *out malloc'ed) */
typedef struct {
  int k[7];
  double v[3];
} lg_dof_rec;
int lg_dof_rec_cmp(const void *a, const void *b);
void lg_dof_rec_key(const mesh_part *P, const dofmap *dm, int d, lg_dof_rec *r);
int lg_function_records(lg_env *env, const lg_function *f, int coords, lg_dof_rec **out, long *n);
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

/* The element loop of a vector or a matrix (arity 1 and 2). The items are cut into windows
 * of consecutive items, and each of the consumer's rows (its own numbering, 0 .. nrows - 1)
 * belongs to the window of the first item that has it. Each window is one task, taken by
 * the next free OpenMP thread, which runs the items that have rows of the window in item
 * order, a run of consecutive such items at a time into its own buffer, and hands the run
 * to use(ud, first, n, tensors, ew, w): ew gives the window of each of the run's element
 * rows (item after item, in the order rows() lists them; NULL: all of them are w's), and
 * use adds the rows of window w only. Every entry thus gets its items' terms in item order
 * whatever the number of threads or windows (the same bits as one thread), with no barrier
 * and no serial section: an item with rows of two windows is evaluated by both (the items
 * along the cuts). A non-zero return from use stops the loop (its message in env). */
typedef int (*lg_chunk_use)(void *ud, int first, int n, const double *tensors, const unsigned char *ew, int w);
/* item it's element rows in the consumer's numbering, in its order, into rows; returns
 * their number (the same for every item of a list). A row outside 0 .. nrows - 1 is not the
 * consumer's (another rank's) */
typedef int (*lg_item_rows)(void *ud, int it, int *rows);
#define LG_ITEM_ROWS (2 * KER_MAXFIELD * FEM_MAXLOC * FEM_MAXBS)
/* an element row of no window (not the consumer's) */
#define LG_NO_WINDOW 255
/* a list's windows, kept by the consumer between assemblies (built again when the window
 * count, the rows or the items change) */
typedef struct {
  int n, nrows, nitems, first; /* first: the list's first item (a rank's share) */
  int nr;                      /* element rows per item */
  unsigned char *ew;           /* nr per item: each element row's window, or LG_NO_WINDOW */
  int *range;                  /* 2 per window: its first item and one past its last */
} lg_windows;
void lg_windows_free(lg_windows *w);
/* an element row er of a run is window w's (use()'s test) */
#define LG_IN_WINDOW(ew, er, w) (!(ew) || (ew)[er] == (w))
/* items per run for element tensors of size values: buffers of LG_CHUNK_VALUES doubles
 * (256 KiB, in the cache while the thread adds them into the matrix) */
#define LG_CHUNK_VALUES 32768
int lg_chunk_items(int size);
/* one buffer per thread, kept between assemblies and grown for larger tensors */
typedef struct {
  double **b;
  int nb;
  size_t cap;
} lg_chunk_bufs;
void lg_chunk_bufs_free(lg_chunk_bufs *cb);
typedef struct {
  lg_chunk_use use;
  lg_item_rows rows;
  int nrows;
  void *ud;
  lg_windows *win;
  lg_chunk_bufs *bufs;
  int first; /* the list's first item in the consumer's (a rank's share), for the windows' key */
} lg_consumer;
int lg_assemble_chunks(lg_env *env, lg_mesh *lm, const lg_kernel *k, int total, const int *cells, const int *facets,
                       const coef_binding *bind, const lg_consumer *cons);
/* a functional's kernel (arity 0) over the items, on one thread in item order, added to *out */
int lg_assemble_sum(lg_env *env, lg_mesh *lm, const lg_kernel *k, int total, const int *cells, const int *facets,
                    const coef_binding *bind, double *out);
/* the terms of a sum over the ranks of a parallel run (functionals, arity 0, into out[0];
 * their derivatives, arity 1, through use): each rank runs its share of the items, a
 * contiguous slice from *first (interior facet terms: all of them on rank 0, none elsewhere);
 * a serial run all of them. lg_sum_ranks then sums out[0..n) over the ranks, once for all
 * the terms, with the error of any rank. On a distributed mesh a number takes the items of
 * the rank's owned cells, a vector every local item (its owned dofs' entries are then
 * complete; lg_dist_ghosts gives the ghost dofs theirs) */
int lg_assemble_share(lg_env *env, lg_mesh *lm, const lg_kernel *k, int nitems, const int *cells, const int *facets,
                      const coef_binding *bind, double *out, lg_consumer *cons, int *first);
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

/* the fields on a mesh that every rank holds whole, written for ParaView: npiece 0, a .vtu
 * that rank 0 writes; else a .pvtu of npiece pieces <stem>_p<k>.vtu beside it (k = 0 ..
 * npiece - 1: the parts of the mesh's partition into npiece, lg_mesh_partition, or where it
 * keeps the problems' order mesh_vertex_runs), rank r writing the pieces k = r mod size
 * and rank 0 the collection. Every rank gets the outcome, and the message (MESH_ERRLEN) in
 * err */
int lg_write_vtu(lg_env *env, lg_mesh *lm, const char *path, int nf, const mesh_field *fl, int format, int npiece, char *err);
/* a ParaView series (.pvd) written step by step: each step a .vtu beside it (<stem>_NNNN.vtu),
 * or under mpiexec a .pvtu of a piece per rank (lg_write_vtu), and the .pvd rewritten with
 * every step so far (rank 0) */
typedef struct {
  char *path;
  int n, cap;
  double *t;
  char **files;
} lg_series;
lg_series *lg_series_new(lg_env *env, const char *path);
int lg_series_write(lg_env *env, lg_series *s, lg_mesh *lm, int nf, const mesh_field *fl, double t);
void lg_series_free(lg_series *s);

#endif
