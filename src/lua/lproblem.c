/* lproblem.c — Lua bindings of the assembly layer: discrete functions (lg.function,
 * lg.interpolate), linear and nonlinear problems, PETSc options and the JIT. */
#include "largs.h"

#include <lauxlib.h>
#include <limits.h>
#include <math.h>
#include <petscsys.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static int func_gc(lua_State *L) {
  ud_func *u = lua_touserdata(L, 1);
  if (!u->f) return 0;
  lua_getfield(L, LUA_REGISTRYINDEX, "lugal.env");
  ud_env *ue = lua_touserdata(L, -1);
  lua_pop(L, 1);
  if (ue && ue->env) {
    expr_func_forget_user(ue->env->c, u->f->fid);
  }
  lg_function_free(u->f);
  u->f = NULL;
  return 0;
}

/* a distributed function's values or dof coordinates (w per dof) over the whole mesh */
static int push_gathered(lua_State *L, ud_func *u, int coords, const char *fn) {
  lg_env *env = get_env(L);
  double *v;
  long n;
  if (lg_function_gather(env, u->f, coords, &v, &n)) return lgerror(L, fn, env);
  int w = coords ? u->f->mesh->m->dim : 1;
  lua_createtable(L, n < INT_MAX ? (int)n : 0, 0);
  for (long i = 0; i < n; i++) {
    if (coords) {
      lua_createtable(L, w, 0);
      for (int j = 0; j < w; j++) { lua_pushnumber(L, v[(size_t)i * (size_t)w + (size_t)j]); lua_rawseti(L, -2, j + 1); }
    } else lua_pushnumber(L, v[i]);
    lua_rawseti(L, -2, i + 1);
  }
  free(v);
  return 1;
}

static int func_values(lua_State *L) {
  ud_func *u = check_func(L, 1, "f:values");
  if (u->f->mesh->dist) return push_gathered(L, u, 0, "f:values");
  lua_createtable(L, u->f->dm->ndof, 0);
  for (int i = 0; i < u->f->dm->ndof; i++) { lua_pushnumber(L, u->f->x[i]); lua_rawseti(L, -2, i + 1); }
  return 1;
}

/* a table given to f:assign is a vector expression ({e1, e2[, e3]}: as many entries as
 * the function has components, or any entry not a number), else the dof values */
static int table_is_vector_expr(lua_State *L, int idx, int ncomp) {
  lua_Integer n = luaL_len(L, idx);
  if (ncomp > 1 && n == ncomp) return 1;
  for (lua_Integer i = 1; i <= n; i++) {
    int number = lua_geti(L, idx, i) == LUA_TNUMBER;
    lua_pop(L, 1);
    if (!number) return 1;
  }
  return 0;
}

static int func_assign(lua_State *L) {
  ud_func *u = check_func(L, 1, "f:assign");
  ud_func *g = luaL_testudata(L, 2, MT_FUNC);
  if (lua_istable(L, 2) && table_is_vector_expr(L, 2, u->f->dm->bs)) {
    lg_env *env = get_env(L);
    expr *e = check_expr(L, 2, "f:assign");
    if (lg_interpolate(env, u->f, e)) return lgerror(L, "f:assign", env);
    return 0;
  }
  if (g) {
    if (g->f->dm != u->f->dm)
      return luaL_error(L, "f:assign: argument 1 must be a discrete function of the same basis and mesh");
    memcpy(u->f->x, g->f->x, sizeof(double) * (size_t)u->f->dm->ndof);
    return 0;
  }
  if (lua_istable(L, 2) && u->f->mesh->dist) {
    /* the whole function's values in f:values()'s order */
    lua_Integer n = luaL_len(L, 2);
    double *v = lua_newuserdatauv(L, sizeof(double) * ((size_t)(n > 0 ? n : 0) + 1), 0);
    for (lua_Integer i = 1; i <= n; i++) {
      lua_geti(L, 2, i);
      int isnum;
      v[i - 1] = lua_tonumberx(L, -1, &isnum);
      if (!isnum) return luaL_error(L, "f:assign: entry %I of the table must be a number, got %s", i, luaL_typename(L, -1));
      if (!isfinite(v[i - 1])) return luaL_error(L, "f:assign: entry %I of the table is not finite (%f)", i, v[i - 1]);
      lua_pop(L, 1);
    }
    lg_env *env = get_env(L);
    if (lg_function_assign_whole(env, u->f, v, (long)n)) return lgerror(L, "f:assign", env);
    return 0;
  }
  if (lua_istable(L, 2)) {
    int n = (int)luaL_len(L, 2);
    if (n != u->f->dm->ndof) return luaL_error(L, "f:assign: the table has %d values, the function %d dofs", n, u->f->dm->ndof);
    for (int i = 1; i <= n; i++) {
      lua_geti(L, 2, i);
      int isnum;
      double v = lua_tonumberx(L, -1, &isnum);
      if (!isnum) return luaL_error(L, "f:assign: entry %d of the table must be a number, got %s", i, luaL_typename(L, -1));
      if (!isfinite(v)) return luaL_error(L, "f:assign: entry %d of the table is not finite (%f)", i, v);
      u->f->x[i - 1] = v;
      lua_pop(L, 1);
    }
    return 0;
  }
  lg_env *env = get_env(L);
  expr *e = check_expr(L, 2, "f:assign");
  if (lg_interpolate(env, u->f, e)) return lgerror(L, "f:assign", env);
  return 0;
}

static int func_ndof(lua_State *L) {
  ud_func *u = check_func(L, 1, "f:ndof");
  lg_env *env = get_env(L);
  long n = lg_function_global_ndof(env, u->f); /* the whole mesh's, on a distributed one too */
  if (n < 0) return lgerror(L, "f:ndof", env);
  lua_pushinteger(L, n);
  return 1;
}

static int func_degree(lua_State *L) { lua_pushinteger(L, check_func(L, 1, "f:degree")->f->degree); return 1; }

static int func_index(lua_State *L) {
  if (lua_type(L, 2) == LUA_TSTRING) {
    luaL_getmetatable(L, MT_FUNC);
    lua_getfield(L, -1, "methods");
    lua_getfield(L, -1, lua_tostring(L, 2));
    if (!lua_isnil(L, -1)) return 1;
    return luaL_error(L, "discrete functions have no field '%s'", lua_tostring(L, 2));
  }
  ud_func *u = check_func(L, 1, "index");
  int n = u->f->dm->bs;
  if (n == 1) return luaL_error(L, "a scalar discrete function cannot be indexed");
  lua_Integer i = luaL_checkinteger(L, 2);
  if (i < 1 || i > n) return luaL_error(L, "index %I out of range 1..%d", i, n);
  unsigned char z[3] = {0, 0, 0};
  int deps[1] = {1};
  push_expr(L, expr_field(get_env(L)->c, u->f->fid, (int)i - 1, z), 1, deps, "index");
  return 1;
}

static int func_len(lua_State *L) {
  ud_func *u = check_func(L, 1, "#");
  lua_pushinteger(L, u->f->dm->bs > 1 ? u->f->dm->bs : 0);
  return 1;
}

/* uh(x, y[, z]): the value at a point (a vector function returns its components) */
/* f at point x into out; a distributed mesh's ranks whose part holds the point answer (the
 * same value up to rounding at a shared facet: their mean); 1 with env->err when none does */
static int eval_at(lg_env *env, const lg_function *f, const double *x, double *out) {
  if (!f->mesh->dist) return lg_eval_point(env, (lg_function *)f, x, out);
  int bs = f->dm->bs;
  double r[FEM_MAXBS + 1] = {0};
  if (!lg_eval_point(env, (lg_function *)f, x, out)) {
    for (int j = 0; j < bs; j++) r[j] = out[j];
    r[bs] = 1;
  }
  if (lg_allreduce(r, bs + 1, LG_SUM)) { lg_seterr(env, "the sum over the ranks failed"); return 1; }
  if (r[bs] == 0) {
    lg_seterr(env, "the point (%g, %g, %g) is in no rank's part of the mesh: outside the mesh", x[0], x[1], x[2]);
    return 1;
  }
  for (int j = 0; j < bs; j++) out[j] = r[j] / r[bs];
  return 0;
}

static int func_call(lua_State *L) {
  ud_func *u = check_func(L, 1, "f(x, y)");
  int dim = u->f->mesh->m->dim, n = lua_gettop(L) - 1;
  if (n != dim) return luaL_error(L, "f(x, y%s): give the %d coordinates of a point, got %d arguments", dim == 3 ? ", z" : "", dim, n);
  double x[3] = {0, 0, 0}, out[FEM_MAXBS];
  for (int k = 0; k < dim; k++) {
    x[k] = luaL_checknumber(L, k + 2);
    if (!isfinite(x[k])) return luaL_error(L, "f(x, y): coordinate %d is not finite (%f)", k + 1, x[k]);
  }
  lg_env *env = get_env(L);
  if (eval_at(env, u->f, x, out)) return lgerror(L, "f(x, y)", env);
  for (int j = 0; j < u->f->dm->bs; j++) lua_pushnumber(L, out[j]);
  return u->f->dm->bs;
}

/* f:eval({{x, y}, ...}): the values at many points (tables of components for a vector) */
static int func_eval(lua_State *L) {
  const char *fn = "f:eval";
  ud_func *u = check_func(L, 1, fn);
  if (!lua_istable(L, 2)) return typeerror(L, fn, 1, "a table of points {{x, y}, ...}");
  int dim = u->f->mesh->m->dim, bs = u->f->dm->bs;
  lua_Integer n = luaL_len(L, 2);
  lua_createtable(L, n > 0 && n < INT_MAX ? (int)n : 0, 0);
  lg_env *env = get_env(L);
  for (lua_Integer i = 1; i <= n; i++) {
    lua_geti(L, 2, i);
    if (!lua_istable(L, -1) || luaL_len(L, -1) != dim) return luaL_error(L, "%s: point %I must be a table of %d coordinates", fn, i, dim);
    double x[3] = {0, 0, 0}, out[FEM_MAXBS];
    for (int k = 0; k < dim; k++) {
      lua_geti(L, -1, k + 1);
      int isnum;
      x[k] = lua_tonumberx(L, -1, &isnum);
      if (!isnum || !isfinite(x[k])) return luaL_error(L, "%s: coordinate %d of point %I must be a finite number", fn, k + 1, i);
      lua_pop(L, 1);
    }
    lua_pop(L, 1);
    if (eval_at(env, u->f, x, out)) return luaL_error(L, "%s: point %I: %s", fn, i, env->err);
    if (bs == 1) lua_pushnumber(L, out[0]);
    else {
      lua_createtable(L, bs, 0);
      for (int j = 0; j < bs; j++) { lua_pushnumber(L, out[j]); lua_rawseti(L, -2, j + 1); }
    }
    lua_rawseti(L, -2, i);
  }
  return 1;
}

/* f:dof_coordinates(): the point of every dof ({x, y} tables, in dof order) */
static int func_dof_coordinates(lua_State *L) {
  ud_func *u = check_func(L, 1, "f:dof_coordinates");
  if (u->f->mesh->dist) return push_gathered(L, u, 1, "f:dof_coordinates");
  const dofmap *dm = u->f->dm;
  int dim = dm->m->dim;
  lua_createtable(L, dm->ndof, 0);
  unsigned char *done = calloc((size_t)dm->ndof + 1, 1);
  if (!done) return luaL_error(L, "f:dof_coordinates: out of memory");
  for (int c = 0; c < dm->m->ncell; c++)
    for (int k = 0; k < dm->nloc; k++) {
      int g = dm->cell_dofs[(size_t)c * dm->nloc + k];
      if (done[g]) continue;
      done[g] = 1;
      double x[3];
      dofmap_node_coords(dm, c, k, x);
      lua_createtable(L, dim, 0);
      for (int j = 0; j < dim; j++) { lua_pushnumber(L, x[j]); lua_rawseti(L, -2, j + 1); }
      lua_rawseti(L, -2, g + 1);
    }
  free(done);
  return 1;
}

static int func_tostring(lua_State *L) {
  ud_func *u = check_func(L, 1, "tostring");
  expr_func_info *fi = expr_func_get(get_env(L)->c, u->f->fid);
  if (u->f->dm->bs > 1)
    lua_pushfstring(L, "discrete function %s (P%d, %d components, %d dofs)", fi ? fi->name : "?", u->f->degree, u->f->dm->bs,
                    u->f->dm->ndof);
  else lua_pushfstring(L, "discrete function %s (P%d, %d dofs)", fi ? fi->name : "?", u->f->degree, u->f->dm->ndof);
  return 1;
}

static int l_interpolate(lua_State *L) {
  gc_point(L, 0);
  const char *fn = "lg.interpolate";
  if (lua_gettop(L) > 4) return luaL_error(L, "%s: takes a basis, a mesh, an expression and a name, got %d arguments", fn, lua_gettop(L));
  ud_basis *b = luaL_testudata(L, 1, MT_BASIS);
  if (!b) return typeerror(L, fn, 1, "a basis (lg.lagrange(p))");
  ud_mesh *um = check_mesh(L, 2, fn);
  expr *e = check_expr(L, 3, fn);
  lg_env *env = get_env(L);
  const char *name = opt_cstring(L, 4, "f", fn, "argument 4 (the name)");
  lg_function *f = lg_function_new(env, um->lm, lg_mesh_dofmap(env, um->lm, b->degree, b->ncomp, b->disc), name);
  if (!f) return lgerror(L, fn, env);
  push_function(L, f, 2);
  if (lg_interpolate(env, f, e)) return lgerror(L, fn, env);
  return 1;
}

static int l_function(lua_State *L) {
  gc_point(L, 0);
  const char *fn = "lg.zero_function";
  if (lua_gettop(L) > 3) return luaL_error(L, "%s: takes a basis, a mesh and a name, got %d arguments", fn, lua_gettop(L));
  ud_basis *b = luaL_testudata(L, 1, MT_BASIS);
  if (!b) return typeerror(L, fn, 1, "a basis (lg.lagrange(p))");
  ud_mesh *um = check_mesh(L, 2, fn);
  lg_env *env = get_env(L);
  lg_function *f = lg_function_new(env, um->lm, lg_mesh_dofmap(env, um->lm, b->degree, b->ncomp, b->disc),
                                 opt_cstring(L, 3, "f", fn, "argument 3 (the name)"));
  if (!f) return lgerror(L, fn, env);
  push_function(L, f, 2);
  return 1;
}

/* the functions of kind listed under key of the table at t (one or a table); returns how many */
int check_symbols(lua_State *L, int t, const char *key, func_kind kind, int *ids, const char *fn) {
  int ty = lua_getfield(L, t, key);
  int n = 0;
  const char *what = kind == FK_TEST ? "a test function (lg.test) or a table of them" : "an unknown (lg.unknown) or a table of them";
  if (ty == LUA_TTABLE) {
    n = (int)luaL_len(L, -1);
    if (n < 1 || n > KER_MAXFIELD) luaL_error(L, "%s: option '%s' must list 1 to %d functions", fn, key, KER_MAXFIELD);
    for (int i = 1; i <= n; i++) {
      lua_geti(L, -1, i);
      ud_expr *u = luaL_testudata(L, -1, MT_EXPR);
      int f = u ? symbol_func(get_env(L), expr_of(L, u)) : -1;
      if (f < 0 || expr_func_get(get_env(L)->c, f)->kind != kind)
        luaL_error(L, "%s: option '%s' entry %d must be %s", fn, key, i, what);
      ids[i - 1] = f;
      lua_pop(L, 1);
    }
  } else {
    ud_expr *u = luaL_testudata(L, -1, MT_EXPR);
    int f = u ? symbol_func(get_env(L), expr_of(L, u)) : -1;
    if (f < 0 || expr_func_get(get_env(L)->c, f)->kind != kind)
      luaL_error(L, "%s: option '%s' must be %s, got %s", fn, key, what, ty == LUA_TNIL ? "nothing" : luaL_typename(L, -1));
    ids[0] = f;
    n = 1;
  }
  lua_pop(L, 1);
  for (int i = 0; i < n; i++)
    for (int j = 0; j < i; j++)
      if (ids[i] == ids[j])
        luaL_error(L, "%s: option '%s' lists %s twice (entries %d and %d): each %s appears once", fn, key,
                   expr_func_get(get_env(L)->c, ids[i])->name, j + 1, i + 1, kind == FK_TEST ? "test function" : "unknown");
  return n;
}

/* the essential conditions at idx (nil, one, or a table of them, combined into *owned) */
const form *check_bcs(lua_State *L, int idx, const char *fn, form **owned) {
  *owned = NULL;
  if (lua_isnil(L, idx)) return NULL;
  if (lua_istable(L, idx)) {
    form *f = form_new();
    if (!f) luaL_error(L, "%s: out of memory", fn);
    int n = (int)luaL_len(L, idx);
    for (int i = 1; i <= n; i++) {
      lua_geti(L, idx, i);
      ud_form *ub = luaL_testudata(L, -1, MT_BC);
      if (!ub) { form_free(f); luaL_error(L, "%s: option 'bc' entry %d must be lg.essential_bc(...)", fn, i); }
      for (int k = 0; k < ub->f->n; k++)
        if (form_add_term(f, &ub->f->t[k].reg, ub->f->t[k].integrand, -1)) { form_free(f); luaL_error(L, "%s: out of memory", fn); }
      lua_pop(L, 1);
    }
    return *owned = f;
  }
  ud_form *ub = luaL_testudata(L, idx, MT_BC);
  if (!ub) luaL_error(L, "%s: option 'bc' must be lg.essential_bc(...) or a table of them, got %s", fn, luaL_typename(L, idx));
  return ub->f;
}

/* the problem userdata for p, keeping the values at deps alive and the option 'initial' of
 * the table at 1 as its initial guess */
void push_problem(lua_State *L, lg_problem *p, int nfield, int nonlinear, int ndeps, const int *deps) {
  ud_prob *u = new_ud(L, sizeof *u, MT_PROB, ndeps, deps);
  u->p = p;
  u->nfield = nfield;
  u->nonlinear = nonlinear;
  lua_getfield(L, 1, "initial");
  lua_getiuservalue(L, -2, 1);
  lua_insert(L, -2);
  lua_setfield(L, -2, "__initial");
  lua_pop(L, 1);
}

lg_problem *problem_from_table(lua_State *L, const char *fn, int nonlinear, const char *const *keys, int *nfield, int *deps,
                               int *ndeps) {
  if (!lua_istable(L, 1)) typeerror(L, fn, 1, "a table {mesh=, eqn=, bc=, test=, unknown=}");
  check_keys(L, 1, fn, keys);
  lua_getfield(L, 1, "mesh");
  ud_mesh *um = luaL_testudata(L, -1, MT_MESH);
  if (!um) luaL_error(L, "%s: option 'mesh' must be a mesh, got %s", fn, luaL_typename(L, -1));
  int mesh_idx = lua_gettop(L);
  lua_getfield(L, 1, "eqn");
  ud_form *ue = luaL_testudata(L, -1, MT_FORM);
  if (!ue) luaL_error(L, "%s: option 'eqn' must be a form (lg.integral(...) + ...), got %s", fn,
                             luaL_testudata(L, -1, MT_BC) ? "a boundary condition" : luaL_typename(L, -1));
  int eqn_idx = lua_gettop(L);
  int test[KER_MAXFIELD], unk[KER_MAXFIELD];
  int nt = check_symbols(L, 1, "test", FK_TEST, test, fn);
  int nu = check_symbols(L, 1, "unknown", FK_UNKNOWN, unk, fn);
  if (nt != nu) luaL_error(L, "%s: %d test functions for %d unknowns", fn, nt, nu);
  lua_getfield(L, 1, "symmetric");
  int sym = lua_toboolean(L, -1);
  lua_pop(L, 1);
  const char *prefix = opt_str(L, 1, "prefix", NULL, fn);
  /* nullspace = an unknown (its constants), a table of them, or "rigid" */
  int nnull = 0, null_fields[KER_MAXFIELD], rigid = 0;
  int nty = lua_getfield(L, 1, "nullspace");
  lua_pop(L, 1);
  if (nty == LUA_TSTRING) {
    lua_getfield(L, 1, "nullspace");
    const char *k = lua_tostring(L, -1);
    if (strcmp(k, "rigid")) luaL_error(L, "%s: option 'nullspace' must be an unknown, a table of unknowns or \"rigid\", got \"%s\"", fn, k);
    lua_pop(L, 1);
    rigid = 1;
  } else if (nty != LUA_TNIL) {
    nnull = check_symbols(L, 1, "nullspace", FK_UNKNOWN, null_fields, fn);
    for (int i = 0; i < nnull; i++) {
      int found = 0;
      for (int j = 0; j < nu; j++) found |= unk[j] == null_fields[i];
      if (!found) luaL_error(L, "%s: option 'nullspace' lists %s, which is not one of the unknowns", fn, expr_func_get(get_env(L)->c, null_fields[i])->name);
    }
  }
  /* last: what raises an error after this frees bc_owned first */
  lua_getfield(L, 1, "bc");
  int bc_idx = lua_gettop(L);
  form *bc_owned = NULL;
  const form *bcf = check_bcs(L, bc_idx, fn, &bc_owned);
  for (int i = 0; ue && i < ue->f->n; i++)
    if (ue->f->t[i].reg.mesh != um->lm) { form_free(bc_owned); luaL_error(L, "%s: the equation integrates over a different mesh than 'mesh'", fn); }
  for (int i = 0; bcf && i < bcf->n; i++)
    if (bcf->t[i].reg.mesh != um->lm) { form_free(bc_owned); luaL_error(L, "%s: a boundary condition is on a different mesh than 'mesh'", fn); }
  lg_env *env = get_env(L);
  lg_problem_spec s = {um->lm, ue->f, bcf, nt, test, unk, nonlinear, sym, prefix, nnull, null_fields, rigid};
  lg_problem *p = lg_problem_new(env, &s);
  form_free(bc_owned);
  if (!p) lgerror(L, fn, env);
  deps[0] = mesh_idx;
  deps[1] = eqn_idx;
  deps[2] = bc_idx;
  *ndeps = lua_isnil(L, bc_idx) ? 2 : 3;
  *nfield = nt;
  return p;
}

static int make_problem(lua_State *L, int nonlinear) {
  gc_point(L, 1);
  const char *fn = nonlinear ? "lg.nonlinear_problem" : "lg.linear_problem";
  static const char *const keys[] = {"mesh", "eqn", "bc", "test", "unknown", "initial", "symmetric", "prefix", "nullspace", NULL};
  int nt, deps[3], ndeps;
  lg_problem *p = problem_from_table(L, fn, nonlinear, keys, &nt, deps, &ndeps);
  push_problem(L, p, nt, nonlinear, ndeps, deps);
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
  gc_point(L, 1);
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
    } else return typeerror(L, fn, init_idx, u->nfield == 1 ? "a discrete function (initial guess)" : "a table of discrete functions (initial guesses, one per unknown)");
  }
  lg_function *out[KER_MAXFIELD];
  lg_solve_info info;
  if (lg_problem_solve(env, u->p, init, out, &info)) return lgerror(L, fn, env);
  int base = lua_gettop(L);
  push_functions_of(L, 1, out, u->nfield);
  /* info table */
  push_info_table(L, 8);
  lua_pushinteger(L, info.iterations); lua_setfield(L, -2, "iterations");
  lua_pushinteger(L, info.linear_iterations); lua_setfield(L, -2, "linear_iterations");
  lua_pushstring(L, info.reason); lua_setfield(L, -2, "reason");
  lua_pushstring(L, info.solver); lua_setfield(L, -2, "solver");
  lua_pushnumber(L, info.assemble_ms); lua_setfield(L, -2, "assemble_ms");
  lua_pushnumber(L, info.solve_ms); lua_setfield(L, -2, "solve_ms");
  lua_createtable(L, info.nres, 0);
  for (int i = 0; i < info.nres; i++) { lua_pushnumber(L, info.res[i]); lua_rawseti(L, -2, i + 1); }
  lua_setfield(L, -2, "residuals");
  lua_pushinteger(L, lg_problem_global_size(u->p)); lua_setfield(L, -2, "dofs");
  return lua_gettop(L) - base;
}

/* problem:sensitivity(a): du/da at the last solution, a discrete function per unknown */
static int prob_sensitivity(lua_State *L) {
  const char *fn = "problem:sensitivity";
  ud_prob *u = luaL_checkudata(L, 1, MT_PROB);
  ud_expr *ue = luaL_testudata(L, 2, MT_EXPR);
  if (!ue || expr_of(L, ue)->kind != E_PARAM) return typeerror(L, fn, 2, "a parameter (lg.parameter)");
  lg_env *env = get_env(L);
  int N = lg_problem_size(u->p);
  double *du = lua_newuserdatauv(L, sizeof(double) * ((size_t)N + 1), 0);
  if (lg_sensitivity(env, u->p, ue->e->i0, du)) return lgerror(L, fn, env);
  lg_field_info fi[KER_MAXFIELD];
  int nf = lg_problem_fields(u->p, fi);
  lg_function *out[KER_MAXFIELD];
  for (int a = 0; a < nf; a++) {
    expr_func_info *info = expr_func_get(env->c, fi[a].unknown);
    char nm[80];
    snprintf(nm, sizeof nm, "d%s_d%s", info ? info->name : "u", expr_param_name(env->c, ue->e->i0));
    out[a] = lg_function_new(env, lg_problem_mesh(u->p), (dofmap *)fi[a].dm, nm);
    if (!out[a]) return lgerror(L, fn, env);
    memcpy(out[a]->x, du + fi[a].offset, sizeof(double) * (size_t)fi[a].dm->ndof);
  }
  push_functions_of(L, 1, out, nf);
  return nf;
}

int push_dense_matrix(lua_State *L, lg_problem *p, const char *fn) {
  int n = lg_problem_global_size(p);
  if (n > 2000) return luaL_error(L, "%s: the dense matrix is for small problems (n <= 2000, this one has %d)", fn, n);
  double *d = malloc(sizeof(double) * (size_t)n * n);
  if (!d) return luaL_error(L, "%s: out of memory", fn);
  lg_env *env = get_env(L);
  if (lg_problem_dense_matrix(env, p, d, n)) { free(d); return lgerror(L, fn, env); }
  lua_createtable(L, n, 0);
  for (int i = 0; i < n; i++) {
    lua_createtable(L, n, 0);
    for (int j = 0; j < n; j++) { lua_pushnumber(L, d[(size_t)i * n + j]); lua_rawseti(L, -2, j + 1); }
    lua_rawseti(L, -2, i + 1);
  }
  free(d);
  return 1;
}

static int prob_matrix(lua_State *L) {
  ud_prob *u = luaL_checkudata(L, 1, MT_PROB);
  return push_dense_matrix(L, u->p, "problem:matrix");
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
  lua_pushinteger(L, lg_problem_global_size(u->p)); /* the whole problem's, distributed or not */
  return 1;
}

/* problem:ownership(): {rows = this rank's rows, ghosts = the other ranks' columns they read} */
static int prob_ownership(lua_State *L) {
  ud_prob *u = luaL_checkudata(L, 1, MT_PROB);
  int rows;
  long ghosts;
  lg_problem_ownership(u->p, &rows, &ghosts);
  lua_createtable(L, 0, 2);
  lua_pushinteger(L, rows); lua_setfield(L, -2, "rows");
  lua_pushinteger(L, ghosts); lua_setfield(L, -2, "ghosts");
  return 1;
}

static int l_options(lua_State *L) {
  const char *s = check_cstring(L, 1, "lg.options", "argument 1");
  if (PetscOptionsInsertString(NULL, s)) return luaL_error(L, "lg.options: PETSc could not parse \"%s\"", s);
  return 0;
}

/* lg.jit("tcc" | "cc" | "auto"[, {tier_ms = }]): the compiler of kernels built from now on */
static int l_jit(lua_State *L) {
  const char *fn = "lg.jit";
  if (lua_type(L, 1) != LUA_TSTRING) return typeerror(L, fn, 1, "\"tcc\", \"cc\" or \"auto\"");
  const char *b = check_cstring(L, 1, fn, "argument 1");
  lg_env *env = get_env(L);
  jit_backend kind;
  if (!strcmp(b, "tcc")) kind = JIT_TCC;
  else if (!strcmp(b, "cc")) kind = JIT_CC;
  else if (!strcmp(b, "auto")) kind = JIT_AUTO;
  else return luaL_error(L, "%s: argument 1 must be \"tcc\", \"cc\" or \"auto\", got \"%s\"", fn, b);
  if (!lua_isnoneornil(L, 2)) {
    if (!lua_istable(L, 2)) return typeerror(L, fn, 2, "an options table {tier_ms=}");
    static const char *const keys[] = {"tier_ms", NULL};
    check_keys(L, 2, fn, keys);
    double ms = opt_num(L, 2, "tier_ms", JIT_TIER_MS, fn);
    if (!(ms >= 0) || !isfinite(ms)) return luaL_error(L, "%s: option 'tier_ms' must be a finite number >= 0", fn);
    jit_set_tier_ms(env->jit, ms);
  }
  jit_set_backend(env->jit, kind);
  return 0;
}

/* lg.jit_status([wait]): kernels per tier {tcc=, compiling=, cc=, stays=}; with wait = true,
 * first waits for the background builds */
static int l_jit_status(lua_State *L) {
  lg_env *env = get_env(L);
  if (!lua_isnoneornil(L, 1) && !lua_isboolean(L, 1)) return typeerror(L, "lg.jit_status", 1, "a boolean (wait)");
  if (lua_toboolean(L, 1)) jit_wait(env->jit);
  int c[4];
  jit_tiers(env->jit, c);
  lua_createtable(L, 0, 4);
  static const char *const names[] = {"tcc", "compiling", "cc", "stays"};
  for (int t = 0; t < 4; t++) { lua_pushinteger(L, c[t]); lua_setfield(L, -2, names[t]); }
  return 1;
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
  /* the point caches (kernel.h): live groups, their bytes, assemblies by mode */
  lua_Integer ng = 0, nb = 0;
  for (const kernel_pcache_group *g = env->pcache.next; g && g != &env->pcache; g = g->next) {
    ng++;
    nb += (lua_Integer)(g->n * sizeof(double));
  }
  lua_createtable(L, 0, 5);
  lua_pushinteger(L, ng); lua_setfield(L, -2, "groups");
  lua_pushinteger(L, nb); lua_setfield(L, -2, "bytes");
  static const char *const modes[] = {"computed", "stored", "read"};
  for (int i = 0; i < 3; i++) { lua_pushinteger(L, (lua_Integer)env->pcache_uses[i]); lua_setfield(L, -2, modes[i]); }
  lua_setfield(L, -2, "point_cache");
  return 1;
}

/* ---------------------------------------------------------------- registration */

void lg_lua_problem_register(lua_State *L) {
  static const luaL_Reg func_methods[] = {{"values", func_values}, {"assign", func_assign}, {"ndof", func_ndof},
                                          {"degree", func_degree}, {"eval", func_eval},
                                          {"dof_coordinates", func_dof_coordinates}, {NULL, NULL}};
  luaL_newmetatable(L, MT_FUNC);
  luaL_setfuncs(L, lg_arith_mm, 0);
  lua_pushcfunction(L, func_gc); lua_setfield(L, -2, "__gc");
  lua_pushcfunction(L, func_tostring); lua_setfield(L, -2, "__tostring");
  lua_pushcfunction(L, func_index); lua_setfield(L, -2, "__index");
  lua_pushcfunction(L, func_len); lua_setfield(L, -2, "__len");
  lua_pushcfunction(L, func_call); lua_setfield(L, -2, "__call");
  lua_newtable(L);
  set_funcs_checked(L, func_methods, MT_FUNC);
  lua_setfield(L, -2, "methods");
  lua_pop(L, 1);
  static const luaL_Reg prob_mm[] = {{"__gc", prob_gc}, {NULL, NULL}};
  static const luaL_Reg prob_methods[] = {{"solve", prob_solve}, {"matrix", prob_matrix}, {"assemble", prob_assemble},
                                          {"size", prob_size}, {"sensitivity", prob_sensitivity},
                                          {"ownership", prob_ownership}, {NULL, NULL}};
  new_mt(L, MT_PROB, prob_mm, prob_methods);
}

const luaL_Reg lg_problem_lib[] = {
    {"interpolate", l_interpolate}, {"zero_function", l_function}, {"function", l_function}, {"linear_problem", l_linear_problem},
    {"nonlinear_problem", l_nonlinear_problem}, {"options", l_options}, {"jit", l_jit}, {"jit_status", l_jit_status},
    {"stats", l_stats}, {"wtime", l_wtime}, {NULL, NULL}};
