/* loperator.c — Lua bindings of assembled operators: lg.assemble(form) returns a number (a
 * form without test functions), a vector (linear in one test function: the dual vector,
 * no boundary conditions) or a matrix (bilinear in a test function and an unknown of the
 * same space, no boundary conditions), for users who need the raw operators. */
#include "largs.h"

#include <lauxlib.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#define MT_VECTOR "lugal.Vector"
#define MT_MATRIX "lugal.Matrix"

/* the space of a vector or a matrix's rows: n values, the dofs of dm on lm (on a
 * distributed mesh: the rank's owned and ghost dofs, each with its owner's value) */
typedef struct { int n; lg_mesh *lm; const dofmap *dm; } op_space;
typedef struct { op_space sp; double *v; } ud_vector;
typedef struct { lg_problem *p; op_space sp; } ud_matrix;

static ud_vector *push_vector(lua_State *L, op_space sp) {
  ud_vector *u = new_ud(L, sizeof *u, MT_VECTOR, 0, NULL);
  u->v = calloc((size_t)sp.n + 1, sizeof(double));
  if (!u->v) luaL_error(L, "lg.assemble: out of memory for %d values", sp.n);
  u->sp = sp;
  return u;
}

static int distributed(const op_space *sp) { return sp->lm && sp->lm->dist; }

/* the space's values as a discrete function (for the gathering and counting of distributed.c) */
static lg_function as_function(const op_space *sp, double *v) {
  lg_function f = {sp->lm, (dofmap *)sp->dm, sp->dm ? sp->dm->degree : 0, v, -1, 0, NULL};
  return f;
}

/* sum_i a_i b_i: a distributed space's owned dofs summed over the ranks (collective) */
static double space_dot(lua_State *L, const op_space *sp, const double *a, const double *b, const char *fn) {
  double s = 0;
  if (!distributed(sp)) {
    for (int i = 0; i < sp->n; i++) s += a[i] * b[i];
    return s;
  }
  lg_env *env = get_env(L);
  const char *own = lg_dist_owned(env, sp->lm, sp->dm, NULL);
  double v[2] = {own ? lg_dist_dot(own, sp->n, a, b) : 0, !own};
  if (lg_allreduce(v, 2, LG_SUM) || v[1]) return luaL_error(L, "%s: %s", fn, own ? "a rank failed to number its dofs" : env->err), 0;
  return v[0];
}

/* the number of values in all (a distributed space's whole count) */
static long space_size(lua_State *L, const op_space *sp, const char *fn) {
  if (!distributed(sp)) return sp->n;
  lg_function f = as_function(sp, NULL);
  lg_env *env = get_env(L);
  long n = lg_function_global_ndof(env, &f);
  if (n < 0) lgerror(L, fn, env);
  return n;
}

static int vector_gc(lua_State *L) {
  ud_vector *u = lua_touserdata(L, 1);
  free(u->v);
  u->v = NULL;
  return 0;
}

/* the values of argument idx in the space sp: a vector, a discrete function of n dofs, a
 * table (on a distributed mesh: a vector or function of the same space, or a table of the
 * whole space's values in f:values()'s order) */
static const double *values_of(lua_State *L, int idx, const op_space *sp, const char *fn, double **own) {
  *own = NULL;
  int n = sp->n;
  ud_vector *v = luaL_testudata(L, idx, MT_VECTOR);
  if (v) {
    if (distributed(sp) && v->sp.dm != sp->dm) luaL_error(L, "%s: the vector is of another space", fn);
    if (v->sp.n != n) luaL_error(L, "%s: the vector has %d values, %d expected", fn, v->sp.n, n);
    return v->v;
  }
  ud_func *f = luaL_testudata(L, idx, MT_FUNC);
  if (f) {
    if (distributed(sp) && f->f->dm != sp->dm) luaL_error(L, "%s: the discrete function is of another space", fn);
    if (f->f->dm->ndof != n) luaL_error(L, "%s: the discrete function has %d dofs, %d expected", fn, f->f->dm->ndof, n);
    return f->f->x;
  }
  if (lua_istable(L, idx) && distributed(sp)) {
    long whole = space_size(L, sp, fn), k = (long)luaL_len(L, idx);
    if (k != whole) luaL_error(L, "%s: the table has %I entries, %I expected", fn, (lua_Integer)k, (lua_Integer)whole);
    double *t = lua_newuserdatauv(L, sizeof(double) * ((size_t)whole + 1), 0);
    for (long i = 0; i < whole; i++) {
      lua_geti(L, idx, i + 1);
      int isnum;
      t[i] = lua_tonumberx(L, -1, &isnum);
      lua_pop(L, 1);
      if (!isnum) luaL_error(L, "%s: entry %I of the table must be a number", fn, (lua_Integer)(i + 1));
    }
    *own = malloc(sizeof(double) * ((size_t)n + 1));
    if (!*own) luaL_error(L, "%s: out of memory", fn);
    lg_function g = as_function(sp, *own);
    lg_env *env = get_env(L);
    int rc = lg_function_assign_whole(env, &g, t, whole);
    lua_pop(L, 1);
    if (rc) { free(*own); *own = NULL; lgerror(L, fn, env); }
    return *own;
  }
  if (lua_istable(L, idx)) {
    if (luaL_len(L, idx) != n) luaL_error(L, "%s: the table has %d entries, %d expected", fn, (int)luaL_len(L, idx), n);
    *own = malloc(sizeof(double) * ((size_t)n + 1));
    if (!*own) luaL_error(L, "%s: out of memory", fn);
    for (int i = 0; i < n; i++) {
      lua_geti(L, idx, i + 1);
      int isnum;
      (*own)[i] = lua_tonumberx(L, -1, &isnum);
      lua_pop(L, 1);
      if (!isnum) { free(*own); *own = NULL; luaL_error(L, "%s: entry %d of the table must be a number", fn, i + 1); }
    }
    return *own;
  }
  typeerror(L, fn, idx - 1, "a vector (lg.assemble), a discrete function or a table of numbers");
  return NULL;
}

static int vector_values(lua_State *L) {
  ud_vector *u = luaL_checkudata(L, 1, MT_VECTOR);
  const double *v = u->v;
  double *all = NULL;
  long n = u->sp.n;
  if (distributed(&u->sp)) { /* gathered, in f:values()'s order */
    lg_function f = as_function(&u->sp, u->v);
    lg_env *env = get_env(L);
    if (lg_function_gather(env, &f, 0, &all, &n)) return lgerror(L, "vector:values", env);
    v = all;
  }
  lua_createtable(L, (int)n, 0);
  for (long i = 0; i < n; i++) { lua_pushnumber(L, v[i]); lua_rawseti(L, -2, i + 1); }
  free(all);
  return 1;
}

static int vector_norm(lua_State *L) {
  ud_vector *u = luaL_checkudata(L, 1, MT_VECTOR);
  lua_pushnumber(L, sqrt(space_dot(L, &u->sp, u->v, u->v, "vector:norm")));
  return 1;
}

static int vector_dot(lua_State *L) {
  ud_vector *u = luaL_checkudata(L, 1, MT_VECTOR);
  double *own;
  const double *x = values_of(L, 2, &u->sp, "vector:dot", &own);
  double s = space_dot(L, &u->sp, u->v, x, "vector:dot");
  free(own);
  lua_pushnumber(L, s);
  return 1;
}

static int vector_size(lua_State *L) {
  ud_vector *u = luaL_checkudata(L, 1, MT_VECTOR);
  lua_pushinteger(L, space_size(L, &u->sp, "vector:size"));
  return 1;
}

static int matrix_gc(lua_State *L) {
  ud_matrix *u = lua_touserdata(L, 1);
  lg_problem_free(u->p);
  u->p = NULL;
  return 0;
}

static int matrix_norm(lua_State *L) {
  ud_matrix *u = luaL_checkudata(L, 1, MT_MATRIX);
  lg_env *env = get_env(L);
  double n;
  if (lg_problem_matrix_norm(env, u->p, &n)) return lgerror(L, "matrix:norm", env);
  lua_pushnumber(L, n);
  return 1;
}

static int matrix_mult(lua_State *L) {
  ud_matrix *u = luaL_checkudata(L, 1, MT_MATRIX);
  double *own;
  const double *x = values_of(L, 2, &u->sp, "matrix:mult", &own);
  ud_vector *y = push_vector(L, u->sp);
  lg_env *env = get_env(L);
  int rc = lg_problem_matrix_mult(env, u->p, x, y->v);
  free(own);
  if (rc) return lgerror(L, "matrix:mult", env);
  return 1;
}

/* x^T A y */
static int matrix_dot(lua_State *L) {
  ud_matrix *u = luaL_checkudata(L, 1, MT_MATRIX);
  double *ox, *oy;
  const double *x = values_of(L, 2, &u->sp, "matrix:dot", &ox);
  const double *y = values_of(L, 3, &u->sp, "matrix:dot", &oy);
  double *t = malloc(sizeof(double) * ((size_t)u->sp.n + 1));
  lg_env *env = get_env(L);
  int rc = !t || lg_problem_matrix_mult(env, u->p, y, t);
  double s = rc ? 0 : space_dot(L, &u->sp, x, t, "matrix:dot");
  free(t);
  free(ox);
  free(oy);
  if (rc) return t ? lgerror(L, "matrix:dot", env) : luaL_error(L, "matrix:dot: out of memory");
  lua_pushnumber(L, s);
  return 1;
}

static int matrix_values(lua_State *L) {
  ud_matrix *u = luaL_checkudata(L, 1, MT_MATRIX);
  return push_dense_matrix(L, u->p, "matrix:values");
}

static int matrix_size(lua_State *L) {
  ud_matrix *u = luaL_checkudata(L, 1, MT_MATRIX);
  lua_pushinteger(L, space_size(L, &u->sp, "matrix:size"));
  return 1;
}

static int matrix_nnz(lua_State *L) {
  ud_matrix *u = luaL_checkudata(L, 1, MT_MATRIX);
  lua_pushinteger(L, lg_problem_nnz(u->p));
  return 1;
}

/* the test functions and unknowns a form contains (distinct function ids) */
static void form_symbols(lg_env *env, const form *F, int *tests, int *nt, int *unks, int *nu) {
  *nt = *nu = 0;
  for (int i = 0; i < F->n; i++) {
    expr *e = expr_canon(env->c, F->t[i].integrand), *leaf[256];
    int m = e ? expr_collect_fields(env->c, 1, &e, -1, 256, leaf) : 0;
    for (int k = 0; k < m && k < 256; k++) {
      expr_func_info *fi = expr_func_get(env->c, leaf[k]->i0);
      if (!fi || (fi->kind != FK_TEST && fi->kind != FK_UNKNOWN)) continue;
      int *list = fi->kind == FK_TEST ? tests : unks, *n = fi->kind == FK_TEST ? nt : nu, have = 0;
      for (int j = 0; j < *n; j++) have |= list[j] == leaf[k]->i0;
      if (!have && *n < KER_MAXFIELD) list[(*n)++] = leaf[k]->i0;
    }
  }
}

static int l_assemble(lua_State *L) {
  gc_point(L, 1);
  const char *fn = "lg.assemble";
  ud_form *uf = luaL_testudata(L, 1, MT_FORM);
  if (!uf) return typeerror(L, fn, 1, "a form (lg.integral(...) + ...)");
  if (lua_gettop(L) > 1) return luaL_error(L, "%s: takes one form, got %d arguments", fn, lua_gettop(L));
  const form *F = uf->f;
  lg_env *env = get_env(L);
  if (F->n == 0) return luaL_error(L, "%s: the form is empty", fn);
  lg_mesh *lm = F->t[0].reg.mesh;
  for (int i = 1; i < F->n; i++)
    if (F->t[i].reg.mesh != lm) return luaL_error(L, "%s: the form integrates over two different meshes", fn);
  if (lg_mesh_check(env, lm)) return lgerror(L, fn, env);
  int tests[KER_MAXFIELD], unks[KER_MAXFIELD], nt, nu;
  form_symbols(env, F, tests, &nt, unks, &nu);
  if (nt > 1 || nu > 1)
    return luaL_error(L, "%s: the form has %d test functions and %d unknowns; lg.assemble takes at most one of each", fn, nt, nu);
  if (nt == 0 && nu == 1)
    return luaL_error(L, "%s: the form contains the unknown %s but no test function: a functional is a number of discrete "
                         "functions (use lg.interpolate or a solution)", fn, expr_func_get(env->c, unks[0])->name);
  if (nt == 0) {
    lg_form_kernels *K = lg_form_kernels_new(env, lm, F, -1, NULL);
    double v = 0;
    int rc = !K || lg_form_kernels_eval(env, lm, K, 0, NULL, &v);
    lg_form_kernels_free(K);
    if (rc) return lgerror(L, fn, env);
    lua_pushnumber(L, v);
    return 1;
  }
  expr_func_info *ti = expr_func_get(env->c, tests[0]);
  if (nu == 0) {
    const dofmap *dm = lg_mesh_dofmap(env, lm, ti->degree, ti->ncomp > 1 ? ti->ncomp : 1, ti->disc);
    if (!dm) return lgerror(L, fn, env);
    lg_form_kernels *K = lg_form_kernels_new(env, lm, F, tests[0], dm);
    if (!K) return lgerror(L, fn, env);
    ud_vector *v = push_vector(L, (op_space){dm->ndof, lm, dm});
    int rc = lg_form_kernels_eval(env, lm, K, 0, NULL, v->v);
    lg_form_kernels_free(K);
    if (rc) return lgerror(L, fn, env);
    return 1;
  }
  expr_func_info *ui = expr_func_get(env->c, unks[0]);
  if (ui->degree != ti->degree || ui->ncomp != ti->ncomp || ui->disc != ti->disc)
    return luaL_error(L, "%s: the test function %s and the unknown %s are of different spaces: rectangular operators are not "
                         "supported yet", fn, ti->name, ui->name);
  lg_problem_spec s = {lm, F, NULL, 1, &tests[0], &unks[0], 0, 0, NULL, 0, NULL, 0};
  lg_problem *p = lg_problem_new(env, &s);
  if (!p) return lgerror(L, fn, env);
  int deps[1] = {1};
  ud_matrix *m = new_ud(L, sizeof *m, MT_MATRIX, 1, deps);
  m->p = p;
  const dofmap *dm = lg_mesh_dofmap(env, lm, ti->degree, ti->ncomp > 1 ? ti->ncomp : 1, ti->disc);
  if (!dm) return lgerror(L, fn, env);
  m->sp = (op_space){lg_problem_size(p), lm, dm};
  return 1;
}

void lg_lua_operator_register(lua_State *L) {
  static const luaL_Reg vector_mm[] = {{"__gc", vector_gc}, {"__len", vector_size}, {NULL, NULL}};
  static const luaL_Reg vector_methods[] = {{"values", vector_values}, {"norm", vector_norm}, {"dot", vector_dot},
                                            {"size", vector_size}, {NULL, NULL}};
  new_mt(L, MT_VECTOR, vector_mm, vector_methods);
  static const luaL_Reg matrix_mm[] = {{"__gc", matrix_gc}, {NULL, NULL}};
  static const luaL_Reg matrix_methods[] = {{"norm", matrix_norm}, {"mult", matrix_mult}, {"dot", matrix_dot},
                                            {"values", matrix_values}, {"size", matrix_size}, {"nnz", matrix_nnz},
                                            {NULL, NULL}};
  new_mt(L, MT_MATRIX, matrix_mm, matrix_methods);
}

const luaL_Reg lg_operator_lib[] = {{"assemble", l_assemble}, {NULL, NULL}};
