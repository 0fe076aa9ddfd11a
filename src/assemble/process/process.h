/* process.h — the bottom of the assembly layer, the room src/assemble/process: the
 * environment of a run (the symbolic context, the JIT, the kept integration kernels, the
 * options read once, the last error), errors (lg_seterr, PETSc's through lg_petsc_fail and
 * PCHK) and the process layout (PETSc and MPI start-up, ranks, reductions, outcomes shared
 * between ranks). It uses src/expr and the kernel room below it; it knows nothing of meshes.
 * Every fallible function of the layer returns 0 on success, nonzero on failure with
 * env->err set. */
#ifndef LUGAL_PROCESS_H
#define LUGAL_PROCESS_H

#include "../../expr/expr.h"
#include "../kernel/kernel.h"

#include <stddef.h>

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

lg_env *lg_env_new(const char *tcc_libdir);
void lg_env_free(lg_env *env);
void lg_seterr(lg_env *env, const char *fmt, ...);

/* PETSc calls inside functions that return int: on error, record PETSc's message (ierr a
 * PetscErrorCode; the header stays free of PETSc's and MPI's, for programs using lugal's
 * headers without them; PCHK is for files that include PETSc) */
int lg_petsc_fail(lg_env *env, int ierr, const char *what);
#define PCHK(call, what) do { PetscErrorCode ierr_ = (call); if (ierr_) { lg_petsc_fail(env, ierr_, what); return 1; } } while (0)

/* milliseconds on the monotonic clock (timings for -lugal_verbose) */
double lg_now_ms(void);
/* the machine's runnable tasks now (/proc/loadavg's running count, the caller's thread among
 * them), or -1 where that cannot be read: whether a core is idle for another thread */
int lg_runnable_tasks(void);
/* at most T threads, one for the calling thread and one per idle core (all T where the load
 * cannot be read) */
int lg_threads_for_load(int T);

/* PETSc start-up and shutdown with lugal's defaults (see the runner) */
int lg_petsc_init(int *argc, char ***argv);
void lg_petsc_finalize(void);
/* PETSc options that nothing used (a mistyped -ksp_tpye), one warning each on stderr, as
 * -options_left does; returns how many */
int lg_petsc_report_unused_options(void);

/* process.c: the ranks of a run (1 and 0 before MPI starts or after it ends) */
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
/* the end of the whole run from one rank: the message, with the rank, on stderr, then
 * MPI_Abort so that no rank waits for this one (a single process only prints) */
void lg_abort_run(const char *msg);

#endif
