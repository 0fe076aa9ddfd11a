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

#include "../expr/expr.h"
#include "fem.h"

#define KER_MAXFIELD 8
#define KER_MAXCOEF 32

typedef void (*kernel_fn)(const double *X, const double *W, const double *P, int facet, double *A,
                          double *C, int cmode);

/* the per-point cache of a kernel (see expr_tape_point_cache): the values of its cached
 * coordinate-only subexpressions at every quadrature point of every item, kept for one
 * geometry and item list (key); filled on the second assembly with the same key, read from
 * the third on. The kernel's cmode: 0 compute, 1 compute and store in C, 2 read C. */
typedef struct {
  uint64_t key;
  int seen, valid;
  size_t n;
  double *v;
} kernel_pcache;
#define KER_PCACHE_MAX ((size_t)1 << 24) /* doubles (128 MB) per kernel at most */

typedef struct {
  int n;
  int func[KER_MAXFIELD];
  int degree[KER_MAXFIELD];
  int nloc[KER_MAXFIELD];
  int off[KER_MAXFIELD];
  int size;
} field_layout;

typedef struct {
  kernel_fn fn;
  int arity, facet, qdeg, nq;
  field_layout rows, cols;
  int ncoef;
  int coef_func[KER_MAXCOEF];
  int coef_degree[KER_MAXCOEF];
  int coef_off[KER_MAXCOEF];
  int wsize;
  double compile_ms;
  int cached; /* 1 when the JIT found it compiled already */
  int ncache;        /* cached values per quadrature point */
  kernel_pcache *pc; /* NULL when ncache == 0; freed by kernel_release */
} lg_kernel;

typedef struct lg_jit lg_jit;
typedef enum { JIT_TCC, JIT_CC } jit_backend;

lg_jit *jit_new(jit_backend b, const char *tcc_libdir);
void jit_free(lg_jit *j);
void jit_set_backend(lg_jit *j, jit_backend b);
/* compile (or find in the cache) a source defining `lugal_kernel` */
kernel_fn jit_compile(lg_jit *j, const char *src, double *ms, int *cached, char *err, size_t errlen);
size_t jit_count(const lg_jit *j);

/* what the kernel contracts: arity 2 uses jac entries, arity 1 res entries, arity 0 the
 * single integrand */
typedef struct {
  int arity;
  const coef_table *tab;
  expr *integrand; /* arity 0 */
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
