/* lmodule.c — the `lugal` Lua module: userdata and metamethods over the C API. Thin by
 * design (DESIGN.md): argument checking, conversion and error messages that name the
 * function, the argument and what was expected; no numerical logic lives here.
 *
 * Lifetimes: expressions are nodes of the environment's context; an expression, form or
 * problem userdata keeps the discrete functions and meshes it refers to alive through a
 * dependency table in its user value. */
#include "lmodule.h"

#include "../assemble/assemble.h"
#include "../config.h"
#include "../mesh/quality.h"
#include "../mesh/untangle.h"

#include <lauxlib.h>
#include <lua.h>
#include <math.h>
#include <petscsys.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

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

typedef struct { lg_mesh *lm; } ud_mesh;
typedef struct { region r; } ud_region;
typedef struct { int degree; } ud_basis;
typedef struct { expr *e; } ud_expr;
typedef struct { lg_function *f; } ud_func;
typedef struct { form *f; } ud_form;
typedef struct { lg_problem *p; int nfield; int nonlinear; } ud_prob;
typedef struct { char path[512]; int n, cap; double *t; char **files; } ud_series;
typedef struct { lg_env *env; int owns_petsc; } ud_env;
typedef struct { int n; int measure; double *v; } ud_qarray; /* v from mesh_big_alloc */

static lg_env *get_env(lua_State *L) {
  lua_getfield(L, LUA_REGISTRYINDEX, "lugal.env");
  ud_env *u = lua_touserdata(L, -1);
  lua_pop(L, 1);
  if (!u || !u->env) luaL_error(L, "lugal: the module is not initialized");
  return u->env;
}

static int env_gc(lua_State *L) {
  ud_env *u = luaL_checkudata(L, 1, MT_ENV);
  lg_env_free(u->env);
  u->env = NULL;
  /* the module loaded into a plain Lua interpreter started PETSc; the environment is
   * finalized after every other lugal object, so PETSc can stop now */
  if (u->owns_petsc) lg_petsc_finalize();
  u->owns_petsc = 0;
  return 0;
}

/* ---------------------------------------------------------------- errors */

static int typeerror(lua_State *L, const char *fn, int arg, const char *expected) {
  const char *got = luaL_typename(L, arg);
  if (lua_type(L, arg) == LUA_TUSERDATA && luaL_getmetafield(L, arg, "__name") == LUA_TSTRING) {
    got = lua_tostring(L, -1);
    if (!strncmp(got, "lugal.", 6)) got += 6;
  }
  return luaL_error(L, "%s: argument %d must be %s, got %s", fn, arg, expected, got);
}

static int lgerror(lua_State *L, const char *fn, lg_env *env) {
  return luaL_error(L, "%s: %s", fn, env->err);
}

static int exprerror(lua_State *L, const char *fn) {
  return luaL_error(L, "%s: %s", fn, expr_error(get_env(L)->c));
}

/* ---------------------------------------------------------------- dependencies */

/* merge the dependency table of the value at idx (or the value itself when it is a
 * discrete function or mesh) into the table at the top of the stack */
static void deps_merge(lua_State *L, int idx) {
  idx = lua_absindex(L, idx);
  if (luaL_testudata(L, idx, MT_FUNC) || luaL_testudata(L, idx, MT_MESH)) {
    lua_pushvalue(L, idx);
    lua_pushboolean(L, 1);
    lua_rawset(L, -3);
  }
  if (lua_type(L, idx) != LUA_TUSERDATA) return;
  if (lua_getiuservalue(L, idx, 1) == LUA_TTABLE) {
    lua_pushnil(L);
    while (lua_next(L, -2)) {
      lua_pushvalue(L, -2);
      lua_insert(L, -2);
      lua_rawset(L, -5);
    }
  }
  lua_pop(L, 1);
}

/* a new userdata with one user value: a dependency table merged from the given slots */
static void *new_ud(lua_State *L, size_t size, const char *mt, int ndeps, const int *deps) {
  int abs[8];
  for (int i = 0; i < ndeps && i < 8; i++) abs[i] = lua_absindex(L, deps[i]);
  void *u = lua_newuserdatauv(L, size, 1);
  memset(u, 0, size);
  luaL_setmetatable(L, mt);
  if (ndeps) {
    lua_newtable(L);
    for (int i = 0; i < ndeps && i < 8; i++) deps_merge(L, abs[i]);
    lua_setiuservalue(L, -2, 1);
  }
  return u;
}

/* ---------------------------------------------------------------- expressions */

static void push_expr(lua_State *L, expr *e, int ndeps, const int *deps, const char *fn) {
  if (!e) exprerror(L, fn);
  ud_expr *u = new_ud(L, sizeof *u, MT_EXPR, ndeps, deps);
  u->e = e;
}

static expr *to_expr_opt(lua_State *L, int idx, int *ok);

static expr *table_to_list(lua_State *L, int idx, int *ok) {
  lg_env *env = get_env(L);
  int n = (int)luaL_len(L, idx);
  if (n < 1 || n > 64) { *ok = 0; return NULL; }
  expr *items[64];
  for (int i = 1; i <= n; i++) {
    lua_geti(L, idx, i);
    items[i - 1] = to_expr_opt(L, -1, ok);
    lua_pop(L, 1);
    if (!*ok) return NULL;
  }
  return expr_list(env->c, n, items);
}

/* number, Expr, Function or table of those; *ok = 0 when the type does not fit */
static expr *to_expr_opt(lua_State *L, int idx, int *ok) {
  lg_env *env = get_env(L);
  *ok = 1;
  if (lua_type(L, idx) == LUA_TNUMBER) return expr_num(env->c, lua_tonumber(L, idx));
  ud_expr *ue = luaL_testudata(L, idx, MT_EXPR);
  if (ue) return ue->e;
  ud_func *uf = luaL_testudata(L, idx, MT_FUNC);
  if (uf) {
    unsigned char z[3] = {0, 0, 0};
    return expr_field(env->c, uf->f->fid, 0, z);
  }
  if (lua_type(L, idx) == LUA_TTABLE) return table_to_list(L, lua_absindex(L, idx), ok);
  *ok = 0;
  return NULL;
}

static expr *check_expr(lua_State *L, int idx, const char *fn) {
  int ok;
  expr *e = to_expr_opt(L, idx, &ok);
  if (!ok) typeerror(L, fn, idx, "an expression, a number or a discrete function");
  if (!e) exprerror(L, fn);
  return e;
}


typedef expr *(*binop_fn)(expr_ctx *, expr *, expr *);

static int arith(lua_State *L, binop_fn op, const char *name) {
  lg_env *env = get_env(L);
  expr *a = check_expr(L, 1, name), *b = check_expr(L, 2, name);
  int deps[2] = {1, 2};
  push_expr(L, op(env->c, a, b), 2, deps, name);
  return 1;
}

static int form_arith(lua_State *L, double s, const char *name);

static int m_add(lua_State *L) {
  if (luaL_testudata(L, 1, MT_FORM) || luaL_testudata(L, 2, MT_FORM) || luaL_testudata(L, 1, MT_BC) ||
      luaL_testudata(L, 2, MT_BC))
    return form_arith(L, 1, "+");
  return arith(L, expr_add, "operator +");
}
static int m_sub(lua_State *L) {
  if (luaL_testudata(L, 1, MT_FORM) || luaL_testudata(L, 2, MT_FORM)) return form_arith(L, -1, "-");
  return arith(L, expr_sub, "operator -");
}
static int m_mul(lua_State *L);
static int m_div(lua_State *L) { return arith(L, expr_div, "operator /"); }
static int m_pow(lua_State *L) { return arith(L, expr_pow, "operator ^"); }
static int m_unm(lua_State *L) {
  lg_env *env = get_env(L);
  expr *a = check_expr(L, 1, "unary -");
  int deps[1] = {1};
  push_expr(L, expr_neg(env->c, a), 1, deps, "unary -");
  return 1;
}

static int expr_tostring(lua_State *L) {
  lg_env *env = get_env(L);
  int ok;
  expr *e = to_expr_opt(L, 1, &ok);
  char buf[2048];
  expr_print(env->c, e, buf, sizeof buf);
  lua_pushstring(L, buf);
  return 1;
}

static int expr_len(lua_State *L) {
  ud_expr *u = luaL_checkudata(L, 1, MT_EXPR);
  lua_pushinteger(L, expr_shape(u->e, NULL));
  return 1;
}

static int param_set(lua_State *L) {
  ud_expr *u = luaL_checkudata(L, 1, MT_EXPR);
  if (u->e->kind != E_PARAM) return luaL_error(L, "set: only parameters (lg.parameter) can be set");
  double v = luaL_checknumber(L, 2);
  expr_param_values(get_env(L)->c)[u->e->i0] = v;
  return 0;
}

static int param_value(lua_State *L) {
  ud_expr *u = luaL_checkudata(L, 1, MT_EXPR);
  if (u->e->kind == E_CONST) { lua_pushnumber(L, u->e->value); return 1; }
  if (u->e->kind != E_PARAM) return luaL_error(L, "value: only parameters and constants have a value");
  lua_pushnumber(L, expr_param_values(get_env(L)->c)[u->e->i0]);
  return 1;
}

static int expr_index_mm(lua_State *L) {
  ud_expr *u = luaL_checkudata(L, 1, MT_EXPR);
  if (lua_type(L, 2) == LUA_TSTRING) {
    const char *k = lua_tostring(L, 2);
    if (!strcmp(k, "set")) { lua_pushcfunction(L, param_set); return 1; }
    if (!strcmp(k, "value")) { lua_pushcfunction(L, param_value); return 1; }
    return luaL_error(L, "expressions have no field '%s'", k);
  }
  lua_Integer i = luaL_checkinteger(L, 2);
  if (u->e->kind != E_LIST) return luaL_error(L, "cannot index a scalar expression");
  if (i < 1 || i > u->e->n) return luaL_error(L, "index %d out of range 1..%d", (int)i, u->e->n);
  int deps[1] = {1};
  push_expr(L, u->e->ch[i - 1], 1, deps, "index");
  return 1;
}

/* ---------------------------------------------------------------- forms */

static form *check_form(lua_State *L, int idx, const char *fn) {
  ud_form *u = luaL_testudata(L, idx, MT_FORM);
  if (!u) u = luaL_testudata(L, idx, MT_BC);
  if (!u) typeerror(L, fn, idx, "a form (lg.integral)");
  return u->f;
}

static int form_arith(lua_State *L, double s, const char *name) {
  lg_env *env = get_env(L);
  int isbc = luaL_testudata(L, 1, MT_BC) != NULL;
  if (isbc != (luaL_testudata(L, 2, MT_BC) != NULL))
    return luaL_error(L, "operator %s: cannot combine an equation with a boundary condition; pass bc= separately", name);
  const char *mt = isbc ? MT_BC : MT_FORM;
  if (!luaL_testudata(L, 1, mt)) typeerror(L, "operator +", 1, "a form");
  if (!luaL_testudata(L, 2, mt)) typeerror(L, "operator +", 2, "a form");
  form *a = check_form(L, 1, name), *b = check_form(L, 2, name);
  form *r = form_combine(env->c, a, s, b);
  if (!r) return exprerror(L, name);
  int deps[2] = {1, 2};
  ud_form *u = new_ud(L, sizeof *u, mt, 2, deps);
  u->f = r;
  return 1;
}

static int form_scale(lua_State *L, int fidx, int nidx) {
  lg_env *env = get_env(L);
  form *a = check_form(L, fidx, "operator *");
  double s = luaL_checknumber(L, nidx);
  form *r = form_combine(env->c, &(form){0, 0, NULL}, s, a);
  if (!r) return exprerror(L, "operator *");
  int deps[1] = {fidx};
  ud_form *u = new_ud(L, sizeof *u, luaL_testudata(L, fidx, MT_BC) ? MT_BC : MT_FORM, 1, deps);
  u->f = r;
  return 1;
}

static int m_mul(lua_State *L) {
  if (luaL_testudata(L, 1, MT_FORM)) return form_scale(L, 1, 2);
  if (luaL_testudata(L, 2, MT_FORM)) return form_scale(L, 2, 1);
  return arith(L, expr_mul, "operator *");
}

static int form_unm(lua_State *L) {
  lua_pushnumber(L, -1);
  return form_scale(L, 1, 2);
}

static int form_gc(lua_State *L) {
  ud_form *u = lua_touserdata(L, 1);
  form_free(u->f);
  u->f = NULL;
  return 0;
}

static int form_tostring(lua_State *L) {
  lg_env *env = get_env(L);
  form *f = check_form(L, 1, "tostring");
  luaL_Buffer b;
  luaL_buffinit(L, &b);
  for (int i = 0; i < f->n; i++) {
    char buf[1024];
    expr_print(env->c, f->t[i].integrand, buf, sizeof buf);
    if (i) luaL_addstring(&b, " + ");
    luaL_addstring(&b, f->t[i].reg.kind == REGION_CELLS ? "∫_cells " : "∫_boundary ");
    luaL_addstring(&b, buf);
  }
  luaL_pushresult(&b);
  return 1;
}

/* ---------------------------------------------------------------- meshes */

static ud_mesh *check_mesh(lua_State *L, int idx, const char *fn) {
  ud_mesh *u = luaL_testudata(L, idx, MT_MESH);
  if (!u) typeerror(L, fn, idx, "a mesh");
  return u;
}

static void push_mesh(lua_State *L, mesh *m) {
  lg_env *env = get_env(L);
  ud_mesh *u = lua_newuserdatauv(L, sizeof *u, 1);
  u->lm = lg_mesh_wrap(m);
  if (!u->lm) { mesh_free(m); luaL_error(L, "out of memory"); }
  luaL_setmetatable(L, MT_MESH);
  expr_set_dim(env->c, m->dim);
}

static int mesh_gc(lua_State *L) {
  ud_mesh *u = lua_touserdata(L, 1);
  lg_mesh_free(u->lm);
  u->lm = NULL;
  return 0;
}

static double opt_num(lua_State *L, int t, const char *key, double def, const char *fn) {
  double v = def;
  int ty = lua_getfield(L, t, key);
  if (ty == LUA_TNUMBER) v = lua_tonumber(L, -1);
  else if (ty != LUA_TNIL) luaL_error(L, "%s: option '%s' must be a number, got %s", fn, key, luaL_typename(L, -1));
  lua_pop(L, 1);
  return v;
}

static int opt_int(lua_State *L, int t, const char *key, int def, const char *fn) {
  int v = def;
  int ty = lua_getfield(L, t, key);
  if (ty == LUA_TNUMBER && lua_isinteger(L, -1)) v = (int)lua_tointeger(L, -1);
  else if (ty != LUA_TNIL) luaL_error(L, "%s: option '%s' must be an integer, got %s", fn, key, ty == LUA_TNUMBER ? "a fraction" : luaL_typename(L, -1));
  lua_pop(L, 1);
  return v;
}

static const char *opt_str(lua_State *L, int t, const char *key, const char *def, const char *fn) {
  const char *v = def;
  int ty = lua_getfield(L, t, key);
  if (ty == LUA_TSTRING) v = lua_tostring(L, -1);
  else if (ty != LUA_TNIL) luaL_error(L, "%s: option '%s' must be a string, got %s", fn, key, luaL_typename(L, -1));
  lua_pop(L, 1);
  return v; /* valid while the table holds it */
}

static void check_keys(lua_State *L, int t, const char *fn, const char *const *allowed) {
  lua_pushnil(L);
  while (lua_next(L, t)) {
    lua_pop(L, 1);
    if (lua_type(L, -1) != LUA_TSTRING) luaL_error(L, "%s: options must be named (key = value)", fn);
    const char *k = lua_tostring(L, -1);
    int ok = 0;
    for (int i = 0; allowed[i]; i++) ok |= !strcmp(allowed[i], k);
    if (!ok) {
      char list[512] = "";
      size_t used = 0;
      for (int i = 0; allowed[i] && used < sizeof list; i++)
        used += (size_t)snprintf(list + used, sizeof list - used, "%s%s", i ? ", " : "", allowed[i]);
      luaL_error(L, "%s: unknown option '%s' (options: %s)", fn, k, list);
    }
  }
}

static int l_rectangle(lua_State *L) {
  const char *fn = "lg.mesh.rectangle";
  if (lua_isnoneornil(L, 1)) lua_newtable(L);
  if (!lua_istable(L, 1)) typeerror(L, fn, 1, "a table of options");
  static const char *const keys[] = {"nx", "ny", "x0", "x1", "y0", "y1", "cell", "diagonal", NULL};
  check_keys(L, 1, fn, keys);
  mesh_box_opts o;
  memset(&o, 0, sizeof o);
  o.nx = opt_int(L, 1, "nx", 8, fn);
  o.ny = opt_int(L, 1, "ny", o.nx, fn);
  o.x0 = opt_num(L, 1, "x0", 0, fn);
  o.x1 = opt_num(L, 1, "x1", 1, fn);
  o.y0 = opt_num(L, 1, "y0", 0, fn);
  o.y1 = opt_num(L, 1, "y1", 1, fn);
  const char *cell = opt_str(L, 1, "cell", "triangle", fn);
  if (!strcmp(cell, "triangle")) o.type = CELL_TRIANGLE;
  else if (!strcmp(cell, "quadrilateral")) o.type = CELL_QUADRILATERAL;
  else return luaL_error(L, "%s: option 'cell' must be \"triangle\" or \"quadrilateral\", got \"%s\"", fn, cell);
  const char *dg = opt_str(L, 1, "diagonal", "right", fn);
  if (!strcmp(dg, "right")) o.diagonal = 0;
  else if (!strcmp(dg, "left")) o.diagonal = 1;
  else if (!strcmp(dg, "crossed")) o.diagonal = 2;
  else return luaL_error(L, "%s: option 'diagonal' must be \"right\", \"left\" or \"crossed\", got \"%s\"", fn, dg);
  char err[MESH_ERRLEN];
  mesh *m = mesh_rectangle(&o, err);
  if (!m) return luaL_error(L, "%s: %s", fn, err);
  push_mesh(L, m);
  return 1;
}

static int l_box(lua_State *L) {
  const char *fn = "lg.mesh.box";
  if (lua_isnoneornil(L, 1)) lua_newtable(L);
  if (!lua_istable(L, 1)) typeerror(L, fn, 1, "a table of options");
  static const char *const keys[] = {"nx", "ny", "nz", "x0", "x1", "y0", "y1", "z0", "z1", "cell", NULL};
  check_keys(L, 1, fn, keys);
  mesh_box_opts o;
  memset(&o, 0, sizeof o);
  o.nx = opt_int(L, 1, "nx", 4, fn);
  o.ny = opt_int(L, 1, "ny", o.nx, fn);
  o.nz = opt_int(L, 1, "nz", o.nx, fn);
  o.x0 = opt_num(L, 1, "x0", 0, fn);
  o.x1 = opt_num(L, 1, "x1", 1, fn);
  o.y0 = opt_num(L, 1, "y0", 0, fn);
  o.y1 = opt_num(L, 1, "y1", 1, fn);
  o.z0 = opt_num(L, 1, "z0", 0, fn);
  o.z1 = opt_num(L, 1, "z1", 1, fn);
  const char *cell = opt_str(L, 1, "cell", "tetrahedron", fn);
  if (!strcmp(cell, "tetrahedron")) o.type = CELL_TETRAHEDRON;
  else if (!strcmp(cell, "hexahedron")) o.type = CELL_HEXAHEDRON;
  else return luaL_error(L, "%s: option 'cell' must be \"tetrahedron\" or \"hexahedron\", got \"%s\"", fn, cell);
  char err[MESH_ERRLEN];
  mesh *m = mesh_box(&o, err);
  if (!m) return luaL_error(L, "%s: %s", fn, err);
  push_mesh(L, m);
  return 1;
}

static int l_read(lua_State *L) {
  const char *path = luaL_checkstring(L, 1);
  char err[MESH_ERRLEN];
  mesh *m = mesh_read_gmsh(path, err);
  if (!m) return luaL_error(L, "lg.mesh.read: %s", err);
  push_mesh(L, m);
  return 1;
}

/* lg.mesh.new{cell=, vertices={{x,y},...}, cells={{1,2,3},...}, boundary={name={{a,b},...}}} */
static int l_mesh_new(lua_State *L) {
  const char *fn = "lg.mesh.new";
  if (!lua_istable(L, 1)) typeerror(L, fn, 1, "a table {cell=, vertices=, cells=, boundary=}");
  static const char *const keys[] = {"cell", "vertices", "cells", "boundary", NULL};
  check_keys(L, 1, fn, keys);
  const char *cell = opt_str(L, 1, "cell", "triangle", fn);
  cell_type t;
  if (!strcmp(cell, "triangle")) t = CELL_TRIANGLE;
  else if (!strcmp(cell, "quadrilateral")) t = CELL_QUADRILATERAL;
  else if (!strcmp(cell, "tetrahedron")) t = CELL_TETRAHEDRON;
  else if (!strcmp(cell, "hexahedron")) t = CELL_HEXAHEDRON;
  else return luaL_error(L, "%s: 'cell' must be triangle, quadrilateral, tetrahedron or hexahedron, got \"%s\"", fn, cell);
  int dim = cell_dim(t), nvc = cell_nverts(t);
  if (lua_getfield(L, 1, "vertices") != LUA_TTABLE) return luaL_error(L, "%s: 'vertices' must be a table of coordinate tables", fn);
  int nv = (int)luaL_len(L, -1);
  if (lua_getfield(L, 1, "cells") != LUA_TTABLE) return luaL_error(L, "%s: 'cells' must be a table of vertex-index tables", fn);
  int nc = (int)luaL_len(L, -1);
  if (nv < 1 || nc < 1) return luaL_error(L, "%s: need at least one vertex and one cell", fn);
  double *x = malloc(sizeof(double) * (size_t)nv * dim);
  int *c = malloc(sizeof(int) * (size_t)nc * nvc);
  if (!x || !c) { free(x); free(c); return luaL_error(L, "%s: out of memory", fn); }
  for (int i = 1; i <= nv; i++) {
    if (lua_geti(L, -2, i) != LUA_TTABLE || luaL_len(L, -1) != dim) {
      free(x); free(c);
      return luaL_error(L, "%s: vertex %d must be a table of %d numbers", fn, i, dim);
    }
    for (int d = 1; d <= dim; d++) {
      lua_geti(L, -1, d);
      if (!lua_isnumber(L, -1)) { free(x); free(c); return luaL_error(L, "%s: vertex %d coordinate %d is not a number", fn, i, d); }
      x[(size_t)(i - 1) * dim + d - 1] = lua_tonumber(L, -1);
      lua_pop(L, 1);
    }
    lua_pop(L, 1);
  }
  for (int i = 1; i <= nc; i++) {
    if (lua_geti(L, -1, i) != LUA_TTABLE || luaL_len(L, -1) != nvc) {
      free(x); free(c);
      return luaL_error(L, "%s: cell %d must be a table of %d vertex indices", fn, i, nvc);
    }
    for (int k = 1; k <= nvc; k++) {
      lua_geti(L, -1, k);
      if (!lua_isinteger(L, -1)) { free(x); free(c); return luaL_error(L, "%s: cell %d entry %d is not an integer", fn, i, k); }
      c[(size_t)(i - 1) * nvc + k - 1] = (int)lua_tointeger(L, -1) - 1;
      lua_pop(L, 1);
    }
    lua_pop(L, 1);
  }
  lua_pop(L, 2);
  char err[MESH_ERRLEN];
  mesh *m = mesh_create(t, nv, x, nc, c, err);
  free(x);
  free(c);
  if (!m) return luaL_error(L, "%s: %s", fn, err);
  push_mesh(L, m);
  int midx = lua_gettop(L);
  if (lua_getfield(L, 1, "boundary") == LUA_TTABLE) {
    int tag = 1;
    lua_pushnil(L);
    while (lua_next(L, -2)) {
      if (lua_type(L, -2) != LUA_TSTRING || lua_type(L, -1) != LUA_TTABLE)
        return luaL_error(L, "%s: 'boundary' maps names to tables of facets", fn);
      const char *name = lua_tostring(L, -2);
      int n = (int)luaL_len(L, -1), nvf = m->nvf;
      int *fv = malloc(sizeof(int) * (size_t)(n + 1) * nvf);
      if (!fv) return luaL_error(L, "%s: out of memory", fn);
      for (int i = 1; i <= n; i++) {
        if (lua_geti(L, -1, i) != LUA_TTABLE || luaL_len(L, -1) != nvf) {
          free(fv);
          return luaL_error(L, "%s: boundary '%s' facet %d must list %d vertices", fn, name, i, nvf);
        }
        for (int k = 1; k <= nvf; k++) {
          lua_geti(L, -1, k);
          fv[(i - 1) * nvf + k - 1] = (int)lua_tointeger(L, -1) - 1;
          lua_pop(L, 1);
        }
        lua_pop(L, 1);
      }
      int rc = mesh_add_boundary_facets(m, n, fv, tag++, name);
      free(fv);
      if (rc) return luaL_error(L, "%s: %s", fn, m->err);
      lua_pop(L, 1);
    }
    if (mesh_build_boundary_cells(m)) return luaL_error(L, "%s: %s", fn, m->err);
  }
  lua_pop(L, 1);
  lua_pushvalue(L, midx);
  return 1;
}

static int region_new(lua_State *L, region_kind kind, const char *fn) {
  ud_mesh *um = check_mesh(L, 1, fn);
  mesh *m = um->lm->m;
  int n = lua_gettop(L) - 1;
  region r;
  memset(&r, 0, sizeof r);
  r.kind = kind;
  r.mesh = um->lm;
  if (n > REGION_MAXTAGS) return luaL_error(L, "%s: at most %d names", fn, REGION_MAXTAGS);
  if (kind == REGION_BOUNDARY && n == 0) {
    /* every tagged boundary facet */
    for (int i = 0; i < m->nbname && r.ntag < REGION_MAXTAGS; i++) r.tags[r.ntag++] = m->bnames[i].tag;
  }
  for (int i = 0; i < n; i++) {
    int arg = i + 2;
    int tag;
    if (lua_isinteger(L, arg)) tag = (int)lua_tointeger(L, arg);
    else if (lua_type(L, arg) == LUA_TSTRING) {
      const char *name = lua_tostring(L, arg);
      tag = kind == REGION_BOUNDARY ? mesh_boundary_tag(m, name) : mesh_region_tag(m, name);
      if (tag < 0) {
        char list[512];
        if (kind == REGION_BOUNDARY) mesh_boundary_names(m, list, sizeof list);
        else {
          size_t used = 0;
          list[0] = 0;
          for (int k = 0; k < m->ncname; k++) used += (size_t)snprintf(list + used, sizeof list - used, "%s\"%s\"", k ? ", " : "", m->cnames[k].name);
          if (!m->ncname) snprintf(list, sizeof list, "(none)");
        }
        return luaL_error(L, "%s: unknown %s name \"%s\" (this mesh has: %s)", fn,
                          kind == REGION_BOUNDARY ? "boundary" : "region", name, list);
      }
    } else return typeerror(L, fn, arg, "a boundary name or tag");
    r.tags[r.ntag++] = tag;
  }
  int deps[1] = {1};
  ud_region *u = new_ud(L, sizeof *u, MT_REGION, 1, deps);
  u->r = r;
  return 1;
}

static int mesh_cells(lua_State *L) { return region_new(L, REGION_CELLS, "mesh:cells"); }
static int mesh_boundary(lua_State *L) { return region_new(L, REGION_BOUNDARY, "mesh:boundary"); }

static int mesh_info(lua_State *L) {
  ud_mesh *u = check_mesh(L, 1, "mesh:info");
  mesh *m = u->lm->m;
  lua_createtable(L, 0, 6);
  lua_pushinteger(L, m->nvert); lua_setfield(L, -2, "vertices");
  lua_pushinteger(L, m->ncell); lua_setfield(L, -2, "cells");
  lua_pushinteger(L, m->dim); lua_setfield(L, -2, "dim");
  lua_pushstring(L, cell_name(m->type)); lua_setfield(L, -2, "cell");
  lua_pushinteger(L, m->nbf); lua_setfield(L, -2, "boundary_facets");
  lua_newtable(L);
  for (int i = 0; i < m->nbname; i++) { lua_pushstring(L, m->bnames[i].name); lua_rawseti(L, -2, i + 1); }
  lua_setfield(L, -2, "boundaries");
  return 1;
}

static int mesh_nvertices(lua_State *L) { lua_pushinteger(L, check_mesh(L, 1, "mesh:nvertices")->lm->m->nvert); return 1; }
static int mesh_ncells(lua_State *L) { lua_pushinteger(L, check_mesh(L, 1, "mesh:ncells")->lm->m->ncell); return 1; }
static int mesh_dim(lua_State *L) { lua_pushinteger(L, check_mesh(L, 1, "mesh:dim")->lm->m->dim); return 1; }

static int lmesh_refine(lua_State *L) {
  ud_mesh *u = check_mesh(L, 1, "mesh:refine");
  char err[MESH_ERRLEN];
  mesh *r = mesh_refine(u->lm->m, err);
  if (!r) return luaL_error(L, "mesh:refine: %s", err);
  push_mesh(L, r);
  return 1;
}

static int lmesh_copy(lua_State *L) {
  ud_mesh *u = check_mesh(L, 1, "mesh:copy");
  mesh *c = mesh_copy(u->lm->m);
  if (!c) return luaL_error(L, "mesh:copy: out of memory");
  push_mesh(L, c);
  return 1;
}

static int lmesh_hmax(lua_State *L) { lua_pushnumber(L, mesh_hmax(check_mesh(L, 1, "mesh:hmax")->lm->m)); return 1; }

/* ---------------------------------------------------------------- untangle, smooth, move */

/* a report table whose tostring is the readable text in its field `text` */
static int report_tostring(lua_State *L) {
  lua_getfield(L, 1, "text");
  return 1;
}

static void push_report_meta(lua_State *L) {
  if (luaL_newmetatable(L, "lugal.report")) {
    lua_pushcfunction(L, report_tostring);
    lua_setfield(L, -2, "__tostring");
  }
  lua_setmetatable(L, -2);
}

/* the report table on the stack gets its text and metatable, and is printed unless quiet */
static int finish_report(lua_State *L, const char *text, int quiet) {
  lua_pushstring(L, text);
  lua_setfield(L, -2, "text");
  push_report_meta(L);
  if (!quiet) printf("%s\n", text);
  return 1;
}

static void set_num(lua_State *L, const char *k, double v) { lua_pushnumber(L, v); lua_setfield(L, -2, k); }
static void set_int(lua_State *L, const char *k, lua_Integer v) { lua_pushinteger(L, v); lua_setfield(L, -2, k); }

static int opt_boundary(lua_State *L, int t, const char *fn) {
  const char *b = t ? opt_str(L, t, "boundary", "slide", fn) : "slide";
  if (!strcmp(b, "slide")) return 1;
  if (!strcmp(b, "fixed")) return 0;
  return luaL_error(L, "%s: option 'boundary' must be \"slide\" or \"fixed\", got \"%s\"", fn, b);
}

static int lmesh_untangle(lua_State *L) {
  const char *fn = "mesh:untangle";
  ud_mesh *u = check_mesh(L, 1, fn);
  int t = 0;
  if (!lua_isnoneornil(L, 2)) {
    if (!lua_istable(L, 2)) return typeerror(L, fn, 2, "an options table {beta=, max_iterations=, boundary=, placement=, quiet=}");
    static const char *const keys[] = {"beta", "max_iterations", "boundary", "placement", "quiet", NULL};
    check_keys(L, 2, fn, keys);
    t = 2;
  }
  untangle_opts o;
  untangle_defaults(&o);
  int quiet = 0;
  if (t) {
    o.beta = opt_num(L, t, "beta", -1, fn);
    if (lua_getfield(L, t, "beta") != LUA_TNIL && !(o.beta >= 0))
      return luaL_error(L, "%s: option 'beta' must be >= 0 (a minimum corner Jacobian), got %f", fn, o.beta);
    lua_pop(L, 1);
    o.max_iterations = opt_int(L, t, "max_iterations", 100, fn);
    if (o.max_iterations < 1) return luaL_error(L, "%s: option 'max_iterations' must be >= 1", fn);
    const char *pl = opt_str(L, t, "placement", "chebyshev", fn);
    if (!strcmp(pl, "chebyshev")) o.placement = 0;
    else if (!strcmp(pl, "corners")) o.placement = 1;
    else return luaL_error(L, "%s: option 'placement' must be \"chebyshev\" or \"corners\", got \"%s\"", fn, pl);
    lua_getfield(L, t, "quiet");
    quiet = lua_toboolean(L, -1);
    lua_pop(L, 1);
  }
  o.slide = opt_boundary(L, t, fn);
  mesh *m = u->lm->m;
  untangle_report r;
  char err[MESH_ERRLEN];
  if (mesh_untangle(m, &o, &r, err)) return luaL_error(L, "%s: %s", fn, err);
  lg_mesh_changed(u->lm);
  char text[2048];
  size_t n = (size_t)snprintf(text, sizeof text,
                              "untangle: %d %s, beta %.3g: invalid %d -> %d (%s), %d vertices moved (mean %.3g, max "
                              "%.3g), %.3f s",
                              m->ncell, cell_plural(m->type), r.beta, r.invalid_before, r.invalid_after,
                              r.invalid_after ? "FAILED" : "valid", r.moved, r.mean_displacement, r.max_displacement,
                              r.seconds);
  lua_createtable(L, 0, 12);
  set_num(L, "beta", r.beta);
  set_int(L, "invalid_before", r.invalid_before);
  set_int(L, "invalid_after", r.invalid_after);
  lua_pushboolean(L, r.invalid_after == 0);
  lua_setfield(L, -2, "success");
  set_int(L, "moved", r.moved);
  set_num(L, "mean_displacement", r.mean_displacement);
  set_num(L, "max_displacement", r.max_displacement);
  set_num(L, "seconds", r.seconds);
  lua_createtable(L, r.nstage, 0);
  for (int i = 0; i < r.nstage; i++) {
    untangle_stage *st = &r.stage[i];
    lua_createtable(L, 0, 7);
    lua_pushstring(L, st->name);
    lua_setfield(L, -2, "name");
    set_int(L, "invalid_before", st->invalid_before);
    set_int(L, "invalid_after", st->invalid_after);
    set_int(L, "below_beta", st->below_beta_after);
    set_int(L, "moved", st->moved);
    set_int(L, "iterations", st->iterations);
    set_num(L, "seconds", st->seconds);
    lua_rawseti(L, -2, i + 1);
    if (n < sizeof text)
      n += (size_t)snprintf(text + n, sizeof text - n,
                            "\n  stage %-26s invalid %d -> %d, below beta %d, moved %d vertices, %d iterations, %.3f s",
                            st->name, st->invalid_before, st->invalid_after, st->below_beta_after, st->moved,
                            st->iterations, st->seconds);
  }
  lua_setfield(L, -2, "stages");
  return finish_report(L, text, quiet);
}

static int lmesh_smooth(lua_State *L) {
  const char *fn = "mesh:smooth";
  ud_mesh *u = check_mesh(L, 1, fn);
  mesh *m = u->lm->m;
  int t = 0;
  if (!lua_isnoneornil(L, 2)) {
    if (!lua_istable(L, 2)) return typeerror(L, fn, 2, "an options table {measure=, method=, iterations=, boundary=, quiet=}");
    static const char *const keys[] = {"measure", "method", "iterations", "boundary", "quiet", NULL};
    check_keys(L, 2, fn, keys);
    t = 2;
  }
  smooth_opts o = {m->type == CELL_TRIANGLE || m->type == CELL_TETRAHEDRON ? QM_MEAN_RATIO : QM_CORNER_CONDITION, 20, 1, 0, 0};
  int quiet = 0;
  if (t) {
    const char *name = opt_str(L, t, "measure", NULL, fn);
    if (name) {
      o.measure = quality_from_name(name);
      if (o.measure < 0) {
        char names[4096];
        quality_names(names, sizeof names);
        return luaL_error(L, "%s: unknown measure '%s' (measures: %s)", fn, name, names);
      }
    }
    const char *method = opt_str(L, t, "method", "local", fn);
    if (!strcmp(method, "global")) o.global = 1;
    else if (strcmp(method, "local"))
      return luaL_error(L, "%s: option 'method' must be \"local\" or \"global\", got '%s'", fn, method);
    o.iterations = opt_int(L, t, "iterations", 20, fn);
    if (o.iterations < 1) return luaL_error(L, "%s: option 'iterations' must be >= 1", fn);
    lua_getfield(L, t, "quiet");
    quiet = lua_toboolean(L, -1);
    lua_pop(L, 1);
  }
  o.slide = opt_boundary(L, t, fn);
  smooth_report r;
  char err[MESH_ERRLEN];
  if (mesh_smooth(m, &o, &r, err)) return luaL_error(L, "%s: %s", fn, err);
  lg_mesh_changed(u->lm);
  char text[512];
  snprintf(text, sizeof text, "smooth (%s): %s min %.4g -> %.4g, mean %.4g -> %.4g, %d vertices moved, %d %s, %.3f s",
           o.global ? "global" : "local", quality_name(o.measure), r.min_before, r.min_after, r.mean_before, r.mean_after,
           r.moved, r.sweeps, o.global ? "rounds" : "sweeps", r.seconds);
  lua_createtable(L, 0, 10);
  lua_pushstring(L, quality_name(o.measure));
  lua_setfield(L, -2, "measure");
  lua_pushstring(L, o.global ? "global" : "local");
  lua_setfield(L, -2, "method");
  set_num(L, "min_before", r.min_before);
  set_num(L, "min_after", r.min_after);
  set_num(L, "mean_before", r.mean_before);
  set_num(L, "mean_after", r.mean_after);
  set_int(L, "moved", r.moved);
  set_int(L, "sweeps", r.sweeps);
  set_num(L, "seconds", r.seconds);
  return finish_report(L, text, quiet);
}

/* a displacement per vertex from a Lua function (x, y[, z]) -> dx, dy[, dz] (or a table), or
 * from a table of dim P1/P2/P3 functions on this mesh (one per component); only vertices with
 * want[v] (all when NULL) are evaluated */
static void displacement_field(lua_State *L, int idx, ud_mesh *u, const unsigned char *want, double *out,
                               const char *fn) {
  mesh *m = u->lm->m;
  int d = m->dim;
  if (lua_isfunction(L, idx)) {
    for (int v = 0; v < m->nvert; v++) {
      if (want && !want[v]) continue;
      lua_pushvalue(L, idx);
      for (int j = 0; j < d; j++) lua_pushnumber(L, m->x[(size_t)v * d + j]);
      lua_call(L, d, d);
      if (lua_istable(L, -d)) { /* one table {dx, dy[, dz]} */
        int tb = lua_gettop(L) - d + 1;
        for (int j = 0; j < d; j++) {
          lua_rawgeti(L, tb, j + 1);
          if (!lua_isnumber(L, -1)) luaL_error(L, "%s: the displacement function returned a table without %d numbers", fn, d);
          out[(size_t)v * d + j] = lua_tonumber(L, -1);
          lua_pop(L, 1);
        }
      } else
        for (int j = 0; j < d; j++) {
          if (!lua_isnumber(L, -d + j))
            luaL_error(L, "%s: the displacement function must return %d numbers (or one table of them) at vertex %d, got %s",
                       fn, d, v + 1, luaL_typename(L, -d + j));
          out[(size_t)v * d + j] = lua_tonumber(L, -d + j);
        }
      lua_pop(L, d);
    }
    return;
  }
  if (lua_istable(L, idx) && (int)luaL_len(L, idx) == d) {
    for (int j = 0; j < d; j++) {
      lua_rawgeti(L, idx, j + 1);
      ud_func *uf = luaL_testudata(L, -1, MT_FUNC);
      if (!uf) luaL_error(L, "%s: component %d of the displacement must be a discrete function, got %s", fn, j + 1, luaL_typename(L, -1));
      if (uf->f->mesh != u->lm) luaL_error(L, "%s: component %d of the displacement lives on a different mesh", fn, j + 1);
      for (int v = 0; v < m->nvert; v++) out[(size_t)v * d + j] = uf->f->x[v]; /* vertex dofs come first */
      lua_pop(L, 1);
    }
    return;
  }
  typeerror(L, fn, idx, d == 2 ? "a function (x, y) -> dx, dy or a table {fx, fy} of discrete functions"
                                : "a function (x, y, z) -> dx, dy, dz or a table {fx, fy, fz} of discrete functions");
}

static int lmesh_move(lua_State *L) {
  const char *fn = "mesh:move";
  ud_mesh *u = check_mesh(L, 1, fn);
  mesh *m = u->lm->m;
  if (!lua_istable(L, 2)) return typeerror(L, fn, 2, "an options table {displacement = function or {fx, fy[, fz]}, quiet=}");
  static const char *const keys[] = {"displacement", "quiet", NULL};
  check_keys(L, 2, fn, keys);
  lua_getfield(L, 2, "quiet");
  int quiet = lua_toboolean(L, -1);
  lua_pop(L, 1);
  lua_getfield(L, 2, "displacement");
  if (lua_isnil(L, -1)) return luaL_error(L, "%s: option 'displacement' is required (the boundary displacement)", fn);
  int idx = lua_gettop(L);
  unsigned char *fixed = lua_newuserdatauv(L, (size_t)m->nvert + 1, 0);
  double *disp = lua_newuserdatauv(L, sizeof(double) * ((size_t)m->nvert * m->dim + 1), 0);
  char err[MESH_ERRLEN];
  if (mesh_boundary_vertices(m, fixed, err)) return luaL_error(L, "%s: %s", fn, err);
  memset(disp, 0, sizeof(double) * (size_t)m->nvert * m->dim);
  displacement_field(L, idx, u, fixed, disp, fn);
  move_report r;
  if (mesh_move(m, disp, fixed, &r, err)) return luaL_error(L, "%s: %s", fn, err);
  lg_mesh_changed(u->lm);
  char text[512];
  snprintf(text, sizeof text, "move: Laplacian motion, tau_max %.3g, %d CG iterations (residual %.1e), %d invalid cells after, %.3f s",
           r.tau_max, r.iterations, r.residual, r.invalid_after, r.seconds);
  lua_createtable(L, 0, 6);
  set_int(L, "iterations", r.iterations);
  set_num(L, "residual", r.residual);
  set_num(L, "tau_max", r.tau_max);
  set_int(L, "invalid_after", r.invalid_after);
  set_num(L, "seconds", r.seconds);
  return finish_report(L, text, quiet);
}

static int lmesh_displace(lua_State *L) {
  const char *fn = "mesh:displace";
  ud_mesh *u = check_mesh(L, 1, fn);
  mesh *m = u->lm->m;
  if (lua_isnoneornil(L, 2)) return typeerror(L, fn, 2, "a function (x, y[, z]) -> displacement or a table of discrete functions");
  double *disp = lua_newuserdatauv(L, sizeof(double) * ((size_t)m->nvert * m->dim + 1), 0);
  displacement_field(L, 2, u, NULL, disp, fn);
  for (size_t i = 0; i < (size_t)m->nvert * m->dim; i++) m->x[i] += disp[i];
  lg_mesh_changed(u->lm);
  int ninv;
  mesh_count_invalid(m, 0, NULL, &ninv);
  lua_pushinteger(L, ninv);
  return 1;
}

static int mesh_check(lua_State *L) {
  ud_mesh *u = check_mesh(L, 1, "mesh:check");
  int ids[10], n;
  mesh_count_invalid(u->lm->m, 10, ids, &n);
  lua_pushinteger(L, n);
  lua_newtable(L);
  for (int i = 0; i < n && i < 10; i++) { lua_pushinteger(L, ids[i] + 1); lua_rawseti(L, -2, i + 1); }
  return 2;
}

static int mesh_coordinates(lua_State *L) {
  ud_mesh *u = check_mesh(L, 1, "mesh:coordinates");
  mesh *m = u->lm->m;
  lua_Integer i = luaL_checkinteger(L, 2);
  if (i < 1 || i > m->nvert) return luaL_error(L, "mesh:coordinates: vertex %d out of range 1..%d", (int)i, m->nvert);
  for (int d = 0; d < m->dim; d++) lua_pushnumber(L, m->x[(size_t)(i - 1) * m->dim + d]);
  return m->dim;
}

static int mesh_set_coordinates(lua_State *L) {
  ud_mesh *u = check_mesh(L, 1, "mesh:set_coordinates");
  mesh *m = u->lm->m;
  lua_Integer i = luaL_checkinteger(L, 2);
  if (i < 1 || i > m->nvert) return luaL_error(L, "mesh:set_coordinates: vertex %d out of range 1..%d", (int)i, m->nvert);
  for (int d = 0; d < m->dim; d++) m->x[(size_t)(i - 1) * m->dim + d] = luaL_checknumber(L, 3 + d);
  lg_mesh_changed(u->lm);
  return 0;
}

/* values of a discrete function at the mesh vertices */
static ud_func *check_func(lua_State *L, int idx, const char *fn) {
  ud_func *u = luaL_testudata(L, idx, MT_FUNC);
  if (!u) typeerror(L, fn, idx, "a discrete function");
  return u;
}

static int write_fields(lua_State *L, mesh *m, lg_mesh *lm, const char *path, int tidx, const char *fn) {
  mesh_field fl[64];
  int nf = 0;
  if (!lua_isnoneornil(L, tidx)) {
    if (!lua_istable(L, tidx)) return typeerror(L, fn, tidx, "a table {name = function or array}");
    lua_pushnil(L);
    while (lua_next(L, tidx)) {
      if (nf >= 64) return luaL_error(L, "%s: at most 64 fields", fn);
      if (lua_type(L, -2) != LUA_TSTRING) return luaL_error(L, "%s: field names must be strings", fn);
      ud_func *uf = luaL_testudata(L, -1, MT_FUNC);
      ud_qarray *qa = luaL_testudata(L, -1, MT_QARRAY);
      if (qa) {
        if (qa->n != m->ncell) return luaL_error(L, "%s: quality array '%s' belongs to a mesh of %d cells", fn, lua_tostring(L, -2), qa->n);
        fl[nf].name = lua_tostring(L, -2);
        fl[nf].ncomp = 1;
        fl[nf].on_cells = 1;
        fl[nf].val = qa->v;
        nf++;
      } else if (uf) {
        if (uf->f->mesh != lm) return luaL_error(L, "%s: field '%s' lives on a different mesh", fn, lua_tostring(L, -2));
        fl[nf].name = lua_tostring(L, -2);
        fl[nf].ncomp = 1;
        fl[nf].on_cells = 0;
        fl[nf].val = uf->f->x; /* vertex dofs come first in every Lagrange numbering */
        nf++;
      } else if (lua_istable(L, -1)) {
        int n = (int)luaL_len(L, -1);
        if (n != m->ncell && n != m->nvert)
          return luaL_error(L, "%s: array '%s' has %d entries; need one per cell (%d) or vertex (%d)", fn, lua_tostring(L, -2), n, m->ncell, m->nvert);
        double *v = lua_newuserdatauv(L, sizeof(double) * (size_t)n, 0);
        lua_setfield(L, LUA_REGISTRYINDEX, lua_tostring(L, -3)); /* keep alive until written */
        for (int i = 1; i <= n; i++) {
          lua_geti(L, -1, i);
          v[i - 1] = lua_tonumber(L, -1);
          lua_pop(L, 1);
        }
        fl[nf].name = lua_tostring(L, -2);
        fl[nf].ncomp = 1;
        fl[nf].on_cells = n == m->ncell && n != m->nvert;
        fl[nf].val = v;
        nf++;
      } else return luaL_error(L, "%s: field '%s' must be a discrete function or an array", fn, lua_tostring(L, -2));
      lua_pop(L, 1);
    }
  }
  int rc = mesh_write_vtu(m, path, nf, fl);
  for (int i = 0; i < nf; i++) {
    lua_pushnil(L);
    lua_setfield(L, LUA_REGISTRYINDEX, fl[i].name);
  }
  if (rc) return luaL_error(L, "%s: %s", fn, m->err);
  return 0;
}

static int mesh_write(lua_State *L) {
  const char *fn = "mesh:write";
  ud_mesh *u = check_mesh(L, 1, fn);
  const char *path = luaL_checkstring(L, 2);
  size_t l = strlen(path);
  if (l > 4 && !strcmp(path + l - 4, ".msh")) {
    if (mesh_write_gmsh(u->lm->m, path)) return luaL_error(L, "%s: %s", fn, u->lm->m->err);
    return 0;
  }
  if (!(l > 4 && !strcmp(path + l - 4, ".vtu")))
    return luaL_error(L, "%s: argument 1 must end in .vtu (ParaView) or .msh (Gmsh), got \"%s\"", fn, path);
  write_fields(L, u->lm->m, u->lm, path, 3, fn);
  return 0;
}

static int mesh_tostring(lua_State *L) {
  ud_mesh *u = check_mesh(L, 1, "tostring");
  mesh *m = u->lm->m;
  lua_pushfstring(L, "mesh: %d %s, %d vertices, %dD", m->ncell, cell_plural(m->type), m->nvert, m->dim);
  return 1;
}

/* ---------------------------------------------------------------- quality */

/* {metric = {{a, b}, {b, c}}} (constant) or {metric = {M_1, ..., M_nvert}} (per vertex) */
static int read_metric(lua_State *L, int t, mesh *m, double **buf, quality_metric *qm, const char *fn) {
  int d = m->dim;
  qm->kind = 0;
  qm->m = NULL;
  *buf = NULL;
  if (lua_getfield(L, t, "metric") == LUA_TNIL) { lua_pop(L, 1); return 0; }
  if (!lua_istable(L, -1)) return luaL_error(L, "%s: option 'metric' must be a %dx%d table or one per vertex", fn, d, d);
  int n = (int)luaL_len(L, -1);
  lua_geti(L, -1, 1);
  int nested = lua_istable(L, -1), pervertex = 0;
  if (nested) {
    lua_geti(L, -1, 1);
    pervertex = lua_istable(L, -1);
    lua_pop(L, 1);
  }
  lua_pop(L, 1);
  if (!nested) return luaL_error(L, "%s: option 'metric' must be a %dx%d table or a list of %d of them (one per vertex)", fn, d, d, m->nvert);
  int count = pervertex ? m->nvert : 1;
  if ((pervertex && n != m->nvert) || (!pervertex && n != d))
    return luaL_error(L, "%s: option 'metric' must be a %dx%d table or a list of %d of them (one per vertex)", fn, d, d, m->nvert);
  double *b = lua_newuserdatauv(L, sizeof(double) * (size_t)count * d * d, 0);
  lua_insert(L, -2); /* keep the buffer below the table while reading */
  for (int v = 0; v < count; v++) {
    if (pervertex) lua_geti(L, -1, v + 1);
    for (int i = 0; i < d; i++) {
      if (lua_geti(L, -1, i + 1) != LUA_TTABLE || luaL_len(L, -1) != d)
        return luaL_error(L, "%s: metric row %d must have %d numbers", fn, i + 1, d);
      for (int j = 0; j < d; j++) {
        lua_geti(L, -1, j + 1);
        if (!lua_isnumber(L, -1)) return luaL_error(L, "%s: metric entries must be numbers", fn);
        b[(size_t)v * d * d + (size_t)i * d + j] = lua_tonumber(L, -1);
        lua_pop(L, 1);
      }
      lua_pop(L, 1);
    }
    if (pervertex) lua_pop(L, 1);
  }
  lua_pop(L, 1); /* the metric table; the buffer stays on the stack */
  qm->kind = pervertex ? 2 : 1;
  qm->m = b;
  *buf = b;
  return 1;
}

static ud_qarray *push_quality(lua_State *L, int midx, const char *name, int tidx, const char *fn) {
  ud_mesh *um = check_mesh(L, midx, fn);
  mesh *m = um->lm->m;
  int q = quality_from_name(name);
  if (q < 0) {
    char list[1024];
    quality_names(list, sizeof list);
    luaL_error(L, "%s: unknown measure \"%s\" (measures: %s)", fn, name, list);
  }
  quality_metric qm = {0, NULL};
  double *buf = NULL;
  int pushed = 0;
  const mesh *ref = NULL;
  double pexp = 2;
  if (tidx && !lua_isnoneornil(L, tidx)) {
    if (!lua_istable(L, tidx)) typeerror(L, fn, tidx, "a table of options {metric=, reference=, p=}");
    static const char *const keys[] = {"metric", "reference", "p", NULL};
    check_keys(L, tidx, fn, keys);
    if (lua_getfield(L, tidx, "reference") != LUA_TNIL) {
      ud_mesh *ur = luaL_testudata(L, -1, MT_MESH);
      if (!ur) luaL_error(L, "%s: option 'reference' must be a mesh (the same mesh in another configuration)", fn);
      ref = ur->lm->m;
      if (ref->type != m->type || ref->nvert != m->nvert || ref->ncell != m->ncell ||
          memcmp(ref->cells, m->cells, sizeof(int) * (size_t)m->ncell * (size_t)m->nvc))
        luaL_error(L, "%s: the reference must be the same mesh (same cells) in another configuration", fn);
    }
    lua_pop(L, 1);
    pexp = opt_num(L, tidx, "p", 2, fn);
    pushed = read_metric(L, tidx, m, &buf, &qm, fn);
  }
  if (quality_is_deformation(q) && !ref)
    luaL_error(L, "%s: %s compares two configurations: pass {reference = mesh}", fn, name);
  if (!quality_is_deformation(q) && ref) luaL_error(L, "%s: option 'reference' is for the deformation measures", fn);
  ud_qarray *a = lua_newuserdatauv(L, sizeof(ud_qarray), 0);
  a->n = 0;
  a->measure = q;
  a->v = NULL;
  luaL_setmetatable(L, MT_QARRAY);
  a->v = mesh_big_alloc(sizeof(double) * (size_t)(m->ncell + 1));
  if (!a->v) luaL_error(L, "%s: out of memory for %d values", fn, m->ncell);
  a->n = m->ncell;
  char err[MESH_ERRLEN];
  int rc = ref ? mesh_deformation(m, ref->x, q, pexp, a->v, err) : mesh_quality(m, q, qm.kind ? &qm : NULL, a->v, err);
  if (rc) luaL_error(L, "%s: %s", fn, err);
  if (pushed) lua_remove(L, -2); /* the metric buffer */
  return a;
}

static int mesh_quality_l(lua_State *L) {
  push_quality(L, 1, luaL_checkstring(L, 2), 3, "mesh:quality");
  return 1;
}

static ud_qarray *check_qarray(lua_State *L, int i) { return luaL_checkudata(L, i, MT_QARRAY); }

static int qa_index(lua_State *L) {
  ud_qarray *a = check_qarray(L, 1);
  if (lua_type(L, 2) == LUA_TSTRING) {
    luaL_getmetatable(L, MT_QARRAY);
    lua_getfield(L, -1, "methods");
    lua_getfield(L, -1, lua_tostring(L, 2));
    if (!lua_isnil(L, -1)) return 1;
    return luaL_error(L, "quality arrays have no field '%s'", lua_tostring(L, 2));
  }
  lua_Integer i = luaL_checkinteger(L, 2);
  if (i < 1 || i > a->n) return luaL_error(L, "quality index %d out of range 1..%d", (int)i, a->n);
  lua_pushnumber(L, a->v[i - 1]);
  return 1;
}
static int qa_len(lua_State *L) { lua_pushinteger(L, check_qarray(L, 1)->n); return 1; }
static int qa_gc(lua_State *L) {
  ud_qarray *a = lua_touserdata(L, 1);
  mesh_big_free(a->v);
  a->v = NULL;
  a->n = 0;
  return 0;
}
static int qa_totable(lua_State *L) {
  ud_qarray *a = check_qarray(L, 1);
  lua_createtable(L, a->n, 0);
  for (int i = 0; i < a->n; i++) { lua_pushnumber(L, a->v[i]); lua_rawseti(L, -2, i + 1); }
  return 1;
}
static int qa_stat(lua_State *L, int which) {
  ud_qarray *a = check_qarray(L, 1);
  quality_stats st;
  quality_stats_compute(a->v, a->n, &st);
  lua_pushnumber(L, which == 0 ? st.min : which == 1 ? st.max : st.mean);
  if (which == 2) return 1;
  lua_pushinteger(L, (which == 0 ? st.argmin : st.argmax) + 1);
  return 2;
}
static int qa_min(lua_State *L) { return qa_stat(L, 0); }
static int qa_max(lua_State *L) { return qa_stat(L, 1); }
static int qa_mean(lua_State *L) { return qa_stat(L, 2); }
static int qa_histogram(lua_State *L) {
  ud_qarray *a = check_qarray(L, 1);
  lua_Integer nb = luaL_optinteger(L, 2, 10);
  if (nb < 1 || nb > 10000) return luaL_error(L, "q:histogram: argument 1 must be a bin count 1..10000, got %d", (int)nb);
  quality_stats st;
  quality_stats_compute(a->v, a->n, &st);
  double lo = luaL_optnumber(L, 3, st.min), hi = luaL_optnumber(L, 4, st.max);
  int *c = lua_newuserdatauv(L, sizeof(int) * (size_t)nb, 0);
  quality_histogram(a->v, a->n, (int)nb, lo, hi, c);
  lua_createtable(L, 0, 3);
  lua_createtable(L, (int)nb, 0);
  for (int i = 0; i < nb; i++) { lua_pushinteger(L, c[i]); lua_rawseti(L, -2, i + 1); }
  lua_setfield(L, -2, "counts");
  lua_pushnumber(L, lo); lua_setfield(L, -2, "lo");
  lua_pushnumber(L, hi); lua_setfield(L, -2, "hi");
  return 1;
}
static int qa_worst(lua_State *L) {
  ud_qarray *a = check_qarray(L, 1);
  lua_Integer k = luaL_optinteger(L, 2, 10);
  if (k < 1) return luaL_error(L, "q:worst: argument 1 must be a positive count, got %d", (int)k);
  if (k > a->n) k = a->n;
  int *ids = lua_newuserdatauv(L, sizeof(int) * (size_t)(k + 1), 0);
  quality_worst(a->v, a->n, (int)k, quality_larger_is_better(a->measure), ids);
  lua_createtable(L, (int)k, 0);
  for (int i = 0; i < k; i++) {
    lua_createtable(L, 0, 2);
    lua_pushinteger(L, ids[i] + 1); lua_setfield(L, -2, "cell");
    lua_pushnumber(L, a->v[ids[i]]); lua_setfield(L, -2, "value");
    lua_rawseti(L, -2, i + 1);
  }
  return 1;
}
static int qa_tostring(lua_State *L) {
  ud_qarray *a = check_qarray(L, 1);
  quality_stats st;
  quality_stats_compute(a->v, a->n, &st);
  lua_pushfstring(L, "%s of %d cells: min %f, max %f, mean %f", quality_name(a->measure), a->n, st.min, st.max, st.mean);
  return 1;
}

/* every measure that applies, with statistics, as a table; printed unless quiet */
static int mesh_quality_report(lua_State *L) {
  const char *fn = "mesh:quality_report";
  ud_mesh *um = check_mesh(L, 1, fn);
  mesh *m = um->lm->m;
  int quiet = lua_toboolean(L, 2);
  /* split the invalid cells: inverted (clearly negative) and degenerate (about zero) */
  double *jac = mesh_big_alloc(sizeof(double) * (size_t)(m->ncell + 1));
  if (!jac) return luaL_error(L, "%s: out of memory", fn);
  char err[MESH_ERRLEN];
  mesh_quality(m, QM_MIN_CORNER_JACOBIAN, NULL, jac, err);
  double hm = mesh_hmax(m), tol = 1e-13 * pow(hm, m->dim);
  int ninverted = 0, ndegenerate = 0;
  for (int c = 0; c < m->ncell; c++) {
    if (jac[c] < -tol) ninverted++;
    else if (!(jac[c] > tol)) ndegenerate++;
  }
  mesh_big_free(jac);
  lua_createtable(L, 0, QM_COUNT + 4);
  int rep = lua_gettop(L);
  lua_pushinteger(L, m->ncell); lua_setfield(L, rep, "cells");
  lua_pushinteger(L, ninverted); lua_setfield(L, rep, "inverted");
  lua_pushinteger(L, ndegenerate); lua_setfield(L, rep, "degenerate");
  if (m->type == CELL_QUADRILATERAL) { /* Remark 1.1 classes */
    int cls[4] = {0, 0, 0, 0};
    for (int c = 0; c < m->ncell; c++) {
      double x[8];
      for (int i = 0; i < 4; i++) { x[2 * i] = m->x[2 * m->cells[4 * c + i]]; x[2 * i + 1] = m->x[2 * m->cells[4 * c + i] + 1]; }
      quad_class k;
      quad_corner_area(x, &k);
      cls[k]++;
    }
    lua_createtable(L, 0, 4);
    lua_pushinteger(L, cls[QUAD_CONVEX]); lua_setfield(L, -2, "convex");
    lua_pushinteger(L, cls[QUAD_NONCONVEX]); lua_setfield(L, -2, "nonconvex");
    lua_pushinteger(L, cls[QUAD_DEGENERATE]); lua_setfield(L, -2, "degenerate");
    lua_pushinteger(L, cls[QUAD_CROSSED]); lua_setfield(L, -2, "crossed");
    lua_setfield(L, rep, "quadrilaterals");
    if (!quiet) printf("quadrilaterals: %d convex, %d non-convex, %d degenerate, %d crossed\n", cls[0], cls[1], cls[2], cls[3]);
  }
  if (!quiet) printf("mesh quality: %d %s, %d inverted, %d degenerate\n  %-28s %12s %12s %12s %8s\n", m->ncell,
                     cell_plural(m->type), ninverted, ndegenerate, "measure", "min", "mean", "max", "worst");
  for (int q = 0; q < QM_COUNT; q++) {
    if (!quality_applies(q, m->type) || quality_is_deformation(q)) continue;
    ud_qarray *a = push_quality(L, 1, quality_name(q), 0, fn);
    quality_stats st;
    quality_stats_compute(a->v, a->n, &st);
    lua_pop(L, 1);
    lua_createtable(L, 0, 4);
    lua_pushnumber(L, st.min); lua_setfield(L, -2, "min");
    lua_pushnumber(L, st.max); lua_setfield(L, -2, "max");
    lua_pushnumber(L, st.mean); lua_setfield(L, -2, "mean");
    int wi = quality_worst_index(a->v, a->n, quality_larger_is_better(q));
    lua_pushinteger(L, wi + 1); lua_setfield(L, -2, "worst");
    lua_setfield(L, rep, quality_name(q));
    if (!quiet) printf("  %-28s %12.6g %12.6g %12.6g %8d\n", quality_name(q), st.min, st.mean, st.max, wi + 1);
  }
  if (!quiet) fflush(stdout);
  lua_settop(L, rep);
  return 1;
}

/* ---------------------------------------------------------------- basis, symbols */

static int l_lagrange(lua_State *L) {
  lua_Integer p = luaL_checkinteger(L, 1);
  if (p < 1 || p > 3) return luaL_error(L, "lg.lagrange: argument 1 must be a degree 1, 2 or 3, got %d", (int)p);
  ud_basis *u = new_ud(L, sizeof *u, MT_BASIS, 0, NULL);
  u->degree = (int)p;
  return 1;
}

static int basis_tostring(lua_State *L) {
  ud_basis *u = luaL_checkudata(L, 1, MT_BASIS);
  lua_pushfstring(L, "Lagrange P%d", u->degree);
  return 1;
}

static int new_symbol(lua_State *L, func_kind kind, const char *fn) {
  ud_basis *b = luaL_testudata(L, 1, MT_BASIS);
  if (!b) return typeerror(L, fn, 1, "a basis (lg.lagrange(p))");
  const char *name = luaL_optstring(L, 2, kind == FK_TEST ? "v" : "u");
  lg_env *env = get_env(L);
  int id = expr_func_new(env->c, kind, name, b->degree, 1, NULL);
  if (id < 0) return luaL_error(L, "%s: out of memory", fn);
  unsigned char z[3] = {0, 0, 0};
  push_expr(L, expr_field(env->c, id, 0, z), 0, NULL, fn);
  return 1;
}

static int l_unknown(lua_State *L) { return new_symbol(L, FK_UNKNOWN, "lg.unknown"); }
static int l_test(lua_State *L) { return new_symbol(L, FK_TEST, "lg.test"); }

static int l_coord(lua_State *L) {
  lua_Integer i = luaL_checkinteger(L, 1);
  if (i < 1 || i > 3) return luaL_error(L, "lg.coord: argument 1 must be 1, 2 or 3, got %d", (int)i);
  push_expr(L, expr_coord(get_env(L)->c, (int)i - 1), 0, NULL, "lg.coord");
  return 1;
}

static int l_normal(lua_State *L) {
  lg_env *env = get_env(L);
  int dim = expr_dim(env->c);
  expr *n[3];
  for (int d = 0; d < dim; d++) n[d] = expr_normal(env->c, d);
  push_expr(L, expr_list(env->c, dim, n), 0, NULL, "lg.normal");
  return 1;
}

static int l_parameter(lua_State *L) {
  const char *name = luaL_checkstring(L, 1);
  double v = luaL_optnumber(L, 2, 0);
  lg_env *env = get_env(L);
  int id = expr_param_new(env->c, name, v);
  if (id < 0) return luaL_error(L, "lg.parameter: out of memory");
  push_expr(L, expr_param(env->c, id), 0, NULL, "lg.parameter");
  return 1;
}

#define UNARY(NAME, FN)                                                   \
  static int l_##NAME(lua_State *L) {                                     \
    if (lua_type(L, 1) == LUA_TNUMBER) {                                  \
      expr *e = expr_apply(get_env(L)->c, FN, expr_num(get_env(L)->c, lua_tonumber(L, 1))); \
      if (!e) return exprerror(L, "lg." #NAME);                           \
      lua_pushnumber(L, e->value);                                        \
      return 1;                                                           \
    }                                                                     \
    expr *a = check_expr(L, 1, "lg." #NAME);                              \
    int deps[1] = {1};                                                    \
    push_expr(L, expr_apply(get_env(L)->c, FN, a), 1, deps, "lg." #NAME); \
    return 1;                                                             \
  }
UNARY(sin, FN_SIN)
UNARY(cos, FN_COS)
UNARY(tan, FN_TAN)
UNARY(exp, FN_EXP)
UNARY(log, FN_LOG)
UNARY(sqrt, FN_SQRT)
UNARY(abs, FN_ABS)
UNARY(tanh, FN_TANH)
UNARY(sinh, FN_SINH)
UNARY(cosh, FN_COSH)
UNARY(atan, FN_ATAN)
UNARY(asin, FN_ASIN)
UNARY(acos, FN_ACOS)
UNARY(sign, FN_SIGN)

static int l_pow(lua_State *L) { return arith(L, expr_pow, "lg.pow"); }
static int l_dot(lua_State *L) { return arith(L, expr_dot, "lg.dot"); }
static int l_inner(lua_State *L) { return arith(L, expr_inner, "lg.inner"); }

static int l_grad(lua_State *L) {
  expr *a = check_expr(L, 1, "lg.grad");
  int deps[1] = {1};
  push_expr(L, expr_grad(get_env(L)->c, a), 1, deps, "lg.grad");
  return 1;
}

static int l_div(lua_State *L) {
  expr *a = check_expr(L, 1, "lg.div");
  int deps[1] = {1};
  push_expr(L, expr_div_op(get_env(L)->c, a), 1, deps, "lg.div");
  return 1;
}

static int l_dx(lua_State *L) {
  expr *a = check_expr(L, 1, "lg.dx");
  lua_Integer i = luaL_checkinteger(L, 2);
  if (i < 1 || i > 3) return luaL_error(L, "lg.dx: argument 2 must be a direction 1, 2 or 3, got %d", (int)i);
  int deps[1] = {1};
  push_expr(L, expr_dx(get_env(L)->c, a, (int)i - 1), 1, deps, "lg.dx");
  return 1;
}

static int l_diff(lua_State *L) {
  expr *a = check_expr(L, 1, "lg.diff");
  expr *v = check_expr(L, 2, "lg.diff");
  int deps[2] = {1, 2};
  push_expr(L, expr_diff(get_env(L)->c, a, v), 2, deps, "lg.diff");
  return 1;
}

static int l_list(lua_State *L) {
  int n = lua_gettop(L);
  if (n == 1 && lua_istable(L, 1)) {
    int ok;
    expr *e = to_expr_opt(L, 1, &ok);
    if (!ok) return typeerror(L, "lg.list", 1, "a table of expressions");
    int deps[1] = {1};
    push_expr(L, e, 1, deps, "lg.list");
    return 1;
  }
  if (n < 1 || n > 8) return luaL_error(L, "lg.list: give 1 to 8 entries, or one table");
  expr *items[8];
  int deps[8];
  for (int i = 0; i < n; i++) {
    items[i] = check_expr(L, i + 1, "lg.list");
    deps[i] = i + 1;
  }
  push_expr(L, expr_list(get_env(L)->c, n, items), n, deps, "lg.list");
  return 1;
}

/* ---------------------------------------------------------------- integrals */

static int quad_order(lua_State *L, int idx, const char *fn) {
  if (lua_isnoneornil(L, idx)) return -1;
  if (!lua_istable(L, idx)) return typeerror(L, fn, idx, "a table of options {order=}");
  static const char *const keys[] = {"order", NULL};
  check_keys(L, idx, fn, keys);
  int o = opt_int(L, idx, "order", -1, fn);
  if (o != -1 && (o < 0 || o > FEM_MAXDEG)) return luaL_error(L, "%s: option 'order' must be 0..%d, got %d", fn, FEM_MAXDEG, o);
  return o;
}

static int make_integral(lua_State *L, const char *fn, const char *mt) {
  ud_region *r = luaL_testudata(L, 1, MT_REGION);
  if (!r) return typeerror(L, fn, 1, "a region (mesh:cells() or mesh:boundary(...))");
  expr *e = check_expr(L, 2, fn);
  if (e->kind == E_LIST) {
    char s[64];
    expr_describe_shape(e, s, sizeof s);
    return luaL_error(L, "%s: argument 2 must be a scalar expression, got %s", fn, s);
  }
  int order = quad_order(L, 3, fn);
  form *f = form_new();
  if (!f || form_add_term(f, &r->r, e, order)) { form_free(f); return luaL_error(L, "%s: out of memory", fn); }
  int deps[2] = {1, 2};
  ud_form *u = new_ud(L, sizeof *u, mt, 2, deps);
  u->f = f;
  return 1;
}

static int l_integral(lua_State *L) { return make_integral(L, "lg.integral", MT_FORM); }
static int l_essential_bc(lua_State *L) {
  ud_region *r = luaL_testudata(L, 1, MT_REGION);
  if (r && r->r.kind != REGION_BOUNDARY)
    return luaL_error(L, "lg.essential_bc: argument 1 must be a boundary region (mesh:boundary(...)), got cells");
  return make_integral(L, "lg.essential_bc", MT_BC);
}

static lg_mesh *region_or_mesh(lua_State *L, int idx, const char *fn, region *r) {
  ud_region *ur = luaL_testudata(L, idx, MT_REGION);
  if (ur) { *r = ur->r; return ur->r.mesh; }
  ud_mesh *um = luaL_testudata(L, idx, MT_MESH);
  if (um) {
    memset(r, 0, sizeof *r);
    r->kind = REGION_CELLS;
    r->mesh = um->lm;
    return um->lm;
  }
  typeerror(L, fn, idx, "a mesh or a region");
  return NULL;
}

static int l_integrate(lua_State *L) {
  const char *fn = "lg.integrate";
  region r;
  lg_mesh *lm = region_or_mesh(L, 1, fn, &r);
  expr *e = check_expr(L, 2, fn);
  int order = quad_order(L, 3, fn);
  lg_env *env = get_env(L);
  double v;
  if (lg_integrate(env, lm, &r, e, order, &v)) return lgerror(L, fn, env);
  lua_pushnumber(L, v);
  return 1;
}

/* ---------------------------------------------------------------- functions */

static void push_function(lua_State *L, lg_function *f, int mesh_idx) {
  int deps[1] = {mesh_idx};
  ud_func *u = new_ud(L, sizeof *u, MT_FUNC, 1, deps);
  u->f = f;
}

static int func_gc(lua_State *L) {
  ud_func *u = lua_touserdata(L, 1);
  if (!u->f) return 0;
  lua_getfield(L, LUA_REGISTRYINDEX, "lugal.env");
  ud_env *ue = lua_touserdata(L, -1);
  lua_pop(L, 1);
  if (ue && ue->env) {
    expr_func_info *fi = expr_func_get(ue->env->c, u->f->fid);
    if (fi) fi->user = NULL;
  }
  lg_function_free(u->f);
  u->f = NULL;
  return 0;
}

static int func_values(lua_State *L) {
  ud_func *u = check_func(L, 1, "f:values");
  lua_createtable(L, u->f->dm->ndof, 0);
  for (int i = 0; i < u->f->dm->ndof; i++) { lua_pushnumber(L, u->f->x[i]); lua_rawseti(L, -2, i + 1); }
  return 1;
}

static int func_assign(lua_State *L) {
  ud_func *u = check_func(L, 1, "f:assign");
  ud_func *g = luaL_testudata(L, 2, MT_FUNC);
  if (g) {
    if (g->f->mesh != u->f->mesh || g->f->degree != u->f->degree)
      return luaL_error(L, "f:assign: argument 1 must be a discrete function of the same basis and mesh");
    memcpy(u->f->x, g->f->x, sizeof(double) * (size_t)u->f->dm->ndof);
    return 0;
  }
  if (lua_istable(L, 2)) {
    int n = (int)luaL_len(L, 2);
    if (n != u->f->dm->ndof) return luaL_error(L, "f:assign: the table has %d values, the function %d dofs", n, u->f->dm->ndof);
    for (int i = 1; i <= n; i++) {
      lua_geti(L, 2, i);
      u->f->x[i - 1] = luaL_checknumber(L, -1);
      lua_pop(L, 1);
    }
    return 0;
  }
  lg_env *env = get_env(L);
  expr *e = check_expr(L, 2, "f:assign");
  if (lg_interpolate(env, u->f, e)) return lgerror(L, "f:assign", env);
  return 0;
}

static int func_ndof(lua_State *L) { lua_pushinteger(L, check_func(L, 1, "f:ndof")->f->dm->ndof); return 1; }
static int func_degree(lua_State *L) { lua_pushinteger(L, check_func(L, 1, "f:degree")->f->degree); return 1; }

static int func_index(lua_State *L) {
  if (lua_type(L, 2) == LUA_TSTRING) {
    luaL_getmetatable(L, MT_FUNC);
    lua_getfield(L, -1, "methods");
    lua_getfield(L, -1, lua_tostring(L, 2));
    if (!lua_isnil(L, -1)) return 1;
    return luaL_error(L, "discrete functions have no field '%s'", lua_tostring(L, 2));
  }
  return luaL_error(L, "discrete functions are scalar: they cannot be indexed");
}

static int func_tostring(lua_State *L) {
  ud_func *u = check_func(L, 1, "tostring");
  expr_func_info *fi = expr_func_get(get_env(L)->c, u->f->fid);
  lua_pushfstring(L, "discrete function %s (P%d, %d dofs)", fi ? fi->name : "?", u->f->degree, u->f->dm->ndof);
  return 1;
}

static int l_interpolate(lua_State *L) {
  const char *fn = "lg.interpolate";
  ud_basis *b = luaL_testudata(L, 1, MT_BASIS);
  if (!b) return typeerror(L, fn, 1, "a basis (lg.lagrange(p))");
  ud_mesh *um = check_mesh(L, 2, fn);
  expr *e = check_expr(L, 3, fn);
  lg_env *env = get_env(L);
  const char *name = luaL_optstring(L, 4, "f");
  lg_function *f = lg_function_new(env, um->lm, b->degree, name);
  if (!f) return lgerror(L, fn, env);
  push_function(L, f, 2);
  if (lg_interpolate(env, f, e)) return lgerror(L, fn, env);
  return 1;
}

static int l_function(lua_State *L) {
  const char *fn = "lg.function";
  ud_basis *b = luaL_testudata(L, 1, MT_BASIS);
  if (!b) return typeerror(L, fn, 1, "a basis (lg.lagrange(p))");
  ud_mesh *um = check_mesh(L, 2, fn);
  lg_env *env = get_env(L);
  lg_function *f = lg_function_new(env, um->lm, b->degree, luaL_optstring(L, 3, "f"));
  if (!f) return lgerror(L, fn, env);
  push_function(L, f, 2);
  return 1;
}

/* ---------------------------------------------------------------- problems */

static int symbol_list(lua_State *L, int t, const char *key, func_kind kind, int *ids, const char *fn) {
  int ty = lua_getfield(L, t, key);
  int n = 0;
  const char *what = kind == FK_TEST ? "a test function (lg.test) or a table of them" : "an unknown (lg.unknown) or a table of them";
  if (ty == LUA_TTABLE) {
    n = (int)luaL_len(L, -1);
    if (n < 1 || n > KER_MAXFIELD) luaL_error(L, "%s: option '%s' must list 1 to %d functions", fn, key, KER_MAXFIELD);
    for (int i = 1; i <= n; i++) {
      lua_geti(L, -1, i);
      ud_expr *u = luaL_testudata(L, -1, MT_EXPR);
      if (!u || u->e->kind != E_FIELD || u->e->order || expr_func_get(get_env(L)->c, u->e->i0)->kind != kind)
        luaL_error(L, "%s: option '%s' entry %d must be %s", fn, key, i, what);
      ids[i - 1] = u->e->i0;
      lua_pop(L, 1);
    }
  } else {
    ud_expr *u = luaL_testudata(L, -1, MT_EXPR);
    if (!u || u->e->kind != E_FIELD || u->e->order || expr_func_get(get_env(L)->c, u->e->i0)->kind != kind)
      luaL_error(L, "%s: option '%s' must be %s, got %s", fn, key, what, ty == LUA_TNIL ? "nothing" : luaL_typename(L, -1));
    ids[0] = u->e->i0;
    n = 1;
  }
  lua_pop(L, 1);
  return n;
}

static int make_problem(lua_State *L, int nonlinear) {
  const char *fn = nonlinear ? "lg.nonlinear_problem" : "lg.linear_problem";
  if (!lua_istable(L, 1)) return typeerror(L, fn, 1, "a table {mesh=, eqn=, bc=, test=, unknown=}");
  static const char *const keys[] = {"mesh", "eqn", "bc", "test", "unknown", "initial", "symmetric", "prefix", NULL};
  check_keys(L, 1, fn, keys);
  lua_getfield(L, 1, "mesh");
  ud_mesh *um = luaL_testudata(L, -1, MT_MESH);
  if (!um) return luaL_error(L, "%s: option 'mesh' must be a mesh, got %s", fn, luaL_typename(L, -1));
  int mesh_idx = lua_gettop(L);
  lua_getfield(L, 1, "eqn");
  ud_form *ue = luaL_testudata(L, -1, MT_FORM);
  if (!ue) return luaL_error(L, "%s: option 'eqn' must be a form (lg.integral(...) + ...), got %s", fn,
                             luaL_testudata(L, -1, MT_BC) ? "a boundary condition" : luaL_typename(L, -1));
  int eqn_idx = lua_gettop(L);
  lua_getfield(L, 1, "bc");
  form *bcf = NULL;
  int bc_idx = lua_gettop(L);
  form *bc_owned = NULL;
  if (lua_istable(L, bc_idx)) {
    /* a table of boundary conditions: combine */
    bc_owned = form_new();
    int n = (int)luaL_len(L, bc_idx);
    for (int i = 1; i <= n; i++) {
      lua_geti(L, bc_idx, i);
      ud_form *ub = luaL_testudata(L, -1, MT_BC);
      if (!ub) { form_free(bc_owned); return luaL_error(L, "%s: option 'bc' entry %d must be lg.essential_bc(...)", fn, i); }
      for (int k = 0; k < ub->f->n; k++) form_add_term(bc_owned, &ub->f->t[k].reg, ub->f->t[k].integrand, -1);
      lua_pop(L, 1);
    }
    bcf = bc_owned;
  } else if (!lua_isnil(L, bc_idx)) {
    ud_form *ub = luaL_testudata(L, bc_idx, MT_BC);
    if (!ub) return luaL_error(L, "%s: option 'bc' must be lg.essential_bc(...) or a table of them, got %s", fn, luaL_typename(L, bc_idx));
    bcf = ub->f;
  }
  int test[KER_MAXFIELD], unk[KER_MAXFIELD];
  int nt = symbol_list(L, 1, "test", FK_TEST, test, fn);
  int nu = symbol_list(L, 1, "unknown", FK_UNKNOWN, unk, fn);
  if (nt != nu) { form_free(bc_owned); return luaL_error(L, "%s: %d test functions for %d unknowns", fn, nt, nu); }
  lua_getfield(L, 1, "symmetric");
  int sym = lua_toboolean(L, -1);
  lua_pop(L, 1);
  const char *prefix = opt_str(L, 1, "prefix", NULL, fn);
  for (int i = 0; ue && i < ue->f->n; i++)
    if (ue->f->t[i].reg.mesh != um->lm) { form_free(bc_owned); return luaL_error(L, "%s: the equation integrates over a different mesh than 'mesh'", fn); }
  for (int i = 0; bcf && i < bcf->n; i++)
    if (bcf->t[i].reg.mesh != um->lm) { form_free(bc_owned); return luaL_error(L, "%s: a boundary condition is on a different mesh than 'mesh'", fn); }
  lg_env *env = get_env(L);
  lg_problem_spec s = {um->lm, ue->f, bcf, nt, test, unk, nonlinear, sym, prefix};
  lg_problem *p = lg_problem_new(env, &s);
  form_free(bc_owned);
  if (!p) return lgerror(L, fn, env);
  int deps[3] = {mesh_idx, eqn_idx, bc_idx};
  ud_prob *u = new_ud(L, sizeof *u, MT_PROB, lua_isnil(L, bc_idx) ? 2 : 3, deps);
  u->p = p;
  u->nfield = nt;
  u->nonlinear = nonlinear;
  /* the initial guess is kept with the problem */
  lua_getfield(L, 1, "initial");
  lua_getiuservalue(L, -2, 1);
  lua_insert(L, -2);
  lua_setfield(L, -2, "__initial");
  lua_pop(L, 1);
  return 1;
}

static int l_linear_problem(lua_State *L) { return make_problem(L, 0); }
static int l_nonlinear_problem(lua_State *L) { return make_problem(L, 1); }

static int prob_gc(lua_State *L) {
  ud_prob *u = lua_touserdata(L, 1);
  lg_problem_free(u->p);
  u->p = NULL;
  return 0;
}

static int prob_solve(lua_State *L) {
  const char *fn = "problem:solve";
  ud_prob *u = luaL_checkudata(L, 1, MT_PROB);
  lg_env *env = get_env(L);
  lg_function *init[KER_MAXFIELD] = {NULL};
  int init_idx = 2;
  if (lua_isnoneornil(L, 2)) {
    lua_settop(L, 1);
    lua_getiuservalue(L, 1, 1);
    lua_getfield(L, -1, "__initial");
    lua_remove(L, 2);
  }
  lua_settop(L, 2);
  if (!lua_isnil(L, init_idx)) {
    if (u->nfield == 1 && luaL_testudata(L, init_idx, MT_FUNC)) init[0] = ((ud_func *)lua_touserdata(L, init_idx))->f;
    else if (lua_istable(L, init_idx)) {
      for (int i = 1; i <= u->nfield; i++) {
        lua_geti(L, init_idx, i);
        ud_func *g = luaL_testudata(L, -1, MT_FUNC);
        if (!g && !lua_isnil(L, -1)) return luaL_error(L, "%s: initial guess %d must be a discrete function", fn, i);
        init[i - 1] = g ? g->f : NULL;
        lua_pop(L, 1);
      }
    } else return typeerror(L, fn, init_idx, "a discrete function (initial guess)");
  }
  lg_function *out[KER_MAXFIELD];
  lg_solve_info info;
  if (lg_problem_solve(env, u->p, init, out, &info)) return lgerror(L, fn, env);
  /* find the mesh userdata among the dependencies to anchor the outputs */
  lua_getiuservalue(L, 1, 1);
  int mesh_idx = 0;
  lua_pushnil(L);
  while (lua_next(L, -2)) {
    lua_pop(L, 1);
    ud_mesh *um = luaL_testudata(L, -1, MT_MESH);
    if (um && um->lm == out[0]->mesh) { mesh_idx = lua_gettop(L); break; }
  }
  int base = lua_gettop(L);
  for (int a = 0; a < u->nfield; a++) {
    if (mesh_idx) push_function(L, out[a], mesh_idx);
    else {
      ud_func *uf = new_ud(L, sizeof *uf, MT_FUNC, 0, NULL);
      uf->f = out[a];
    }
  }
  /* info table */
  lua_createtable(L, 0, 8);
  lua_pushinteger(L, info.iterations); lua_setfield(L, -2, "iterations");
  lua_pushinteger(L, info.linear_iterations); lua_setfield(L, -2, "linear_iterations");
  lua_pushstring(L, info.reason); lua_setfield(L, -2, "reason");
  lua_pushnumber(L, info.assemble_ms); lua_setfield(L, -2, "assemble_ms");
  lua_pushnumber(L, info.solve_ms); lua_setfield(L, -2, "solve_ms");
  lua_createtable(L, info.nres, 0);
  for (int i = 0; i < info.nres; i++) { lua_pushnumber(L, info.res[i]); lua_rawseti(L, -2, i + 1); }
  lua_setfield(L, -2, "residuals");
  lua_pushinteger(L, lg_problem_size(u->p)); lua_setfield(L, -2, "dofs");
  return lua_gettop(L) - base;
}

static int prob_matrix(lua_State *L) {
  const char *fn = "problem:matrix";
  ud_prob *u = luaL_checkudata(L, 1, MT_PROB);
  int n = lg_problem_size(u->p);
  if (n > 2000) return luaL_error(L, "%s: the dense matrix is for small problems (n <= 2000, this one has %d)", fn, n);
  double *d = malloc(sizeof(double) * (size_t)n * n);
  if (!d) return luaL_error(L, "%s: out of memory", fn);
  lg_env *env = get_env(L);
  if (lg_problem_dense_matrix(env, u->p, d, n)) { free(d); return lgerror(L, fn, env); }
  lua_createtable(L, n, 0);
  for (int i = 0; i < n; i++) {
    lua_createtable(L, n, 0);
    for (int j = 0; j < n; j++) { lua_pushnumber(L, d[(size_t)i * n + j]); lua_rawseti(L, -2, j + 1); }
    lua_rawseti(L, -2, i + 1);
  }
  free(d);
  return 1;
}

static int prob_assemble(lua_State *L) {
  ud_prob *u = luaL_checkudata(L, 1, MT_PROB);
  lg_env *env = get_env(L);
  double ms;
  if (lg_problem_assemble_matrix(env, u->p, &ms)) return lgerror(L, "problem:assemble", env);
  lua_pushnumber(L, ms / 1000.0);
  lua_pushinteger(L, lg_problem_nnz(u->p));
  return 2;
}

static int prob_size(lua_State *L) {
  ud_prob *u = luaL_checkudata(L, 1, MT_PROB);
  lua_pushinteger(L, lg_problem_size(u->p));
  return 1;
}

/* ---------------------------------------------------------------- series */

static int l_series(lua_State *L) {
  const char *path = luaL_checkstring(L, 1);
  size_t l = strlen(path);
  if (l < 5 || strcmp(path + l - 4, ".pvd")) return luaL_error(L, "lg.series: argument 1 must be a path ending in .pvd, got \"%s\"", path);
  if (l >= 500) return luaL_error(L, "lg.series: path too long");
  ud_series *u = new_ud(L, sizeof *u, MT_SERIES, 0, NULL);
  snprintf(u->path, sizeof u->path, "%s", path);
  return 1;
}

static int series_write(lua_State *L) {
  const char *fn = "series:write";
  ud_series *u = luaL_checkudata(L, 1, MT_SERIES);
  ud_mesh *um = check_mesh(L, 2, fn);
  double t = luaL_optnumber(L, 4, u->n);
  if (u->n == u->cap) {
    int cap = u->cap ? 2 * u->cap : 16;
    double *nt = realloc(u->t, sizeof(double) * (size_t)cap);
    if (!nt) return luaL_error(L, "%s: out of memory", fn);
    u->t = nt;
    char **nf = realloc(u->files, sizeof(char *) * (size_t)cap);
    if (!nf) return luaL_error(L, "%s: out of memory", fn);
    u->files = nf;
    u->cap = cap;
  }
  char file[600];
  snprintf(file, sizeof file, "%.*s_%04d.vtu", (int)(strlen(u->path) - 4), u->path, u->n);
  write_fields(L, um->lm->m, um->lm, file, 3, fn);
  u->files[u->n] = strdup(file);
  u->t[u->n] = t;
  if (!u->files[u->n]) return luaL_error(L, "%s: out of memory", fn);
  u->n++;
  char err[MESH_ERRLEN];
  if (mesh_write_pvd(u->path, u->n, u->t, u->files, err)) return luaL_error(L, "%s: %s", fn, err);
  lua_pushstring(L, file);
  return 1;
}

static int series_gc(lua_State *L) {
  ud_series *u = lua_touserdata(L, 1);
  for (int i = 0; i < u->n; i++) free(u->files[i]);
  free(u->files);
  free(u->t);
  u->files = NULL;
  u->t = NULL;
  u->n = 0;
  return 0;
}

/* ---------------------------------------------------------------- misc */

static int l_options(lua_State *L) {
  const char *s = luaL_checkstring(L, 1);
  if (PetscOptionsInsertString(NULL, s)) return luaL_error(L, "lg.options: PETSc could not parse \"%s\"", s);
  return 0;
}

static int l_jit(lua_State *L) {
  const char *b = luaL_checkstring(L, 1);
  lg_env *env = get_env(L);
  if (!strcmp(b, "tcc")) jit_set_backend(env->jit, JIT_TCC);
  else if (!strcmp(b, "cc")) jit_set_backend(env->jit, JIT_CC);
  else return luaL_error(L, "lg.jit: argument 1 must be \"tcc\" or \"cc\", got \"%s\"", b);
  return 0;
}

/* wall-clock seconds from a monotonic clock (os.clock is CPU time of every thread) */
static int l_wtime(lua_State *L) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  lua_pushnumber(L, ts.tv_sec + 1e-9 * ts.tv_nsec);
  return 1;
}

static int l_stats(lua_State *L) {
  lg_env *env = get_env(L);
  lua_createtable(L, 0, 3);
  lua_pushinteger(L, env->nkernels); lua_setfield(L, -2, "kernels");
  lua_pushnumber(L, env->kernel_ms); lua_setfield(L, -2, "kernel_ms");
  lua_pushinteger(L, (lua_Integer)expr_node_count(env->c)); lua_setfield(L, -2, "nodes");
  return 1;
}

static void new_mt(lua_State *L, const char *name, const luaL_Reg *mm, const luaL_Reg *methods) {
  luaL_newmetatable(L, name);
  if (mm) luaL_setfuncs(L, mm, 0);
  if (methods) {
    lua_newtable(L);
    luaL_setfuncs(L, methods, 0);
    lua_pushvalue(L, -1);
    lua_setfield(L, -3, "methods");
    if (lua_getfield(L, -2, "__index") == LUA_TNIL) {
      lua_pop(L, 1);
      lua_setfield(L, -2, "__index");
    } else lua_pop(L, 2);
  }
  lua_pop(L, 1);
}

int luaopen_lugal(lua_State *L) {
  /* the environment: created once per Lua state, finalized last */
  if (lua_getfield(L, LUA_REGISTRYINDEX, "lugal.env") == LUA_TNIL) {
    lua_pop(L, 1);
    ud_env *ue = lua_newuserdatauv(L, sizeof *ue, 0);
    ue->owns_petsc = 0;
    PetscBool inited = PETSC_FALSE;
    PetscInitialized(&inited);
    if (!inited) {
      /* loaded by a plain Lua interpreter (lua5.4 with package.cpath): start PETSc here;
       * options come from PETSC_OPTIONS and lg.options */
      if (lg_petsc_init(NULL, NULL)) return luaL_error(L, "lugal: PETSc failed to initialize");
      ue->owns_petsc = 1;
    }
    ue->env = lg_env_new(LUGAL_TCC_LIBDIR);
    if (!ue->env) return luaL_error(L, "lugal: out of memory");
    if (luaL_newmetatable(L, MT_ENV)) { lua_pushcfunction(L, env_gc); lua_setfield(L, -2, "__gc"); }
    lua_setmetatable(L, -2);
    lua_setfield(L, LUA_REGISTRYINDEX, "lugal.env");
    PetscBool set = PETSC_FALSE;
    char backend[16] = "";
    PetscOptionsGetString(NULL, NULL, "-lugal_jit", backend, sizeof backend, &set);
    if (set && !strcmp(backend, "cc")) jit_set_backend(ue->env->jit, JIT_CC);
    PetscBool verbose = PETSC_FALSE;
    PetscOptionsHasName(NULL, NULL, "-lugal_verbose", &verbose);
    ue->env->verbose = verbose;
  } else lua_pop(L, 1);

  static const luaL_Reg arith_mm[] = {{"__add", m_add}, {"__sub", m_sub}, {"__mul", m_mul}, {"__div", m_div},
                                      {"__pow", m_pow}, {"__unm", m_unm}, {NULL, NULL}};
  luaL_newmetatable(L, MT_EXPR);
  luaL_setfuncs(L, arith_mm, 0);
  lua_pushcfunction(L, expr_tostring); lua_setfield(L, -2, "__tostring");
  lua_pushcfunction(L, expr_len); lua_setfield(L, -2, "__len");
  lua_pushcfunction(L, expr_index_mm); lua_setfield(L, -2, "__index");
  lua_pop(L, 1);

  static const luaL_Reg func_methods[] = {{"values", func_values}, {"assign", func_assign}, {"ndof", func_ndof},
                                          {"degree", func_degree}, {NULL, NULL}};
  luaL_newmetatable(L, MT_FUNC);
  luaL_setfuncs(L, arith_mm, 0);
  lua_pushcfunction(L, func_gc); lua_setfield(L, -2, "__gc");
  lua_pushcfunction(L, func_tostring); lua_setfield(L, -2, "__tostring");
  lua_pushcfunction(L, func_index); lua_setfield(L, -2, "__index");
  lua_newtable(L);
  luaL_setfuncs(L, func_methods, 0);
  lua_setfield(L, -2, "methods");
  lua_pop(L, 1);

  static const luaL_Reg form_mm[] = {{"__add", m_add}, {"__sub", m_sub}, {"__mul", m_mul}, {"__unm", form_unm},
                                     {"__gc", form_gc}, {"__tostring", form_tostring}, {NULL, NULL}};
  new_mt(L, MT_FORM, form_mm, NULL);
  new_mt(L, MT_BC, form_mm, NULL);

  static const luaL_Reg mesh_mm[] = {{"__gc", mesh_gc}, {"__tostring", mesh_tostring}, {NULL, NULL}};
  static const luaL_Reg mesh_methods[] = {{"cells", mesh_cells}, {"boundary", mesh_boundary}, {"info", mesh_info},
                                          {"write", mesh_write}, {"refine", lmesh_refine}, {"copy", lmesh_copy}, {"hmax", lmesh_hmax},
                                          {"check", mesh_check}, {"nvertices", mesh_nvertices}, {"ncells", mesh_ncells},
                                          {"dim", mesh_dim}, {"coordinates", mesh_coordinates},
                                          {"set_coordinates", mesh_set_coordinates}, {"quality", mesh_quality_l},
                                          {"quality_report", mesh_quality_report}, {"untangle", lmesh_untangle}, {"smooth", lmesh_smooth},
                                          {"move", lmesh_move}, {"displace", lmesh_displace}, {NULL, NULL}};
  new_mt(L, MT_MESH, mesh_mm, mesh_methods);
  new_mt(L, MT_REGION, NULL, NULL);
  static const luaL_Reg basis_mm[] = {{"__tostring", basis_tostring}, {NULL, NULL}};
  new_mt(L, MT_BASIS, basis_mm, NULL);
  static const luaL_Reg prob_mm[] = {{"__gc", prob_gc}, {NULL, NULL}};
  static const luaL_Reg prob_methods[] = {{"solve", prob_solve}, {"matrix", prob_matrix}, {"assemble", prob_assemble},
                                          {"size", prob_size}, {NULL, NULL}};
  new_mt(L, MT_PROB, prob_mm, prob_methods);
  static const luaL_Reg qa_mm[] = {{"__index", qa_index}, {"__len", qa_len}, {"__tostring", qa_tostring},
                                   {"__gc", qa_gc}, {NULL, NULL}};
  static const luaL_Reg qa_methods[] = {{"totable", qa_totable}, {"min", qa_min}, {"max", qa_max}, {"mean", qa_mean},
                                        {"histogram", qa_histogram}, {"worst", qa_worst}, {NULL, NULL}};
  luaL_newmetatable(L, MT_QARRAY);
  luaL_setfuncs(L, qa_mm, 0);
  lua_newtable(L);
  luaL_setfuncs(L, qa_methods, 0);
  lua_setfield(L, -2, "methods");
  lua_pop(L, 1);
  static const luaL_Reg series_mm[] = {{"__gc", series_gc}, {NULL, NULL}};
  static const luaL_Reg series_methods[] = {{"write", series_write}, {NULL, NULL}};
  new_mt(L, MT_SERIES, series_mm, series_methods);

  static const luaL_Reg lib[] = {
      {"lagrange", l_lagrange}, {"unknown", l_unknown}, {"test", l_test}, {"coord", l_coord},
      {"normal", l_normal}, {"parameter", l_parameter}, {"sin", l_sin}, {"cos", l_cos}, {"tan", l_tan},
      {"exp", l_exp}, {"log", l_log}, {"sqrt", l_sqrt}, {"abs", l_abs}, {"tanh", l_tanh}, {"sinh", l_sinh},
      {"cosh", l_cosh}, {"atan", l_atan}, {"asin", l_asin}, {"acos", l_acos}, {"sign", l_sign},
      {"pow", l_pow}, {"grad", l_grad}, {"div", l_div}, {"dot", l_dot}, {"inner", l_inner}, {"dx", l_dx},
      {"diff", l_diff}, {"list", l_list}, {"integral", l_integral}, {"essential_bc", l_essential_bc},
      {"integrate", l_integrate}, {"interpolate", l_interpolate}, {"function", l_function},
      {"linear_problem", l_linear_problem}, {"nonlinear_problem", l_nonlinear_problem},
      {"series", l_series}, {"options", l_options}, {"jit", l_jit}, {"stats", l_stats},
      {"wtime", l_wtime}, {NULL, NULL}};
  luaL_newlib(L, lib);
  static const luaL_Reg meshlib[] = {{"rectangle", l_rectangle}, {"box", l_box}, {"read", l_read},
                                     {"new", l_mesh_new}, {NULL, NULL}};
  luaL_newlib(L, meshlib);
  lua_setfield(L, -2, "mesh");
  lg_env *env = get_env(L);
  for (int d = 0; d < 3; d++) {
    ud_expr *u = new_ud(L, sizeof *u, MT_EXPR, 0, NULL);
    u->e = expr_coord(env->c, d);
    lua_setfield(L, -2, d == 0 ? "x" : d == 1 ? "y" : "z");
  }
  lua_pushstring(L, LUGAL_VERSION);
  lua_setfield(L, -2, "version");
  return 1;
}
