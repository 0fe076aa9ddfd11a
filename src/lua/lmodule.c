/* lmodule.c — the `lugal` Lua module's entry point: the environment (one per Lua state,
 * finalized after every other lugal object) and the registration of the bindings of each
 * layer (lexpr.c, lmesh.c, lproblem.c, lopt.c; shared helpers in largs.c). The bindings are thin by
 * design (DESIGN.md): argument checking, conversion and error messages that name the
 * function, the argument and what was expected; no numerical logic lives here.
 *
 * Lifetimes: expressions are nodes of the environment's context; an expression, form or
 * problem userdata keeps the discrete functions and meshes it refers to alive through a
 * dependency table in its user value. */
#include "lmodule.h"

#include "../config.h"
#include "largs.h"

#include <petscsys.h>
#include <string.h>

static int env_gc(lua_State *L) {
  ud_env *u = luaL_checkudata(L, 1, MT_ENV);
  lg_env_free(u->env);
  u->env = NULL;
  /* the module loaded into a plain Lua interpreter started PETSc; the environment is
   * finalized after every other lugal object, so PETSc can stop now */
  if (u->owns_petsc) {
    lg_petsc_report_unused_options();
    lg_petsc_finalize();
  }
  u->owns_petsc = 0;
  return 0;
}

int luaopen_lugal(lua_State *L) {
  /* the environment: created once per Lua state, finalized last */
  if (lua_getfield(L, LUA_REGISTRYINDEX, "lugal.env") == LUA_TNIL) {
    lua_pop(L, 1);
    ud_env *ue = lua_newuserdatauv(L, sizeof *ue, 0);
    ue->owns_petsc = 0;
    ue->env = NULL;
    if (luaL_newmetatable(L, MT_ENV)) { lua_pushcfunction(L, env_gc); lua_setfield(L, -2, "__gc"); }
    lua_setmetatable(L, -2);
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
    /* several ranks: collections only at the points every rank passes alike (gc_point) */
    if (lg_mpi_size() > 1) lua_gc(L, LUA_GCSTOP);
    lua_setfield(L, LUA_REGISTRYINDEX, "lugal.env");
    PetscBool set = PETSC_FALSE;
    char backend[16] = "";
    PetscOptionsGetString(NULL, NULL, "-lugal_jit", backend, sizeof backend, &set);
    if (set && !strcmp(backend, "cc")) jit_set_backend(ue->env->jit, JIT_CC);
    else if (set && !strcmp(backend, "tcc")) jit_set_backend(ue->env->jit, JIT_TCC);
    else if (set && strcmp(backend, "auto"))
      return luaL_error(L, "lugal: -lugal_jit must be tcc, cc or auto, got %s", backend);
    PetscReal tier_ms = JIT_TIER_MS;
    PetscBool tset = PETSC_FALSE;
    PetscOptionsGetReal(NULL, NULL, "-lugal_jit_tier_ms", &tier_ms, &tset);
    if (tset && !(tier_ms >= 0)) return luaL_error(L, "lugal: -lugal_jit_tier_ms must be >= 0");
    jit_set_tier_ms(ue->env->jit, tier_ms);
    PetscInt nice = JIT_NICE;
    PetscOptionsGetInt(NULL, NULL, "-lugal_jit_nice", &nice, NULL);
    if (nice < 0 || nice > 19) return luaL_error(L, "lugal: -lugal_jit_nice must be 0 .. 19, got %d", (int)nice);
    jit_set_nice(ue->env->jit, (int)nice);
    PetscBool verbose = PETSC_FALSE;
    PetscOptionsHasName(NULL, NULL, "-lugal_verbose", &verbose);
    ue->env->verbose = verbose;
    jit_set_verbose(ue->env->jit, verbose);
    PetscBool pcache = PETSC_TRUE;
    PetscOptionsGetBool(NULL, NULL, "-lugal_point_cache", &pcache, NULL);
    ue->env->no_point_cache = !pcache;
    PetscBool vmath = PETSC_TRUE;
    PetscOptionsGetBool(NULL, NULL, "-lugal_vector_math", &vmath, NULL);
    ue->env->no_vector_math = !vmath;
    PetscInt wait_s = 10;
    PetscOptionsGetInt(NULL, NULL, "-lugal_collective_wait", &wait_s, NULL);
    if (wait_s < 1) return luaL_error(L, "lugal: -lugal_collective_wait must be >= 1 (seconds), got %d", (int)wait_s);
    ue->env->collective_wait_s = (int)wait_s;
    PetscBool keep = PETSC_TRUE;
    PetscOptionsGetBool(NULL, NULL, "-lugal_keep_factor", &keep, NULL);
    ue->env->no_keep_factor = !keep;
    /* -lugal_distribute and -lugal_ghost_layers, read again when a mesh is made: a script
     * that makes none is not told they went unused */
    (void)lg_distribute_wanted();
  } else lua_pop(L, 1);

  lg_lua_expr_register(L);
  lg_lua_mesh_register(L);
  lg_lua_problem_register(L);
  lg_lua_opt_register(L);
  lg_lua_time_register(L);
  lg_lua_operator_register(L);
  lua_newtable(L);
  set_funcs_checked(L, lg_expr_lib, "lg");
  set_funcs_checked(L, lg_problem_lib, "lg");
  set_funcs_checked(L, lg_output_lib, "lg");
  set_funcs_checked(L, lg_opt_lib, "lg");
  set_funcs_checked(L, lg_time_lib, "lg");
  set_funcs_checked(L, lg_operator_lib, "lg");
  set_funcs_checked(L, lg_parallel_lib, "lg");
  lg_lua_parallel_register(L);
  lua_newtable(L);
  set_funcs_checked(L, lg_mesh_lib, "lg.mesh");
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
