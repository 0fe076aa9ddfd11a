/* part.c — one part of a mesh whose cells are split into parts, as a process of a
 * distributed run holds it: the part's own cells plus layers of ghost cells (the first:
 * every cell that shares a vertex with an owned one; the next: every cell sharing a vertex
 * with one of those), with the global numbers and owners of its
 * vertices and cells; and such a part as one byte buffer and back (what the reading rank
 * sends to each of the others).
 *
 * Why a vertex layer: every cell around a vertex of an owned cell is then on the rank, so
 * the rows of the nodes it owns (a node goes to a part of one of its cells) are assembled
 * from local cells only, with no communication, and each entry sums its contributions in
 * the whole mesh's cell order (local cells keep that order), as a serial run does.
 * Local vertices keep the global order too, so that an edge runs from its lower to its
 * higher vertex in both numberings (the dof maps orient edge nodes that way). */
#include "mesh.h"

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define PART_MAGIC 0x6c677074u /* "lgpt" */

int mesh_grow_vertex_layers(const mesh *m, char *mark, int n) {
  size_t nvc = (size_t)m->nvc;
  char *next = n > 0 ? malloc((size_t)m->nvert + 1) : NULL;
  if (n > 0 && !next) return 1;
  for (int layer = 0; layer < n; layer++) {
    memcpy(next, mark, (size_t)m->nvert);
    for (int c = 0; c < m->ncell; c++) {
      const int *cv = m->cells + (size_t)c * nvc;
      int touch = 0;
      for (size_t k = 0; k < nvc && !touch; k++) touch = mark[cv[k]];
      if (touch)
        for (size_t k = 0; k < nvc; k++) next[cv[k]] = 1;
    }
    memcpy(mark, next, (size_t)m->nvert);
  }
  free(next);
  return 0;
}

int mesh_vertex_owners(const mesh *m, const int *part, int *owner) {
  /* Boyer-Moore's vote in cell order: the part of most of a vertex's cells where there is
   * a majority, which keeps the parts' vertex counts near their cell counts */
  int *cnt = calloc((size_t)m->nvert + 1, sizeof(int));
  if (!cnt) return 1;
  for (int v = 0; v < m->nvert; v++) owner[v] = -1;
  for (int c = 0; c < m->ncell; c++)
    for (int k = 0; k < m->nvc; k++) {
      int v = m->cells[(size_t)c * (size_t)m->nvc + (size_t)k];
      if (!cnt[v]) { owner[v] = part[c]; cnt[v] = 1; }
      else cnt[v] += owner[v] == part[c] ? 1 : -1;
    }
  free(cnt);
  return 0;
}

/* a mesh of no cells (a part of a mesh with fewer cells than parts): mesh_create refuses
 * one, every loop over cells and vertices takes it */
static mesh *empty_mesh(cell_type t, char *err) {
  double x[3] = {0, 0, 0};
  int cells[8] = {0, 0, 0, 0, 0, 0, 0, 0};
  mesh *m = mesh_create(t, 1, x, 1, cells, err);
  if (m) m->nvert = m->ncell = 0;
  return m;
}

static int copy_names(mesh *to, const mesh *from, char *err) {
  for (int i = 0; i < from->nbname; i++)
    if (mesh_set_boundary_name(to, from->bnames[i].tag, from->bnames[i].name)) goto bad;
  for (int i = 0; i < from->ncname; i++)
    if (mesh_set_region_name(to, from->cnames[i].tag, from->cnames[i].name)) goto bad;
  return 0;
bad:
  snprintf(err, MESH_ERRLEN, "%s", to->err);
  return 1;
}

void mesh_vertex_runs(const mesh *m, const int *vglob, int nvert_global, int nparts, int *part) {
  for (int c = 0; c < m->ncell; c++) {
    const int *v = m->cells + (size_t)c * (size_t)m->nvc;
    int lo = vglob ? vglob[v[0]] : v[0];
    for (int k = 1; k < m->nvc; k++) {
      int g = vglob ? vglob[v[k]] : v[k];
      lo = g < lo ? g : lo;
    }
    part[c] = (int)((long)lo * nparts / nvert_global);
  }
}

long mesh_runs_interface(const mesh *m, const int *vglob, int nvert_global, int nparts, int vlo, int vhi) {
  char *mark = calloc((size_t)m->nvert + 1, 1);
  if (!mark) return -1;
  long n = 0;
  for (int c = 0; c < m->ncell; c++) {
    const int *v = m->cells + (size_t)c * (size_t)m->nvc;
    long p0 = (long)(vglob ? vglob[v[0]] : v[0]) * nparts / nvert_global;
    int cut = 0;
    for (int k = 1; k < m->nvc && !cut; k++) cut = (long)(vglob ? vglob[v[k]] : v[k]) * nparts / nvert_global != p0;
    for (int k = 0; cut && k < m->nvc; k++) {
      int g = vglob ? vglob[v[k]] : v[k];
      if (!mark[v[k]] && g >= vlo && g < vhi) { mark[v[k]] = 1; n++; }
    }
  }
  free(mark);
  return n;
}

mesh_part *mesh_part_extract(mesh *m, const int *part, const int *vowner, int p, int layers, char *err) {
  return mesh_part_extract_window(m, NULL, NULL, m->nvert, m->ncell, part, vowner, p, layers, err);
}

mesh_part *mesh_part_extract_window(mesh *m, const int *vglob, const int *cglob, int nvert_global, int ncell_global,
                                    const int *part, const int *vowner, int p, int layers, char *err) {
  if (mesh_build_boundary_cells(m)) { snprintf(err, MESH_ERRLEN, "%s", m->err); return NULL; }
  size_t nv = (size_t)m->nvert, nc = (size_t)m->ncell, nvc = (size_t)m->nvc;
  /* near: the vertices whose cells are local; vmap: the local number + 1 of local vertices;
   * cmap: the local number + 1 of local cells */
  int *vmap = calloc(nv + 1, sizeof(int)), *cmap = calloc(nc + 1, sizeof(int));
  char *near = calloc(nv + 1, 1);
  mesh_part *P = calloc(1, sizeof *P);
  if (!vmap || !cmap || !near || !P) goto oom;
  if (layers < 1) layers = 1;
  /* the vertices of owned cells and layers - 1 vertex layers around them; the local cells
   * are the owned ones and those with a vertex there */
  for (size_t c = 0; c < nc; c++)
    if (part[c] == p)
      for (size_t k = 0; k < nvc; k++) near[m->cells[c * nvc + k]] = 1;
  if (mesh_grow_vertex_layers(m, near, layers - 1)) goto oom;
  int ncl = 0, nown = 0;
  for (size_t c = 0; c < nc; c++) {
    int in = part[c] == p;
    for (size_t k = 0; k < nvc && !in; k++) in = near[m->cells[c * nvc + k]];
    if (in) { cmap[c] = ++ncl; nown += part[c] == p; }
  }
  free(near);
  near = NULL;
  for (size_t v = 0; v < nv; v++) vmap[v] = 0;
  for (size_t c = 0; c < nc; c++)
    if (cmap[c])
      for (size_t k = 0; k < nvc; k++) vmap[m->cells[c * nvc + k]] = 1;
  int nvl = 0;
  for (size_t v = 0; v < nv; v++)
    if (vmap[v]) vmap[v] = ++nvl;
  P->nvert_global = nvert_global;
  P->ncell_global = ncell_global;
  P->part = p;
  P->layers = layers;
  P->m = ncl ? mesh_create(m->type, nvl, NULL, ncl, NULL, err) : empty_mesh(m->type, err);
  if (!P->m) goto fail;
  P->vglobal = malloc(sizeof(int) * ((size_t)nvl + 1));
  P->vowner = malloc(sizeof(int) * ((size_t)nvl + 1));
  P->cglobal = malloc(sizeof(int) * ((size_t)ncl + 1));
  P->cowner = malloc(sizeof(int) * ((size_t)ncl + 1));
  if (!P->vglobal || !P->vowner || !P->cglobal || !P->cowner) goto oom;
  mesh *l = P->m;
  size_t dim = (size_t)m->dim;
  for (size_t v = 0; v < nv; v++)
    if (vmap[v]) {
      size_t i = (size_t)vmap[v] - 1;
      P->vglobal[i] = vglob ? vglob[v] : (int)v;
      P->vowner[i] = vowner[v];
      memcpy(l->x + i * dim, m->x + v * dim, sizeof(double) * dim);
      P->nown_vert += vowner[v] == p;
    }
  for (size_t c = 0; c < nc; c++)
    if (cmap[c]) {
      size_t i = (size_t)cmap[c] - 1;
      P->cglobal[i] = cglob ? cglob[c] : (int)c;
      P->cowner[i] = part[c];
      l->cell_tag[i] = m->cell_tag[c];
      for (size_t k = 0; k < nvc; k++) l->cells[i * nvc + k] = vmap[m->cells[c * nvc + k]] - 1;
    }
  P->nown_cell = nown;
  /* the tagged boundary facets of local cells (a facet whose vertices are local but whose
   * cell is not would have no cell here) */
  int nb = 0;
  for (int b = 0; b < m->nbf; b++) nb += m->bf_cell[b] >= 0 && cmap[m->bf_cell[b]];
  if (nb) {
    size_t nvf = (size_t)m->nvf;
    l->bf_verts = malloc(sizeof(int) * (size_t)nb * nvf);
    l->bf_tag = malloc(sizeof(int) * (size_t)nb);
    if (!l->bf_verts || !l->bf_tag) goto oom;
    for (int b = 0; b < m->nbf; b++)
      if (m->bf_cell[b] >= 0 && cmap[m->bf_cell[b]]) {
        for (size_t k = 0; k < nvf; k++) l->bf_verts[(size_t)l->nbf * nvf + k] = vmap[m->bf_verts[(size_t)b * nvf + k]] - 1;
        l->bf_tag[l->nbf++] = m->bf_tag[b];
      }
  }
  if (copy_names(l, m, err)) goto fail;
  free(vmap);
  free(cmap);
  return P;
oom:
  snprintf(err, MESH_ERRLEN, "out of memory for part %d of a mesh of %d cells", p + 1, ncell_global);
fail:
  free(vmap);
  free(cmap);
  free(near);
  mesh_part_free(P);
  return NULL;
}

void mesh_part_free(mesh_part *P) {
  if (!P) return;
  mesh_free(P->m);
  free(P->vglobal);
  free(P->vowner);
  free(P->cglobal);
  free(P->cowner);
  free(P);
}

/* the buffer: a header, the packed local mesh (mesh_pack), then vglobal, vowner, cglobal,
 * cowner */
int mesh_part_pack(const mesh_part *P, char **buf, size_t *len) {
  mesh one = *P->m; /* an empty part's mesh keeps the single vertex and cell it was made with */
  if (!one.ncell) one.nvert = one.ncell = 1;
  size_t ml = mesh_pack_size(&one), nv = (size_t)P->m->nvert, nc = (size_t)P->m->ncell;
  int64_t hd[11] = {PART_MAGIC, P->m->type, P->nvert_global, P->ncell_global, P->part, P->nown_vert, P->nown_cell, (int64_t)nv, (int64_t)nc, (int64_t)ml, P->layers};
  size_t n = sizeof hd + ml + sizeof(int) * (2 * nv + 2 * nc);
  char *b = malloc(n), *at = b;
  if (!b) return 1;
  memcpy(at, hd, sizeof hd); at += sizeof hd;
  at = mesh_pack_into(&one, at);
  memcpy(at, P->vglobal, sizeof(int) * nv); at += sizeof(int) * nv;
  memcpy(at, P->vowner, sizeof(int) * nv); at += sizeof(int) * nv;
  memcpy(at, P->cglobal, sizeof(int) * nc); at += sizeof(int) * nc;
  memcpy(at, P->cowner, sizeof(int) * nc);
  *buf = b;
  *len = n;
  return 0;
}

static int check_ids(const int *a, size_t n, int lo, int hi, int increasing) {
  for (size_t i = 0; i < n; i++)
    if (a[i] < lo || a[i] >= hi || (increasing && i && a[i] <= a[i - 1])) return 1;
  return 0;
}

mesh_part *mesh_part_unpack(const char *buf, size_t len, char *err) {
  int64_t hd[11];
  if (len < sizeof hd) { snprintf(err, MESH_ERRLEN, "a packed mesh part of %zu bytes has no header", len); return NULL; }
  memcpy(hd, buf, sizeof hd);
  if (hd[0] != PART_MAGIC || hd[1] < 0 || hd[1] > CELL_INTERVAL || hd[2] < 1 || hd[2] > 0x7fffffff || hd[3] < 1 ||
      hd[3] > 0x7fffffff || hd[4] < 0 || hd[7] < 0 || hd[7] > hd[2] || hd[8] < 0 || hd[8] > hd[3] || hd[9] < 0 ||
      (size_t)hd[9] > len || hd[5] < 0 || hd[5] > hd[7] || hd[6] < 0 || hd[6] > hd[8] || hd[10] < 1 || hd[10] > 1000) {
    snprintf(err, MESH_ERRLEN, "not a packed mesh part (a bad header)");
    return NULL;
  }
  size_t nv = (size_t)hd[7], nc = (size_t)hd[8], ml = (size_t)hd[9];
  if (len != sizeof hd + ml + sizeof(int) * (2 * nv + 2 * nc)) {
    snprintf(err, MESH_ERRLEN, "a packed mesh part of %zu bytes has a wrong length", len);
    return NULL;
  }
  mesh_part *P = calloc(1, sizeof *P);
  if (!P) { snprintf(err, MESH_ERRLEN, "out of memory"); return NULL; }
  P->nvert_global = (int)hd[2];
  P->ncell_global = (int)hd[3];
  P->part = (int)hd[4];
  P->nown_vert = (int)hd[5];
  P->nown_cell = (int)hd[6];
  P->layers = (int)hd[10];
  const char *at = buf + sizeof hd;
  P->m = mesh_unpack(at, ml, err);
  at += ml;
  if (!P->m) goto fail;
  if (!nc && P->m->ncell == 1 && P->m->nvert == 1) P->m->ncell = P->m->nvert = 0; /* an empty part */
  if ((size_t)P->m->nvert != nv || (size_t)P->m->ncell != nc) {
    snprintf(err, MESH_ERRLEN, "a packed mesh part's sizes disagree with its mesh");
    goto fail;
  }
  P->vglobal = malloc(sizeof(int) * (nv + 1));
  P->vowner = malloc(sizeof(int) * (nv + 1));
  P->cglobal = malloc(sizeof(int) * (nc + 1));
  P->cowner = malloc(sizeof(int) * (nc + 1));
  if (!P->vglobal || !P->vowner || !P->cglobal || !P->cowner) { snprintf(err, MESH_ERRLEN, "out of memory"); goto fail; }
  memcpy(P->vglobal, at, sizeof(int) * nv); at += sizeof(int) * nv;
  memcpy(P->vowner, at, sizeof(int) * nv); at += sizeof(int) * nv;
  memcpy(P->cglobal, at, sizeof(int) * nc); at += sizeof(int) * nc;
  memcpy(P->cowner, at, sizeof(int) * nc);
  if (check_ids(P->vglobal, nv, 0, P->nvert_global, 1) || check_ids(P->cglobal, nc, 0, P->ncell_global, 1) ||
      check_ids(P->vowner, nv, 0, 1 << 30, 0) || check_ids(P->cowner, nc, 0, 1 << 30, 0)) {
    snprintf(err, MESH_ERRLEN, "a packed mesh part has a global number or owner out of range");
    goto fail;
  }
  return P;
fail:
  mesh_part_free(P);
  return NULL;
}
