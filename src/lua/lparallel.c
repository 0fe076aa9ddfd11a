/* lparallel.c — the bindings of the process layout (src/assemble/parallel.c): lg.rank(),
 * lg.size(), lg.allreduce(x, op), and under mpiexec a `print` that prints on rank 0 only
 * (every rank runs the same script; the original is kept as lg.print_all). */
#include "largs.h"

#include <string.h>

static int l_rank(lua_State *L) {
  lua_pushinteger(L, lg_mpi_rank());
  return 1;
}

static int l_size(lua_State *L) {
  lua_pushinteger(L, lg_mpi_size());
  return 1;
}

/* lg.allreduce(x [, "sum" | "max" | "min"]): x a number or an array of numbers; the result
 * (the same type) on every rank */
static int l_allreduce(lua_State *L) {
  const char *fn = "lg.allreduce";
  static const char *const ops[] = {"sum", "max", "min", NULL};
  static const lg_reduce_op opv[] = {LG_SUM, LG_MAX, LG_MIN};
  int op = 0;
  if (!lua_isnoneornil(L, 2)) {
    if (lua_type(L, 2) != LUA_TSTRING) return typeerror(L, fn, 2, "\"sum\", \"max\" or \"min\"");
    const char *s = check_cstring(L, 2, fn, "argument 2");
    for (op = 0; ops[op] && strcmp(ops[op], s); op++) {}
    if (!ops[op]) return luaL_error(L, "%s: argument 2 must be \"sum\", \"max\" or \"min\", got \"%s\"", fn, s);
  }
  if (lua_type(L, 1) == LUA_TNUMBER) {
    double x = lua_tonumber(L, 1);
    if (lg_allreduce(&x, 1, opv[op])) return luaL_error(L, "%s: the reduction failed", fn);
    if (lua_isinteger(L, 1) && x == (double)(lua_Integer)x) lua_pushinteger(L, (lua_Integer)x);
    else lua_pushnumber(L, x);
    return 1;
  }
  if (!lua_istable(L, 1)) return typeerror(L, fn, 1, "a number or an array of numbers");
  lua_Integer n = luaL_len(L, 1);
  if (n > 100000000) return luaL_error(L, "%s: argument 1 has too many entries (%I)", fn, n);
  double *v = lua_newuserdatauv(L, sizeof(double) * (size_t)(n + 1), 0);
  char *isint = lua_newuserdatauv(L, (size_t)n + 1, 0);
  for (lua_Integer i = 0; i < n; i++) {
    lua_geti(L, 1, i + 1);
    int isnum;
    isint[i] = (char)lua_isinteger(L, -1);
    v[i] = lua_tonumberx(L, -1, &isnum);
    if (!isnum) return luaL_error(L, "%s: argument 1 entry %I must be a number, got %s", fn, i + 1, luaL_typename(L, -1));
    lua_pop(L, 1);
  }
  /* every rank must pass as many: the count first */
  double cnt[2] = {(double)n, -(double)n};
  if (lg_allreduce(cnt, 2, LG_MAX)) return luaL_error(L, "%s: the reduction failed", fn);
  if (cnt[0] != -cnt[1]) return luaL_error(L, "%s: the ranks passed arrays of different lengths (%.0f to %.0f)", fn, -cnt[1], cnt[0]);
  if (lg_allreduce(v, (int)n, opv[op])) return luaL_error(L, "%s: the reduction failed", fn);
  lua_createtable(L, (int)n, 0);
  for (lua_Integer i = 0; i < n; i++) {
    /* integers stay integers where the sum is one (counts) */
    if (isint[i] && v[i] == (double)(lua_Integer)v[i]) lua_pushinteger(L, (lua_Integer)v[i]);
    else lua_pushnumber(L, v[i]);
    lua_rawseti(L, -2, i + 1);
  }
  return 1;
}

static int print_root(lua_State *L) {
  if (lg_mpi_rank() != 0) return 0;
  lua_pushvalue(L, lua_upvalueindex(1));
  lua_insert(L, 1);
  lua_call(L, lua_gettop(L) - 1, 0);
  return 0;
}

const luaL_Reg lg_parallel_lib[] = {{"rank", l_rank}, {"size", l_size}, {"allreduce", l_allreduce}, {NULL, NULL}};

/* under mpiexec: print on rank 0 (once per Lua state); lg.print_all is the original. The
 * lg table is on the top of the stack */
void lg_lua_parallel_register(lua_State *L) {
  lua_getglobal(L, "print");
  lua_pushvalue(L, -1);
  lua_setfield(L, -3, "print_all");
  if (lg_mpi_size() == 1) { lua_pop(L, 1); return; }
  if (lua_getfield(L, LUA_REGISTRYINDEX, "lugal.print_root") != LUA_TNIL) { lua_pop(L, 2); return; }
  lua_pop(L, 1);
  lua_pushcclosure(L, print_root, 1);
  lua_setglobal(L, "print");
  lua_pushboolean(L, 1);
  lua_setfield(L, LUA_REGISTRYINDEX, "lugal.print_root");
}
