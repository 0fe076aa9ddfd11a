/* ltime.c — Lua bindings of time-dependent problems (problem/time.c): lg.time_problem and
 * step:solve(). Their reduced functionals are made by lg.reduced_functional (lopt.c). */
#include "largs.h"

#include <lauxlib.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static ud_time *check_time(lua_State *L, int idx, const char *fn) {
  ud_time *u = luaL_testudata(L, idx, MT_TIME);
  if (!u) typeerror(L, fn, idx, "a time-dependent problem (lg.time_problem)");
  return u;
}

lg_time *time_of(lua_State *L, int idx) {
  ud_time *u = luaL_testudata(L, idx, MT_TIME);
  return u ? u->T : NULL;
}

/* the discrete function at idx, or an error naming what it should be */
static lg_function *prev_function(lua_State *L, int idx, const char *fn, const char *what) {
  ud_func *f = luaL_testudata(L, idx, MT_FUNC);
  if (!f) luaL_error(L, "%s: %s must be a discrete function (lg.interpolate, lg.control), got %s", fn, what, luaL_typename(L, idx));
  return f->f;
}

/* option 'previous': one function (one unknown), a list of one per unknown, or levels:
 * {u0, u00} for one unknown, {{u0, p0}, {u00, p00}} for several; returns the levels */
static int read_previous(lua_State *L, int t, int nfield, lg_function *prev[LG_TIME_MAXLEV][KER_MAXFIELD], const char *fn) {
  lua_getfield(L, t, "previous");
  int v = lua_gettop(L), nlev = 1;
  if (luaL_testudata(L, v, MT_FUNC)) {
    if (nfield != 1) luaL_error(L, "%s: option 'previous' must list a previous state per unknown (%d)", fn, nfield);
    prev[0][0] = prev_function(L, v, fn, "option 'previous'");
  } else if (lua_istable(L, v)) {
    int n = (int)luaL_len(L, v);
    lua_geti(L, v, 1);
    int nested = lua_istable(L, -1) && !luaL_testudata(L, -1, MT_FUNC);
    lua_pop(L, 1);
    if (nfield == 1 && !nested) { /* {u0} or {u0, u00}: levels of the one unknown */
      if (n < 1 || n > LG_TIME_MAXLEV) luaL_error(L, "%s: option 'previous' lists 1 or %d previous states, got %d", fn, LG_TIME_MAXLEV, n);
      nlev = n;
      for (int j = 0; j < n; j++) {
        lua_geti(L, v, j + 1);
        prev[j][0] = prev_function(L, -1, fn, "each entry of option 'previous'");
        lua_pop(L, 1);
      }
    } else if (!nested) { /* one level, a function per unknown */
      if (n != nfield) luaL_error(L, "%s: option 'previous' must list %d previous states (one per unknown), got %d", fn, nfield, n);
      for (int a = 0; a < n; a++) {
        lua_geti(L, v, a + 1);
        prev[0][a] = prev_function(L, -1, fn, "each entry of option 'previous'");
        lua_pop(L, 1);
      }
    } else {
      if (n < 1 || n > LG_TIME_MAXLEV) luaL_error(L, "%s: option 'previous' lists 1 or %d levels, got %d", fn, LG_TIME_MAXLEV, n);
      nlev = n;
      for (int j = 0; j < n; j++) {
        lua_geti(L, v, j + 1);
        if (!lua_istable(L, -1) || (int)luaL_len(L, -1) != nfield)
          luaL_error(L, "%s: level %d of option 'previous' must list %d previous states (one per unknown)", fn, j + 1, nfield);
        for (int a = 0; a < nfield; a++) {
          lua_geti(L, -1, a + 1);
          prev[j][a] = prev_function(L, -1, fn, "each entry of option 'previous'");
          lua_pop(L, 1);
        }
        lua_pop(L, 1);
      }
    }
  } else
    luaL_error(L, "%s: option 'previous' is required: the discrete function(s) holding the state before each step, got %s", fn,
               luaL_typename(L, v));
  lua_pop(L, 1);
  return nlev;
}

/* before_step(k, t): the script's function, called on a thread of its own (the hook runs
 * inside C calls made from any thread); an error in it stops the march with its message */
static int before_step(lg_env *env, void *ud, int k, double t) {
  ud_time *u = ud;
  lua_State *L = u->hook_L;
  lua_rawgeti(L, LUA_REGISTRYINDEX, u->hook_ref);
  lua_pushinteger(L, k);
  lua_pushnumber(L, t);
  if (lua_pcall(L, 2, 0, 0) != LUA_OK) {
    lg_seterr(env, "before_step(%d, %g): %s", k, t, lua_tostring(L, -1) ? lua_tostring(L, -1) : "an error");
    lua_settop(L, 0);
    return 1;
  }
  lua_settop(L, 0);
  return 0;
}

/* lg.time_problem{mesh=, test=, unknown=, previous=, eqn=, bc=, dt=, t0=, t1= | steps=,
 * time=, nonlinear=, symmetric=, prefix=, output=, every=, monitor=} */
static int l_time_problem(lua_State *L) {
  gc_point(L, 1);
  const char *fn = "lg.time_problem";
  if (!lua_istable(L, 1)) return typeerror(L, fn, 1, "a table {mesh=, eqn=, test=, unknown=, previous=, dt=, t1=}");
  static const char *const keys[] = {"mesh", "eqn", "bc", "test", "unknown", "symmetric", "prefix", "nullspace", "previous", "dt",
                                     "t0", "t1", "steps", "time", "nonlinear", "output", "every", "monitor", "before_step", NULL};
  check_keys(L, 1, fn, keys);
  lua_getfield(L, 1, "dt");
  int have_dt = !lua_isnil(L, -1);
  lua_getfield(L, 1, "t1");
  int have_t1 = !lua_isnil(L, -1);
  lua_pop(L, 2);
  if (!have_dt) return luaL_error(L, "%s: option 'dt' (the time step) is required, a positive number", fn);
  double dt = opt_num(L, 1, "dt", 1, fn), t0 = opt_num(L, 1, "t0", 0, fn), t1 = opt_num(L, 1, "t1", 0, fn);
  if (!(dt > 0)) return luaL_error(L, "%s: option 'dt' must be a positive number, got %f", fn, dt);
  int steps = opt_int(L, 1, "steps", 0, fn);
  if (steps < 0) return luaL_error(L, "%s: option 'steps' must be a positive whole number, got %d", fn, steps);
  if (have_t1 == (steps > 0)) return luaL_error(L, "%s: give the end time 't1' or the number of 'steps' (one of them)", fn);
  if (!steps) {
    double x = (t1 - t0) / dt;
    if (!(x >= 0.5) || fabs(x - nearbyint(x)) > 1e-9 * x || x > 1e8)
    {
      char why[160];
      snprintf(why, sizeof why, "t1 - t0 = %g must be a whole number of steps of dt = %g (got %.12g steps)", t1 - t0, dt, x);
      return luaL_error(L, "%s: %s", fn, why);
    }
    steps = (int)nearbyint(x);
  }
  int tparam = -1;
  if (lua_getfield(L, 1, "time") != LUA_TNIL) {
    ud_expr *ue = luaL_testudata(L, -1, MT_EXPR);
    if (!ue || expr_of(L, ue)->kind != E_PARAM)
      return luaL_error(L, "%s: option 'time' must be a parameter (lg.parameter), set to each step's time, got %s", fn,
                        ue ? "an expression" : luaL_typename(L, -1));
    tparam = expr_of(L, ue)->i0;
  }
  lua_pop(L, 1);
  lua_getfield(L, 1, "nonlinear");
  int nonlinear = lua_toboolean(L, -1);
  lua_pop(L, 1);
  int bty = lua_getfield(L, 1, "before_step");
  lua_pop(L, 1);
  if (bty != LUA_TNIL && bty != LUA_TFUNCTION)
    return luaL_error(L, "%s: option 'before_step' must be a function(k, t), got %s", fn, lua_typename(L, bty));
  lua_getfield(L, 1, "monitor");
  int monitor = lua_isnil(L, -1) ? 1 : lua_toboolean(L, -1);
  lua_pop(L, 1);
  const char *output = opt_str(L, 1, "output", NULL, fn);
  if (output && (strlen(output) < 5 || strcmp(output + strlen(output) - 4, ".pvd")))
    return luaL_error(L, "%s: option 'output' must be a path ending in .pvd, got \"%s\"", fn, output);
  int every = opt_int(L, 1, "every", steps >= 10 ? steps / 10 : 1, fn);
  if (every < 1) return luaL_error(L, "%s: option 'every' must be >= 1, got %d", fn, every);
  /* the unknowns' count first (previous is read against it), then the step problem */
  int ids[KER_MAXFIELD], nfield = check_symbols(L, 1, "unknown", FK_UNKNOWN, ids, fn);
  lg_time_spec s;
  memset(&s, 0, sizeof s);
  s.nlev = read_previous(L, 1, nfield, s.prev, fn);
  ud_time *u = new_ud(L, sizeof *u, MT_TIME, 0, NULL); /* anchors what is made below */
  int uidx = lua_gettop(L);
  if (output && !(u->output = strdup(output))) return luaL_error(L, "%s: out of memory", fn);
  int deps[3], ndeps, nf;
  u->p = problem_from_table(L, fn, nonlinear, keys, &nf, deps, &ndeps);
  u->nfield = nf;
  u->every = every;
  u->monitor = monitor;
  s.step = u->p;
  s.time_param = tparam;
  s.t0 = t0;
  s.dt = dt;
  s.nsteps = steps;
  lg_env *env = get_env(L);
  if (!(u->T = lg_time_new(env, &s))) return lgerror(L, fn, env);
  /* what it reads stays alive: the mesh, the forms, the previous functions */
  lua_newtable(L);
  for (int i = 0; i < ndeps; i++) {
    lua_pushvalue(L, deps[i]);
    lua_pushboolean(L, 1);
    lua_rawset(L, -3);
  }
  lua_getfield(L, 1, "previous");
  lua_setfield(L, -2, "__previous");
  if (bty == LUA_TFUNCTION) {
    u->hook_L = lua_newthread(L);
    lua_setfield(L, -2, "__before_step_thread");
    lua_getfield(L, 1, "before_step");
    u->hook_ref = luaL_ref(L, LUA_REGISTRYINDEX);
    lg_time_set_hook(u->T, before_step, u);
  }
  lua_setiuservalue(L, uidx, 1);
  lua_pushvalue(L, uidx);
  return 1;
}

static int time_gc(lua_State *L) {
  ud_time *u = lua_touserdata(L, 1);
  if (u->hook_L) luaL_unref(L, LUA_REGISTRYINDEX, u->hook_ref);
  u->hook_L = NULL;
  lg_time_free(u->T);
  lg_problem_free(u->p);
  free(u->output);
  u->T = NULL;
  u->p = NULL;
  u->output = NULL;
  return 0;
}

/* the fields of level 0 (the state after the last step) for output */
static int write_state(lg_env *env, ud_time *u, lg_series *s, int k) {
  mesh_field fl[KER_MAXFIELD];
  for (int a = 0; a < u->nfield; a++) {
    lg_function *f = lg_time_previous(u->T, 0, a);
    expr_func_info *fi = expr_func_get(env->c, f->fid);
    fl[a] = (mesh_field){fi ? fi->name : "u", f->dm->bs, f->dm->degree == 0, f->x};
  }
  return lg_series_write(env, s, lg_time_previous(u->T, 0, 0)->mesh, u->nfield, fl, lg_time_at(u->T, k));
}

/* step:solve(): the march from t0 to t1; the final state (new functions, one per unknown) and
 * {steps=, iterations=, linear_iterations=, seconds=}; the previous functions keep the
 * initial state */
static int time_solve(lua_State *L) {
  gc_point(L, 1);
  const char *fn = "step:solve";
  ud_time *u = check_time(L, 1, fn);
  lg_env *env = get_env(L);
  lg_time *T = u->T;
  int N = lg_time_nsteps(T);
  lg_series *series = NULL;
  if (u->output && !(series = lg_series_new(env, u->output))) return lgerror(L, fn, env);
  double t0 = (lg_now_ms() * 1e-3);
  long its = 0, lits = 0;
  if (lg_time_begin(env, T)) { lg_series_free(series); return lgerror(L, fn, env); }
  int rc = series ? write_state(env, u, series, 0) : 0;
  for (int k = 1; k <= N && !rc; k++) {
    lg_solve_info info;
    if ((rc = lg_time_step(env, T, k, &info))) break;
    its += info.iterations;
    lits += info.linear_iterations;
    if (k % u->every == 0 || k == N) {
      if (series && (rc = write_state(env, u, series, k))) break;
      if (u->monitor && lg_mpi_rank() == 0) {
        printf("step %d of %d: t = %.6g, %d %s, %.3f s\n", k, N, lg_time_at(T, k), info.iterations,
               lg_problem_is_nonlinear(u->p) ? "Newton iterations" : "linear iterations", (lg_now_ms() * 1e-3) - t0);
        fflush(stdout);
      }
    }
  }
  lg_function *out[KER_MAXFIELD] = {NULL};
  for (int a = 0; !rc && a < u->nfield; a++) {
    lg_function *f = lg_time_previous(T, 0, a);
    expr_func_info *fi = expr_func_get(env->c, f->fid);
    char nm[80];
    snprintf(nm, sizeof nm, "%s_T", fi ? fi->name : "u");
    if (!(out[a] = lg_function_new(env, f->mesh, f->dm, nm))) rc = 1;
    else memcpy(out[a]->x, f->x, sizeof(double) * (size_t)f->dm->ndof);
  }
  lg_time_end(env, T);
  lg_series_free(series);
  if (rc) {
    for (int a = 0; a < u->nfield; a++) lg_function_free(out[a]);
    return lgerror(L, fn, env);
  }
  int base = lua_gettop(L);
  push_functions_of(L, 1, out, u->nfield);
  push_info_table(L, 4);
  lua_pushinteger(L, N); lua_setfield(L, -2, "steps");
  lua_pushinteger(L, its); lua_setfield(L, -2, "iterations");
  lua_pushinteger(L, lits); lua_setfield(L, -2, "linear_iterations");
  lua_pushnumber(L, (lg_now_ms() * 1e-3) - t0); lua_setfield(L, -2, "seconds");
  return lua_gettop(L) - base;
}

/* step:times(): t0 + k dt for k = 0 .. steps */
static int time_times(lua_State *L) {
  ud_time *u = check_time(L, 1, "step:times");
  int N = lg_time_nsteps(u->T);
  lua_createtable(L, N + 1, 0);
  for (int k = 0; k <= N; k++) { lua_pushnumber(L, lg_time_at(u->T, k)); lua_rawseti(L, -2, k + 1); }
  return 1;
}

void lg_lua_time_register(lua_State *L) {
  static const luaL_Reg mm[] = {{"__gc", time_gc}, {NULL, NULL}};
  static const luaL_Reg methods[] = {{"solve", time_solve}, {"times", time_times}, {"sensitivity", lg_lua_time_sensitivity},
                                          {NULL, NULL}};
  new_mt(L, MT_TIME, mm, methods);
}

const luaL_Reg lg_time_lib[] = {{"time_problem", l_time_problem}, {NULL, NULL}};
