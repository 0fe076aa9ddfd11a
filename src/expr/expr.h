/* expr.h — the symbolic engine: an immutable, hash-consed expression DAG owned by a
 * context, simplified at construction, with differentiation with respect to leaves,
 * spatial derivatives pushed to the leaves, substitution, evaluation tapes, C code
 * generation, and linearization of integrands into coefficient tables.
 *
 * Depends on libc and libm only. Constructors return NULL on a shape or domain error and
 * leave a message in ctx->err ("cannot add a 2-vector and a scalar").
 */
#ifndef LUGAL_EXPR_H
#define LUGAL_EXPR_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

typedef enum {
  E_CONST,  /* value */
  E_PARAM,  /* a named scalar parameter: index */
  E_COORD,  /* spatial coordinate: comp */
  E_NORMAL, /* outward unit normal on a facet: comp */
  E_FIELD,  /* D^alpha f_c: func, comp, alpha */
  E_SUM,    /* n-ary sum */
  E_PROD,   /* n-ary product */
  E_POW,    /* ch[0]^ch[1] */
  E_FUNC,   /* fn(ch[0]) */
  E_LIST,   /* vector / nested list */
  /* pending sums and products (expr_add_lazy, expr_mul_lazy): ch[0] + ch[1] or ch[0]*ch[1]
   * where ch[0] is a large sum or product; they make term-by-term building O(n log n)
   * instead of O(n^2). Only expr_canon and the lazy constructors see them: every other
   * function of this header resolves its arguments first. */
  E_LAZY_SUM,
  E_LAZY_PROD
} expr_kind;

typedef enum {
  FN_SIN, FN_COS, FN_TAN, FN_EXP, FN_LOG, FN_SQRT, FN_ABS, FN_TANH, FN_SINH, FN_COSH,
  FN_ATAN, FN_ASIN, FN_ACOS, FN_SIGN, FN_COUNT
} expr_fn;

#define EXPR_MAXDIM 3
#define EXPR_ERRLEN 512
#define EXPR_MAXRANK 8        /* lists nest at most this deep */
#define EXPR_MAXENTRIES 65536 /* and hold at most this many scalar entries */

/* what a node depends on */
#define DEP_POINT 1 /* coordinates, normals or fields: varies within a cell */
#define DEP_PARAM 2

typedef struct expr {
  expr_kind kind;
  int id;         /* creation index in the context */
  uint64_t hash;  /* structural hash, the same across runs */
  int n;          /* children */
  struct expr **ch;
  double value;   /* E_CONST */
  int i0;         /* PARAM: index; COORD/NORMAL: comp; FIELD: function id; FUNC: fn */
  int i1;         /* FIELD: component */
  unsigned char alpha[EXPR_MAXDIM]; /* FIELD: derivative orders per direction */
  int dep;        /* DEP_* */
  int order;      /* FIELD: |alpha| */
  struct expr *canon; /* E_LAZY_*: the resolved expression, once computed */
} expr;

/* kinds of functions a FIELD leaf can refer to */
typedef enum { FK_TEST, FK_UNKNOWN, FK_DISCRETE } func_kind;

typedef struct {
  func_kind kind;
  char name[64]; /* for messages only; never emitted into generated code */
  int degree;    /* polynomial degree of the basis (for quadrature selection) */
  int ncomp;
  int disc;      /* discontinuous (lg.discontinuous): its dofs belong to the cells */
  int side;      /* interior facets: 1 for a function's restriction to the '-' side (its
                  * values from the neighbour cell), 0 otherwise */
  int twin;      /* the function of the other side, -1 until expr_func_side makes it */
  void *user;    /* owned by the layer that created it */
} expr_func_info;

typedef struct expr_ctx expr_ctx;

expr_ctx *expr_ctx_new(void);
void expr_ctx_free(expr_ctx *c);
const char *expr_error(const expr_ctx *c);
void expr_set_error(expr_ctx *c, const char *fmt, ...);
void expr_set_dim(expr_ctx *c, int dim);
int expr_dim(const expr_ctx *c);
size_t expr_node_count(const expr_ctx *c);
/* a bound on the memory a context's nodes take, in slots of 8 bytes (a node costs 8 + its
 * number of children): past it constructors fail with a message instead of exhausting
 * memory on an expansion that grows without bound */
#define EXPR_DEFAULT_BUDGET ((size_t)1 << 27)
void expr_set_budget(expr_ctx *c, size_t slots);

/* parameters */
int expr_param_new(expr_ctx *c, const char *name, double value);
double *expr_param_values(expr_ctx *c);
int expr_param_count(const expr_ctx *c);
const char *expr_param_name(const expr_ctx *c, int i);

/* functions */
int expr_func_new(expr_ctx *c, func_kind kind, const char *name, int degree, int ncomp, void *user);
expr_func_info *expr_func_get(expr_ctx *c, int id);
int expr_func_count(const expr_ctx *c);

/* the user data of a function is gone (a freed discrete function): NULL in it and in its
 * other side's copy */
void expr_func_forget_user(expr_ctx *c, int id);
/* the function id of function id restricted to side 0 ('+', the function itself) or 1
 * ('-': a copy of it, made once, with the same kind, basis and user data); -1 on error */
int expr_func_side(expr_ctx *c, int id, int side);
/* e restricted to one side of an interior facet: side 0 is e; side 1 replaces every
 * function by its '-' copy (functions already on '-' stay) and the normal n by -n (the
 * normal of an interior facet points from its '+' cell to its '-' cell) */
expr *expr_restrict(expr_ctx *c, expr *e, int side);

/* leaves */
expr *expr_num(expr_ctx *c, double v);
expr *expr_param(expr_ctx *c, int index);
expr *expr_coord(expr_ctx *c, int comp);
expr *expr_normal(expr_ctx *c, int comp);
expr *expr_field(expr_ctx *c, int func, int comp, const unsigned char *alpha);

/* operations (NULL propagates: any NULL argument gives NULL). Every function of this
 * header returns a resolved (canonical) expression, except the _lazy constructors. */
expr *expr_add(expr_ctx *c, expr *a, expr *b);
expr *expr_sub(expr_ctx *c, expr *a, expr *b);
expr *expr_mul(expr_ctx *c, expr *a, expr *b);
expr *expr_div(expr_ctx *c, expr *a, expr *b);
expr *expr_neg(expr_ctx *c, expr *a);
expr *expr_pow(expr_ctx *c, expr *a, expr *b);
expr *expr_apply(expr_ctx *c, expr_fn fn, expr *a);
expr *expr_list(expr_ctx *c, int n, expr **items);
expr *expr_sum_n(expr_ctx *c, int n, expr **terms);
expr *expr_prod_n(expr_ctx *c, int n, expr **factors);
/* a + b, a - b and a*b that may leave a pending node when one side is a large sum or product
 * (what a script's `s = s + t` in a loop builds): O(1) each, resolved once by expr_canon */
expr *expr_add_lazy(expr_ctx *c, expr *a, expr *b);
expr *expr_sub_lazy(expr_ctx *c, expr *a, expr *b);
expr *expr_mul_lazy(expr_ctx *c, expr *a, expr *b);
/* the canonical expression of e (e itself unless it is pending): O(n log n) for n terms */
expr *expr_canon(expr_ctx *c, expr *e);

/* vector calculus on lists */
expr *expr_index(expr_ctx *c, expr *list, int i); /* 0-based */
expr *expr_dot(expr_ctx *c, expr *a, expr *b);     /* contracts the last/first index */
expr *expr_inner(expr_ctx *c, expr *a, expr *b);   /* full contraction, same shape */
expr *expr_grad(expr_ctx *c, expr *a);             /* appends an index of size dim */
expr *expr_div_op(expr_ctx *c, expr *a);           /* divergence of a vector */
expr *expr_dx(expr_ctx *c, expr *a, int dir);      /* spatial derivative, pushed to leaves */

/* tensor algebra (tensor.c), shapes checked (a message and NULL otherwise): matrices are
 * lists of rows, 1x1 to 3x3 */
expr *expr_transpose(expr_ctx *c, expr *a);
expr *expr_sym(expr_ctx *c, expr *a);   /* (A + A^T)/2 */
expr *expr_skew(expr_ctx *c, expr *a);  /* (A - A^T)/2 */
expr *expr_trace(expr_ctx *c, expr *a);
expr *expr_det(expr_ctx *c, expr *a);
expr *expr_inv(expr_ctx *c, expr *a);
expr *expr_identity(expr_ctx *c, int n);
expr *expr_outer(expr_ctx *c, expr *a, expr *b); /* a_i b_j */
expr *expr_cross(expr_ctx *c, expr *a, expr *b); /* 3-vectors; two 2-vectors give a scalar */
expr *expr_dev(expr_ctx *c, expr *a);   /* A - tr(A)/n I */

/* shape: 0 for scalars, else the list length; *rank the nesting depth */
int expr_shape(const expr *e, int *rank);
void expr_describe_shape(const expr *e, char *buf, size_t len);

/* differentiation with respect to a leaf (FIELD, PARAM, COORD or NORMAL node) */
expr *expr_diff(expr_ctx *c, expr *e, expr *leaf);
/* replace leaves: from[i] (leaf nodes) by to[i] */
expr *expr_subs(expr_ctx *c, expr *e, int n, expr **from, expr **to);
/* every FIELD leaf of function func (or any function when func < 0) in e, deduplicated */
int expr_collect_fields(expr_ctx *c, int nroot, expr **roots, int func, int max, expr **out);
int expr_uses(expr_ctx *c, expr *e, expr_kind kind, int *maxcomp);
/* the parameters the roots read, their indices increasing and each once, up to max of
 * them written into out; returns how many there are (-1: out of memory) */
int expr_collect_params(expr_ctx *c, int nroot, expr **roots, int max, int *out);
/* the first abs or sign node of e whose argument depends on one of the functions fids or the
 * parameters pids (a kink: not twice differentiable there), NULL when there is none */
expr *expr_find_kink(expr_ctx *c, expr *e, int nf, const int *fids, int np, const int *pids);
/* a polynomial-degree estimate used to choose quadrature orders */
int expr_degree(expr_ctx *c, expr *e, int cell_degree_of_coords);
/* the same, and *exact = 1 when e is a polynomial (the estimate is its degree): no
 * transcendental function, non-integer power or division of a non-constant */
int expr_degree_exact(expr_ctx *c, expr *e, int cell_degree_of_coords, int *exact);
/* the same on a cell kind: simplex = 0 (quadrilaterals, hexahedra: degrees per variable of
 * tensor-product bases) keeps a leaf's degree under a derivative, as UFL does there */
int expr_degree_cell(expr_ctx *c, expr *e, int cell_degree_of_coords, int simplex, int *exact);

/* text form for messages and __tostring */
void expr_print(expr_ctx *c, const expr *e, char *buf, size_t len);

/* ---- tapes: a topologically sorted list of the nodes under some roots */
typedef struct {
  int n;
  expr **node;  /* nodes in evaluation order */
  int nroot;
  int *root;    /* tape index of each root */
} expr_tape;

int expr_tape_build(expr_ctx *c, int nroot, expr **roots, expr_tape *t);
void expr_tape_free(expr_tape *t);
/* evaluate with leaf values from a callback: returns 0 or nonzero if the callback fails */
typedef int (*expr_leaf_fn)(void *ud, const expr *leaf, double *val);
int expr_tape_eval(const expr_tape *t, const double *params, expr_leaf_fn leaf, void *ud,
                   double *work /* t->n */, double *out /* t->nroot */);

/* ---- C code generation: emits "const double tN = ...;" lines for the nodes of tape t
 * that satisfy (dep & mask) == want (e.g. the parameter-only nodes before a loop), with
 * leaves named by a callback. Names are generated identifiers only. */
typedef void (*expr_leaf_name_fn)(void *ud, const expr *leaf, char *buf, size_t len);
typedef struct {
  char *s;
  size_t len, cap;
  int failed;
} strbuf;
void sb_printf(strbuf *b, const char *fmt, ...);
void sb_free(strbuf *b);
/* emit code for nodes with index in [0, t->n) selected by `select` (1 = emit); the caller
 * decides which nodes go before a loop and which inside. Node k is named "<prefix>k". */
/* select[k]: 0 skip, 1 declare ("const double tN = ..."), 2 assign to a variable declared
 * before ("tN = ..."), 3 declare as the value at point q of the array VN ("const double tN =
 * VN[q];", a call evaluated for all points at once, expr_tape_vector_calls), 4 assign it */
void expr_codegen(strbuf *b, const expr_tape *t, const char *prefix, const char *param_array,
                  const unsigned char *select, expr_leaf_name_fn leafname, void *ud,
                  const char *indent);
/* the classes of tape nodes for a per-point cache of coordinate-only transcendental
 * subexpressions (see codegen.c); returns the number of cached nodes, -1 out of memory */
enum { PC_OTHER, PC_CACHED, PC_INNER, PC_SHARED };
int expr_tape_point_cache(const expr_tape *t, unsigned char *cls /* t->n */, int *slot /* t->n */);
/* the calls of sin, cos, tan, exp, log, tanh, sinh, cosh, atan, asin and acos whose
 * argument varies in the cell (DEP_POINT) and depends on the coordinates, constants and
 * parameters only: a kernel evaluates them for all quadrature points of an item at once (a
 * vector math routine). level[k] = 1 + the highest level of such calls inside node k's
 * argument for these calls (up to EXPR_VECTOR_LEVELS; deeper ones get 0), 0 for every other
 * node; returns their number, -1 out of memory */
int expr_tape_vector_calls(const expr_tape *t, int *level /* t->n */);
#define EXPR_VECTOR_LEVELS 4
/* mark[j] = 1 for the point-varying nodes that the arguments of the calls with roots[k] set
 * need, computed from the coordinates (stopping at vector calls, marked 3: their values are
 * loaded); mark is not cleared first */
int expr_tape_vector_closure(const expr_tape *t, const unsigned char *roots, const int *level, unsigned char *mark);
/* live[j] = 1 for the nodes that the nodes with need[j] set are computed from inside the
 * quadrature loop: through point-varying nodes, stopping at vector calls (level[j] > 0,
 * their values are loaded) and at the nodes computed before the loop; live is not cleared
 * first. Generated code keeps only these (libtcc keeps dead code). -1 out of memory */
int expr_tape_live(const expr_tape *t, const unsigned char *need, const int *level, unsigned char *live);
/* the C expression naming tape node k (a literal for constants) */
void expr_codegen_ref(const expr_tape *t, int k, const char *prefix, expr_leaf_name_fn leafname,
                      void *ud, char *buf, size_t len);

/* ---- forms: sums of integrals of scalar integrands over regions */
/* REGION_POINTS: mesh vertices (tags holds their ids), for essential conditions only */
/* REGION_INTERIOR: the facets shared by two cells (integrands restricted to a side:
 * expr_restrict) */
typedef enum { REGION_CELLS, REGION_BOUNDARY, REGION_POINTS, REGION_INTERIOR } region_kind;
#define REGION_MAXTAGS 64
typedef struct {
  region_kind kind;
  int ntag;              /* 0: every cell (REGION_CELLS), every tagged facet (REGION_BOUNDARY) */
  int tags[REGION_MAXTAGS];
  void *mesh;            /* the mesh the region belongs to (opaque here) */
} region;

typedef struct {
  region reg;
  expr *integrand;
  int order; /* quadrature order, -1 = choose from the integrand */
} form_term;

typedef struct {
  int n, cap;
  form_term *t;
} form;

form *form_new(void);
void form_free(form *f);
form *form_copy(const form *f);
/* the integrand must be resolved (expr_canon) */
int form_add_term(form *f, const region *r, expr *integrand, int order);
/* f + s*g (s = ±1 or any scalar): scales integrands */
form *form_combine(expr_ctx *c, const form *f, double s, const form *g);

/* linearization of one integrand: entries of the residual table R_i = df/d(test leaf i)
 * and of the Jacobian table J_ij = d2f/d(test leaf i)d(trial leaf j), where the trial
 * leaves are the FIELD leaves of the trial functions. Returns nonzero with a message when
 * the integrand is not linear in the test functions. */
typedef struct {
  int nres;
  expr **res_leaf; /* test leaves */
  expr **res;      /* coefficients */
  int njac;
  expr **jac_test, **jac_trial, **jac;
} coef_table;

int form_linearize(expr_ctx *c, expr *integrand, int ntest, const int *test_funcs,
                   int ntrial, const int *trial_funcs, int want_jacobian, coef_table *out);
void coef_table_free(coef_table *t);
/* the gradient table of an integrand with respect to a function that need not enter it
 * linearly: res_leaf = the leaves D^a w of function func in f, res = df/d(D^a w) (the
 * coefficients of a linear form in w's space: derivatives of functionals, adjoint
 * right-hand sides, design derivatives) */
int form_gradient_table(expr_ctx *c, expr *f, int func, coef_table *out);
/* the directional derivative d/de f(w + e dw) at e = 0: sum over the leaves D^a w of f of
 * df/d(D^a w) * D^a dw (dw a function too: a tangent or a direction), w's '-' side
 * restriction in the direction of dw's */
expr *form_directional(expr_ctx *c, expr *f, int func, int dir);
/* the first variation of a form: each integrand f replaced by sum_k d/de f(w_k + e dir_k),
 * terms that vanish dropped (a Lagrangian's variations in its test directions are the
 * equations of its stationary point) */
form *form_variation(expr_ctx *c, const form *F, int n, const int *funcs, const int *dirs);
/* f with every leaf D^a from_c replaced by D^a to_c (a test function by an adjoint), and
 * from's '-' side restriction (interior facets) by to's */
expr *form_replace_function(expr_ctx *c, expr *f, int from, int to);

#endif
