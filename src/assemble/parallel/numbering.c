/* numbering.c — the global numbering of the nodes of a distributed mesh (a problem's, or a
 * dof map's): each rank numbers the nodes it owns (a node goes to the part of most of its
 * cells, as in a run on a whole mesh) and learns the numbers of its ghost nodes from their
 * owners through a rendezvous on the nodes' keys (the global numbers of the vertices of the
 * entity holding the node), with no rank holding anything of the whole size. */
#include "parallel_int.h"

#include <mpi.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/* the key of dof d of dof map dm on the part P: field 0, its component, the entity that
 * holds its node and the node's place there, the entity's global vertex numbers sorted (a
 * cell's: its global number) */
void lg_dof_key(const mesh_part *P, const dofmap *dm, int d, int *key) {
  const mesh *m = P->m;
  int kind, id, j;
  dofmap_dof_entity(dm, d / dm->bs, &kind, &id, &j);
  for (int i = 0; i < LG_KEYLEN; i++) key[i] = -1;
  key[0] = 0;
  key[1] = d % dm->bs;
  key[2] = kind;
  key[3] = j;
  int nv = 0, v[4];
  if (kind == 0) v[nv++] = P->vglobal[id];
  else if (kind == 1) for (int i = 0; i < 2; i++) v[nv++] = P->vglobal[m->edges[2 * (size_t)id + (size_t)i]];
  else if (kind == 2) for (int i = 0; i < m->nvf; i++) v[nv++] = P->vglobal[m->faces[(size_t)id * (size_t)m->nvf + (size_t)i]];
  else v[nv++] = P->cglobal[id];
  for (int i = 1; i < nv; i++) /* sorted: an entity is its vertex set */
    for (int k = i; k > 0 && v[k] < v[k - 1]; k--) { int t = v[k]; v[k] = v[k - 1]; v[k - 1] = t; }
  for (int i = 0; i < nv; i++) key[4 + i] = v[i];
}

static int key_rank(const int *key, int size) {
  uint64_t h = 1469598103934665603ull;
  for (int i = 0; i < LG_KEYLEN; i++) { h ^= (uint32_t)key[i]; h *= 1099511628211ull; h ^= h >> 29; }
  return (int)(h % (uint64_t)size);
}

static int cmp_key(const void *a, const void *b) {
  const int *x = a, *y = b;
  for (int i = 0; i < LG_KEYLEN; i++)
    if (x[i] != y[i]) return x[i] < y[i] ? -1 : 1;
  return 0;
}

/* the vertices of this part's cells of other parts (a rank holding an owned node holds a
 * cell through it, which shares a vertex with an owned cell of it, or is one), and with more
 * ghost layers the vertices of every cell within the further layers of those (another rank's
 * outer ghosts reach that far into this part); NULL when out of memory */
char *lg_other_vertices(const mesh_part *P) {
  const mesh *m = P->m;
  size_t nvc = (size_t)m->nvc;
  int rank = lg_mpi_rank();
  char *iv = calloc((size_t)m->nvert + 1, 1);
  for (int c = 0; iv && c < m->ncell; c++)
    if (P->cowner[c] != rank)
      for (size_t k = 0; k < nvc; k++) iv[m->cells[(size_t)c * nvc + k]] = 1;
  if (iv && mesh_grow_vertex_layers(m, iv, P->layers - 1)) { free(iv); return NULL; }
  return iv;
}

/* the nodes (B dofs from off on: dof map dm in a problem's vector) of owned cells with a
 * vertex in other_vertices: the owned nodes another rank may hold */
void lg_mark_shared(const mesh_part *P, const char *ivert, const dofmap *dm, int off, int B, char *shared) {
  const mesh *m = P->m;
  int rank = lg_mpi_rank();
  for (int c = 0; c < m->ncell; c++) {
    if (P->cowner[c] != rank) continue;
    int touch = 0;
    for (int k = 0; k < m->nvc; k++) touch |= ivert[m->cells[(size_t)c * (size_t)m->nvc + (size_t)k]];
    if (!touch) continue;
    for (int k = 0; k < dm->nloc; k += B) shared[(off + dm->cell_dofs[(size_t)c * (size_t)dm->nloc + (size_t)k]) / B] = 1;
  }
}

/* the global numbers perm[Nn] of a part's nodes: the owned ones (owner[i] == rank) after the
 * lower ranks' in the local order, the others the numbers their owners gave them, learnt
 * through a rendezvous on the nodes' keys (registrations of the shared owned nodes and
 * questions go to the rank of the key's hash, which answers). *first: this rank's first
 * number, *nown its count, *total all ranks'. Collective, bad = this rank failed already
 * (it still takes part); returns 0, or on every rank 1 (out of memory) or 2 (a ghost node
 * without an owner) */
int lg_rendezvous_number(int bad, int Nn, const int *owner, const char *shared, lg_node_key_fn key, const void *ctx,
                             int *perm, int *first, int *nown_out, int *total_out) {
  int rank = lg_mpi_rank(), size = lg_mpi_size();
  int nown = 0, nask = 0;
  for (int i = 0; !bad && i < Nn; i++) {
    nown += owner[i] == rank;
    nask += owner[i] != rank;
  }
  int f0 = 0, total = 0; /* every rank reduces, failed or not */
  MPI_Exscan(&nown, &f0, 1, MPI_INT, MPI_SUM, PETSC_COMM_WORLD);
  if (rank == 0) f0 = 0;
  MPI_Allreduce(&nown, &total, 1, MPI_INT, MPI_SUM, PETSC_COMM_WORLD);
  /* registrations of the shared owned nodes (key, number) and questions (key) to the key's
   * hash's rank (rendezvous.c: a failed rank takes part with empty messages) */
  lg_box reg = {sizeof(int) * (LG_KEYLEN + 1), 0, 0, NULL, NULL}, ask = {sizeof(int) * LG_KEYLEN, 0, 0, NULL, NULL};
  int *askn = malloc(sizeof(int) * ((size_t)nask + 1)), *cnt = malloc(sizeof(int) * 4 * (size_t)size); /* the node of each question */
  int nomem = !askn || !cnt, anynomem = 1; /* every rank skips the exchanges where any cannot count */
  MPI_Allreduce(&nomem, &anynomem, 1, MPI_INT, MPI_MAX, PETSC_COMM_WORLD);
  bad |= !perm || anynomem;
  for (int i = 0, k = 0; !bad && i < Nn; i++) {
    int kb[LG_KEYLEN];
    if (owner[i] == rank) {
      perm[i] = f0 + k++;
      if (!shared[i]) continue;
      key(ctx, i, kb);
      int *r = lg_box_add(&reg, key_rank(kb, size), &bad);
      if (r) { memcpy(r, kb, sizeof kb); r[LG_KEYLEN] = perm[i]; }
    } else {
      perm[i] = -1;
      key(ctx, i, kb);
      int *q = lg_box_add(&ask, key_rank(kb, size), &bad);
      if (q) { memcpy(q, kb, sizeof kb); askn[ask.n - 1] = i; }
    }
  }
  int lost = 0;
  long ndir = 0, nq = 0, *ord = NULL;
  int *dir = NULL, *qs = NULL, *ans = NULL, *back = NULL;
  if (!anynomem) {
    int *rcnt1 = cnt + size, *cnt2 = rcnt1 + size, *rcnt2 = cnt2 + size;
    dir = (int *)lg_box_send(&reg, cnt, rcnt1, NULL, &ndir, &bad);
    qs = (int *)lg_box_send(&ask, cnt2, rcnt2, &ord, &nq, &bad);
    if (!(ans = malloc(sizeof(int) * ((size_t)nq + 1)))) bad = 1;
    if (!bad) qsort(dir, (size_t)ndir, sizeof(int) * (LG_KEYLEN + 1), cmp_key);
    for (long i = 0; !bad && i < nq; i++) {
      const int *f = bsearch(qs + (size_t)i * LG_KEYLEN, dir, (size_t)ndir, sizeof(int) * (LG_KEYLEN + 1), cmp_key);
      ans[i] = f ? f[LG_KEYLEN] : -1;
    }
    /* the answers back in the order asked */
    back = (int *)lg_reply((char *)ans, sizeof(int), rcnt2, cnt2, &bad);
  }
  for (long k = 0; !bad && k < ask.n; k++) {
    perm[askn[ord[k]]] = back[k];
    lost += back[k] < 0;
  }
  free(dir); free(qs); free(ans); free(back); free(ord); free(askn); free(cnt);
  lg_box_free(&reg);
  lg_box_free(&ask);
  int fail[2] = {bad, lost}, any[2];
  MPI_Allreduce(fail, any, 2, MPI_INT, MPI_MAX, PETSC_COMM_WORLD);
  *first = f0;
  *nown_out = nown;
  *total_out = total;
  return any[0] ? 1 : any[1] ? 2 : 0;
}

