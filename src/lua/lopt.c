/* lopt.c — Lua bindings of PDE-constrained optimization (functional.c): controls,
 * functionals, reduced functionals (value, derivative, gradient with Riesz maps, state) and
 * the Taylor test. */
#include "largs.h"

#include <lauxlib.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* a functional: one form (f), or the terms of a time-dependent problem's (lg.functional{final=,
 * running=, at=}: f NULL) */
typedef struct {
  form *f;
  int nterm;
  form *tf[LG_TIME_MAXTERMS];
  int kind[LG_TIME_MAXTERMS];
  double at[LG_TIME_MAXTERMS];
} ud_functional;
typedef struct { lg_reduced *rf; } ud_reduced;

/* ---------------------------------------------------------------- controls, functionals */

/* lg.control(basis, mesh, name[, initial]): a discrete function to optimize over */
static int l_control(lua_State *L) {
  const char *fn = "lg.control";
  /* the options last: {per_step = true} (a table with that key, not a vector expression) */
  int per_step = 0, top = lua_gettop(L);
  if (top >= 4 && lua_istable(L, top) && !luaL_testudata(L, top, MT_EXPR) && lua_getfield(L, top, "per_step") != LUA_TNIL) {
    lua_pop(L, 1);
    static const char *const keys[] = {"per_step", NULL};
    check_keys(L, top, fn, keys);
    lua_getfield(L, top, "per_step");
    if (!lua_isboolean(L, -1)) return luaL_error(L, "%s: option 'per_step' must be a boolean", fn);
    per_step = lua_toboolean(L, -1);
    lua_settop(L, top - 1);
  } else if (top >= 4) lua_settop(L, top);
  ud_basis *b = luaL_testudata(L, 1, MT_BASIS);
  if (!b) return typeerror(L, fn, 1, "a basis (lg.lagrange(p))");
  ud_mesh *um = check_mesh(L, 2, fn);
  const char *name = opt_cstring(L, 3, "m", fn, "argument 3 (the name)");
  lg_env *env = get_env(L);
  lg_function *f = lg_function_new(env, um->lm, lg_mesh_dofmap(env, um->lm, b->degree, b->ncomp, b->disc), name);
  if (!f) return lgerror(L, fn, env);
  f->per_step = per_step;
  push_function(L, f, 2);
  if (!lua_isnoneornil(L, 4)) {
    ud_func *g = luaL_testudata(L, 4, MT_FUNC);
    if (g) {
      if (g->f->dm != f->dm)
        return luaL_error(L, "%s: argument 4 must be a discrete function of the same basis and mesh", fn);
      memcpy(f->x, g->f->x, sizeof(double) * (size_t)f->dm->ndof);
    } else {
      expr *e = check_expr(L, 4, fn);
      if (lg_interpolate(env, f, e)) return lgerror(L, fn, env);
    }
  }
  if (!per_step) return 1;
  /* the companion: the control's value at the step before (a regularization of its rate,
   * a Crank-Nicolson source); kept alive by the control */
  int fidx = lua_gettop(L);
  char nm[96];
  snprintf(nm, sizeof nm, "%s_prev", name);
  lg_function *fp = lg_function_new(env, um->lm, f->dm, nm);
  if (!fp) return lgerror(L, fn, env);
  memcpy(fp->x, f->x, sizeof(double) * (size_t)f->dm->ndof);
  push_function(L, fp, 2);
  f->step_prev = fp;
  lua_getiuservalue(L, fidx, 1);
  lua_pushvalue(L, -2);
  lua_pushboolean(L, 1);
  lua_rawset(L, -3);
  lua_pop(L, 1);
  return 2;
}

/* the form at idx checked as a functional's (no test functions) */
static form *functional_form(lua_State *L, int idx, const char *fn, const char *what) {
  ud_form *u = luaL_testudata(L, idx, MT_FORM);
  if (!u) luaL_error(L, "%s: %s must be a form (lg.integral(...) + ...), got %s", fn, what,
                     luaL_testudata(L, idx, MT_BC) ? "a boundary condition" : luaL_typename(L, idx));
  lg_env *env = get_env(L);
  for (int i = 0; i < u->f->n; i++) {
    expr *e = u->f->t[i].integrand, *leaf[64];
    int n = expr_collect_fields(env->c, 1, &e, -1, 64, leaf);
    for (int k = 0; k < n && k < 64; k++) {
      expr_func_info *fi = expr_func_get(env->c, leaf[k]->i0);
      if (fi && fi->kind == FK_TEST)
        luaL_error(L, "%s: the form contains the test function %s: a functional is a number (integrals of the "
                      "state and the controls, without test functions)", fn, fi->name);
    }
  }
  form *f = form_copy(u->f);
  if (!f) luaL_error(L, "%s: out of memory", fn);
  return f;
}

/* one term of a time-dependent functional into f (its form anchored in f's userdata) */
static void add_term(lua_State *L, ud_functional *f, int idx, int kind, double at, const char *fn, const char *what) {
  if (f->nterm == LG_TIME_MAXTERMS) luaL_error(L, "%s: at most %d terms", fn, LG_TIME_MAXTERMS);
  f->tf[f->nterm] = functional_form(L, idx, fn, what);
  f->kind[f->nterm] = kind;
  f->at[f->nterm++] = at;
}

/* lg.functional(form), or for a time-dependent problem lg.functional{final = form, running =
 * form, at = {[t] = form, ...}} */
static int l_functional(lua_State *L) {
  const char *fn = "lg.functional";
  if (!luaL_testudata(L, 1, MT_FORM) && !lua_istable(L, 1))
    return typeerror(L, fn, 1, luaL_testudata(L, 1, MT_BC) ? "a form (lg.integral), not a boundary condition"
                                                          : "a form (lg.integral(...) + ...) or a table {final=, running=, at=}");
  int deps[1] = {1};
  ud_functional *f = new_ud(L, sizeof *f, MT_FUNCTIONAL, 1, deps);
  int fi = lua_gettop(L);
  if (luaL_testudata(L, 1, MT_FORM)) {
    f->f = functional_form(L, 1, fn, "argument 1");
    return 1;
  }
  static const char *const keys[] = {"final", "running", "at", "initial", NULL};
  check_keys(L, 1, fn, keys);
  if (lua_getfield(L, 1, "initial") != LUA_TNIL) add_term(L, f, lua_gettop(L), LG_TJ_INITIAL, 0, fn, "option 'initial'");
  if (lua_getfield(L, 1, "final") != LUA_TNIL) add_term(L, f, lua_gettop(L), LG_TJ_FINAL, 0, fn, "option 'final'");
  if (lua_getfield(L, 1, "running") != LUA_TNIL) add_term(L, f, lua_gettop(L), LG_TJ_RUNNING, 0, fn, "option 'running'");
  lua_settop(L, fi);
  if (lua_getfield(L, 1, "at") != LUA_TNIL) {
    int t = lua_gettop(L);
    if (!lua_istable(L, t)) return luaL_error(L, "%s: option 'at' must be a table {[t] = form, ...}", fn);
    lua_pushnil(L);
    while (lua_next(L, t)) {
      int isnum;
      double at = lua_tonumberx(L, -2, &isnum);
      if (!isnum || !isfinite(at)) return luaL_error(L, "%s: option 'at' must be indexed by times (numbers)", fn);
      add_term(L, f, lua_gettop(L), LG_TJ_AT, at, fn, "each entry of option 'at'");
      lua_pop(L, 1);
    }
  }
  lua_settop(L, fi);
  if (!f->nterm) return luaL_error(L, "%s: give at least one of 'final', 'running', 'at', 'initial'", fn);
  return 1;
}

static int functional_gc(lua_State *L) {
  ud_functional *f = lua_touserdata(L, 1);
  form_free(f->f);
  f->f = NULL;
  for (int i = 0; i < f->nterm; i++) form_free(f->tf[i]);
  f->nterm = 0;
  return 0;
}

/* ---------------------------------------------------------------- reduced functionals */

static ud_reduced *check_reduced(lua_State *L, int idx, const char *fn) {
  ud_reduced *u = luaL_testudata(L, idx, MT_REDUCED);
  if (!u) typeerror(L, fn, idx, "a reduced functional (lg.reduced_functional)");
  return u;
}

/* one control from the value at idx: a discrete function or a parameter */
static int to_control(lua_State *L, int idx, lg_control *c, const char *fn, int k) {
  ud_func *uf = luaL_testudata(L, idx, MT_FUNC);
  if (uf) {
    c->kind = LG_CONTROL_FIELD;
    c->f = uf->f;
    c->param = -1;
    c->per_step = uf->f->per_step;
    c->fprev = uf->f->step_prev;
    return 1;
  }
  ud_expr *ue = luaL_testudata(L, idx, MT_EXPR);
  if (ue && expr_of(L, ue)->kind == E_PARAM) { c->kind = LG_CONTROL_PARAM; c->f = NULL; c->param = ue->e->i0; c->per_step = 0; c->fprev = NULL; return 1; }
  return luaL_error(L, "%s: control %d must be a discrete function (lg.control) or a parameter (lg.parameter), got %s", fn, k,
                    ue ? "an expression" : luaL_typename(L, idx));
}

/* option 'checkpoints' of a time-dependent reduced functional: "all" (every state), a number
 * of snapshots in memory, or {ram =, disk =, dir =}; by default every state while they take
 * at most 1 GiB, else as many snapshots as fit in it. Option 'schedule': "revolve" (memory
 * only) or "multistage" (memory and disk, the default with disk snapshots) */
static void read_checkpoints(lua_State *L, lg_time *T, lg_checkpoints *ck, const char *fn) {
  double state_bytes = 8.0 * lg_time_state_size(T), budget = 1024.0 * 1024 * 1024;
  int N = lg_time_nsteps(T);
  memset(ck, 0, sizeof *ck);
  int ty = lua_getfield(L, 1, "checkpoints");
  if (ty == LUA_TSTRING) {
    if (strcmp(lua_tostring(L, -1), "all"))
      luaL_error(L, "%s: option 'checkpoints' must be \"all\", a number of snapshots or {ram =, disk =, dir =}, got \"%s\"", fn, lua_tostring(L, -1));
  } else if (ty == LUA_TTABLE) {
    static const char *const keys[] = {"ram", "disk", "dir", NULL};
    int t = lua_gettop(L);
    check_keys(L, t, "lg.reduced_functional: option 'checkpoints'", keys);
    ck->ram = opt_int(L, t, "ram", 0, fn);
    ck->disk = opt_int(L, t, "disk", 0, fn);
    ck->dir = opt_str(L, t, "dir", NULL, fn);
    if (ck->ram < 0 || ck->disk < 0 || ck->ram + ck->disk < 1)
      luaL_error(L, "%s: option 'checkpoints' = {ram = %d, disk = %d}: snapshots in memory and on disk, at least one in all", fn, ck->ram, ck->disk);
    if (ck->disk && ck->ram < 1) luaL_error(L, "%s: option 'checkpoints' needs at least one snapshot in memory (ram = 1) beside disk ones", fn);
  } else if (ty != LUA_TNIL) {
    int isnum;
    lua_Integer k = lua_tointegerx(L, -1, &isnum);
    if (!isnum || k < 1) luaL_error(L, "%s: option 'checkpoints' must be \"all\", a number of snapshots >= 1 or {ram =, disk =, dir =}", fn);
    ck->ram = k > N ? 0 : (int)k;
  } else if ((N + 1) * state_bytes > budget) {
    ck->ram = (int)(budget / state_bytes) - 2;
    if (ck->ram < 2) ck->ram = 2;
  }
  if (ck->ram + ck->disk > N) ck->ram = ck->disk = 0; /* as many as states: every one kept */
  lua_pop(L, 1);
  const char *sched = opt_str(L, 1, "schedule", NULL, fn);
  if (sched && !strcmp(sched, "mixed"))
    luaL_error(L, "%s: schedule \"mixed\" is not provided: lugal's binomial schedule never re-runs a step for its own adjoint "
                  "(the step's output is held from the later step), the saving the mixed schedule makes over revolve; at equal "
                  "memory it recomputes within 1 to 4 percent of the mixed schedule's steps (bench/RESULTS.md). Use \"revolve\"", fn);
  if (sched && strcmp(sched, "revolve") && strcmp(sched, "multistage"))
    luaL_error(L, "%s: option 'schedule' must be \"revolve\" (snapshots in memory) or \"multistage\" (in memory and on disk), got \"%s\"",
               fn, sched);
  if (sched && !strcmp(sched, "revolve") && ck->disk)
    luaL_error(L, "%s: schedule \"revolve\" keeps its snapshots in memory: with disk ones use \"multistage\"", fn);
}

/* the controls at idx: one, or a table of them (what names them in messages); their number */
static int read_controls(lua_State *L, int idx, lg_control *c, const char *fn, const char *what) {
  int nc = 0;
  if (lua_istable(L, idx) && !luaL_testudata(L, idx, MT_EXPR)) {
    lua_Integer n = luaL_len(L, idx);
    if (n < 1 || n > LG_MAXCONTROL) return luaL_error(L, "%s: %s must list 1 to %d controls", fn, what, LG_MAXCONTROL);
    for (int i = 1; i <= n; i++) {
      lua_geti(L, idx, i);
      to_control(L, -1, &c[nc], fn, i);
      for (int j = 0; j < nc; j++)
        if (c[j].kind == c[nc].kind && c[j].f == c[nc].f && c[j].param == c[nc].param)
          return luaL_error(L, "%s: %s lists control %d twice (entries %d and %d)", fn, what, i, j + 1, i);
      nc++;
      lua_pop(L, 1);
    }
  } else if (lua_isnoneornil(L, idx))
    return luaL_error(L, "%s: %s is required (a discrete function, a parameter or a table of them)", fn, what);
  else
    to_control(L, idx, &c[nc++], fn, 1);
  return nc;
}

/* the reduced functional of a time-dependent problem */
static lg_reduced *time_reduced(lua_State *L, lg_time *T, const ud_functional *uf, int nc, const lg_control *c, const char *fn) {
  lg_env *env = get_env(L);
  lg_time_term terms[LG_TIME_MAXTERMS];
  int nterm = 0;
  if (uf->f) terms[nterm++] = (lg_time_term){uf->f, LG_TJ_FINAL, 0};
  for (int i = 0; i < uf->nterm; i++) terms[nterm++] = (lg_time_term){uf->tf[i], uf->kind[i], uf->at[i]};
  lg_checkpoints ck;
  read_checkpoints(L, T, &ck, fn);
  /* monitor = true: a line per sweep as often as the problem's own (its option 'every') */
  lua_getfield(L, 1, "monitor");
  int monitor = lua_toboolean(L, -1);
  lua_pop(L, 1);
  lua_getfield(L, 1, "problem");
  ud_time *ut = luaL_testudata(L, -1, MT_TIME);
  lua_pop(L, 1);
  return lg_reduced_new_time(env, T, nterm, terms, nc, c, &ck, monitor && ut ? ut->every : 0);
}

static int l_reduced_functional(lua_State *L) {
  gc_point(L, 1);
  const char *fn = "lg.reduced_functional";
  if (!lua_istable(L, 1)) return typeerror(L, fn, 1, "a table {problem=, functional=, control=}");
  static const char *const keys[] = {"problem", "functional", "control", "checkpoints", "schedule", "monitor", NULL};
  check_keys(L, 1, fn, keys);
  lua_getfield(L, 1, "problem");
  ud_prob *up = luaL_testudata(L, -1, MT_PROB);
  lg_time *T = time_of(L, -1);
  if (!up && !T)
    return luaL_error(L, "%s: option 'problem' must be a problem (lg.linear_problem, lg.nonlinear_problem or lg.time_problem), "
                         "got %s", fn, luaL_typename(L, -1));
  int pidx = lua_gettop(L);
  lua_getfield(L, 1, "functional");
  ud_functional *uf = luaL_testudata(L, -1, MT_FUNCTIONAL);
  if (!uf) return luaL_error(L, "%s: option 'functional' must be lg.functional(...), got %s", fn,
                             luaL_testudata(L, -1, MT_FORM) ? "a form (wrap it in lg.functional)" : luaL_typename(L, -1));
  int fidx = lua_gettop(L);
  lua_getfield(L, 1, "control");
  int cidx = lua_gettop(L);
  lg_control c[LG_MAXCONTROL];
  int nc = read_controls(L, cidx, c, fn, "option 'control'");
  lg_env *env = get_env(L);
  lg_reduced *rf;
  if (T) rf = time_reduced(L, T, uf, nc, c, fn);
  else {
    if (!uf->f) return luaL_error(L, "%s: a functional with final, running or observed terms is for a time-dependent problem", fn);
    if (lua_getfield(L, 1, "checkpoints") != LUA_TNIL) return luaL_error(L, "%s: option 'checkpoints' is for a time-dependent problem", fn);
    if (lua_getfield(L, 1, "schedule") != LUA_TNIL) return luaL_error(L, "%s: option 'schedule' is for a time-dependent problem", fn);
    lua_pop(L, 1);
    rf = lg_reduced_new(env, up->p, uf->f, nc, c);
  }
  if (!rf) return lgerror(L, fn, env);
  int deps[3] = {pidx, fidx, cidx};
  ud_reduced *u = new_ud(L, sizeof *u, MT_REDUCED, 3, deps);
  u->rf = rf;
  /* the problem, the functional and the controls themselves are kept alive too (rf points
   * into the first two; a script may drop its own references to them) */
  lua_getiuservalue(L, -1, 1);
  for (int i = 0; i < 3; i++) {
    lua_pushvalue(L, deps[i]);
    lua_pushboolean(L, 1);
    lua_rawset(L, -3);
  }
  lua_pop(L, 1);
  return 1;
}

static int reduced_gc(lua_State *L) {
  ud_reduced *u = lua_touserdata(L, 1);
  lg_reduced_free(u->rf);
  u->rf = NULL;
  return 0;
}

/* one block (nd dofs) of field control i from the value at idx: a discrete function of its
 * space, or an expression interpolated (at step k's time for a per-step control: the time
 * parameter set as the march sets it); what names it in messages */
static void fill_block(lua_State *L, lg_reduced *rf, int i, int idx, int k, double *out, const char *fn, const char *what) {
  lg_env *env = get_env(L);
  const lg_control *c = lg_reduced_control(rf, i);
  int nd = c->f->dm->ndof;
  ud_func *g = luaL_testudata(L, idx, MT_FUNC);
  if (g) {
    if (g->f->dm != c->f->dm) luaL_error(L, "%s: %s must be a discrete function of the control's basis and mesh (P%d)", fn, what, c->f->degree);
    if (lg_check_finite(env, g->f->dm, g->f->x, what)) lgerror(L, fn, env);
    if (out != g->f->x) memcpy(out, g->f->x, sizeof(double) * (size_t)nd);
    return;
  }
  int ok;
  expr *e = to_expr_opt(L, idx, &ok);
  if (!ok) typeerror(L, fn, idx, "a discrete function, an expression or a number");
  e = expr_canon(env->c, e);
  if (!e) exprerror(L, fn);
  lg_time *T = lg_reduced_time(rf);
  lg_function *t = lg_function_new(env, c->f->mesh, c->f->dm, "m");
  if (!t) lgerror(L, fn, env);
  int rc = c->per_step && lg_time_begin(env, T);
  if (!rc && c->per_step) lg_time_prepare(env, T, k);
  if (!rc) rc = lg_interpolate(env, t, e);
  if (c->per_step) lg_time_end(env, T);
  if (!rc) memcpy(out, t->x, sizeof(double) * (size_t)nd);
  expr_func_forget_user(env->c, t->fid);
  lg_function_free(t);
  if (rc) lgerror(L, fn, env);
}

/* control i's values (lg_reduced_control_size of them) into out from the value at idx: a
 * parameter's number; a field's function or expression; a per-step control's one value for
 * every step, or a table of one per step time (N + 1) */
static void fill_control(lua_State *L, lg_reduced *rf, int i, int idx, double *out, const char *fn, const char *what) {
  lg_env *env = get_env(L);
  const lg_control *c = lg_reduced_control(rf, i);
  if (c->kind == LG_CONTROL_PARAM) {
    int isnum;
    double v = lua_tonumberx(L, idx, &isnum);
    if (!isnum) luaL_error(L, "%s: %s (a parameter, %s) must be a number, got %s", fn, what, expr_param_name(env->c, c->param),
                           luaL_typename(L, idx));
    if (!isfinite(v)) luaL_error(L, "%s: %s is not finite (%f)", fn, what, v);
    out[0] = v;
    return;
  }
  int nb = lg_reduced_control_blocks(rf, i), nd = c->f->dm->ndof;
  if (nb > 1 && lua_istable(L, idx) && !luaL_testudata(L, idx, MT_EXPR) && !luaL_testudata(L, idx, MT_FUNC)) {
    if ((int)luaL_len(L, idx) != nb)
      luaL_error(L, "%s: %s has a value per step time: give one value or %d (t0 .. t1), got %d", fn, what, nb, (int)luaL_len(L, idx));
    for (int k = 0; k < nb; k++) {
      lua_geti(L, idx, k + 1);
      fill_block(L, rf, i, lua_gettop(L), k, out + (size_t)k * (size_t)nd, fn, what);
      lua_pop(L, 1);
    }
    return;
  }
  for (int k = 0; k < nb; k++) fill_block(L, rf, i, idx, k, out + (size_t)k * (size_t)nd, fn, what);
}

/* set control i from the value at idx (fill_control) */
static void set_control(lua_State *L, lg_reduced *rf, int i, int idx, const char *fn) {
  char what[48];
  snprintf(what, sizeof what, "the value of control %d", i + 1);
  fill_control(L, rf, i, idx, lg_reduced_control_values(rf, i), fn, what);
  lg_reduced_changed(rf);
}

/* a per-step control's blocks as a table of discrete functions (one per step time) on the
 * stack; other controls push nothing and return 0 */
static int push_blocks(lua_State *L, lg_reduced *rf, int i, const double *v, const char *prefix, const char *fn) {
  const lg_control *c = lg_reduced_control(rf, i);
  if (c->kind != LG_CONTROL_FIELD || !c->per_step) return 0;
  lg_env *env = get_env(L);
  int nb = lg_reduced_control_blocks(rf, i), nd = c->f->dm->ndof;
  expr_func_info *fi = expr_func_get(env->c, c->f->fid);
  lua_createtable(L, nb, 0);
  for (int k = 0; k < nb; k++) {
    char nm[96];
    snprintf(nm, sizeof nm, "%s%s_%d", prefix, fi ? fi->name : "m", k);
    lg_function *gf = lg_function_new(env, c->f->mesh, c->f->dm, nm);
    if (!gf) lgerror(L, fn, env);
    push_functions_of(L, 1, &gf, 1);
    memcpy(gf->x, v + (size_t)k * (size_t)nd, sizeof(double) * (size_t)nd);
    lua_rawseti(L, -2, k + 1);
  }
  return 1;
}

/* the controls from the argument at idx (one value, or a table of one per control when there
 * are several); nothing when it is none or nil */
static void set_controls(lua_State *L, lg_reduced *rf, int idx, const char *fn) {
  if (lua_isnoneornil(L, idx)) return;
  int nc = lg_reduced_ncontrols(rf);
  if (nc == 1) { set_control(L, rf, 0, idx, fn); return; }
  if (!lua_istable(L, idx) || luaL_testudata(L, idx, MT_EXPR))
    typeerror(L, fn, idx, "a table with one value per control");
  if (luaL_len(L, idx) != nc) luaL_error(L, "%s: give %d control values, got %d", fn, nc, (int)luaL_len(L, idx));
  for (int i = 0; i < nc; i++) {
    lua_geti(L, idx, i + 1);
    set_control(L, rf, i, lua_gettop(L), fn);
    lua_pop(L, 1);
  }
}

static int reduced_value(lua_State *L) {
  const char *fn = "rf:value";
  ud_reduced *u = check_reduced(L, 1, fn);
  set_controls(L, u->rf, 2, fn);
  lg_env *env = get_env(L);
  double J;
  if (lg_reduced_value(env, u->rf, &J)) return lgerror(L, fn, env);
  lua_pushnumber(L, J);
  return 1;
}

/* the raw gradient (dual vectors) into userdata buffers on the stack; returns their pointers */
static void raw_gradient(lua_State *L, lg_reduced *rf, double **g, const char *fn) {
  int nc = lg_reduced_ncontrols(rf);
  for (int i = 0; i < nc; i++) g[i] = lua_newuserdatauv(L, sizeof(double) * ((size_t)lg_reduced_control_size(rf, i) + 1), 0);
  lg_env *env = get_env(L);
  if (lg_reduced_gradient(env, rf, g)) lgerror(L, fn, env);
}

/* a direction for the controls from the value at idx (given like the controls: one value, or
 * a table of one per control): vectors in userdata buffers left on the stack */
static void read_direction(lua_State *L, lg_reduced *rf, int idx, double **dm, const char *fn) {
  int nc = lg_reduced_ncontrols(rf);
  if (nc > 1 && (!lua_istable(L, idx) || luaL_testudata(L, idx, MT_EXPR)))
    typeerror(L, fn, idx, "a direction: a table with one value per control");
  if (nc > 1 && luaL_len(L, idx) != nc) luaL_error(L, "%s: the direction needs %d values (one per control), got %d", fn, nc, (int)luaL_len(L, idx));
  for (int i = 0; i < nc; i++) {
    int n = lg_reduced_control_size(rf, i);
    dm[i] = lua_newuserdatauv(L, sizeof(double) * ((size_t)n + 1), 0);
    int k = nc == 1 ? idx : (lua_geti(L, idx, i + 1), lua_gettop(L));
    char what[48];
    snprintf(what, sizeof what, "the direction of control %d", i + 1);
    fill_control(L, rf, i, k, dm[i], fn, what);
  }
}

/* sum_i <a_i, b_i> over the controls' vectors */
static double pair_vectors(lua_State *L, lg_reduced *rf, double **a, double **b, const char *fn) {
  double s;
  lg_env *env = get_env(L);
  if (lg_reduced_dot(env, rf, a, b, &s)) lgerror(L, fn, env);
  return s;
}

/* the option 'riesz' of the table at idx (0: none given) */
static int opt_riesz(lua_State *L, int idx, const char *fn) {
  if (!idx) return LG_RIESZ_L2;
  static const char *const keys[] = {"riesz", NULL};
  check_keys(L, idx, fn, keys);
  const char *r = opt_str(L, idx, "riesz", "l2", fn);
  if (!strcmp(r, "l2")) return LG_RIESZ_L2;
  if (!strcmp(r, "h1")) return LG_RIESZ_H1;
  if (!strcmp(r, "none")) return LG_RIESZ_NONE;
  return luaL_error(L, "%s: option 'riesz' must be \"l2\", \"h1\" or \"none\", got \"%s\"", fn, r);
}

/* is the value at idx an options table (a table with a key 'riesz')? */
static int is_opts(lua_State *L, int idx) {
  if (!lua_istable(L, idx) || luaL_testudata(L, idx, MT_EXPR)) return 0;
  int t = lua_getfield(L, idx, "riesz");
  lua_pop(L, 1);
  return t != LUA_TNIL;
}

/* push dual vectors of the controls as their Riesz representatives: functions named
 * <prefix>_<control> for field controls, numbers for parameters; returns how many */
static int push_riesz(lua_State *L, lg_reduced *rf, double **g, int riesz, const char *prefix, const char *fn) {
  lg_env *env = get_env(L);
  int nc = lg_reduced_ncontrols(rf);
  for (int i = 0; i < nc; i++) {
    const lg_control *c = lg_reduced_control(rf, i);
    if (c->kind == LG_CONTROL_PARAM) { lua_pushnumber(L, g[i][0]); continue; }
    if (c->per_step) { /* a function per step time, each mapped by the space's Riesz map */
      int n = lg_reduced_control_size(rf, i);
      double *r = lua_newuserdatauv(L, sizeof(double) * ((size_t)n + 1), 0);
      if (lg_reduced_riesz(env, rf, i, riesz, g[i], r)) return lgerror(L, fn, env);
      push_blocks(L, rf, i, r, prefix, fn);
      lua_remove(L, -2);
      continue;
    }
    expr_func_info *fi = expr_func_get(env->c, c->f->fid);
    char nm[80];
    snprintf(nm, sizeof nm, "%s_%s", prefix, fi ? fi->name : "m");
    lg_function *gf = lg_function_new(env, c->f->mesh, c->f->dm, nm);
    if (!gf) return lgerror(L, fn, env);
    push_functions_of(L, 1, &gf, 1);
    if (lg_reduced_riesz(env, rf, i, riesz, g[i], gf->x)) return lgerror(L, fn, env);
  }
  return nc;
}

/* the Hessian action H dm (dual vectors) into userdata buffers on the stack */
static void raw_hessian(lua_State *L, lg_reduced *rf, double **dm, double **out, const char *fn) {
  int nc = lg_reduced_ncontrols(rf);
  for (int i = 0; i < nc; i++) out[i] = lua_newuserdatauv(L, sizeof(double) * ((size_t)lg_reduced_control_size(rf, i) + 1), 0);
  lg_env *env = get_env(L);
  if (lg_reduced_hessian(env, rf, dm, out)) lgerror(L, fn, env);
}

static int reduced_derivative(lua_State *L) {
  const char *fn = "rf:derivative";
  ud_reduced *u = check_reduced(L, 1, fn);
  if (lua_isnoneornil(L, 2)) return typeerror(L, fn, 2, "a direction (like the controls)");
  set_controls(L, u->rf, 3, fn);
  lua_settop(L, 3);
  double *g[LG_MAXCONTROL], *dm[LG_MAXCONTROL];
  read_direction(L, u->rf, 2, dm, fn);
  raw_gradient(L, u->rf, g, fn);
  lua_pushnumber(L, pair_vectors(L, u->rf, g, dm, fn));
  return 1;
}

/* rf:gradient([m][, {riesz=}]) */
static int reduced_gradient(lua_State *L) {
  const char *fn = "rf:gradient";
  ud_reduced *u = check_reduced(L, 1, fn);
  int oidx = is_opts(L, 2) ? 2 : is_opts(L, 3) ? 3 : 0;
  if (!oidx && lua_istable(L, 3)) oidx = 3;
  int riesz = opt_riesz(L, oidx, fn);
  if (oidx != 2) set_controls(L, u->rf, 2, fn);
  lua_settop(L, 3);
  double *g[LG_MAXCONTROL];
  raw_gradient(L, u->rf, g, fn);
  return push_riesz(L, u->rf, g, riesz, "grad", fn);
}

/* rf:hessian(dm[, m][, {riesz=}]): the Hessian action H(m) dm, like the gradient */
static int reduced_hessian(lua_State *L) {
  const char *fn = "rf:hessian";
  ud_reduced *u = check_reduced(L, 1, fn);
  if (lua_isnoneornil(L, 2)) return typeerror(L, fn, 2, "a direction (like the controls)");
  int oidx = is_opts(L, 3) ? 3 : is_opts(L, 4) ? 4 : 0;
  if (!oidx && lua_istable(L, 4)) oidx = 4;
  int riesz = opt_riesz(L, oidx, fn);
  if (oidx != 3) set_controls(L, u->rf, 3, fn);
  lua_settop(L, 4);
  double *dm[LG_MAXCONTROL], *h[LG_MAXCONTROL];
  read_direction(L, u->rf, 2, dm, fn);
  raw_hessian(L, u->rf, dm, h, fn);
  return push_riesz(L, u->rf, h, riesz, "hess", fn);
}

/* rf:stats(): {recomputed = forward steps the last gradient solved beyond the value's march,
 * states = the states it holds at most, in_memory = of them in memory, disk_writes,
 * disk_reads = checkpoint files written and read, dir = their directory} (a time-dependent
 * problem's; 0 and 1 otherwise) */
static int reduced_stats(lua_State *L) {
  ud_reduced *u = check_reduced(L, 1, "rf:stats");
  lg_time_stats st;
  lg_time_rf_stats(u->rf, &st);
  push_info_table(L, 6);
  lua_pushinteger(L, st.recomputed); lua_setfield(L, -2, "recomputed");
  lua_pushinteger(L, st.states ? st.states : 1); lua_setfield(L, -2, "states");
  lua_pushinteger(L, st.states ? st.in_memory : 1); lua_setfield(L, -2, "in_memory");
  lua_pushinteger(L, st.disk_writes); lua_setfield(L, -2, "disk_writes");
  lua_pushinteger(L, st.disk_reads); lua_setfield(L, -2, "disk_reads");
  if (st.dir) { lua_pushstring(L, st.dir); lua_setfield(L, -2, "dir"); }
  return 1;
}

/* ---------------------------------------------------------------- sensitivities */

typedef struct {
  int nf, N, history;
  size_t stride;               /* values of one step's tangent (every field) */
  int ndof[KER_MAXFIELD];
  double *buf;
} sens_rec;

static void sens_take(void *ud, int k, const double *const *du) {
  sens_rec *r = ud;
  if (!r->history && k != r->N) return;
  double *o = r->buf + (r->history ? (size_t)k * r->stride : 0);
  for (int a = 0; a < r->nf; a++) {
    memcpy(o, du[a], sizeof(double) * (size_t)r->ndof[a]);
    o += r->ndof[a];
  }
}

/* step k's tangent as new functions (one per unknown) on the stack */
static void push_tangent(lua_State *L, lg_time *T, const sens_rec *r, int k, const char *fn) {
  lg_env *env = get_env(L);
  lg_function *out[KER_MAXFIELD];
  const double *x = r->buf + (size_t)k * r->stride;
  for (int a = 0; a < r->nf; a++) {
    lg_function *p = lg_time_previous(T, 0, a);
    expr_func_info *fi = expr_func_get(env->c, p->fid);
    char nm[80];
    snprintf(nm, sizeof nm, "d%s", fi ? fi->name : "u");
    if (!(out[a] = lg_function_new(env, p->mesh, p->dm, nm))) {
      for (int b = 0; b < a; b++) lg_function_free(out[b]);
      lgerror(L, fn, env);
    }
    memcpy(out[a]->x, x, sizeof(double) * (size_t)r->ndof[a]);
    x += r->ndof[a];
  }
  push_functions_of(L, 1, out, r->nf);
}

/* step:sensitivity(m[, dm][, {history = true}]): the tangent-linear march along dm of the
 * controls m (as for rf:hessian: fields, parameters, initial states, per-step controls; a
 * parameter's direction defaults to 1): du(t1)/dm dm, one function per unknown, or with
 * history every step's (a table of N + 1, t0 .. t1; of tables of one per unknown when there
 * are several) */
int lg_lua_time_sensitivity(lua_State *L) {
  gc_point(L, 1);
  const char *fn = "step:sensitivity";
  lg_time *T = time_of(L, 1);
  if (!T) return typeerror(L, fn, 1, "a time-dependent problem (lg.time_problem)");
  lua_settop(L, 4);
  int oidx = 4, didx = 3;
  if (lua_isnil(L, 4) && lua_istable(L, 3) && !luaL_testudata(L, 3, MT_EXPR) && lua_getfield(L, 3, "history") != LUA_TNIL) {
    oidx = 3;
    didx = 0;
  }
  lua_settop(L, 4);
  int history = 0;
  if (!lua_isnil(L, oidx)) {
    if (!lua_istable(L, oidx)) return typeerror(L, fn, oidx, "an options table {history = true}");
    static const char *const keys[] = {"history", NULL};
    check_keys(L, oidx, fn, keys);
    lua_getfield(L, oidx, "history");
    history = lua_toboolean(L, -1);
    lua_pop(L, 1);
  }
  if (didx && lua_isnil(L, didx)) didx = 0;
  lg_control c[LG_MAXCONTROL];
  int nc = read_controls(L, 2, c, fn, "argument 2 (the control)");
  lg_env *env = get_env(L);
  ud_time *ut = luaL_testudata(L, 1, MT_TIME); /* its progress lines as the problem's own */
  lg_reduced *rf = lg_reduced_new_time(env, T, 0, NULL, nc, c, NULL, ut->monitor ? ut->every : 0);
  if (!rf) return lgerror(L, fn, env);
  ud_reduced *u = new_ud(L, sizeof *u, MT_REDUCED, 0, NULL); /* frees rf at an error too */
  u->rf = rf;
  double *dm[LG_MAXCONTROL];
  if (didx) read_direction(L, rf, didx, dm, fn);
  else
    for (int i = 0; i < nc; i++) {
      if (c[i].kind != LG_CONTROL_PARAM)
        return luaL_error(L, "%s: argument 3 (the direction) is required for control %d, a field or an initial state", fn, i + 1);
      dm[i] = lua_newuserdatauv(L, sizeof(double) * 2, 0);
      dm[i][0] = 1;
    }
  sens_rec r = {0};
  lg_field_info fi[KER_MAXFIELD];
  r.nf = lg_problem_fields(lg_time_step_problem(T), fi);
  r.N = lg_time_nsteps(T);
  r.history = history;
  for (int a = 0; a < r.nf; a++) {
    r.ndof[a] = fi[a].dm->ndof;
    r.stride += (size_t)r.ndof[a];
  }
  r.buf = lua_newuserdatauv(L, sizeof(double) * r.stride * (history ? (size_t)r.N + 1 : 1) + 8, 0);
  if (lg_time_sensitivity(env, rf, dm, sens_take, &r)) return lgerror(L, fn, env);
  if (!history) {
    int base = lua_gettop(L);
    push_tangent(L, T, &r, 0, fn);
    return lua_gettop(L) - base;
  }
  lua_createtable(L, r.N + 1, 0);
  int t = lua_gettop(L);
  for (int k = 0; k <= r.N; k++) {
    push_tangent(L, T, &r, k, fn);
    if (r.nf > 1) {
      lua_createtable(L, r.nf, 0);
      lua_insert(L, -r.nf - 1);
      for (int a = r.nf; a >= 1; a--) lua_rawseti(L, -a - 1, a); /* f_a on top, the table below the a of them */
    }
    lua_rawseti(L, t, k + 1);
  }
  return 1;
}

static int reduced_state(lua_State *L) {
  const char *fn = "rf:state";
  ud_reduced *u = check_reduced(L, 1, fn);
  lg_env *env = get_env(L);
  double J;
  if (lg_reduced_value(env, u->rf, &J)) return lgerror(L, fn, env);
  lg_problem *p = lg_reduced_problem(u->rf);
  lg_field_info fi[KER_MAXFIELD];
  int nf = lg_problem_fields(p, fi);
  const double *x = lg_problem_solution(p);
  lg_function *out[KER_MAXFIELD];
  for (int a = 0; a < nf; a++) {
    expr_func_info *info = expr_func_get(env->c, fi[a].unknown);
    char nm[80];
    snprintf(nm, sizeof nm, "%sh", info ? info->name : "u");
    out[a] = lg_function_new(env, lg_problem_mesh(p), (dofmap *)fi[a].dm, nm);
    if (!out[a]) return lgerror(L, fn, env);
    memcpy(out[a]->x, x + fi[a].offset, sizeof(double) * (size_t)fi[a].dm->ndof);
  }
  push_functions_of(L, 1, out, nf);
  return nf;
}

/* ---------------------------------------------------------------- Taylor test */

static int taylor_tostring(lua_State *L) {
  lua_getfield(L, 1, "text");
  return 1;
}

/* set the controls to m0 + h dm (h = 0: back to m0) */
static void move_controls(lg_reduced *rf, double **m0, double **dm, double h) {
  for (int i = 0; i < lg_reduced_ncontrols(rf); i++) {
    int n = lg_reduced_control_size(rf, i);
    double *x = lg_reduced_control_values(rf, i);
    for (int j = 0; j < n; j++) x[j] = m0[i][j] + h * dm[i][j];
  }
  lg_reduced_changed(rf);
}

/* lg.taylor_test(rf, m, dm[, {steps=4, h=1e-2, hessian=false}]): the remainders
 * R0 = |j(m + h dm) - j(m)|, R1 = |j(m + h dm) - j(m) - h dj(m; dm)| and, with hessian,
 * R2 = |... - h^2/2 dm.H(m) dm| for h, h/2, ...: rates 1, 2 and 3 when the derivatives are right */
static int l_taylor_test(lua_State *L) {
  gc_point(L, 1);
  const char *fn = "lg.taylor_test";
  ud_reduced *u = check_reduced(L, 1, fn);
  if (lua_isnoneornil(L, 2)) return typeerror(L, fn, 2, "the control values to test at (like rf:value's)");
  if (lua_isnoneornil(L, 3)) return typeerror(L, fn, 3, "a direction (like the controls)");
  int steps = 4, hess = 0;
  double h0 = 1e-2;
  if (!lua_isnoneornil(L, 4)) {
    if (!lua_istable(L, 4)) return typeerror(L, fn, 4, "an options table {steps=, h=, hessian=}");
    static const char *const keys[] = {"steps", "h", "hessian", NULL};
    check_keys(L, 4, fn, keys);
    steps = opt_int(L, 4, "steps", 4, fn);
    if (steps < 2 || steps > 30) return luaL_error(L, "%s: option 'steps' must be 2 to 30, got %d", fn, steps);
    h0 = opt_num(L, 4, "h", 1e-2, fn);
    if (!(h0 > 0) || !isfinite(h0)) return luaL_error(L, "%s: option 'h' must be a positive number, got %f", fn, h0);
    int t = lua_getfield(L, 4, "hessian");
    if (t != LUA_TNIL && t != LUA_TBOOLEAN) return luaL_error(L, "%s: option 'hessian' must be a boolean, got %s", fn, lua_typename(L, t));
    hess = lua_toboolean(L, -1);
    lua_pop(L, 1);
  }
  lg_reduced *rf = u->rf;
  lg_env *env = get_env(L);
  int nc = lg_reduced_ncontrols(rf);
  lua_settop(L, 4);
  double *m0[LG_MAXCONTROL], *dm[LG_MAXCONTROL], *g[LG_MAXCONTROL], *hd[LG_MAXCONTROL];
  read_direction(L, rf, 3, dm, fn);
  /* j(m), dj(m; dm) and dm.H(m) dm */
  set_controls(L, rf, 2, fn);
  for (int i = 0; i < nc; i++) {
    int n = lg_reduced_control_size(rf, i);
    m0[i] = lua_newuserdatauv(L, sizeof(double) * ((size_t)n + 1), 0);
    memcpy(m0[i], lg_reduced_control_values(rf, i), sizeof(double) * (size_t)n);
  }
  double J0;
  if (lg_reduced_value(env, rf, &J0)) return lgerror(L, fn, env);
  raw_gradient(L, rf, g, fn);
  double dJ = pair_vectors(L, rf, g, dm, fn), d2J = 0;
  if (hess) {
    raw_hessian(L, rf, dm, hd, fn);
    d2J = pair_vectors(L, rf, dm, hd, fn);
  }
  lua_createtable(L, 0, 9);
  int res = lua_gettop(L);
  double r[3][32], hs[32];
  int nr = hess ? 3 : 2;
  for (int s = 0; s < steps; s++) {
    double h = h0 / pow(2, s);
    move_controls(rf, m0, dm, h);
    double Jh;
    if (lg_reduced_value(env, rf, &Jh)) {
      move_controls(rf, m0, dm, 0); /* restore m before reporting */
      return lgerror(L, fn, env);
    }
    hs[s] = h;
    r[0][s] = fabs(Jh - J0);
    r[1][s] = fabs(Jh - J0 - h * dJ);
    r[2][s] = fabs(Jh - J0 - h * dJ - 0.5 * h * h * d2J);
  }
  move_controls(rf, m0, dm, 0);
  static const char *const rname[3] = {"remainders0", "remainders1", "remainders2"};
  static const char *const qname[3] = {"rates0", "rates1", "rates2"};
  lua_createtable(L, steps, 0);
  for (int s = 0; s < steps; s++) { lua_pushnumber(L, hs[s]); lua_rawseti(L, -2, s + 1); }
  lua_setfield(L, res, "h");
  double q[3][32];
  for (int k = 0; k < nr; k++) {
    lua_createtable(L, steps, 0);
    for (int s = 0; s < steps; s++) { lua_pushnumber(L, r[k][s]); lua_rawseti(L, -2, s + 1); }
    lua_setfield(L, res, rname[k]);
    lua_createtable(L, steps - 1, 0);
    for (int s = 1; s < steps; s++) {
      q[k][s] = log(r[k][s - 1] / r[k][s]) / log(hs[s - 1] / hs[s]);
      lua_pushnumber(L, q[k][s]);
      lua_rawseti(L, -2, s);
    }
    lua_setfield(L, res, qname[k]);
  }
  lua_pushnumber(L, J0); lua_setfield(L, res, "j");
  lua_pushnumber(L, dJ); lua_setfield(L, res, "dj");
  if (hess) { lua_pushnumber(L, d2J); lua_setfield(L, res, "d2j"); }
  luaL_Buffer b;
  luaL_buffinit(L, &b);
  char line[200];
  snprintf(line, sizeof line, "Taylor test: j = %.10g, dj(m; dm) = %.10g", J0, dJ);
  luaL_addstring(&b, line);
  if (hess) { snprintf(line, sizeof line, ", dm.H dm = %.10g", d2J); luaL_addstring(&b, line); }
  snprintf(line, sizeof line, "\n  %-10s", "h");
  luaL_addstring(&b, line);
  for (int k = 0; k < nr; k++) { snprintf(line, sizeof line, " |R%d|%-10s rate  ", k, ""); luaL_addstring(&b, line); }
  for (int s = 0; s < steps; s++) {
    snprintf(line, sizeof line, "\n  %-10.3g", hs[s]);
    luaL_addstring(&b, line);
    for (int k = 0; k < nr; k++) {
      if (s) snprintf(line, sizeof line, " %-14.6e %-6.2f", r[k][s], q[k][s]);
      else snprintf(line, sizeof line, " %-14.6e %-6s", r[k][s], "");
      luaL_addstring(&b, line);
    }
  }
  luaL_pushresult(&b);
  lua_setfield(L, res, "text");
  if (luaL_newmetatable(L, "lugal.TaylorTest")) {
    lua_pushcfunction(L, taylor_tostring);
    lua_setfield(L, -2, "__tostring");
  }
  lua_setmetatable(L, res);
  lua_settop(L, res);
  return 1;
}

/* ---------------------------------------------------------------- minimization */

/* a bound for control i from the value at idx: a number or a discrete function of its space;
 * the values go into a userdata buffer left on the stack */
static const double *bound_values(lua_State *L, lg_reduced *rf, int i, int idx, const char *fn, const char *which) {
  if (lua_isnoneornil(L, idx)) return NULL;
  const lg_control *c = lg_reduced_control(rf, i);
  int n = lg_reduced_control_size(rf, i);
  double *v = lua_newuserdatauv(L, sizeof(double) * ((size_t)n + 1), 0);
  int isnum;
  double b = lua_tonumberx(L, idx, &isnum);
  if (isnum) { /* a number (±math.huge: none) */
    for (int k = 0; k < n; k++) v[k] = b;
    return v;
  }
  ud_func *bf = luaL_testudata(L, idx, MT_FUNC);
  if (c->kind != LG_CONTROL_FIELD || (bf && bf->f->dm != c->f->dm) || (!bf && !(c->per_step && lua_istable(L, idx))))
    luaL_error(L, "%s: the %s bound of control %d must be a number or a discrete function of the control's basis and mesh, got %s",
               fn, which, i + 1, luaL_typename(L, idx));
  char what[48];
  snprintf(what, sizeof what, "the %s bound of control %d", which, i + 1);
  fill_control(L, rf, i, idx, v, fn, what);
  return v;
}

/* the bounds of control i: no NaN, lower <= upper everywhere (either may be absent; ±math.huge
 * is no bound). A box with lower above upper has no point: TAO's bounded methods returned one
 * side with converged = true after 0 iterations */
static void check_bounds(lua_State *L, lg_reduced *rf, int i, const double *lo, const double *up, const char *fn) {
  int n = lg_reduced_control_size(rf, i);
  for (int k = 0; k < n; k++) {
    if ((lo && isnan(lo[k])) || (up && isnan(up[k])))
      luaL_error(L, "%s: the %s bound of control %d is nan at dof %d", fn, lo && isnan(lo[k]) ? "lower" : "upper", i + 1, k + 1);
    if (lo && up && lo[k] > up[k])
      luaL_error(L, "%s: the lower bound of control %d is above its upper bound at dof %d (%f > %f): bounds = {lower, upper}", fn,
                 i + 1, k + 1, lo[k], up[k]);
  }
}

/* lg.minimize(rf, {method=, bounds={lower, upper}, gatol=, grtol=, gttol=, maxit=, monitor=, series=,
 * inner_product=}) */
/* lg.minimize's option constraints = {{g, "<=" | ">=" | "==", c}, ...} (on the top of the
 * stack, not nil) into o->cons; u is the objective */
static void opt_constraints(lua_State *L, const ud_reduced *u, lg_minimize_opts *o, const char *fn) {
  int ct = lua_gettop(L);
  if (!lua_istable(L, ct)) (void)luaL_error(L, "%s: option 'constraints' must be a table {{g, \"<=\", c}, ...}, got %s", fn,
                                            luaL_typename(L, ct));
  lua_Integer ncon = luaL_len(L, ct);
  if (ncon < 1 || ncon > LG_MAXCONS) (void)luaL_error(L, "%s: option 'constraints' must list 1 to %d constraints", fn, LG_MAXCONS);
  for (lua_Integer j = 1; j <= ncon; j++) {
    lua_geti(L, ct, j);
    int e = lua_gettop(L);
    if (!lua_istable(L, e) || luaL_len(L, e) != 3)
      (void)luaL_error(L, "%s: constraint %d must be {g, \"<=\" | \">=\" | \"==\", c} with g a reduced functional", fn, (int)j);
    lua_geti(L, e, 1);
    ud_reduced *ug = luaL_testudata(L, -1, MT_REDUCED);
    if (!ug) (void)luaL_error(L, "%s: constraint %d: g must be a reduced functional (lg.reduced_functional), got %s", fn, (int)j,
                               luaL_typename(L, -1));
    if (ug == u) (void)luaL_error(L, "%s: constraint %d is the objective itself", fn, (int)j);
    lua_geti(L, e, 2);
    const char *op = lua_tostring(L, -1);
    int kind = !op ? -1 : !strcmp(op, "<=") ? LG_CON_LE : !strcmp(op, ">=") ? LG_CON_GE : !strcmp(op, "==") ? LG_CON_EQ : -1;
    if (kind < 0) (void)luaL_error(L, "%s: constraint %d: the relation must be \"<=\", \">=\" or \"==\"", fn, (int)j);
    lua_geti(L, e, 3);
    int isnum = 0;
    double c = lua_tonumberx(L, -1, &isnum);
    if (!isnum || !isfinite(c)) (void)luaL_error(L, "%s: constraint %d: the bound must be a finite number", fn, (int)j);
    o->cons[o->ncons].rf = ug->rf;
    o->cons[o->ncons].kind = kind;
    o->cons[o->ncons].c = c;
    o->ncons++;
    lua_pop(L, 4);
  }
}

/* lg.minimize's option bounds = {lower, upper} (the options table at index 2) into
 * o->lower, o->upper, the bounded variant of the method chosen; the bound buffers are
 * anchored in a table left on the stack */
static void opt_bounds(lua_State *L, const ud_reduced *u, lg_minimize_opts *o, int nc, const char *fn) {
  lua_newtable(L); /* anchors the bound buffers */
  int anchor = lua_gettop(L), nanch = 0;
  if (lua_getfield(L, 2, "bounds") != LUA_TNIL) {
    if (!lua_istable(L, -1)) (void)luaL_error(L, "%s: option 'bounds' must be a table {lower, upper}", fn);
    int bt = lua_gettop(L);
    /* bounds need the bounded variant */
    if (!strcmp(o->method, "lmvm")) o->method = "blmvm";
    else if (!strcmp(o->method, "nls")) o->method = "bnls";
    else if (!strcmp(o->method, "ntr")) o->method = "bntr";
    for (int side = 0; side < 2; side++) {
      lua_geti(L, bt, side + 1);
      int vidx = lua_gettop(L);
      for (int i = 0; i < nc; i++) {
        int k = vidx;
        if (nc > 1 && !lua_isnil(L, vidx)) {
          if (!lua_istable(L, vidx) || luaL_testudata(L, vidx, MT_FUNC))
            (void)luaL_error(L, "%s: with %d controls, each bound is a table of one per control", fn, nc);
          lua_geti(L, vidx, i + 1);
          k = lua_gettop(L);
        }
        const double *b = bound_values(L, u->rf, i, k, fn, side ? "upper" : "lower");
        if (side) o->upper[i] = b; else o->lower[i] = b;
        if (b) lua_rawseti(L, anchor, ++nanch); /* the buffer lives in the anchor table */
        if (k != vidx) lua_pop(L, 1);
      }
      lua_pop(L, 1);
    }
    for (int i = 0; i < nc; i++) check_bounds(L, u->rf, i, o->lower[i], o->upper[i], fn);
  }
}

static int l_minimize(lua_State *L) {
  gc_point(L, 1);
  const char *fn = "lg.minimize";
  ud_reduced *u = check_reduced(L, 1, fn);
  lg_minimize_opts o;
  memset(&o, 0, sizeof o);
  o.method = "lmvm";
  o.gatol = o.grtol = o.gttol = -1;
  o.monitor = 1;
  o.riesz = LG_RIESZ_L2;
  int nc = lg_reduced_ncontrols(u->rf);
  if (!lua_isnoneornil(L, 2)) {
    if (!lua_istable(L, 2)) return typeerror(L, fn, 2, "an options table {method=, bounds=, gatol=, grtol=, maxit=, monitor=, series=}");
    static const char *const keys[] = {"method", "bounds", "gatol", "grtol", "gttol", "maxit", "monitor", "series", "inner_product",
                                       "constraints", NULL};
    check_keys(L, 2, fn, keys);
    int has_cons = lua_getfield(L, 2, "constraints") != LUA_TNIL;
    lua_pop(L, 1);
    o.method = opt_str(L, 2, "method", has_cons ? "almm" : "lmvm", fn);
    static const char *const methods[] = {"lmvm", "blmvm", "nls", "ntr", "bnls", "bntr", "almm", NULL};
    int known = 0;
    for (int i = 0; methods[i]; i++) known |= !strcmp(o.method, methods[i]);
    if (!known)
      return luaL_error(L, "%s: option 'method' must be \"lmvm\", \"blmvm\", \"nls\", \"ntr\", \"bnls\", \"bntr\" or \"almm\", "
                           "got \"%s\"", fn, o.method);
    if (!strcmp(o.method, "almm") && !has_cons)
      return luaL_error(L, "%s: method \"almm\" needs constraints = {{g, \"<=\", c}, ...}", fn);
    if (has_cons && strcmp(o.method, "almm"))
      return luaL_error(L, "%s: constraints need method \"almm\" (the augmented Lagrangian), got \"%s\"", fn, o.method);
    o.gatol = opt_tolerance(L, 2, "gatol", -1, fn);
    o.grtol = opt_tolerance(L, 2, "grtol", -1, fn);
    o.gttol = opt_tolerance(L, 2, "gttol", -1, fn);
    o.maxit = opt_int(L, 2, "maxit", 0, fn);
    if (o.maxit < 0) return luaL_error(L, "%s: option 'maxit' must be >= 0", fn);
    lua_getfield(L, 2, "monitor");
    if (!lua_isnil(L, -1)) o.monitor = lua_toboolean(L, -1);
    lua_pop(L, 1);
    o.series = opt_str(L, 2, "series", NULL, fn);
    if (o.series && (strlen(o.series) < 5 || strcmp(o.series + strlen(o.series) - 4, ".pvd")))
      return luaL_error(L, "%s: option 'series' must be a path ending in .pvd, got \"%s\"", fn, o.series);
    const char *ip = opt_str(L, 2, "inner_product", "l2", fn);
    if (!strcmp(ip, "l2")) o.riesz = LG_RIESZ_L2;
    else if (!strcmp(ip, "dofs")) o.riesz = LG_RIESZ_NONE;
    else return luaL_error(L, "%s: option 'inner_product' must be \"l2\" or \"dofs\", got \"%s\"", fn, ip);
    if (lua_getfield(L, 2, "constraints") != LUA_TNIL) opt_constraints(L, u, &o, fn);
    lua_pop(L, 1);
    opt_bounds(L, u, &o, nc, fn);
  }
  lg_env *env = get_env(L);
  lg_minimize_info info;
  int rc = lg_minimize(env, u->rf, &o, &info);
  if (rc) return lgerror(L, fn, env);
  /* the controls (which hold the minimizer) and the info table */
  lua_getiuservalue(L, 1, 1);
  int base = lua_gettop(L);
  for (int i = 0; i < nc; i++) {
    const lg_control *c = lg_reduced_control(u->rf, i);
    if (c->kind == LG_CONTROL_PARAM) { lua_pushnumber(L, expr_param_values(env->c)[c->param]); continue; }
    if (push_blocks(L, u->rf, i, lg_reduced_control_values(u->rf, i), "", fn)) continue; /* a function per step time */
    /* the control userdata: among the dependencies */
    int found = 0;
    lua_pushnil(L);
    while (lua_next(L, base)) {
      lua_pop(L, 1);
      ud_func *uf = luaL_testudata(L, -1, MT_FUNC);
      if (uf && uf->f == c->f) { found = 1; break; }
      if (lua_istable(L, -1)) { /* the control table */
        for (lua_Integer k = 1; k <= luaL_len(L, -1) && !found; k++) {
          lua_geti(L, -1, k);
          ud_func *vf = luaL_testudata(L, -1, MT_FUNC);
          if (vf && vf->f == c->f) { found = 1; lua_remove(L, -2); }
          else lua_pop(L, 1);
        }
        if (found) break;
      }
    }
    if (!found) lua_pushnil(L);
  }
  push_info_table(L, 6);
  lua_pushinteger(L, info.iterations); lua_setfield(L, -2, "iterations");
  lua_pushinteger(L, info.evaluations); lua_setfield(L, -2, "evaluations");
  lua_pushinteger(L, info.hessian_products); lua_setfield(L, -2, "hessian_products");
  lua_pushnumber(L, info.J); lua_setfield(L, -2, "J");
  lua_pushnumber(L, info.gnorm); lua_setfield(L, -2, "gnorm");
  lua_pushstring(L, info.reason); lua_setfield(L, -2, "reason");
  lua_pushboolean(L, info.converged); lua_setfield(L, -2, "converged");
  if (o.ncons) {
    lua_createtable(L, o.ncons, 0);
    for (int j = 0; j < o.ncons; j++) { lua_pushnumber(L, info.g[j]); lua_rawseti(L, -2, j + 1); }
    lua_setfield(L, -2, "constraints");
    lua_createtable(L, o.ncons, 0);
    for (int j = 0; j < o.ncons; j++) { lua_pushnumber(L, info.lambda[j]); lua_rawseti(L, -2, j + 1); }
    lua_setfield(L, -2, "multipliers");
    lua_pushnumber(L, info.cnorm); lua_setfield(L, -2, "cnorm");
  }
  return lua_gettop(L) - base;
}

/* ---------------------------------------------------------------- full space (KKT) */

/* which of the n functions ids the integrand e contains (a bit each) */
static unsigned uses_of(lg_env *env, expr *e, int n, const int *ids) {
  expr *leaf[64];
  int m = expr_collect_fields(env->c, 1, &e, -1, 64, leaf);
  unsigned bits = 0;
  for (int k = 0; k < m && k < 64; k++)
    for (int i = 0; i < n; i++)
      if (leaf[k]->i0 == ids[i]) bits |= 1u << i;
  return bits;
}

/* lg.kkt_problem{mesh=, lagrangian=, state=, adjoint=, control=, bc=, prefix=, initial=}:
 * the stationary point of L(u, lam, m) = J(u, m) + <R(u, m), lam> as one coupled nonlinear
 * problem in (u, lam, m): its equations are the variations of L in test directions of each
 * (dL/dlam: the state, dL/du: the adjoint, dL/dm: the optimality condition). The essential
 * conditions are the state's; the adjoint gets homogeneous ones on the same boundaries. */
static int l_kkt_problem(lua_State *L) {
  gc_point(L, 1);
  const char *fn = "lg.kkt_problem";
  if (!lua_istable(L, 1)) return typeerror(L, fn, 1, "a table {mesh=, lagrangian=, state=, adjoint=, control=, bc=}");
  static const char *const keys[] = {"mesh", "lagrangian", "state", "adjoint", "control", "bc", "prefix", "initial", NULL};
  check_keys(L, 1, fn, keys);
  lua_getfield(L, 1, "mesh");
  ud_mesh *um = luaL_testudata(L, -1, MT_MESH);
  if (!um) return luaL_error(L, "%s: option 'mesh' must be a mesh, got %s", fn, luaL_typename(L, -1));
  int mesh_idx = lua_gettop(L);
  lua_getfield(L, 1, "lagrangian");
  ud_form *uL = luaL_testudata(L, -1, MT_FORM);
  if (!uL) return luaL_error(L, "%s: option 'lagrangian' must be a form (lg.integral(...) + ...): J plus the equation with "
                                "its test functions replaced by the adjoint, got %s", fn, luaL_typename(L, -1));
  int lag_idx = lua_gettop(L);
  lg_env *env = get_env(L);
  int unk[KER_MAXFIELD], ns, na, nc;
  ns = check_symbols(L, 1, "state", FK_UNKNOWN, unk, fn);
  na = check_symbols(L, 1, "adjoint", FK_UNKNOWN, unk + ns, fn);
  if (na != ns) return luaL_error(L, "%s: %d adjoints for %d states (one per state)", fn, na, ns);
  if (2 * ns + 1 > KER_MAXFIELD) return luaL_error(L, "%s: at most %d fields in all", fn, KER_MAXFIELD);
  int ctl[KER_MAXFIELD];
  nc = check_symbols(L, 1, "control", FK_UNKNOWN, ctl, fn);
  if (2 * ns + nc > KER_MAXFIELD) return luaL_error(L, "%s: at most %d fields in all (states, adjoints, controls)", fn, KER_MAXFIELD);
  for (int i = 0; i < nc; i++) unk[2 * ns + i] = ctl[i];
  int n = 2 * ns + nc;
  for (int i = 0; i < n; i++)
    for (int j = 0; j < i; j++)
      if (unk[i] == unk[j])
        return luaL_error(L, "%s: %s is listed twice (state, adjoint and control are different unknowns)", fn,
                          expr_func_get(env->c, unk[i])->name);
  for (int a = 0; a < ns; a++) {
    const expr_func_info *s = expr_func_get(env->c, unk[a]), *l = expr_func_get(env->c, unk[ns + a]);
    if (s->degree != l->degree || s->ncomp != l->ncomp || s->disc != l->disc)
      return luaL_error(L, "%s: the adjoint %s must use the basis of its state %s (P%d), got P%d", fn, l->name, s->name, s->degree,
                        l->degree);
  }
  const form *Lf = uL->f;
  unsigned used = 0;
  for (int i = 0; i < Lf->n; i++) {
    if (Lf->t[i].reg.mesh != um->lm) return luaL_error(L, "%s: the lagrangian integrates over a different mesh than 'mesh'", fn);
    expr *e = Lf->t[i].integrand, *leaf[64];
    int m = expr_collect_fields(env->c, 1, &e, -1, 64, leaf);
    for (int k = 0; k < m && k < 64; k++) {
      expr_func_info *fi = expr_func_get(env->c, leaf[k]->i0);
      if (fi && fi->kind == FK_TEST)
        return luaL_error(L, "%s: the lagrangian contains the test function %s: write the equation with the adjoint in its place",
                          fn, fi->name);
    }
    used |= uses_of(env, e, n, unk);
  }
  for (int i = 0; i < n; i++)
    if (!(used & (1u << i)))
      return luaL_error(L, "%s: the lagrangian does not contain the %s %s", fn, i < ns ? "state" : i < 2 * ns ? "adjoint" : "control",
                        expr_func_get(env->c, unk[i])->name);
  const char *prefix = opt_str(L, 1, "prefix", NULL, fn);
  /* a test direction per unknown, and the variations */
  int test[KER_MAXFIELD];
  for (int i = 0; i < n; i++) {
    const expr_func_info *fi = expr_func_get(env->c, unk[i]);
    char nm[80];
    snprintf(nm, sizeof nm, "%.60s_test", fi->name);
    if ((test[i] = expr_func_new(env->c, FK_TEST, nm, fi->degree, fi->ncomp, NULL)) < 0) return luaL_error(L, "%s: out of memory", fn);
    expr_func_get(env->c, test[i])->disc = fi->disc;
  }
  lua_getfield(L, 1, "bc");
  int bc_idx = lua_gettop(L);
  form *bc_user = NULL;
  const form *bcu = check_bcs(L, bc_idx, fn, &bc_user);
  /* from here on errors free what they own first */
  form *F = form_variation(env->c, Lf, n, unk, test), *bc = form_new();
  char err[LG_ERRLEN + 64] = "";
  if (!F || !bc) snprintf(err, sizeof err, "%s", expr_error(env->c)[0] ? expr_error(env->c) : "out of memory");
  unsigned char z[3] = {0, 0, 0};
  for (int i = 0; !err[0] && bcu && i < bcu->n; i++) {
    const form_term *t = &bcu->t[i];
    if (t->reg.mesh != um->lm) { snprintf(err, sizeof err, "a boundary condition is on a different mesh than 'mesh'"); break; }
    unsigned u = uses_of(env, t->integrand, n, unk);
    int a = -1;
    for (int k = 0; k < ns; k++)
      if (u & (1u << k)) a = a < 0 ? k : -2;
    if (u >> ns) { snprintf(err, sizeof err, "boundary condition %d involves an adjoint or a control: only the state's essential "
                                             "conditions are given (Dirichlet controls are not supported yet)", i + 1); break; }
    if (a < 0) { snprintf(err, sizeof err, "boundary condition %d must constrain exactly one state", i + 1); break; }
    /* its test function becomes the state's test direction */
    expr *e = t->integrand, *leaf[64];
    int m = expr_collect_fields(env->c, 1, &e, -1, 64, leaf);
    for (int k = 0; k < m && k < 64 && e; k++) {
      expr_func_info *fi = expr_func_get(env->c, leaf[k]->i0);
      if (fi && fi->kind == FK_TEST && leaf[k]->i0 != test[a]) e = form_replace_function(env->c, e, leaf[k]->i0, test[a]);
    }
    /* the adjoint's homogeneous condition on the same boundary and components */
    expr *hom = expr_num(env->c, 0), *tl[16];
    int ntl = e ? expr_collect_fields(env->c, 1, &e, test[a], 16, tl) : 0;
    unsigned comps = 0;
    for (int k = 0; k < ntl && k < 16; k++) comps |= 1u << tl[k]->i1;
    for (int j = 0; hom && j < FEM_MAXBS; j++)
      if (comps & (1u << j))
        hom = expr_add(env->c, hom, expr_mul(env->c, expr_field(env->c, test[ns + a], j, z), expr_field(env->c, unk[ns + a], j, z)));
    if (!e || !hom || form_add_term(bc, &t->reg, e, -1) || form_add_term(bc, &t->reg, hom, -1))
      snprintf(err, sizeof err, "%s", expr_error(env->c)[0] ? expr_error(env->c) : "out of memory");
  }
  form_free(bc_user);
  lg_problem *p = NULL;
  if (!err[0]) {
    lg_problem_spec s = {um->lm, F, bc->n ? bc : NULL, n, test, unk, 1, 0, prefix, 0, NULL, 0};
    p = lg_problem_new(env, &s);
    if (!p) snprintf(err, sizeof err, "%s", env->err);
  }
  form_free(F);
  form_free(bc);
  if (err[0]) return luaL_error(L, "%s: %s", fn, err);
  int deps[3] = {mesh_idx, lag_idx, bc_idx};
  push_problem(L, p, n, 1, lua_isnil(L, bc_idx) ? 2 : 3, deps);
  return 1;
}

/* ---------------------------------------------------------------- registration */

void lg_lua_opt_register(lua_State *L) {
  static const luaL_Reg functional_mm[] = {{"__gc", functional_gc}, {NULL, NULL}};
  new_mt(L, MT_FUNCTIONAL, functional_mm, NULL);
  static const luaL_Reg reduced_mm[] = {{"__gc", reduced_gc}, {NULL, NULL}};
  static const luaL_Reg reduced_methods[] = {{"value", reduced_value}, {"derivative", reduced_derivative},
                                             {"gradient", reduced_gradient}, {"hessian", reduced_hessian},
                                             {"state", reduced_state}, {"stats", reduced_stats}, {NULL, NULL}};
  new_mt(L, MT_REDUCED, reduced_mm, reduced_methods);
}

const luaL_Reg lg_opt_lib[] = {{"control", l_control}, {"functional", l_functional},
                               {"reduced_functional", l_reduced_functional}, {"taylor_test", l_taylor_test},
                               {"minimize", l_minimize}, {"kkt_problem", l_kkt_problem}, {NULL, NULL}};
