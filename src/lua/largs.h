/* largs.h — the shared header of the Lua bindings (DESIGN.md: "one bindings file per layer
 * it binds, sharing one small header of argument checkers"): metatable names, userdata
 * types, and the helpers that check arguments and raise errors naming the function, the
 * argument and what was expected. Internal to src/lua. */
#ifndef LUGAL_LARGS_H
#define LUGAL_LARGS_H

#include "../assemble/optimize/optimize.h"
#include "../mesh/quality/quality.h"

#include <lauxlib.h>
#include <lua.h>

#define MT_MESH "lugal.Mesh"
#define MT_REGION "lugal.Region"
#define MT_BASIS "lugal.Basis"
#define MT_EXPR "lugal.Expr"
#define MT_FUNC "lugal.Function"
#define MT_FORM "lugal.Form"
#define MT_BC "lugal.BC"
#define MT_PROB "lugal.Problem"
#define MT_SERIES "lugal.Series"
#define MT_ENV "lugal.Env"
#define MT_QARRAY "lugal.QualityArray"
#define MT_FUNCTIONAL "lugal.Functional"
#define MT_REDUCED "lugal.ReducedFunctional"
#define MT_TIME "lugal.TimeProblem"

typedef struct { lg_mesh *lm; } ud_mesh;
typedef struct { region r; } ud_region;
typedef struct { int degree, ncomp, disc; } ud_basis; /* ncomp 1: scalar; disc: lg.discontinuous */
typedef struct { expr *e; } ud_expr;
typedef struct { lg_function *f; } ud_func;
typedef struct { form *f; } ud_form;
typedef struct { lg_problem *p; int nfield; int nonlinear; } ud_prob;
/* a time-dependent problem (ltime.c): its step problem, owned; output every `every` steps
 * into the series, a progress line as often with monitor */
typedef struct {
  lg_time *T;
  lg_problem *p;
  int nfield, every, monitor;
  char *output;
  lua_State *hook_L;   /* before_step's own thread (kept in the userdata's uservalue), or NULL */
  int hook_ref;        /* before_step in the registry */
  double t1;           /* an adaptive march's end */
  double *sizes;       /* the last adaptive march's step sizes (nsizes), or NULL */
  int nsizes;
} ud_time;
/* format: VTU_*; pieces: 0 for .vtu steps, else .pvtu steps of so many pieces */
typedef struct { char *path; int n, cap; double *t; char **files; int format, pieces; } ud_series;
typedef struct { lg_env *env; int owns_petsc; } ud_env;
/* a quality array: v (mesh_big_alloc) per cell; on a distributed mesh the owned cells' only,
 * gid their global numbers and loc their local ones (malloc'ed; NULL on a whole mesh), of
 * nglobal cells in all */
typedef struct { int n; int measure; double *v; int *gid, *loc; long nglobal; } ud_qarray;

/* Lua's garbage collection in a run of several ranks. Finalizers destroy PETSc objects,
 * which is collective (a parallel matrix, MUMPS's factors), and Lua's automatic collector
 * runs when a rank's own allocations say so, which differ between ranks (a distributed
 * mesh's local sizes): rank 1 destroying a factor while rank 0 waits in a reduction hangs
 * both. So the automatic collector is stopped there (luaopen_lugal) and full collections run
 * at points every rank passes in the same order: always where `always` is set (problems
 * created and solved, reduced functionals, minimizations, operators, meshes), every 32nd
 * pass elsewhere (integrals, interpolations, functions). Nothing in a serial run. */
void gc_point(lua_State *L, int always);

/* the environment of this Lua state (symbolic context, JIT) */
lg_env *get_env(lua_State *L);
int typeerror(lua_State *L, const char *fn, int arg, const char *expected);
int lgerror(lua_State *L, const char *fn, lg_env *env);
int exprerror(lua_State *L, const char *fn);
void *new_ud(lua_State *L, size_t size, const char *mt, int ndeps, const int *deps);
void push_expr(lua_State *L, expr *e, int ndeps, const int *deps, const char *fn);
expr *to_expr_opt(lua_State *L, int idx, int *ok);
/* the expression of a function symbol (unknown, test, discrete function): its leaf, or the
 * list of its components for a vector; and back: the function id of such an expression, or -1 */
expr *symbol_expr(lg_env *env, int fid);
int symbol_func(lg_env *env, expr *e);
/* an expression argument, resolved (check_expr) or possibly pending (check_expr_raw, for
 * the + - * that build sums term by term) */
expr *check_expr(lua_State *L, int idx, const char *fn);
expr *check_expr_raw(lua_State *L, int idx, const char *fn);
/* the resolved expression of a userdata */
expr *expr_of(lua_State *L, ud_expr *u);
ud_mesh *check_mesh(lua_State *L, int idx, const char *fn);
void push_mesh(lua_State *L, mesh *m);
/* a rank's part of a distributed mesh, made on that rank (lg_mesh_generate_part) */
void push_mesh_part(lua_State *L, lg_mesh *lm);
/* the info table of a solve or a minimization (problem:solve, lg.minimize: returned after
 * the results), marked so that it is never taken for an options table */
void push_info_table(lua_State *L, int nrec);
int is_info_table(lua_State *L, int idx);
/* the string at idx (what: "argument 2", "field name", for the message), which must hold no
 * zero byte: C strings end there ("p\0x" and "p\0y" were written as one field "p") */
const char *check_cstring(lua_State *L, int idx, const char *fn, const char *what);
/* the same, or def where the argument is absent or nil */
const char *opt_cstring(lua_State *L, int idx, const char *def, const char *fn, const char *what);
double opt_num(lua_State *L, int t, const char *key, double def, const char *fn);
/* a tolerance option: a finite number >= 0, or absent (def) */
double opt_tolerance(lua_State *L, int t, const char *key, double def, const char *fn);
/* integers checked as the C int they become (lo..hi within the int range): a float with an
 * integral value is accepted, 2.5 is "a fraction", 2^32 + 2 "too large" */
lua_Integer check_int_value(lua_State *L, int idx, lua_Integer lo, lua_Integer hi, const char *fn, const char *what);
int check_int_arg(lua_State *L, int arg, lua_Integer lo, lua_Integer hi, const char *fn);
int opt_int(lua_State *L, int t, const char *key, int def, const char *fn);
const char *opt_str(lua_State *L, int t, const char *key, const char *def, const char *fn);
void check_keys(lua_State *L, int t, const char *fn, const char *const *allowed);
int finish_report(lua_State *L, const char *text, int quiet);
/* lrepair.c: the option 'reference' of options table t (the same mesh as lm's in another
 * configuration, or NULL), and the repair methods lmesh.c registers on meshes */
lg_mesh *opt_reference(lua_State *L, int t, const lg_mesh *lm, const char *fn);
int lmesh_untangle(lua_State *L);
int lmesh_smooth(lua_State *L);
int lmesh_move(lua_State *L);
int lmesh_displace(lua_State *L);
void set_num(lua_State *L, const char *k, double v);
void set_int(lua_State *L, const char *k, lua_Integer v);
ud_func *check_func(lua_State *L, int idx, const char *fn);
void push_function(lua_State *L, lg_function *f, int mesh_idx);
/* push n new functions (the caller's to own) anchored to the mesh among the dependencies of
 * the userdata at owner */
void push_functions_of(lua_State *L, int owner, lg_function **f, int n);
/* problems (lproblem.c): the functions of a kind listed under key of the table at t (one or
 * a table of them; returns how many), the essential conditions at idx (nil, one or a table,
 * combined into *owned when several), and the problem userdata */
int check_symbols(lua_State *L, int t, const char *key, func_kind kind, int *ids, const char *fn);
const form *check_bcs(lua_State *L, int idx, const char *fn, form **owned);
void push_problem(lua_State *L, lg_problem *p, int nfield, int nonlinear, int ndeps, const int *deps);
/* a problem from the options table at 1 (mesh, eqn, bc, test, unknown, symmetric, prefix,
 * nullspace; keys: every key allowed): the values it reads at deps (*ndeps of them) and its
 * number of unknowns; raises a Lua error naming fn on bad options */
lg_problem *problem_from_table(lua_State *L, const char *fn, int nonlinear, const char *const *keys, int *nfield, int *deps,
                               int *ndeps);
/* the assembled matrix of p as a Lua table of rows (small problems: n <= 2000) */
int push_dense_matrix(lua_State *L, lg_problem *p, const char *fn);
void new_mt(lua_State *L, const char *name, const luaL_Reg *mm, const luaL_Reg *methods);
/* luaL_setfuncs(lib) into the table on top, each function of the module's arity table
 * ("lg", "lg.mesh" or a metatable name) checking that it got no extra arguments */
void set_funcs_checked(lua_State *L, const luaL_Reg *lib, const char *table);

/* the bindings of each layer: metatables (register) and library functions */
extern const luaL_Reg lg_arith_mm[]; /* + - * / ^ unary- for expressions and functions */
void lg_lua_expr_register(lua_State *L);
extern const luaL_Reg lg_expr_lib[];
void lg_lua_mesh_register(lua_State *L);
extern const luaL_Reg lg_mesh_lib[];     /* lg.mesh.* */
extern const luaL_Reg lg_output_lib[];   /* lg.series */
void lg_lua_problem_register(lua_State *L);
extern const luaL_Reg lg_problem_lib[];
void lg_lua_opt_register(lua_State *L);
extern const luaL_Reg lg_opt_lib[];
/* ltime.c: time-dependent problems; time_of: the problem at idx, or NULL */
void lg_lua_time_register(lua_State *L);
extern const luaL_Reg lg_time_lib[];
lg_time *time_of(lua_State *L, int idx);
/* lopt.c: step:sensitivity (a method of time-dependent problems, made of a reduced
 * functional's tangent march) */
int lg_lua_time_sensitivity(lua_State *L);
void lg_lua_operator_register(lua_State *L);
extern const luaL_Reg lg_parallel_lib[]; /* lg.rank, lg.size, lg.allreduce */
/* lparallel.c: the function on the top of the stack replaced by one that first checks, in a
 * parallel run, that every rank makes this collective call (where it is one: the table
 * collectives there); nothing for a function that is not collective */
void lg_lua_collective_wrap(lua_State *L, const char *table, const char *name);
/* the end of a script as a collective call: a rank still waiting in a collective call that
 * another rank never made gets the message instead of a hang (lua_CFunction; the runner's) */
int lg_lua_end_check(lua_State *L);
void lg_lua_parallel_register(lua_State *L); /* print on rank 0 under mpiexec (lg on top) */
extern const luaL_Reg lg_operator_lib[]; /* lg.assemble */     /* lg.control, lg.functional, lg.reduced_functional, lg.taylor_test */

#endif
