/* pack.c — a whole mesh as one byte buffer and back: what one process reads and sends to the
 * others (lg.mesh.read under mpiexec: rank 0 parses the file, the other ranks unpack its
 * buffer instead of parsing the text again). The buffer holds the cell type, coordinates,
 * cells and their tags, the tagged boundary facets and the names; derived adjacency is
 * rebuilt on demand. Both sides run the same build (native byte order and sizes); the
 * unpacker still checks every length against the buffer's. */
#include "mesh.h"

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define PACK_MAGIC 0x6c67706bu /* "lgpk" */

typedef struct {
  char *b;
  size_t n, cap;
} wbuf;

static int put(wbuf *w, const void *p, size_t n) {
  if (w->n + n > w->cap) {
    size_t cap = w->cap ? w->cap : 4096;
    while (cap < w->n + n) cap *= 2;
    char *nb = realloc(w->b, cap);
    if (!nb) return 1;
    w->b = nb;
    w->cap = cap;
  }
  if (n) memcpy(w->b + w->n, p, n);
  w->n += n;
  return 0;
}

static int put_names(wbuf *w, const mesh_name *t, int n) {
  int bad = 0;
  for (int i = 0; i < n && !bad; i++) {
    int64_t hd[2] = {t[i].tag, (int64_t)strlen(t[i].name)};
    bad = put(w, hd, sizeof hd) || put(w, t[i].name, (size_t)hd[1]);
  }
  return bad;
}

int mesh_pack(const mesh *m, char **buf, size_t *len) {
  wbuf w = {NULL, 0, 0};
  int64_t hd[8] = {PACK_MAGIC, m->type, m->nvert, m->ncell, m->nbf, m->nbname, m->ncname, 0};
  size_t nx = (size_t)m->nvert * (size_t)m->dim, nc = (size_t)m->ncell * (size_t)m->nvc, nf = (size_t)m->nbf * (size_t)m->nvf;
  int bad = put(&w, hd, sizeof hd) || put(&w, m->x, sizeof(double) * nx) || put(&w, m->cells, sizeof(int) * nc) ||
            put(&w, m->cell_tag, sizeof(int) * (size_t)m->ncell) || put(&w, m->bf_verts, sizeof(int) * nf) ||
            put(&w, m->bf_tag, sizeof(int) * (size_t)m->nbf) || put_names(&w, m->bnames, m->nbname) ||
            put_names(&w, m->cnames, m->ncname);
  if (bad) {
    free(w.b);
    return 1;
  }
  *buf = w.b;
  *len = w.n;
  return 0;
}

typedef struct {
  const char *b;
  size_t n, at;
} rbuf;

/* the next n bytes, or NULL past the end */
static const void *take(rbuf *r, size_t n) {
  if (n > r->n - r->at) return NULL;
  const void *p = r->b + r->at;
  r->at += n;
  return p;
}

static int take_names(rbuf *r, mesh *m, int n, int boundary, char *err) {
  for (int i = 0; i < n; i++) {
    int64_t hd[2];
    const void *p = take(r, sizeof hd);
    if (!p) { snprintf(err, MESH_ERRLEN, "a packed mesh ends in its names"); return 1; }
    memcpy(hd, p, sizeof hd);
    const char *s = hd[1] >= 0 ? take(r, (size_t)hd[1]) : NULL;
    char *name = s ? malloc((size_t)hd[1] + 1) : NULL;
    if (!name) { snprintf(err, MESH_ERRLEN, "a packed mesh's name %d is cut or too long", i + 1); return 1; }
    memcpy(name, s, (size_t)hd[1]);
    name[hd[1]] = 0;
    int bad = boundary ? mesh_set_boundary_name(m, (int)hd[0], name) : mesh_set_region_name(m, (int)hd[0], name);
    free(name);
    if (bad) { snprintf(err, MESH_ERRLEN, "%s", m->err); return 1; }
  }
  return 0;
}

mesh *mesh_unpack(const char *buf, size_t len, char *err) {
  rbuf r = {buf, len, 0};
  int64_t hd[8];
  const void *p = take(&r, sizeof hd);
  if (!p) { snprintf(err, MESH_ERRLEN, "a packed mesh of %zu bytes has no header", len); return NULL; }
  memcpy(hd, p, sizeof hd);
  if (hd[0] != PACK_MAGIC || hd[1] < 0 || hd[1] > CELL_INTERVAL || hd[2] < 1 || hd[2] > 0x7fffffff || hd[3] < 1 ||
      hd[3] > 0x7fffffff || hd[4] < 0 || hd[4] > 0x3fffffff || hd[5] < 0 || hd[5] > 0x7fffffff || hd[6] < 0 || hd[6] > 0x7fffffff) {
    snprintf(err, MESH_ERRLEN, "not a packed mesh (a bad header)");
    return NULL;
  }
  cell_type t = (cell_type)hd[1];
  int nvert = (int)hd[2], ncell = (int)hd[3], nbf = (int)hd[4];
  size_t nx = (size_t)nvert * (size_t)cell_dim(t), nc = (size_t)ncell * (size_t)cell_nverts(t);
  const double *x = take(&r, sizeof(double) * nx);
  const int *cells = x ? take(&r, sizeof(int) * nc) : NULL;
  const int *tags = cells ? take(&r, sizeof(int) * (size_t)ncell) : NULL;
  if (!tags) { snprintf(err, MESH_ERRLEN, "a packed mesh of %zu bytes is cut in its cells", len); return NULL; }
  mesh *m = mesh_create(t, nvert, x, ncell, cells, err);
  if (!m) return NULL;
  memcpy(m->cell_tag, tags, sizeof(int) * (size_t)ncell);
  size_t nf = (size_t)nbf * (size_t)m->nvf;
  const int *bv = take(&r, sizeof(int) * nf), *bt = bv ? take(&r, sizeof(int) * (size_t)nbf) : NULL;
  if (!bt) {
    snprintf(err, MESH_ERRLEN, "a packed mesh of %zu bytes is cut in its boundary facets", len);
    mesh_free(m);
    return NULL;
  }
  if (nbf) {
    m->bf_verts = malloc(sizeof(int) * nf);
    m->bf_tag = malloc(sizeof(int) * (size_t)nbf);
    if (!m->bf_verts || !m->bf_tag) {
      snprintf(err, MESH_ERRLEN, "out of memory for %d boundary facets", nbf);
      mesh_free(m);
      return NULL;
    }
    for (size_t i = 0; i < nf; i++)
      if (bv[i] < 0 || bv[i] >= nvert) {
        snprintf(err, MESH_ERRLEN, "a packed mesh's boundary facet %zu refers to vertex %d of %d", i / (size_t)m->nvf + 1, bv[i] + 1, nvert);
        mesh_free(m);
        return NULL;
      }
    memcpy(m->bf_verts, bv, sizeof(int) * nf);
    memcpy(m->bf_tag, bt, sizeof(int) * (size_t)nbf);
    m->nbf = nbf;
  }
  if (take_names(&r, m, (int)hd[5], 1, err) || take_names(&r, m, (int)hd[6], 0, err)) {
    mesh_free(m);
    return NULL;
  }
  if (r.at != len) {
    snprintf(err, MESH_ERRLEN, "a packed mesh has %zu bytes after its end", len - r.at);
    mesh_free(m);
    return NULL;
  }
  return m;
}
