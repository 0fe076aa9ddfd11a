/* lparallel.c — the bindings of the process layout (src/assemble/process/process.c): lg.rank(),
 * lg.size(), lg.allreduce(x, op), under mpiexec a `print` that prints on rank 0 only
 * (every rank runs the same script; the original is kept as lg.print_all), and the check of
 * collective calls: each one is numbered, and the ranks compare number and name before it
 * runs, so that a collective call made on one rank only ends the run with a message naming
 * what each rank called, instead of a hang. */
#include "largs.h"

#include <petscsys.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>
#include <time.h>

/* The collective calls of the module. ALWAYS: collective in every parallel run (they
 * communicate, or are points where the Lua collector may run, whose finalizers destroy
 * PETSc objects collectively: gc_point); DIST: only on distributed meshes (-lugal_distribute,
 * the default under mpiexec), where they reduce or gather over the ranks; with
 * -lugal_distribute 0 they are local. Calls that are collective only with some arguments
 * (mesh:quality with a reference, mesh:cells with names, mesh:vertices{near =}) are not
 * listed: a rank that waits in them is told so after -lugal_collective_wait seconds by the
 * other ranks' next listed call. docs/lua-api.md, "Parallel runs", lists these. */
enum { ALWAYS = 1, DIST = 2 };
typedef struct {
  const char *table, *name, *shown;
  int when;
} collective;
static const collective collectives[] = {
    {"lg.mesh", "read", "lg.mesh.read", ALWAYS},
    {"lg.mesh", "interval", "lg.mesh.interval", ALWAYS},
    {"lg.mesh", "rectangle", "lg.mesh.rectangle", ALWAYS},
    {"lg.mesh", "box", "lg.mesh.box", ALWAYS},
    {"lg.mesh", "new", "lg.mesh.new", ALWAYS},
    {MT_MESH, "copy", "mesh:copy", ALWAYS},
    {MT_MESH, "refine", "mesh:refine", ALWAYS},
    {"lg", "interpolate", "lg.interpolate", ALWAYS},
    {"lg", "zero_function", "lg.zero_function", ALWAYS},
    {"lg", "function", "lg.function", ALWAYS},
    {"lg", "linear_problem", "lg.linear_problem", ALWAYS},
    {"lg", "nonlinear_problem", "lg.nonlinear_problem", ALWAYS},
    {"lg", "kkt_problem", "lg.kkt_problem", ALWAYS},
    {"lg", "reduced_functional", "lg.reduced_functional", ALWAYS},
    {"lg", "integrate", "lg.integrate", ALWAYS},
    {"lg", "allreduce", "lg.allreduce", ALWAYS},
    {"lg", "minimize", "lg.minimize", ALWAYS},
    {"lg", "taylor_test", "lg.taylor_test", ALWAYS},
    {"lg", "assemble", "lg.assemble", ALWAYS},
    {MT_PROB, "solve", "problem:solve", ALWAYS},
    {MT_PROB, "matrix", "problem:matrix", ALWAYS},
    {MT_PROB, "assemble", "problem:assemble", ALWAYS},
    {MT_PROB, "sensitivity", "problem:sensitivity", ALWAYS},
    {MT_REDUCED, "value", "rf:value", ALWAYS},
    {MT_REDUCED, "derivative", "rf:derivative", ALWAYS},
    {MT_REDUCED, "gradient", "rf:gradient", ALWAYS},
    {MT_REDUCED, "hessian", "rf:hessian", ALWAYS},
    {MT_REDUCED, "state", "rf:state", ALWAYS},
    {"lg", "time_problem", "lg.time_problem", ALWAYS},
    {MT_TIME, "solve", "step:solve", ALWAYS},
    {MT_SERIES, "write", "series:write", ALWAYS},
    {MT_MESH, "write", "mesh:write", DIST},
    {MT_MESH, "hmax", "mesh:hmax", DIST},
    {MT_MESH, "check", "mesh:check", DIST},
    {MT_MESH, "info", "mesh:info", DIST},
    {MT_MESH, "boundary", "mesh:boundary", DIST},
    {MT_MESH, "quality_report", "mesh:quality_report", DIST},
    {MT_MESH, "untangle", "mesh:untangle", DIST},
    {MT_MESH, "smooth", "mesh:smooth", DIST},
    {MT_MESH, "move", "mesh:move", DIST},
    {MT_MESH, "displace", "mesh:displace", DIST},
    {MT_QARRAY, "min", "q:min", DIST},
    {MT_QARRAY, "max", "q:max", DIST},
    {MT_QARRAY, "mean", "q:mean", DIST},
    {MT_QARRAY, "histogram", "q:histogram", DIST},
    {MT_QARRAY, "worst", "q:worst", DIST},
    {MT_QARRAY, "totable", "q:totable", DIST},
    {MT_FUNC, "values", "f:values", DIST},
    {MT_FUNC, "dof_coordinates", "f:dof_coordinates", DIST},
    {MT_FUNC, "eval", "f:eval", DIST},
    {MT_FUNC, "assign", "f:assign", DIST},
    {"lugal.Vector", "values", "b:values", DIST},
    {"lugal.Vector", "norm", "b:norm", DIST},
    {"lugal.Vector", "dot", "b:dot", DIST},
    {"lugal.Vector", "size", "b:size", DIST},
    {"lugal.Matrix", "norm", "A:norm", DIST},
    {"lugal.Matrix", "mult", "A:mult", DIST},
    {"lugal.Matrix", "dot", "A:dot", DIST},
    {"lugal.Matrix", "size", "A:size", DIST},
    {NULL, NULL, NULL, 0}};

#define WHERE_LEN 96
#define NAME_LEN 40
typedef struct {
  long long seq;
  char name[NAME_LEN], where[WHERE_LEN];
} call_record;

/* the ranks' calls differ: every rank gathers what each called, and raises the same error */
static int out_of_step(lua_State *L, const call_record *mine, MPI_Comm comm) {
  int size = lg_mpi_size();
  call_record *all = lua_newuserdatauv(L, sizeof *all * (size_t)size, 0);
  if (MPI_Allgather(mine, (int)sizeof *mine, MPI_BYTE, all, (int)sizeof *mine, MPI_BYTE, comm) != MPI_SUCCESS)
    return luaL_error(L, "lugal: the ranks' collective calls are out of step (and gathering what each called failed)");
  luaL_Buffer b;
  luaL_buffinit(L, &b);
  luaL_addstring(&b, "collective calls out of step: ");
  for (int r = 0, shown = 0; r < size && shown < 8; r++) {
    int first = 1; /* ranks at the same call are named once, the first of them */
    for (int q = 0; q < r && first; q++) first = all[q].seq != all[r].seq || strcmp(all[q].name, all[r].name);
    if (!first) continue;
    char line[256];
    snprintf(line, sizeof line, "%srank %d is at %s (collective call #%lld%s%s)", shown ? ", " : "", r, all[r].name,
             all[r].seq, all[r].where[0] ? ", " : "", all[r].where);
    luaL_addstring(&b, line);
    shown++;
  }
  luaL_addstring(&b, ": every rank must make the same collective calls in the same order (a collective call under "
                     "`if lg.rank() == 0`? docs/lua-api.md, \"Parallel runs\", lists them)");
  luaL_pushresult(&b);
  return lua_error(L);
}

/* the communicator of the checks: a duplicate of the world's, so that a check never matches
 * a collective operation of a call another rank is making (made when the module is loaded) */
#define CHECK_COMM "lugal.check_comm"
static int check_comm_gc(lua_State *L) {
  MPI_Comm *c = lua_touserdata(L, 1);
  if (*c != MPI_COMM_NULL) MPI_Comm_free(c);
  return 0;
}
static MPI_Comm check_comm(lua_State *L) {
  lua_getfield(L, LUA_REGISTRYINDEX, CHECK_COMM);
  MPI_Comm *c = lua_touserdata(L, -1);
  lua_pop(L, 1);
  if (!c || *c == MPI_COMM_NULL) luaL_error(L, "lugal: the communicator of the collective checks is missing");
  return *c;
}

/* before a collective call (name, at the script's line where): the ranks agree on its number
 * and name. A rank that waits here long is told so once (another rank may be elsewhere, in a
 * call this does not see) */
static void collective_check(lua_State *L, const char *name, const char *where) {
  lg_env *env = get_env(L);
  MPI_Comm comm = check_comm(L);
  long long seq = (long long)++env->collective_seq;
  uint32_t h = 2166136261u;
  for (const char *c = name; *c; c++) h = (h ^ (unsigned char)*c) * 16777619u;
  long long v[4] = {seq, -seq, (long long)(h >> 1), -(long long)(h >> 1)}, r[4];
  MPI_Request rq;
  if (MPI_Iallreduce(v, r, 4, MPI_LONG_LONG, MPI_MAX, comm, &rq) != MPI_SUCCESS)
    luaL_error(L, "%s: the check of the collective calls failed", name);
  int done = 0, told = 0;
  struct timespec t0, t1, nap = {0, 0};
  clock_gettime(CLOCK_MONOTONIC, &t0);
  for (long spins = 0; !done; spins++) {
    if (MPI_Test(&rq, &done, MPI_STATUS_IGNORE) != MPI_SUCCESS) luaL_error(L, "%s: the check of the collective calls failed", name);
    if (done) break;
    if (spins < 1000) continue;
    nap.tv_nsec = nap.tv_nsec < 1000000 ? nap.tv_nsec + 10000 : 1000000; /* up to 1 ms between looks */
    nanosleep(&nap, NULL);
    clock_gettime(CLOCK_MONOTONIC, &t1);
    if (!told && t1.tv_sec - t0.tv_sec >= env->collective_wait_s) {
      fprintf(stderr, "lugal: rank %d has waited %d s at %s (collective call #%lld%s%s) for the other ranks: if the run goes "
                      "no further, a rank is not making this call (a collective call under `if lg.rank() == 0`?)\n",
              lg_mpi_rank(), env->collective_wait_s, name, seq, where[0] ? ", " : "", where);
      told = 1;
    }
  }
  if (r[0] != -r[1] || r[2] != -r[3]) {
    call_record mine;
    memset(&mine, 0, sizeof mine);
    mine.seq = seq;
    snprintf(mine.name, sizeof mine.name, "%s", name);
    snprintf(mine.where, sizeof mine.where, "%s", where);
    out_of_step(L, &mine, comm);
  }
}

/* the script's file:line that made the call (luaL_where's text without its ": ") */
static void caller_where(lua_State *L, char *where) {
  luaL_where(L, 1);
  snprintf(where, WHERE_LEN, "%s", lua_tostring(L, -1));
  lua_pop(L, 1);
  size_t n = strlen(where);
  while (n && (where[n - 1] == ' ' || where[n - 1] == ':')) where[--n] = 0;
}

static int collective_call(lua_State *L) {
  int when = (int)lua_tointeger(L, lua_upvalueindex(3));
  if (lg_mpi_size() > 1 && (when == ALWAYS || lg_distribute_wanted())) {
    char where[WHERE_LEN];
    caller_where(L, where);
    collective_check(L, lua_tostring(L, lua_upvalueindex(2)), where);
  }
  lua_pushvalue(L, lua_upvalueindex(1));
  lua_insert(L, 1);
  lua_call(L, lua_gettop(L) - 1, LUA_MULTRET);
  return lua_gettop(L);
}

void lg_lua_collective_wrap(lua_State *L, const char *table, const char *name) {
  for (const collective *c = collectives; c->table; c++)
    if (!strcmp(c->table, table) && !strcmp(c->name, name)) {
      lua_pushstring(L, c->shown);
      lua_pushinteger(L, c->when);
      lua_pushcclosure(L, collective_call, 3);
      return;
    }
}

int lg_lua_end_check(lua_State *L) {
  lua_getfield(L, LUA_REGISTRYINDEX, "lugal.env");
  int loaded = lua_touserdata(L, -1) != NULL;
  lua_pop(L, 1);
  if (loaded && lg_mpi_size() > 1) collective_check(L, "the end of the script", "");
  return 0;
}

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
  if (cnt[0] != -cnt[1])
    return luaL_error(L, "%s: the ranks passed arrays of different lengths (%I to %I)", fn, (lua_Integer)-cnt[1], (lua_Integer)cnt[0]);
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
  MPI_Comm *c = lua_newuserdatauv(L, sizeof *c, 0);
  *c = MPI_COMM_NULL;
  lua_createtable(L, 0, 1);
  lua_pushcfunction(L, check_comm_gc);
  lua_setfield(L, -2, "__gc");
  lua_setmetatable(L, -2);
  if (MPI_Comm_dup(PETSC_COMM_WORLD, c) != MPI_SUCCESS) *c = MPI_COMM_NULL;
  lua_setfield(L, LUA_REGISTRYINDEX, CHECK_COMM);
  lua_pop(L, 1);
  lua_pushcclosure(L, print_root, 1);
  lua_setglobal(L, "print");
  lua_pushboolean(L, 1);
  lua_setfield(L, LUA_REGISTRYINDEX, "lugal.print_root");
}
