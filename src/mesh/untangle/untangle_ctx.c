/* untangle_ctx.c — the context the untangler (untangle.c, untangle_place.c,
 * untangle_global.c) and the smoother (smooth.c) work in: corners and vertex -> cell
 * adjacency, the boundary (facets, fixed corners, 2D neighbours, 3D sliding directions) and
 * sliding a boundary vertex along it, corner Jacobians (seed, untangling paper, section 1:
 * "an element is valid if each corner is valid") and the scales (default beta, jtol). */
#include "untangle_int.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

double ut_now(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

/* ---------------------------------------------------------------- corners and adjacency */




void ut_ctx_free(ctx *C) {
  free(C->vc_off);
  free(C->vc);
  free(C->bnd);
  free(C->fixed);
  free(C->bnb);
  free(C->bf_off);
  free(C->bf);
  free(C->ntan);
  free(C->tan);
}

/* the shortest edge at v */
double ut_star_h(const ctx *C, int v) {
  int d = C->d;
  const double *p0 = C->m->x + (size_t)v * d;
  double h = INFINITY;
  for (int pp = C->vc_off[v]; pp < C->vc_off[v + 1]; pp++) {
    const int *cell = cell_of(C, C->vc[pp]);
    for (int i = 0; i < C->nvc; i++) {
      if (cell[i] == v) continue;
      double s2 = 0;
      for (int j = 0; j < d; j++) s2 += (C->m->x[(size_t)cell[i] * d + j] - p0[j]) * (C->m->x[(size_t)cell[i] * d + j] - p0[j]);
      h = fmin(h, sqrt(s2));
    }
  }
  return h;
}

static double bbox_diag(const mesh *m) {
  double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY}, s = 0;
  for (int v = 0; v < m->nvert; v++)
    for (int k = 0; k < m->dim; k++) {
      lo[k] = fmin(lo[k], m->x[(size_t)v * m->dim + k]);
      hi[k] = fmax(hi[k], m->x[(size_t)v * m->dim + k]);
    }
  for (int k = 0; k < m->dim; k++) s += (hi[k] - lo[k]) * (hi[k] - lo[k]);
  return sqrt(s);
}

double untangle_default_beta(const mesh *m) {
  /* section 3: "10% of the problem size (diagonal of the bounding box) normalized by the
   * number of elements in either direction" — a length; raised to the dimension it is
   * comparable with corner Jacobians (≈ 1–2% of a regular cell's) */
  double n = pow((double)m->ncell / (m->type == CELL_TRIANGLE ? 2 : m->type == CELL_TETRAHEDRON ? 6 : 1),
                 1.0 / m->dim);
  return pow(0.1 * bbox_diag(m) / fmax(n, 1), m->dim);
}

/* a facet is on the boundary when no other cell has it. Each facet is examined at its
 * smallest vertex v, among the facets of v's cells: their keys (the other vertices, sorted)
 * are sorted and a key that occurs once is a boundary facet. Linear and cache-local (a
 * global facet hash table is 4x slower on a 500k-tet mesh). The boundary facets come back
 * as cell * nfacets + local facet, in a malloc'ed array. */
typedef struct {
  int k[3];
  int id;
} fkey;
static int fkey_cmp(const void *a, const void *b) { return memcmp(a, b, sizeof(int) * 3); }
/* fkey_cmp's order (memcmp's, which the boundary facets' order, and so the order of a 2D
 * boundary vertex's neighbours, has always followed) without the calls: the keys' bytes in
 * memory order, as one unsigned number per int */
static inline unsigned fkey_word(int k) {
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
  return __builtin_bswap32((unsigned)k);
#else
  return (unsigned)k;
#endif
}
static inline int fkey_after(const fkey *a, const fkey *b) {
  for (int i = 0; i < 3; i++)
    if (a->k[i] != b->k[i]) return fkey_word(a->k[i]) > fkey_word(b->k[i]);
  return 0;
}

/* the vertex -> cells map of m: vertex v's cells, ascending, are vc[off[v] .. off[v + 1]); both
 * malloc'ed (NULL and 1 when out of memory) */
static int vertex_cells(const mesh *m, int **offp, int **vcp) {
  int nv = m->nvert, nvc = m->nvc;
  int *off = calloc((size_t)nv + 1, sizeof(int)), *vc = malloc(sizeof(int) * ((size_t)m->ncell * nvc + 1)),
      *pos = malloc(sizeof(int) * ((size_t)nv + 1));
  *offp = off;
  *vcp = vc;
  if (!off || !vc || !pos) {
    free(off); free(vc); free(pos);
    *offp = *vcp = NULL;
    return 1;
  }
  for (size_t i = 0; i < (size_t)m->ncell * nvc; i++) off[m->cells[i] + 1]++;
  for (int v = 0; v < nv; v++) off[v + 1] += off[v];
  memcpy(pos, off, sizeof(int) * (size_t)nv);
  for (int c = 0; c < m->ncell; c++)
    for (int i = 0; i < nvc; i++) vc[pos[m->cells[(size_t)c * nvc + i]]++] = c;
  free(pos);
  return 0;
}

/* the boundary facets of m (cell * nfacets + facet: those of one cell only), from its vertex ->
 * cells map (voff, vcl; built here when NULL) */
static int boundary_facets(const mesh *m, const int *voff, const int *vcl, int **out, int *nout, char *err) {
  int nf = cell_nfacets(m->type), nvf = m->nvf, nv = m->nvert, nvc = m->nvc, n_out = 0, cap = 64;
  int *off = NULL, *vc = NULL;
  int *res = malloc(sizeof(int) * (size_t)cap);
  fkey *keys = NULL;
  if (!res) goto oom;
  if (!voff) {
    if (vertex_cells(m, &off, &vc)) goto oom;
    voff = off;
    vcl = vc;
  }
  int maxdeg = 0;
  for (int v = 0; v < nv; v++) maxdeg = voff[v + 1] - voff[v] > maxdeg ? voff[v + 1] - voff[v] : maxdeg;
  keys = malloc(sizeof(fkey) * ((size_t)maxdeg * nf + 1));
  if (!keys) goto oom;
  for (int v = 0; v < nv; v++) {
    int n = 0;
    for (int p = voff[v]; p < voff[v + 1]; p++) {
      const int *cell = m->cells + (size_t)vcl[p] * nvc;
      for (int f = 0; f < nf; f++) {
        const int *lv = cell_facet_verts(m->type, f);
        int has = 0, smallest = 1, k = 0;
        fkey key = {{-1, -1, -1}, vcl[p] * nf + f};
        for (int i = 0; i < nvf; i++) {
          int w = cell[lv[i]];
          if (w == v) has = 1;
          else if (w < v) { smallest = 0; break; }
          else if (k < 3) key.k[k++] = w; /* a facet without v has nvf others: skipped below */
        }
        if (!has || !smallest) continue;
        for (int i = 1; i < k; i++) /* insertion sort of at most 3 */
          for (int j = i; j > 0 && key.k[j - 1] > key.k[j]; j--) { int t = key.k[j]; key.k[j] = key.k[j - 1]; key.k[j - 1] = t; }
        keys[n++] = key;
      }
    }
    /* a vertex has a few facets: an insertion sort (qsort's calls were 0.1 s of a million
     * triangles' 0.12 s); only a key's count is read, and that does not depend on the order
     * of equal keys */
    if (n > 32) qsort(keys, (size_t)n, sizeof(fkey), fkey_cmp);
    else
      for (int i = 1; i < n; i++)
        for (int j = i; j > 0 && fkey_after(keys + j - 1, keys + j); j--) {
          fkey t = keys[j];
          keys[j] = keys[j - 1];
          keys[j - 1] = t;
        }
    for (int i = 0; i < n;) {
      int j = i + 1;
      while (j < n && keys[i].k[0] == keys[j].k[0] && keys[i].k[1] == keys[j].k[1] && keys[i].k[2] == keys[j].k[2]) j++;
      if (j == i + 1) {
        if (n_out == cap) {
          int *nr = realloc(res, sizeof(int) * (size_t)(cap *= 2));
          if (!nr) goto oom;
          res = nr;
        }
        res[n_out++] = keys[i].id;
      }
      i = j;
    }
  }
  free(off); free(vc); free(keys);
  *out = res;
  *nout = n_out;
  return 0;
oom:
  free(off); free(vc); free(keys); free(res);
  snprintf(err, MESH_ERRLEN, "out of memory");
  return 1;
}

/* flags[v] = 1 on the vertices of the n boundary facets bf, 0 elsewhere */
static void facet_vertices(const mesh *m, const int *bf, int n, unsigned char *flags) {
  int nf = cell_nfacets(m->type);
  memset(flags, 0, (size_t)m->nvert);
  for (int i = 0; i < n; i++) {
    const int *lv = cell_facet_verts(m->type, bf[i] % nf);
    for (int j = 0; j < m->nvf; j++) flags[m->cells[(size_t)(bf[i] / nf) * m->nvc + lv[j]]] = 1;
  }
}

int mesh_boundary_vertices(const mesh *m, unsigned char *flags, char *err) {
  int *bf, n;
  if (boundary_facets(m, NULL, NULL, &bf, &n, err)) return 1;
  facet_vertices(m, bf, n, flags);
  free(bf);
  return 0;
}

/* 2D boundary edges (bf, n: the boundary facets): the two boundary neighbours of every boundary
 * vertex; a vertex with other than two, or whose two edges are not collinear, is a corner of
 * the boundary */
static int boundary_2d(ctx *C, int slide, const int *bf, int n, char *err) {
  mesh *m = C->m;
  C->bnb = malloc(sizeof(int) * 2 * (size_t)m->nvert);
  if (slide) {
    C->ntan = calloc((size_t)m->nvert + 1, 1);
    C->tan = calloc((size_t)m->nvert * 4 + 1, sizeof(double));
  }
  int *nb = calloc((size_t)m->nvert, sizeof(int)), nf = cell_nfacets(m->type);
  if (!C->bnb || !nb || (slide && (!C->ntan || !C->tan))) {
    free(nb);
    snprintf(err, MESH_ERRLEN, "out of memory");
    return 1;
  }
  for (int i = 0; i < 2 * m->nvert; i++) C->bnb[i] = -1;
  for (int i = 0; i < n; i++) {
    const int *lv = cell_facet_verts(m->type, bf[i] % nf), *cell = cell_of(C, bf[i] / nf);
    for (int s = 0; s < 2; s++) {
      int a = cell[lv[s]], b = cell[lv[1 - s]];
      if (nb[a] < 2) C->bnb[2 * a + nb[a]] = b;
      nb[a]++;
    }
  }
  for (int v = 0; v < m->nvert; v++) {
    if (!C->bnd[v]) continue;
    int corner = nb[v] != 2;
    if (!corner) {
      const double *p = m->x + 2 * v, *a = m->x + 2 * C->bnb[2 * v], *b = m->x + 2 * C->bnb[2 * v + 1];
      double ax = a[0] - p[0], ay = a[1] - p[1], bx = b[0] - p[0], by = b[1] - p[1];
      double cr = ax * by - ay * bx;
      /* straight: the two edges collinear (possibly folded back by a tangle) */
      corner = !(fabs(cr) <= 1e-12 * sqrt((ax * ax + ay * ay) * (bx * bx + by * by)));
      double l = sqrt((bx - ax) * (bx - ax) + (by - ay) * (by - ay));
      if (slide && !corner && l > 0) { /* the line's direction */
        double *t = ut_tangents(C, v);
        t[0] = (bx - ax) / l;
        t[1] = (by - ay) / l;
        C->ntan[v] = 1;
      }
    }
    if (corner) C->fixed[v] = 1;
  }
  free(nb);
  return 0;
}

static void cross3(const double *a, const double *b, double *c) {
  c[0] = a[1] * b[2] - a[2] * b[1];
  c[1] = a[2] * b[0] - a[0] * b[2];
  c[2] = a[0] * b[1] - a[1] * b[0];
}

/* 3D sliding (the paper's 2D "move only along the discrete boundary", carried to surfaces):
 * a boundary vertex whose boundary facets are all coplanar slides in their plane; one where
 * they lie in two planes slides along the planes' intersection (a straight edge of the
 * domain); any other (a corner, a curved surface) stays. */
static int boundary_3d(ctx *C, const int *bfl, int n, char *err) {
  mesh *m = C->m;
  int nv = m->nvert, nf = cell_nfacets(m->type);
  C->bf_off = calloc((size_t)nv + 2, sizeof(int));
  C->ntan = calloc((size_t)nv + 1, 1);
  C->tan = calloc((size_t)nv * 6 + 1, sizeof(double));
  if (!C->bf_off || !C->ntan || !C->tan) goto oom;
  C->bf = malloc(sizeof(int) * ((size_t)n * m->nvf + 1));
  if (!C->bf) goto oom;
  for (int i = 0; i < n; i++) {
    const int *lv = cell_facet_verts(m->type, bfl[i] % nf), *cell = cell_of(C, bfl[i] / nf);
    for (int j = 0; j < m->nvf; j++) C->bf_off[cell[lv[j]] + 2]++;
  }
  for (int v = 0; v < nv; v++) C->bf_off[v + 2] += C->bf_off[v + 1];
  for (int i = 0; i < n; i++) {
    const int *lv = cell_facet_verts(m->type, bfl[i] % nf), *cell = cell_of(C, bfl[i] / nf);
    for (int j = 0; j < m->nvf; j++) C->bf[C->bf_off[cell[lv[j]] + 1]++] = bfl[i];
  }
  for (int v = 0; v < nv; v++) {
    if (!C->bnd[v]) continue;
    double cl[2][3]; /* up to two distinct plane normals */
    int ncl = 0;
    for (int p = C->bf_off[v]; p < C->bf_off[v + 1] && ncl <= 2; p++) {
      const int *lv = cell_facet_verts(m->type, C->bf[p] % nf), *cell = cell_of(C, C->bf[p] / nf);
      double nrm[3] = {0, 0, 0}, e1[3], e2[3], c[3];
      for (int j = 0; j < m->nvf; j++) { /* Newell-like: sum of the corner cross products */
        const double *a = m->x + 3 * cell[lv[j]], *b = m->x + 3 * cell[lv[(j + 1) % m->nvf]],
                     *z = m->x + 3 * cell[lv[(j + m->nvf - 1) % m->nvf]];
        for (int k = 0; k < 3; k++) { e1[k] = b[k] - a[k]; e2[k] = z[k] - a[k]; }
        cross3(e1, e2, c);
        for (int k = 0; k < 3; k++) nrm[k] += c[k];
      }
      double len = sqrt(nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2]);
      if (!(len > 0)) { ncl = 3; break; } /* degenerate facet: keep the vertex */
      for (int k = 0; k < 3; k++) nrm[k] /= len;
      int same = -1;
      for (int q = 0; q < ncl && same < 0; q++) {
        cross3(nrm, cl[q], c);
        if (sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]) <= 1e-10) same = q;
      }
      if (same < 0) {
        if (ncl < 2) memcpy(cl[ncl], nrm, sizeof nrm);
        ncl++;
      }
    }
    double *t = ut_tangents(C, v);
    if (ncl == 1) {
      /* a unit vector orthogonal to the normal, then the normal cross it */
      const double *nn = cl[0];
      double a[3] = {0, 0, 0};
      a[fabs(nn[0]) < 0.6 ? 0 : fabs(nn[1]) < 0.6 ? 1 : 2] = 1;
      cross3(nn, a, t);
      double l = sqrt(t[0] * t[0] + t[1] * t[1] + t[2] * t[2]);
      for (int k = 0; k < 3; k++) t[k] /= l;
      cross3(nn, t, t + 3);
      C->ntan[v] = 2;
    } else if (ncl == 2) {
      cross3(cl[0], cl[1], t);
      double l = sqrt(t[0] * t[0] + t[1] * t[1] + t[2] * t[2]);
      for (int k = 0; k < 3; k++) t[k] /= l;
      C->ntan[v] = 1;
    }
    if (!C->ntan[v]) C->fixed[v] = 1;
  }
  return 0;
oom:
  snprintf(err, MESH_ERRLEN, "out of memory");
  return 1;
}

/* 3D: p (the new position of v) lies on v's current boundary star: in one of the triangles
 * (v, a, b) the boundary facets at v make (a quadrilateral facet v a b c gives two), with
 * weight at least 5% on v so the star's outer edges are not reached (the 2D slide stops at
 * 95% of a boundary edge likewise) */
static int on_star(const ctx *C, const double *x, int v, const double *p) {
  mesh *m = C->m;
  int nf = cell_nfacets(m->type), nvf = m->nvf;
  const double *o = x + 3 * (size_t)v;
  for (int q = C->bf_off[v]; q < C->bf_off[v + 1]; q++) {
    const int *lv = cell_facet_verts(m->type, C->bf[q] % nf), *cell = cell_of(C, C->bf[q] / nf);
    int at = 0;
    while (cell[lv[at]] != v) at++;
    for (int tri = 0; tri < nvf - 2; tri++) {
      const double *a = x + 3 * (size_t)cell[lv[(at + 1 + tri) % nvf]], *b = x + 3 * (size_t)cell[lv[(at + 2 + tri) % nvf]];
      double ab[3], ob[3], n[3], u[3], w[3], c[3];
      for (int k = 0; k < 3; k++) { ab[k] = a[k] - o[k]; ob[k] = b[k] - o[k]; }
      cross3(ab, ob, n);
      double nn = n[0] * n[0] + n[1] * n[1] + n[2] * n[2];
      if (!(nn > 0)) continue;
      /* barycentric weights of p in (o, a, b) */
      for (int k = 0; k < 3; k++) { u[k] = a[k] - p[k]; w[k] = b[k] - p[k]; }
      cross3(u, w, c);
      double lo = (c[0] * n[0] + c[1] * n[1] + c[2] * n[2]) / nn;
      for (int k = 0; k < 3; k++) { u[k] = b[k] - p[k]; w[k] = o[k] - p[k]; }
      cross3(u, w, c);
      double la = (c[0] * n[0] + c[1] * n[1] + c[2] * n[2]) / nn, lb = 1 - lo - la;
      if (lo >= 0.05 && la >= -1e-12 && lb >= -1e-12) return 1;
    }
  }
  return 0;
}

/* 3D: one boundary vertex descends pen (evaluated at the current coordinates) along its
 * slide directions — the gradient in the tangent basis, from grad or by central differences,
 * backtracking — while it stays on its boundary star; 1 if it moved. Each backtracking starts
 * at twice the step the previous one accepted (at most half the shortest edge): starting
 * every time from half the edge, a vertex near its optimum spent ten trials per step and
 * fourteen on its last, and the sliding 3D smoother's rounds spent most of their slides there */

int ut_slide_3d(const ctx *C, double *x, int v, vertex_penalty pen, vertex_gradient grad, const void *arg) {
  int nt = C->ntan[v], moved = 0;
  const double *t = ut_tangents(C, v);
  double *p = x + 3 * (size_t)v, h = ut_star_h(C, v), f = pen(C, v, arg, 0);
  if (!nt || !(f > 0) || !isfinite(f)) return 0;
  double s0 = 1;
  for (int it = 0; it < 20; it++) {
    double p0[3] = {p[0], p[1], p[2]}, g[2] = {0, 0}, e = 1e-6 * h, dir[3] = {0, 0, 0}, gn = 0, gx[3];
    if (grad) {
      if (grad(C, v, arg, gx)) break;
      for (int k = 0; k < nt; k++) {
        g[k] = gx[0] * t[3 * k] + gx[1] * t[3 * k + 1] + gx[2] * t[3 * k + 2];
        gn += g[k] * g[k];
      }
    } else
      for (int k = 0; k < nt; k++) {
        for (int j = 0; j < 3; j++) p[j] = p0[j] + e * t[3 * k + j];
        double fp = pen(C, v, arg, 1);
        for (int j = 0; j < 3; j++) p[j] = p0[j] - e * t[3 * k + j];
        double fm = pen(C, v, arg, 1);
        g[k] = isfinite(fp) && isfinite(fm) ? (fp - fm) / (2 * e) : 0;
        gn += g[k] * g[k];
      }
    for (int j = 0; j < 3; j++) p[j] = p0[j];
    if (!(gn > 0)) break;
    for (int k = 0; k < nt; k++)
      for (int j = 0; j < 3; j++) dir[j] -= g[k] / sqrt(gn) * 0.5 * h * t[3 * k + j];
    int ok = 0;
    for (double s = s0; s > 1e-4 && !ok; s *= 0.5) {
      double q[3] = {p0[0] + s * dir[0], p0[1] + s * dir[1], p0[2] + s * dir[2]};
      if (!on_star(C, x, v, q)) continue;
      memcpy(p, q, sizeof q);
      double fn = pen(C, v, arg, 0);
      if (fn < f) { f = fn; ok = 1; s0 = fmin(1, 2 * s); }
      else memcpy(p, p0, sizeof p0);
    }
    if (!ok) break;
    moved = 1;
    if (f == 0) break;
  }
  return moved;
}

void ut_progress_tick(ut_progress *p, const char *what, int it, double f, double qmin) {
  if (!p || !(p->every > 0)) return;
  double now = ut_now();
  if (now - p->t0 < p->every || now - p->last < p->every) return;
  p->last = now;
  char qs[48] = "";
  if (qmin > 0) snprintf(qs, sizeof qs, ", min quality %.4g", qmin);
  fprintf(stderr, "%s: %s%s%s %d, objective %.6g%s, %.1f s\n", p->task, p->stage ? p->stage : "", p->stage ? ", " : "", what, it,
          f, qs, now - p->t0);
  fflush(stderr);
}

int ut_ctx_init(ctx *C, mesh *m, int slide, char *err) {
  memset(C, 0, sizeof *C);
  C->m = m;
  C->d = m->dim;
  C->nvc = m->nvc;
  switch (m->type) {
  case CELL_INTERVAL:
    snprintf(err, MESH_ERRLEN, "untangling, smoothing and mesh motion are for 2D and 3D meshes, not intervals");
    return 1;
  case CELL_TRIANGLE: C->ncorner = 1; C->ct[0][0] = 0; C->ct[0][1] = 1; C->ct[0][2] = 2; break;
  case CELL_TETRAHEDRON: C->ncorner = 1; for (int i = 0; i < 4; i++) C->ct[0][i] = i; break;
  case CELL_QUADRILATERAL:
    C->ncorner = 4;
    for (int i = 0; i < 4; i++) { C->ct[i][0] = i; C->ct[i][1] = (i + 1) % 4; C->ct[i][2] = (i + 3) % 4; }
    break;
  case CELL_HEXAHEDRON:
    C->ncorner = 8;
    for (int i = 0; i < 8; i++) {
      const int *nb = hex_corner_neighbors(i);
      C->ct[i][0] = i;
      for (int k = 0; k < 3; k++) C->ct[i][k + 1] = nb[k];
    }
    break;
  }
  int nv = m->nvert;
  C->bnd = malloc((size_t)nv + 1);
  C->fixed = malloc((size_t)nv + 1);
  if (vertex_cells(m, &C->vc_off, &C->vc) || !C->bnd || !C->fixed) { snprintf(err, MESH_ERRLEN, "out of memory"); return 1; }
  /* the boundary facets once, from the map just built: for the boundary vertices and the 2D
   * and 3D boundary structures (each had found them again: 0.08 s per search on a million
   * triangles) */
  int *bf, nbf;
  if (boundary_facets(m, C->vc_off, C->vc, &bf, &nbf, err)) return 1;
  facet_vertices(m, bf, nbf, C->bnd);
  for (int v = 0; v < nv; v++) C->fixed[v] = C->bnd[v] && !slide;
  int rc = (m->dim == 2 && boundary_2d(C, slide, bf, nbf, err)) || (m->dim == 3 && slide && boundary_3d(C, bf, nbf, err));
  free(bf);
  if (rc) return 1;
  double h = bbox_diag(m) / pow(fmax((double)m->ncell, 1), 1.0 / m->dim);
  C->jscale = pow(h, m->dim);
  C->jtol = 1e-13 * pow(mesh_hmax(m), m->dim);
  return 0;
}

/* corner k of cell (global vertex ids) at coordinates x: J = det(x_n1 − x_c, ..., x_nd − x_c),
 * and, when g is given, ∂J/∂x of each of the d+1 corner vertices (J is affine in each); J
 * alone is ut_corner_det's (untangle_int.h), the same operations */
double ut_corner_jac(const ctx *C, const double *x, const int *cell, int k, double g[4][3]) {
  if (!g) return ut_corner_det(C, x, cell, k);
  const int *t = C->ct[k];
  int d = C->d;
  const double *p = x + (size_t)d * cell[t[0]];
  double e[3][3];
  for (int i = 0; i < d; i++)
    for (int j = 0; j < d; j++) e[i][j] = x[(size_t)d * cell[t[i + 1]] + j] - p[j];
  double J;
  if (d == 2) {
    J = e[0][0] * e[1][1] - e[0][1] * e[1][0];
    g[1][0] = e[1][1]; g[1][1] = -e[1][0];
    g[2][0] = -e[0][1]; g[2][1] = e[0][0];
  } else {
    double c12[3] = {e[1][1] * e[2][2] - e[1][2] * e[2][1], e[1][2] * e[2][0] - e[1][0] * e[2][2],
                     e[1][0] * e[2][1] - e[1][1] * e[2][0]};
    J = e[0][0] * c12[0] + e[0][1] * c12[1] + e[0][2] * c12[2];
    for (int j = 0; j < 3; j++) g[1][j] = c12[j];
    g[2][0] = e[2][1] * e[0][2] - e[2][2] * e[0][1];
    g[2][1] = e[2][2] * e[0][0] - e[2][0] * e[0][2];
    g[2][2] = e[2][0] * e[0][1] - e[2][1] * e[0][0];
    g[3][0] = e[0][1] * e[1][2] - e[0][2] * e[1][1];
    g[3][1] = e[0][2] * e[1][0] - e[0][0] * e[1][2];
    g[3][2] = e[0][0] * e[1][1] - e[0][1] * e[1][0];
  }
  for (int j = 0; j < d; j++) {
    g[0][j] = 0;
    for (int i = 1; i <= d; i++) g[0][j] -= g[i][j];
  }
  return J;
}


double ut_cell_min_jac(const ctx *C, const double *x, int c) {
  double mn = INFINITY;
  for (int k = 0; k < C->ncorner; k++) mn = fmin(mn, ut_corner_det(C, x, cell_of(C, c), k));
  return mn;
}

void ut_count_cells(const ctx *C, const double *x, double beta, int *ninv, int *nbelow) {
  int a = 0, b = 0, nc = C->m->ncell;
#ifdef _OPENMP
#pragma omp parallel for schedule(static) reduction(+ : a, b) if (nc > 8192)
#endif
  for (int c = 0; c < nc; c++) {
    double j = ut_cell_min_jac(C, x, c);
    a += !(j > C->jtol);
    b += !(j >= beta);
  }
  *ninv = a;
  if (nbelow) *nbelow = b;
}
