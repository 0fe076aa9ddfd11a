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

/* a parameter option (or -1) */
static int param_option(lua_State *L, const char *key, const char *what, const char *fn) {
  int id = -1;
  if (lua_getfield(L, 1, key) != LUA_TNIL) {
    ud_expr *ue = luaL_testudata(L, -1, MT_EXPR);
    if (!ue || expr_of(L, ue)->kind != E_PARAM)
      return luaL_error(L, "%s: option '%s' must be a parameter (lg.parameter), %s, got %s", fn, key, what,
                        ue ? "an expression" : luaL_typename(L, -1));
    id = expr_of(L, ue)->i0;
  }
  lua_pop(L, 1);
  return id;
}

/* option 'dt' as a list of step sizes into *dts (a userdata buffer left on the stack);
 * their number */
static int read_sizes(lua_State *L, double **dts, const char *fn) {
  lua_getfield(L, 1, "dt");
  int n = (int)luaL_len(L, -1);
  if (n < 1 || n > 100000000) luaL_error(L, "%s: option 'dt' as a table must list the step sizes (1 or more numbers)", fn);
  double *d = lua_newuserdatauv(L, sizeof(double) * (size_t)n, 0);
  for (int k = 0; k < n; k++) {
    lua_geti(L, -2, k + 1);
    int isnum;
    d[k] = lua_tonumberx(L, -1, &isnum);
    if (!isnum || !(d[k] > 0) || !isfinite(d[k]))
      luaL_error(L, "%s: option 'dt': step size %d must be a positive number, got %s", fn, k + 1, luaL_tolstring(L, -1, NULL));
    lua_pop(L, 1);
  }
  lua_remove(L, -2);
  *dts = d;
  return n;
}

/* the value at idx as a list: itself when there is one unknown, else the table */
static void push_item(lua_State *L, int list, int a, int n) {
  if (n == 1 && !(lua_istable(L, list) && !luaL_testudata(L, list, MT_EXPR) && !luaL_testudata(L, list, MT_FUNC)))
    lua_pushvalue(L, list);
  else
    lua_geti(L, list, a + 1);
}

/* out = a*x + b*y (Lua arithmetic on expressions and forms; b = 0: a*x) */
static void push_combination(lua_State *L, double a, int x, double b, int y) {
  lua_pushnumber(L, a);
  lua_pushvalue(L, x);
  lua_arith(L, LUA_OPMUL);
  if (b == 0) return;
  lua_pushnumber(L, b);
  lua_pushvalue(L, y);
  lua_arith(L, LUA_OPMUL);
  lua_arith(L, LUA_OPADD);
}

/* option 'scheme': the step's equation from eqn = function(u_t, u, t) returning M(u_t) +
 * A(u, t) (linear in u_t): backward Euler eqn((u - u0)/dt, u, t); theta (Crank-Nicolson: 1/2)
 * theta eqn(u_t, u, t) + (1 - theta) eqn(u_t, u0, t - dt), u_t = (u - u0)/dt; BDF2
 * eqn((3/2 u - 2 u0 + 1/2 u00)/dt, u, t). dt the step_size parameter when there is one. With
 * several unknowns u_t, u and u0 are tables (one per unknown). The options table at 1 is
 * replaced by a copy whose eqn is the form made; tprev receives the hidden parameter t - dt
 * (or -1) */
static void scheme_equation(lua_State *L, int nfield, int nlev, int *tprev, const char *fn) {
  const char *scheme = opt_str(L, 1, "scheme", NULL, fn);
  double theta = opt_num(L, 1, "theta", 0.5, fn);
  *tprev = -1;
  if (!scheme) {
    if (lua_getfield(L, 1, "theta") != LUA_TNIL) luaL_error(L, "%s: option 'theta' goes with scheme = \"theta\"", fn);
    lua_pop(L, 1);
    return;
  }
  int be = !strcmp(scheme, "backward_euler"), cn = !strcmp(scheme, "crank_nicolson"), th = !strcmp(scheme, "theta"),
      bdf2 = !strcmp(scheme, "bdf2");
  if (!be && !cn && !th && !bdf2)
    luaL_error(L, "%s: option 'scheme' must be \"backward_euler\", \"crank_nicolson\", \"theta\" or \"bdf2\", got \"%s\"", fn, scheme);
  if (!th && lua_getfield(L, 1, "theta") != LUA_TNIL) luaL_error(L, "%s: option 'theta' goes with scheme = \"theta\"", fn);
  if (!th) lua_pop(L, 1);
  if (cn) theta = 0.5;
  if (be || bdf2) theta = 1; /* (BDF2 is implicit in A) */
  if (th && !(theta >= 0 && theta <= 1)) luaL_error(L, "%s: option 'theta' must be in [0, 1], got %f", fn, theta);
  if (bdf2 != (nlev == 2))
    luaL_error(L, "%s: scheme \"%s\" reads %d previous state%s: option 'previous' %s", fn, scheme, bdf2 ? 2 : 1, bdf2 ? "s" : "",
               bdf2 ? "= {u0, u00} (u00 the state a step before u0; u0 again for a first-order start)" : "lists one level");
  int top = lua_gettop(L);
  if (lua_getfield(L, 1, "eqn") != LUA_TFUNCTION)
    luaL_error(L, "%s: with option 'scheme' the equation is a function(u_t, u, t) returning the form M(u_t) + A(u, t), got %s", fn,
               luaL_typename(L, -1));
  int eqn = lua_gettop(L);
  lua_getfield(L, 1, "unknown");
  int unk = lua_gettop(L);
  lua_getfield(L, 1, "previous");
  int prev = lua_gettop(L), lev[2];
  for (int j = 0; j < nlev; j++) { /* level j's list of previous functions */
    if (nlev == 1) lua_pushvalue(L, prev);
    else lua_geti(L, prev, j + 1);
    lev[j] = lua_gettop(L);
  }
  if (lua_getfield(L, 1, "step_size") == LUA_TNIL) {
    lua_pop(L, 1);
    lua_getfield(L, 1, "dt");
  }
  int dt = lua_gettop(L);
  lua_getfield(L, 1, "time");
  int t = lua_gettop(L);
  /* u_t per unknown, into a list (or the one value) */
  lua_createtable(L, nfield, 0);
  int ut = lua_gettop(L);
  for (int a = 0; a < nfield; a++) {
    push_item(L, unk, a, nfield);
    int u = lua_gettop(L);
    push_item(L, lev[0], a, nfield);
    int u0 = lua_gettop(L);
    if (bdf2) {
      push_item(L, lev[1], a, nfield);
      int u00 = lua_gettop(L);
      push_combination(L, 1.5, u, -2, u0);
      push_combination(L, 0.5, u00, 0, 0);
      lua_arith(L, LUA_OPADD);
    } else
      push_combination(L, 1, u, -1, u0);
    lua_pushvalue(L, dt);
    lua_arith(L, LUA_OPDIV);
    lua_rawseti(L, ut, a + 1);
    lua_settop(L, ut);
  }
  if (nfield == 1) {
    lua_geti(L, ut, 1);
    lua_replace(L, ut);
  }
  /* the implicit part, then the explicit part at (u0, t - dt) */
  lua_pushvalue(L, eqn);
  lua_pushvalue(L, ut);
  lua_pushvalue(L, unk);
  lua_pushvalue(L, t);
  lua_call(L, 3, 1);
  int F = lua_gettop(L);
  if (!luaL_testudata(L, F, MT_FORM)) luaL_error(L, "%s: the equation function must return a form (lg.integral ...), got %s", fn, luaL_typename(L, F));
  if (theta < 1) {
    if (!lua_isnil(L, t)) { /* t - dt: a parameter of its own the march sets */
      lg_env *env = get_env(L);
      *tprev = expr_param_new(env->c, "t_prev", 0);
      if (*tprev < 0) luaL_error(L, "%s: out of memory", fn);
      push_expr(L, expr_param(env->c, *tprev), 0, NULL, fn);
      lua_replace(L, t);
    }
    lua_pushvalue(L, eqn);
    lua_pushvalue(L, ut);
    lua_pushvalue(L, lev[0]);
    lua_pushvalue(L, t);
    lua_call(L, 3, 1);
    int G = lua_gettop(L);
    if (!luaL_testudata(L, G, MT_FORM)) luaL_error(L, "%s: the equation function must return a form (lg.integral ...), got %s", fn, luaL_typename(L, G));
    push_combination(L, theta, F, 1 - theta, G);
    lua_replace(L, F);
    lua_settop(L, F);
  }
  /* the options, copied, with the form as eqn */
  lua_newtable(L);
  lua_pushnil(L);
  while (lua_next(L, 1)) {
    lua_pushvalue(L, -2);
    lua_insert(L, -2);
    lua_rawset(L, -4);
  }
  lua_pushvalue(L, F);
  lua_setfield(L, -2, "eqn");
  lua_replace(L, 1);
  lua_settop(L, top);
}

/* lg.time_problem{mesh=, test=, unknown=, previous=, eqn=, bc=, dt=, t0=, t1= | steps=,
 * time=, step_size=, nonlinear=, symmetric=, prefix=, output=, every=, monitor=}; dt a
 * number, a list of step sizes, or a function(k, t, last) choosing each (adaptive) */
static int l_time_problem(lua_State *L) {
  gc_point(L, 1);
  const char *fn = "lg.time_problem";
  if (!lua_istable(L, 1)) return typeerror(L, fn, 1, "a table {mesh=, eqn=, test=, unknown=, previous=, dt=, t1=}");
  static const char *const keys[] = {"mesh", "eqn", "bc", "test", "unknown", "symmetric", "prefix", "nullspace", "previous", "dt",
                                     "t0", "t1", "steps", "time", "step_size", "nonlinear", "output", "every", "monitor",
                                     "before_step", "scheme", "theta", NULL};
  check_keys(L, 1, fn, keys);
  int dty = lua_getfield(L, 1, "dt");
  lua_getfield(L, 1, "t1");
  int have_t1 = !lua_isnil(L, -1);
  lua_pop(L, 2);
  if (dty == LUA_TNIL) return luaL_error(L, "%s: option 'dt' (the time step) is required, a positive number", fn);
  if (dty != LUA_TNUMBER && dty != LUA_TTABLE && dty != LUA_TFUNCTION)
    return luaL_error(L, "%s: option 'dt' must be a positive number, a list of step sizes or a function(k, t, last) "
                         "choosing each step's size, got %s", fn, lua_typename(L, dty));
  int adaptive = dty == LUA_TFUNCTION, dtsz = param_option(L, "step_size", "set to each step's size", fn);
  if (dty != LUA_TNUMBER && dtsz < 0)
    return luaL_error(L, "%s: with step sizes that change (option 'dt' a %s) the step's equation must read them: give "
                         "step_size = a parameter (lg.parameter) and write the equation with it", fn, lua_typename(L, dty));
  double *dts = NULL;
  int nsizes = dty == LUA_TTABLE ? read_sizes(L, &dts, fn) : 0;
  double dt = dty == LUA_TNUMBER ? opt_num(L, 1, "dt", 1, fn) : dts ? dts[0] : 0, t0 = opt_num(L, 1, "t0", 0, fn),
         t1 = opt_num(L, 1, "t1", 0, fn);
  if (dty == LUA_TNUMBER && !(dt > 0)) return luaL_error(L, "%s: option 'dt' must be a positive number, got %f", fn, dt);
  int steps = opt_int(L, 1, "steps", 0, fn);
  if (steps < 0) return luaL_error(L, "%s: option 'steps' must be a positive whole number, got %d", fn, steps);
  if (adaptive && (!have_t1 || steps)) return luaL_error(L, "%s: with option 'dt' a function give the end time 't1' (not 'steps')", fn);
  if (adaptive && !(t1 > t0)) return luaL_error(L, "%s: option 't1' must be after t0", fn);
  if (nsizes) {
    double end = t0;
    for (int k = 0; k < nsizes; k++) end += dts[k];
    if (steps && steps != nsizes) return luaL_error(L, "%s: option 'steps' (%d) differs from the %d step sizes of option 'dt'", fn, steps, nsizes);
    if (have_t1 && fabs(end - t1) > 1e-9 * (fabs(t1) + (end - t0))) {
      char why[160];
      snprintf(why, sizeof why, "the step sizes of option 'dt' end at %.12g, not at t1 = %.12g", end, t1);
      return luaL_error(L, "%s: %s", fn, why);
    }
    steps = nsizes;
  } else if (!adaptive && have_t1 == (steps > 0))
    return luaL_error(L, "%s: give the end time 't1' or the number of 'steps' (one of them)", fn);
  if (!steps && !adaptive) {
    double x = (t1 - t0) / dt;
    if (!(x >= 0.5) || fabs(x - nearbyint(x)) > 1e-9 * x || x > 1e8)
    {
      char why[160];
      snprintf(why, sizeof why, "t1 - t0 = %g must be a whole number of steps of dt = %g (got %.12g steps)", t1 - t0, dt, x);
      return luaL_error(L, "%s: %s", fn, why);
    }
    steps = (int)nearbyint(x);
  }
  int tparam = param_option(L, "time", "set to each step's time", fn);
  if (tparam >= 0 && tparam == dtsz) return luaL_error(L, "%s: options 'time' and 'step_size' must be two parameters", fn);
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
  int every = opt_int(L, 1, "every", adaptive ? 10 : steps >= 10 ? steps / 10 : 1, fn);
  if (every < 1) return luaL_error(L, "%s: option 'every' must be >= 1, got %d", fn, every);
  /* the unknowns' count first (previous is read against it), then the step problem */
  int ids[KER_MAXFIELD], nfield = check_symbols(L, 1, "unknown", FK_UNKNOWN, ids, fn);
  lg_time_spec s;
  memset(&s, 0, sizeof s);
  s.nlev = read_previous(L, 1, nfield, s.prev, fn);
  int tprev;
  scheme_equation(L, nfield, s.nlev, &tprev, fn); /* (eqn from a function and a scheme) */
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
  s.dt_param = dtsz;
  s.tprev_param = tprev;
  s.t0 = t0;
  s.dt = adaptive ? t1 - t0 : dt;
  s.dts = dts;
  s.nsteps = steps;
  s.adaptive = adaptive;
  u->t1 = t1;
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
  if (adaptive) {
    lua_getfield(L, 1, "dt");
    lua_setfield(L, -2, "__dt");
  }
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
  free(u->sizes);
  u->sizes = NULL;
  u->T = NULL;
  u->p = NULL;
  u->output = NULL;
  return 0;
}

/* the fields of level 0 (the state after the last step) for output */
static int write_state(lg_env *env, ud_time *u, lg_series *s, double t) {
  mesh_field fl[KER_MAXFIELD];
  for (int a = 0; a < u->nfield; a++) {
    lg_function *f = lg_time_previous(u->T, 0, a);
    expr_func_info *fi = expr_func_get(env->c, f->fid);
    fl[a] = (mesh_field){fi ? fi->name : "u", f->dm->bs, f->dm->degree == 0, f->x};
  }
  return lg_series_write(env, s, lg_time_previous(u->T, 0, 0)->mesh, u->nfield, fl, t);
}

/* a march's counts, and the progress line of step k */
typedef struct {
  long its, lits;
  int steps, retries;
  double t0;
} march_info;

static void progress(const ud_time *u, const march_info *m, int k, int N, double t, double dt, const lg_solve_info *info) {
  if (!u->monitor || lg_mpi_rank() != 0) return;
  char of[32] = "";
  if (N > 0) snprintf(of, sizeof of, " of %d", N);
  printf("step %d%s: t = %.6g, dt = %.3g, %d %s, %.3f s\n", k, of, t, dt, info->iterations,
         lg_problem_is_nonlinear(u->p) ? "Newton iterations" : "linear iterations", (lg_now_ms() * 1e-3) - m->t0);
  fflush(stdout);
}

/* the step sizes' function: dt(k, t, last) with last = nil (the first step) or {dt =,
 * iterations =, linear_iterations =, failed =, message =}; the size it gives, checked and
 * agreed by the ranks (their least), or an error (a message in env) */
static int ask_dt(lua_State *L, lg_env *env, int k, double t, const lg_solve_info *last, double last_dt, int failed, double *h) {
  lua_getiuservalue(L, 1, 1);
  lua_getfield(L, -1, "__dt");
  lua_remove(L, -2);
  lua_pushinteger(L, k);
  lua_pushnumber(L, t);
  if (k == 1 && !failed) lua_pushnil(L);
  else {
    lua_createtable(L, 0, 5);
    lua_pushnumber(L, last_dt); lua_setfield(L, -2, "dt");
    lua_pushinteger(L, last->iterations); lua_setfield(L, -2, "iterations");
    lua_pushinteger(L, last->linear_iterations); lua_setfield(L, -2, "linear_iterations");
    lua_pushboolean(L, failed); lua_setfield(L, -2, "failed");
    if (failed) { lua_pushstring(L, env->err); lua_setfield(L, -2, "message"); }
  }
  int rc = 0;
  if (lua_pcall(L, 3, 1, 0) != LUA_OK) {
    lg_seterr(env, "dt(%d, %g): %s", k, t, lua_tostring(L, -1) ? lua_tostring(L, -1) : "an error");
    rc = 1;
  } else {
    int isnum;
    *h = lua_tonumberx(L, -1, &isnum);
    if (!isnum || !(*h > 0) || !isfinite(*h)) {
      lg_seterr(env, "dt(%d, %g) must return a positive number, got %s", k, t, luaL_tolstring(L, -1, NULL));
      lua_pop(L, 1);
      rc = 1;
    }
  }
  lua_pop(L, 1);
  double any = rc;
  lg_allreduce(&any, 1, LG_MAX); /* one rank's error stops them all */
  if (any > 0 && !rc) { lg_seterr(env, "dt(%d, %g) failed on another rank", k, t); rc = 1; }
  if (!rc) {
    double m = *h;
    lg_allreduce(&m, 1, LG_MIN);
    *h = m;
  }
  return rc;
}

/* the adaptive march: sizes from the script's dt function, the last clipped to end at t1; a
 * failed step (Newton not converging) is tried again when the function, told it failed,
 * gives a smaller size (10 tries at most) */
static int adaptive_march(lua_State *L, lg_env *env, ud_time *u, lg_series *series, march_info *m) {
  double t0 = lg_time_at(u->T, 0), t = t0, t1 = u->t1, span = t1 - t0, h = 0;
  lg_solve_info info = {0};
  int cap = 64, n = 0;
  free(u->sizes);
  u->nsizes = 0;
  if (!(u->sizes = malloc(sizeof(double) * (size_t)cap))) { lg_seterr(env, "out of memory"); return 1; }
  for (int k = 1; t < t1 - 1e-12 * span; k++) {
    int failed = 0, tries = 0;
    for (;;) {
      double prev = h;
      if (ask_dt(L, env, k, t, &info, h, failed, &h)) return 1;
      if (failed && !(h < prev)) {
        char why[LG_ERRLEN];
        snprintf(why, sizeof why, "%s", env->err);
        lg_seterr(env, "%s (dt(%d, %g), told the step failed, gave %g, not a smaller step)", why, k, t, h);
        return 1;
      }
      if (t + h >= t1 - 1e-9 * h) h = t1 - t;
      if (h < 1e-14 * span) { lg_seterr(env, "step %d (t = %.9g): the step size %g is below 1e-14 of the interval", k, t, h); return 1; }
      int r = lg_time_step_at(env, u->T, k, t + h, h, &info);
      if (!r) break;
      if (r != 2 || ++tries >= 10) return 1; /* before_step's errors are the script's */
      failed = 1;
      m->retries++;
    }
    t += h; /* as lg_time_at sums a list of sizes: the list replays these times to the bit */
    m->its += info.iterations;
    m->lits += info.linear_iterations;
    m->steps = k;
    if (n == cap) {
      double *g = realloc(u->sizes, sizeof(double) * (size_t)(cap *= 2));
      if (!g) { lg_seterr(env, "out of memory"); return 1; }
      u->sizes = g;
    }
    u->sizes[n++] = h;
    u->nsizes = n;
    int last = !(t < t1 - 1e-12 * span);
    if (k % u->every == 0 || last) {
      if (series && write_state(env, u, series, t)) return 1;
      progress(u, m, k, 0, t, h, &info);
    }
  }
  return 0;
}

/* the march of fixed steps */
static int fixed_march(lg_env *env, ud_time *u, lg_series *series, march_info *m) {
  lg_time *T = u->T;
  int N = lg_time_nsteps(T);
  for (int k = 1; k <= N; k++) {
    lg_solve_info info;
    if (lg_time_step(env, T, k, &info)) return 1;
    m->its += info.iterations;
    m->lits += info.linear_iterations;
    m->steps = k;
    if (k % u->every == 0 || k == N) {
      if (series && write_state(env, u, series, lg_time_at(T, k))) return 1;
      progress(u, m, k, N, lg_time_at(T, k), lg_time_step_size(T, k), &info);
    }
  }
  return 0;
}

/* step:solve(): the march from t0 to t1; the final state (new functions, one per unknown) and
 * {steps=, iterations=, linear_iterations=, seconds=[, retries=]}; the previous functions
 * keep the initial state */
static int time_solve(lua_State *L) {
  gc_point(L, 1);
  const char *fn = "step:solve";
  ud_time *u = check_time(L, 1, fn);
  lua_settop(L, 1);
  lg_env *env = get_env(L);
  lg_time *T = u->T;
  lg_series *series = NULL;
  if (u->output && !(series = lg_series_new(env, u->output))) return lgerror(L, fn, env);
  march_info m = {0, 0, 0, 0, lg_now_ms() * 1e-3};
  if (lg_time_begin(env, T)) { lg_series_free(series); return lgerror(L, fn, env); }
  int rc = series ? write_state(env, u, series, lg_time_at(T, 0)) : 0;
  if (!rc) rc = lg_time_adaptive(T) ? adaptive_march(L, env, u, series, &m) : fixed_march(env, u, series, &m);
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
  push_info_table(L, 5);
  lua_pushinteger(L, m.steps); lua_setfield(L, -2, "steps");
  lua_pushinteger(L, m.its); lua_setfield(L, -2, "iterations");
  lua_pushinteger(L, m.lits); lua_setfield(L, -2, "linear_iterations");
  lua_pushnumber(L, (lg_now_ms() * 1e-3) - m.t0); lua_setfield(L, -2, "seconds");
  if (lg_time_adaptive(T)) { lua_pushinteger(L, m.retries); lua_setfield(L, -2, "retries"); }
  return lua_gettop(L) - base;
}

/* step:times() and step:sizes(): the step times t_0 .. t_N and sizes t_k - t_{k-1} (an
 * adaptive march's: those of the last one, the times summed from t0 as a list of sizes
 * sums them, so that dt = step:sizes() replays the march to the bit) */
static int times_or_sizes(lua_State *L, int sizes) {
  const char *fn = sizes ? "step:sizes" : "step:times";
  ud_time *u = check_time(L, 1, fn);
  if (lg_time_adaptive(u->T)) {
    if (!u->sizes) return luaL_error(L, "%s: the step %s of an adaptive march are known after step:solve()", fn, sizes ? "sizes" : "times");
    lua_createtable(L, u->nsizes + 1, 0);
    double t = lg_time_at(u->T, 0);
    if (!sizes) { lua_pushnumber(L, t); lua_rawseti(L, -2, 1); }
    for (int k = 0; k < u->nsizes; k++) {
      t += u->sizes[k];
      lua_pushnumber(L, sizes ? u->sizes[k] : t);
      lua_rawseti(L, -2, k + 1 + !sizes);
    }
    return 1;
  }
  int N = lg_time_nsteps(u->T);
  lua_createtable(L, N + 1, 0);
  for (int k = !!sizes; k <= N; k++) {
    lua_pushnumber(L, sizes ? lg_time_step_size(u->T, k) : lg_time_at(u->T, k));
    lua_rawseti(L, -2, k + !sizes);
  }
  return 1;
}

static int time_sizes(lua_State *L) { return times_or_sizes(L, 1); }

static int time_times(lua_State *L) { return times_or_sizes(L, 0); }

void lg_lua_time_register(lua_State *L) {
  static const luaL_Reg mm[] = {{"__gc", time_gc}, {NULL, NULL}};
  static const luaL_Reg methods[] = {{"solve", time_solve}, {"times", time_times}, {"sizes", time_sizes}, {"sensitivity", lg_lua_time_sensitivity},
                                          {NULL, NULL}};
  new_mt(L, MT_TIME, mm, methods);
}

const luaL_Reg lg_time_lib[] = {{"time_problem", l_time_problem}, {NULL, NULL}};
