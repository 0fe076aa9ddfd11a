/* lexpr.c — Lua bindings of the symbolic layer: expressions and their operators, forms
 * (lg.integral, lg.essential_bc), bases and symbols, vector calculus, lg.integrate. */
#include "largs.h"

#include <lauxlib.h>
#include <limits.h>
#include <math.h>
#include <petscsys.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

typedef expr *(*binop_fn)(expr_ctx *, expr *, expr *);

static int form_arith(lua_State *L, double s, const char *name);
static int m_mul(lua_State *L);

static int arith(lua_State *L, binop_fn op, const char *name) {
  lg_env *env = get_env(L);
  int lazy = op == expr_add_lazy || op == expr_sub_lazy || op == expr_mul_lazy;
  expr *a = lazy ? check_expr_raw(L, 1, name) : check_expr(L, 1, name);
  expr *b = lazy ? check_expr_raw(L, 2, name) : check_expr(L, 2, name);
  int deps[2] = {1, 2};
  push_expr(L, op(env->c, a, b), 2, deps, name);
  return 1;
}

static int m_add(lua_State *L) {
  if (luaL_testudata(L, 1, MT_FORM) || luaL_testudata(L, 2, MT_FORM) || luaL_testudata(L, 1, MT_BC) ||
      luaL_testudata(L, 2, MT_BC))
    return form_arith(L, 1, "+");
  return arith(L, expr_add_lazy, "operator +");
}

static int m_sub(lua_State *L) {
  if (luaL_testudata(L, 1, MT_FORM) || luaL_testudata(L, 2, MT_FORM)) return form_arith(L, -1, "-");
  return arith(L, expr_sub_lazy, "operator -");
}

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
  lua_pushinteger(L, expr_shape(expr_of(L, u), NULL));
  return 1;
}

static int param_set(lua_State *L) {
  ud_expr *u = luaL_checkudata(L, 1, MT_EXPR);
  if (expr_of(L, u)->kind != E_PARAM) return luaL_error(L, "set: only parameters (lg.parameter) can be set");
  double v = luaL_checknumber(L, 2);
  if (!isfinite(v))
    return luaL_error(L, "set: parameter %s must be set to a finite number, got %f", expr_param_name(get_env(L)->c, u->e->i0), v);
  expr_param_values(get_env(L)->c)[u->e->i0] = v;
  return 0;
}

static int param_value(lua_State *L) {
  ud_expr *u = luaL_checkudata(L, 1, MT_EXPR);
  if (expr_of(L, u)->kind == E_CONST) { lua_pushnumber(L, u->e->value); return 1; }
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
  if (expr_of(L, u)->kind != E_LIST) return luaL_error(L, "cannot index a scalar expression");
  if (i < 1 || i > u->e->n) return luaL_error(L, "index %I out of range 1..%d", i, u->e->n);
  int deps[1] = {1};
  push_expr(L, u->e->ch[i - 1], 1, deps, "index");
  return 1;
}

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
  return arith(L, expr_mul_lazy, "operator *");
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
    luaL_addstring(&b, f->t[i].reg.kind == REGION_CELLS ? "∫_cells " : f->t[i].reg.kind == REGION_INTERIOR ? "∫_interior " : "∫_boundary ");
    luaL_addstring(&b, buf);
  }
  luaL_pushresult(&b);
  return 1;
}

static int l_lagrange(lua_State *L) {
  if (lua_gettop(L) > 1) return luaL_error(L, "lg.lagrange: takes one argument (the degree), got %d", lua_gettop(L));
  lua_Integer p = luaL_checkinteger(L, 1);
  if (p < 0 || p > 3)
    return luaL_error(L, "lg.lagrange: argument 1 must be a degree 0 (piecewise constants), 1, 2 or 3, got %I", p);
  ud_basis *u = new_ud(L, sizeof *u, MT_BASIS, 0, NULL);
  u->degree = (int)p;
  u->ncomp = 1;
  return 1;
}

static int basis_tostring(lua_State *L) {
  ud_basis *u = luaL_checkudata(L, 1, MT_BASIS);
  const char *fam = u->disc ? "discontinuous Lagrange" : "Lagrange";
  if (u->ncomp > 1) lua_pushfstring(L, "%s P%d, %d components", fam, u->degree, u->ncomp);
  else lua_pushfstring(L, "%s P%d", fam, u->degree);
  return 1;
}

/* lg.discontinuous(p): the Lagrange element of degree p with every node owned by its cell
 * (DG Pk on simplices, Qk on quadrilaterals and hexahedra; p = 0 is lg.lagrange(0)) */
static int l_discontinuous(lua_State *L) {
  if (lua_gettop(L) > 1) return luaL_error(L, "lg.discontinuous: takes one argument (the degree), got %d", lua_gettop(L));
  lua_Integer p = luaL_checkinteger(L, 1);
  if (p < 0 || p > 3) return luaL_error(L, "lg.discontinuous: argument 1 must be a degree 0, 1, 2 or 3, got %I", p);
  ud_basis *u = new_ud(L, sizeof *u, MT_BASIS, 0, NULL);
  u->degree = (int)p;
  u->ncomp = 1;
  u->disc = p > 0;
  return 1;
}

/* lg.vector(basis[, n]): n components (default: the dimension of the last mesh made) of a
 * scalar basis, interlaced in one dof map */
static int l_vector(lua_State *L) {
  const char *fn = "lg.vector";
  ud_basis *b = luaL_testudata(L, 1, MT_BASIS);
  if (!b) return typeerror(L, fn, 1, "a scalar basis (lg.lagrange(p))");
  if (b->ncomp > 1) return luaL_error(L, "%s: argument 1 is already a vector basis (%d components)", fn, b->ncomp);
  if (lua_gettop(L) > 2) return luaL_error(L, "%s: takes a basis and a number of components, got %d arguments", fn, lua_gettop(L));
  int n = lua_isnoneornil(L, 2) ? expr_dim(get_env(L)->c) : check_int_arg(L, 2, 1, FEM_MAXBS, fn);
  ud_basis *u = new_ud(L, sizeof *u, MT_BASIS, 0, NULL);
  u->degree = b->degree;
  u->ncomp = n;
  u->disc = b->disc;
  return 1;
}

static int new_symbol(lua_State *L, func_kind kind, const char *fn) {
  ud_basis *b = luaL_testudata(L, 1, MT_BASIS);
  if (!b) return typeerror(L, fn, 1, "a basis (lg.lagrange(p))");
  const char *name = opt_cstring(L, 2, kind == FK_TEST ? "v" : "u", fn, "argument 2 (the name)");
  if (lua_gettop(L) > 2) return luaL_error(L, "%s: takes a basis and a name, got %d arguments", fn, lua_gettop(L));
  lg_env *env = get_env(L);
  int id = expr_func_new(env->c, kind, name, b->degree, b->ncomp, NULL);
  if (id < 0) return luaL_error(L, "%s: out of memory", fn);
  expr_func_get(env->c, id)->disc = b->disc;
  push_expr(L, symbol_expr(env, id), 0, NULL, fn);
  return 1;
}

static int l_unknown(lua_State *L) { return new_symbol(L, FK_UNKNOWN, "lg.unknown"); }

static int l_test(lua_State *L) { return new_symbol(L, FK_TEST, "lg.test"); }

static int l_coord(lua_State *L) {
  lua_Integer i = luaL_checkinteger(L, 1);
  if (i < 1 || i > 3) return luaL_error(L, "lg.coord: argument 1 must be 1, 2 or 3, got %I", i);
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
  const char *name = check_cstring(L, 1, "lg.parameter", "argument 1 (the name)");
  double v = luaL_optnumber(L, 2, 0);
  if (!isfinite(v)) return luaL_error(L, "lg.parameter: argument 2 (the value of %s) must be a finite number, got %f", name, v);
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
  if (i < 1 || i > 3) return luaL_error(L, "lg.dx: argument 2 must be a direction 1, 2 or 3, got %I", i);
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

/* tensor algebra (src/expr/tensor.c) */
#define TENSOR1(NAME, FN)                                                  \
  static int l_##NAME(lua_State *L) {                                      \
    if (lua_gettop(L) != 1) return luaL_error(L, "lg." #NAME ": takes one matrix, got %d arguments", lua_gettop(L)); \
    expr *a = check_expr(L, 1, "lg." #NAME);                               \
    int deps[1] = {1};                                                     \
    push_expr(L, FN(get_env(L)->c, a), 1, deps, "lg." #NAME);              \
    return 1;                                                              \
  }
/* restrictions to the sides of an interior facet (mesh:interior_facets()): lg.minus(e) is
 * e on the '-' cell (its functions' values there, n -> -n), lg.plus(e) e on the '+' cell
 * (e itself: the normal points from '+' to '-'), lg.jump(e) = e+ - e-, lg.jump(e, n) =
 * e+ n+ + e- n- (for a vector e the normal component of the jump), lg.avg(e) = (e+ + e-)/2 */
static expr *minus_side(lua_State *L, expr *e, const char *fn) {
  expr *r = expr_restrict(get_env(L)->c, e, 1);
  if (!r) exprerror(L, fn);
  return r;
}

static void one_expression(lua_State *L, const char *fn, int most) {
  int n = lua_gettop(L);
  if (n < 1 || n > most)
    luaL_error(L, "%s: takes %s, got %d argument%s", fn, most == 1 ? "one expression" : "an expression and optionally the normal",
               n, n == 1 ? "" : "s");
}

static int l_minus(lua_State *L) {
  one_expression(L, "lg.minus", 1);
  expr *e = check_expr(L, 1, "lg.minus");
  int deps[1] = {1};
  push_expr(L, minus_side(L, e, "lg.minus"), 1, deps, "lg.minus");
  return 1;
}

static int l_plus(lua_State *L) {
  one_expression(L, "lg.plus", 1);
  expr *e = check_expr(L, 1, "lg.plus");
  int deps[1] = {1};
  push_expr(L, e, 1, deps, "lg.plus");
  return 1;
}

static int l_jump(lua_State *L) {
  one_expression(L, "lg.jump", 2);
  expr_ctx *c = get_env(L)->c;
  expr *e = check_expr(L, 1, "lg.jump");
  expr *j = expr_sub(c, e, minus_side(L, e, "lg.jump"));
  if (lua_gettop(L) == 2) {
    expr *n = check_expr(L, 2, "lg.jump");
    int rank = 0, len = expr_shape(n, &rank);
    if (rank != 1) return luaL_error(L, "lg.jump: argument #2 must be the normal (a vector, lg.normal()), got a %s", len ? "matrix" : "scalar");
    int er = 0;
    expr_shape(j, &er);
    j = er == 0 ? expr_mul(c, j, n) : expr_dot(c, j, n);
  }
  int deps[2] = {1, 2};
  push_expr(L, j, lua_gettop(L), deps, "lg.jump");
  return 1;
}

static int l_avg(lua_State *L) {
  one_expression(L, "lg.avg", 1);
  expr_ctx *c = get_env(L)->c;
  expr *e = check_expr(L, 1, "lg.avg");
  expr *a = expr_mul(c, expr_num(c, 0.5), expr_add(c, e, minus_side(L, e, "lg.avg")));
  int deps[1] = {1};
  push_expr(L, a, 1, deps, "lg.avg");
  return 1;
}

TENSOR1(transpose, expr_transpose)
TENSOR1(sym, expr_sym)
TENSOR1(skew, expr_skew)
TENSOR1(tr, expr_trace)
TENSOR1(det, expr_det)
TENSOR1(inv, expr_inv)
TENSOR1(dev, expr_dev)

static int l_outer(lua_State *L) { return arith(L, expr_outer, "lg.outer"); }
static int l_cross(lua_State *L) { return arith(L, expr_cross, "lg.cross"); }

static int l_identity(lua_State *L) {
  int n = lua_isnoneornil(L, 1) ? expr_dim(get_env(L)->c) : check_int_arg(L, 1, 1, 3, "lg.identity");
  push_expr(L, expr_identity(get_env(L)->c, n), 0, NULL, "lg.identity");
  return 1;
}

/* lg.derivative(F, u, v): the Gateaux derivative of F (an expression or a form) at u in the
 * direction v, d/dt F(u + t v) at t = 0; u an unknown or discrete function (scalar or
 * vector), v a function of the same shape (a test function for a residual) */
static int l_derivative(lua_State *L) {
  const char *fn = "lg.derivative";
  lg_env *env = get_env(L);
  int fu = -1, fv = -1;
  int ok;
  expr *ue = to_expr_opt(L, 2, &ok);
  if (ok && ue) fu = symbol_func(env, expr_canon(env->c, ue));
  if (fu < 0) return typeerror(L, fn, 2, "an unknown, test or discrete function (lg.unknown, lg.test, lg.function)");
  expr *ve = to_expr_opt(L, 3, &ok);
  if (ok && ve) fv = symbol_func(env, expr_canon(env->c, ve));
  if (fv < 0) return typeerror(L, fn, 3, "a function symbol of the same shape as argument 2 (lg.test, lg.unknown)");
  expr_func_info *iu = expr_func_get(env->c, fu), *iv = expr_func_get(env->c, fv);
  if ((iu->ncomp > 1 ? iu->ncomp : 1) != (iv->ncomp > 1 ? iv->ncomp : 1))
    return luaL_error(L, "%s: argument 3 has %d components, argument 2 %d", fn, iv->ncomp > 1 ? iv->ncomp : 1,
                      iu->ncomp > 1 ? iu->ncomp : 1);
  if (lua_gettop(L) > 3) return luaL_error(L, "%s: takes 3 arguments (F, u, v), got %d", fn, lua_gettop(L));
  ud_form *uf = luaL_testudata(L, 1, MT_FORM);
  if (uf) {
    form *r = form_variation(env->c, uf->f, 1, &fu, &fv);
    if (!r) return exprerror(L, fn);
    if (r->n == 0) { form_free(r); return luaL_error(L, "%s: the form does not depend on %s", fn, iu->name); }
    int deps[3] = {1, 2, 3};
    ud_form *out = new_ud(L, sizeof *out, MT_FORM, 3, deps);
    out->f = r;
    return 1;
  }
  expr *F = check_expr(L, 1, fn);
  int deps[3] = {1, 2, 3};
  push_expr(L, form_directional(env->c, F, fu, fv), 3, deps, fn);
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

static int quad_order(lua_State *L, int idx, const char *fn) {
  /* lg.integrate(mesh, problem:solve()): the solve's info table follows the solution */
  if (lua_isnoneornil(L, idx) || is_info_table(L, idx)) return -1;
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
  if (r->r.kind == REGION_POINTS && !strcmp(mt, MT_FORM))
    return luaL_error(L, "%s: argument 1 is a set of vertices (mesh:vertices), which has no measure: it is for "
                         "lg.essential_bc (pinning values); integrate over cells or boundary facets", fn);
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
  if (r && r->r.kind == REGION_CELLS)
    return luaL_error(L, "lg.essential_bc: argument 1 must be a boundary region (mesh:boundary(...)) or vertices "
                         "(mesh:vertices{near = ...}), got cells");
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
  gc_point(L, 0);
  const char *fn = "lg.integrate";
  region r;
  lg_mesh *lm = region_or_mesh(L, 1, fn, &r);
  if (r.kind == REGION_POINTS)
    return luaL_error(L, "%s: argument 1 is a set of vertices (mesh:vertices), which has no measure", fn);
  expr *e = check_expr(L, 2, fn);
  int order = quad_order(L, 3, fn);
  lg_env *env = get_env(L);
  double v;
  if (lg_integrate(env, lm, &r, e, order, &v)) return lgerror(L, fn, env);
  lua_pushnumber(L, v);
  return 1;
}

/* ---------------------------------------------------------------- registration */

const luaL_Reg lg_arith_mm[] = {{"__add", m_add}, {"__sub", m_sub}, {"__mul", m_mul}, {"__div", m_div},
                                {"__pow", m_pow}, {"__unm", m_unm}, {NULL, NULL}};

void lg_lua_expr_register(lua_State *L) {
  luaL_newmetatable(L, MT_EXPR);
  luaL_setfuncs(L, lg_arith_mm, 0);
  lua_pushcfunction(L, expr_tostring); lua_setfield(L, -2, "__tostring");
  lua_pushcfunction(L, expr_len); lua_setfield(L, -2, "__len");
  lua_pushcfunction(L, expr_index_mm); lua_setfield(L, -2, "__index");
  lua_pop(L, 1);
  static const luaL_Reg form_mm[] = {{"__add", m_add}, {"__sub", m_sub}, {"__mul", m_mul}, {"__unm", form_unm},
                                     {"__gc", form_gc}, {"__tostring", form_tostring}, {NULL, NULL}};
  new_mt(L, MT_FORM, form_mm, NULL);
  new_mt(L, MT_BC, form_mm, NULL);
  static const luaL_Reg basis_mm[] = {{"__tostring", basis_tostring}, {NULL, NULL}};
  new_mt(L, MT_BASIS, basis_mm, NULL);
}

const luaL_Reg lg_expr_lib[] = {
    {"lagrange", l_lagrange}, {"discontinuous", l_discontinuous}, {"vector", l_vector}, {"unknown", l_unknown}, {"test", l_test}, {"coord", l_coord},
    {"normal", l_normal}, {"parameter", l_parameter}, {"sin", l_sin}, {"cos", l_cos}, {"tan", l_tan},
    {"exp", l_exp}, {"log", l_log}, {"sqrt", l_sqrt}, {"abs", l_abs}, {"tanh", l_tanh}, {"sinh", l_sinh},
    {"cosh", l_cosh}, {"atan", l_atan}, {"asin", l_asin}, {"acos", l_acos}, {"sign", l_sign},
    {"pow", l_pow}, {"grad", l_grad}, {"div", l_div}, {"dot", l_dot}, {"inner", l_inner}, {"dx", l_dx},
    {"diff", l_diff}, {"list", l_list}, {"integral", l_integral}, {"essential_bc", l_essential_bc},
    {"integrate", l_integrate}, {"transpose", l_transpose}, {"sym", l_sym}, {"skew", l_skew}, {"tr", l_tr},
    {"det", l_det}, {"inv", l_inv}, {"dev", l_dev}, {"outer", l_outer}, {"cross", l_cross}, {"identity", l_identity},
    {"derivative", l_derivative}, {"jump", l_jump}, {"avg", l_avg}, {"minus", l_minus}, {"plus", l_plus}, {NULL, NULL}};
