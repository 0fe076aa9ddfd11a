/* main.c — the runner (lugal-core, started by the `lugal` command of launch.c): initializes PETSc (with fast single-process MPI defaults),
 * exposes script arguments as `arg`, makes `require "lugal"` available, runs the script,
 * and reports a Lua error as "script.lua:LINE: message" with exit status 1. */
#include "../assemble/assemble.h"
#include "../config.h"
#include "lmodule.h"

#include <lauxlib.h>
#include <lua.h>
#include <lualib.h>
#include <petscsys.h>
#include <stdio.h>
#include <string.h>

static void usage(FILE *f) {
  fprintf(f,
          "usage: lugal SCRIPT.lua [ARGS] [PETSc options]\n"
          "       lugal --version | --help\n\n"
          "Runs a Lua script with the lugal module (require \"lugal\"). Arguments after the\n"
          "script are visible to it as arg[1], arg[2], ... and are also read by PETSc, so\n"
          "options such as -ksp_type cg -pc_type gamg -snes_monitor apply to its solvers.\n\n"
          "lugal options:\n"
          "  -lugal_jit auto|tcc|cc  kernel compiler: libtcc in memory, then the system C\n"
          "                        compiler in the background for kernels that took 20 ms\n"
          "                        (auto, the default); libtcc only; the system compiler\n"
          "                        at -O3 into a cached shared object from the start\n"
          "  -lugal_jit_tier_ms T  the assembly time after which auto moves a kernel\n"
          "  -lugal_jit_nice N     the nice level of those background builds (default 10,\n"
          "                        0..19): they take a core the run's threads leave idle\n"
          "  -lugal_verbose        timings and kernel statistics on stderr\n"
          "  -lugal_point_cache 0  recompute coordinate-only transcendental terms (a target\n"
          "                        sin(pi x)) at every assembly instead of keeping them\n"
          "  -lugal_vector_math 0  transcendental functions of the coordinates per point\n"
          "                        through libm instead of libmvec's AVX2 routines\n"
          "  -lugal_iterative 0    keep the direct solver for large problems (by default\n"
          "                        CG or GMRES with GAMG from 2e4 unknowns in 3D, 2e5 in\n"
          "                        2D, where the diagonal is positive; Newton's steps too)\n"
          "  -lugal_iterative_min N  the size from which that default applies\n"
          "  -lugal_keep_factor 0  refactor a linear problem's matrix whenever it changes\n"
          "                        (by default it is solved by CG or GMRES with its\n"
          "                        last factorization while that costs less)\n"
          "  -lugal_keep_ksp_monitor  the iterations of those kept-factor solves\n"
          "  -lugal_traceback      print a Lua traceback with errors\n"
          "\nunder mpiexec:\n"
          "  -lugal_distribute 0   every rank holds the whole mesh (by default each holds\n"
          "                        its part and a layer of ghost cells)\n"
          "  -lugal_ghost_layers N ghost cell layers of a distributed mesh, 1..8 (default 1;\n"
          "                        2 for interior-facet terms of continuous fields)\n"
          "  -lugal_partitioner P  how cells are split over the ranks: auto (default: the\n"
          "                        numbering's runs where they cut little, else ptscotch),\n"
          "                        natural, or a PETSc MatPartitioningType\n"
          "  -lugal_read_parts 0   a Gmsh file read whole by rank 0 (by default each rank\n"
          "                        parses its run of the file)\n"
          "  -lugal_read_parts_min N  files with fewer than N cells a rank (default 8) are\n"
          "                        read whole by rank 0\n"
          "  -lugal_collective_wait S  a rank that waits S seconds (default 10) at a\n"
          "                        collective call for the others says so\n\n"
          "  -lugal_hugepages 1    let glibc's malloc and the mesh's arrays use transparent\n"
          "                        huge pages (off by default: slower on virtual machines\n"
          "                        that hand free memory back to their host)\n");
}

static int traceback(lua_State *L) {
  const char *msg = lua_tostring(L, 1);
  if (!msg) msg = luaL_tolstring(L, 1, NULL);
  luaL_traceback(L, L, msg, 1);
  return 1;
}

int main(int argc, char **argv) {
  if (argc < 2) { usage(stderr); return 2; }
  if (!strcmp(argv[1], "--version") || !strcmp(argv[1], "-v")) {
    printf("lugal %s\n", LUGAL_VERSION);
    return 0;
  }
  if (!strcmp(argv[1], "--help") || !strcmp(argv[1], "-h")) { usage(stdout); return 0; }
  const char *script = argv[1];
  if (script[0] == '-') { fprintf(stderr, "lugal: the first argument must be a script, got %s\n", script); usage(stderr); return 2; }
  int pargc = argc;
  char **pargv = argv;
  if (lg_petsc_init(&pargc, &pargv)) { fprintf(stderr, "lugal: PETSc failed to initialize\n"); return 1; }
  /* a run ended by a signal removes its temporary files; a write past ulimit -f is an error */
  outfile_on_signals();
  PetscBool want_tb = PETSC_FALSE;
  PetscOptionsHasName(NULL, NULL, "-lugal_traceback", &want_tb);
  PetscBool seen; /* read by the launcher (launch.c): used, not a misspelling */
  PetscOptionsHasName(NULL, NULL, "-lugal_hugepages", &seen);
  lua_State *L = luaL_newstate();
  if (!L) { fprintf(stderr, "lugal: cannot create a Lua state\n"); lg_petsc_finalize(); return 1; }
  luaL_openlibs(L);
  lua_getglobal(L, "package");
  lua_getfield(L, -1, "preload");
  lua_pushcfunction(L, luaopen_lugal);
  lua_setfield(L, -2, "lugal");
  lua_pop(L, 2);
  lua_createtable(L, argc, 1);
  lua_pushstring(L, argv[0]);
  lua_rawseti(L, -2, -1);
  for (int i = 1; i < argc; i++) {
    lua_pushstring(L, argv[i]);
    lua_rawseti(L, -2, i - 1);
  }
  lua_setglobal(L, "arg");
  int status = 0;
  lua_pushcfunction(L, traceback);
  int msgh = lua_gettop(L);
  if (luaL_loadfile(L, script) != LUA_OK) {
    char msg[1024];
    snprintf(msg, sizeof msg, "lugal: %s", lua_tostring(L, -1));
    lg_abort_run(msg);
    status = 1;
  } else if (!lua_checkstack(L, argc)) { /* the script's arguments are pushed as its "...": room for them */
    lg_abort_run("lugal: too many arguments for the script's Lua stack");
    status = 1;
  } else {
    /* (without the room, more than about 40 arguments wrote past the Lua stack, and the run
     * ended in a crash in MPI_Finalize) */
    for (int i = 2; i < argc; i++) lua_pushstring(L, argv[i]);
    int rc = lua_pcall(L, argc - 2, 0, want_tb ? msgh : 0);
    if (rc == LUA_OK) { /* every rank at the end: none still waits in a collective call */
      lua_pushcfunction(L, lg_lua_end_check);
      rc = lua_pcall(L, 0, 0, 0);
    }
    if (rc != LUA_OK) {
      const char *msg = lua_tostring(L, -1);
      /* under mpiexec the other ranks may be waiting for this one: end them all */
      lg_abort_run(msg ? msg : "(error object is not a string)");
      status = 1;
    }
  }
  lua_close(L);
  lg_petsc_report_unused_options();
  lg_petsc_finalize();
  return status;
}
