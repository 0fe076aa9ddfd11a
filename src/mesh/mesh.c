/* mesh.c — mesh construction, names, generators, derived adjacency, geometry, the
 * validity check and uniform refinement. Reference-cell numbering follows Gmsh/VTK for
 * vertices; simplex edges and facets are numbered opposite-vertex style (as in Basix). */
#ifdef _OPENMP
#include <omp.h>
#endif
#include "mesh.h"
#include "tuplehash.h"

#include <stdint.h>

#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <sys/mman.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* an interval's facets opposite its vertices, as a simplex's: facet 0 is vertex 1 */
static const int int_facets[2][1] = {{1}, {0}};
static const int int_edges[1][2] = {{0, 1}};
static const int tri_facets[3][2] = {{1, 2}, {2, 0}, {0, 1}};
static const int tri_edges[3][2] = {{1, 2}, {0, 2}, {0, 1}};
static const int quad_facets[4][2] = {{0, 1}, {1, 2}, {2, 3}, {3, 0}};
static const int tet_facets[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};
static const int tet_edges[6][2] = {{2, 3}, {1, 3}, {1, 2}, {0, 3}, {0, 2}, {0, 1}};
static const int hex_facets[6][4] = {{0, 3, 2, 1}, {4, 5, 6, 7}, {0, 1, 5, 4},
                                     {1, 2, 6, 5}, {2, 3, 7, 6}, {3, 0, 4, 7}};
static const int hex_edges[12][2] = {{0, 1}, {1, 2}, {2, 3}, {3, 0}, {4, 5}, {5, 6},
                                     {6, 7}, {7, 4}, {0, 4}, {1, 5}, {2, 6}, {3, 7}};

int cell_nfacets(cell_type t) { static const int n[] = {3, 4, 4, 6, 2}; return n[t]; }
/* an interval's interior dofs belong to the cell, not to an edge */
int cell_nedges(cell_type t) { static const int n[] = {3, 4, 6, 12, 0}; return n[t]; }
int cell_dim(cell_type t) { return t == CELL_INTERVAL ? 1 : t <= CELL_QUADRILATERAL ? 2 : 3; }
int cell_nverts(cell_type t) { static const int n[] = {3, 4, 4, 8, 2}; return n[t]; }
const char *cell_name(cell_type t) {
  static const char *n[] = {"triangle", "quadrilateral", "tetrahedron", "hexahedron", "interval"};
  return n[t];
}
const char *cell_plural(cell_type t) {
  static const char *n[] = {"triangles", "quadrilaterals", "tetrahedra", "hexahedra", "intervals"};
  return n[t];
}
int cell_nvf(cell_type t) { static const int n[] = {2, 2, 3, 4, 1}; return n[t]; }

const int *cell_facet_verts(cell_type t, int f) {
  switch (t) {
  case CELL_TRIANGLE: return tri_facets[f];
  case CELL_QUADRILATERAL: return quad_facets[f];
  case CELL_TETRAHEDRON: return tet_facets[f];
  case CELL_INTERVAL: return int_facets[f];
  default: return hex_facets[f];
  }
}
const int *cell_edge_verts(cell_type t, int e) {
  switch (t) {
  case CELL_TRIANGLE: return tri_edges[e];
  case CELL_QUADRILATERAL: return quad_facets[e];
  case CELL_TETRAHEDRON: return tet_edges[e];
  case CELL_INTERVAL: return int_edges[e];
  default: return hex_edges[e];
  }
}

#define BIG_HEADER 64
#define BIG_MAPPED 0x6c7567616c6d6d70ull
#define BIG_HEAP 0x6c7567616c686570ull

/* the big arrays on transparent huge pages where malloc's are (the launcher's
 * -lugal_hugepages 1 sets glibc's tunable; off by default: src/lua/launch.c says why) */
static int big_huge(void) {
  static int huge = -1;
  if (huge < 0) {
    const char *t = getenv("GLIBC_TUNABLES");
    huge = t && strstr(t, "glibc.malloc.hugetlb=1") != NULL;
  }
  return huge;
}

void *mesh_big_alloc(size_t bytes) {
  size_t total = bytes + BIG_HEADER;
  unsigned char *p;
  uint64_t kind;
  if (total >= (2u << 20)) {
    p = mmap(NULL, total, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (p == MAP_FAILED) return NULL;
#ifdef MADV_HUGEPAGE
    if (big_huge()) madvise(p, total, MADV_HUGEPAGE);
#endif
    kind = BIG_MAPPED;
  } else {
    p = malloc(total);
    if (!p) return NULL;
    kind = BIG_HEAP;
  }
  uint64_t h[2] = {kind, (uint64_t)total};
  memcpy(p, h, sizeof h);
  return p + BIG_HEADER;
}

void mesh_big_free(void *ptr) {
  if (!ptr) return;
  unsigned char *p = (unsigned char *)ptr - BIG_HEADER;
  uint64_t h[2];
  memcpy(h, p, sizeof h);
  if (h[0] == BIG_MAPPED) munmap(p, (size_t)h[1]);
  else free(p);
}

static void seterr(char *err, const char *fmt, ...) {
  if (!err) return;
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(err, MESH_ERRLEN, fmt, ap);
  va_end(ap);
}

mesh *mesh_create(cell_type t, int nvert, const double *x, int ncell, const int *cells,
                  char *err) {
  if (nvert <= 0 || ncell <= 0) {
    seterr(err, "a mesh needs at least one vertex and one cell (got %d vertices, %d cells)",
           nvert, ncell);
    return NULL;
  }
  mesh *m = calloc(1, sizeof *m);
  if (!m) { seterr(err, "out of memory"); return NULL; }
  m->type = t;
  m->dim = cell_dim(t);
  m->nvc = cell_nverts(t);
  m->nvf = cell_nvf(t);
  m->nvert = nvert;
  m->ncell = ncell;
  m->x = mesh_big_alloc(sizeof(double) * (size_t)nvert * (size_t)m->dim);
  m->cells = mesh_big_alloc(sizeof(int) * (size_t)ncell * (size_t)m->nvc);
  m->cell_tag = calloc((size_t)ncell, sizeof(int));
  if (!m->x || !m->cells || !m->cell_tag) {
    mesh_free(m);
    seterr(err, "out of memory for a mesh of %d vertices and %d cells", nvert, ncell);
    return NULL;
  }
  if (x) memcpy(m->x, x, sizeof(double) * (size_t)nvert * (size_t)m->dim);
  if (cells) {
    for (size_t i = 0; i < (size_t)ncell * (size_t)m->nvc; i++) {
      if (cells[i] < 0 || cells[i] >= nvert) {
        seterr(err, "cell %zu refers to vertex %d, but the mesh has %d vertices",
               i / (size_t)m->nvc + 1, cells[i] + 1, nvert);
        mesh_free(m);
        return NULL;
      }
    }
    memcpy(m->cells, cells, sizeof(int) * (size_t)ncell * (size_t)m->nvc);
  }
  return m;
}

static void free_names(mesh_name *tab, int n);
static int copy_names(mesh_name **dst, int *nd, int *capd, const mesh_name *src, int n);

static void mesh_free_derived(mesh *m) {
  free(m->edges); free(m->cell_edges); free(m->faces); free(m->cell_faces);
  free(m->bf_cell); free(m->bf_local);
  free(m->if_cell); free(m->if_local); free(m->if_perm);
  m->edges = m->cell_edges = m->faces = m->cell_faces = m->bf_cell = m->bf_local = NULL;
  m->if_cell = m->if_local = m->if_perm = NULL;
  m->nedge = m->nface = m->nif = 0;
}

void mesh_free(mesh *m) {
  if (!m) return;
  mesh_free_derived(m);
  mesh_big_free(m->x); mesh_big_free(m->cells); free(m->cell_tag); free(m->bf_verts); free(m->bf_tag);
  free_names(m->bnames, m->nbname);
  free_names(m->cnames, m->ncname);
  free(m);
}

mesh *mesh_copy(const mesh *m) {
  char err[MESH_ERRLEN];
  mesh *c = mesh_create(m->type, m->nvert, m->x, m->ncell, m->cells, err);
  if (!c) return NULL;
  memcpy(c->cell_tag, m->cell_tag, sizeof(int) * (size_t)m->ncell);
  if (m->nbf) {
    c->bf_verts = malloc(sizeof(int) * (size_t)m->nbf * (size_t)m->nvf);
    c->bf_tag = malloc(sizeof(int) * (size_t)m->nbf);
    if (!c->bf_verts || !c->bf_tag) { mesh_free(c); return NULL; }
    memcpy(c->bf_verts, m->bf_verts, sizeof(int) * (size_t)m->nbf * (size_t)m->nvf);
    memcpy(c->bf_tag, m->bf_tag, sizeof(int) * (size_t)m->nbf);
    c->nbf = m->nbf;
  }
  if (copy_names(&c->bnames, &c->nbname, &c->capbname, m->bnames, m->nbname) ||
      copy_names(&c->cnames, &c->ncname, &c->capcname, m->cnames, m->ncname)) {
    mesh_free(c);
    return NULL;
  }
  return c;
}

static int set_name(mesh_name **tab, int *n, int *cap, int tag, const char *name, char *err) {
  for (int i = 0; i < *n; i++) {
    if ((*tab)[i].tag == tag) {
      char *s = strdup(name);
      if (!s) { seterr(err, "out of memory"); return 1; }
      free((*tab)[i].name);
      (*tab)[i].name = s;
      return 0;
    }
  }
  if (*n == *cap) {
    int nc = *cap ? 2 * *cap : 8;
    mesh_name *nt = realloc(*tab, sizeof(mesh_name) * (size_t)nc);
    if (!nt) { seterr(err, "out of memory"); return 1; }
    *tab = nt;
    *cap = nc;
  }
  char *s = strdup(name);
  if (!s) { seterr(err, "out of memory"); return 1; }
  (*tab)[*n].tag = tag;
  (*tab)[*n].name = s;
  (*n)++;
  return 0;
}

static void free_names(mesh_name *tab, int n) {
  for (int i = 0; i < n; i++) free(tab[i].name);
  free(tab);
}

static int copy_names(mesh_name **dst, int *nd, int *capd, const mesh_name *src, int n) {
  *dst = NULL;
  *nd = *capd = 0;
  for (int i = 0; i < n; i++)
    if (set_name(dst, nd, capd, src[i].tag, src[i].name, NULL)) return 1;
  return 0;
}

int mesh_set_boundary_name(mesh *m, int tag, const char *name) {
  return set_name(&m->bnames, &m->nbname, &m->capbname, tag, name, m->err);
}
int mesh_set_region_name(mesh *m, int tag, const char *name) {
  return set_name(&m->cnames, &m->ncname, &m->capcname, tag, name, m->err);
}

int mesh_add_boundary_facets(mesh *m, int n, const int *verts, int tag, const char *name) {
  if (n < 0 || n > 0x3fffffff - m->nbf) { seterr(m->err, "bad boundary facet count %d", n); return 1; }
  for (int i = 0; i < n * m->nvf; i++) {
    if (verts[i] < 0 || verts[i] >= m->nvert) {
      seterr(m->err, "boundary facet %d refers to vertex %d, but the mesh has %d vertices",
             i / m->nvf + 1, verts[i] + 1, m->nvert);
      return 1;
    }
  }
  int *bv = realloc(m->bf_verts, sizeof(int) * (size_t)(m->nbf + n) * (size_t)m->nvf + 1);
  if (!bv) { seterr(m->err, "out of memory"); return 1; }
  m->bf_verts = bv;
  int *bt = realloc(m->bf_tag, sizeof(int) * (size_t)(m->nbf + n) + 1);
  if (!bt) { seterr(m->err, "out of memory"); return 1; }
  m->bf_tag = bt;
  if (n) memcpy(m->bf_verts + (size_t)m->nbf * (size_t)m->nvf, verts,
         sizeof(int) * (size_t)n * (size_t)m->nvf);
  for (int i = 0; i < n; i++) m->bf_tag[m->nbf + i] = tag;
  m->nbf += n;
  free(m->bf_cell); free(m->bf_local);
  m->bf_cell = m->bf_local = NULL;
  if (name) return mesh_set_boundary_name(m, tag, name);
  return 0;
}

static int icmp(const void *a, const void *b) {
  int x = *(const int *)a, y = *(const int *)b;
  return (x > y) - (x < y);
}

static int find_names(const mesh_name *tab, int n, const char *name, int *tags, int max) {
  int k = 0;
  for (int i = 0; i < n; i++)
    if (!strcmp(tab[i].name, name)) {
      if (k < max) tags[k] = tab[i].tag;
      k++;
    }
  if (tags) qsort(tags, (size_t)(k < max ? k : max), sizeof(int), icmp);
  return k;
}
int mesh_boundary_tags(const mesh *m, const char *name, int *tags, int max) {
  return find_names(m->bnames, m->nbname, name, tags, max);
}
int mesh_region_tags(const mesh *m, const char *name, int *tags, int max) {
  return find_names(m->cnames, m->ncname, name, tags, max);
}

/* distinct nonzero values of v[0..n) ascending: count, up to max written */
static int distinct_tags(const int *v, int n, int *tags, int max) {
  int *s = malloc(sizeof(int) * (size_t)n + 1);
  if (!s) return -1;
  int k = 0;
  for (int i = 0; i < n; i++)
    if (v[i]) s[k++] = v[i];
  qsort(s, (size_t)k, sizeof(int), icmp);
  int d = 0;
  for (int i = 0; i < k; i++) {
    if (i && s[i] == s[i - 1]) continue;
    if (d < max) tags[d] = s[i];
    d++;
  }
  free(s);
  return d;
}
int mesh_used_boundary_tags(const mesh *m, int *tags, int max) { return distinct_tags(m->bf_tag, m->nbf, tags, max); }
int mesh_used_region_tags(const mesh *m, int *tags, int max) { return distinct_tags(m->cell_tag, m->ncell, tags, max); }
int mesh_has_boundary_tag(const mesh *m, int tag) {
  for (int b = 0; b < m->nbf; b++)
    if (m->bf_tag[b] == tag) return 1;
  return 0;
}
int mesh_has_region_tag(const mesh *m, int tag) {
  for (int c = 0; c < m->ncell; c++)
    if (m->cell_tag[c] == tag) return 1;
  return 0;
}

static void list_names(const mesh_name *tab, int n, char *buf, size_t len) {
  size_t used = 0;
  buf[0] = 0;
  for (int i = 0; i < n; i++) {
    int dup = 0;
    for (int j = 0; j < i && !dup; j++) dup = !strcmp(tab[j].name, tab[i].name);
    if (dup) continue;
    size_t need = strlen(tab[i].name) + 4;
    if (used + need + 6 >= len) {
      snprintf(buf + used, len - used, "%s...", used ? ", " : "");
      return;
    }
    used += (size_t)snprintf(buf + used, len - used, "%s\"%s\"", used ? ", " : "", tab[i].name);
  }
  if (!n) snprintf(buf, len, "(none)");
}
void mesh_boundary_names(const mesh *m, char *buf, size_t len) { list_names(m->bnames, m->nbname, buf, len); }
void mesh_region_names(const mesh *m, char *buf, size_t len) { list_names(m->cnames, m->ncname, buf, len); }

/* ---------------------------------------------------------------- geometry */

static double det3(const double *a, const double *b, const double *c) {
  return a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) +
         a[2] * (b[0] * c[1] - b[1] * c[0]);
}

/* hexahedron corner neighbours in right-handed order (Knupp / Verdict) */
static const int hex_corner[8][3] = {{1, 3, 4}, {2, 0, 5}, {3, 1, 6}, {0, 2, 7},
                                     {7, 5, 0}, {4, 6, 1}, {5, 7, 2}, {6, 4, 3}};

const int *hex_corner_neighbors(int i) { return hex_corner[i]; }

/* minimum corner Jacobian determinant of a quad or hex (the untangling paper's validity:
 * every corner Jacobian positive) */
double mesh_min_corner_jacobian(const mesh *m, int c) {
  const int *v = m->cells + (size_t)c * (size_t)m->nvc;
  double mn = INFINITY;
  if (m->type == CELL_QUADRILATERAL) {
    for (int i = 0; i < 4; i++) {
      const double *p = m->x + 2 * v[i], *a = m->x + 2 * v[(i + 1) % 4],
                   *b = m->x + 2 * v[(i + 3) % 4];
      double j = (a[0] - p[0]) * (b[1] - p[1]) - (a[1] - p[1]) * (b[0] - p[0]);
      if (j < mn) mn = j;
    }
  } else {
    for (int i = 0; i < 8; i++) {
      const double *p = m->x + 3 * v[i];
      double e[3][3];
      for (int k = 0; k < 3; k++)
        for (int d = 0; d < 3; d++) e[k][d] = m->x[3 * v[hex_corner[i][k]] + d] - p[d];
      double j = det3(e[0], e[1], e[2]);
      if (j < mn) mn = j;
    }
  }
  return mn;
}

double mesh_cell_signed_measure(const mesh *m, int c) {
  const int *v = m->cells + (size_t)c * (size_t)m->nvc;
  const double *x = m->x;
  switch (m->type) {
  case CELL_INTERVAL: return x[v[1]] - x[v[0]];
  case CELL_TRIANGLE: {
    const double *a = x + 2 * v[0], *b = x + 2 * v[1], *d = x + 2 * v[2];
    return 0.5 * ((b[0] - a[0]) * (d[1] - a[1]) - (b[1] - a[1]) * (d[0] - a[0]));
  }
  case CELL_QUADRILATERAL: {
    double s = 0;
    for (int i = 0; i < 4; i++) {
      const double *a = x + 2 * v[i], *b = x + 2 * v[(i + 1) % 4];
      s += a[0] * b[1] - a[1] * b[0];
    }
    return 0.5 * s;
  }
  case CELL_TETRAHEDRON: {
    double e[3][3];
    for (int k = 0; k < 3; k++)
      for (int d = 0; d < 3; d++) e[k][d] = x[3 * v[k + 1] + d] - x[3 * v[0] + d];
    return det3(e[0], e[1], e[2]) / 6.0;
  }
  default: {
    double h[24];
    for (int i = 0; i < 8; i++)
      for (int d = 0; d < 3; d++) h[3 * i + d] = x[3 * v[i] + d];
    return hex_signed_volume(h);
  }
  }
}

double hex_signed_volume(const double *x) {
  /* divergence theorem over the 6 (possibly non-planar) faces, each split into 4 triangles
   * about its centroid; hex_facets are oriented outward */
  double vol = 0;
  for (int f = 0; f < 6; f++) {
    double cf[3] = {0, 0, 0};
    for (int k = 0; k < 4; k++)
      for (int d = 0; d < 3; d++) cf[d] += 0.25 * x[3 * hex_facets[f][k] + d];
    for (int k = 0; k < 4; k++) {
      const double *a = x + 3 * hex_facets[f][k], *b = x + 3 * hex_facets[f][(k + 1) % 4];
      vol += det3(cf, a, b) / 6.0;
    }
  }
  return vol;
}

/* the length of a d-vector without overflow or underflow of its squares */
static double vec_length(const double *t, int d) {
  double a = 0;
  for (int k = 0; k < d; k++) a = fmax(a, fabs(t[k]));
  if (a == 0 || !(a < INFINITY)) return a;
  if (a > 1e-150 && a < 1e150) {
    double s = 0;
    for (int k = 0; k < d; k++) s += t[k] * t[k];
    return sqrt(s);
  }
  double s = 0;
  for (int k = 0; k < d; k++) s += (t[k] / a) * (t[k] / a);
  return a * sqrt(s);
}

/* the old loop: each edge's length without overflow or underflow (vec_length) */
static double hmax_scaled(const mesh *m) {
  double h = 0;
  int ne = cell_nedges(m->type), d = m->dim;
  for (int c = 0; c < m->ncell; c++) {
    const int *v = m->cells + (size_t)c * (size_t)m->nvc;
    for (int e = 0; e < ne; e++) {
      const int *ev = cell_edge_verts(m->type, e);
      double t[3];
      for (int k = 0; k < d; k++) t[k] = m->x[(size_t)d * v[ev[0]] + k] - m->x[(size_t)d * v[ev[1]] + k];
      double l = vec_length(t, d);
      if (l > h || isnan(l)) h = l;
      if (isnan(h)) return h;
    }
  }
  return h;
}

/* One pass (on threads for large meshes) of the longest squared edge and the largest
 * coordinate difference: where that difference is in the range where squares neither
 * overflow nor underflow the longest edge is the square root of the first, the same bits as
 * the edge-by-edge lengths (sqrt is monotone and correctly rounded; an edge too short for
 * its square is not the longest), else that loop runs (hmax_scaled). With the validity
 * check this ran before every first assembly: 15% of a P1 N = 64 setup and assembly. */
double mesh_hmax(const mesh *m) {
  int ne = cell_nedges(m->type), d = m->dim, nc = m->ncell, nvc = m->nvc;
  int ev[12][2];
  for (int e = 0; e < ne; e++) ev[e][0] = cell_edge_verts(m->type, e)[0], ev[e][1] = cell_edge_verts(m->type, e)[1];
  double h2 = 0, amax = 0;
  int bad = 0;
  const double *x = m->x;
#ifdef _OPENMP
#pragma omp parallel for schedule(static) reduction(max : h2, amax) reduction(| : bad) if (nc > 100000)
#endif
  for (int c = 0; c < nc; c++) {
    const int *v = m->cells + (size_t)c * (size_t)nvc;
    for (int e = 0; e < ne; e++) {
      const double *a = x + (size_t)d * (size_t)v[ev[e][0]], *b = x + (size_t)d * (size_t)v[ev[e][1]];
      double s2 = 0;
      for (int k = 0; k < d; k++) {
        double t = a[k] - b[k];
        s2 += t * t;
        if (fabs(t) > amax) amax = fabs(t);
        bad |= t != t;
      }
      if (s2 > h2) h2 = s2;
    }
  }
  if (bad) return NAN;
  if (amax > 1e-150 && amax < 1e150) return sqrt(h2);
  return hmax_scaled(m);
}

int points_normalized(int nv, int d, const double *in, double *out) {
  int n = nv * d;
  double amax = 0;
  for (int i = 0; i < n; i++) {
    double a = fabs(in[i]);
    if (!(a <= 1.79e308)) { /* NaN or infinite */
      for (int k = 0; k < n; k++) out[k] = NAN;
      return 0;
    }
    if (a > amax) amax = a;
  }
  /* huge coordinates: scale first so that differences cannot overflow */
  int e1 = 0;
  if (amax > 0x1p900) {
    frexp(amax, &e1);
    for (int i = 0; i < n; i++) out[i] = ldexp(in[i], -e1);
    for (int i = n - 1; i >= 0; i--) out[i] -= out[i % d];
  } else {
    for (int i = 0; i < n; i++) out[i] = in[i] - in[i % d];
  }
  double dmax = 0;
  for (int i = d; i < n; i++) {
    double a = fabs(out[i]);
    if (a > dmax) dmax = a;
  }
  if (dmax == 0) return 0;
  int e2;
  frexp(dmax, &e2);
  if (e2 != 0) {
    if (e2 > -1000 && e2 < 1000) { /* a multiplication by a power of two is exact */
      double s = ldexp(1.0, -e2);
      for (int i = d; i < n; i++) out[i] *= s;
    } else
      for (int i = d; i < n; i++) out[i] = ldexp(out[i], -e2);
  }
  return e1 + e2;
}

int mesh_cell_normalized(const mesh *m, int c, double *out) {
  double x[8 * 3];
  const int *v = m->cells + (size_t)c * (size_t)m->nvc;
  int d = m->dim;
  for (int i = 0; i < m->nvc; i++)
    for (int k = 0; k < d; k++) x[i * d + k] = m->x[(size_t)v[i] * d + k];
  return points_normalized(m->nvc, d, x, out);
}

/* signed measure of a cell given its (normalized) coordinates */
static double coords_signed_measure(cell_type t, const double *x) {
  switch (t) {
  case CELL_INTERVAL: return x[1] - x[0];
  case CELL_TRIANGLE:
    return 0.5 * ((x[2] - x[0]) * (x[5] - x[1]) - (x[3] - x[1]) * (x[4] - x[0]));
  case CELL_QUADRILATERAL: {
    double s = 0;
    for (int i = 0; i < 4; i++) s += x[2 * i] * x[2 * ((i + 1) % 4) + 1] - x[2 * i + 1] * x[2 * ((i + 1) % 4)];
    return 0.5 * s;
  }
  case CELL_TETRAHEDRON: {
    double e[3][3];
    for (int k = 0; k < 3; k++)
      for (int d = 0; d < 3; d++) e[k][d] = x[3 * (k + 1) + d] - x[d];
    return det3(e[0], e[1], e[2]) / 6.0;
  }
  default: return hex_signed_volume(x);
  }
}

static double coords_min_corner_jacobian(cell_type t, const double *x) {
  double mn = INFINITY;
  if (t == CELL_QUADRILATERAL) {
    for (int i = 0; i < 4; i++) {
      const double *p = x + 2 * i, *a = x + 2 * ((i + 1) % 4), *b = x + 2 * ((i + 3) % 4);
      double j = (a[0] - p[0]) * (b[1] - p[1]) - (a[1] - p[1]) * (b[0] - p[0]);
      if (j < mn) mn = j;
    }
    return mn;
  }
  for (int i = 0; i < 8; i++) {
    const double *p = x + 3 * i;
    double e[3][3];
    for (int k = 0; k < 3; k++)
      for (int d = 0; d < 3; d++) e[k][d] = x[3 * hex_corner[i][k] + d] - p[d];
    double j = det3(e[0], e[1], e[2]);
    if (j < mn) mn = j;
  }
  return mn;
}

double mesh_cell_relative_validity(const mesh *m, int c) {
  double x[8 * 3];
  mesh_cell_normalized(m, c, x);
  if (isnan(x[0])) return NAN;
  if (m->type == CELL_INTERVAL) return x[1] - x[0] > 0 ? 1 : x[1] - x[0] < 0 ? -1 : 0; /* normalized: the sign */
  double q = m->type == CELL_QUADRILATERAL || m->type == CELL_HEXAHEDRON ? coords_min_corner_jacobian(m->type, x)
                                                                           : coords_signed_measure(m->type, x);
  /* relative to the longest edge to the power dim (the coordinates are O(1) now) */
  double h = 0;
  int ne = cell_nedges(m->type), d = m->dim;
  for (int e = 0; e < ne; e++) {
    const int *ev = cell_edge_verts(m->type, e);
    double s = 0;
    for (int k = 0; k < d; k++) {
      double t = x[ev[0] * d + k] - x[ev[1] * d + k];
      s += t * t;
    }
    if (s > h) h = s;
  }
  if (h == 0) return 0;
  return q / (d == 2 ? h : h * sqrt(h));
}

/* the validity check's decision (relative validity above 1e-13) for a triangle or
 * tetrahedron without the normalization, the division or the square root: when its
 * coordinates and their differences are in a range where scaling by a power of two is exact,
 * q = (det / d!) / h^(d/2) (h the longest squared edge) is compared as det^2 against
 * (d! 1e-13)^2 h^d, and only a value within 1e-9 of the threshold is computed as
 * mesh_cell_relative_validity does. Returns 1 valid, 0 invalid, -1 when outside the range
 * (the caller takes the slow path). The check runs before every first assembly; the
 * normalization was 20% of the setup of a P1 problem on 1.5 M tetrahedra */
/* inlined where d is a constant (mesh_validate): the loops unroll (not inlined, the pass took
 * 43 ns per tetrahedron, half of it in the call's loops over d) */
#if defined(__GNUC__)
#define MESH_INLINE static inline __attribute__((always_inline))
#else
#define MESH_INLINE static inline
#endif
MESH_INLINE int simplex_valid_at(const double *const *p, int d) {
  double e[4][3];
  const double *p0 = p[0];
  double amax = 0, dmax = 0;
  for (int k = 0; k < d; k++) { double a = fabs(p0[k]); if (!(a <= amax)) amax = a; }
  for (int i = 1; i <= d; i++)
    for (int k = 0; k < d; k++) {
      double a = fabs(p[i][k]), t = p[i][k] - p0[k];
      if (!(a <= amax)) amax = a;
      e[i][k] = t;
      if (!(fabs(t) <= dmax)) dmax = fabs(t);
    }
  /* an infinite coordinate fails the range test; a NaN may not (a later comparison can
   * drop it), but it makes det NaN, which takes the slow path below */
  if (!(amax < 0x1p900) || !(dmax > 0x1p-200) || !(dmax < 0x1p200)) return -1;
  for (int k = 0; k < d; k++) e[0][k] = 0;
  double det;
  if (d == 2) det = e[1][0] * e[2][1] - e[1][1] * e[2][0];
  else det = det3(e[1], e[2], e[3]);
  if (!(det > 0)) return det == det ? 0 : -1;
  const int(*ev)[2] = d == 2 ? tri_edges : tet_edges;
  double h = 0;
  for (int k = 0; k < (d == 2 ? 3 : 6); k++) {
    double s2 = 0;
    for (int j = 0; j < d; j++) {
      double t = e[ev[k][0]][j] - e[ev[k][1]][j];
      s2 += t * t;
    }
    if (s2 > h) h = s2;
  }
  static const double c2 = 4e-26, c3 = 36e-26; /* (2 1e-13)^2, (6 1e-13)^2 */
  double lhs = det * det, rhs = d == 2 ? c2 * h * h : c3 * h * h * h;
  if (lhs > rhs * (1 + 1e-9)) return 1;
  if (lhs < rhs * (1 - 1e-9)) return 0;
  return -1;
}

static int fast_simplex_valid(const mesh *m, int c) {
  const int *v = m->cells + (size_t)c * (size_t)m->nvc;
  const double *p[4];
  for (int i = 0; i < m->nvc && i < 4; i++) p[i] = m->x + (size_t)m->dim * (size_t)v[i];
  return simplex_valid_at(p, m->dim);
}

static int cell_valid(const mesh *m, int simplex, int c) {
  int ok = simplex ? fast_simplex_valid(m, c) : -1;
  return ok < 0 ? mesh_cell_relative_validity(m, c) > 1e-13 : ok;
}

/* the count on OpenMP threads (every assembly's first check of a mesh: 1.57 M tetrahedra),
 * the first invalid cells, in cell order, by a second pass only when there are some */
int mesh_count_invalid(const mesh *m, int maxids, int *ids, int *ninv) {
  int n = 0, nc = m->ncell;
  int simplex = (m->type == CELL_TRIANGLE && m->dim == 2) || (m->type == CELL_TETRAHEDRON && m->dim == 3);
#ifdef _OPENMP
#pragma omp parallel for schedule(static) reduction(+ : n) if (nc > 100000)
#endif
  for (int c = 0; c < nc; c++) n += !cell_valid(m, simplex, c);
  for (int c = 0, k = 0; ids && n && k < maxids && c < nc; c++)
    if (!cell_valid(m, simplex, c)) ids[k++] = c;
  *ninv = n;
  return 0;
}

/* a triangle's edges for mesh_validate, given its vertices: the longest squared edge, NaN
 * seen (a tetrahedron's come from tet_validate) */
MESH_INLINE void triangle_edges_at(const double *const *p, double *h2, int *bad) {
  for (int e = 0; e < 3; e++) {
    const double *a = p[tri_edges[e][0]], *b = p[tri_edges[e][1]];
    double s2 = 0;
    for (int k = 0; k < 2; k++) {
      double t = a[k] - b[k];
      s2 += t * t;
      *bad |= t != t;
    }
    if (s2 > *h2) *h2 = s2;
  }
}

/* one tetrahedron for mesh_validate, written out: simplex_valid_at's decision (1, 0, -1: the
 * slow path), the same operations in the same order, and its six squared edges, from the
 * differences to the first vertex, as the longest edge (*h2; *nan: a NaN coordinate). The
 * loops over the edge tables took 43 ns per cell, with mesh_hmax's edges beside them */
#define TET_MAX(m, v) ((v) > (m) ? (v) : (m))
static inline int tet_validate(const double *p0, const double *p1, const double *p2, const double *p3, double *h2,
                               int *nan) {
  double cm = 0, dm = 0;
  for (int k = 0; k < 3; k++) cm = TET_MAX(cm, fabs(p0[k]));
  double e[3][3];
  const double *pi[3] = {p1, p2, p3};
  for (int i = 0; i < 3; i++)
    for (int k = 0; k < 3; k++) {
      double t = pi[i][k] - p0[k];
      cm = TET_MAX(cm, fabs(pi[i][k]));
      e[i][k] = t;
      dm = TET_MAX(dm, fabs(t));
    }
  /* the edges (0,i) are e[i - 1]; (2,3), (1,3), (1,2) their differences */
  double hv = 0;
  for (int i = 0; i < 3; i++) hv = TET_MAX(hv, e[i][0] * e[i][0] + e[i][1] * e[i][1] + e[i][2] * e[i][2]);
  static const int pr[3][2] = {{1, 2}, {0, 2}, {0, 1}};
  for (int k = 0; k < 3; k++) {
    const double *a = e[pr[k][0]], *b = e[pr[k][1]];
    double t0 = a[0] - b[0], t1 = a[1] - b[1], t2 = a[2] - b[2];
    hv = TET_MAX(hv, t0 * t0 + t1 * t1 + t2 * t2);
  }
  double det = det3(e[0], e[1], e[2]);
  *h2 = TET_MAX(*h2, hv);
  if (det != det) /* a NaN coordinate makes det NaN, and so may huge ones (inf - inf) */
    for (int k = 0; k < 3; k++) *nan |= p0[k] != p0[k] || p1[k] != p1[k] || p2[k] != p2[k] || p3[k] != p3[k];
  /* an infinite coordinate fails the range test; a NaN makes det NaN: the slow path */
  if (!(cm < 0x1p900) || !(dm > 0x1p-200) || !(dm < 0x1p200)) return -1;
  if (!(det > 0)) return det == det ? 0 : -1;
  double lhs = det * det, rhs = 36e-26 * hv * hv * hv; /* (6 1e-13)^2 */
  if (lhs > rhs * (1 + 1e-9)) return 1;
  if (lhs < rhs * (1 - 1e-9)) return 0;
  return -1;
}
#undef TET_MAX

/* mesh_validate's pass over the simplices of dimension d: each cell's vertices read once for
 * its edges and its validity */
static int simplex_check_pass(const mesh *m, int d, double *h2out, int *badout) {
  int n = 0, nc = m->ncell, nvc = m->nvc, bad = 0;
  double h2 = 0;
  const double *x = m->x;
#ifdef _OPENMP
#pragma omp parallel for schedule(static) reduction(max : h2) reduction(| : bad) reduction(+ : n) if (nc > 100000)
#endif
  for (int c = 0; c < nc; c++) {
    const int *v = m->cells + (size_t)c * (size_t)nvc;
    int ok;
    if (d == 3) ok = tet_validate(x + 3 * (size_t)v[0], x + 3 * (size_t)v[1], x + 3 * (size_t)v[2], x + 3 * (size_t)v[3], &h2, &bad);
    else {
      const double *p[3] = {x + 2 * (size_t)v[0], x + 2 * (size_t)v[1], x + 2 * (size_t)v[2]};
      triangle_edges_at(p, &h2, &bad);
      ok = simplex_valid_at(p, 2);
    }
    n += ok < 0 ? !(mesh_cell_relative_validity(m, c) > 1e-13) : !ok;
  }
  *h2out = h2;
  *badout = bad;
  return n;
}

int mesh_validate(const mesh *m, double *hmax, int maxids, int *ids, int *ninv) {
  int d = m->dim, n;
  if (m->ncell == 0) {
    *hmax = 1;
    *ninv = 0;
    return 0;
  }
  if (!((m->type == CELL_TRIANGLE && d == 2) || (m->type == CELL_TETRAHEDRON && d == 3))) {
    *hmax = mesh_hmax(m);
    return mesh_count_invalid(m, maxids, ids, ninv);
  }
  double h2;
  int bad;
  n = simplex_check_pass(m, d, &h2, &bad);
  /* the squared edges' range where no square overflowed and the longest one's did not
   * underflow; else the edge-by-edge loop */
  *hmax = bad ? NAN : h2 > 1e-290 && h2 < 1e290 ? sqrt(h2) : hmax_scaled(m);
  for (int c = 0, k = 0; ids && n && k < maxids && c < m->ncell; c++)
    if (!cell_valid(m, 1, c)) ids[k++] = c;
  *ninv = n;
  return 0;
}

int mesh_cells_negative(const mesh *m, const char *which) {
  double x[8 * 3];
  for (int c = 0; c < m->ncell; c++) {
    if (which && !which[c]) continue;
    mesh_cell_normalized(m, c, x);
    if (!(coords_signed_measure(m->type, x) < 0)) return 0;
  }
  return 1;
}

int mesh_orient_consistently(mesh *m) {
  if (m->ncell == 0 || !mesh_cells_negative(m, NULL)) return 0;
  mesh_flip_cells(m);
  return 1;
}

void mesh_flip_cells(mesh *m) {
  int nvc = m->nvc;
  for (int c = 0; c < m->ncell; c++) {
    int *v = m->cells + (size_t)c * (size_t)nvc, t;
    switch (m->type) {
    case CELL_TRIANGLE: case CELL_TETRAHEDRON: case CELL_INTERVAL:
      t = v[nvc - 1]; v[nvc - 1] = v[nvc - 2]; v[nvc - 2] = t;
      break;
    case CELL_QUADRILATERAL:
      t = v[1]; v[1] = v[3]; v[3] = t;
      break;
    case CELL_HEXAHEDRON:
      for (int k = 0; k < 4; k++) { t = v[k]; v[k] = v[k + 4]; v[k + 4] = t; }
      break;
    }
  }
}

/* ---------------------------------------------------------------- adjacency */

/* the cells' local entities for number_entities: a slot is (cell, entity), numbered
 * cell * nper + entity */
typedef struct {
  const int *cells;
  int nvc, nper, klen;
  int lv[12][4]; /* each local entity's vertices */
} slot_table;

/* the vertex tuple of entity e of cell c, sorted by a network on locals (an insertion sort in
 * the array stalled on its stores: three quarters of the time) */
static inline void slot_key(const slot_table *T, int c, int e, int *k) {
  const int *v = T->cells + (size_t)c * (size_t)T->nvc, *lv = T->lv[e];
#define SLOT_CS(a, b) do { int lo_ = a < b ? a : b, hi_ = a < b ? b : a; a = lo_; b = hi_; } while (0)
  int a = v[lv[0]], b = v[lv[1]], x = T->klen > 2 ? v[lv[2]] : INT_MAX, y = T->klen > 3 ? v[lv[3]] : INT_MAX;
  SLOT_CS(a, b); SLOT_CS(x, y); SLOT_CS(a, x); SLOT_CS(b, y); SLOT_CS(b, x);
#undef SLOT_CS
  k[0] = a, k[1] = b;
  if (T->klen > 2) k[2] = x;
  if (T->klen > 3) k[3] = y;
}

static inline void slot_key_of(const slot_table *T, int s, int *k) {
  unsigned c = (unsigned)s / (unsigned)T->nper;
  slot_key(T, (int)c, s - (int)c * T->nper, k);
}

/* number the distinct vertex tuples (edges or faces) of the cells: per cell, the ids of its
 * `nper` local entities (from `local`, klen vertices each), numbered in the order of their
 * first cell; the sorted tuples go to *list. The slots (cell, entity) are put in buckets by
 * their smallest vertex, a bucket's distinct tuples found by comparing within it (a marker
 * on the other vertex for edges), then numbered in cell order. This replaced a hash table
 * sized for every slot, whose random accesses took 850 ms for the edges of 1.57 M
 * tetrahedra (20 ms for the 83 k of a P2 N = 24 problem, a quarter of its setup) */
static int number_entities(mesh *m, int nper, int klen, const int *(*local)(cell_type, int),
                           int **cell_ids, int **list, int *count) {
  size_t ns = (size_t)m->ncell * (size_t)nper;
  int nv = m->nvert, nc = m->ncell, n = 0, *mark = NULL;
  *list = NULL;
  *cell_ids = malloc(sizeof(int) * (ns + 1));
  size_t *start = calloc((size_t)nv + 2, sizeof(size_t));
  int *slot = malloc(sizeof(int) * (ns + 1)), *newid = NULL, *rep = NULL;
  if (!*cell_ids || !start || !slot || ns > (size_t)INT_MAX || nper > 12) goto oom;
  slot_table T = {m->cells, m->nvc, nper, klen, {{0}}};
  for (int e = 0; e < nper; e++) memcpy(T.lv[e], local(m->type, e), sizeof(int) * (size_t)klen);
  int k[4] = {0, 0, 0, 0};
  for (int c = 0; c < nc; c++)
    for (int e = 0; e < nper; e++) {
      slot_key(&T, c, e, k);
      start[(size_t)k[0] + 2]++;
    }
  for (int v = 0; v < nv; v++) start[v + 2] += start[v + 1];
  for (int c = 0, s = 0; c < nc; c++)
    for (int e = 0; e < nper; e++, s++) {
      slot_key(&T, c, e, k);
      slot[start[(size_t)k[0] + 1]++] = s;
    }
  /* bucket v: slots start[v] .. start[v + 1] - 1 in cell order; provisional ids in
   * cell_ids, each the first slot that has the tuple (rep: a bucket's distinct tuples) */
  size_t maxb = 0;
  for (int v = 0; v < nv; v++) if (start[v + 1] - start[v] > maxb) maxb = start[v + 1] - start[v];
  rep = malloc(sizeof(int) * 4 * (maxb + 1)); /* edges: the other vertices; else slot and key */
  if (klen == 2) mark = malloc(sizeof(int) * ((size_t)nv + 1));
  if (!rep || (klen == 2 && !mark)) goto oom;
  if (mark) for (int v = 0; v < nv; v++) mark[v] = -1;
  for (int v = 0; v < nv; v++) {
    size_t nrep = 0;
    for (size_t i = start[v]; i < start[v + 1]; i++) {
      int s = slot[i], found = -1;
      slot_key_of(&T, s, k);
      if (mark) {
        found = mark[k[1]];
        if (found < 0) mark[k[1]] = s, rep[nrep++] = k[1];
      } else {
        for (size_t r = 0; r < nrep && found < 0; r++) {
          const int *q = rep + 4 * r; /* the slot, then the key's vertices after v */
          if (q[1] == k[1] && q[2] == k[2] && (klen < 4 || q[3] == k[3])) found = q[0];
        }
        if (found < 0) {
          int *q = rep + 4 * nrep++;
          q[0] = s, q[1] = k[1], q[2] = k[2], q[3] = klen > 3 ? k[3] : 0;
        }
      }
      (*cell_ids)[s] = found < 0 ? s : found;
    }
    if (mark) /* the bucket's other vertices back to unmarked */
      for (size_t r = 0; r < nrep; r++) mark[rep[r]] = -1;
  }
  /* ids in the order of each tuple's first slot: a first slot is its own provisional id */
  newid = slot; /* reused: the buckets are done */
  for (size_t s = 0; s < ns; s++) {
    int p = (*cell_ids)[s];
    (*cell_ids)[s] = p == (int)s ? (newid[s] = n++) : newid[p];
  }
  *list = malloc(sizeof(int) * (size_t)klen * (size_t)(n + 1));
  if (!*list) goto oom;
  for (int c = 0, s = 0, id = 0; c < nc; c++)
    for (int e = 0; e < nper; e++, s++)
      if ((*cell_ids)[s] == id) { /* the tuple's first slot */
        slot_key(&T, c, e, *list + (size_t)klen * (size_t)id);
        id++;
      }
  *count = n;
  free(start); free(slot); free(rep); free(mark);
  return 0;
oom:
  free(start); free(slot); free(rep); free(mark);
  free(*cell_ids);
  free(*list);
  *cell_ids = *list = NULL;
  seterr(m->err, "out of memory numbering mesh entities");
  return 1;
}

int mesh_build_edges(mesh *m) {
  if (m->edges) return 0;
  return number_entities(m, cell_nedges(m->type), 2, cell_edge_verts, &m->cell_edges, &m->edges, &m->nedge);
}

int mesh_build_faces(mesh *m) {
  if (m->faces || (m->type != CELL_TETRAHEDRON && m->type != CELL_HEXAHEDRON)) return 0;
  return number_entities(m, cell_nfacets(m->type), m->nvf, cell_facet_verts, &m->cell_faces, &m->faces, &m->nface);
}

void mesh_perm_of_rank(int n, int r, int *p) {
  int used[4] = {0, 0, 0, 0}, fact = 1;
  for (int i = 2; i < n; i++) fact *= i;
  for (int k = 0; k < n; k++) {
    int q = n - 1 - k > 0 ? r / fact : 0;
    r -= q * fact;
    if (n - 1 - k > 1) fact /= n - 1 - k;
    for (int j = 0; j < n; j++)
      if (!used[j] && q-- == 0) { p[k] = j; used[j] = 1; break; }
  }
}

int mesh_perm_rank(int n, const int *p) {
  int nperm = 1;
  for (int i = 2; i <= n; i++) nperm *= i;
  for (int r = 0; r < nperm; r++) {
    int q[4];
    mesh_perm_of_rank(n, r, q);
    if (!memcmp(q, p, sizeof(int) * (size_t)n)) return r;
  }
  return -1;
}

int mesh_build_interior_facets(mesh *m) {
  if (m->if_cell || m->ncell == 0) return 0;
  int nf = cell_nfacets(m->type), *cf = NULL, *list = NULL, n = 0;
  if (number_entities(m, nf, m->nvf, cell_facet_verts, &cf, &list, &n)) return 1;
  free(list);
  /* the first and second cell of each facet */
  int *first = malloc(sizeof(int) * (size_t)(n + 1)), *second = malloc(sizeof(int) * (size_t)(n + 1));
  if (!first || !second) { free(cf); free(first); free(second); seterr(m->err, "out of memory"); return 1; }
  for (int i = 0; i < n; i++) first[i] = second[i] = -1;
  int nif = 0;
  for (int c = 0; c < m->ncell; c++)
    for (int f = 0; f < nf; f++) {
      int id = cf[(size_t)c * (size_t)nf + (size_t)f], slot = c * nf + f;
      if (first[id] < 0) first[id] = slot;
      else if (second[id] < 0) { second[id] = slot; nif++; }
      else {
        seterr(m->err, "a facet is shared by more than two cells (cells %d, %d and %d): the mesh is not a manifold there",
               first[id] / nf + 1, second[id] / nf + 1, c + 1);
        free(cf); free(first); free(second);
        return 1;
      }
    }
  free(cf);
  m->if_cell = malloc(sizeof(int) * (size_t)(2 * nif + 1));
  m->if_local = malloc(sizeof(int) * (size_t)(2 * nif + 1));
  m->if_perm = malloc(sizeof(int) * (size_t)(nif + 1));
  if (!m->if_cell || !m->if_local || !m->if_perm) {
    free(first); free(second);
    free(m->if_cell); free(m->if_local); free(m->if_perm);
    m->if_cell = m->if_local = m->if_perm = NULL;
    seterr(m->err, "out of memory");
    return 1;
  }
  int k = 0;
  for (int i = 0; i < n; i++) {
    if (second[i] < 0) continue;
    int cp = first[i] / nf, fp = first[i] % nf, cm = second[i] / nf, fm = second[i] % nf;
    const int *vp = m->cells + (size_t)cp * (size_t)m->nvc, *vm = m->cells + (size_t)cm * (size_t)m->nvc;
    const int *lp = cell_facet_verts(m->type, fp), *lm = cell_facet_verts(m->type, fm);
    int perm[4] = {0, 0, 0, 0};
    for (int a = 0; a < m->nvf; a++)
      for (int b = 0; b < m->nvf; b++)
        if (vp[lp[a]] == vm[lm[b]]) perm[a] = b;
    m->if_cell[2 * k] = cp;
    m->if_cell[2 * k + 1] = cm;
    m->if_local[2 * k] = fp;
    m->if_local[2 * k + 1] = fm;
    m->if_perm[k] = mesh_perm_rank(m->nvf, perm);
    k++;
  }
  free(first);
  free(second);
  m->nif = nif;
  return 0;
}

int mesh_build_boundary_cells(mesh *m) {
  if (m->bf_cell || m->nbf == 0) return 0;
  int nf = cell_nfacets(m->type);
  tuplehash h;
  if (th_init(&h, (size_t)m->nbf + 16, m->nvf)) goto oom;
  for (int b = 0; b < m->nbf; b++) {
    int found;
    if (th_get(&h, m->bf_verts + (size_t)b * (size_t)m->nvf, b, &found) == -2) goto oom;
  }
  m->bf_cell = malloc(sizeof(int) * (size_t)(unsigned)m->nbf);
  m->bf_local = malloc(sizeof(int) * (size_t)(unsigned)m->nbf);
  /* the vertices of tagged facets: a cell facet with an unmarked vertex is none of them, so
   * only the few facets near the boundary are looked up (the lookup of every facet of 1.5 M
   * tetrahedra was 0.2 s of a 3D problem's setup) */
  unsigned char *onb = calloc((size_t)m->nvert + 1, 1);
  if (!m->bf_cell || !m->bf_local || !onb) { free(onb); goto oom; }
  for (size_t i = 0; i < (size_t)m->nbf * (size_t)m->nvf; i++) onb[m->bf_verts[i]] = 1;
  for (int b = 0; b < m->nbf; b++) m->bf_cell[b] = -1;
  for (int c = 0; c < m->ncell; c++) {
    const int *v = m->cells + (size_t)c * (size_t)m->nvc;
    for (int f = 0; f < nf; f++) {
      const int *fv = cell_facet_verts(m->type, f);
      int k[4], found, all = 1;
      for (int i = 0; i < m->nvf; i++) { k[i] = v[fv[i]]; all &= onb[k[i]]; }
      if (!all) continue;
      int b = th_get(&h, k, -1, &found);
      if (b >= 0) {
        m->bf_cell[b] = c;
        m->bf_local[b] = f;
      }
    }
  }
  free(onb);
  /* duplicates of the same facet under different tags: resolve by direct lookup */
  for (int b = 0; b < m->nbf; b++) {
    if (m->bf_cell[b] >= 0) continue;
    int found;
    int first = th_get(&h, m->bf_verts + (size_t)b * (size_t)m->nvf, -1, &found);
    if (first >= 0 && m->bf_cell[first] >= 0) {
      m->bf_cell[b] = m->bf_cell[first];
      m->bf_local[b] = m->bf_local[first];
    }
  }
  th_free(&h);
  for (int b = 0; b < m->nbf; b++) {
    if (m->bf_cell[b] < 0) {
      seterr(m->err, "boundary facet %d (tag %d) is not a facet of any cell", b + 1,
             m->bf_tag[b]);
      free(m->bf_cell); free(m->bf_local);
      m->bf_cell = m->bf_local = NULL;
      return 1;
    }
  }
  return 0;
oom:
  th_free(&h);
  free(m->bf_cell); free(m->bf_local);
  m->bf_cell = m->bf_local = NULL;
  seterr(m->err, "out of memory matching boundary facets");
  return 1;
}

/* make every simplex positively oriented by swapping its last two vertices */
static void orient_simplices(mesh *m) {
  if (m->type != CELL_TRIANGLE && m->type != CELL_TETRAHEDRON) return;
  for (int c = 0; c < m->ncell; c++) {
    if (mesh_cell_signed_measure(m, c) < 0) {
      int *v = m->cells + (size_t)c * (size_t)m->nvc;
      int t = v[m->nvc - 1];
      v[m->nvc - 1] = v[m->nvc - 2];
      v[m->nvc - 2] = t;
    }
  }
}

mesh *mesh_interval(int nx, double x0, double x1, char *err) {
  if (nx < 1) { seterr(err, "nx must be at least 1 (got %d)", nx); return NULL; }
  if (!(x1 > x0) || !isfinite(x0) || !isfinite(x1)) { seterr(err, "need finite x0 < x1 (got %g, %g)", x0, x1); return NULL; }
  if (nx > 1000000000) { seterr(err, "nx = %d is too large", nx); return NULL; }
  mesh *m = mesh_create(CELL_INTERVAL, nx + 1, NULL, nx, NULL, err);
  if (!m) return NULL;
  for (int i = 0; i <= nx; i++) m->x[i] = i == nx ? x1 : x0 + (x1 - x0) * i / nx;
  for (int c = 0; c < nx; c++) { m->cells[2 * c] = c; m->cells[2 * c + 1] = c + 1; }
  int left = 0, right = nx;
  if (mesh_add_boundary_facets(m, 1, &left, 1, "left") || mesh_add_boundary_facets(m, 1, &right, 2, "right")) {
    seterr(err, "%s", m->err);
    mesh_free(m);
    return NULL;
  }
  return m;
}

/* the whole mesh's counts and layers (mesh.h); 1 with the reason in err when the options
 * are refused */
static int box_counts(const mesh_box_opts *o, long *nvert, long *ncell, int *layers, long *per_layer, char *err) {
  int nx = o->nx, ny = o->ny, nz = o->nz, box = o->type == CELL_TETRAHEDRON || o->type == CELL_HEXAHEDRON;
  *nvert = *ncell = *per_layer = 0;
  *layers = 0;
  if (box) {
    if (nx < 1 || ny < 1 || nz < 1) { seterr(err, "nx, ny and nz must be at least 1"); return 1; }
    if (!(o->x1 > o->x0) || !(o->y1 > o->y0) || !(o->z1 > o->z0)) { seterr(err, "need x0 < x1, y0 < y1 and z0 < z1"); return 1; }
    /* the counts in doubles first (exact below 2^53, no overflow), reported as they are */
    double dv = ((double)nx + 1) * ((double)ny + 1) * ((double)nz + 1),
           dc = (double)nx * ny * nz * (o->type == CELL_TETRAHEDRON ? 6 : 1);
    if (dv > 2e9 || dc * 8 > 2e9) {
      seterr(err, "a %d x %d x %d mesh is too large (%.0f vertices and %.0f cells; at most 2e9 vertices and 2.5e8 cells)", nx, ny,
             nz, dv, dc);
      return 1;
    }
    long nv = (long)dv, nc = (long)dc;
    *nvert = nv;
    *ncell = nc;
    *layers = nz;
    *per_layer = ((long)nx + 1) * ((long)ny + 1);
  } else if (o->type == CELL_TRIANGLE || o->type == CELL_QUADRILATERAL) {
    if (nx < 1 || ny < 1) { seterr(err, "nx and ny must be at least 1 (got %d, %d)", nx, ny); return 1; }
    if (!(o->x1 > o->x0) || !(o->y1 > o->y0)) { seterr(err, "need x0 < x1 and y0 < y1"); return 1; }
    int crossed = o->type == CELL_TRIANGLE && o->diagonal == 2;
    double dv = ((double)nx + 1) * ((double)ny + 1) + (crossed ? (double)nx * ny : 0),
           dc = (double)nx * ny * (o->type == CELL_QUADRILATERAL ? 1 : crossed ? 4 : 2); /* exact, no overflow */
    if (dv > 2e9 || dc * 4 > 2e9) {
      seterr(err, "a %d x %d mesh is too large (%.0f vertices and %.0f cells; at most 2e9 vertices and 5e8 cells)", nx, ny, dv, dc);
      return 1;
    }
    long nv = (long)dv, nc = (long)dc;
    *nvert = nv;
    *ncell = nc;
    *layers = crossed ? 0 : ny;
    *per_layer = crossed ? 0 : (long)nx + 1;
  } else {
    seterr(err, "a rectangle has triangles or quadrilaterals, a box tetrahedra or hexahedra");
    return 1;
  }
  int n = box ? nz : ny;
  if (o->hi && (o->lo < 0 || o->hi > n || o->lo >= o->hi)) {
    seterr(err, "the window of cell layers %d .. %d is not within 0 .. %d", o->lo, o->hi - 1, n - 1);
    return 1;
  }
  return 0;
}

void mesh_box_counts(const mesh_box_opts *o, long *nvert, long *ncell, int *layers, long *per_layer) {
  char err[MESH_ERRLEN];
  long nv, nc, per;
  int nl;
  box_counts(o, &nv, &nc, &nl, &per, err);
  if (nvert) *nvert = nv;
  if (ncell) *ncell = nc;
  if (layers) *layers = nl;
  if (per_layer) *per_layer = per;
}

int mesh_box_part_window(const mesh_box_opts *o, int nparts, int p, int layers, mesh_box_opts *w, long *vlo, long *vhi) {
  long nv, nc, per;
  int nl;
  mesh_box_counts(o, &nv, &nc, &nl, &per);
  if (!nl || nparts < 1 || p < 0 || p >= nparts || nv < nparts || layers < 1) return 1;
  /* the run: the vertices v with v nparts / nv = p. A cell of the part has its lowest
   * vertex there, in the cell's own lowest vertex layer; ghost layer g lies within g cell
   * layers of the part, the cells around its vertices within one more: a margin of
   * layers + 1 holds them all, and two layers are to spare */
  *vlo = ((long)p * nv + nparts - 1) / nparts;
  *vhi = ((long)(p + 1) * nv + nparts - 1) / nparts;
  int margin = layers + 3;
  *w = *o;
  w->lo = (int)(*vlo / per) - margin;
  w->hi = (int)((*vhi - 1) / per) + margin + 1;
  if (w->lo < 0) w->lo = 0;
  if (w->hi > nl) w->hi = nl;
  return 0;
}

void mesh_box_window_numbers(const mesh_box_opts *o, const mesh *w, int *vglob, int *cglob) {
  int box = o->type == CELL_TETRAHEDRON || o->type == CELL_HEXAHEDRON, lo = o->hi ? o->lo : 0;
  long nx = o->nx, ny = o->ny, plane = box ? (nx + 1) * (ny + 1) : nx + 1;
  long ncl = box ? nx * ny * (o->type == CELL_TETRAHEDRON ? 6 : 1) : nx * (o->type == CELL_QUADRILATERAL ? 1 : o->diagonal == 2 ? 4 : 2);
  /* the crossed triangles' centres follow the window's grid vertices, and every grid vertex
   * in the whole mesh */
  long ngrid = o->type == CELL_TRIANGLE && o->diagonal == 2 ? (long)w->nvert - nx * (w->ncell / (4 * nx)) : w->nvert;
  for (long v = 0; v < w->nvert; v++)
    vglob[v] = (int)(v < ngrid ? lo * plane + v : (nx + 1) * (ny + 1) + nx * lo + (v - ngrid));
  for (long c = 0; c < w->ncell; c++) cglob[c] = (int)(lo * ncl + c);
}

mesh *mesh_rectangle(const mesh_box_opts *o, char *err) {
  long nv, nc, plane;
  int rows;
  if (o->type != CELL_TRIANGLE && o->type != CELL_QUADRILATERAL) {
    seterr(err, "a rectangle has triangles or quadrilaterals");
    return NULL;
  }
  if (box_counts(o, &nv, &nc, &rows, &plane, err)) return NULL;
  int nx = o->nx, ny = o->ny, lo = o->hi ? o->lo : 0, hi = o->hi ? o->hi : ny, nr = hi - lo;
  int crossed = o->type == CELL_TRIANGLE && o->diagonal == 2;
  /* the window's rows lo .. hi - 1: its grid vertices (rows lo .. hi) first, then the
   * crossed triangles' centres */
  long ngrid = ((long)nx + 1) * (nr + 1);
  nv = ngrid + (crossed ? (long)nx * nr : 0);
  nc = nc / ny * nr;
  mesh *m = mesh_create(o->type, (int)nv, NULL, (int)nc, NULL, err);
  if (!m) return NULL;
  for (int j = lo; j <= hi; j++)
    for (int i = 0; i <= nx; i++) {
      int id = (j - lo) * (nx + 1) + i;
      m->x[2 * id] = o->x0 + (o->x1 - o->x0) * i / nx;
      m->x[2 * id + 1] = o->y0 + (o->y1 - o->y0) * j / ny;
    }
  int *c = m->cells;
  for (int j = lo; j < hi; j++)
    for (int i = 0; i < nx; i++) {
      int v0 = (j - lo) * (nx + 1) + i, v1 = v0 + 1, v3 = v0 + nx + 1, v2 = v3 + 1;
      if (o->type == CELL_QUADRILATERAL) {
        *c++ = v0; *c++ = v1; *c++ = v2; *c++ = v3;
      } else if (crossed) {
        int vc = (int)ngrid + (j - lo) * nx + i;
        m->x[2 * vc] = 0.25 * (m->x[2 * v0] + m->x[2 * v1] + m->x[2 * v2] + m->x[2 * v3]);
        m->x[2 * vc + 1] = 0.25 * (m->x[2 * v0 + 1] + m->x[2 * v1 + 1] + m->x[2 * v2 + 1] + m->x[2 * v3 + 1]);
        *c++ = v0; *c++ = v1; *c++ = vc;
        *c++ = v1; *c++ = v2; *c++ = vc;
        *c++ = v2; *c++ = v3; *c++ = vc;
        *c++ = v3; *c++ = v0; *c++ = vc;
      } else if (o->diagonal == 1) {
        *c++ = v0; *c++ = v1; *c++ = v3;
        *c++ = v1; *c++ = v2; *c++ = v3;
      } else {
        *c++ = v0; *c++ = v1; *c++ = v2;
        *c++ = v0; *c++ = v2; *c++ = v3;
      }
    }
  /* boundary edges, side by side (left x0, right x1, bottom y0, top y1), oriented with the
   * domain on their left; a window has the bottom and top only where it reaches them */
  static const char *names[] = {"left", "right", "bottom", "top"};
  int cap = 2 * (nx > ny ? nx : ny), *fv = malloc(sizeof(int) * 2 * (size_t)cap);
  if (!fv) { mesh_free(m); seterr(err, "out of memory"); return NULL; }
  for (int side = 0; side < 4; side++) {
    int n = side < 2 ? nr : (side == 2 ? lo == 0 : hi == ny) ? nx : 0, top = (hi - lo) * (nx + 1);
    for (int k = 0; k < n; k++) {
      int a, b;
      if (side == 0) { a = (k + 1) * (nx + 1); b = k * (nx + 1); }
      else if (side == 1) { a = k * (nx + 1) + nx; b = (k + 1) * (nx + 1) + nx; }
      else if (side == 2) { a = k; b = k + 1; }
      else { a = top + k + 1; b = top + k; }
      fv[2 * k] = a;
      fv[2 * k + 1] = b;
    }
    if (mesh_add_boundary_facets(m, n, fv, side + 1, names[side])) {
      seterr(err, "%s", m->err);
      free(fv);
      mesh_free(m);
      return NULL;
    }
  }
  free(fv);
  return m;
}

mesh *mesh_box(const mesh_box_opts *o, char *err) {
  long nv, nc, plane;
  int layers;
  if (o->type != CELL_TETRAHEDRON && o->type != CELL_HEXAHEDRON) {
    seterr(err, "a box has tetrahedra or hexahedra");
    return NULL;
  }
  if (box_counts(o, &nv, &nc, &layers, &plane, err)) return NULL;
  int nx = o->nx, ny = o->ny, nz = o->nz, lo = o->hi ? o->lo : 0, hi = o->hi ? o->hi : nz;
  /* the window's cell layers lo .. hi - 1 and vertex layers lo .. hi */
  nv = plane * (hi - lo + 1);
  nc = nc / nz * (hi - lo);
  mesh *m = mesh_create(o->type, (int)nv, NULL, (int)nc, NULL, err);
  if (!m) return NULL;
#define VID(i, j, k) ((((k) - lo) * (ny + 1) + (j)) * (nx + 1) + (i))
  for (int k = lo; k <= hi; k++)
    for (int j = 0; j <= ny; j++)
      for (int i = 0; i <= nx; i++) {
        int id = VID(i, j, k);
        m->x[3 * id] = o->x0 + (o->x1 - o->x0) * i / nx;
        m->x[3 * id + 1] = o->y0 + (o->y1 - o->y0) * j / ny;
        m->x[3 * id + 2] = o->z0 + (o->z1 - o->z0) * k / nz;
      }
  /* Kuhn (Freudenthal) split: one tetrahedron per permutation of the axes along the
   * main diagonal; conforming because every cube is split the same way */
  static const int perm[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  int *c = m->cells;
  for (int k = lo; k < hi; k++)
    for (int j = 0; j < ny; j++)
      for (int i = 0; i < nx; i++) {
        if (o->type == CELL_HEXAHEDRON) {
          *c++ = VID(i, j, k); *c++ = VID(i + 1, j, k); *c++ = VID(i + 1, j + 1, k); *c++ = VID(i, j + 1, k);
          *c++ = VID(i, j, k + 1); *c++ = VID(i + 1, j, k + 1); *c++ = VID(i + 1, j + 1, k + 1); *c++ = VID(i, j + 1, k + 1);
          continue;
        }
        for (int p = 0; p < 6; p++) {
          int a[3] = {0, 0, 0};
          *c++ = VID(i, j, k);
          for (int s = 0; s < 3; s++) {
            a[perm[p][s]] = 1;
            *c++ = VID(i + a[0], j + a[1], k + a[2]);
          }
        }
      }
  orient_simplices(m);
  /* boundary facets side by side, straight from the grid: a square of side s (normal
   * axis d, at index 0 or n_d) spans the two other axes (u, w); the Kuhn split cuts every
   * square along the diagonal from its low to its high corner. A window has the squares
   * of its layers, and the bottom and top only where it reaches them */
  static const char *names[] = {"left", "right", "front", "back", "bottom", "top"};
  int nn[3] = {nx, ny, nz};
  int tets = o->type == CELL_TETRAHEDRON;
  long maxface = 0;
  for (int d = 0; d < 3; d++) {
    long f = (long)nn[(d + 1) % 3] * nn[(d + 2) % 3];
    if (f > maxface) maxface = f;
  }
  int *fv = malloc(sizeof(int) * (size_t)maxface * 2 * 4);
  if (!fv) { mesh_free(m); seterr(err, "out of memory"); return NULL; }
  for (int side = 0; side < 6; side++) {
    int d = side / 2, u = d == 0 ? 1 : 0, w = d == 2 ? 1 : 2, cnt = 0;
    int at = side % 2 ? nn[d] : 0;
    int b2lo = w == 2 ? lo : 0, b2hi = w == 2 ? hi : nn[w];
    if (d == 2 && (side % 2 ? hi != nz : lo != 0)) b2hi = b2lo; /* not in the window */
    for (int b2 = b2lo; b2 < b2hi; b2++)
      for (int b1 = 0; b1 < nn[u]; b1++) {
        int idx[4][3];
        int cu[4] = {0, 1, 1, 0}, cw[4] = {0, 0, 1, 1};
        for (int c = 0; c < 4; c++) {
          idx[c][d] = at;
          idx[c][u] = b1 + cu[c];
          idx[c][w] = b2 + cw[c];
        }
        int v[4];
        for (int c = 0; c < 4; c++) v[c] = VID(idx[c][0], idx[c][1], idx[c][2]);
        if (tets) {
          int t[6] = {v[0], v[1], v[2], v[0], v[2], v[3]};
          memcpy(fv + (size_t)cnt * 3, t, sizeof t);
          cnt += 2;
        } else {
          memcpy(fv + (size_t)cnt * 4, v, sizeof v);
          cnt++;
        }
      }
    if (mesh_add_boundary_facets(m, cnt, fv, side + 1, names[side])) {
      seterr(err, "%s", m->err);
      free(fv);
      mesh_free(m);
      return NULL;
    }
  }
#undef VID
  free(fv);
  return m;
}

/* ---------------------------------------------------------------- refinement */

/* an interval mesh: each interval into two at its midpoint; the boundary points and names
 * stay (they are vertices of the old mesh, which keep their ids) */
static mesh *refine_intervals(const mesh *m, char *err) {
  if ((long)m->nvert + m->ncell > 2000000000L || 2L * m->ncell > 1000000000L) { seterr(err, "refined mesh too large"); return NULL; }
  mesh *r = mesh_copy(m);
  if (!r) { seterr(err, "out of memory"); return NULL; }
  int nv = m->nvert + m->ncell, nc = 2 * m->ncell;
  double *x = mesh_big_alloc(sizeof(double) * (size_t)nv);
  int *cells = mesh_big_alloc(sizeof(int) * 2 * (size_t)nc), *tag = calloc((size_t)nc, sizeof(int));
  if (!x || !cells || !tag) {
    mesh_big_free(x); mesh_big_free(cells); free(tag); mesh_free(r);
    seterr(err, "out of memory");
    return NULL;
  }
  memcpy(x, m->x, sizeof(double) * (size_t)m->nvert);
  for (int c = 0; c < m->ncell; c++) {
    int a = m->cells[2 * c], b = m->cells[2 * c + 1], mid = m->nvert + c;
    x[mid] = 0.5 * m->x[a] + 0.5 * m->x[b];
    cells[4 * c] = a; cells[4 * c + 1] = mid; cells[4 * c + 2] = mid; cells[4 * c + 3] = b;
    tag[2 * c] = tag[2 * c + 1] = m->cell_tag[c];
  }
  mesh_big_free(r->x); mesh_big_free(r->cells); free(r->cell_tag);
  mesh_free_derived(r);
  r->x = x; r->cells = cells; r->cell_tag = tag;
  r->nvert = nv; r->ncell = nc;
  return r;
}

mesh *mesh_refine(const mesh *m, char *err) {
  if (m->type == CELL_INTERVAL) return refine_intervals(m, err);
  if (m->type == CELL_HEXAHEDRON) {
    seterr(err, "uniform refinement of hexahedral meshes is not implemented yet");
    return NULL;
  }
  mesh *mm = mesh_copy(m);
  if (!mm || mesh_build_edges(mm)) {
    seterr(err, "out of memory");
    mesh_free(mm);
    return NULL;
  }
  int quad = m->type == CELL_QUADRILATERAL;
  int nchild = m->dim == 2 ? 4 : 8;
  long nv = (long)m->nvert + mm->nedge + (quad ? m->ncell : 0);
  long nc = (long)m->ncell * nchild;
  if (nv > 2000000000L || nc * m->nvc > 2000000000L) {
    seterr(err, "refined mesh too large");
    mesh_free(mm);
    return NULL;
  }
  mesh *r = mesh_create(m->type, (int)nv, NULL, (int)nc, NULL, err);
  if (!r) { mesh_free(mm); return NULL; }
  int d = m->dim;
  memcpy(r->x, m->x, sizeof(double) * (size_t)m->nvert * (size_t)d);
  for (int e = 0; e < mm->nedge; e++)
    for (int k = 0; k < d; k++)
      r->x[(size_t)(m->nvert + e) * d + k] =
          0.5 * m->x[d * mm->edges[2 * e] + k] + 0.5 * m->x[d * mm->edges[2 * e + 1] + k]; /* no overflow */
  int ne = cell_nedges(m->type);
  for (int c = 0; c < m->ncell; c++) {
    const int *v = m->cells + (size_t)c * (size_t)m->nvc;
    const int *ce = mm->cell_edges + (size_t)c * (size_t)ne;
    int *o = r->cells + (size_t)c * (size_t)nchild * (size_t)m->nvc;
    for (int k = 0; k < nchild; k++) r->cell_tag[(size_t)c * nchild + k] = m->cell_tag[c];
    if (m->type == CELL_TRIANGLE) {
      /* edges e0=(1,2) e1=(0,2) e2=(0,1) */
      int m12 = m->nvert + ce[0], m02 = m->nvert + ce[1], m01 = m->nvert + ce[2];
      int t[4][3] = {{v[0], m01, m02}, {m01, v[1], m12}, {m02, m12, v[2]}, {m01, m12, m02}};
      memcpy(o, t, sizeof t);
    } else if (quad) {
      int cv = m->nvert + mm->nedge + c;
      for (int k = 0; k < 2; k++) {
        double s = 0;
        for (int i = 0; i < 4; i++) s += 0.25 * m->x[2 * v[i] + k];
        r->x[2 * cv + k] = s;
      }
      int m01 = m->nvert + ce[0], m12 = m->nvert + ce[1], m23 = m->nvert + ce[2], m30 = m->nvert + ce[3];
      int t[4][4] = {{v[0], m01, cv, m30}, {m01, v[1], m12, cv}, {cv, m12, v[2], m23}, {m30, cv, m23, v[3]}};
      memcpy(o, t, sizeof t);
    } else {
      /* edges e0=(2,3) e1=(1,3) e2=(1,2) e3=(0,3) e4=(0,2) e5=(0,1); Bey's subdivision */
      int x23 = m->nvert + ce[0], x13 = m->nvert + ce[1], x12 = m->nvert + ce[2];
      int x03 = m->nvert + ce[3], x02 = m->nvert + ce[4], x01 = m->nvert + ce[5];
      int t[8][4] = {{v[0], x01, x02, x03}, {x01, v[1], x12, x13}, {x02, x12, v[2], x23},
                     {x03, x13, x23, v[3]}, {0, 0, 0, 0}, {0, 0, 0, 0}, {0, 0, 0, 0}, {0, 0, 0, 0}};
      /* the inner octahedron is split along its shortest diagonal, which keeps the shapes
       * bounded under repeated refinement; mid[i][j] is the midpoint of edge (i,j) */
      int mid[4][4] = {{-1, x01, x02, x03}, {x01, -1, x12, x13}, {x02, x12, -1, x23}, {x03, x13, x23, -1}};
      static const int diag[3][4] = {{0, 1, 2, 3}, {0, 2, 1, 3}, {0, 3, 1, 2}};
      int best = 0;
      double bl = INFINITY;
      for (int k = 0; k < 3; k++) {
        const double *a = r->x + 3 * mid[diag[k][0]][diag[k][1]], *b = r->x + 3 * mid[diag[k][2]][diag[k][3]];
        double l = (a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) + (a[2] - b[2]) * (a[2] - b[2]);
        if (l < bl) { bl = l; best = k; }
      }
      int i = diag[best][0], j = diag[best][1], k = diag[best][2], l = diag[best][3];
      int d1 = mid[i][j], d2 = mid[k][l];
      int cyc[4] = {mid[i][k], mid[i][l], mid[j][l], mid[j][k]};
      for (int q = 0; q < 4; q++) {
        t[4 + q][0] = d1; t[4 + q][1] = d2; t[4 + q][2] = cyc[q]; t[4 + q][3] = cyc[(q + 1) % 4];
      }
      memcpy(o, t, sizeof t);
    }
  }
  /* keep each child's orientation equal to its parent's (so tangled meshes stay tangled) */
  if (!quad) {
    for (int c = 0; c < m->ncell; c++) {
      double sp = mesh_cell_signed_measure(m, c);
      for (int k = 0; k < nchild; k++) {
        int cc = c * nchild + k;
        double sc = mesh_cell_signed_measure(r, cc);
        if ((sp > 0 && sc < 0) || (sp < 0 && sc > 0)) {
          int *w = r->cells + (size_t)cc * (size_t)r->nvc;
          int t = w[r->nvc - 1];
          w[r->nvc - 1] = w[r->nvc - 2];
          w[r->nvc - 2] = t;
        }
      }
    }
  }
  /* boundary facets */
  if (m->nbf) {
    tuplehash h;
    if (th_init(&h, (size_t)mm->nedge + 16, 2)) goto oom;
    for (int e = 0; e < mm->nedge; e++) th_get(&h, mm->edges + 2 * e, e, NULL);
    int per = m->dim == 2 ? 2 : 4;
    r->bf_verts = malloc(sizeof(int) * (size_t)m->nbf * (size_t)per * (size_t)m->nvf);
    r->bf_tag = malloc(sizeof(int) * (size_t)m->nbf * (size_t)per);
    if (!r->bf_verts || !r->bf_tag) { th_free(&h); goto oom; }
    for (int b = 0; b < m->nbf; b++) {
      const int *fv = m->bf_verts + (size_t)b * (size_t)m->nvf;
      int *o = r->bf_verts + (size_t)b * (size_t)per * (size_t)m->nvf;
      for (int k = 0; k < per; k++) r->bf_tag[b * per + k] = m->bf_tag[b];
      if (m->dim == 2) {
        int mid = m->nvert + th_get(&h, fv, -1, NULL);
        o[0] = fv[0]; o[1] = mid; o[2] = mid; o[3] = fv[1];
      } else {
        int k01[2] = {fv[0], fv[1]}, k12[2] = {fv[1], fv[2]}, k02[2] = {fv[0], fv[2]};
        int a = m->nvert + th_get(&h, k01, -1, NULL), bb = m->nvert + th_get(&h, k12, -1, NULL),
            cc = m->nvert + th_get(&h, k02, -1, NULL);
        int t[4][3] = {{fv[0], a, cc}, {a, fv[1], bb}, {cc, bb, fv[2]}, {a, bb, cc}};
        memcpy(o, t, sizeof t);
      }
    }
    r->nbf = m->nbf * per;
    th_free(&h);
  }
  if (copy_names(&r->bnames, &r->nbname, &r->capbname, m->bnames, m->nbname) ||
      copy_names(&r->cnames, &r->ncname, &r->capcname, m->cnames, m->ncname))
    goto oom;
  mesh_free(mm);
  return r;
oom:
  seterr(err, "out of memory refining");
  mesh_free(mm);
  mesh_free(r);
  return NULL;
}
