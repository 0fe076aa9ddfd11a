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

/* the bytes of the names t[0 .. n - 1] packed: tag, length, text each */
static size_t names_size(const mesh_name *t, int n) {
  size_t z = 0;
  for (int i = 0; i < n; i++) z += 2 * sizeof(int64_t) + strlen(t[i].name);
  return z;
}

static char *put(char *at, const void *p, size_t n) {
  if (n) memcpy(at, p, n);
  return at + n;
}

static char *put_names(char *at, const mesh_name *t, int n) {
  for (int i = 0; i < n; i++) {
    int64_t hd[2] = {t[i].tag, (int64_t)strlen(t[i].name)};
    at = put(at, hd, sizeof hd);
    at = put(at, t[i].name, (size_t)hd[1]);
  }
  return at;
}

size_t mesh_pack_size(const mesh *m) {
  size_t nx = (size_t)m->nvert * (size_t)m->dim, nc = (size_t)m->ncell * (size_t)m->nvc, nf = (size_t)m->nbf * (size_t)m->nvf;
  return 8 * sizeof(int64_t) + sizeof(double) * nx + sizeof(int) * (nc + (size_t)m->ncell + nf + (size_t)m->nbf) +
         names_size(m->bnames, m->nbname) + names_size(m->cnames, m->ncname);
}

/* written once into a buffer of its exact size (a part of a large mesh is tens of MB: a
 * growing buffer copied it several times) */
char *mesh_pack_into(const mesh *m, char *at) {
  int64_t hd[8] = {PACK_MAGIC, m->type, m->nvert, m->ncell, m->nbf, m->nbname, m->ncname, 0};
  size_t nx = (size_t)m->nvert * (size_t)m->dim, nc = (size_t)m->ncell * (size_t)m->nvc, nf = (size_t)m->nbf * (size_t)m->nvf;
  at = put(at, hd, sizeof hd);
  at = put(at, m->x, sizeof(double) * nx);
  at = put(at, m->cells, sizeof(int) * nc);
  at = put(at, m->cell_tag, sizeof(int) * (size_t)m->ncell);
  at = put(at, m->bf_verts, sizeof(int) * nf);
  at = put(at, m->bf_tag, sizeof(int) * (size_t)m->nbf);
  at = put_names(at, m->bnames, m->nbname);
  return put_names(at, m->cnames, m->ncname);
}

int mesh_pack(const mesh *m, char **buf, size_t *len) {
  size_t n = mesh_pack_size(m);
  char *b = malloc(n);
  if (!b) return 1;
  mesh_pack_into(m, b);
  *buf = b;
  *len = n;
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
