/* kernel.h — generation of element kernels from coefficient tables, and the JIT that
 * compiles them (libtcc in memory, or the system C compiler into a cached shared object).
 *
 * A kernel computes one element tensor:
 *   void k(const double *X, const double *W, const double *P, int facet, double *A,
 *          double *C, int cmode)
 * X: the cell's vertex coordinates; W: the local dofs of every coefficient function in
 * kernel order; P: parameter values; facet: local facet for boundary integrals; A: the
 * element tensor (zeroed by the caller), rows × cols, row-major; C, cmode: the item's slice
 * of the point cache (kernel_pcache) and what to do with it. */
#ifndef LUGAL_KERNEL_H
#define LUGAL_KERNEL_H

#include <stdint.h>

#include "../../expr/expr.h"
#include "../fem/fem.h"

#define KER_MAXFIELD 8
#define KER_MAXCOEF 32

typedef void (*kernel_fn)(const double *X, const double *W, const double *P, int facet, double *A,
                          double *C, int cmode);

/* the per-point cache of kernels (see expr_tape_point_cache): the values of their cached
 * coordinate-only subexpressions at every quadrature point of every item, kept for one
 * geometry. Kernels that cache the same subexpressions with the same rule (their csig) on the
 * same item list share one group, so the values a functional J computed serve dJ/du, the
 * Hessian and the next problem built with them. A group is filled on its first assembly when
 * small (KER_PCACHE_FIRST), else on its second with the same geometry, and read from then
 * on. The kernel's cmode: 0 compute, 1 compute and store in C, 2 read C. */
typedef struct kernel_pcache_group {
  struct kernel_pcache_group *prev, *next; /* the environment's circular list (a sentinel) */
  uint64_t sig, items; /* the kernels' csig and the item list's hash */
  int refs;            /* kernels linked to it; freed with the last */
  uint64_t key;        /* the geometry's hash when seen */
  int seen, valid;
  size_t n;
  double *v;
} kernel_pcache_group;
/* a kernel's link to its group, and the mode of the assembly in progress (a range after
 * the first keeps it) */
typedef struct {
  kernel_pcache_group *g;
  int mode;
} kernel_pcache;
/* drop the kernel's link (the group goes with its last kernel) */
void kernel_pcache_unlink(kernel_pcache *pc);
#define KER_PCACHE_FIRST ((size_t)1 << 21) /* doubles (16 MB): stored on the first assembly */
#define KER_PCACHE_MAX ((size_t)1 << 24) /* doubles (128 MB) per kernel at most */

/* the fields of an element tensor's rows (or columns): field i has nloc[i] local dofs from
 * off[i]; a vector field of bs[i] components (0 or 1: scalar) interlaces them, local dof
 * off + k*bs + j being component j at node k (fem.h) */
typedef struct {
  int n;
  int func[KER_MAXFIELD];
  int degree[KER_MAXFIELD];
  int nloc[KER_MAXFIELD];
  int off[KER_MAXFIELD];
  int bs[KER_MAXFIELD];
  int size;
} field_layout;

typedef struct {
  kernel_fn fn;
  int arity, facet, qdeg, nq;
  field_layout rows, cols;
  int ncoef;
  int coef_func[KER_MAXCOEF];
  int coef_degree[KER_MAXCOEF];
  int coef_ncomp[KER_MAXCOEF]; /* components (interlaced in W) */
  int coef_off[KER_MAXCOEF];
  int coef_side[KER_MAXCOEF];  /* 1: the '-' cell's values (interior facets) */
  int wsize;
  double compile_ms;
  int cached; /* 1 when the JIT found it compiled already */
  int jid;           /* the JIT's id of its code (jit_current) */
  int ncache;        /* cached values per quadrature point */
  uint64_t csig;     /* what they are: the cached subexpressions, the rule, the integral kind */
  kernel_pcache *pc; /* NULL when ncache == 0; freed by kernel_release */
} lg_kernel;

/* ---- the JIT (jit.c) */
typedef struct lg_jit lg_jit;
/* libtcc only, the system compiler only, or libtcc first and the system compiler in the
 * background for kernels that have taken JIT_TIER_MS of assembly time (the default) */
typedef enum { JIT_TCC, JIT_CC, JIT_AUTO } jit_backend;
#define JIT_TIER_MS 20.0

lg_jit *jit_new(jit_backend b, const char *tcc_libdir);
void jit_free(lg_jit *j); /* stops background compilers */
void jit_set_backend(lg_jit *j, jit_backend b);
void jit_set_tier_ms(lg_jit *j, double ms);
/* the nice level of the background builds (-lugal_jit_nice; 0: the run's own) */
#define JIT_NICE 10
void jit_set_nice(lg_jit *j, int nice);
void jit_set_verbose(lg_jit *j, int verbose);
int jit_verbose(const lg_jit *j);
/* compile (or find compiled) a source defining `lugal_kernel`: its code and its id */
int jit_compile(lg_jit *j, const char *src, kernel_fn *fn, int *id, double *ms, int *cached, char *err, size_t errlen);
/* the best code of kernel id now (a finished background build is swapped in here) */
kernel_fn jit_current(lg_jit *j, int id, kernel_fn fallback);
/* ms more spent in kernel id (may start its background build) */
void jit_account(lg_jit *j, int id, double ms);
/* an assembly with kernel id took thread_ms of thread time (wall time times threads) over
 * items items; jit_item_ms gives the last such cost per item (0: not measured yet), by
 * which an assembly decides whether threads pay */
void jit_cost(lg_jit *j, int id, long items, double thread_ms);
double jit_item_ms(const lg_jit *j, int id);
/* wait for every background build; returns how many were swapped in */
int jit_wait(lg_jit *j);
/* kernels per tier: libtcc, compiling, system compiler, staying in libtcc */
void jit_tiers(const lg_jit *j, int count[4]);
size_t jit_count(const lg_jit *j);

/* what the kernel contracts: arity 2 uses jac entries, arity 1 res entries, arity 0 the
 * single integrand */
typedef struct {
  int arity;
  const coef_table *tab;
  expr *integrand; /* arity 0 */
  int scalar_math; /* -lugal_vector_math 0: every call per point, through libm */
} kernel_spec;

/* generate the C source; returns NULL with a message on an unsupported expression */
char *kernel_source(expr_ctx *c, cell_type ct, int facet, int qdeg, const kernel_spec *s,
                    const field_layout *rows, const field_layout *cols, lg_kernel *k,
                    char *err, size_t errlen);
int kernel_build(lg_jit *j, expr_ctx *c, cell_type ct, int facet, int qdeg, const kernel_spec *s,
                 const field_layout *rows, const field_layout *cols, lg_kernel *k, char *err,
                 size_t errlen);
/* free what a built kernel owns (its point cache); the code stays with the JIT */
void kernel_release(lg_kernel *k);

#endif
