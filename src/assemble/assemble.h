/* assemble.h — the assembly layer's public API, used by src/lua: the environment (symbolic
 * context + JIT), meshes with their dof maps, discrete functions, interpolation,
 * integration of functionals, and linear / nonlinear problems solved with PETSc.
 * Every fallible function returns 0 on success, nonzero on failure with env->err set. */
#ifndef LUGAL_ASSEMBLE_H
#define LUGAL_ASSEMBLE_H

#include "../expr/expr.h"
#include "../mesh/mesh.h"
#include "fem.h"
#include "kernel.h"

#define LG_ERRLEN 1024

typedef struct {
  expr_ctx *c;
  lg_jit *jit;
  int verbose;          /* -lugal_verbose: timings and kernel statistics on stderr */
  double kernel_ms;     /* total JIT time */
  int nkernels;
  char err[LG_ERRLEN];
} lg_env;

typedef struct {
  mesh *m;
  dofmap *dm[4];        /* by degree, built on demand */
  int validated;        /* the validity check passed for the current geometry */
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
dofmap *lg_mesh_dofmap(lg_env *env, lg_mesh *lm, int degree);
/* the validity check run before assembly */
int lg_mesh_check(lg_env *env, lg_mesh *lm);

lg_function *lg_function_new(lg_env *env, lg_mesh *lm, int degree, const char *name);
void lg_function_free(lg_function *f);

/* items (cell, local facet) of a region */
int lg_region_items(lg_env *env, lg_mesh *lm, const region *r, int *n, int **cells, int **facets);

/* coefficient bindings: where the dof values of a function come from */
typedef struct {
  int func;
  const dofmap *dm;
  const double *vals;
} coef_binding;

/* run kernel k over items, writing element tensors one after another into out (arity 1
 * and 2, nitems*size values) or summing into out[0] (arity 0) */
int lg_assemble_items(lg_env *env, lg_mesh *lm, const lg_kernel *k, int nitems, const int *cells,
                      const int *facets, int nbind, const coef_binding *bind, double *out);
/* bindings for every discrete function the kernel uses (unknowns need extra bindings) */
int lg_bind_discrete(lg_env *env, lg_mesh *lm, const lg_kernel *k, int nextra,
                     const coef_binding *extra, coef_binding *out);

/* every value of v (dm->ndof) finite, or a message "<what> is not finite (nan) at dof 7 (x, y)" */
int lg_check_finite(lg_env *env, const dofmap *dm, const double *v, const char *what);
int lg_interpolate(lg_env *env, lg_function *f, expr *e);
/* integrate a scalar expression over a region (cells or boundary) */
int lg_integrate(lg_env *env, lg_mesh *lm, const region *r, expr *e, int order, double *result);
/* quadrature degree for an integrand */
int lg_quad_degree(lg_env *env, expr *e, int order, int dim);

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
  double assemble_ms, solve_ms, setup_ms;
} lg_solve_info;
int lg_problem_solve(lg_env *env, lg_problem *p, lg_function **initial, lg_function **out,
                     lg_solve_info *info);
int lg_problem_size(const lg_problem *p);

/* assembled operators for tests and benchmarks: the matrix (values into a dense n*n array
 * when n is small) */
int lg_problem_dense_matrix(lg_env *env, lg_problem *p, double *dense, int n);
/* reassemble the matrix only (benchmarks); returns milliseconds */
int lg_problem_assemble_matrix(lg_env *env, lg_problem *p, double *ms);
long lg_problem_nnz(const lg_problem *p);

/* PETSc start-up and shutdown with lugal's defaults (see the runner) */
int lg_petsc_init(int *argc, char ***argv);
void lg_petsc_finalize(void);
/* PETSc options that nothing used (a mistyped -ksp_tpye), one warning each on stderr, as
 * -options_left does; returns how many */
int lg_petsc_report_unused_options(void);
/* number of MPI processes */
int lg_petsc_size(void);

#endif
