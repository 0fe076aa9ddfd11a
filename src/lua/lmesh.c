/* lmesh.c — Lua bindings of the mesh layer: generators, Gmsh reading, lg.mesh.new, regions
 * (mesh:cells, mesh:boundary), output (VTU, MSH, .pvd series), quality arrays and reports.
 * The repairs (untangling, smoothing, motion) are lrepair.c's. */
#include "largs.h"
#include "../mesh/io/svg.h"

#include <lauxlib.h>
#include <limits.h>
#include <math.h>
#include <petscsys.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static int mesh_gc(lua_State *L) {
  ud_mesh *u = lua_touserdata(L, 1);
  lg_mesh_free(u->lm);
  u->lm = NULL;
  return 0;
}

/* a generator's mesh: under -lugal_distribute only rank 0 makes it (push_mesh sends each rank
 * its part), and its failure is every rank's */
static int generate_here(void) { return !lg_distribute_wanted() || lg_mpi_rank() == 0; }

/* a distributed box or rectangle: each rank generates its own part where it can
 * (lg_mesh_generate_part) and pushes it (1); 0 where rank 0 must generate the whole mesh */
static int generate_part(lua_State *L, const mesh_box_opts *o, const char *fn) {
  if (!lg_distribute_wanted()) return 0;
  lg_env *env = get_env(L);
  int whole = 0;
  lg_mesh *lm = lg_mesh_generate_part(env, o, &whole);
  if (!lm && !whole) return luaL_error(L, "%s: %s", fn, env->err);
  if (!lm) return 0;
  push_mesh_part(L, lm);
  return 1;
}

static void generated(lua_State *L, mesh *m, char *err, const char *fn) {
  int bad = generate_here() && !m;
  if (lg_distribute_wanted() ? lg_root_result(bad, err, MESH_ERRLEN) : bad) luaL_error(L, "%s: %s", fn, err);
}

static int l_interval(lua_State *L) {
  const char *fn = "lg.mesh.interval";
  if (lua_isnoneornil(L, 1)) lua_newtable(L);
  if (!lua_istable(L, 1)) typeerror(L, fn, 1, "a table of options {n =, x0 =, x1 =}");
  static const char *const keys[] = {"n", "nx", "x0", "x1", NULL};
  check_keys(L, 1, fn, keys);
  int n = opt_int(L, 1, "n", opt_int(L, 1, "nx", 8, fn), fn);
  double x0 = opt_num(L, 1, "x0", 0, fn), x1 = opt_num(L, 1, "x1", 1, fn);
  char err[MESH_ERRLEN];
  err[0] = 0;
  mesh *m = generate_here() ? mesh_interval(n, x0, x1, err) : NULL;
  generated(L, m, err, fn);
  push_mesh(L, m);
  return 1;
}

static int l_rectangle(lua_State *L) {
  const char *fn = "lg.mesh.rectangle";
  if (lua_isnoneornil(L, 1)) lua_newtable(L);
  if (!lua_istable(L, 1)) typeerror(L, fn, 1, "a table of options");
  static const char *const keys[] = {"nx", "ny", "x0", "x1", "y0", "y1", "cell", "diagonal", NULL};
  check_keys(L, 1, fn, keys);
  mesh_box_opts o;
  memset(&o, 0, sizeof o);
  o.nx = opt_int(L, 1, "nx", 8, fn);
  o.ny = opt_int(L, 1, "ny", o.nx, fn);
  o.x0 = opt_num(L, 1, "x0", 0, fn);
  o.x1 = opt_num(L, 1, "x1", 1, fn);
  o.y0 = opt_num(L, 1, "y0", 0, fn);
  o.y1 = opt_num(L, 1, "y1", 1, fn);
  const char *cell = opt_str(L, 1, "cell", "triangle", fn);
  if (!strcmp(cell, "triangle")) o.type = CELL_TRIANGLE;
  else if (!strcmp(cell, "quadrilateral")) o.type = CELL_QUADRILATERAL;
  else return luaL_error(L, "%s: option 'cell' must be \"triangle\" or \"quadrilateral\", got \"%s\"", fn, cell);
  const char *dg = opt_str(L, 1, "diagonal", "right", fn);
  if (!strcmp(dg, "right")) o.diagonal = 0;
  else if (!strcmp(dg, "left")) o.diagonal = 1;
  else if (!strcmp(dg, "crossed")) o.diagonal = 2;
  else return luaL_error(L, "%s: option 'diagonal' must be \"right\", \"left\" or \"crossed\", got \"%s\"", fn, dg);
  char err[MESH_ERRLEN];
  err[0] = 0;
  if (generate_part(L, &o, fn)) return 1;
  mesh *m = generate_here() ? mesh_rectangle(&o, err) : NULL;
  generated(L, m, err, fn);
  push_mesh(L, m);
  return 1;
}

static int l_box(lua_State *L) {
  const char *fn = "lg.mesh.box";
  if (lua_isnoneornil(L, 1)) lua_newtable(L);
  if (!lua_istable(L, 1)) typeerror(L, fn, 1, "a table of options");
  static const char *const keys[] = {"nx", "ny", "nz", "x0", "x1", "y0", "y1", "z0", "z1", "cell", NULL};
  check_keys(L, 1, fn, keys);
  mesh_box_opts o;
  memset(&o, 0, sizeof o);
  o.nx = opt_int(L, 1, "nx", 4, fn);
  o.ny = opt_int(L, 1, "ny", o.nx, fn);
  o.nz = opt_int(L, 1, "nz", o.nx, fn);
  o.x0 = opt_num(L, 1, "x0", 0, fn);
  o.x1 = opt_num(L, 1, "x1", 1, fn);
  o.y0 = opt_num(L, 1, "y0", 0, fn);
  o.y1 = opt_num(L, 1, "y1", 1, fn);
  o.z0 = opt_num(L, 1, "z0", 0, fn);
  o.z1 = opt_num(L, 1, "z1", 1, fn);
  const char *cell = opt_str(L, 1, "cell", "tetrahedron", fn);
  if (!strcmp(cell, "tetrahedron")) o.type = CELL_TETRAHEDRON;
  else if (!strcmp(cell, "hexahedron")) o.type = CELL_HEXAHEDRON;
  else return luaL_error(L, "%s: option 'cell' must be \"tetrahedron\" or \"hexahedron\", got \"%s\"", fn, cell);
  char err[MESH_ERRLEN];
  err[0] = 0;
  if (generate_part(L, &o, fn)) return 1;
  mesh *m = generate_here() ? mesh_box(&o, err) : NULL;
  generated(L, m, err, fn);
  push_mesh(L, m);
  return 1;
}

/* lg.mesh.read(path); under mpiexec with distributed meshes each rank reads its part of the
 * file (read_dist.c), or where that cannot be (the file's layout, a mesh the whole reader
 * refuses, -lugal_read_parts 0) rank 0 parses the file and sends each rank its part; with
 * -lugal_distribute 0 it sends every rank the whole mesh (mesh_pack) */
static int l_read(lua_State *L) {
  const char *path = check_cstring(L, 1, "lg.mesh.read", "argument 1 (the path)");
  char err[MESH_ERRLEN] = "";
  int root = lg_mpi_rank() == 0;
  if (lg_distribute_wanted() && lg_read_parts_wanted()) {
    lg_mesh *lm = lg_mesh_read_parts(get_env(L), path);
    if (lm) {
      push_mesh_part(L, lm);
      return 1;
    }
  }
  mesh *m = root ? mesh_read_gmsh(path, err) : NULL;
  if (lg_distribute_wanted()) { /* rank 0 sends each rank its part only (push_mesh) */
    if (lg_root_result(m == NULL, err, sizeof err)) return luaL_error(L, "lg.mesh.read: %s", err);
    push_mesh(L, m);
    return 1;
  }
  if (lg_mpi_size() > 1) {
    char *buf = NULL;
    size_t len = 0;
    int rc = root && (!m || mesh_pack(m, &buf, &len));
    if (root && m && rc) snprintf(err, sizeof err, "out of memory packing the mesh for the other ranks");
    if (lg_root_result(rc, err, sizeof err)) { mesh_free(m); return luaL_error(L, "lg.mesh.read: %s", err); }
    rc = lg_bcast_bytes(&buf, &len);
    if (!rc && !root && !(m = mesh_unpack(buf, len, err))) rc = 1;
    free(buf);
    if (lg_any_result(rc, err, sizeof err)) {
      mesh_free(m);
      return luaL_error(L, "lg.mesh.read: sending the mesh to every rank failed: %s", err[0] ? err : "out of memory");
    }
  }
  if (!m) return luaL_error(L, "lg.mesh.read: %s", err);
  push_mesh(L, m);
  return 1;
}

static int cmp_str(const void *a, const void *b) { return strcmp(*(const char *const *)a, *(const char *const *)b); }

/* lg.mesh.new{cell=, vertices={{x,y},...}, cells={{1,2,3},...}, boundary={name={{a,b},...}}};
 * buffers are userdata, so that an error anywhere leaks nothing */
static int l_mesh_new(lua_State *L) {
  const char *fn = "lg.mesh.new";
  if (!lua_istable(L, 1)) typeerror(L, fn, 1, "a table {cell=, vertices=, cells=, boundary=}");
  static const char *const keys[] = {"cell", "vertices", "cells", "boundary", NULL};
  check_keys(L, 1, fn, keys);
  const char *cell = opt_str(L, 1, "cell", "triangle", fn);
  cell_type t;
  if (!strcmp(cell, "triangle")) t = CELL_TRIANGLE;
  else if (!strcmp(cell, "quadrilateral")) t = CELL_QUADRILATERAL;
  else if (!strcmp(cell, "tetrahedron")) t = CELL_TETRAHEDRON;
  else if (!strcmp(cell, "hexahedron")) t = CELL_HEXAHEDRON;
  else return luaL_error(L, "%s: 'cell' must be triangle, quadrilateral, tetrahedron or hexahedron, got \"%s\"", fn, cell);
  int dim = cell_dim(t), nvc = cell_nverts(t);
  if (lua_getfield(L, 1, "vertices") != LUA_TTABLE) return luaL_error(L, "%s: 'vertices' must be a table of coordinate tables", fn);
  int vt = lua_gettop(L);
  if (lua_getfield(L, 1, "cells") != LUA_TTABLE) return luaL_error(L, "%s: 'cells' must be a table of vertex-index tables", fn);
  int ct = lua_gettop(L);
  lua_Integer nv = luaL_len(L, vt), nc = luaL_len(L, ct);
  if (nv < 1 || nc < 1) return luaL_error(L, "%s: need at least one vertex and one cell", fn);
  if (nv > INT_MAX / 3 || nc > INT_MAX / 8) return luaL_error(L, "%s: too many vertices or cells", fn);
  double *x = lua_newuserdatauv(L, sizeof(double) * (size_t)nv * dim, 0);
  int *c = lua_newuserdatauv(L, sizeof(int) * (size_t)nc * nvc, 0);
  unsigned char *used = lua_newuserdatauv(L, (size_t)nv, 0);
  memset(used, 0, (size_t)nv);
  for (lua_Integer i = 1; i <= nv; i++) {
    if (lua_geti(L, vt, i) != LUA_TTABLE || luaL_len(L, -1) != dim)
      return luaL_error(L, "%s: vertex %I must be a table of %d numbers", fn, i, dim);
    for (int d = 1; d <= dim; d++) {
      lua_geti(L, -1, d);
      int isnum;
      double v = lua_tonumberx(L, -1, &isnum);
      if (!isnum) return luaL_error(L, "%s: vertex %I coordinate %d must be a number, got %s", fn, i, d, luaL_typename(L, -1));
      if (!isfinite(v)) return luaL_error(L, "%s: vertex %I coordinate %d is not finite (%f)", fn, i, d, v);
      x[(size_t)(i - 1) * dim + d - 1] = v;
      lua_pop(L, 1);
    }
    lua_pop(L, 1);
  }
  char what[128];
  for (lua_Integer i = 1; i <= nc; i++) {
    if (lua_geti(L, ct, i) != LUA_TTABLE || luaL_len(L, -1) != nvc)
      return luaL_error(L, "%s: cell %I must be a table of %d vertex indices", fn, i, nvc);
    for (int k = 1; k <= nvc; k++) {
      lua_geti(L, -1, k);
      snprintf(what, sizeof what, "cell %lld entry %d", (long long)i, k);
      int v = (int)check_int_value(L, -1, 1, nv, fn, what) - 1;
      c[(size_t)(i - 1) * nvc + k - 1] = v;
      used[v] = 1;
      lua_pop(L, 1);
    }
    lua_pop(L, 1);
  }
  for (lua_Integer i = 0; i < nv; i++)
    if (!used[i])
      return luaL_error(L, "%s: vertex %I is not in any cell (every vertex of a mesh must be: it would be a dof "
                           "that no equation constrains)", fn, i + 1);
  char err[MESH_ERRLEN];
  mesh *m = mesh_create(t, (int)nv, x, (int)nc, c, err);
  if (!m) return luaL_error(L, "%s: %s", fn, err);
  push_mesh(L, m);
  int midx = lua_gettop(L);
  if (lua_getfield(L, 1, "boundary") == LUA_TTABLE) {
    /* names in sorted order get tags 1, 2, ...: the same script numbers them the same way */
    int bt = lua_gettop(L), nnames = 0;
    lua_pushnil(L);
    while (lua_next(L, bt)) {
      if (lua_type(L, -2) != LUA_TSTRING || lua_type(L, -1) != LUA_TTABLE)
        return luaL_error(L, "%s: 'boundary' maps names to tables of facets", fn);
      check_cstring(L, -2, fn, "boundary name");
      lua_pop(L, 1);
      nnames++;
    }
    const char **names = lua_newuserdatauv(L, sizeof(char *) * (size_t)(nnames + 1), 0);
    nnames = 0;
    lua_pushnil(L);
    while (lua_next(L, bt)) { lua_pop(L, 1); names[nnames++] = lua_tostring(L, -1); }
    qsort(names, (size_t)nnames, sizeof(char *), cmp_str);
    int nvf = m->nvf;
    for (int tag = 1; tag <= nnames; tag++) {
      const char *name = names[tag - 1];
      lua_getfield(L, bt, name);
      lua_Integer n = luaL_len(L, -1);
      if (n > INT_MAX / 4) return luaL_error(L, "%s: boundary '%s' has too many facets", fn, name);
      int *fv = lua_newuserdatauv(L, sizeof(int) * (size_t)(n + 1) * nvf, 0);
      for (lua_Integer i = 1; i <= n; i++) {
        if (lua_geti(L, -2, i) != LUA_TTABLE || luaL_len(L, -1) != nvf)
          return luaL_error(L, "%s: boundary '%s' facet %I must list %d vertices", fn, name, i, nvf);
        for (int k = 1; k <= nvf; k++) {
          lua_geti(L, -1, k);
          snprintf(what, sizeof what, "boundary '%.20s' facet %lld vertex %d", name, (long long)i, k);
          fv[(i - 1) * nvf + k - 1] = (int)check_int_value(L, -1, 1, nv, fn, what) - 1;
          lua_pop(L, 1);
        }
        lua_pop(L, 1);
      }
      if (mesh_add_boundary_facets(m, (int)n, fv, tag, name)) return luaL_error(L, "%s: %s", fn, m->err);
      lua_pop(L, 2);
    }
    if (mesh_build_boundary_cells(m)) return luaL_error(L, "%s: %s", fn, m->err);
  }
  lua_pushvalue(L, midx);
  return 1;
}

/* "1, 2, 3" (the tags in use), cut with "..." */
static void tag_list(const mesh *m, region_kind kind, char *buf, size_t len) {
  int tags[64];
  int n = kind == REGION_BOUNDARY ? mesh_used_boundary_tags(m, tags, 64) : mesh_used_region_tags(m, tags, 64);
  size_t used = 0;
  buf[0] = 0;
  for (int i = 0; i < n && i < 64 && used + 16 < len; i++) used += (size_t)snprintf(buf + used, len - used, "%s%d", i ? ", " : "", tags[i]);
  if (n > 64 || used + 16 >= len) snprintf(buf + used, len - used, ", ...");
  if (n <= 0) snprintf(buf, len, kind == REGION_BOUNDARY ? "none" : "none: every cell has tag 0");
}

static void region_add_tag(lua_State *L, region *r, int tag, const char *fn) {
  for (int i = 0; i < r->ntag; i++)
    if (r->tags[i] == tag) return;
  if (r->ntag == REGION_MAXTAGS) luaL_error(L, "%s: the names and tags given cover more than %d tags", fn, REGION_MAXTAGS);
  r->tags[r->ntag++] = tag;
}

/* a distributed mesh's answer to "is it anywhere": v on any rank (collective there) */
static int on_any_rank(const lg_mesh *lm, int v) {
  if (!lm->dist) return v;
  double x = v;
  lg_allreduce(&x, 1, LG_MAX);
  return x != 0;
}

static int region_new(lua_State *L, region_kind kind, const char *fn) {
  ud_mesh *um = check_mesh(L, 1, fn);
  mesh *m = um->lm->m;
  int n = lua_gettop(L) - 1;
  region r;
  memset(&r, 0, sizeof r);
  r.kind = kind;
  r.mesh = um->lm;
  const char *what = kind == REGION_BOUNDARY ? "boundary" : "region";
  /* no names: every cell, or every tagged boundary facet (ntag = 0) */
  if (kind == REGION_BOUNDARY && n == 0 && !on_any_rank(um->lm, m->nbf > 0))
    return luaL_error(L, "%s: this mesh has no tagged boundary facets (lg.mesh.new takes them as boundary = "
                         "{name = {facets}}; Gmsh files as physical groups)", fn);
  for (int i = 0; i < n; i++) {
    int arg = i + 2;
    int isint = 0;
    lua_Integer t = lua_type(L, arg) == LUA_TNUMBER ? lua_tointegerx(L, arg, &isint) : 0;
    if (isint) {
      int known = t >= INT_MIN && t <= INT_MAX &&
                  (kind == REGION_BOUNDARY ? mesh_has_boundary_tag(m, (int)t) : mesh_has_region_tag(m, (int)t));
      if (!on_any_rank(um->lm, known)) {
        char list[256];
        tag_list(m, kind, list, sizeof list);
        return luaL_error(L, "%s: no %s has tag %I (this mesh's %s tags: %s)", fn,
                          kind == REGION_BOUNDARY ? "boundary facet" : "cell", t, what, list);
      }
      region_add_tag(L, &r, (int)t, fn);
    } else if (lua_type(L, arg) == LUA_TSTRING) {
      const char *name = check_cstring(L, arg, fn, "the name");
      int tags[REGION_MAXTAGS];
      int k = kind == REGION_BOUNDARY ? mesh_boundary_tags(m, name, tags, REGION_MAXTAGS) : mesh_region_tags(m, name, tags, REGION_MAXTAGS);
      if (k == 0) {
        char list[512];
        if (kind == REGION_BOUNDARY) mesh_boundary_names(m, list, sizeof list);
        else mesh_region_names(m, list, sizeof list);
        return luaL_error(L, "%s: unknown %s name \"%s\" (this mesh has: %s)", fn, what, name, list);
      }
      if (k > REGION_MAXTAGS) return luaL_error(L, "%s: the name \"%s\" covers more than %d tags", fn, name, REGION_MAXTAGS);
      int used = 0;
      for (int j = 0; j < k; j++) {
        used |= kind == REGION_BOUNDARY ? mesh_has_boundary_tag(m, tags[j]) : mesh_has_region_tag(m, tags[j]);
        region_add_tag(L, &r, tags[j], fn);
      }
      if (!on_any_rank(um->lm, used)) return luaL_error(L, "%s: the %s \"%s\" has no %s in this mesh", fn, what, name,
                                   kind == REGION_BOUNDARY ? "facets" : "cells");
    } else return typeerror(L, fn, arg, kind == REGION_BOUNDARY ? "a boundary name or an integer tag" : "a region name or an integer tag");
  }
  int deps[1] = {1};
  ud_region *u = new_ud(L, sizeof *u, MT_REGION, 1, deps);
  u->r = r;
  return 1;
}

static int mesh_cells(lua_State *L) { return region_new(L, REGION_CELLS, "mesh:cells"); }

static int mesh_boundary(lua_State *L) { return region_new(L, REGION_BOUNDARY, "mesh:boundary"); }

/* mesh:interior_facets(): the facets shared by two cells, for the jumps and averages of
 * discontinuous Galerkin and interior penalty forms */
static int mesh_interior_facets(lua_State *L) {
  const char *fn = "mesh:interior_facets";
  ud_mesh *um = check_mesh(L, 1, fn);
  if (lua_gettop(L) > 1) return luaL_error(L, "%s: takes no arguments, got %d", fn, lua_gettop(L) - 1);
  mesh *m = um->lm->m;
  if (m->type == CELL_HEXAHEDRON)
    return luaL_error(L, "%s: interior facet integrals are implemented on intervals, triangles, quadrilaterals and "
                         "tetrahedra, not on hexahedra", fn);
  if (mesh_build_interior_facets(m)) return luaL_error(L, "%s: %s", fn, m->err);
  region r;
  memset(&r, 0, sizeof r);
  r.kind = REGION_INTERIOR;
  r.mesh = um->lm;
  int deps[1] = {1};
  ud_region *u = new_ud(L, sizeof *u, MT_REGION, 1, deps);
  u->r = r;
  return 1;
}

/* mesh:vertices{near = {x, y}} or {near = {{x, y}, ...}}: the vertex nearest to each point,
 * a region for lg.essential_bc (a pinned pressure, a fixed point of a free body) */
static int mesh_vertices(lua_State *L) {
  const char *fn = "mesh:vertices";
  ud_mesh *um = check_mesh(L, 1, fn);
  mesh *m = um->lm->m;
  if (!lua_istable(L, 2)) return typeerror(L, fn, 1, "a table {near = {x, y}} or {near = {{x, y}, ...}}");
  static const char *const keys[] = {"near", NULL};
  check_keys(L, 2, fn, keys);
  if (lua_getfield(L, 2, "near") != LUA_TTABLE) return luaL_error(L, "%s: option 'near' must be a point {x, y} or a table of points", fn);
  int t = lua_gettop(L);
  region r;
  memset(&r, 0, sizeof r);
  r.kind = REGION_POINTS;
  r.mesh = um->lm;
  int list = lua_geti(L, t, 1) == LUA_TTABLE;
  lua_pop(L, 1);
  lua_Integer np = list ? luaL_len(L, t) : 1;
  if (np < 1 || np > REGION_MAXTAGS) return luaL_error(L, "%s: option 'near' lists 1 to %d points, got %I", fn, REGION_MAXTAGS, np);
  for (lua_Integer i = 1; i <= np; i++) {
    if (list) lua_geti(L, t, i);
    else lua_pushvalue(L, t);
    if (!lua_istable(L, -1) || luaL_len(L, -1) != m->dim)
      return luaL_error(L, "%s: point %I of option 'near' must be a table of %d coordinates", fn, i, m->dim);
    double x[3] = {0, 0, 0};
    for (int d = 0; d < m->dim; d++) {
      lua_geti(L, -1, d + 1);
      int isnum;
      x[d] = lua_tonumberx(L, -1, &isnum);
      if (!isnum || !isfinite(x[d])) return luaL_error(L, "%s: coordinate %d of point %I must be a finite number", fn, d + 1, i);
      lua_pop(L, 1);
    }
    lua_pop(L, 1);
    int best = -1;
    double bd = INFINITY;
    for (int v = 0; v < m->nvert; v++) {
      double s = 0;
      for (int d = 0; d < m->dim; d++) s += (m->x[(size_t)v * m->dim + d] - x[d]) * (m->x[(size_t)v * m->dim + d] - x[d]);
      if (s < bd) { bd = s; best = v; }
    }
    if (um->lm->dist) {
      /* the whole mesh's nearest vertex (the lowest global number among equally near ones),
       * on the ranks that hold it */
      const mesh_part *P = um->lm->dist;
      double d[2] = {bd, 0};
      lg_allreduce(d, 1, LG_MIN);
      d[1] = -INFINITY;
      for (int v = 0; v < m->nvert; v++) {
        double s = 0;
        for (int k = 0; k < m->dim; k++) s += (m->x[(size_t)v * m->dim + k] - x[k]) * (m->x[(size_t)v * m->dim + k] - x[k]);
        if (s == d[0] && -(double)P->vglobal[v] > d[1]) d[1] = -(double)P->vglobal[v];
      }
      lg_allreduce(d + 1, 1, LG_MAX);
      int g = (int)-d[1];
      best = -1;
      for (int lo = 0, hi = m->nvert - 1; lo <= hi && best < 0;) {
        int mid = (lo + hi) / 2;
        if (P->vglobal[mid] == g) best = mid;
        else if (P->vglobal[mid] < g) lo = mid + 1;
        else hi = mid - 1;
      }
      if (best < 0) continue; /* another rank's vertex */
    } else if (best < 0) return luaL_error(L, "%s: the mesh has no vertices", fn);
    int dup = 0;
    for (int k = 0; k < r.ntag; k++) dup |= r.tags[k] == best;
    if (!dup) r.tags[r.ntag++] = best;
  }
  int deps[1] = {1};
  ud_region *ur = new_ud(L, sizeof *ur, MT_REGION, 1, deps);
  ur->r = r;
  return 1;
}

static int mesh_info(lua_State *L) {
  ud_mesh *u = check_mesh(L, 1, "mesh:info");
  mesh *m = u->lm->m;
  /* the whole mesh's counts (a distributed one's: each tagged facet counted by the rank
   * that owns its cell) */
  double nbf = m->nbf;
  if (u->lm->dist) {
    if (mesh_build_boundary_cells(m)) return luaL_error(L, "mesh:info: %s", m->err);
    nbf = 0;
    for (int b = 0; b < m->nbf; b++) nbf += u->lm->dist->cowner[m->bf_cell[b]] == lg_mpi_rank();
    lg_allreduce(&nbf, 1, LG_SUM);
  }
  lua_createtable(L, 0, 6);
  lua_pushinteger(L, lg_mesh_global_vertices(u->lm)); lua_setfield(L, -2, "vertices");
  lua_pushinteger(L, lg_mesh_global_cells(u->lm)); lua_setfield(L, -2, "cells");
  lua_pushinteger(L, m->dim); lua_setfield(L, -2, "dim");
  lua_pushstring(L, cell_name(m->type)); lua_setfield(L, -2, "cell");
  lua_pushinteger(L, (lua_Integer)nbf); lua_setfield(L, -2, "boundary_facets");
  lua_newtable(L);
  for (int i = 0; i < m->nbname; i++) { lua_pushstring(L, m->bnames[i].name); lua_rawseti(L, -2, i + 1); }
  lua_setfield(L, -2, "boundaries");
  return 1;
}

/* the whole mesh's counts, on a distributed mesh too */
static int mesh_nvertices(lua_State *L) { lua_pushinteger(L, lg_mesh_global_vertices(check_mesh(L, 1, "mesh:nvertices")->lm)); return 1; }

static int mesh_ncells(lua_State *L) { lua_pushinteger(L, lg_mesh_global_cells(check_mesh(L, 1, "mesh:ncells")->lm)); return 1; }

static int mesh_dim(lua_State *L) { lua_pushinteger(L, check_mesh(L, 1, "mesh:dim")->lm->m->dim); return 1; }

static int lmesh_refine(lua_State *L) {
  ud_mesh *u = check_mesh(L, 1, "mesh:refine");
  char err[MESH_ERRLEN] = "";
  if (u->lm->dist) { /* rank 0 refines the whole mesh and distributes the result (push_mesh) */
    lg_env *env = get_env(L);
    mesh *W = NULL, *r = NULL;
    int rc = lg_dist_gather_mesh(env, u->lm->dist, &W);
    if (rc) snprintf(err, sizeof err, "%.*s", (int)sizeof err - 1, env->err);
    else if (lg_mpi_rank() == 0 && !(r = mesh_refine(W, err))) rc = 1;
    mesh_free(W);
    if (lg_root_result(rc, err, sizeof err)) { mesh_free(r); return luaL_error(L, "mesh:refine: %s", err); }
    push_mesh(L, r);
    return 1;
  }
  mesh *r = mesh_refine(u->lm->m, err);
  if (!r) return luaL_error(L, "mesh:refine: %s", err);
  push_mesh(L, r);
  return 1;
}

static int lmesh_copy(lua_State *L) {
  ud_mesh *u = check_mesh(L, 1, "mesh:copy");
  if (u->lm->dist) { /* each rank copies its part: the same partition, no communication */
    char *buf;
    size_t len;
    char err[MESH_ERRLEN];
    mesh_part *P = mesh_part_pack(u->lm->dist, &buf, &len) ? NULL : mesh_part_unpack(buf, len, err);
    if (P) free(buf);
    lg_mesh *lm = P ? lg_mesh_wrap_part(P) : NULL;
    if (!lm) { mesh_part_free(P); return luaL_error(L, "mesh:copy: out of memory"); }
    ud_mesh *c = lua_newuserdatauv(L, sizeof *c, 1);
    c->lm = lm;
    luaL_setmetatable(L, MT_MESH);
    return 1;
  }
  mesh *c = mesh_copy(u->lm->m);
  if (!c) return luaL_error(L, "mesh:copy: out of memory");
  push_mesh(L, c);
  return 1;
}

static int lmesh_hmax(lua_State *L) {
  ud_mesh *u = check_mesh(L, 1, "mesh:hmax");
  double h = u->lm->m->ncell ? mesh_hmax(u->lm->m) : 0;
  if (u->lm->dist) lg_allreduce(&h, 1, LG_MAX); /* the whole mesh's */
  lua_pushnumber(L, h);
  return 1;
}

static int mesh_check(lua_State *L) {
  ud_mesh *u = check_mesh(L, 1, "mesh:check");
  int ids[10], n;
  const mesh_part *P = u->lm->dist;
  if (P) { /* each rank its owned cells; the ten lowest global numbers of all */
    mesh *m = u->lm->m;
    double v[10], cnt = 0;
    int g[10], k = 0, rank = lg_mpi_rank();
    for (int c = 0; c < m->ncell; c++) {
      if (P->cowner[c] != rank) continue;
      double q = mesh_cell_relative_validity(m, c);
      if (q > 1e-13) continue;
      cnt++;
      if (k < 10) { g[k] = P->cglobal[c]; v[k++] = P->cglobal[c]; }
    }
    lg_env *env = get_env(L);
    if (lg_allreduce(&cnt, 1, LG_SUM)) return luaL_error(L, "mesh:check: the sum over the ranks failed");
    double wv[10];
    int got = lg_dist_worst(env, v, g, k, 10, 1, ids, wv); /* the smallest values: the lowest cells */
    if (got < 0) return lgerror(L, "mesh:check", env);
    n = (int)cnt;
  } else mesh_count_invalid(u->lm->m, 10, ids, &n);
  lua_pushinteger(L, n);
  lua_newtable(L);
  for (int i = 0; i < n && i < 10; i++) { lua_pushinteger(L, ids[i] + 1); lua_rawseti(L, -2, i + 1); }
  return 2;
}

/* argument 1 of a vertex method: a vertex number 1..nvert */
/* argument 2, a vertex of the whole mesh (1-based): its local number (1-based), or 0 when
 * it is a distributed mesh's vertex this rank does not hold */
static lua_Integer vertex_arg(lua_State *L, const lg_mesh *lm, const char *fn) {
  int isint;
  lua_Integer i = lua_tointegerx(L, 2, &isint), n = lg_mesh_global_vertices(lm);
  if (!isint) luaL_error(L, "%s: argument 1 must be a vertex number (an integer 1..%I), got %s", fn, n, luaL_typename(L, 2));
  if (i < 1 || i > n) luaL_error(L, "%s: vertex %I out of range 1..%I", fn, i, n);
  const mesh_part *P = lm->dist;
  if (!P) return i;
  for (int lo = 0, hi = P->m->nvert - 1; lo <= hi;) { /* vglobal increases */
    int mid = (lo + hi) / 2;
    if (P->vglobal[mid] == i - 1) return mid + 1;
    if (P->vglobal[mid] < i - 1) lo = mid + 1;
    else hi = mid - 1;
  }
  return 0;
}

static int mesh_coordinates(lua_State *L) {
  ud_mesh *u = check_mesh(L, 1, "mesh:coordinates");
  mesh *m = u->lm->m;
  lua_Integer i = vertex_arg(L, u->lm, "mesh:coordinates");
  if (!i) return 0; /* another rank's vertex: nothing */
  for (int d = 0; d < m->dim; d++) lua_pushnumber(L, m->x[(size_t)(i - 1) * m->dim + d]);
  return m->dim;
}

static int mesh_set_coordinates(lua_State *L) {
  ud_mesh *u = check_mesh(L, 1, "mesh:set_coordinates");
  mesh *m = u->lm->m;
  lua_Integer i = vertex_arg(L, u->lm, "mesh:set_coordinates");
  double v[3];
  for (int d = 0; d < m->dim; d++) {
    int isnum;
    v[d] = lua_tonumberx(L, 3 + d, &isnum);
    if (!isnum)
      return luaL_error(L, "mesh:set_coordinates: argument %d must be coordinate %d (a number), got %s", 2 + d, d + 1,
                        luaL_typename(L, 3 + d));
    if (!isfinite(v[d])) return luaL_error(L, "mesh:set_coordinates: argument %d is not finite (%f)", 3 + d, v[d]);
  }
  /* the geometry's count moves on every rank (a collective call), so that the ranks' caches
   * (the matrix fingerprints, the rigid body modes) stay in step */
  lg_mesh_changed(u->lm);
  if (!i) return 0; /* another rank's vertex: that rank moves it */
  for (int d = 0; d < m->dim; d++) m->x[(size_t)(i - 1) * m->dim + d] = v[d];
  return 0;
}

/* the options table {format = "binary" | "ascii" | "zlib", pieces = n} at index idx
 * (argument argno for messages), or none: a VTU_*, and n in *pieces (0 when not given) */
static int vtu_format_opt(lua_State *L, int idx, const char *fn, int argno, int *pieces) {
  *pieces = 0;
  if (lua_isnoneornil(L, idx)) return VTU_BINARY;
  if (!lua_istable(L, idx))
    return typeerror(L, fn, argno, "a table of options {format = \"binary\", \"ascii\" or \"zlib\", pieces = n}");
  static const char *const keys[] = {"format", "pieces", NULL};
  check_keys(L, idx, fn, keys);
  if (lua_getfield(L, idx, "pieces") != LUA_TNIL) {
    int isnum;
    lua_Integer n = lua_tointegerx(L, -1, &isnum);
    if (!isnum || n < 1 || n > 1000000)
      return luaL_error(L, "%s: option 'pieces' must be a whole number from 1 to 1000000, got %s", fn,
                        lua_type(L, -1) == LUA_TNUMBER ? lua_tostring(L, -1) : luaL_typename(L, -1));
    *pieces = (int)n;
  }
  lua_pop(L, 1);
  const char *f = opt_str(L, idx, "format", "binary", fn);
  if (!strcmp(f, "binary")) return VTU_BINARY;
  if (!strcmp(f, "ascii")) return VTU_ASCII;
  if (!strcmp(f, "zlib")) return VTU_ZLIB;
  return luaL_error(L, "%s: option 'format' must be \"binary\", \"ascii\" or \"zlib\", got \"%s\"", fn, f);
}

/* the fields of the table at tidx on the mesh into a .vtu (npiece 0: rank 0 writes the
 * whole mesh) or a .pvtu of npiece pieces; every buffer lives in a table on the stack until
 * the files are written (never under user-named keys in the registry) */
static int cmp_field(const void *a, const void *b) { return strcmp(((const mesh_field *)a)->name, ((const mesh_field *)b)->name); }

static int write_fields(lua_State *L, mesh *m, lg_mesh *lm, const char *path, int tidx, const char *fn, int format, int npiece) {
  int nf = 0;
  if (!lua_isnoneornil(L, tidx)) {
    if (!lua_istable(L, tidx)) return typeerror(L, fn, tidx, "a table {name = function or array}");
    lua_pushnil(L);
    while (lua_next(L, tidx)) { lua_pop(L, 1); nf++; }
  }
  mesh_field *fl = lua_newuserdatauv(L, sizeof(mesh_field) * (size_t)(nf + 1), 0);
  lua_newtable(L); /* anchors the arrays */
  int anchor = lua_gettop(L);
  nf = 0;
  if (!lua_isnoneornil(L, tidx)) {
    lua_pushnil(L);
    while (lua_next(L, tidx)) {
      if (lua_type(L, -2) != LUA_TSTRING) return luaL_error(L, "%s: field names must be strings, got %s", fn, luaL_typename(L, -2));
      const char *name = check_cstring(L, -2, fn, "field name");
      ud_func *uf = luaL_testudata(L, -1, MT_FUNC);
      ud_qarray *qa = luaL_testudata(L, -1, MT_QARRAY);
      if (qa) {
        if (qa->nglobal != lg_mesh_global_cells(lm) || (qa->gid != NULL) != (lm->dist != NULL))
          return luaL_error(L, "%s: quality array '%s' belongs to a mesh of %I cells", fn, name, (lua_Integer)qa->nglobal);
        if (qa->gid) { /* the owned cells' values on the local cells (ghosts are not written) */
          double *v = lua_newuserdatauv(L, sizeof(double) * ((size_t)m->ncell + 1), 0);
          lua_rawseti(L, anchor, nf + 1);
          for (int c = 0; c < m->ncell; c++) v[c] = NAN;
          for (int i = 0; i < qa->n; i++) v[qa->loc[i]] = qa->v[i];
          fl[nf] = (mesh_field){name, 1, 1, v};
        } else fl[nf] = (mesh_field){name, 1, 1, qa->v};
      } else if (uf) {
        if (uf->f->mesh != lm) return luaL_error(L, "%s: field '%s' lives on a different mesh", fn, name);
        /* vertex dofs come first in every Lagrange numbering; P0 dofs are the cells' */
        const dofmap *dm = uf->f->dm;
        int bs = dm->bs, oncells = dm->degree == 0;
        if (dm->disc && !oncells) {
          /* a discontinuous field has a value per cell at each vertex: their mean (what
           * ParaView can show as point data) */
          double *v = lua_newuserdatauv(L, sizeof(double) * 3 * (size_t)m->nvert + 1, 0);
          lua_rawseti(L, anchor, nf + 1);
          int *cnt = calloc((size_t)m->nvert + 1, sizeof(int));
          if (!cnt) return luaL_error(L, "%s: out of memory", fn);
          memset(v, 0, sizeof(double) * 3 * (size_t)m->nvert);
          for (int c = 0; c < m->ncell; c++)
            for (int k = 0; k < dm->el.nloc; k++) {
              if (dm->el.ent_dim[k] != 0) continue;
              int vx = m->cells[(size_t)c * m->nvc + dm->el.ent_id[k]];
              for (int j = 0; j < bs; j++) v[3 * (size_t)vx + j] += uf->f->x[dm->cell_dofs[(size_t)c * dm->nloc + k * bs + j]];
              cnt[vx]++;
            }
          for (int i = 0; i < m->nvert; i++)
            for (int j = 0; j < 3; j++) v[3 * (size_t)i + j] = cnt[i] ? v[3 * (size_t)i + j] / cnt[i] : 0;
          free(cnt);
          if (bs == 1)
            for (int i = 0; i < m->nvert; i++) v[i] = v[3 * (size_t)i];
          fl[nf] = (mesh_field){name, bs == 1 ? 1 : 3, 0, v};
        } else if (bs == 1) fl[nf] = (mesh_field){name, 1, oncells, uf->f->x};
        else {
          /* a vector: three components per point as ParaView expects (z = 0 in 2D) */
          size_t n = oncells ? (size_t)m->ncell : (size_t)m->nvert;
          double *v = lua_newuserdatauv(L, sizeof(double) * 3 * n + 1, 0);
          lua_rawseti(L, anchor, nf + 1);
          for (size_t i = 0; i < n; i++)
            for (int j = 0; j < 3; j++) v[3 * i + j] = j < bs ? uf->f->x[(size_t)bs * i + (size_t)j] : 0;
          fl[nf] = (mesh_field){name, 3, oncells, v};
        }
      } else if (lua_istable(L, -1)) {
        /* one value per cell or vertex of the whole mesh (a distributed one's: each rank
         * takes its local cells' or vertices' by their global numbers) */
        lua_Integer n = luaL_len(L, -1);
        long NC = lg_mesh_global_cells(lm), NV = lg_mesh_global_vertices(lm);
        if (n != NC && n != NV)
          return luaL_error(L, "%s: array '%s' has %I entries; need one per cell (%I) or vertex (%I)", fn, name, n, (lua_Integer)NC,
                            (lua_Integer)NV);
        int oncells = n == NC && n != NV;
        const int *glob = lm->dist ? (oncells ? lm->dist->cglobal : lm->dist->vglobal) : NULL;
        lua_Integer nl = glob ? (oncells ? m->ncell : m->nvert) : n;
        double *v = lua_newuserdatauv(L, sizeof(double) * (size_t)(nl + 1), 0);
        lua_rawseti(L, anchor, nf + 1);
        for (lua_Integer i = 1; i <= nl; i++) {
          lua_Integer at = glob ? glob[i - 1] + 1 : i;
          lua_geti(L, -1, at);
          int isnum;
          v[i - 1] = lua_tonumberx(L, -1, &isnum);
          if (!isnum) return luaL_error(L, "%s: array '%s' entry %I must be a number, got %s", fn, name, at, luaL_typename(L, -1));
          lua_pop(L, 1);
        }
        fl[nf] = (mesh_field){name, 1, oncells, v};
      } else return luaL_error(L, "%s: field '%s' must be a discrete function, a quality array or an array of numbers, got %s",
                               fn, name, luaL_typename(L, -1));
      nf++;
      lua_pop(L, 1);
    }
  }
  char err[MESH_ERRLEN] = "";
  /* by name: a table's iteration order differs between processes (Lua seeds its string
   * hashes per state), and a distributed mesh's ranks gather the fields in turn */
  qsort(fl, (size_t)nf, sizeof *fl, cmp_field);
  int rc = lg_write_vtu(get_env(L), lm, path, nf, fl, format, npiece, err);
  lua_pop(L, 2);
  if (rc) return luaL_error(L, "%s: %s", fn, err);
  return 0;
}

/* an SVG picture of a 2D mesh coloured by one per-cell field {name = P0 function, quality
 * array or array of one number per cell}, over the field's range */
static int write_svg(lua_State *L, mesh *m, lg_mesh *lm, const char *path, const char *fn) {
  if (m->dim != 2) return luaL_error(L, "%s: an SVG picture is of a 2D mesh, this one is %dD", fn, m->dim);
  if (!lua_istable(L, 3)) return typeerror(L, fn, 3, "a table {name = one value per cell} for an SVG picture");
  lua_pushnil(L);
  if (!lua_next(L, 3)) return luaL_error(L, "%s: an SVG picture needs one per-cell field", fn);
  if (lua_type(L, -2) != LUA_TSTRING) return luaL_error(L, "%s: field names must be strings", fn);
  const char *name = check_cstring(L, -2, fn, "field name");
  int vidx = lua_gettop(L);
  lua_pushvalue(L, -2);
  if (lua_next(L, 3)) return luaL_error(L, "%s: an SVG picture shows one field, the table has more", fn);
  const double *v = NULL;
  double *own = NULL;
  ud_func *uf = luaL_testudata(L, vidx, MT_FUNC);
  ud_qarray *qa = luaL_testudata(L, vidx, MT_QARRAY);
  if (uf) {
    if (uf->f->mesh != lm) return luaL_error(L, "%s: field '%s' lives on a different mesh", fn, name);
    if (uf->f->dm->degree != 0)
      return luaL_error(L, "%s: an SVG picture colours cells: field '%s' must be piecewise constant (P0), or write a .vtu", fn, name);
    v = uf->f->x;
  } else if (qa && lm->dist) { /* the owned cells' values at their local places */
    if (!qa->loc || qa->nglobal != lm->dist->ncell_global)
      return luaL_error(L, "%s: quality array '%s' belongs to another mesh", fn, name);
    own = lua_newuserdatauv(L, sizeof(double) * ((size_t)m->ncell + 1), 0);
    for (int i = 0; i < m->ncell; i++) own[i] = NAN;
    for (int i = 0; i < qa->n; i++) own[qa->loc[i]] = qa->v[i];
    v = own;
  } else if (qa) {
    if (qa->n != m->ncell) return luaL_error(L, "%s: quality array '%s' belongs to a mesh of %d cells", fn, name, qa->n);
    v = qa->v;
  } else if (lua_istable(L, vidx) && luaL_len(L, vidx) == lg_mesh_global_cells(lm)) {
    /* one value per cell of the whole mesh: a distributed mesh's local cells by their global numbers */
    own = lua_newuserdatauv(L, sizeof(double) * ((size_t)m->ncell + 1), 0);
    for (int i = 0; i < m->ncell; i++) {
      int at = (lm->dist ? lm->dist->cglobal[i] : i) + 1;
      lua_geti(L, vidx, at);
      int isnum;
      own[i] = lua_tonumberx(L, -1, &isnum);
      if (!isnum) return luaL_error(L, "%s: array '%s' entry %d must be a number", fn, name, at);
      lua_pop(L, 1);
    }
    v = own;
  } else return luaL_error(L, "%s: field '%s' must be a P0 function, a quality array or %I numbers (one per cell)", fn, name,
                           (lua_Integer)lg_mesh_global_cells(lm));
  char err[MESH_ERRLEN] = "";
  mesh *W = NULL; /* a distributed mesh's whole, with the values, on rank 0 */
  double **vals = NULL;
  int rc = 0;
  if (lm->dist) {
    mesh_field f = {name, 1, 1, v};
    lg_env *env = get_env(L);
    if ((rc = lg_dist_gather(env, lm->dist, 1, &f, &W, &vals))) snprintf(err, sizeof err, "%.*s", (int)sizeof err - 1, env->err);
    else if (W) {
      m = W;
      v = vals[0];
    }
  }
  if (!rc && lg_mpi_rank() == 0) {
    double lo = INFINITY, hi = -INFINITY;
    for (int i = 0; i < m->ncell; i++)
      if (isfinite(v[i])) { lo = fmin(lo, v[i]); hi = fmax(hi, v[i]); }
    if (!(lo <= hi)) lo = 0, hi = 1;
    rc = mesh_write_svg(m, path, v, lo, hi, name, err);
  }
  if (vals) free(vals[0]);
  free(vals);
  mesh_free(W);
  if (lg_root_result(rc, err, sizeof err)) return luaL_error(L, "%s: %s", fn, err);
  return 0;
}

static int mesh_write(lua_State *L) {
  const char *fn = "mesh:write";
  ud_mesh *u = check_mesh(L, 1, fn);
  const char *path = check_cstring(L, 2, fn, "argument 1 (the path)");
  size_t l = strlen(path);
  if (l > 4 && !strcmp(path + l - 4, ".msh") && u->lm->dist) { /* gathered and written by rank 0 */
    lg_env *env = get_env(L);
    mesh *W = NULL;
    char err[MESH_ERRLEN];
    int rc = lg_dist_gather_mesh(env, u->lm->dist, &W);
    if (rc) snprintf(err, sizeof err, "%.*s", (int)sizeof err - 1, env->err);
    else if (lg_mpi_rank() == 0 && (rc = mesh_write_gmsh(W, path))) snprintf(err, sizeof err, "%s", W->err);
    mesh_free(W);
    if (lg_root_result(rc, err, sizeof err)) return luaL_error(L, "%s: %s", fn, err);
    return 0;
  }
  if (l > 4 && !strcmp(path + l - 4, ".msh")) {
    int rc = lg_mpi_rank() == 0 ? mesh_write_gmsh(u->lm->m, path) : 0;
    if (lg_root_result(rc, u->lm->m->err, sizeof u->lm->m->err)) return luaL_error(L, "%s: %s", fn, u->lm->m->err);
    return 0;
  }
  if (l > 4 && !strcmp(path + l - 4, ".svg")) return write_svg(L, u->lm->m, u->lm, path, fn);
  int pvtu = l > 5 && !strcmp(path + l - 5, ".pvtu");
  if (!pvtu && !(l > 4 && !strcmp(path + l - 4, ".vtu")))
    return luaL_error(L, "%s: argument 1 must end in .vtu or .pvtu (ParaView), .msh (Gmsh) or .svg (a 2D picture), got \"%s\"",
                      fn, path);
  int pieces, format = vtu_format_opt(L, 4, fn, 3, &pieces);
  if (pieces && !pvtu) return luaL_error(L, "%s: option 'pieces' is for a .pvtu, got \"%s\"", fn, path);
  lua_settop(L, 3);
  write_fields(L, u->lm->m, u->lm, path, 3, fn, format, pvtu ? (pieces ? pieces : lg_mpi_size()) : 0);
  return 0;
}

static int mesh_tostring(lua_State *L) {
  ud_mesh *u = check_mesh(L, 1, "tostring");
  mesh *m = u->lm->m;
  lua_pushfstring(L, "mesh: %d %s, %d vertices, %dD", m->ncell, cell_plural(m->type), m->nvert, m->dim);
  return 1;
}

/* {metric = {{a, b}, {b, c}}} (constant) or {metric = {M_1, ..., M_nvert}} (per vertex; on
 * a distributed mesh P the whole mesh's vertices, each rank reading its local ones' by their
 * global numbers) */
static int read_metric(lua_State *L, int t, mesh *m, const mesh_part *P, double **buf, quality_metric *qm, const char *fn) {
  int d = m->dim, nv = P ? P->nvert_global : m->nvert;
  qm->kind = 0;
  qm->m = NULL;
  *buf = NULL;
  if (lua_getfield(L, t, "metric") == LUA_TNIL) { lua_pop(L, 1); return 0; }
  if (!lua_istable(L, -1)) return luaL_error(L, "%s: option 'metric' must be a %dx%d table or one per vertex", fn, d, d);
  int n = (int)luaL_len(L, -1);
  lua_geti(L, -1, 1);
  int nested = lua_istable(L, -1), pervertex = 0;
  if (nested) {
    lua_geti(L, -1, 1);
    pervertex = lua_istable(L, -1);
    lua_pop(L, 1);
  }
  lua_pop(L, 1);
  if (!nested) return luaL_error(L, "%s: option 'metric' must be a %dx%d table or a list of %d of them (one per vertex)", fn, d, d, nv);
  int count = pervertex ? m->nvert : 1;
  if ((pervertex && n != nv) || (!pervertex && n != d))
    return luaL_error(L, "%s: option 'metric' must be a %dx%d table or a list of %d of them (one per vertex)", fn, d, d, nv);
  double *b = lua_newuserdatauv(L, sizeof(double) * (size_t)count * d * d, 0);
  lua_insert(L, -2); /* keep the buffer below the table while reading */
  for (int v = 0; v < count; v++) {
    if (pervertex) lua_geti(L, -1, (P ? P->vglobal[v] : v) + 1);
    for (int i = 0; i < d; i++) {
      if (lua_geti(L, -1, i + 1) != LUA_TTABLE || luaL_len(L, -1) != d)
        return luaL_error(L, "%s: metric row %d must have %d numbers", fn, i + 1, d);
      for (int j = 0; j < d; j++) {
        lua_geti(L, -1, j + 1);
        if (!lua_isnumber(L, -1)) return luaL_error(L, "%s: metric entries must be numbers", fn);
        b[(size_t)v * d * d + (size_t)i * d + j] = lua_tonumber(L, -1);
        lua_pop(L, 1);
      }
      lua_pop(L, 1);
    }
    if (pervertex) lua_pop(L, 1);
  }
  lua_pop(L, 1); /* the metric table; the buffer stays on the stack */
  qm->kind = pervertex ? 2 : 1;
  qm->m = b;
  *buf = b;
  return 1;
}

/* two distributed meshes' parts hold the same cells with the same vertices on every rank */
static int same_parts(lua_State *L, const lg_mesh *a, const lg_mesh *b) {
  const mesh *p = a->m, *q = b->m;
  double bad = p->type != q->type || p->nvert != q->nvert || p->ncell != q->ncell ||
               memcmp(p->cells, q->cells, sizeof(int) * (size_t)p->ncell * (size_t)p->nvc) ||
               memcmp(a->dist->vglobal, b->dist->vglobal, sizeof(int) * (size_t)p->nvert) ||
               memcmp(a->dist->cglobal, b->dist->cglobal, sizeof(int) * (size_t)p->ncell);
  if (lg_allreduce(&bad, 1, LG_MAX)) luaL_error(L, "mesh:quality: comparing the reference's parts failed");
  return bad == 0;
}

static ud_qarray *push_quality(lua_State *L, int midx, const char *name, int tidx, const char *fn) {
  ud_mesh *um = check_mesh(L, midx, fn);
  mesh *m = um->lm->m;
  int q = quality_from_name(name);
  if (q < 0) {
    char list[1024];
    quality_names(list, sizeof list);
    luaL_error(L, "%s: unknown measure \"%s\" (measures: %s)", fn, name, list);
  }
  quality_metric qm = {0, NULL};
  double *buf = NULL;
  int pushed = 0;
  const mesh *ref = NULL;
  double pexp = 2;
  if (tidx && !lua_isnoneornil(L, tidx)) {
    if (!lua_istable(L, tidx)) typeerror(L, fn, tidx, "a table of options {metric=, reference=, p=}");
    static const char *const keys[] = {"metric", "reference", "p", NULL};
    check_keys(L, tidx, fn, keys);
    lg_mesh *refl = opt_reference(L, tidx, um->lm, fn);
    ref = refl ? refl->m : NULL;
    if (refl && um->lm->dist && !same_parts(L, um->lm, refl))
      luaL_error(L, "%s: the reference must be distributed as the mesh is (a copy made before the motion, or the same "
                    "file read with the same partitioner)", fn);
    pexp = opt_num(L, tidx, "p", 2, fn);
    pushed = read_metric(L, tidx, m, um->lm->dist, &buf, &qm, fn);
  }
  if (quality_is_deformation(q) && !ref)
    luaL_error(L, "%s: %s compares two configurations: pass {reference = mesh}", fn, name);
  if (!quality_is_deformation(q) && ref) luaL_error(L, "%s: option 'reference' is for the deformation measures", fn);
  ud_qarray *a = lua_newuserdatauv(L, sizeof(ud_qarray), 0);
  a->n = 0;
  a->measure = q;
  a->v = NULL;
  a->gid = a->loc = NULL;
  a->nglobal = m->ncell;
  luaL_setmetatable(L, MT_QARRAY);
  a->v = mesh_big_alloc(sizeof(double) * (size_t)(m->ncell + 1));
  if (!a->v) luaL_error(L, "%s: out of memory for %d values", fn, m->ncell);
  a->n = m->ncell;
  char err[MESH_ERRLEN];
  int rc = ref ? mesh_deformation(m, ref->x, q, pexp, a->v, err) : mesh_quality(m, q, qm.kind ? &qm : NULL, a->v, err);
  if (rc) luaL_error(L, "%s: %s", fn, err);
  const mesh_part *P = um->lm->dist;
  if (P) { /* the owned cells' values, in the local (global) order */
    a->gid = malloc(sizeof(int) * ((size_t)P->nown_cell + 1));
    a->loc = malloc(sizeof(int) * ((size_t)P->nown_cell + 1));
    if (!a->gid || !a->loc) luaL_error(L, "%s: out of memory", fn);
    int k = 0, rank = lg_mpi_rank();
    for (int c = 0; c < m->ncell; c++)
      if (P->cowner[c] == rank) {
        a->v[k] = a->v[c];
        a->loc[k] = c;
        a->gid[k++] = P->cglobal[c];
      }
    a->n = k;
    a->nglobal = P->ncell_global;
  }
  if (pushed) lua_remove(L, -2); /* the metric buffer */
  return a;
}

static int mesh_quality_l(lua_State *L) {
  push_quality(L, 1, check_cstring(L, 2, "mesh:quality", "argument 1 (the measure)"), 3, "mesh:quality");
  return 1;
}

static ud_qarray *check_qarray(lua_State *L, int i) { return luaL_checkudata(L, i, MT_QARRAY); }

static int qa_index(lua_State *L) {
  ud_qarray *a = check_qarray(L, 1);
  if (lua_type(L, 2) == LUA_TSTRING) {
    luaL_getmetatable(L, MT_QARRAY);
    lua_getfield(L, -1, "methods");
    lua_getfield(L, -1, lua_tostring(L, 2));
    if (!lua_isnil(L, -1)) return 1;
    return luaL_error(L, "quality arrays have no field '%s'", lua_tostring(L, 2));
  }
  lua_Integer i = luaL_checkinteger(L, 2);
  if (a->gid) return luaL_error(L, "q[i]: a distributed mesh's quality array holds each rank's cells: q:totable() gathers them all");
  if (i < 1 || i > a->n) return luaL_error(L, "quality index %I out of range 1..%d", i, a->n);
  lua_pushnumber(L, a->v[i - 1]);
  return 1;
}

static int qa_len(lua_State *L) { lua_pushinteger(L, check_qarray(L, 1)->nglobal); return 1; }

/* the statistics of the whole mesh's values (a distributed one's reduced over the ranks;
 * argmin and argmax are global cells) */
static void qa_stats(lua_State *L, ud_qarray *a, quality_stats *st, const char *fn) {
  if (!a->gid) { quality_stats_compute(a->v, a->n, st); return; }
  lg_env *env = get_env(L);
  if (lg_dist_stats(env, a->v, a->gid, a->n, st)) lgerror(L, fn, env);
}

static int qa_gc(lua_State *L) {
  ud_qarray *a = lua_touserdata(L, 1);
  mesh_big_free(a->v);
  free(a->gid);
  free(a->loc);
  a->gid = a->loc = NULL;
  a->v = NULL;
  a->n = 0;
  return 0;
}

static int qa_totable(lua_State *L) {
  ud_qarray *a = check_qarray(L, 1);
  if (a->gid) { /* every rank's cells, in the global order */
    double *all = lua_newuserdatauv(L, sizeof(double) * ((size_t)a->nglobal + 1), 0);
    lg_env *env = get_env(L);
    if (lg_dist_cell_values(env, a->v, a->gid, a->n, a->nglobal, all)) return lgerror(L, "q:totable", env);
    lua_createtable(L, (int)a->nglobal, 0);
    for (long i = 0; i < a->nglobal; i++) { lua_pushnumber(L, all[i]); lua_rawseti(L, -2, i + 1); }
    return 1;
  }
  lua_createtable(L, a->n, 0);
  for (int i = 0; i < a->n; i++) { lua_pushnumber(L, a->v[i]); lua_rawseti(L, -2, i + 1); }
  return 1;
}

static int qa_stat(lua_State *L, int which) {
  ud_qarray *a = check_qarray(L, 1);
  quality_stats st;
  qa_stats(L, a, &st, which == 0 ? "q:min" : which == 1 ? "q:max" : "q:mean");
  lua_pushnumber(L, which == 0 ? st.min : which == 1 ? st.max : st.mean);
  if (which == 2) return 1;
  lua_pushinteger(L, (which == 0 ? st.argmin : st.argmax) + 1);
  return 2;
}

static int qa_min(lua_State *L) { return qa_stat(L, 0); }

static int qa_max(lua_State *L) { return qa_stat(L, 1); }

static int qa_mean(lua_State *L) { return qa_stat(L, 2); }

static int qa_histogram(lua_State *L) {
  ud_qarray *a = check_qarray(L, 1);
  int nb = lua_isnoneornil(L, 2) ? 10 : check_int_arg(L, 2, 1, 10000, "q:histogram");
  quality_stats st;
  qa_stats(L, a, &st, "q:histogram");
  double lo = luaL_optnumber(L, 3, st.min), hi = luaL_optnumber(L, 4, st.max);
  if (!isfinite(lo) || !isfinite(hi) || !(lo <= hi))
    return luaL_error(L, "q:histogram: the range [lo, hi] must be finite with lo <= hi, got [%f, %f]%s", lo, hi,
                      lua_isnoneornil(L, 3) ? " (the values are not all finite: pass lo and hi)" : "");
  int *c = lua_newuserdatauv(L, sizeof(int) * (size_t)nb, 0);
  quality_histogram(a->v, a->n, (int)nb, lo, hi, c);
  if (a->gid) { /* each rank counted its cells */
    double *d = lua_newuserdatauv(L, sizeof(double) * (size_t)nb, 0);
    for (int i = 0; i < nb; i++) d[i] = c[i];
    if (lg_allreduce(d, nb, LG_SUM)) return luaL_error(L, "q:histogram: the sum over the ranks failed");
    for (int i = 0; i < nb; i++) c[i] = (int)d[i];
    lua_pop(L, 1);
  }
  lua_createtable(L, 0, 3);
  lua_createtable(L, (int)nb, 0);
  for (int i = 0; i < nb; i++) { lua_pushinteger(L, c[i]); lua_rawseti(L, -2, i + 1); }
  lua_setfield(L, -2, "counts");
  lua_pushnumber(L, lo); lua_setfield(L, -2, "lo");
  lua_pushnumber(L, hi); lua_setfield(L, -2, "hi");
  return 1;
}

static int qa_worst(lua_State *L) {
  ud_qarray *a = check_qarray(L, 1);
  lua_Integer k = lua_isnoneornil(L, 2) ? 10 : check_int_arg(L, 2, 1, INT_MAX, "q:worst");
  if (a->gid) { /* the whole mesh's worst, from each rank's */
    if (k > a->nglobal) k = a->nglobal;
    int *gids = lua_newuserdatauv(L, sizeof(int) * (size_t)(k + 1), 0);
    double *vals = lua_newuserdatauv(L, sizeof(double) * (size_t)(k + 1), 0);
    lg_env *env = get_env(L);
    int got = lg_dist_worst(env, a->v, a->gid, a->n, (int)k, quality_larger_is_better(a->measure), gids, vals);
    if (got < 0) return lgerror(L, "q:worst", env);
    lua_createtable(L, got, 0);
    for (int i = 0; i < got; i++) {
      lua_createtable(L, 0, 2);
      lua_pushinteger(L, gids[i] + 1); lua_setfield(L, -2, "cell");
      lua_pushnumber(L, vals[i]); lua_setfield(L, -2, "value");
      lua_rawseti(L, -2, i + 1);
    }
    return 1;
  }
  if (k > a->n) k = a->n;
  int *ids = lua_newuserdatauv(L, sizeof(int) * (size_t)(k + 1), 0);
  quality_worst(a->v, a->n, (int)k, quality_larger_is_better(a->measure), ids);
  lua_createtable(L, (int)k, 0);
  for (int i = 0; i < k; i++) {
    lua_createtable(L, 0, 2);
    lua_pushinteger(L, ids[i] + 1); lua_setfield(L, -2, "cell");
    lua_pushnumber(L, a->v[ids[i]]); lua_setfield(L, -2, "value");
    lua_rawseti(L, -2, i + 1);
  }
  return 1;
}

static int qa_tostring(lua_State *L) {
  ud_qarray *a = check_qarray(L, 1);
  quality_stats st;
  quality_stats_compute(a->v, a->n, &st);
  /* not collective (print calls it on rank 0 only): a distributed array shows its rank's cells */
  if (a->gid) lua_pushfstring(L, "%s of this rank's %d of %I cells: min %f, max %f, mean %f", quality_name(a->measure), a->n,
                              (lua_Integer)a->nglobal, st.min, st.max, st.mean);
  else lua_pushfstring(L, "%s of %d cells: min %f, max %f, mean %f", quality_name(a->measure), a->n, st.min, st.max, st.mean);
  return 1;
}

/* every measure that applies, with statistics, as a table; printed unless quiet */
static int mesh_quality_report(lua_State *L) {
  const char *fn = "mesh:quality_report";
  ud_mesh *um = check_mesh(L, 1, fn);
  mesh *m = um->lm->m;
  const mesh_part *P = um->lm->dist; /* a distributed mesh: each rank its owned cells, reduced */
  int rank = lg_mpi_rank();
  int quiet = lua_toboolean(L, 2) || rank != 0; /* every rank has the same report */
  /* split the invalid cells: inverted (clearly negative) and degenerate (about zero),
   * relative to each cell's size; the quadrilaterals' Remark 1.1 classes */
  double cnt[6] = {0, 0, 0, 0, 0, 0}; /* inverted, degenerate, then the four classes */
  for (int c = 0; c < m->ncell; c++) {
    if (P && P->cowner[c] != rank) continue;
    double q = mesh_cell_relative_validity(m, c);
    if (q < -1e-13) cnt[0]++;
    else if (!(q > 1e-13)) cnt[1]++;
    if (m->type == CELL_QUADRILATERAL) {
      double x[8];
      for (int i = 0; i < 4; i++) { x[2 * i] = m->x[2 * m->cells[4 * c + i]]; x[2 * i + 1] = m->x[2 * m->cells[4 * c + i] + 1]; }
      quad_class k;
      quad_corner_area(x, &k);
      cnt[2 + k]++;
    }
  }
  if (P && lg_allreduce(cnt, 6, LG_SUM)) return luaL_error(L, "%s: the sum over the ranks failed", fn);
  long ncell = lg_mesh_global_cells(um->lm);
  int ninverted = (int)cnt[0], ndegenerate = (int)cnt[1];
  lua_createtable(L, 0, QM_COUNT + 4);
  int rep = lua_gettop(L);
  lua_pushinteger(L, ncell); lua_setfield(L, rep, "cells");
  lua_pushinteger(L, ninverted); lua_setfield(L, rep, "inverted");
  lua_pushinteger(L, ndegenerate); lua_setfield(L, rep, "degenerate");
  if (m->type == CELL_QUADRILATERAL) {
    int cls[4] = {(int)cnt[2 + QUAD_CONVEX], (int)cnt[2 + QUAD_NONCONVEX], (int)cnt[2 + QUAD_DEGENERATE], (int)cnt[2 + QUAD_CROSSED]};
    lua_createtable(L, 0, 4);
    lua_pushinteger(L, cls[0]); lua_setfield(L, -2, "convex");
    lua_pushinteger(L, cls[1]); lua_setfield(L, -2, "nonconvex");
    lua_pushinteger(L, cls[2]); lua_setfield(L, -2, "degenerate");
    lua_pushinteger(L, cls[3]); lua_setfield(L, -2, "crossed");
    lua_setfield(L, rep, "quadrilaterals");
    if (!quiet) printf("quadrilaterals: %d convex, %d non-convex, %d degenerate, %d crossed\n", cls[0], cls[1], cls[2], cls[3]);
  }
  if (!quiet) printf("mesh quality: %ld %s, %d inverted, %d degenerate\n  %-28s %12s %12s %12s %8s\n", ncell,
                     cell_plural(m->type), ninverted, ndegenerate, "measure", "min", "mean", "max", "worst");
  for (int q = 0; q < QM_COUNT; q++) {
    if (!quality_applies(q, m->type) || quality_is_deformation(q)) continue;
    ud_qarray *a = push_quality(L, 1, quality_name(q), 0, fn);
    quality_stats st;
    qa_stats(L, a, &st, fn);
    int wi = -1;
    if (a->gid) { /* the whole mesh's worst cell, as quality_worst_index picks it */
      double wv;
      lg_env *env = get_env(L);
      if (lg_dist_worst(env, a->v, a->gid, a->n, 1, quality_larger_is_better(q), &wi, &wv) < 0) return lgerror(L, fn, env);
    } else wi = quality_worst_index(a->v, a->n, quality_larger_is_better(q));
    lua_pop(L, 1);
    lua_createtable(L, 0, 4);
    lua_pushnumber(L, st.min); lua_setfield(L, -2, "min");
    lua_pushnumber(L, st.max); lua_setfield(L, -2, "max");
    lua_pushnumber(L, st.mean); lua_setfield(L, -2, "mean");
    lua_pushinteger(L, wi + 1); lua_setfield(L, -2, "worst");
    lua_setfield(L, rep, quality_name(q));
    if (!quiet) printf("  %-28s %12.6g %12.6g %12.6g %8d\n", quality_name(q), st.min, st.mean, st.max, wi + 1);
  }
  if (!quiet) fflush(stdout);
  lua_settop(L, rep);
  return 1;
}

/* ---------------------------------------------------------------- series */

static int l_series(lua_State *L) {
  const char *path = check_cstring(L, 1, "lg.series", "argument 1 (the path)");
  size_t l = strlen(path);
  if (l < 5 || strcmp(path + l - 4, ".pvd")) return luaL_error(L, "lg.series: argument 1 must be a path ending in .pvd, got \"%s\"", path);

  int pieces, format = vtu_format_opt(L, 2, "lg.series", 2, &pieces);
  ud_series *u = new_ud(L, sizeof *u, MT_SERIES, 0, NULL);
  if (!(u->path = strdup(path))) return luaL_error(L, "lg.series: out of memory");
  u->format = format;
  /* under mpiexec each step is a .pvtu of a piece per rank */
  u->pieces = pieces ? pieces : lg_mpi_size() > 1 ? lg_mpi_size() : 0;
  return 1;
}

static int series_write(lua_State *L) {
  const char *fn = "series:write";
  ud_series *u = luaL_checkudata(L, 1, MT_SERIES);
  ud_mesh *um = check_mesh(L, 2, fn);
  double t = luaL_optnumber(L, 4, u->n);
  if (!isfinite(t)) return luaL_error(L, "%s: argument 3 (the time) must be a finite number, got %f", fn, t);
  if (u->n == u->cap) {
    int cap = u->cap ? 2 * u->cap : 16;
    double *nt = realloc(u->t, sizeof(double) * (size_t)cap);
    if (!nt) return luaL_error(L, "%s: out of memory", fn);
    u->t = nt;
    char **nf = realloc(u->files, sizeof(char *) * (size_t)cap);
    if (!nf) return luaL_error(L, "%s: out of memory", fn);
    u->files = nf;
    u->cap = cap;
  }
  /* the step's file: the .pvd's path without ".pvd", "_NNNN.vtu" (held on the stack) */
  char suffix[32];
  snprintf(suffix, sizeof suffix, "_%04d.%s", u->n, u->pieces ? "pvtu" : "vtu");
  lua_pushlstring(L, u->path, strlen(u->path) - 4);
  lua_pushstring(L, suffix);
  lua_concat(L, 2);
  const char *file = lua_tostring(L, -1);
  write_fields(L, um->lm->m, um->lm, file, 3, fn, u->format, u->pieces);
  u->files[u->n] = strdup(file);
  u->t[u->n] = t;
  if (!u->files[u->n]) return luaL_error(L, "%s: out of memory", fn);
  u->n++;
  char err[MESH_ERRLEN] = "";
  int rc = lg_mpi_rank() == 0 ? mesh_write_pvd(u->path, u->n, u->t, u->files, err) : 0;
  if (lg_root_result(rc, err, sizeof err)) return luaL_error(L, "%s: %s", fn, err);
  lua_pushstring(L, file);
  return 1;
}

static int series_gc(lua_State *L) {
  ud_series *u = lua_touserdata(L, 1);
  for (int i = 0; i < u->n; i++) free(u->files[i]);
  free(u->files);
  free(u->t);
  free(u->path);
  u->files = NULL;
  u->t = NULL;
  u->path = NULL;
  u->n = 0;
  return 0;
}

/* ---------------------------------------------------------------- registration */

void lg_lua_mesh_register(lua_State *L) {
  static const luaL_Reg mesh_mm[] = {{"__gc", mesh_gc}, {"__tostring", mesh_tostring}, {NULL, NULL}};
  static const luaL_Reg mesh_methods[] = {{"cells", mesh_cells}, {"boundary", mesh_boundary}, {"interior_facets", mesh_interior_facets}, {"vertices", mesh_vertices}, {"info", mesh_info},
                                          {"write", mesh_write}, {"refine", lmesh_refine}, {"copy", lmesh_copy}, {"hmax", lmesh_hmax},
                                          {"check", mesh_check}, {"nvertices", mesh_nvertices}, {"ncells", mesh_ncells},
                                          {"dim", mesh_dim}, {"coordinates", mesh_coordinates},
                                          {"set_coordinates", mesh_set_coordinates}, {"quality", mesh_quality_l},
                                          {"quality_report", mesh_quality_report}, {"untangle", lmesh_untangle}, {"smooth", lmesh_smooth},
                                          {"move", lmesh_move}, {"displace", lmesh_displace}, {NULL, NULL}};
  new_mt(L, MT_MESH, mesh_mm, mesh_methods);
  new_mt(L, MT_REGION, NULL, NULL);
  static const luaL_Reg qa_mm[] = {{"__index", qa_index}, {"__len", qa_len}, {"__tostring", qa_tostring},
                                   {"__gc", qa_gc}, {NULL, NULL}};
  static const luaL_Reg qa_methods[] = {{"totable", qa_totable}, {"min", qa_min}, {"max", qa_max}, {"mean", qa_mean},
                                        {"histogram", qa_histogram}, {"worst", qa_worst}, {NULL, NULL}};
  luaL_newmetatable(L, MT_QARRAY);
  luaL_setfuncs(L, qa_mm, 0);
  lua_newtable(L);
  set_funcs_checked(L, qa_methods, MT_QARRAY);
  lua_setfield(L, -2, "methods");
  lua_pop(L, 1);
  static const luaL_Reg series_mm[] = {{"__gc", series_gc}, {NULL, NULL}};
  static const luaL_Reg series_methods[] = {{"write", series_write}, {NULL, NULL}};
  new_mt(L, MT_SERIES, series_mm, series_methods);
}

const luaL_Reg lg_output_lib[] = {{"series", l_series}, {NULL, NULL}};

const luaL_Reg lg_mesh_lib[] = {{"interval", l_interval}, {"rectangle", l_rectangle}, {"box", l_box}, {"read", l_read},
                                {"new", l_mesh_new}, {NULL, NULL}};
