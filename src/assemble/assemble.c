/* assemble.c — environment, meshes with dof maps, discrete functions, regions, the
 * element loop that runs generated kernels, point evaluation (interpolation), and
 * integration of functionals. No PETSc in this file. */
#ifdef _OPENMP
#include <omp.h>
#endif
#include "assemble.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

lg_mesh *lg_mesh_wrap(mesh *m) {
  lg_mesh *lm = calloc(1, sizeof *lm);
  if (lm) lm->m = m;
  return lm;
}

void lg_mesh_changed(lg_mesh *lm) {
  /* dof maps depend on topology only; geometry changes need a new validity check */
  lm->validated = 0;
  lm->geometry++;
}

void lg_mesh_free(lg_mesh *lm) {
  if (!lm) return;
  for (int d = 0; d < 2; d++)
    for (int i = 0; i < 4; i++)
      for (int j = 0; j < FEM_MAXBS; j++) dofmap_free(lm->dm[d][i][j]);
  lg_locator_free(lm->locator);
  lg_dist_dofs_free(lm->ddofs);
  free(lm->part);
  if (lm->dist) mesh_part_free(lm->dist); /* its mesh is lm->m */
  else mesh_free(lm->m);
  free(lm);
}

dofmap *lg_mesh_dofmap(lg_env *env, lg_mesh *lm, int degree, int ncomp, int disc) {
  if (degree < 0 || degree > 3) { lg_seterr(env, "Lagrange degree %d is not available (0, 1, 2, 3)", degree); return NULL; }
  if (ncomp < 1 || ncomp > FEM_MAXBS) { lg_seterr(env, "a vector space has 1 to %d components (got %d)", FEM_MAXBS, ncomp); return NULL; }
  char err[256];
  int d = disc && degree > 0; /* P0 is discontinuous already */
  dofmap **s = &lm->dm[d][degree][0], **v = &lm->dm[d][degree][ncomp - 1];
  if (!*s) {
    *s = dofmap_new(lm->m, degree, d, err);
    if (!*s) { lg_seterr(env, "%s", err); return NULL; }
  }
  if (!*v) {
    *v = dofmap_block(*s, ncomp, err);
    if (!*v) { lg_seterr(env, "%s", err); return NULL; }
  }
  return *v;
}

/* the cells' scale assembly can take: kernels compute in the mesh's units, and a cell's
 * measure h^d (with quadrature weights and basis values around it) must stay well inside
 * the doubles' range: h^d within 1e±280 (a 2D mesh scaled by 1e-155 gave NaN matrices, a 3D
 * one at 1e-110 was reported "inverted or zero-size") */
#define LG_SCALE_EXP 280

static int mesh_check_passes(lg_env *env, lg_mesh *lm);

/* the mesh room's threaded pass (mesh_validate) on the idle cores only:
 * their halves are static, and one whose thread waits for a busy core holds up the pass */
static int mesh_threads(void) {
  int old = 1;
#ifdef _OPENMP
  old = omp_get_max_threads();
  if (old > 1) omp_set_num_threads(lg_threads_for_load(old));
#endif
  return old;
}

int lg_mesh_check(lg_env *env, lg_mesh *lm) {
  if (lm->validated) return 0;
  int old = mesh_threads();
  int rc = mesh_check_passes(env, lm);
#ifdef _OPENMP
  omp_set_num_threads(old);
#endif
  return rc;
}

static int mesh_check_passes(lg_env *env, lg_mesh *lm) {
  /* the longest edge and the invalid cells in one pass over the cells (a P1 setup on 1.57 M
   * tetrahedra spent 80 ms in the two passes, about a third of it) */
  double h;
  int ids[5], n;
  mesh_validate(lm->m, &h, 5, ids, &n);
  int d = lm->m->dim;
  if (h > 0 && isfinite(h) && fabs(d * log10(h)) > LG_SCALE_EXP) {
    double lim = pow(10, floor((double)LG_SCALE_EXP / d));
    lg_seterr(env, "the mesh's cells are about %.3g in size (their longest edge): assembly computes in the mesh's units, "
                   "where a cell's measure (about 1e%+.0f) leaves the range of doubles; scale the coordinates to units where "
                   "cells are between %.0g and %.0g in size (lg.mesh.* with other x1, y1, z1, or mesh:displace), and the "
                   "equation's coefficients with them", h, floor(d * log10(h)), 1 / lim, lim);
    return 1;
  }
  if (n) {
    char list[128] = "";
    size_t used = 0;
    for (int i = 0; i < n && i < 5; i++) /* a distributed mesh's cells by their global numbers */
      used += (size_t)snprintf(list + used, sizeof list - used, "%s%d", i ? ", " : "", (lm->dist ? lm->dist->cglobal[ids[i]] : ids[i]) + 1);
    lg_seterr(env, "the mesh has %d inverted or zero-size cell%s (cell%s %s%s); assembly needs "
                   "every cell positively oriented: repair it with mesh:untangle()",
              n, n == 1 ? "" : "s", n == 1 ? "" : "s", list, n > 5 ? ", ..." : "");
    return 1;
  }
  lm->validated = 1;
  return 0;
}

lg_function *lg_function_new(lg_env *env, lg_mesh *lm, dofmap *dm, const char *name) {
  if (!dm) return NULL;
  int degree = dm->degree, ncomp = dm->bs;
  lg_function *f = calloc(1, sizeof *f);
  if (!f) { lg_seterr(env, "out of memory"); return NULL; }
  f->mesh = lm;
  f->dm = dm;
  f->degree = degree;
  f->x = calloc((size_t)dm->ndof, sizeof(double));
  if (!f->x) { free(f); lg_seterr(env, "out of memory for %d dofs", dm->ndof); return NULL; }
  f->fid = expr_func_new(env->c, FK_DISCRETE, name ? name : "uh", degree, ncomp, f);
  if (f->fid < 0) { free(f->x); free(f); lg_seterr(env, "out of memory"); return NULL; }
  expr_func_get(env->c, f->fid)->disc = dm->disc;
  return f;
}

void lg_function_free(lg_function *f) {
  if (!f) return;
  /* the expression context may still hold leaves naming this function: detach */
  free(f->x);
  free(f);
}

/* ---------------------------------------------------------------- regions */

static int cmp_long(const void *a, const void *b) {
  long x = *(const long *)a, y = *(const long *)b;
  return (x > y) - (x < y);
}

int lg_region_items(lg_env *env, lg_mesh *lm, const region *r, int *n, int **cells, int **facets) {
  mesh *m = lm->m;
  *cells = NULL;
  *facets = NULL;
  *n = 0;
  if (r->kind == REGION_POINTS) {
    /* a vertex: one cell that has it and its local index there (facets[] holds it) */
    *cells = malloc(sizeof(int) * (size_t)(r->ntag + 1));
    *facets = malloc(sizeof(int) * (size_t)(r->ntag + 1));
    if (!*cells || !*facets) { free(*cells); free(*facets); *cells = *facets = NULL; lg_seterr(env, "out of memory"); return 1; }
    for (int i = 0; i < r->ntag; i++) (*cells)[i] = -1;
    for (int c = 0; c < m->ncell; c++)
      for (int k = 0; k < m->nvc; k++)
        for (int i = 0; i < r->ntag; i++)
          if ((*cells)[i] < 0 && m->cells[(size_t)c * (size_t)m->nvc + k] == r->tags[i]) { (*cells)[i] = c; (*facets)[i] = k; }
    for (int i = 0; i < r->ntag; i++)
      if ((*cells)[i] < 0) {
        free(*cells); free(*facets); *cells = *facets = NULL;
        lg_seterr(env, "vertex %d belongs to no cell", r->tags[i] + 1);
        return 1;
      }
    *n = r->ntag;
    return 0;
  }
  if (r->kind == REGION_INTERIOR) {
    /* cells holds the '+' cells then the '-' cells (2n), facets the code
     * f+ + nf*(f- + nf*perm) that interior facet kernels take (kernel.h) */
    if (mesh_build_interior_facets(m)) { lg_seterr(env, "%s", m->err); return 1; }
    int nf = cell_nfacets(m->type), ni = m->nif;
    *cells = malloc(sizeof(int) * (size_t)(2 * ni + 1));
    *facets = malloc(sizeof(int) * (size_t)(ni + 1));
    if (!*cells || !*facets) { free(*cells); free(*facets); *cells = *facets = NULL; lg_seterr(env, "out of memory"); return 1; }
    for (int i = 0; i < ni; i++) {
      (*cells)[i] = m->if_cell[2 * i];
      (*cells)[ni + i] = m->if_cell[2 * i + 1];
      (*facets)[i] = m->if_local[2 * i] + nf * (m->if_local[2 * i + 1] + nf * m->if_perm[i]);
    }
    *n = ni;
    return 0;
  }
  if (r->kind == REGION_CELLS) {
    int cnt = 0;
    for (int c = 0; c < m->ncell; c++) {
      int in = r->ntag == 0;
      for (int t = 0; t < r->ntag && !in; t++) in = m->cell_tag[c] == r->tags[t];
      cnt += in;
    }
    *cells = malloc(sizeof(int) * (size_t)(cnt + 1));
    if (!*cells) { lg_seterr(env, "out of memory"); return 1; }
    int k = 0;
    for (int c = 0; c < m->ncell; c++) {
      int in = r->ntag == 0;
      for (int t = 0; t < r->ntag && !in; t++) in = m->cell_tag[c] == r->tags[t];
      if (in) (*cells)[k++] = c;
    }
    *n = k;
    return 0;
  }
  if (mesh_build_boundary_cells(m)) { lg_seterr(env, "%s", m->err); return 1; }
  int cnt = 0;
  for (int b = 0; b < m->nbf; b++) {
    int in = r->ntag == 0;
    for (int t = 0; t < r->ntag && !in; t++) in = m->bf_tag[b] == r->tags[t];
    cnt += in;
  }
  *cells = malloc(sizeof(int) * (size_t)(cnt + 1));
  *facets = malloc(sizeof(int) * (size_t)(cnt + 1));
  if (!*cells || !*facets) { free(*cells); free(*facets); *cells = *facets = NULL; lg_seterr(env, "out of memory"); return 1; }
  int k = 0;
  for (int b = 0; b < m->nbf; b++) {
    int in = r->ntag == 0;
    for (int t = 0; t < r->ntag && !in; t++) in = m->bf_tag[b] == r->tags[t];
    if (in) {
      (*cells)[k] = m->bf_cell[b];
      (*facets)[k] = m->bf_local[b];
      k++;
    }
  }
  /* a facet under two of the region's tags is one facet of the region, integrated once */
  long *key = malloc(sizeof(long) * (size_t)(k + 1));
  if (!key) { free(*cells); free(*facets); *cells = *facets = NULL; lg_seterr(env, "out of memory"); return 1; }
  for (int i = 0; i < k; i++) key[i] = (long)(*cells)[i] * 8 + (*facets)[i];
  qsort(key, (size_t)k, sizeof(long), cmp_long);
  int u = 0;
  for (int i = 0; i < k; i++) {
    if (u && key[u - 1] == key[i]) continue;
    key[u++] = key[i];
  }
  for (int i = 0; i < u; i++) {
    (*cells)[i] = (int)(key[i] / 8);
    (*facets)[i] = (int)(key[i] % 8);
  }
  free(key);
  *n = u;
  return 0;
}

/* ---------------------------------------------------------------- non-finite data */

/* "(x, y)" of dof k of dm: the first cell that has it */
static void dof_where(const dofmap *dm, int k, char *buf, size_t len) {
  double x[3] = {0, 0, 0};
  for (int c = 0; c < dm->m->ncell; c++)
    for (int i = 0; i < dm->nloc; i++)
      if (dm->cell_dofs[(size_t)c * dm->nloc + i] == k) {
        dofmap_node_coords(dm, c, i, x);
        if (dm->m->dim == 2) snprintf(buf, len, "(%g, %g)", x[0], x[1]);
        else snprintf(buf, len, "(%g, %g, %g)", x[0], x[1], x[2]);
        return;
      }
  snprintf(buf, len, "(unknown place)");
}

int lg_check_finite(lg_env *env, const dofmap *dm, const double *v, const char *what) {
  for (int k = 0; k < dm->ndof; k++)
    if (!isfinite(v[k])) {
      char at[96];
      dof_where(dm, k, at, sizeof at);
      lg_seterr(env, "%s is not finite (%g) at dof %d %s", what, v[k], k + 1, at);
      return 1;
    }
  return 0;
}

/* ---------------------------------------------------------------- element loop */

int lg_bind_discrete(lg_env *env, lg_mesh *lm, const lg_kernel *k, int nextra,
                     const coef_binding *extra, coef_binding *out) {
  for (int i = 0; i < k->ncoef; i++) {
    int f = k->coef_func[i];
    out[i].func = f;
    int found = 0;
    for (int j = 0; j < nextra; j++)
      if (extra[j].func == f) { out[i] = extra[j]; found = 1; }
    if (found) continue;
    expr_func_info *fi = expr_func_get(env->c, f);
    if (!fi || fi->kind != FK_DISCRETE || !fi->user) {
      lg_seterr(env, "%s %s has no values here: %s", fi && fi->kind == FK_UNKNOWN ? "the unknown" : "the function",
                fi ? fi->name : "?", fi && fi->kind == FK_UNKNOWN ? "it is not an unknown of this problem; use a discrete function (a solution or lg.interpolate)" : "it was freed");
      return 1;
    }
    lg_function *fn = fi->user;
    if (fn->mesh != lm) {
      lg_seterr(env, "the discrete function %s lives on a different mesh", fi->name);
      return 1;
    }
    char what[96];
    snprintf(what, sizeof what, "the discrete function %.60s", fi->name);
    if (lg_check_finite(env, fn->dm, fn->x, what)) return 1;
    out[i].dm = fn->dm;
    out[i].vals = fn->x;
  }
  return 0;
}

/* a 64-bit hash of what the point cache depends on: the coordinates and the items */
static uint64_t mix(uint64_t h, const void *p, size_t n) {
  const unsigned char *b = p;
  size_t i = 0;
  for (; i + 8 <= n; i += 8) {
    uint64_t w;
    memcpy(&w, b + i, 8);
    h = (h ^ w) * 0x9E3779B97F4A7C15ull;
    h ^= h >> 29;
  }
  for (; i < n; i++) h = (h ^ b[i]) * 0x100000001B3ull;
  return h;
}

/* the point cache mode of this assembly (kernel.h, kernel_pcache): 0 compute, 1 compute and
 * store, 2 read; *C the cache when 1 or 2. The kernel links to the group of its csig and
 * item list (created on first use). */
static int pcache_mode(lg_env *env, const lg_kernel *k, const mesh *m, int nitems, const int *cells,
                       const int *facets, double **C) {
  *C = NULL;
  kernel_pcache *pc = k->pc;
  if (!pc || env->no_point_cache) return 0;
  uint64_t ih = 0xcbf29ce484222325ull;
  ih = mix(ih, &nitems, sizeof nitems);
  ih = mix(ih, cells, sizeof(int) * (size_t)nitems);
  if (facets) ih = mix(ih, facets, sizeof(int) * (size_t)nitems);
  if (!pc->g || pc->g->sig != k->csig || pc->g->items != ih) {
    kernel_pcache_unlink(pc);
    kernel_pcache_group *head = &env->pcache, *g = head->next;
    while (g != head && !(g->sig == k->csig && g->items == ih)) g = g->next;
    if (g == head) {
      if (!(g = calloc(1, sizeof *g))) return 0;
      g->sig = k->csig;
      g->items = ih;
      g->prev = head;
      g->next = head->next;
      head->next->prev = g;
      head->next = g;
    }
    g->refs++;
    pc->g = g;
  }
  kernel_pcache_group *g = pc->g;
  uint64_t h = mix(0x9E3779B97F4A7C15ull, m->x, sizeof(double) * (size_t)m->nvert * (size_t)m->dim);
  size_t n = (size_t)nitems * (size_t)k->nq * (size_t)k->ncache;
  if (g->valid && g->key == h && g->n == n) { *C = g->v; return 2; }
  int store = n > 0 && n <= KER_PCACHE_MAX && ((g->seen && g->key == h) || n <= KER_PCACHE_FIRST);
  g->key = h;
  g->seen = 1;
  g->valid = 0;
  if (store) {
    if (g->n != n) {
      free(g->v);
      g->v = malloc(sizeof(double) * n);
      g->n = g->v ? n : 0;
    }
    if (g->v) { *C = g->v; return 1; }
  }
  return 0;
}

#define LG_TIER_CHECK 2048 /* items between two looks at the JIT's tiers */

/* what every item of a list reads: the kernel, its items, coefficients and caches */
typedef struct {
  const lg_kernel *k;
  const mesh *m;
  const int *cells, *cells_m, *facets; /* cells_m: interior facets' '-' cells, or NULL */
  const coef_binding *bind;
  const double *P;
  double *C;                           /* the list's point cache, or NULL */
  size_t cstride;
  int cm, size;
} item_ctx;

/* item it of the range: its vertex coordinates into X (two cells' for an interior facet),
 * its coefficients into W, and the kernel's tensor into dst (zeroed first) */
static inline void eval_item(const item_ctx *ic, kernel_fn fn, int it, double *X, double *W, double *dst) {
  const lg_kernel *k = ic->k;
  const mesh *m = ic->m;
  int nvc = m->nvc, d = m->dim;
  int c = ic->cells[it], cm2 = ic->cells_m ? ic->cells_m[it] : c;
  const int *v = m->cells + (size_t)c * (size_t)nvc;
  for (int i = 0; i < nvc; i++)
    for (int j = 0; j < d; j++) X[i * d + j] = m->x[(size_t)v[i] * d + j];
  if (ic->cells_m) {
    const int *vm = m->cells + (size_t)cm2 * (size_t)nvc;
    for (int i = 0; i < nvc; i++)
      for (int j = 0; j < d; j++) X[(nvc + i) * d + j] = m->x[(size_t)vm[i] * d + j];
  }
  for (int ci = 0; ci < k->ncoef; ci++) {
    const dofmap *dm = ic->bind[ci].dm;
    const int *cd = dm->cell_dofs + (size_t)(k->coef_side[ci] ? cm2 : c) * (size_t)dm->nloc;
    double *w = W + k->coef_off[ci];
    for (int i = 0; i < dm->nloc; i++) w[i] = ic->bind[ci].vals[cd[i]];
  }
  memset(dst, 0, sizeof(double) * (size_t)ic->size);
  fn(X, W, ic->P, ic->facets ? ic->facets[it] : 0, dst, ic->C ? ic->C + (size_t)it * ic->cstride : NULL, ic->cm);
}

static double elapsed_ms(const struct timespec *t0, const struct timespec *t1) {
  return (double)(t1->tv_sec - t0->tv_sec) * 1e3 + (double)(t1->tv_nsec - t0->tv_nsec) * 1e-6;
}

int lg_chunk_items(int size) {
  int n = LG_CHUNK_VALUES / (size > 0 ? size : 1);
  return n < 16 ? 16 : n > 4096 ? 4096 : n;
}

/* one buffer of chunk items' tensors per thread */
static int chunk_bufs_reserve(lg_env *env, lg_chunk_bufs *cb, int size, int nthr) {
  size_t n = (size_t)lg_chunk_items(size) * (size_t)size + 1;
  if (n <= cb->cap && nthr <= cb->nb) return 0;
  lg_chunk_bufs_free(cb);
  if (!(cb->b = calloc((size_t)nthr, sizeof *cb->b))) { lg_seterr(env, "out of memory"); return 1; }
  cb->nb = nthr;
  int ok = 1;
  for (int b = 0; b < nthr; b++) ok &= (cb->b[b] = malloc(sizeof(double) * n)) != NULL;
  if (!ok) { lg_chunk_bufs_free(cb); lg_seterr(env, "out of memory"); return 1; }
  cb->cap = n;
  return 0;
}

void lg_chunk_bufs_free(lg_chunk_bufs *cb) {
  for (int b = 0; b < cb->nb; b++) free(cb->b[b]);
  free(cb->b);
  cb->b = NULL;
  cb->nb = 0;
  cb->cap = 0;
}

void lg_windows_free(lg_windows *w) {
  free(w->ew);
  free(w->range);
  memset(w, 0, sizeof *w);
}

/* n windows of the consumer's items (equal counts of consecutive items) and each element
 * row's window: that of the first item with its row */
static int windows_build(lg_env *env, const lg_consumer *cons, int n, int total) {
  lg_windows *w = cons->win;
  if (w->n == n && w->nrows == cons->nrows && w->nitems == total && w->first == cons->first && w->ew) return 0;
  lg_windows_free(w);
  int R[LG_ITEM_ROWS], nr = cons->rows(cons->ud, 0, R);
  unsigned char *own = malloc((size_t)cons->nrows + 1);
  w->ew = malloc((size_t)total * (size_t)nr + 1);
  w->range = malloc(sizeof(int) * 2 * (size_t)n);
  if (!own || !w->ew || !w->range) {
    free(own);
    lg_windows_free(w);
    lg_seterr(env, "out of memory");
    return 1;
  }
  memset(own, LG_NO_WINDOW, (size_t)cons->nrows);
  for (int i = 0; i < n; i++) w->range[2 * i] = total, w->range[2 * i + 1] = 0;
  for (int it = 0; it < total; it++) {
    int wi = (int)((long)it * n / total);
    unsigned char *e = w->ew + (size_t)it * (size_t)nr;
    cons->rows(cons->ud, it, R);
    for (int i = 0; i < nr; i++) {
      if (R[i] < 0 || R[i] >= cons->nrows) { e[i] = LG_NO_WINDOW; continue; }
      if (own[R[i]] == LG_NO_WINDOW) own[R[i]] = (unsigned char)wi;
      int x = e[i] = own[R[i]];
      if (it < w->range[2 * x]) w->range[2 * x] = it;
      w->range[2 * x + 1] = it + 1;
    }
  }
  free(own);
  w->n = n;
  w->nrows = cons->nrows;
  w->nitems = total;
  w->first = cons->first;
  w->nr = nr;
  return 0;
}

/* threads below this much estimated work (thread time, ms) do not pay: a parallel region's
 * start and end, and on a busy machine a thread that waits for a core, cost more */
#define LG_PAR_MIN_MS 2.0
/* windows per thread at most: a thread slowed by another process leaves its share to the
 * others */
#define LG_WINDOWS_PER_THREAD 4
#define LG_WINDOW_ITEMS 16384

/* the threads an assembly of total items with kernel k uses: all of them when its last
 * measured cost says the work pays (on the first assembly, when it has many items) */
static int assembly_threads(const lg_env *env, const lg_kernel *k, int total) {
#ifdef _OPENMP
  int T = omp_get_max_threads();
  if (T < 2 || omp_in_parallel() || total < 64) return 1;
  double per = jit_item_ms(env->jit, k->jid);
  if (per > 0 ? per * total < LG_PAR_MIN_MS : total < 4096) return 1;
  /* threads for the idle cores only: a thread that waits for a core holds up the end of the
   * loop by a scheduler slice (P1 N = 40, a 15 ms assembly, beside one busy process: 1.20×
   * one thread's time on two threads; P1 N = 64: 0.054-0.075 s against 0.064) */
  T = lg_threads_for_load(T);
  if (T < 2) return 1;
  if (T > LG_NO_WINDOW / LG_WINDOWS_PER_THREAD) T = LG_NO_WINDOW / LG_WINDOWS_PER_THREAD; /* windows fit a byte */
  return T;
#else
  (void)env, (void)k, (void)total;
  return 1;
#endif
}

/* what the threads of one element loop share */
typedef struct {
  lg_env *env;
  const item_ctx *ic;
  const lg_consumer *cons;
  const lg_windows *win; /* NULL: one window, every row and item */
  int total, chunk, nwin;
  kernel_fn fn;          /* the best code now (thread 0 looks at the JIT's tiers between runs) */
  int stop, fail;
  struct timespec t0;    /* since the last look */
} loop_ctx;

/* the items of window w in runs of consecutive items, each run through the consumer */
static void run_window(loop_ctx *L, int w, double *buf, double *W, int tid) {
  const lg_windows *win = L->win;
  const item_ctx *ic = L->ic;
  int i0 = win ? win->range[2 * w] : 0, i1 = win ? win->range[2 * w + 1] : L->total;
  double X[8 * 3 * 2];
#define IN_WINDOW(it) (!win || memchr(win->ew + (size_t)(it) * (size_t)win->nr, w, (size_t)win->nr))
  for (int it = i0; it < i1;) {
    if (!IN_WINDOW(it)) { it++; continue; }
    if (__atomic_load_n(&L->stop, __ATOMIC_RELAXED)) return;
    kernel_fn fn = __atomic_load_n(&L->fn, __ATOMIC_ACQUIRE);
    int f = it, n = 0;
    for (; it < i1 && n < L->chunk && IN_WINDOW(it); it++, n++)
      eval_item(ic, fn, it, X, W, buf + (size_t)n * (size_t)ic->size);
    const unsigned char *ew = win ? win->ew + (size_t)f * (size_t)win->nr : NULL;
    if (L->cons->use(L->cons->ud, f, n, buf, ew, w)) __atomic_store_n(&L->stop, 1, __ATOMIC_RELAXED);
    if (tid == 0) { /* the time so far to the JIT's tiers, and its best code now */
      struct timespec t1;
      clock_gettime(CLOCK_MONOTONIC, &t1);
      jit_account(L->env->jit, ic->k->jid, elapsed_ms(&L->t0, &t1));
      L->t0 = t1;
      __atomic_store_n(&L->fn, jit_current(L->env->jit, ic->k->jid, ic->k->fn), __ATOMIC_RELEASE);
    }
  }
#undef IN_WINDOW
}

int lg_assemble_sum(lg_env *env, lg_mesh *lm, const lg_kernel *k, int total, const int *cells, const int *facets,
                    const coef_binding *bind, double *out) {
  mesh *m = lm->m;
  double *C = NULL;
  int cm = pcache_mode(env, k, m, total, cells, facets, &C);
  if (k->pc) { k->pc->mode = cm; env->pcache_uses[cm]++; }
  item_ctx ic = {k, m, cells, k->facet == 2 ? cells + total : NULL, facets, bind, expr_param_values(env->c), C,
                 (size_t)k->nq * (size_t)k->ncache, cm, 1};
  kernel_fn fn = jit_current(env->jit, k->jid, k->fn);
  struct timespec t0, t1;
  clock_gettime(CLOCK_MONOTONIC, &t0);
  double X[8 * 3 * 2], A[FEM_MAXLOC * KER_MAXFIELD * FEM_MAXLOC * KER_MAXFIELD / 4 + 64], sum = 0;
  double *W = malloc(sizeof(double) * (size_t)(k->wsize + 1));
  if (!W) { lg_seterr(env, "out of memory"); return 1; }
  for (int it = 0; it < total; it++) {
    if (it && it % LG_TIER_CHECK == 0) {
      clock_gettime(CLOCK_MONOTONIC, &t1);
      jit_account(env->jit, k->jid, elapsed_ms(&t0, &t1));
      t0 = t1;
      fn = jit_current(env->jit, k->jid, k->fn);
    }
    eval_item(&ic, fn, it, X, W, A);
    sum += A[0];
  }
  free(W);
  *out += sum;
  clock_gettime(CLOCK_MONOTONIC, &t1);
  jit_account(env->jit, k->jid, elapsed_ms(&t0, &t1));
  if (cm == 1) k->pc->g->valid = 1;
  return 0;
}

/* The element loop (assemble.h): windows of the consumer's rows as tasks over the threads
 * that pay (assembly_threads), one parallel region, no barrier inside. An item evaluated by
 * two windows writes the same point cache slice twice with the same values. */
int lg_assemble_chunks(lg_env *env, lg_mesh *lm, const lg_kernel *k, int total, const int *cells, const int *facets,
                       const coef_binding *bind, const lg_consumer *cons) {
  mesh *m = lm->m;
  double *C = NULL;
  int cm = pcache_mode(env, k, m, total, cells, facets, &C);
  if (k->pc) { k->pc->mode = cm; env->pcache_uses[cm]++; }
  int size = k->arity == 2 ? k->rows.size * k->cols.size : k->rows.size;
  /* interior facets: the '-' cells follow the '+' cells (lg_region_items) */
  item_ctx ic = {k, m, cells, k->facet == 2 ? cells + total : NULL, facets, bind, expr_param_values(env->c), C,
                 (size_t)k->nq * (size_t)k->ncache, cm, size};
  /* windows per thread: up to LG_WINDOWS_PER_THREAD, one per LG_WINDOW_ITEMS items (the items
   * along a cut are evaluated twice: a Neo-Hookean Jacobian on 24 576 cells in 8 windows
   * took 0.197 s on 2 threads, in 2 windows 0.17) */
  int nthr = assembly_threads(env, k, total), per = total / (nthr * LG_WINDOW_ITEMS);
  int nwin = nthr > 1 ? nthr * (per < 1 ? 1 : per > LG_WINDOWS_PER_THREAD ? LG_WINDOWS_PER_THREAD : per) : 1;
  if (nwin > total / 8) nwin = 1, nthr = 1; /* a window of a few items does not pay */
  if (chunk_bufs_reserve(env, cons->bufs, size, nthr) || (nwin > 1 && windows_build(env, cons, nwin, total))) return 1;
  loop_ctx L = {env, &ic, cons, nwin > 1 ? cons->win : NULL, total, lg_chunk_items(size), nwin,
                jit_current(env->jit, k->jid, k->fn), 0, 0, {0, 0}};
  struct timespec ts, t1;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  L.t0 = ts;
#ifdef _OPENMP
#pragma omp parallel num_threads(nthr) if (nthr > 1)
#endif
  {
    int tid = 0;
#ifdef _OPENMP
    tid = omp_get_thread_num();
#endif
    double *W = malloc(sizeof(double) * (size_t)(k->wsize + 1));
    if (!W) __atomic_store_n(&L.fail, 1, __ATOMIC_RELAXED), __atomic_store_n(&L.stop, 1, __ATOMIC_RELAXED);
#ifdef _OPENMP
#pragma omp for schedule(dynamic, 1) nowait
#endif
    for (int w = 0; w < nwin; w++)
      if (W) run_window(&L, w, cons->bufs->b[tid], W, tid);
    free(W);
  }
  clock_gettime(CLOCK_MONOTONIC, &t1);
  jit_account(env->jit, k->jid, elapsed_ms(&L.t0, &t1));
  jit_cost(env->jit, k->jid, total, elapsed_ms(&ts, &t1) * nthr);
  if (L.fail) { lg_seterr(env, "out of memory"); return 1; }
  if (L.stop) return 1;
  if (cm == 1) k->pc->g->valid = 1;
  return 0;
}

/* A parallel run's share of a list of items for a sum over the ranks (functionals and their
 * derivatives): a contiguous slice of the items */
static void rank_slice(int n, int *f0, int *f1) {
  int size = lg_mpi_size(), rank = lg_mpi_rank();
  *f0 = (int)((long)n * rank / size);
  *f1 = (int)((long)n * (rank + 1) / size);
}

int lg_assemble_share(lg_env *env, lg_mesh *lm, const lg_kernel *k, int nitems, const int *cells, const int *facets,
                      const coef_binding *bind, double *out, lg_consumer *cons, int *first) {
  int f0 = 0, f1 = nitems, interior = k->facet == 2;
  if (lm->dist && k->arity == 0) {
    /* a distributed mesh's number: each rank the items of its owned cells (an interior
     * facet's '+' cell), every item of the whole mesh once */
    *first = 0;
    int rank = lg_mpi_rank(), n = 0, *own = malloc(sizeof(int) * (2 * (size_t)nitems + 1)), *of = NULL;
    if (own && facets) of = malloc(sizeof(int) * ((size_t)nitems + 1));
    if (!own || (facets && !of)) { free(own); lg_seterr(env, "out of memory"); return 1; }
    for (int i = 0; i < nitems; i++)
      if (lm->dist->cowner[cells[i]] == rank) {
        if (of) of[n] = facets[i];
        own[n++] = i;
      }
    for (int i = 0; i < n; i++) { /* item numbers into cells: '+' cells, then the '-' ones */
      if (interior) own[n + i] = cells[nitems + own[i]];
      own[i] = cells[own[i]];
    }
    int rc = lg_assemble_sum(env, lm, k, n, own, of, bind, out);
    free(own);
    free(of);
    return rc;
  }
  /* a distributed mesh's vector: every local item, which completes the entries of the owned
   * dofs (all their cells are here) in the whole mesh's order; the caller brings the ghost
   * dofs their owners' values (lg_dist_ghosts) */
  if (lg_mpi_size() > 1 && !lm->dist) rank_slice(nitems, &f0, &f1);
  *first = f0;
  if (f1 <= f0) return 0;
  /* a slice of a plain list starts at its first item; an interior list's '-' cells follow
   * all its '+' cells, so a slice of it is a copy of both parts (the consumer indexes the
   * whole list from *first) */
  const int *c = cells + f0, *f = facets ? facets + f0 : NULL;
  int *part = NULL, n = f1 - f0;
  if (interior && n < nitems) {
    if (!(part = malloc(sizeof(int) * 2 * (size_t)n))) { lg_seterr(env, "out of memory"); return 1; }
    memcpy(part, cells + f0, sizeof(int) * (size_t)n);
    memcpy(part + n, cells + nitems + f0, sizeof(int) * (size_t)n);
    c = part;
  }
  int rc;
  if (k->arity == 0) rc = lg_assemble_sum(env, lm, k, n, c, f, bind, out);
  else {
    cons->first = f0;
    rc = lg_assemble_chunks(env, lm, k, n, c, f, bind, cons);
  }
  free(part);
  return rc;
}

int lg_sum_ranks(lg_env *env, double *out, size_t n, int rc) {
  if (lg_mpi_size() == 1) return rc;
  /* every rank reduces, failed or not, so that none waits; the message is the failed rank's */
  double flag = rc;
  int bad = lg_allreduce(&flag, 1, LG_MAX);
  for (size_t at = 0; !bad && !flag && at < n; at += 1u << 26)
    bad = lg_allreduce(out + at, (int)(n - at < (1u << 26) ? n - at : 1u << 26), LG_SUM);
  if (bad) { lg_seterr(env, "the sum over the ranks failed"); return 1; }
  if (flag && !rc) { lg_seterr(env, "another rank failed to evaluate the integral (its message is on stderr)"); return 1; }
  return rc;
}

/* ---------------------------------------------------------------- point evaluation */

typedef struct {
  lg_env *env;
  lg_mesh *lm;
  int cell;
  double xi[3], x[3], K[3][3];
  int nbind;
  const coef_binding *bind;
} pt_ctx;

static int pt_leaf(void *ud, const expr *e, double *out) {
  pt_ctx *p = ud;
  if (e->kind == E_COORD) { *out = p->x[e->i0]; return 0; }
  if (e->kind == E_NORMAL) { lg_seterr(p->env, "the normal vector has no value at a point"); return 1; }
  const coef_binding *b = NULL;
  for (int i = 0; i < p->nbind; i++)
    if (p->bind[i].func == e->i0) b = &p->bind[i];
  if (!b) {
    expr_func_info *fi = expr_func_get(p->env->c, e->i0);
    lg_seterr(p->env, "%s has no value here", fi ? fi->name : "a function");
    return 1;
  }
  if (e->order > 1) { lg_seterr(p->env, "second derivatives cannot be evaluated at points yet"); return 1; }
  *out = lg_eval_leaf(b->dm, b->vals, p->cell, p->xi, p->K, e);
  return 0;
}

double lg_eval_at(const dofmap *dm, const double *vals, int cell, const double *xi, const double K[3][3], int comp, int dir) {
  double val[FEM_MAXLOC], grad[FEM_MAXLOC * 3];
  lagrange_eval(&dm->el, xi, val, grad);
  int bs = dm->bs, dim = dm->m->dim;
  if (comp >= bs) comp = 0;
  const int *cd = dm->cell_dofs + (size_t)cell * (size_t)dm->nloc;
  double s = 0;
  for (int i = 0; i < dm->el.nloc; i++) {
    double phi;
    if (dir < 0) phi = val[i];
    else {
      phi = 0;
      for (int k = 0; k < dim; k++) phi += grad[i * dim + k] * K[k][dir];
    }
    s += vals[cd[i * bs + comp]] * phi;
  }
  return s;
}

double lg_eval_leaf(const dofmap *dm, const double *vals, int cell, const double *xi, const double K[3][3], const expr *e) {
  int dir = -1;
  for (int d = 0; d < EXPR_MAXDIM; d++)
    if (e->alpha[d]) dir = d;
  return lg_eval_at(dm, vals, cell, xi, K, e->i1, dir);
}

static int bind_all_discrete(lg_env *env, lg_mesh *lm, expr_tape *t, coef_binding *bind, int *nb) {
  *nb = 0;
  for (int i = 0; i < t->n; i++) {
    const expr *e = t->node[i];
    if (e->kind != E_FIELD) continue;
    int have = 0;
    for (int j = 0; j < *nb; j++) have |= bind[j].func == e->i0;
    if (have) continue;
    expr_func_info *fi = expr_func_get(env->c, e->i0);
    if (!fi || fi->kind != FK_DISCRETE || !fi->user) {
      lg_seterr(env, "the expression contains the %s %s, which has no values; use a discrete "
                     "function (a solution or lg.interpolate)",
                fi && fi->kind == FK_TEST ? "test function" : "unknown", fi ? fi->name : "?");
      return 1;
    }
    lg_function *fn = fi->user;
    if (fn->mesh != lm) { lg_seterr(env, "the discrete function %s lives on a different mesh", fi->name); return 1; }
    if (*nb >= KER_MAXCOEF) {
      lg_seterr(env, "an integrand reads more than %d discrete functions (coefficients, controls), the most a kernel takes: split "
                     "the integral into several (docs/lua-api.md, \"Limits\")", KER_MAXCOEF);
      return 1;
    }
    bind[*nb].func = e->i0;
    bind[*nb].dm = fn->dm;
    bind[*nb].vals = fn->x;
    (*nb)++;
  }
  return 0;
}

int lg_interpolate(lg_env *env, lg_function *f, expr *e) {
  if (!e) { lg_seterr(env, "%s", expr_error(env->c)); return 1; }
  int bs = f->dm->bs;
  expr *roots[FEM_MAXBS];
  if (bs == 1) {
    if (e->kind == E_LIST) {
      char sh[64];
      expr_describe_shape(e, sh, sizeof sh);
      lg_seterr(env, "the function is a scalar, the expression %s", sh);
      return 1;
    }
    roots[0] = e;
  } else {
    char sh[64];
    expr_describe_shape(e, sh, sizeof sh);
    if (e->kind != E_LIST || e->n != bs) { lg_seterr(env, "the function has %d components, the expression is %s", bs, sh); return 1; }
    for (int j = 0; j < bs; j++) {
      roots[j] = e->ch[j];
      if (roots[j]->kind == E_LIST) { lg_seterr(env, "the function has %d components, the expression is %s", bs, sh); return 1; }
    }
  }
  expr_tape t;
  if (expr_tape_build(env->c, bs, roots, &t)) { lg_seterr(env, "%s", expr_error(env->c)); return 1; }
  coef_binding bind[KER_MAXCOEF];
  int nb;
  if (bind_all_discrete(env, f->mesh, &t, bind, &nb)) { expr_tape_free(&t); return 1; }
  double *w = malloc(sizeof(double) * (size_t)(t.n + 1));
  double *tmp = f->x;
  int share = 0;
  for (int i = 0; i < nb; i++) share |= bind[i].vals == f->x;
  if (share) tmp = malloc(sizeof(double) * (size_t)f->dm->ndof);
  /* each node once (a P1 node is shared by about 6 triangles or 24 tetrahedra); a
   * discontinuous expression (a gradient of a discrete function) takes the first cell's value */
  unsigned char *done = calloc((size_t)f->dm->ndof + 1, 1);
  if (!w || !tmp || !done) { free(w); free(done); if (share) free(tmp); expr_tape_free(&t); lg_seterr(env, "out of memory"); return 1; }
  mesh *m = f->mesh->m;
  pt_ctx p = {env, f->mesh, 0, {0, 0, 0}, {0, 0, 0}, {{0}}, nb, bind};
  int rc = 0;
  for (int c = 0; c < m->ncell && !rc; c++) {
    double J[3][3];
    int mapped = 0;
    p.cell = c;
    const int *cd = f->dm->cell_dofs + (size_t)c * f->dm->nloc;
    for (int k = 0; k < f->dm->el.nloc && !rc; k++) {
      if (done[cd[k * bs]]) continue;
      done[cd[k * bs]] = 1;
      memcpy(p.xi, f->dm->el.node + 3 * k, sizeof p.xi);
      if (!mapped) { cell_jacobian(m, c, p.xi, J, p.K); mapped = cell_is_simplex(m->type); }
      dofmap_node_coords(f->dm, c, k * bs, p.x);
      double v[FEM_MAXBS];
      rc = expr_tape_eval(&t, expr_param_values(env->c), pt_leaf, &p, w, v);
      for (int j = 0; j < bs && !rc; j++) {
        if (!isfinite(v[j])) {
          char buf[200];
          expr_print(env->c, roots[j], buf, sizeof buf);
          if (m->dim == 2) lg_seterr(env, "the expression %s is not finite (%g) at (%g, %g)", buf, v[j], p.x[0], p.x[1]);
          else lg_seterr(env, "the expression %s is not finite (%g) at (%g, %g, %g)", buf, v[j], p.x[0], p.x[1], p.x[2]);
          rc = 1;
        }
        if (!rc) tmp[cd[k * bs + j]] = v[j];
      }
    }
  }
  if (share && !rc) memcpy(f->x, tmp, sizeof(double) * (size_t)f->dm->ndof);
  if (share) free(tmp);
  free(done);
  free(w);
  expr_tape_free(&t);
  return rc;
}

int lg_quad_degree(lg_env *env, expr *e, int order, cell_type ct) {
  if (order >= 0) return order > FEM_MAXDEG ? FEM_MAXDEG : order;
  /* the estimate treats sin, exp, ... as degree +2 (as FEniCS does); products of such
   * factors overestimate quickly, so automatic orders stop at 12 (2D) and 8 (3D): pass
   * {order=} for more */
  int d = expr_degree_cell(env->c, e, 1, cell_is_simplex(ct), NULL);
  int cap = cell_dim(ct) == 2 ? 12 : 8;
  return d > cap ? cap : d;
}

/* the polynomial degree of the products a kernel integrates: coefficient degree plus the
 * degrees of the test and trial basis functions (less their derivative orders on simplices;
 * a derivative of a Q1 function is still linear in the other variables), so that a
 * stiffness matrix is not integrated with the rule a transcendental load needs */
static int leaf_degree(lg_env *env, const expr *leaf, int simplex) {
  expr_func_info *fi = expr_func_get(env->c, leaf->i0);
  int d = fi ? fi->degree - (simplex ? leaf->order : 0) : 0;
  return d < 0 ? 0 : d;
}

int lg_table_degree(lg_env *env, const coef_table *t, int arity, cell_type ct) {
  int d = 0, sx = cell_is_simplex(ct), dim = cell_dim(ct);
  int n = arity == 2 ? t->njac : t->nres;
  for (int i = 0; i < n; i++) {
    int k;
    if (arity == 2)
      k = expr_degree_cell(env->c, t->jac[i], 1, sx, NULL) + leaf_degree(env, t->jac_test[i], sx) + leaf_degree(env, t->jac_trial[i], sx);
    else k = expr_degree_cell(env->c, t->res[i], 1, sx, NULL) + leaf_degree(env, t->res_leaf[i], sx);
    if (k > d) d = k;
  }
  int cap = dim == 2 ? 12 : 8;
  return d > cap ? cap : d;
}

int lg_integrate(lg_env *env, lg_mesh *lm, const region *r, expr *e, int order, double *result) {
  if (!e) { lg_seterr(env, "%s", expr_error(env->c)); return 1; }
  if (e->kind == E_LIST) {
    char s[64];
    expr_describe_shape(e, s, sizeof s);
    lg_seterr(env, "lg.integrate: the integrand must be a scalar, got %s", s);
    return 1;
  }
  if (lg_mesh_check(env, lm)) return 1;
  kernel_spec s = {0, NULL, e, env->no_vector_math};
  int qd = lg_quad_degree(env, e, order, lm->m->type), ct = (int)lm->m->type;
  int facet = r->kind == REGION_BOUNDARY ? 1 : r->kind == REGION_INTERIOR ? 2 : 0;
  /* the kernel of the same integrand, kept from an earlier call, or a new one in the least
   * recently used place */
  lg_kept_kernel *kk = NULL, *old = &env->kept[0];
  for (int i = 0; i < LG_INTEGRATE_KEEP && !kk; i++) {
    lg_kept_kernel *c = &env->kept[i];
    if (c->e == e && c->cell == ct && c->facet == facet && c->qdeg == qd) kk = c;
    else if (c->used < old->used) old = c;
  }
  if (!kk) {
    kernel_release(&old->k);
    old->e = NULL;
    char err[LG_ERRLEN];
    if (kernel_build(env->jit, env->c, lm->m->type, facet, qd, &s, NULL, NULL, &old->k, err, sizeof err)) {
      lg_seterr(env, "%s", err);
      return 1;
    }
    *old = (lg_kept_kernel){e, ct, facet, qd, 0, old->k};
    env->kernel_ms += old->k.compile_ms;
    env->nkernels += !old->k.cached;
    kk = old;
  }
  kk->used = ++env->nuse;
  const lg_kernel k = kk->k;
  coef_binding bind[KER_MAXCOEF];
  if (lg_bind_discrete(env, lm, &k, 0, NULL, bind)) return 1;
  int n, *cells, *facets;
  if (lg_region_items(env, lm, r, &n, &cells, &facets)) return 1;
  *result = 0;
  int first;
  int rc = lg_assemble_share(env, lm, &kk->k, n, cells, facets, bind, result, NULL, &first);
  rc = lg_sum_ranks(env, result, 1, rc);
  free(cells);
  free(facets);
  if (!rc && !isfinite(*result)) {
    lg_seterr(env, "the integral is not finite (%g): the integrand is not finite somewhere (a division by zero, the "
                   "log or square root of a negative value?)", *result);
    return 1;
  }
  return rc;
}
