/* test_mesh.c — generators (counts, areas, boundary tags), Gmsh 2.2 and 4.1 reading of the
 * same mesh, uniform refinement (counts, measure, orientation), the validity check, and
 * the Gmsh writer round trip, folders and pipes as input, escaped names, and writes that
 * fail (with the reason, leaving the old file), packing into bytes and back. argv[1] is
 * tests/data. */
#include "../../src/mesh/io/io.h"
#include "../../src/mesh/untangle/untangle.h"
#include "check.h"

#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>
#include <unistd.h>

static double total(const mesh *m) {
  double s = 0;
  for (int c = 0; c < m->ncell; c++) s += mesh_cell_signed_measure(m, c);
  return s;
}

/* the first tag of a name, -1 when unknown */
static int btag(const mesh *m, const char *n) { int t; return mesh_boundary_tags(m, n, &t, 1) ? t : -1; }
static int rtag(const mesh *m, const char *n) { int t; return mesh_region_tags(m, n, &t, 1) ? t : -1; }

/* a mesh packed into bytes (pack.c) and unpacked is the same mesh: coordinates, cells,
 * tags, boundary facets and names; every cut of the buffer and a bad header are refused
 * with a reason */
static void pack(const char *data) {
  char err[MESH_ERRLEN], path[600];
  snprintf(path, sizeof path, "%s/square_unstructured.msh", data);
  mesh *m = mesh_read_gmsh(path, err);
  CHECK(m != NULL, "%s", err);
  CHECK(mesh_set_region_name(m, 7, "a region") == 0, "%s", m->err);
  m->cell_tag[3] = 7;
  char *buf;
  size_t len;
  CHECK(mesh_pack(m, &buf, &len) == 0, "pack");
  mesh *u = mesh_unpack(buf, len, err);
  CHECK(u != NULL, "unpack: %s", err);
  CHECK(u->type == m->type && u->nvert == m->nvert && u->ncell == m->ncell && u->nbf == m->nbf &&
        u->nbname == m->nbname && u->ncname == m->ncname, "the sizes");
  CHECK(!memcmp(u->x, m->x, sizeof(double) * (size_t)m->nvert * (size_t)m->dim) &&
        !memcmp(u->cells, m->cells, sizeof(int) * (size_t)m->ncell * (size_t)m->nvc) &&
        !memcmp(u->cell_tag, m->cell_tag, sizeof(int) * (size_t)m->ncell) &&
        !memcmp(u->bf_verts, m->bf_verts, sizeof(int) * (size_t)m->nbf * (size_t)m->nvf) &&
        !memcmp(u->bf_tag, m->bf_tag, sizeof(int) * (size_t)m->nbf), "the arrays");
  CHECK(rtag(u, "a region") == 7 && btag(u, m->bnames[0].name) == m->bnames[0].tag, "the names");
  mesh_free(u);
  int refused = 0;
  for (size_t cut = 0; cut < len; cut += cut < 100 ? 1 : 97) {
    mesh *c = mesh_unpack(buf, cut, err);
    refused += c == NULL && err[0];
    mesh_free(c);
  }
  CHECK(refused == (int)((len - 100 + 96) / 97) + 100, "every cut buffer refused (%d)", refused);
  buf[0] ^= 1;
  CHECK(mesh_unpack(buf, len, err) == NULL && strstr(err, "not a packed mesh"), "a bad header: %s", err);
  free(buf);
  mesh_free(m);
}

/* a mesh cut into parts (part.c): every cell owned by exactly one part, each part holds
 * every cell that shares a vertex with its own and nothing else, local numbers keep the
 * global order, coordinates, tags and boundary facets follow, vertex owners agree with the
 * whole mesh's vote; a part packed and unpacked is the same part; an empty part works */
static void parts(const char *data) {
  char err[MESH_ERRLEN], path[600];
  snprintf(path, sizeof path, "%s/square_unstructured.msh", data);
  mesh *m = mesh_read_gmsh(path, err);
  CHECK(m != NULL, "%s", err);
  if (!m) return;
  const int np = 4; /* three stripes by x, the fourth part empty */
  int *part = malloc(sizeof(int) * (size_t)m->ncell), *vown = malloc(sizeof(int) * (size_t)m->nvert);
  for (int c = 0; c < m->ncell; c++) {
    double cx = 0;
    for (int k = 0; k < m->nvc; k++) cx += m->x[(size_t)m->cells[c * m->nvc + k] * 2] / m->nvc;
    part[c] = cx < 0.3 ? 0 : cx < 0.6 ? 1 : 2;
  }
  m->cell_tag[5] = 9;
  CHECK(mesh_vertex_owners(m, part, vown) == 0, "owners");
  CHECK(mesh_build_boundary_cells(m) == 0, "%s", m->err);
  int *owned = calloc((size_t)m->ncell, sizeof(int)), nbf = 0, nvown = 0;
  for (int p = 0; p < np; p++) {
    mesh_part *P = mesh_part_extract(m, part, vown, p, 1, err);
    CHECK(P != NULL, "part %d: %s", p, err);
    if (!P) continue;
    char *buf;
    size_t len;
    CHECK(mesh_part_pack(P, &buf, &len) == 0, "pack");
    mesh_part *Q = mesh_part_unpack(buf, len, err);
    CHECK(Q != NULL, "unpack: %s", err);
    CHECK(mesh_part_unpack(buf, len - 1, err) == NULL && err[0], "a cut part refused");
    free(buf);
    if (!Q) { mesh_part_free(P); continue; }
    mesh_part_free(P);
    mesh *l = Q->m;
    CHECK(Q->part == p && Q->nvert_global == m->nvert && Q->ncell_global == m->ncell, "the header");
    if (p == 3) CHECK(l->ncell == 0 && l->nvert == 0 && Q->nown_cell == 0, "the empty part");
    /* the local cells: the owned ones and exactly the cells that share a vertex with them */
    char *mine = calloc((size_t)m->nvert, 1), *local = calloc((size_t)m->ncell, 1);
    for (int c = 0; c < m->ncell; c++)
      if (part[c] == p)
        for (int k = 0; k < m->nvc; k++) mine[m->cells[c * m->nvc + k]] = 1;
    int expect = 0, bad = 0, nown = 0;
    for (int c = 0; c < m->ncell; c++) {
      int in = 0;
      for (int k = 0; k < m->nvc; k++) in |= mine[m->cells[c * m->nvc + k]];
      expect += in;
    }
    for (int i = 0; i < l->ncell; i++) {
      int g = Q->cglobal[i];
      local[g] = 1;
      bad += (i && g <= Q->cglobal[i - 1]) || Q->cowner[i] != part[g] || l->cell_tag[i] != m->cell_tag[g];
      for (int k = 0; k < m->nvc; k++) {
        int lv = l->cells[i * m->nvc + k], gv = m->cells[g * m->nvc + k];
        bad += Q->vglobal[lv] != gv || l->x[lv * 2] != m->x[gv * 2] || l->x[lv * 2 + 1] != m->x[gv * 2 + 1];
      }
      if (Q->cowner[i] == p) { owned[g]++; nown++; }
    }
    CHECK(l->ncell == expect && !bad && nown == Q->nown_cell, "part %d: %d cells (expected %d), %d mismatches", p, l->ncell, expect, bad);
    for (int v = 0; v < l->nvert; v++) {
      bad += (v && Q->vglobal[v] <= Q->vglobal[v - 1]) || Q->vowner[v] != vown[Q->vglobal[v]];
      nvown += Q->vowner[v] == p;
    }
    CHECK(!bad, "part %d: vertex numbers and owners", p);
    int want = 0;
    for (int b = 0; b < m->nbf; b++) want += local[m->bf_cell[b]];
    CHECK(l->nbf == want && l->nbname == m->nbname && (!l->nbf || btag(l, m->bnames[0].name) == m->bnames[0].tag),
          "part %d: %d boundary facets (expected %d)", p, l->nbf, want);
    nbf += l->nbf;
    if (l->ncell) CHECK(mesh_build_boundary_cells(l) == 0, "%s", l->err);
    free(mine);
    free(local);
    mesh_part_free(Q);
  }
  int once = 1;
  for (int c = 0; c < m->ncell; c++) once &= owned[c] == 1;
  CHECK(once && nvown == m->nvert, "every cell owned once, every vertex by one part (%d of %d)", nvown, m->nvert);
  CHECK(nbf > m->nbf, "boundary facets near a cut are on both sides (%d > %d)", nbf, m->nbf);
  /* two ghost layers: the cells sharing a vertex with a cell that shares one with an owned
   * cell, and the count kept through packing */
  for (int p = 0; p < 3; p++) {
    mesh_part *P = mesh_part_extract(m, part, vown, p, 2, err);
    CHECK(P != NULL, "part %d with two layers: %s", p, err);
    if (!P) continue;
    char *buf;
    size_t len;
    CHECK(mesh_part_pack(P, &buf, &len) == 0, "pack");
    mesh_part *Q = mesh_part_unpack(buf, len, err);
    free(buf);
    CHECK(Q && Q->layers == 2, "two layers through packing");
    char *v1 = calloc((size_t)m->nvert, 1), *v2 = calloc((size_t)m->nvert, 1);
    for (int c = 0; c < m->ncell; c++)
      if (part[c] == p)
        for (int k = 0; k < m->nvc; k++) v1[m->cells[c * m->nvc + k]] = 1;
    int one = 0, two = 0;
    for (int c = 0; c < m->ncell; c++) {
      int in = 0;
      for (int k = 0; k < m->nvc; k++) in |= v1[m->cells[c * m->nvc + k]];
      one += in;
      if (in)
        for (int k = 0; k < m->nvc; k++) v2[m->cells[c * m->nvc + k]] = 1;
    }
    for (int c = 0; c < m->ncell; c++) {
      int in = 0;
      for (int k = 0; k < m->nvc; k++) in |= v2[m->cells[c * m->nvc + k]];
      two += in;
    }
    CHECK(Q && Q->m->ncell == two && two > one && Q->nown_cell == P->nown_cell,
          "part %d with two layers: %d cells (expected %d, one layer %d)", p, Q ? Q->m->ncell : -1, two, one);
    free(v1);
    free(v2);
    mesh_part_free(P);
    mesh_part_free(Q);
  }
  free(owned);
  free(part);
  free(vown);
  mesh_free(m);
}

/* reading from folders and pipes, writing names with quotes, and writes that fail */
static void files(const char *data) {
  char err[MESH_ERRLEN], path[600], tmp[600];
  CHECK(mesh_read_gmsh("/tmp", err) == NULL && strstr(err, "Is a directory"), "a folder: %s", err);
  /* a pipe is read to its end */
  snprintf(path, sizeof path, "%s/square_unstructured_v22.msh", data);
  snprintf(tmp, sizeof tmp, "/tmp/lugal_fifo_%d", (int)getpid());
  if (mkfifo(tmp, 0600) == 0) {
    pid_t pid = fork();
    if (pid == 0) {
      FILE *in = fopen(path, "rb"), *out = fopen(tmp, "wb");
      for (int c; in && out && (c = fgetc(in)) != EOF;) fputc(c, out);
      if (out) fclose(out);
      _exit(0);
    }
    mesh *p = mesh_read_gmsh(tmp, err);
    waitpid(pid, NULL, 0);
    CHECK(p && p->ncell > 100, "a mesh from a pipe: %s", p ? "" : err);
    mesh_free(p);
    unlink(tmp);
  }
  mesh_box_opts b = {2, 2, 0, 0, 1, 0, 1, 0, 1, CELL_TRIANGLE, 0, 0, 0};
  mesh *m = mesh_rectangle(&b, err);
  CHECK(m && mesh_set_boundary_name(m, 1, "say \"hi\"\\\nnext") == 0, "names");
  snprintf(tmp, sizeof tmp, "/tmp/lugal_names_%d.msh", (int)getpid());
  CHECK(mesh_write_gmsh(m, tmp) == 0, "%s", m->err);
  mesh *r = mesh_read_gmsh(tmp, err);
  CHECK(r && btag(r, "say \"hi\"\\\nnext") == 1, "a name with quotes, a backslash and a newline survives: %s", r ? "" : err);
  mesh_free(r);
  /* errors carry the reason; a failed write leaves the old file as it was */
  CHECK(mesh_write_gmsh(m, "/nonexistent/x.msh") && strstr(m->err, "No such file or directory"), "%s", m->err);
  CHECK(mesh_write_vtu(m, "/tmp", 0, NULL) && strstr(m->err, "/tmp"), "%s", m->err);
  struct stat st0, st1;
  stat(tmp, &st0);
  pid_t pid = fork();
  if (pid == 0) { /* a file size limit makes the write fail half way */
    signal(SIGXFSZ, SIG_IGN);
    struct rlimit rl = {200, 200};
    setrlimit(RLIMIT_FSIZE, &rl);
    mesh_box_opts big = {40, 40, 0, 0, 1, 0, 1, 0, 1, CELL_TRIANGLE, 0, 0, 0};
    mesh *bm = mesh_rectangle(&big, err);
    int rc = mesh_write_gmsh(bm, tmp);
    if (!rc || !strstr(bm->err, "File too large")) fprintf(stderr, "write under a size limit: %d %s\n", rc, bm->err);
    _exit(rc && strstr(bm->err, "File too large") ? 0 : 1);
  }
  int status = 0;
  waitpid(pid, &status, 0);
  CHECK(WIFEXITED(status) && WEXITSTATUS(status) == 0, "the failed write reports the reason");
  stat(tmp, &st1);
  CHECK(st1.st_size == st0.st_size && st1.st_mtime == st0.st_mtime, "the old file is untouched (%ld bytes, was %ld)",
        (long)st1.st_size, (long)st0.st_size);
  unlink(tmp);
  mesh_free(m);
}

/* untangle_defaults sets every option: on a struct full of garbage (a Lua call's stack),
 * the C-only reference_escape was left as it was, and mesh:untangle{reference = ...} now
 * and then stopped at the first valid state instead of moving towards the shapes */
static void untangle_option_defaults(void) {
  untangle_opts o;
  memset(&o, 0xa5, sizeof o);
  untangle_defaults(&o);
  CHECK(o.reference_escape == 0 && o.xref == NULL && o.no_global == 0 && o.verbose == 0 && o.motion_weight == 0 &&
            o.beta == -1 && o.max_iterations == 100 && o.slide == 1 && o.placement == 0,
        "untangle_defaults left a field unset (reference_escape %d)", o.reference_escape);
}

/* a box's or rectangle's part made from a window (what each rank of a distributed run
 * generates) is the part cut from the whole mesh, to the byte, for every part of 2 to 5 runs
 * and 1 or 2 ghost layers; the runs' cuts counted window by window add up to the whole
 * mesh's count */
static void windows(void) {
  char err[MESH_ERRLEN];
  mesh_box_opts cases[] = {{5, 4, 9, 0, 1, 0, 2, 0, 3, CELL_TETRAHEDRON, 0, 0, 0},
                           {3, 4, 11, 0, 1, 0, 1, -1, 1, CELL_HEXAHEDRON, 0, 0, 0},
                           {7, 13, 0, 0, 2, 0, 1, 0, 0, CELL_TRIANGLE, 0, 0, 0},
                           {6, 10, 0, 0, 1, -1, 1, 0, 0, CELL_TRIANGLE, 1, 0, 0},
                           {4, 15, 0, 0, 1, 0, 3, 0, 0, CELL_QUADRILATERAL, 0, 0, 0}};
  int same = 0, tried = 0, smaller = 0;
  for (size_t ci = 0; ci < sizeof cases / sizeof cases[0]; ci++) {
    const mesh_box_opts *o = &cases[ci];
    int box = o->type == CELL_TETRAHEDRON || o->type == CELL_HEXAHEDRON;
    mesh *m = box ? mesh_box(o, err) : mesh_rectangle(o, err);
    CHECK(m != NULL, "%s", err);
    if (!m) continue;
    int *part = malloc(sizeof(int) * (size_t)m->ncell), *vown = malloc(sizeof(int) * (size_t)m->nvert);
    for (int np = 2; np <= 5; np++) {
      mesh_vertex_runs(m, NULL, m->nvert, np, part);
      CHECK(mesh_vertex_owners(m, part, vown) == 0, "owners");
      long cuts = 0, whole = mesh_runs_interface(m, NULL, m->nvert, np, 0, m->nvert);
      for (int layers = 1; layers <= 2; layers++)
        for (int p = 0; p < np; p++) {
          mesh_box_opts w;
          long vlo, vhi;
          CHECK(mesh_box_part_window(o, np, p, layers, &w, &vlo, &vhi) == 0, "a window for part %d of %d", p, np);
          mesh *wm = box ? mesh_box(&w, err) : mesh_rectangle(&w, err);
          CHECK(wm != NULL, "window %d .. %d: %s", w.lo, w.hi, err);
          if (!wm) continue;
          smaller += wm->ncell < m->ncell;
          int *vg = malloc(sizeof(int) * (size_t)wm->nvert), *cg = malloc(sizeof(int) * (size_t)wm->ncell);
          int *wp = malloc(sizeof(int) * (size_t)wm->ncell), *wo = malloc(sizeof(int) * (size_t)wm->nvert);
          mesh_box_window_numbers(&w, wm, vg, cg);
          mesh_vertex_runs(wm, vg, m->nvert, np, wp);
          mesh_vertex_owners(wm, wp, wo);
          if (layers == 1) cuts += mesh_runs_interface(wm, vg, m->nvert, np, (int)vlo, (int)vhi);
          mesh_part *A = mesh_part_extract(m, part, vown, p, layers, err);
          mesh_part *B = mesh_part_extract_window(wm, vg, cg, m->nvert, m->ncell, wp, wo, p, layers, err);
          char *ba = NULL, *bb = NULL;
          size_t la = 0, lb = 0;
          tried++;
          if (A && B && !mesh_part_pack(A, &ba, &la) && !mesh_part_pack(B, &bb, &lb) && la == lb && !memcmp(ba, bb, la)) same++;
          else fprintf(stderr, "case %zu, part %d of %d, %d layers: the window's part differs\n", ci, p, np, layers);
          free(ba); free(bb);
          mesh_part_free(A);
          mesh_part_free(B);
          free(vg); free(cg); free(wp); free(wo);
          mesh_free(wm);
        }
      CHECK(cuts == whole, "case %zu, %d runs: %ld vertices on the cuts window by window, %ld in the whole mesh", ci, np, cuts, whole);
    }
    free(part);
    free(vown);
    mesh_free(m);
  }
  CHECK(same == tried && tried == 5 * 14 * 2 && smaller > tried / 2, "%d of %d parts the same from windows (%d windows smaller than the mesh)", same, tried, smaller);
  /* crossed triangles have no layers (their centres come last): no window */
  mesh_box_opts x = {4, 4, 0, 0, 1, 0, 1, 0, 0, CELL_TRIANGLE, 2, 0, 0}, w;
  long vlo, vhi;
  CHECK(mesh_box_part_window(&x, 2, 0, 1, &w, &vlo, &vhi) == 1, "no window for crossed triangles");
  /* a window outside the mesh is refused with the reason */
  x.diagonal = 0;
  x.lo = 2;
  x.hi = 6;
  CHECK(mesh_rectangle(&x, err) == NULL && strstr(err, "window"), "a window past the top refused: %s", err);
}

/* the file read in nparts parts (mesh_gmsh_layout, mesh_gmsh_read_part): the parts,
 * joined, are the one-part read, item for item (nodes, elements with their physical tags),
 * and the one-part read holds the whole reader's cells; a layout survives packing; files
 * the layout cannot cut say why */
static void read_parts(const char *data) {
  const char *files[] = {"square_unstructured.msh", "square_unstructured_v22.msh", "cube_unstructured.msh", "../../examples/domain.msh"};
  char path[1024], err[MESH_ERRLEN];
  for (int f = 0; f < 4; f++) {
    snprintf(path, sizeof path, "%s/%s", data, files[f]);
    mesh *m = mesh_read_gmsh(path, err);
    CHECK(m != NULL, "%s", err);
    if (!m) continue;
    gmsh_layout L1;
    CHECK(mesh_gmsh_layout(path, 1, &L1), "%s: %s", path, L1.why);
    gmsh_part W;
    CHECK(mesh_gmsh_read_part(path, &L1, 0, &W, err) == 0, "%s", err);
    int cdim = 0;
    long long ncells = 0;
    for (long long i = 0; i < W.ne; i++) cdim = mesh_gmsh_type_dim(W.e[i].type) > cdim ? mesh_gmsh_type_dim(W.e[i].type) : cdim;
    for (long long i = 0; i < W.ne; i++) ncells += mesh_gmsh_type_dim(W.e[i].type) == cdim;
    CHECK(ncells == m->ncell && W.nn >= m->nvert && W.nn == L1.nnodes, "%s: %lld cells, %lld nodes", path, ncells, W.nn);
    for (int np = 2; np <= 7; np++) {
      gmsh_layout L, L2;
      CHECK(mesh_gmsh_layout(path, np, &L), "%s: %s", path, L.why);
      char *buf;
      size_t len;
      CHECK(mesh_gmsh_layout_pack(&L, &buf, &len) == 0 && mesh_gmsh_layout_unpack(buf, len, &L2) == 0, "pack");
      free(buf);
      long long nn = 0, ne = 0, bad = 0;
      for (int p = 0; p < np; p++) {
        gmsh_part G;
        if (mesh_gmsh_read_part(path, &L2, p, &G, err)) { CHECK(0, "%s part %d of %d: %s", path, p, np, err); continue; }
        bad += G.node_first != nn || G.nname != W.nname;
        for (long long i = 0; i < G.nn; i++, nn++)
          bad += G.ntag[i] != W.ntag[nn] || memcmp(G.nx + 3 * i, W.nx + 3 * nn, 3 * sizeof(double));
        bad += G.elem_first != ne;
        for (long long i = 0; i < G.ne; i++, ne++) {
          const gmsh_elem *a = &G.e[i], *b = &W.e[ne];
          bad += a->type != b->type || a->nphys != b->nphys ||
                 memcmp(G.enodes + a->node, W.enodes + b->node, sizeof(long long) * (size_t)mesh_gmsh_type_nodes(a->type)) ||
                 memcmp(G.phys + a->phys, W.phys + b->phys, sizeof(int) * (size_t)a->nphys);
        }
        mesh_gmsh_part_free(&G);
      }
      CHECK(!bad && nn == W.nn && ne == W.ne, "%s in %d parts: %lld differences, %lld of %lld nodes, %lld of %lld elements", path,
            np, bad, nn, W.nn, ne, W.ne);
      mesh_gmsh_layout_free(&L);
      mesh_gmsh_layout_free(&L2);
    }
    mesh_gmsh_part_free(&W);
    mesh_gmsh_layout_free(&L1);
    mesh_free(m);
  }
  /* what the layout does not cut: a pipe, repeated sections, counts beyond the lines */
  gmsh_layout L;
  CHECK(!mesh_gmsh_layout("/dev/null", 2, &L) && strstr(L.why, "regular"), "%s", L.why);
  mesh_gmsh_layout_free(&L);
  const char *bad[] = {"$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n3\n1 0 0 0\n2 1 0 0\n$EndNodes\n$Elements\n0\n$EndElements\n",
                       "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n0\n$EndNodes\n$Nodes\n0\n$EndNodes\n$Elements\n0\n$EndElements\n",
                       "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n1\n1 0 0 0\n2 0 0 0\n$EndNodes\n$Elements\n0\n$EndElements\n"};
  for (int i = 0; i < 3; i++) {
    snprintf(path, sizeof path, "/tmp/lugal_layout_%d.msh", (int)getpid());
    FILE *fp = fopen(path, "w");
    fputs(bad[i], fp);
    fclose(fp);
    CHECK(!mesh_gmsh_layout(path, 2, &L) && L.why[0], "bad layout %d accepted", i);
    mesh_gmsh_layout_free(&L);
    remove(path);
  }
}

/* the longest edge, edge by edge with hypot (no overflow or underflow) */
static double hmax_ref(const mesh *m) {
  double h = 0;
  for (int c = 0; c < m->ncell; c++)
    for (int e = 0; e < cell_nedges(m->type); e++) {
      const int *ev = cell_edge_verts(m->type, e), *v = m->cells + (size_t)c * m->nvc;
      double t[3] = {0, 0, 0};
      for (int k = 0; k < m->dim; k++) t[k] = m->x[(size_t)m->dim * v[ev[0]] + k] - m->x[(size_t)m->dim * v[ev[1]] + k];
      double l = hypot(hypot(t[0], t[1]), t[2]);
      if (l > h) h = l;
    }
  return h;
}

/* mesh_hmax's one pass (threads above 100 000 cells) against the edge-by-edge lengths: a
 * perturbed box of 6·24·24·40 tetrahedra, the same scaled by 1e-200 and 1e200 (the scaled
 * loop), and a NaN coordinate */
static void hmax(void) {
  char err[MESH_ERRLEN];
  mesh_box_opts b = {24, 24, 40, 0, 1, 0, 1, 0, 1, CELL_TETRAHEDRON, 0, 0, 0};
  mesh *m = mesh_box(&b, err);
  CHECK(m && m->ncell > 100000, "box: %s", err);
  if (!m) return;
  unsigned r = 12345;
  for (int i = 0; i < m->nvert * 3; i++) {
    r = r * 1103515245u + 12345u;
    m->x[i] += 0.004 * ((r >> 8) / 16777216.0 - 0.5);
  }
  double h = mesh_hmax(m), ref = hmax_ref(m);
  CHECK(fabs(h - ref) <= 1e-15 * ref && h > 1.0 / 40, "hmax %.17g against %.17g", h, ref);
  for (int i = 0; i < m->nvert * 3; i++) m->x[i] *= 1e-200;
  h = mesh_hmax(m);
  CHECK(fabs(h - ref * 1e-200) <= 1e-14 * ref * 1e-200, "tiny hmax %g against %g", h, ref * 1e-200);
  for (int i = 0; i < m->nvert * 3; i++) m->x[i] *= 1e200, m->x[i] *= 1e200;
  h = mesh_hmax(m);
  CHECK(fabs(h - ref * 1e200) <= 1e-14 * ref * 1e200, "huge hmax %g against %g", h, ref * 1e200);
  m->x[5] = NAN;
  CHECK(isnan(mesh_hmax(m)), "a NaN coordinate makes hmax NaN");
  mesh_free(m);
}

/* mesh_validate (one pass) gives mesh_hmax's value to rounding and mesh_count_invalid's count and first
 * cells: the mesh as it is, scaled by 1e-200 and 1e200, with inverted cells, a flattened one
 * near the threshold (the slow path), a NaN */
static void validate_same(mesh *m, const char *what) {
  int ids[5] = {-1, -1, -1, -1, -1}, ids2[5] = {-1, -1, -1, -1, -1}, n, n2;
  double h;
  mesh_validate(m, &h, 5, ids, &n);
  double h2 = mesh_hmax(m);
  mesh_count_invalid(m, 5, ids2, &n2);
  CHECK((fabs(h - h2) <= 4e-16 * h2 || (isnan(h) && isnan(h2))) && n == n2 && !memcmp(ids, ids2, sizeof ids),
        "%s: mesh_validate hmax %.17g, %d invalid (first %d) against %.17g, %d (first %d)", what, h, n, ids[0], h2, n2, ids2[0]);
}

static void validate(void) {
  char err[MESH_ERRLEN];
  mesh_box_opts b3 = {24, 24, 40, 0, 1, 0, 1, 0, 1, CELL_TETRAHEDRON, 0, 0, 0};
  mesh_box_opts b2 = {300, 200, 0, 0, 1, 0, 1, 0, 0, CELL_TRIANGLE, 0, 0, 0};
  mesh_box_opts bh = {6, 5, 4, 0, 1, 0, 1, 0, 1, CELL_HEXAHEDRON, 0, 0, 0};
  mesh *ms[3] = {mesh_box(&b3, err), mesh_rectangle(&b2, err), mesh_box(&bh, err)};
  for (int i = 0; i < 3; i++) {
    mesh *m = ms[i];
    CHECK(m != NULL, "mesh %d: %s", i, err);
    if (!m) continue;
    int d = m->dim;
    unsigned r = 777;
    for (int k = 0; k < m->nvert * d; k++) {
      r = r * 1103515245u + 12345u;
      m->x[k] += 0.001 * ((r >> 8) / 16777216.0 - 0.5);
    }
    validate_same(m, "perturbed");
    for (int k = 0; k < m->nvert * d; k++) m->x[k] *= 1e-200;
    validate_same(m, "tiny");
    for (int k = 0; k < m->nvert * d; k++) m->x[k] *= 1e200, m->x[k] *= 1e200;
    validate_same(m, "huge");
    for (int k = 0; k < m->nvert * d; k++) m->x[k] *= 1e-200;
    /* invert three cells (two vertices swapped) */
    int inv[3] = {7, m->ncell / 2, m->ncell - 1};
    for (int j = 0; j < 3; j++) {
      int *v = m->cells + (size_t)inv[j] * m->nvc, t = v[1];
      v[1] = v[2], v[2] = t;
    }
    validate_same(m, "inverted cells");
    int nbad;
    mesh_validate(m, &(double){0}, 0, NULL, &nbad);
    CHECK(nbad >= 3, "the inverted cells are counted (%d)", nbad);
    /* a cell flattened to about the threshold's relative validity */
    if (m->type != CELL_HEXAHEDRON) {
      int *v = m->cells + (size_t)20 * m->nvc;
      const double *a = m->x + (size_t)d * v[0], *b2v = m->x + (size_t)d * v[1];
      double *p = m->x + (size_t)d * v[d];
      for (int k = 0; k < d; k++) p[k] = 0.5 * (a[k] + b2v[k]) + (k == 0 ? 1e-14 : 0);
      validate_same(m, "a flattened cell");
    }
    m->x[5] = NAN;
    validate_same(m, "a NaN");
    mesh_free(m);
  }
}

int main(int argc, char **argv) {
  const char *data = argc > 1 ? argv[1] : "tests/data";
  hmax();
  validate();
  untangle_option_defaults();
  pack(data);
  parts(data);
  windows();
  read_parts(data);
  char err[MESH_ERRLEN], path[1024];
  mesh_box_opts o = {3, 2, 2, 0, 2, 0, 1, 0, 1, CELL_TRIANGLE, 0, 0, 0};
  for (int dg = 0; dg < 3; dg++) {
    o.diagonal = dg;
    mesh *m = mesh_rectangle(&o, err);
    CHECK(m != NULL, "%s", err);
    CHECK(m->ncell == (dg == 2 ? 24 : 12), "cells %d", m->ncell);
    CHECK_CLOSE(total(m), 2.0, 1e-14);
    int ninv;
    mesh_count_invalid(m, 0, NULL, &ninv);
    CHECK(ninv == 0, "%d inverted", ninv);
    CHECK(btag(m, "top") == 4 && btag(m, "nope") == -1, "names");
    int nb = 0;
    for (int b = 0; b < m->nbf; b++) nb += m->bf_tag[b] == btag(m, "left");
    CHECK(nb == 2, "left has %d facets", nb);
    mesh_free(m);
  }
  o.type = CELL_QUADRILATERAL;
  mesh *q = mesh_rectangle(&o, err);
  CHECK(q && q->ncell == 6 && fabs(total(q) - 2) < 1e-14, "quad rectangle");
  mesh *qr = mesh_refine(q, err);
  CHECK(qr && qr->ncell == 24 && fabs(total(qr) - 2) < 1e-14 && qr->nbf == 2 * q->nbf, "quad refine");
  mesh_free(q);
  mesh_free(qr);
  mesh_box_opts b = {2, 3, 2, 0, 1, 0, 1, 0, 2, CELL_TETRAHEDRON, 0, 0, 0};
  mesh *t = mesh_box(&b, err);
  CHECK(t && t->ncell == 72 && fabs(total(t) - 2) < 1e-13, "tet box");
  int ninv;
  mesh_count_invalid(t, 0, NULL, &ninv);
  CHECK(ninv == 0, "box has %d inverted", ninv);
  mesh *tr = mesh_refine(t, err);
  CHECK(tr && tr->ncell == 8 * 72 && fabs(total(tr) - 2) < 1e-13, "tet refine");
  mesh_count_invalid(tr, 0, NULL, &ninv);
  CHECK(ninv == 0, "refined box has %d inverted", ninv);
  CHECK(tr->nbf == 4 * t->nbf && mesh_build_boundary_cells(tr) == 0, "refined boundary: %s", tr->err);
  mesh_free(tr);
  mesh_free(t);
  b.type = CELL_HEXAHEDRON;
  mesh *h = mesh_box(&b, err);
  CHECK(h && h->ncell == 12 && fabs(total(h) - 2) < 1e-13, "hex box volume %g", h ? total(h) : 0);
  mesh_free(h);

  /* the same mesh in MSH 4.1 and 2.2 */
  snprintf(path, sizeof path, "%s/square_unstructured.msh", data);
  mesh *g4 = mesh_read_gmsh(path, err);
  CHECK(g4 != NULL, "%s", err);
  snprintf(path, sizeof path, "%s/square_unstructured_v22.msh", data);
  mesh *g2 = mesh_read_gmsh(path, err);
  CHECK(g2 != NULL, "%s", err);
  if (g4 && g2) {
    CHECK(g4->ncell == g2->ncell && g4->nvert == g2->nvert && g4->nbf == g2->nbf, "4.1 vs 2.2 sizes");
    CHECK(!memcmp(g4->cells, g2->cells, sizeof(int) * (size_t)g4->ncell * 3), "4.1 vs 2.2 cells");
    CHECK_CLOSE(total(g4), 1.0, 1e-13);
    CHECK(btag(g4, "left") > 0 && rtag(g4, "domain") > 0, "physical names");
    mesh_count_invalid(g4, 0, NULL, &ninv);
    CHECK(ninv == 0, "gmsh mesh has %d inverted", ninv);
    /* round trip through the writer */
    snprintf(path, sizeof path, "/tmp/lugal_test_%d.msh", (int)getpid());
    CHECK(mesh_write_gmsh(g4, path) == 0, "%s", g4->err);
    mesh *rt = mesh_read_gmsh(path, err);
    CHECK(rt && rt->ncell == g4->ncell && rt->nbf == g4->nbf && btag(rt, "top") == btag(g4, "top"),
          "round trip: %s", rt ? "" : err);
    if (rt) CHECK(!memcmp(rt->x, g4->x, sizeof(double) * 2 * (size_t)g4->nvert), "coordinates survive");
    mesh_free(rt);
    remove(path);
  }
  mesh_free(g4);
  mesh_free(g2);

  /* inverted and zero-size cells are counted with their ids */
  double x[] = {0, 0, 1, 0, 0, 1, 1, 1, 2, 2};
  int cells[] = {0, 1, 2, 1, 2, 3, 0, 3, 4};
  mesh *bad = mesh_create(CELL_TRIANGLE, 5, x, 3, cells, err);
  int ids[3];
  mesh_count_invalid(bad, 3, ids, &ninv);
  CHECK(ninv == 2 && ids[0] == 1 && ids[1] == 2, "invalid cells: %d (%d, %d)", ninv, ids[0], ids[1]);
  mesh_free(bad);
  /* the validity check's fast path for simplices (no normalization) decides as the
   * normalized relative validity does, cell by cell: random tetrahedra and triangles at
   * scales from 1e-250 to 1e250, a third of them flattened to within 1e-13 relative and
   * a tenth with a vertex moved through the opposite face */
  for (int dim = 2; dim <= 3; dim++) {
    enum { NC = 3000 };
    int nvc = dim + 1;
    double *rx = malloc(sizeof(double) * NC * nvc * dim);
    int *rc = malloc(sizeof(int) * NC * nvc);
    unsigned long long st = 12345;
    for (int c = 0; c < NC; c++) {
      double scale = pow(10.0, -250 + 500.0 * (c % 101) / 100.0), *p = rx + (size_t)c * nvc * dim;
      for (int i = 0; i < nvc * dim; i++) {
        st = st * 6364136223846793005ull + 1442695040888963407ull;
        p[i] = scale * ((double)(st >> 11) / 9007199254740992.0 + (i < dim ? 3.0 : 0.0));
      }
      if (c % 3 == 1) /* the last vertex on the plane of the others, up to 1e-13 */
        for (int k = 0; k < dim; k++) {
          double t = 0;
          for (int i = 0; i < dim; i++) t += p[i * dim + k] / dim;
          p[dim * dim + k] = t * (1 + 1e-13 * (double)(c % 7 - 3));
        }
      if (c % 10 == 3)
        for (int k = 0; k < dim; k++) p[dim * dim + k] = 2 * p[k] - p[dim * dim + k];
      for (int i = 0; i < nvc; i++) rc[c * nvc + i] = c * nvc + i;
    }
    mesh *rm = mesh_create(dim == 2 ? CELL_TRIANGLE : CELL_TETRAHEDRON, NC * nvc, rx, NC, rc, err);
    CHECK(rm != NULL, "%s", err);
    if (rm) {
      int slow = 0, fast = 0;
      for (int c = 0; c < NC; c++) slow += !(mesh_cell_relative_validity(rm, c) > 1e-13);
      mesh_count_invalid(rm, 0, NULL, &fast);
      CHECK(fast == slow && slow > NC / 20 && slow < NC - NC / 20, "dim %d: %d invalid by the fast path, %d by the normalized one",
            dim, fast, slow);
    }
    mesh_free(rm);
    free(rx);
    free(rc);
  }
  int badcells[] = {0, 1, 7};
  CHECK(mesh_create(CELL_TRIANGLE, 5, x, 1, badcells, err) == NULL && strstr(err, "refers to vertex 8"), "%s", err);
  files(data);
  return CHECK_DONE();
}
