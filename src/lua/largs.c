/* largs.c — what every binding file of the Lua module shares (largs.h): the environment,
 * errors that name the function and the argument, dependency tables that keep meshes and
 * functions alive, conversion of Lua values to expressions, option tables, reports. */
#include "largs.h"

#include <lauxlib.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

lg_env *get_env(lua_State *L) {
  lua_getfield(L, LUA_REGISTRYINDEX, "lugal.env");
  ud_env *u = lua_touserdata(L, -1);
  lua_pop(L, 1);
  if (!u || !u->env) luaL_error(L, "lugal: the module is not initialized");
  return u->env;
}

int typeerror(lua_State *L, const char *fn, int arg, const char *expected) {
  const char *got = luaL_typename(L, arg);
  if (lua_type(L, arg) == LUA_TUSERDATA && luaL_getmetafield(L, arg, "__name") == LUA_TSTRING) {
    got = lua_tostring(L, -1);
    if (!strncmp(got, "lugal.", 6)) got += 6;
  }
  return luaL_error(L, "%s: argument %d must be %s, got %s", fn, arg, expected, got);
}

int lgerror(lua_State *L, const char *fn, lg_env *env) {
  return luaL_error(L, "%s: %s", fn, env->err);
}

int exprerror(lua_State *L, const char *fn) {
  return luaL_error(L, "%s: %s", fn, expr_error(get_env(L)->c));
}

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
void *new_ud(lua_State *L, size_t size, const char *mt, int ndeps, const int *deps) {
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

void push_expr(lua_State *L, expr *e, int ndeps, const int *deps, const char *fn) {
  if (!e) exprerror(L, fn);
  ud_expr *u = new_ud(L, sizeof *u, MT_EXPR, ndeps, deps);
  u->e = e;
}

expr *symbol_expr(lg_env *env, int fid) {
  unsigned char z[3] = {0, 0, 0};
  expr_func_info *fi = expr_func_get(env->c, fid);
  int n = fi && fi->ncomp > 1 ? fi->ncomp : 1;
  if (n == 1) return expr_field(env->c, fid, 0, z);
  expr *c[FEM_MAXBS];
  for (int j = 0; j < n && j < FEM_MAXBS; j++) c[j] = expr_field(env->c, fid, j, z);
  return expr_list(env->c, n, c);
}

int symbol_func(lg_env *env, expr *e) {
  if (!e) return -1;
  if (e->kind == E_FIELD) {
    expr_func_info *fi = expr_func_get(env->c, e->i0);
    return !e->order && e->i1 == 0 && fi && fi->ncomp <= 1 ? e->i0 : -1;
  }
  if (e->kind != E_LIST || e->n < 2 || e->ch[0]->kind != E_FIELD) return -1;
  int f = e->ch[0]->i0;
  expr_func_info *fi = expr_func_get(env->c, f);
  if (!fi || fi->ncomp != e->n) return -1;
  for (int j = 0; j < e->n; j++)
    if (e->ch[j]->kind != E_FIELD || e->ch[j]->i0 != f || e->ch[j]->i1 != j || e->ch[j]->order) return -1;
  return f;
}

static expr *to_expr_depth(lua_State *L, int idx, int *ok, int depth);

static expr *table_to_list(lua_State *L, int idx, int *ok, int depth) {
  lg_env *env = get_env(L);
  if (depth >= EXPR_MAXRANK) {
    expr_set_error(env->c, "tables of expressions nest at most %d deep", EXPR_MAXRANK);
    return NULL;
  }
  lua_Integer n = luaL_len(L, idx);
  if (n < 1 || n > 64) { *ok = 0; return NULL; }
  expr *items[64];
  for (int i = 1; i <= n; i++) {
    lua_geti(L, idx, i);
    items[i - 1] = to_expr_depth(L, -1, ok, depth + 1);
    lua_pop(L, 1);
    if (!*ok || !items[i - 1]) return NULL;
  }
  return expr_list(env->c, (int)n, items);
}

static expr *to_expr_depth(lua_State *L, int idx, int *ok, int depth) {
  lg_env *env = get_env(L);
  *ok = 1;
  if (lua_type(L, idx) == LUA_TNUMBER) return expr_num(env->c, lua_tonumber(L, idx));
  ud_expr *ue = luaL_testudata(L, idx, MT_EXPR);
  if (ue) return ue->e;
  ud_func *uf = luaL_testudata(L, idx, MT_FUNC);
  if (uf) return symbol_expr(env, uf->f->fid);
  if (lua_type(L, idx) == LUA_TTABLE) return table_to_list(L, lua_absindex(L, idx), ok, depth);
  *ok = 0;
  return NULL;
}

/* number, Expr, Function or table of those; *ok = 0 when the type does not fit. The result
 * may be a pending sum or product (only + - * build those) */
expr *to_expr_opt(lua_State *L, int idx, int *ok) { return to_expr_depth(L, idx, ok, 0); }

expr *expr_of(lua_State *L, ud_expr *u) {
  expr *e = expr_canon(get_env(L)->c, u->e);
  if (!e) luaL_error(L, "%s", expr_error(get_env(L)->c));
  u->e = e; /* resolved once */
  return e;
}

expr *check_expr_raw(lua_State *L, int idx, const char *fn) {
  int ok;
  expr *e = to_expr_opt(L, idx, &ok);
  if (!ok) typeerror(L, fn, idx, "an expression, a number or a discrete function");
  if (!e) exprerror(L, fn);
  return e;
}

expr *check_expr(lua_State *L, int idx, const char *fn) {
  expr *e = check_expr_raw(L, idx, fn);
  ud_expr *ue = luaL_testudata(L, idx, MT_EXPR);
  if (ue) return expr_of(L, ue);
  e = expr_canon(get_env(L)->c, e);
  if (!e) exprerror(L, fn);
  return e;
}

ud_mesh *check_mesh(lua_State *L, int idx, const char *fn) {
  ud_mesh *u = luaL_testudata(L, idx, MT_MESH);
  if (!u) typeerror(L, fn, idx, "a mesh");
  return u;
}

void gc_point(lua_State *L, int always) {
  if (lg_mpi_size() < 2) return;
  lg_env *env = get_env(L);
  if (always || ++env->gc_points % 32 == 0) lua_gc(L, LUA_GCCOLLECT);
}

/* the mesh m (NULL: a rank's part already made, lm) as a Lua mesh */
static void push_either(lua_State *L, mesh *m, lg_mesh *lm) {
  lg_env *env = get_env(L);
  gc_point(L, 1);
  ud_mesh *u = lua_newuserdatauv(L, sizeof *u, 1);
  u->lm = lm;
  luaL_setmetatable(L, MT_MESH);
  /* -lugal_distribute: rank 0's mesh (the others' copy is dropped) cut into parts, each rank
   * keeping its own with a ghost layer */
  if (!lm && lg_distribute_wanted()) {
    u->lm = lg_mesh_distribute(env, m);
    if (!u->lm) luaL_error(L, "distributing the mesh: %s", env->err);
  } else if (!lm) {
    u->lm = lg_mesh_wrap(m);
    if (!u->lm) { mesh_free(m); luaL_error(L, "out of memory"); }
  }
  expr_set_dim(env->c, u->lm->m->dim);
}

void push_mesh(lua_State *L, mesh *m) { push_either(L, m, NULL); }

void push_mesh_part(lua_State *L, lg_mesh *lm) { push_either(L, NULL, lm); }

double opt_num(lua_State *L, int t, const char *key, double def, const char *fn) {
  double v = def;
  int ty = lua_getfield(L, t, key);
  if (ty == LUA_TNUMBER) v = lua_tonumber(L, -1);
  else if (ty != LUA_TNIL) luaL_error(L, "%s: option '%s' must be a number, got %s", fn, key, luaL_typename(L, -1));
  /* NaN is no setting of anything (and passes every comparison a range check makes) */
  if (isnan(v)) luaL_error(L, "%s: option '%s' must be a number, got nan", fn, key);
  lua_pop(L, 1);
  return v;
}

double opt_tolerance(lua_State *L, int t, const char *key, double def, const char *fn) {
  int given = lua_getfield(L, t, key) != LUA_TNIL;
  lua_pop(L, 1);
  double v = opt_num(L, t, key, def, fn);
  if (given && !(v >= 0 && isfinite(v)))
    luaL_error(L, "%s: option '%s' must be a finite number >= 0 (a tolerance), got %f", fn, key, v);
  return v;
}

lua_Integer check_int_value(lua_State *L, int idx, lua_Integer lo, lua_Integer hi, const char *fn, const char *what) {
  int isint;
  lua_Integer v = lua_tointegerx(L, idx, &isint); /* also a float with an integral value */
  if (!isint) {
    if (lua_type(L, idx) != LUA_TNUMBER)
      luaL_error(L, "%s: %s must be an integer, got %s", fn, what, luaL_typename(L, idx));
    double x = lua_tonumber(L, idx);
    if (x != x) luaL_error(L, "%s: %s must be an integer, got nan", fn, what);
    if (x == floor(x)) /* infinite, or integral but beyond 64 bits */
      luaL_error(L, "%s: %s is too large (%f; at most %I)", fn, what, x, hi);
    luaL_error(L, "%s: %s must be an integer, got a fraction (%f)", fn, what, x);
  }
  if (v > hi) luaL_error(L, "%s: %s is too large (%I; at most %I)", fn, what, v, hi);
  if (v < lo) luaL_error(L, "%s: %s must be at least %I, got %I", fn, what, lo, v);
  return v;
}

int opt_int(lua_State *L, int t, const char *key, int def, const char *fn) {
  int v = def;
  if (lua_getfield(L, t, key) != LUA_TNIL) {
    char what[96];
    snprintf(what, sizeof what, "option '%s'", key);
    v = (int)check_int_value(L, -1, INT_MIN, INT_MAX, fn, what);
  }
  lua_pop(L, 1);
  return v;
}

int check_int_arg(lua_State *L, int arg, lua_Integer lo, lua_Integer hi, const char *fn) {
  char what[32];
  snprintf(what, sizeof what, "argument %d", arg);
  if (lua_isnoneornil(L, arg)) luaL_error(L, "%s: %s must be an integer, got %s", fn, what, luaL_typename(L, arg));
  return (int)check_int_value(L, arg, lo, hi, fn, what);
}

const char *check_cstring(lua_State *L, int idx, const char *fn, const char *what) {
  size_t len;
  const char *s = lua_tolstring(L, idx, &len);
  if (!s) luaL_error(L, "%s: %s must be a string, got %s", fn, what, luaL_typename(L, idx));
  if (strlen(s) != len)
    luaL_error(L, "%s: %s \"%s...\" holds a zero byte (\\0): names and paths end at the first one, so two names "
                  "would be one", fn, what, s);
  return s;
}

const char *opt_cstring(lua_State *L, int idx, const char *def, const char *fn, const char *what) {
  return lua_isnoneornil(L, idx) ? def : check_cstring(L, idx, fn, what);
}

const char *opt_str(lua_State *L, int t, const char *key, const char *def, const char *fn) {
  const char *v = def;
  int ty = lua_getfield(L, t, key);
  if (ty == LUA_TSTRING) {
    char what[96];
    snprintf(what, sizeof what, "option '%s'", key);
    v = check_cstring(L, -1, fn, what);
  }
  else if (ty != LUA_TNIL) luaL_error(L, "%s: option '%s' must be a string, got %s", fn, key, luaL_typename(L, -1));
  lua_pop(L, 1);
  return v; /* valid while the table holds it */
}

#define MT_INFO "lugal.info"

void push_info_table(lua_State *L, int nrec) {
  lua_createtable(L, 0, nrec);
  luaL_newmetatable(L, MT_INFO);
  lua_setmetatable(L, -2);
}

int is_info_table(lua_State *L, int idx) {
  if (!lua_istable(L, idx) || !lua_getmetatable(L, idx)) return 0;
  luaL_getmetatable(L, MT_INFO);
  int same = lua_rawequal(L, -1, -2);
  lua_pop(L, 2);
  return same;
}

void check_keys(lua_State *L, int t, const char *fn, const char *const *allowed) {
  if (is_info_table(L, t))
    luaL_error(L, "%s: an options table was expected, got the info table a solve or lg.minimize returns after its results: "
                  "keep the results in locals first (local uh = problem:solve())", fn);
  lua_pushnil(L);
  while (lua_next(L, t)) {
    lua_pop(L, 1);
    if (lua_type(L, -1) != LUA_TSTRING) luaL_error(L, "%s: options must be named (key = value)", fn);
    const char *k = check_cstring(L, -1, fn, "an option's name");
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
int finish_report(lua_State *L, const char *text, int quiet) {
  lua_pushstring(L, text);
  lua_setfield(L, -2, "text");
  push_report_meta(L);
  if (!quiet && lg_mpi_rank() == 0) printf("%s\n", text); /* every rank made the same */
  return 1;
}

void set_num(lua_State *L, const char *k, double v) { lua_pushnumber(L, v); lua_setfield(L, -2, k); }

void set_int(lua_State *L, const char *k, lua_Integer v) { lua_pushinteger(L, v); lua_setfield(L, -2, k); }

/* values of a discrete function at the mesh vertices */
ud_func *check_func(lua_State *L, int idx, const char *fn) {
  ud_func *u = luaL_testudata(L, idx, MT_FUNC);
  if (!u) typeerror(L, fn, idx, "a discrete function");
  return u;
}

void push_function(lua_State *L, lg_function *f, int mesh_idx) {
  int deps[1] = {mesh_idx};
  ud_func *u = new_ud(L, sizeof *u, MT_FUNC, 1, deps);
  u->f = f;
}

/* The most arguments each function of the module takes (methods: besides self), so that an
 * extra or misplaced argument is an error that names the function instead of being
 * ignored (lg.sin(x, 2), mesh:hmax(1)). Functions with a variable number of arguments
 * (mesh:cells(names...), lg.list) or that check their own arguments with their own message
 * (lg.lagrange, lg.unknown, lg.interpolate, ...) are not listed. */
typedef struct {
  const char *table; /* "lg", "lg.mesh", or a metatable name */
  const char *name;
  int max;
  const char *shown; /* the name in messages */
} arity;
static const arity arities[] = {
    
     {"lg", "coord", 1, "lg.coord"},
    {"lg", "normal", 0, "lg.normal"}, {"lg", "parameter", 2, "lg.parameter"}, {"lg", "sin", 1, "lg.sin"},
    {"lg", "cos", 1, "lg.cos"}, {"lg", "tan", 1, "lg.tan"}, {"lg", "exp", 1, "lg.exp"}, {"lg", "log", 1, "lg.log"},
    {"lg", "sqrt", 1, "lg.sqrt"}, {"lg", "abs", 1, "lg.abs"}, {"lg", "tanh", 1, "lg.tanh"}, {"lg", "sinh", 1, "lg.sinh"},
    {"lg", "cosh", 1, "lg.cosh"}, {"lg", "atan", 1, "lg.atan"}, {"lg", "asin", 1, "lg.asin"}, {"lg", "acos", 1, "lg.acos"},
    {"lg", "sign", 1, "lg.sign"}, {"lg", "pow", 2, "lg.pow"}, {"lg", "grad", 1, "lg.grad"}, {"lg", "div", 1, "lg.div"},
    {"lg", "dot", 2, "lg.dot"}, {"lg", "inner", 2, "lg.inner"}, {"lg", "dx", 2, "lg.dx"}, {"lg", "diff", 2, "lg.diff"},
    {"lg", "integral", 3, "lg.integral"}, {"lg", "essential_bc", 2, "lg.essential_bc"},
    {"lg", "integrate", 3, "lg.integrate"}, {"lg", "outer", 2, "lg.outer"}, {"lg", "cross", 2, "lg.cross"},
    {"lg", "identity", 1, "lg.identity"}, 
    
     {"lg", "linear_problem", 1, "lg.linear_problem"},
    {"lg", "nonlinear_problem", 1, "lg.nonlinear_problem"}, {"lg", "options", 1, "lg.options"}, {"lg", "jit", 2, "lg.jit"},
    {"lg", "jit_status", 1, "lg.jit_status"}, {"lg", "stats", 0, "lg.stats"}, {"lg", "wtime", 0, "lg.wtime"},
    {"lg", "rank", 0, "lg.rank"}, {"lg", "size", 0, "lg.size"}, {"lg", "allreduce", 2, "lg.allreduce"},
    {"lg", "control", 5, "lg.control"}, {"lg", "functional", 1, "lg.functional"},
    {"lg", "reduced_functional", 1, "lg.reduced_functional"}, {"lg", "taylor_test", 4, "lg.taylor_test"},
    {"lg", "minimize", 2, "lg.minimize"}, {"lg", "kkt_problem", 1, "lg.kkt_problem"}, {"lg", "series", 2, "lg.series"},
    {"lg.mesh", "interval", 1, "lg.mesh.interval"}, {"lg.mesh", "rectangle", 1, "lg.mesh.rectangle"},
    {"lg.mesh", "box", 1, "lg.mesh.box"}, {"lg.mesh", "read", 1, "lg.mesh.read"}, {"lg.mesh", "new", 1, "lg.mesh.new"},
    {MT_MESH, "vertices", 1, "mesh:vertices"}, {MT_MESH, "info", 0, "mesh:info"}, {MT_MESH, "write", 3, "mesh:write"},
    {MT_MESH, "refine", 0, "mesh:refine"}, {MT_MESH, "copy", 0, "mesh:copy"}, {MT_MESH, "hmax", 0, "mesh:hmax"},
    {MT_MESH, "check", 0, "mesh:check"}, {MT_MESH, "nvertices", 0, "mesh:nvertices"}, {MT_MESH, "ncells", 0, "mesh:ncells"},
    {MT_MESH, "dim", 0, "mesh:dim"}, {MT_MESH, "quality", 2, "mesh:quality"}, {MT_MESH, "quality_report", 1, "mesh:quality_report"},
    {MT_MESH, "untangle", 1, "mesh:untangle"}, {MT_MESH, "smooth", 1, "mesh:smooth"}, {MT_MESH, "move", 1, "mesh:move"},
    {MT_MESH, "displace", 1, "mesh:displace"}, {MT_QARRAY, "totable", 0, "q:totable"}, {MT_QARRAY, "min", 0, "q:min"},
    {MT_QARRAY, "max", 0, "q:max"}, {MT_QARRAY, "mean", 0, "q:mean"}, {MT_QARRAY, "histogram", 3, "q:histogram"},
    {MT_QARRAY, "worst", 1, "q:worst"}, {MT_FUNC, "values", 0, "f:values"}, {MT_FUNC, "assign", 1, "f:assign"},
    {MT_FUNC, "ndof", 0, "f:ndof"}, {MT_FUNC, "degree", 0, "f:degree"}, {MT_FUNC, "eval", 1, "f:eval"},
    {MT_FUNC, "dof_coordinates", 0, "f:dof_coordinates"}, {MT_PROB, "solve", 1, "problem:solve"},
    {MT_PROB, "size", 0, "problem:size"}, {MT_PROB, "sensitivity", 1, "problem:sensitivity"},
    {MT_REDUCED, "value", 1, "rf:value"}, {MT_REDUCED, "derivative", 2, "rf:derivative"},
    {MT_REDUCED, "gradient", 2, "rf:gradient"}, {MT_REDUCED, "hessian", 3, "rf:hessian"}, {MT_REDUCED, "state", 0, "rf:state"},
    {MT_REDUCED, "stats", 0, "rf:stats"}, {"lg", "time_problem", 1, "lg.time_problem"}, {MT_TIME, "solve", 0, "step:solve"},
    {MT_TIME, "times", 0, "step:times"},
    {NULL, NULL, 0, NULL}};

static int checked_call(lua_State *L) {
  int max = (int)lua_tointeger(L, lua_upvalueindex(2)), self = (int)lua_tointeger(L, lua_upvalueindex(4));
  int n = lua_gettop(L) - self;
  if (n > max) {
    const char *nm = lua_tostring(L, lua_upvalueindex(3));
    if (max == 0) return luaL_error(L, "%s: takes no arguments, got %d", nm, n);
    return luaL_error(L, "%s: takes at most %d argument%s, got %d (argument #%d is extra)", nm, max, max == 1 ? "" : "s", n,
                      max + 1);
  }
  return lua_tocfunction(L, lua_upvalueindex(1))(L);
}

/* luaL_setfuncs(L, lib, 0) into the table on top, the functions of `table` listed above
 * wrapped by their argument count check, and the collective ones by the check that every
 * rank makes them (lparallel.c) */
void set_funcs_checked(lua_State *L, const luaL_Reg *lib, const char *table) {
  int self = strcmp(table, "lg") && strcmp(table, "lg.mesh");
  for (; lib->name; lib++) {
    const arity *a = NULL;
    for (const arity *r = arities; r->table && !a; r++)
      if (!strcmp(r->table, table) && !strcmp(r->name, lib->name)) a = r;
    if (!a) lua_pushcfunction(L, lib->func);
    else {
      lua_pushcfunction(L, lib->func);
      lua_pushinteger(L, a->max);
      lua_pushstring(L, a->shown);
      lua_pushinteger(L, self);
      lua_pushcclosure(L, checked_call, 4);
    }
    lg_lua_collective_wrap(L, table, lib->name);
    lua_setfield(L, -2, lib->name);
  }
}

void new_mt(lua_State *L, const char *name, const luaL_Reg *mm, const luaL_Reg *methods) {
  luaL_newmetatable(L, name);
  if (mm) luaL_setfuncs(L, mm, 0);
  if (methods) {
    lua_newtable(L);
    set_funcs_checked(L, methods, name);
    lua_pushvalue(L, -1);
    lua_setfield(L, -3, "methods");
    if (lua_getfield(L, -2, "__index") == LUA_TNIL) {
      lua_pop(L, 1);
      lua_setfield(L, -2, "__index");
    } else lua_pop(L, 2);
  }
  lua_pop(L, 1);
}

void push_functions_of(lua_State *L, int owner, lg_function **f, int n) {
  owner = lua_absindex(L, owner);
  int top = lua_gettop(L), mesh_idx = 0;
  /* the mesh among the owner's dependencies anchors the new functions */
  if (lua_getiuservalue(L, owner, 1) == LUA_TTABLE) {
    lua_pushnil(L);
    while (lua_next(L, -2)) {
      lua_pop(L, 1);
      ud_mesh *um = luaL_testudata(L, -1, MT_MESH);
      if (um && n > 0 && um->lm == f[0]->mesh) { mesh_idx = lua_gettop(L); break; }
    }
  }
  for (int a = 0; a < n; a++) {
    if (mesh_idx) push_function(L, f[a], mesh_idx);
    else {
      ud_func *uf = new_ud(L, sizeof *uf, MT_FUNC, 0, NULL);
      uf->f = f[a];
    }
  }
  /* keep the n functions, drop the helpers below them */
  int extra = lua_gettop(L) - top - n;
  for (int a = 0; a < n; a++) lua_copy(L, top + extra + 1 + a, top + 1 + a);
  lua_settop(L, top + n);
}
