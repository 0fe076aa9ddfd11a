/* locate.c — which cell holds a point: a uniform grid of buckets over the mesh's bounding
 * box, each bucket listing the cells whose bounding boxes meet it (built once per geometry,
 * about one cell per bucket), then barycentric coordinates in the bucket's cells. Point
 * values of discrete functions (uh(x, y), uh:eval) are built on it. */
#include "assemble.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

struct lg_locator {
  unsigned long geometry; /* of the mesh it was built for */
  int dim, g[3];
  double lo[3], h[3];
  int *start, *list; /* CSR: bucket b holds list[start[b] .. start[b+1]) */
};

void lg_locator_free(lg_locator *L) {
  if (!L) return;
  free(L->start);
  free(L->list);
  free(L);
}

static void cell_box(const mesh *m, int c, double lo[3], double hi[3]) {
  int d = m->dim;
  const int *v = m->cells + (size_t)c * (size_t)m->nvc;
  for (int k = 0; k < d; k++) lo[k] = INFINITY, hi[k] = -INFINITY;
  for (int i = 0; i < m->nvc; i++)
    for (int k = 0; k < d; k++) {
      double x = m->x[(size_t)v[i] * d + k];
      lo[k] = fmin(lo[k], x);
      hi[k] = fmax(hi[k], x);
    }
}

static void bucket_range(const lg_locator *L, const double lo[3], const double hi[3], int a[3], int b[3]) {
  for (int k = 0; k < L->dim; k++) {
    a[k] = (int)floor((lo[k] - L->lo[k]) / L->h[k]);
    b[k] = (int)floor((hi[k] - L->lo[k]) / L->h[k]);
    if (a[k] < 0) a[k] = 0;
    if (b[k] > L->g[k] - 1) b[k] = L->g[k] - 1;
  }
  for (int k = L->dim; k < 3; k++) a[k] = b[k] = 0;
}

static lg_locator *locator_build(lg_env *env, lg_mesh *lm) {
  mesh *m = lm->m;
  int d = m->dim;
  lg_locator *L = calloc(1, sizeof *L);
  if (!L) { lg_seterr(env, "out of memory"); return NULL; }
  L->dim = d;
  L->geometry = lm->geometry;
  double hi[3];
  for (int k = 0; k < d; k++) L->lo[k] = INFINITY, hi[k] = -INFINITY;
  for (int i = 0; i < m->nvert; i++)
    for (int k = 0; k < d; k++) {
      L->lo[k] = fmin(L->lo[k], m->x[(size_t)i * d + k]);
      hi[k] = fmax(hi[k], m->x[(size_t)i * d + k]);
    }
  /* about one cell per bucket, the buckets as square as the box allows */
  double vol = 1;
  for (int k = 0; k < d; k++) vol *= fmax(hi[k] - L->lo[k], 1e-300);
  double side = pow(vol / (m->ncell > 0 ? m->ncell : 1), 1.0 / d);
  long nb = 1;
  for (int k = 0; k < d; k++) {
    double n = side > 0 ? ceil((hi[k] - L->lo[k]) / side) : 1;
    L->g[k] = n < 1 ? 1 : n > 1024 ? 1024 : (int)n;
    L->h[k] = fmax(hi[k] - L->lo[k], 1e-300) / L->g[k];
    nb *= L->g[k];
  }
  for (int k = d; k < 3; k++) L->g[k] = 1;
  L->start = calloc((size_t)nb + 1, sizeof(int));
  if (!L->start) { lg_locator_free(L); lg_seterr(env, "out of memory"); return NULL; }
  long total = 0;
  for (int pass = 0; pass < 2; pass++) {
    for (int c = 0; c < m->ncell; c++) {
      double lo[3], up[3];
      int a[3], b[3];
      cell_box(m, c, lo, up);
      bucket_range(L, lo, up, a, b);
      for (int z = a[2]; z <= b[2]; z++)
        for (int y = a[1]; y <= b[1]; y++)
          for (int x = a[0]; x <= b[0]; x++) {
            long bi = ((long)z * L->g[1] + y) * L->g[0] + x;
            if (pass == 0) L->start[bi + 1]++;
            else L->list[L->start[bi]++] = c;
          }
    }
    if (pass == 0) {
      for (long i = 0; i < nb; i++) L->start[i + 1] += L->start[i];
      total = L->start[nb];
      if (total > 2000000000L || !(L->list = malloc(sizeof(int) * ((size_t)total + 1)))) {
        lg_locator_free(L);
        lg_seterr(env, "out of memory for the cell locator");
        return NULL;
      }
    } else {
      for (long i = nb; i > 0; i--) L->start[i] = L->start[i - 1];
      L->start[0] = 0;
    }
  }
  return L;
}

/* the reference coordinates of x in a quadrilateral or hexahedron by Newton's method on its
 * bilinear / trilinear map; how far inside it is (the smallest of xi_d and 1 - xi_d), or
 * -inf when Newton does not converge (x far outside a distorted cell) */
static double box_inside(const mesh *m, int c, const double *x, double *xi) {
  int d = m->dim;
  const int *v = m->cells + (size_t)c * (size_t)m->nvc;
  for (int k = 0; k < d; k++) xi[k] = 0.5;
  for (int it = 0; it < 30; it++) {
    double N[8], J[3][3], K[3][3], r[3] = {0, 0, 0};
    q1_shape(m->type, xi, N, NULL);
    for (int k = 0; k < d; k++) {
      for (int j = 0; j < m->nvc; j++) r[k] += N[j] * m->x[(size_t)v[j] * d + k];
      r[k] -= x[k];
    }
    double det = cell_jacobian(m, c, xi, J, K), step = 0;
    if (!(fabs(det) > 0)) return -INFINITY;
    for (int k = 0; k < d; k++) {
      double dk = 0;
      for (int j = 0; j < d; j++) dk += K[k][j] * r[j];
      xi[k] -= dk;
      step = fmax(step, fabs(dk));
    }
    if (!(fabs(xi[0]) < 10 && fabs(xi[1]) < 10 && (d < 3 || fabs(xi[2]) < 10))) return -INFINITY;
    if (step < 1e-14) break;
  }
  double in = INFINITY;
  for (int k = 0; k < d; k++) in = fmin(in, fmin(xi[k], 1 - xi[k]));
  return in;
}

int lg_locate(lg_env *env, lg_mesh *lm, const double *x, int *cell, double *xi) {
  if (lm->locator && lm->locator->geometry != lm->geometry) {
    lg_locator_free(lm->locator);
    lm->locator = NULL;
  }
  if (!lm->locator && !(lm->locator = locator_build(env, lm))) return -1;
  const lg_locator *L = lm->locator;
  mesh *m = lm->m;
  int d = m->dim, b[3] = {0, 0, 0};
  for (int k = 0; k < d; k++) {
    double t = (x[k] - L->lo[k]) / L->h[k];
    if (!(t >= -1e-9 * L->g[k] && t <= L->g[k] * (1 + 1e-9))) return 1;
    b[k] = (int)floor(t);
    if (b[k] < 0) b[k] = 0;
    if (b[k] > L->g[k] - 1) b[k] = L->g[k] - 1;
  }
  long bi = ((long)b[2] * L->g[1] + b[1]) * L->g[0] + b[0];
  /* the cell where the point is most inside (the largest smallest barycentric coordinate):
   * a point on a shared facet belongs to either, one just outside the boundary to none */
  int best = -1;
  double bestmin = -1e-10, bxi[3] = {0, 0, 0};
  int box = !cell_is_simplex(m->type);
  for (int i = L->start[bi]; i < L->start[bi + 1]; i++) {
    int c = L->list[i];
    if (box) {
      double loc[3] = {0, 0, 0}, in = box_inside(m, c, x, loc);
      if (in > bestmin) {
        bestmin = in;
        best = c;
        memcpy(bxi, loc, sizeof bxi);
      }
      continue;
    }
    double J[3][3], K[3][3], r[3], loc[3] = {0, 0, 0};
    simplex_jacobian(m, c, J, K);
    const int *v = m->cells + (size_t)c * (size_t)m->nvc;
    for (int k = 0; k < d; k++) r[k] = x[k] - m->x[(size_t)v[0] * d + k];
    double lmin = 1;
    for (int k = 0; k < d; k++) {
      for (int j = 0; j < d; j++) loc[k] += K[k][j] * r[j];
      lmin = fmin(lmin, loc[k]);
    }
    double l0 = 1;
    for (int k = 0; k < d; k++) l0 -= loc[k];
    lmin = fmin(lmin, l0);
    if (lmin > bestmin) {
      bestmin = lmin;
      best = c;
      memcpy(bxi, loc, sizeof bxi);
    }
  }
  if (best < 0) return 1;
  *cell = best;
  memcpy(xi, bxi, sizeof(double) * 3);
  return 0;
}

int lg_eval_point(lg_env *env, lg_function *f, const double *x, double *out) {
  int cell;
  double xi[3];
  int rc = lg_locate(env, f->mesh, x, &cell, xi);
  if (rc < 0) return 1;
  if (rc > 0) {
    if (f->mesh->m->dim == 2) lg_seterr(env, "the point (%g, %g) is outside the mesh", x[0], x[1]);
    else lg_seterr(env, "the point (%g, %g, %g) is outside the mesh", x[0], x[1], x[2]);
    return 1;
  }
  double J[3][3], K[3][3];
  cell_jacobian(f->mesh->m, cell, xi, J, K);
  for (int j = 0; j < f->dm->bs; j++) out[j] = lg_eval_at(f->dm, f->x, cell, xi, K, j, -1);
  return 0;
}
