/* fuzz_mesh.c — the Gmsh reader, the quality module, the writers and (on small meshes)
 * refinement, untangling and smoothing, driven by arbitrary bytes.
 *
 * Built two ways: as a libFuzzer target (`make fuzz`: clang -fsanitize=fuzzer,address,
 * undefined) and into tests/c/test_hostile.c, which replays tests/data/hostile/ in
 * `make check`. Besides "no crash, no hang, no leak" it checks what must hold for every
 * mesh the reader accepts: cell and facet vertex ids in range, a written .msh reads back
 * the same, and an untangler report of "no invalid cells" is true of the mesh. A broken
 * invariant aborts (a finding). */
#include "../../src/mesh/io/io.h"
#include "../../src/mesh/quality/quality.h"
#include "../../src/mesh/io/svg.h"
#include "../../src/mesh/untangle/untangle.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

typedef struct {
  int ok;                  /* the reader accepted the input */
  char err[MESH_ERRLEN];   /* its message otherwise */
  int ncell, nvert, nbf, ninvalid, type;
  double mean_ratio_min;   /* simplices; scaled_jacobian min otherwise */
  char names[4096];        /* boundary names */
  char rnames[1024];       /* region names */
} fuzz_mesh_result;

#define FUZZ_CHECK(cond, what)                                                                  \
  do {                                                                                          \
    if (!(cond)) {                                                                              \
      fprintf(stderr, "fuzz_mesh: invariant broken: %s (%s:%d)\n", what, __FILE__, __LINE__);  \
      abort();                                                                                  \
    }                                                                                           \
  } while (0)

static char fuzz_dir[256];

static void fuzz_cleanup(void) {
  static const char *files[] = {"m.msh", "m.vtu", "m.pvd", "m.svg", "h.svg", "in.msh"};
  char p[400];
  for (size_t i = 0; i < sizeof files / sizeof files[0]; i++) {
    snprintf(p, sizeof p, "%s/%s", fuzz_dir, files[i]);
    unlink(p);
  }
  rmdir(fuzz_dir);
}

/* a private scratch folder, in memory when /dev/shm is there, removed at exit */
static const char *fuzz_tmpdir(void) {
  if (!fuzz_dir[0]) {
    const char *base = access("/dev/shm", W_OK) == 0 ? "/dev/shm" : getenv("TMPDIR") ? getenv("TMPDIR") : "/tmp";
    snprintf(fuzz_dir, sizeof fuzz_dir, "%s/lugal-fuzz-XXXXXX", base);
    if (!mkdtemp(fuzz_dir)) { fprintf(stderr, "fuzz_mesh: cannot make a scratch folder in %s\n", base); abort(); }
    atexit(fuzz_cleanup);
  }
  return fuzz_dir;
}

static void check_structure(const mesh *m) {
  for (size_t i = 0; i < (size_t)m->ncell * m->nvc; i++) FUZZ_CHECK(m->cells[i] >= 0 && m->cells[i] < m->nvert, "cell vertex id in range");
  for (size_t i = 0; i < (size_t)m->nbf * m->nvf; i++) FUZZ_CHECK(m->bf_verts[i] >= 0 && m->bf_verts[i] < m->nvert, "facet vertex id in range");
  for (int i = 0; i < m->nbname; i++) FUZZ_CHECK(m->bnames[i].name != NULL, "boundary names set");
  for (size_t i = 0; i < (size_t)m->nvert * m->dim; i++) FUZZ_CHECK(isfinite(m->x[i]), "finite coordinates");
}

/* the untangler's "valid" must be true: no cell left strictly inverted */
static void check_untangled(const mesh *m, const untangle_report *r) {
  if (r->invalid_after) return;
  for (int c = 0; c < m->ncell; c++) FUZZ_CHECK(!(mesh_cell_relative_validity(m, c) < -1e-9), "untangle reported success");
  for (size_t i = 0; i < (size_t)m->nvert * m->dim; i++) FUZZ_CHECK(isfinite(m->x[i]), "untangle kept coordinates finite");
}

static void exercise(mesh *m, fuzz_mesh_result *res) {
  char err[MESH_ERRLEN], path[400];
  const char *dir = fuzz_tmpdir();
  check_structure(m);
  mesh_count_invalid(m, 0, NULL, &res->ninvalid);
  /* the one-pass check counts what the two passes count */
  {
    double h;
    int ids[5], n1 = -1, ids2[5], n2 = -1;
    mesh_validate(m, &h, 5, ids, &n1);
    mesh_count_invalid(m, 5, ids2, &n2);
    FUZZ_CHECK(n1 == res->ninvalid && n2 == n1, "mesh_validate counts the invalid cells as mesh_count_invalid");
    for (int i = 0; i < n1 && i < 5; i++) FUZZ_CHECK(ids[i] == ids2[i], "mesh_validate's first invalid cells");
  }
  /* edges: each cell's edge ids in range, each naming the cell's own two vertices */
  if (m->type != CELL_INTERVAL && !mesh_build_edges(m)) {
    int ne = cell_nedges(m->type);
    for (int c = 0; c < m->ncell; c++)
      for (int e = 0; e < ne; e++) {
        int id = m->cell_edges[(size_t)c * ne + e];
        FUZZ_CHECK(id >= 0 && id < m->nedge, "an edge id in range");
        const int *lv = cell_edge_verts(m->type, e), *v = m->cells + (size_t)c * m->nvc;
        int a = v[lv[0]] < v[lv[1]] ? v[lv[0]] : v[lv[1]], b = v[lv[0]] < v[lv[1]] ? v[lv[1]] : v[lv[0]];
        FUZZ_CHECK(m->edges[2 * id] == a && m->edges[2 * id + 1] == b, "an edge's vertices are its cells'");
      }
  }
  /* interior facets: two distinct cells per facet, local indices in range, a permutation */
  if (!mesh_build_interior_facets(m)) {
    int nf = cell_nfacets(m->type), nperm = 1;
    for (int i = 2; i <= m->nvf; i++) nperm *= i;
    for (int i = 0; i < m->nif; i++)
      if (m->if_cell[2 * i] == m->if_cell[2 * i + 1] || m->if_cell[2 * i] < 0 || m->if_cell[2 * i + 1] >= m->ncell ||
          m->if_local[2 * i] < 0 || m->if_local[2 * i] >= nf || m->if_local[2 * i + 1] < 0 || m->if_local[2 * i + 1] >= nf ||
          m->if_perm[i] < 0 || m->if_perm[i] >= nperm)
        __builtin_trap();
  }
  double *q = calloc((size_t)m->ncell + 8, sizeof(double));
  int counts[16] = {0}; /* no measure applies to an interval mesh: the histogram stays empty */
  if (!q) return;
  int simplex = m->type == CELL_TRIANGLE || m->type == CELL_TETRAHEDRON;
  int sel = simplex ? QM_MEAN_RATIO : QM_SCALED_JACOBIAN;
  for (int k = 0; k < QM_COUNT; k++) {
    if (!quality_applies(k, m->type) || quality_is_deformation(k)) continue;
    if (mesh_quality(m, k, NULL, q, err)) continue;
    quality_stats st;
    quality_stats_compute(q, m->ncell, &st);
    quality_histogram(q, m->ncell, 16, st.min, st.max, counts);
    int w[3];
    quality_worst(q, m->ncell, m->ncell < 3 ? m->ncell : 3, quality_larger_is_better(k), w);
    if (k == sel) res->mean_ratio_min = st.min;
  }
  /* a metric and a deformation against a shifted copy */
  double M[9] = {2, 0.5, 0, 0.5, 1, 0, 0, 0, 1};
  if (m->dim == 3) { M[2] = 0; M[3] = 0.5; M[4] = 1; M[5] = 0; M[6] = 0; M[7] = 0; M[8] = 1; }
  quality_metric qm = {1, M};
  mesh_quality(m, simplex ? QM_MEAN_RATIO : QM_SCALED_JACOBIAN, &qm, q, err);
  double *xr = malloc(sizeof(double) * (size_t)m->nvert * m->dim + 1);
  if (xr) {
    for (size_t i = 0; i < (size_t)m->nvert * m->dim; i++) xr[i] = m->x[i] * 1.5 + 0.25;
    mesh_deformation(m, xr, QM_DEFORMATION_QUALITY, 2, q, err);
    free(xr);
  }
  /* writers, and the .msh written reads back the same */
  snprintf(path, sizeof path, "%s/m.msh", dir);
  if (!mesh_write_gmsh(m, path)) {
    mesh *r = mesh_read_gmsh(path, err);
    FUZZ_CHECK(r != NULL, "a written .msh reads back");
    if (r) {
      FUZZ_CHECK(r->ncell == m->ncell && r->nvert == m->nvert, "the .msh round trip keeps the cells");
      FUZZ_CHECK(r->nbname == m->nbname && r->ncname == m->ncname, "the .msh round trip keeps the names");
      for (int i = 0; i < m->nbname; i++) {
        int t;
        FUZZ_CHECK(mesh_boundary_tags(r, m->bnames[i].name, &t, 1) > 0, "a boundary name survives the round trip");
      }
      mesh_free(r);
    }
  }
  mesh_quality(m, sel, NULL, q, err);
  mesh_field f = {"q\"<&>", 1, 1, q};
  snprintf(path, sizeof path, "%s/m.vtu", dir);
  mesh_write_vtu(m, path, 1, &f);
  char *files[1] = {path};
  double t = 0;
  char pvd[400];
  snprintf(pvd, sizeof pvd, "%s/m.pvd", dir);
  mesh_write_pvd(pvd, 1, &t, files, err);
  if (m->dim == 2) {
    snprintf(path, sizeof path, "%s/m.svg", dir);
    mesh_write_svg(m, path, q, 0, 1, "fuzz <&>", err);
  }
  snprintf(path, sizeof path, "%s/h.svg", dir);
  write_svg_histogram(path, counts, 16, 0, 1, "h", err);
  free(q);
  mesh_boundary_names(m, res->names, sizeof res->names);
  mesh_region_names(m, res->rnames, sizeof res->rnames);
  /* the expensive parts on small meshes only */
  if (m->ncell <= 300) {
    mesh *r = mesh_refine(m, err);
    if (r) { check_structure(r); mesh_free(r); }
    mesh *c = mesh_copy(m);
    if (c) {
      untangle_opts o;
      untangle_defaults(&o);
      o.max_iterations = 5;
      untangle_report ur;
      if (!mesh_untangle(c, &o, &ur, err)) {
        check_untangled(c, &ur);
        if (!ur.invalid_after) {
          smooth_opts so = {smooth_energy_measure(m->type), 2, 1, 0, 0, 0, NULL, SMOOTH_AUTO, SMOOTH_SLIDE_NONE, 1, 0};
          smooth_report sr;
          mesh_smooth(c, &so, &sr, err);
        }
      }
      mesh_free(c);
    }
  }
}

/* the file read in 3 parts (the parallel reader's layout and parts, gmsh_layout.c and gmsh.c): no crash, a
 * message for a part refused, and the parts of a layout hold its counts; where the whole
 * reader took the file, the parts hold at least its cells (repeats merge) */
static void read_in_parts(const uint8_t *data, size_t size, const mesh *m) {
  char path[400], err[MESH_ERRLEN];
  snprintf(path, sizeof path, "%s/in.msh", fuzz_tmpdir());
  FILE *f = fopen(path, "wb");
  if (!f) return;
  fwrite(data, 1, size, f);
  fclose(f);
  gmsh_layout L;
  if (mesh_gmsh_layout(path, 3, &L)) {
    long long nn = 0, ne = 0, ncell = 0;
    int all = 1;
    for (int p = 0; p < 3; p++) {
      gmsh_part G;
      err[0] = 0;
      if (mesh_gmsh_read_part(path, &L, p, &G, err)) {
        FUZZ_CHECK(err[0] != 0, "a refused part has a message");
        all = 0;
        continue;
      }
      nn += G.nn;
      ne += G.ne;
      for (long long i = 0; m && i < G.ne; i++) ncell += mesh_gmsh_type_dim(G.e[i].type) == m->dim;
      mesh_gmsh_part_free(&G);
    }
    FUZZ_CHECK(!all || (nn == L.nnodes && ne == L.nelems), "the parts hold the layout's nodes and elements");
    FUZZ_CHECK(!all || !m || ncell >= m->ncell, "the parts hold the whole reader's cells");
  } else
    FUZZ_CHECK(L.why[0] != 0, "a layout refused has a reason");
  mesh_gmsh_layout_free(&L);
  unlink(path);
}

int fuzz_mesh_run(const uint8_t *data, size_t size, fuzz_mesh_result *res) {
  memset(res, 0, sizeof *res);
  mesh *m = mesh_read_gmsh_buffer((const char *)data, size, "input.msh", res->err);
  read_in_parts(data, size, m);
  if (!m) {
    FUZZ_CHECK(res->err[0] != 0, "a refused mesh has a message");
    return 0;
  }
  res->ok = 1;
  res->ncell = m->ncell;
  res->nvert = m->nvert;
  res->nbf = m->nbf;
  res->type = m->type;
  exercise(m, res);
  mesh_free(m);
  return 0;
}

#ifdef LUGAL_LIBFUZZER
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  fuzz_mesh_result r;
  return fuzz_mesh_run(data, size, &r);
}
#endif
