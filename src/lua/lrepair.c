/* lrepair.c — Lua bindings of the mesh repairs: mesh:untangle, mesh:smooth, mesh:move and
 * mesh:displace (src/mesh/untangle.c and smooth.c), on a whole mesh or, for a distributed
 * one, on rank 0's gathered copy with the new coordinates sent back. */
#include "largs.h"

#include "../mesh/untangle/untangle.h"

#include <lauxlib.h>
#include <math.h>
#include <petscsys.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int opt_boundary(lua_State *L, int t, const char *fn) {
  const char *b = t ? opt_str(L, t, "boundary", "slide", fn) : "slide";
  if (!strcmp(b, "slide")) return 1;
  if (!strcmp(b, "fixed")) return 0;
  return luaL_error(L, "%s: option 'boundary' must be \"slide\" or \"fixed\", got \"%s\"", fn, b);
}

/* the option 'reference' of table t: the same mesh as lm's in another configuration, or
 * NULL. A distributed mesh's reference is distributed too: their cells are compared where
 * they are used (rank 0's gathered meshes for a repair, each rank's parts for quality) */
lg_mesh *opt_reference(lua_State *L, int t, const lg_mesh *lm, const char *fn) {
  lg_mesh *ref = NULL;
  const mesh *m = lm->m;
  if (t && lua_getfield(L, t, "reference") != LUA_TNIL) {
    ud_mesh *ur = luaL_testudata(L, -1, MT_MESH);
    if (!ur) luaL_error(L, "%s: option 'reference' must be a mesh (the same mesh in another configuration)", fn);
    ref = ur->lm;
    const mesh *r = ref->m;
    if (lm->dist || ref->dist) {
      if (!lm->dist || !ref->dist || r->type != m->type || ref->dist->nvert_global != lm->dist->nvert_global ||
          ref->dist->ncell_global != lm->dist->ncell_global)
        luaL_error(L, "%s: the reference must be the same mesh (same cells) in another configuration", fn);
    } else if (r->type != m->type || r->nvert != m->nvert || r->ncell != m->ncell ||
               memcmp(r->cells, m->cells, sizeof(int) * (size_t)m->ncell * (size_t)m->nvc))
      luaL_error(L, "%s: the reference must be the same mesh (same cells) in another configuration", fn);
  }
  if (t) lua_pop(L, 1);
  return ref;
}

/* a repair of a distributed mesh: rank 0 gathers the whole mesh and runs it, its outcome
 * and report (rlen bytes at r) reach every rank, and the new coordinates each rank's
 * vertices. The serial run's result, at the price of one rank's work and memory (issue 14
 * asks at least this much) */
typedef int (*repair_fn)(mesh *m, const void *opts, void *report, char *err);

static int repair_untangle(mesh *m, const void *o, void *r, char *err) { return mesh_untangle(m, o, r, err); }
static int repair_smooth(mesh *m, const void *o, void *r, char *err) { return mesh_smooth(m, o, r, err); }

static int dist_repair(lua_State *L, ud_mesh *u, lg_mesh *ref, const double **xref, repair_fn op, const void *o, void *r,
                       size_t rlen, char *err) {
  lg_env *env = get_env(L);
  mesh *W = NULL, *R = NULL;
  int rc = lg_dist_gather_mesh(env, u->lm->dist, &W);
  if (!rc && ref) rc = lg_dist_gather_mesh(env, ref->dist, &R);
  if (rc) snprintf(err, MESH_ERRLEN, "%.*s", MESH_ERRLEN - 1, env->err);
  else if (lg_mpi_rank() == 0) {
    if (R && (R->nvert != W->nvert || R->ncell != W->ncell ||
              memcmp(R->cells, W->cells, sizeof(int) * (size_t)W->ncell * (size_t)W->nvc))) {
      snprintf(err, MESH_ERRLEN, "the reference must be the same mesh (same cells) in another configuration");
      rc = 1;
    } else {
      if (R) *xref = R->x;
      rc = op(W, o, r, err);
    }
  }
  rc = lg_root_result(rc, err, MESH_ERRLEN);
  if (!rc && MPI_Bcast(r, (int)rlen, MPI_BYTE, 0, PETSC_COMM_WORLD) != MPI_SUCCESS) {
    snprintf(err, MESH_ERRLEN, "sending the report to every rank failed");
    rc = 1;
  }
  if (!rc && lg_dist_scatter_coords(env, u->lm->dist, W)) {
    snprintf(err, MESH_ERRLEN, "%.*s", MESH_ERRLEN - 1, env->err);
    rc = 1;
  }
  if (xref) *xref = NULL; /* R is freed here */
  mesh_free(R);
  mesh_free(W);
  return rc;
}

/* progress = seconds between the progress lines of a long run (default 2; 0 or false: none) */
static double opt_progress(lua_State *L, int t, const char *fn) {
  if (!t) return 2;
  int ty = lua_getfield(L, t, "progress");
  double v = ty == LUA_TBOOLEAN ? (lua_toboolean(L, -1) ? 2 : 0) : ty == LUA_TNIL ? 2 : -1;
  if (ty == LUA_TNUMBER) v = lua_tonumber(L, -1);
  lua_pop(L, 1);
  if (!(v >= 0) || !isfinite(v))
    luaL_error(L, "%s: option 'progress' must be the seconds between progress lines (a number >= 0) or a boolean", fn);
  return v;
}

int lmesh_untangle(lua_State *L) {
  const char *fn = "mesh:untangle";
  ud_mesh *u = check_mesh(L, 1, fn);
  int t = 0;
  if (!lua_isnoneornil(L, 2)) {
    if (!lua_istable(L, 2))
      return typeerror(L, fn, 2, "an options table {beta=, max_iterations=, boundary=, placement=, reference=, motion_weight=, global=, quiet=}");
    static const char *const keys[] = {"beta", "max_iterations", "boundary", "placement", "quiet", "progress", "reference",
                                       "motion_weight", "global", NULL};
    check_keys(L, 2, fn, keys);
    t = 2;
  }
  untangle_opts o;
  untangle_defaults(&o);
  int quiet = 0;
  if (t) {
    o.beta = opt_num(L, t, "beta", -1, fn);
    if (lua_getfield(L, t, "beta") != LUA_TNIL && !(o.beta >= 0))
      return luaL_error(L, "%s: option 'beta' must be >= 0 (a minimum corner Jacobian), got %f", fn, o.beta);
    lua_pop(L, 1);
    o.max_iterations = opt_int(L, t, "max_iterations", 100, fn);
    if (o.max_iterations < 1) return luaL_error(L, "%s: option 'max_iterations' must be >= 1", fn);
    const char *pl = opt_str(L, t, "placement", "chebyshev", fn);
    if (!strcmp(pl, "chebyshev")) o.placement = 0;
    else if (!strcmp(pl, "corners")) o.placement = 1;
    else return luaL_error(L, "%s: option 'placement' must be \"chebyshev\" or \"corners\", got \"%s\"", fn, pl);
    lua_getfield(L, t, "quiet");
    quiet = lua_toboolean(L, -1);
    lua_pop(L, 1);
    o.motion_weight = opt_num(L, t, "motion_weight", 0, fn);
    if (!(o.motion_weight >= 0) || !isfinite(o.motion_weight))
      return luaL_error(L, "%s: option 'motion_weight' must be a finite number >= 0 (the weight of the distance to the input), got %f",
                        fn, o.motion_weight);
    int gt = lua_getfield(L, t, "global");
    if (gt != LUA_TNIL && gt != LUA_TBOOLEAN)
      return luaL_error(L, "%s: option 'global' must be a boolean (false: no global stage), got %s", fn, luaL_typename(L, -1));
    o.no_global = gt == LUA_TBOOLEAN && !lua_toboolean(L, -1);
    lua_pop(L, 1);
  }
  o.slide = opt_boundary(L, t, fn);
  o.progress = quiet ? 0 : opt_progress(L, t, fn); /* on the rank that runs it */
  mesh *m = u->lm->m;
  lg_mesh *refl = opt_reference(L, t, u->lm, fn);
  const mesh *ref = refl ? refl->m : NULL;
  if (ref) o.xref = ref->x;
  if (ref && o.no_global) return luaL_error(L, "%s: option 'reference' needs the global stage (global = false was given)", fn);
  untangle_report r;
  char err[MESH_ERRLEN];
  struct { untangle_report r; char names[3][64]; } both; /* the names outlive the block: r points at them */
  if (u->lm->dist) {
    /* on rank 0's whole mesh (and whole reference); the stages' names are its pointers: sent as text */
    memset(&both, 0, sizeof both);
    int rc = dist_repair(L, u, refl, &o.xref, repair_untangle, &o, &both.r, sizeof both, err);
    if (!rc && lg_mpi_rank() == 0) for (int i = 0; i < both.r.nstage && i < 3; i++) snprintf(both.names[i], 64, "%s", both.r.stage[i].name);
    if (!rc && MPI_Bcast(both.names, (int)sizeof both.names, MPI_CHAR, 0, PETSC_COMM_WORLD) != MPI_SUCCESS) rc = 1;
    lg_mesh_changed(u->lm); /* also on failure: the vertices may have moved */
    if (rc) return luaL_error(L, "%s: %s", fn, err);
    r = both.r;
    for (int i = 0; i < r.nstage && i < 3; i++) r.stage[i].name = both.names[i];
  } else {
    int rc = mesh_untangle(m, &o, &r, err);
    lg_mesh_changed(u->lm);
    if (rc) return luaL_error(L, "%s: %s", fn, err);
  }
  char text[2048];
  size_t n = (size_t)snprintf(text, sizeof text,
                              "untangle: %d %s, beta %.3g: invalid %d -> %d (%s), %d vertices moved (mean %.3g, max "
                              "%.3g), %.3f s",
                              (int)lg_mesh_global_cells(u->lm), cell_plural(m->type), r.beta, r.invalid_before, r.invalid_after,
                              r.invalid_after ? "FAILED" : "valid", r.moved, r.mean_displacement, r.max_displacement,
                              r.seconds);
  if (r.passes > 1 && n < sizeof text) n += (size_t)snprintf(text + n, sizeof text - n, ", %d passes", r.passes);
  if (r.fallback_placement >= 0 && n < sizeof text)
    n += (size_t)snprintf(text + n, sizeof text - n, ", then placement %s", r.fallback_placement ? "corners" : "chebyshev");
  else if (r.fallback_tried && n < sizeof text)
    n += (size_t)snprintf(text + n, sizeof text - n, ", the other placement did not help");
  if (r.tutte_tried && n < sizeof text)
    n += (size_t)snprintf(text + n, sizeof text - n, r.tutte_kept ? ", then Tutte disk shapes" : ", Tutte disk shapes did not help");
  lua_createtable(L, 0, 12);
  set_num(L, "beta", r.beta);
  set_int(L, "invalid_before", r.invalid_before);
  set_int(L, "invalid_after", r.invalid_after);
  lua_pushboolean(L, r.invalid_after == 0);
  lua_setfield(L, -2, "success");
  set_int(L, "moved", r.moved);
  set_num(L, "mean_displacement", r.mean_displacement);
  set_num(L, "max_displacement", r.max_displacement);
  set_num(L, "seconds", r.seconds);
  set_int(L, "passes", r.passes);
  lua_pushboolean(L, r.fallback_tried);
  lua_setfield(L, -2, "fallback_tried");
  lua_pushboolean(L, r.tutte_tried);
  lua_setfield(L, -2, "tutte_tried");
  lua_pushboolean(L, r.tutte_kept);
  lua_setfield(L, -2, "tutte_kept");
  if (r.fallback_placement >= 0) {
    lua_pushstring(L, r.fallback_placement ? "corners" : "chebyshev");
    lua_setfield(L, -2, "fallback_placement");
  }
  lua_createtable(L, r.nstage, 0);
  for (int i = 0; i < r.nstage; i++) {
    untangle_stage *st = &r.stage[i];
    lua_createtable(L, 0, 7);
    lua_pushstring(L, st->name);
    lua_setfield(L, -2, "name");
    set_int(L, "invalid_before", st->invalid_before);
    set_int(L, "invalid_after", st->invalid_after);
    set_int(L, "below_beta", st->below_beta_after);
    set_int(L, "moved", st->moved);
    set_int(L, "iterations", st->iterations);
    set_num(L, "seconds", st->seconds);
    lua_rawseti(L, -2, i + 1);
    if (n < sizeof text)
      n += (size_t)snprintf(text + n, sizeof text - n,
                            "\n  stage %-26s invalid %d -> %d, below beta %d, moved %d vertices, %d iterations, %.3f s",
                            st->name, st->invalid_before, st->invalid_after, st->below_beta_after, st->moved,
                            st->iterations, st->seconds);
  }
  lua_setfield(L, -2, "stages");
  return finish_report(L, text, quiet);
}

int lmesh_smooth(lua_State *L) {
  const char *fn = "mesh:smooth";
  ud_mesh *u = check_mesh(L, 1, fn);
  mesh *m = u->lm->m;
  int t = 0;
  if (!lua_isnoneornil(L, 2)) {
    if (!lua_istable(L, 2))
      return typeerror(L, fn, 2, "an options table {measure=, method=, iterations=, boundary=, quiet=, reference=, optimizer=, sliding=}");
    static const char *const keys[] = {"measure", "method", "iterations", "boundary", "quiet", "progress", "reference", "optimizer",
                                       "sliding", NULL};
    check_keys(L, 2, fn, keys);
    t = 2;
  }
  lg_mesh *refl = opt_reference(L, t, u->lm, fn);
  const mesh *ref = refl ? refl->m : NULL;
  smooth_opts o = {smooth_energy_measure(m->type), 20, 1, 0, 0, 0, NULL, SMOOTH_AUTO, SMOOTH_SLIDE_NONE, 1, 0};
  int quiet = 0;
  if (t) {
    const char *name = opt_str(L, t, "measure", NULL, fn);
    if (name) {
      o.measure = quality_from_name(name);
      if (o.measure < 0) {
        char names[4096];
        quality_names(names, sizeof names);
        return luaL_error(L, "%s: unknown measure '%s' (measures: %s)", fn, name, names);
      }
    }
    const char *method = opt_str(L, t, "method", "auto", fn);
    o.then_energy = !strcmp(method, "auto");
    if (!strcmp(method, "global")) o.global = 1;
    else if (!strcmp(method, "energy")) o.global = o.energy = 1;
    else if (strcmp(method, "local") && strcmp(method, "auto"))
      return luaL_error(L, "%s: option 'method' must be \"auto\", \"local\", \"global\" or \"energy\", got '%s'", fn, method);
    o.iterations = opt_int(L, t, "iterations", 20, fn);
    if (o.iterations < 1) return luaL_error(L, "%s: option 'iterations' must be >= 1", fn);
    lua_getfield(L, t, "quiet");
    quiet = lua_toboolean(L, -1);
    lua_pop(L, 1);
  }
  o.progress = quiet ? 0 : opt_progress(L, t, fn); /* on the rank that runs it */
  o.slide = opt_boundary(L, t, fn);
  if (ref) {
    o.xref = ref->x;
    if (t) {
      lua_getfield(L, t, "method");
      int given = !lua_isnil(L, -1);
      lua_pop(L, 1);
      if (!given) o.global = o.energy = 1; /* reference shapes are the energy method's */
    }
  }
  const char *opt = t ? opt_str(L, t, "optimizer", NULL, fn) : NULL;
  if (opt) {
    if ((o.optimizer = smooth_optimizer_from_name(opt)) < 0)
      return luaL_error(L, "%s: option 'optimizer' must be \"auto\", \"newton\" or \"lbfgs\", got '%s'", fn, opt);
    if (!o.energy) return luaL_error(L, "%s: option 'optimizer' needs method = \"energy\" (or reference shapes)", fn);
  }
  const char *sl = t ? opt_str(L, t, "sliding", NULL, fn) : NULL;
  if (sl) {
    if ((o.sliding = smooth_sliding_from_name(sl)) < 0)
      return luaL_error(L, "%s: option 'sliding' must be \"best\", \"optimizer\" or \"local\", got '%s'", fn, sl);
    if (!smooth_has_sliding_passes(m, &o))
      return luaL_error(L, "%s: option 'sliding' needs method = \"energy\" with boundary = \"slide\", the measure %s and no "
                           "reference", fn, quality_name(smooth_energy_measure(m->type)));
  }
  smooth_report r;
  char err[MESH_ERRLEN];
  /* the geometry's count moves also on failure: the vertices may have moved */
  int rc = u->lm->dist ? dist_repair(L, u, refl, &o.xref, repair_smooth, &o, &r, sizeof r, err) : mesh_smooth(m, &o, &r, err);
  lg_mesh_changed(u->lm);
  if (rc) return luaL_error(L, "%s: %s", fn, err);
  char text[512];
  snprintf(text, sizeof text, "smooth (%s%s): %s%s min %.4g -> %.4g, mean %.4g -> %.4g, %d vertices moved, %d %s, %.3f s",
           smooth_method_label(&o, &r), smooth_sliding_label(&r), quality_name(o.measure), ref ? " relative to the reference" : "",
           r.min_before, r.min_after, r.mean_before,
           r.mean_after, r.moved, r.sweeps, o.global ? "rounds" : "sweeps", r.seconds);
  lua_createtable(L, 0, 10);
  lua_pushstring(L, quality_name(o.measure));
  lua_setfield(L, -2, "measure");
  /* the default ("auto") reports what ran: "local", or "local, then energy" */
  lua_pushstring(L, r.then_energy ? "local, then energy" : o.energy ? "energy" : o.global ? "global" : "local");
  lua_setfield(L, -2, "method");
  if (r.then_energy) set_num(L, "min_local", r.min_local);
  set_num(L, "min_before", r.min_before);
  set_num(L, "min_after", r.min_after);
  set_num(L, "mean_before", r.mean_before);
  set_num(L, "mean_after", r.mean_after);
  set_int(L, "moved", r.moved);
  set_int(L, "sweeps", r.sweeps);
  if (o.energy || r.then_energy) {
    lua_pushstring(L, smooth_optimizer_name(r.optimizer));
    lua_setfield(L, -2, "optimizer");
    set_int(L, "iterations", r.iterations);
    if (r.optimizer == SMOOTH_NEWTON) {
      lua_pushstring(L, r.multigrid ? "multigrid" : "block_jacobi");
      lua_setfield(L, -2, "preconditioner");
    }
    if (smooth_sliding_name(r.sliding)) {
      lua_pushstring(L, smooth_sliding_name(r.sliding));
      lua_setfield(L, -2, "sliding");
    }
  }
  set_num(L, "seconds", r.seconds);
  return finish_report(L, text, quiet);
}

/* a displacement per vertex from a Lua function (x, y[, z]) -> dx, dy[, dz] (or a table), or
 * from a table of dim P1/P2/P3 functions on this mesh (one per component); only vertices with
 * want[v] (all when NULL) are evaluated */
static void displacement_field(lua_State *L, int idx, ud_mesh *u, const unsigned char *want, double *out,
                               const char *fn) {
  mesh *m = u->lm->m;
  int d = m->dim;
  if (lua_isfunction(L, idx)) {
    for (int v = 0; v < m->nvert; v++) {
      if (want && !want[v]) continue;
      lua_pushvalue(L, idx);
      for (int j = 0; j < d; j++) lua_pushnumber(L, m->x[(size_t)v * d + j]);
      lua_call(L, d, d);
      if (lua_istable(L, -d)) { /* one table {dx, dy[, dz]} */
        int tb = lua_gettop(L) - d + 1;
        for (int j = 0; j < d; j++) {
          lua_rawgeti(L, tb, j + 1);
          if (!lua_isnumber(L, -1)) luaL_error(L, "%s: the displacement function returned a table without %d numbers", fn, d);
          out[(size_t)v * d + j] = lua_tonumber(L, -1);
          lua_pop(L, 1);
        }
      } else
        for (int j = 0; j < d; j++) {
          if (!lua_isnumber(L, -d + j))
            luaL_error(L, "%s: the displacement function must return %d numbers (or one table of them) at vertex %d, got %s",
                       fn, d, v + 1, luaL_typename(L, -d + j));
          out[(size_t)v * d + j] = lua_tonumber(L, -d + j);
        }
      lua_pop(L, d);
    }
    return;
  }
  if (lua_istable(L, idx) && (int)luaL_len(L, idx) == d) {
    for (int j = 0; j < d; j++) {
      lua_rawgeti(L, idx, j + 1);
      ud_func *uf = luaL_testudata(L, -1, MT_FUNC);
      if (!uf) luaL_error(L, "%s: component %d of the displacement must be a discrete function, got %s", fn, j + 1, luaL_typename(L, -1));
      if (uf->f->mesh != u->lm) luaL_error(L, "%s: component %d of the displacement lives on a different mesh", fn, j + 1);
      for (int v = 0; v < m->nvert; v++) out[(size_t)v * d + j] = uf->f->x[v]; /* vertex dofs come first */
      lua_pop(L, 1);
    }
    return;
  }
  typeerror(L, fn, idx, d == 2 ? "a function (x, y) -> dx, dy or a table {fx, fy} of discrete functions"
                                : "a function (x, y, z) -> dx, dy, dz or a table {fx, fy, fz} of discrete functions");
}

int lmesh_move(lua_State *L) {
  const char *fn = "mesh:move";
  ud_mesh *u = check_mesh(L, 1, fn);
  mesh *m = u->lm->m;
  if (!lua_istable(L, 2)) return typeerror(L, fn, 2, "an options table {displacement = function or {fx, fy[, fz]}, quiet=}");
  static const char *const keys[] = {"displacement", "quiet", NULL};
  check_keys(L, 2, fn, keys);
  lua_getfield(L, 2, "quiet");
  int quiet = lua_toboolean(L, -1);
  lua_pop(L, 1);
  lua_getfield(L, 2, "displacement");
  if (lua_isnil(L, -1)) return luaL_error(L, "%s: option 'displacement' is required (the boundary displacement)", fn);
  int idx = lua_gettop(L);
  unsigned char *fixed = lua_newuserdatauv(L, (size_t)m->nvert + 1, 0);
  double *disp = lua_newuserdatauv(L, sizeof(double) * ((size_t)m->nvert * m->dim + 1), 0);
  char err[MESH_ERRLEN];
  move_report r;
  if (u->lm->dist) {
    /* every local vertex's displacement (the outer vertices of the ghost layer are not the
     * mesh's boundary), gathered with the mesh on rank 0, which moves it with the whole
     * mesh's boundary fixed; the new coordinates back to every rank */
    memset(disp, 0, sizeof(double) * (size_t)m->nvert * m->dim);
    displacement_field(L, idx, u, NULL, disp, fn);
    lg_env *env = get_env(L);
    mesh_field f = {"displacement", m->dim, 0, disp};
    mesh *W = NULL;
    double **vals = NULL;
    int rc = lg_dist_gather(env, u->lm->dist, 1, &f, &W, &vals);
    if (rc) snprintf(err, sizeof err, "%.*s", (int)sizeof err - 1, env->err);
    else if (lg_mpi_rank() == 0) {
      unsigned char *wf = malloc((size_t)W->nvert + 1);
      rc = !wf || mesh_boundary_vertices(W, wf, err);
      if (!wf) snprintf(err, sizeof err, "out of memory");
      for (int v = 0; !rc && v < W->nvert; v++)
        if (!wf[v]) memset(vals[0] + (size_t)v * m->dim, 0, sizeof(double) * (size_t)m->dim);
      if (!rc) rc = mesh_move(W, vals[0], wf, &r, err);
      free(wf);
    }
    if (vals) free(vals[0]);
    free(vals);
    rc = lg_root_result(rc, err, sizeof err);
    if (!rc && MPI_Bcast(&r, (int)sizeof r, MPI_BYTE, 0, PETSC_COMM_WORLD) != MPI_SUCCESS) { snprintf(err, sizeof err, "sending the report failed"); rc = 1; }
    if (!rc && lg_dist_scatter_coords(env, u->lm->dist, W)) { snprintf(err, sizeof err, "%.*s", (int)sizeof err - 1, env->err); rc = 1; }
    mesh_free(W);
    lg_mesh_changed(u->lm); /* also on failure: the coordinates may have come back in part */
    if (rc) return luaL_error(L, "%s: %s", fn, err);
  } else {
    if (mesh_boundary_vertices(m, fixed, err)) return luaL_error(L, "%s: %s", fn, err);
    memset(disp, 0, sizeof(double) * (size_t)m->nvert * m->dim);
    displacement_field(L, idx, u, fixed, disp, fn);
    int rc = mesh_move(m, disp, fixed, &r, err);
    lg_mesh_changed(u->lm);
    if (rc) return luaL_error(L, "%s: %s", fn, err);
  }
  char text[512];
  snprintf(text, sizeof text, "move: Laplacian motion, tau_max %.3g, %d CG iterations (residual %.1e), %d invalid cells after, %.3f s",
           r.tau_max, r.iterations, r.residual, r.invalid_after, r.seconds);
  lua_createtable(L, 0, 6);
  set_int(L, "iterations", r.iterations);
  set_num(L, "residual", r.residual);
  set_num(L, "tau_max", r.tau_max);
  set_int(L, "invalid_after", r.invalid_after);
  set_num(L, "seconds", r.seconds);
  return finish_report(L, text, quiet);
}

int lmesh_displace(lua_State *L) {
  const char *fn = "mesh:displace";
  ud_mesh *u = check_mesh(L, 1, fn);
  mesh *m = u->lm->m;
  if (lua_isnoneornil(L, 2)) return typeerror(L, fn, 2, "a function (x, y[, z]) -> displacement or a table of discrete functions");
  double *disp = lua_newuserdatauv(L, sizeof(double) * ((size_t)m->nvert * m->dim + 1), 0);
  displacement_field(L, 2, u, NULL, disp, fn);
  for (size_t i = 0; i < (size_t)m->nvert * m->dim; i++)
    if (!isfinite(m->x[i] + disp[i]))
      return luaL_error(L, "%s: the displacement of vertex %d is not finite (%c = %f, or the moved coordinate overflows); the "
                           "mesh is unchanged", fn, (int)(i / m->dim) + 1, "xyz"[i % m->dim], disp[i]);
  for (size_t i = 0; i < (size_t)m->nvert * m->dim; i++) m->x[i] += disp[i];
  lg_mesh_changed(u->lm);
  int ninv = 0;
  if (u->lm->dist) { /* each rank its owned cells (a distributed mesh's vertices move on every rank that holds them) */
    double n = 0;
    for (int c = 0; c < m->ncell; c++) n += u->lm->dist->cowner[c] == lg_mpi_rank() && !(mesh_cell_relative_validity(m, c) > 1e-13);
    lg_allreduce(&n, 1, LG_SUM);
    ninv = (int)n;
  } else mesh_count_invalid(m, 0, NULL, &ninv);
  lua_pushinteger(L, ninv);
  return 1;
}
