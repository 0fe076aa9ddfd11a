/* read_dist.c — a Gmsh file read in parallel (lg.mesh.read under mpiexec, distributed): no
 * rank holds the whole mesh or reads the whole file. Rank 0 scans the file's lines once
 * (mesh_gmsh_layout, constant memory); each rank parses an even run of its nodes and of its
 * elements (mesh_gmsh_read_part); then rendezvous on hashed keys, each an MPI all-to-all,
 * give what the whole reader gives (gmsh.c's build_mesh): node tags to vertex numbers (the
 * nodes of cells, in the file's order), cells repeated in the file merged (MSH 2 repeats an
 * element per physical group), the cells' numbers, the partition (the numbering's runs or
 * PTScotch on the distributed vertex graph, -lugal_partitioner as for a whole mesh), the
 * vertices' owners, each rank's window (its cells, its ghost layers), the tagged facets of
 * the window's cells, the names. The window becomes the rank's part through
 * mesh_part_extract_window, the part rank 0 would cut from the whole mesh with the same
 * partition, to the byte.
 *
 * Every record goes through the vertex's, key's or tag's home rank: vertex v's home is the
 * rank of v's run of the numbering (rank r holds ceil(r V / P) .. ceil((r + 1) V / P) - 1,
 * the rows of the distributed vertex graph); a key's or tag's, its hash modulo P.
 *
 * A file this path cannot take (its layout, a part that does not parse, a mesh the whole
 * reader would refuse: a node missing or defined twice, mixed cells, a cell in two physical
 * groups, a tagged facet of no cell...) is read whole by rank 0 instead, which sends each
 * rank its part (lg_part_distribute) or gives the whole reader's message. */
#include "parallel_int.h"

#include <petscmat.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---------------------------------------------------------------- keys, homes, sorting */

static uint64_t mix(uint64_t h) {
  h ^= h >> 33;
  h *= 0xff51afd7ed558ccdull;
  h ^= h >> 33;
  h *= 0xc4ceb9fe1a85ec53ull;
  return h ^ (h >> 33);
}
static uint64_t key_hash(const int *k, int n) {
  uint64_t h = 1469598103934665603ull;
  for (int i = 0; i < n; i++) h = mix(h ^ (uint32_t)k[i]);
  return h;
}
static int hash_rank(const int *k, int n, int P) { return (int)(key_hash(k, n) % (uint64_t)P); }
static int tag_rank(long long tag, int P) { return (int)(mix((uint64_t)tag) % (uint64_t)P); }

/* vertex v's home: the rank of its run of the numbering (mesh_vertex_runs' parts) */
static int vhome(int v, int nvg, int P) { return (int)((long)v * P / nvg); }
static int vlo(int r, int nvg, int P) { return (int)(((long)r * nvg + P - 1) / P); }

static void sort_small(int *k, int n) {
  for (int i = 1; i < n; i++)
    for (int j = i; j > 0 && k[j] < k[j - 1]; j--) { int t = k[j]; k[j] = k[j - 1]; k[j - 1] = t; }
}
/* stable LSD radix sorts, 16 bits a pass, as many passes as the largest key needs (qsort's
 * merge sort of these records was most of a 1.5 M-cell read) */
#define RADIX_SORT(name, T, KEY)                                                         \
  static int name(T *a, long n) {                                                        \
    uint64_t mx = 0;                                                                     \
    for (long i = 0; i < n; i++) mx |= (uint64_t)KEY(a[i]);                              \
    if (!mx || n < 2) return 0;                                                          \
    T *t = malloc(sizeof(T) * (size_t)n), *from = a, *to = t;                            \
    long *c = malloc(sizeof(long) * 65536);                                              \
    if (!t || !c) { free(t); free(c); return 1; }                                        \
    for (int sh = 0; sh < 64 && (mx >> sh); sh += 16) {                                  \
      memset(c, 0, sizeof(long) * 65536);                                                \
      for (long i = 0; i < n; i++) c[((uint64_t)KEY(from[i]) >> sh) & 0xffff]++;          \
      for (long d = 0, at = 0; d < 65536; d++) { long x = c[d]; c[d] = at; at += x; }    \
      for (long i = 0; i < n; i++) to[c[((uint64_t)KEY(from[i]) >> sh) & 0xffff]++] = from[i]; \
      T *sw = from; from = to; to = sw;                                                  \
    }                                                                                    \
    if (from != a) memcpy(a, from, sizeof(T) * (size_t)n);                               \
    free(t);                                                                             \
    free(c);                                                                             \
    return 0;                                                                            \
  }
typedef struct { uint64_t k; long i; } kv;
#define KV_KEY(x) (x).k
#define SELF_KEY(x) (x)
RADIX_SORT(sort_kv, kv, KV_KEY)
RADIX_SORT(sort_u64, uint64_t, SELF_KEY)
RADIX_SORT(sort_u32, unsigned, SELF_KEY)

static int cmp_int(const void *a, const void *b) { int x = *(const int *)a, y = *(const int *)b; return (x > y) - (x < y); }

/* non-negative ints, sorted and made unique in place; -1 when out of memory */
static long unique_ints(int *a, long n) {
  if (sort_u32((unsigned *)a, n)) return -1;
  long k = 0;
  for (long i = 0; i < n; i++)
    if (!k || a[i] != a[k - 1]) a[k++] = a[i];
  return k;
}

/* ---------------------------------------------------------------- the records */

typedef struct { long long tag, F; double x[3]; } rnode;  /* a node to its tag's home */
typedef struct { long long tag; int used, pad; } rask;     /* a node tag asked for */
typedef struct { int key[8]; long long index; int tag, pad; } rdup; /* a cell's key, where hashes meet */
typedef struct { uint64_t h; int index, tag; } rhash;      /* a cell to its key hash's home */
typedef struct { int v; int pad; double x[3]; } rcoord;
typedef struct { int owner, pad; double x[3]; } rvert;
typedef struct { int key[4], v[4], tag, j; long long index; } rfacet;
typedef struct { int key[4], g; } rface;

static int cmp_rnode(const void *a, const void *b) {
  const rnode *x = a, *y = b;
  if (x->tag != y->tag) return x->tag < y->tag ? -1 : 1;
  return (x->F > y->F) - (x->F < y->F);
}
static int key_cmp(const int *x, const int *y, int n) {
  for (int i = 0; i < n; i++)
    if (x[i] != y[i]) return x[i] < y[i] ? -1 : 1;
  return 0;
}
/* by key (its unused places are 0), then by place in the file */
static int cmp_rdup(const void *a, const void *b) {
  const rdup *x = a, *y = b;
  int c = key_cmp(x->key, y->key, 8);
  return c ? c : (x->index > y->index) - (x->index < y->index);
}
static int cmp_rfacet(const void *a, const void *b) {
  const rfacet *x = a, *y = b;
  int c = key_cmp(x->key, y->key, 4);
  if (c) return c;
  if (x->tag != y->tag) return x->tag < y->tag ? -1 : 1;
  if (x->index != y->index) return x->index < y->index ? -1 : 1;
  return (x->j > y->j) - (x->j < y->j);
}
static int cmp_rfacet_order(const void *a, const void *b) {
  const rfacet *x = a, *y = b;
  if (x->index != y->index) return x->index < y->index ? -1 : 1;
  return (x->j > y->j) - (x->j < y->j);
}
typedef struct { int key[4], g, src; } rface_at;
static int cmp_rface_at(const void *a, const void *b) {
  const rface_at *x = a, *y = b;
  int c = key_cmp(x->key, y->key, 4);
  if (c) return c;
  return (x->g > y->g) - (x->g < y->g);
}

/* ---------------------------------------------------------------- the reader */

typedef struct {
  lg_env *env;
  const char *path;
  int rank, P, bad;
  int *cnt;      /* 6 P counts for the exchanges */
  char why[256];
  gmsh_layout L;
  gmsh_part G;
  int cdim, ctype, nvc, nvf;
  cell_type ct;
  /* after the node numbering */
  int nvg, vbase, nused;
  double *ux;    /* this rank's used nodes' coordinates, numbers vbase .. vbase + nused - 1 */
  int *cv;       /* the local cells' vertices (ncl cells, nvc each) */
  int *ctag, *keep, *cidx, ncl; /* their region tags, kept flags (repeats: 0), elements */
  int *fv, *fidx, nfl; /* the local tagged facets: vertices (-1: a node of no cell), element */
  int *fph, *fnp;      /* and their physical tags (at G.phys + fph, fnp of them) */
  int *cglob;          /* the local cells' numbers where they are not cbase + c (a generated mesh) */
  mesh *names;         /* where the names come from where not the file (a generated mesh) */
  long long efirst;    /* the file's index of this rank's first element */
  /* after the cells' numbering */
  int ncg, cbase;
  int *cpart;
} reader;

static void why(reader *R, const char *reason) {
  if (!R->bad) snprintf(R->why, sizeof R->why, "%s", reason);
  R->bad = 1;
}
static int any(reader *R) {
  int b = R->bad, a = 0;
  if (MPI_Allreduce(&b, &a, 1, MPI_INT, MPI_MAX, PETSC_COMM_WORLD) != MPI_SUCCESS) a = 1;
  if (a && !R->bad) { snprintf(R->why, sizeof R->why, "another rank could not"); R->bad = 1; }
  return a;
}

/* the file's node of index F: its reader's rank */
static int node_reader(const gmsh_layout *L, long long F) {
  int lo = 0, hi = L->nparts - 1;
  while (lo < hi) { /* the last p with run start <= F */
    int c = (lo + hi + 1) / 2;
    if (L->nnodes * c / L->nparts <= F) lo = c;
    else hi = c - 1;
  }
  return lo;
}

/* the answer to tag t among the sorted distinct tags ut (tag << 1 | used) */
static long answer_of(const uint64_t *ut, long n, const long *ans, long long t) {
  long lo = 0, hi = n;
  while (lo < hi) {
    long c = (lo + hi) / 2;
    if ((long long)(ut[c] >> 1) < t) lo = c + 1;
    else hi = c;
  }
  return lo < n && (long long)(ut[lo] >> 1) == t ? ans[lo] : -1;
}

/* step 1: node tags to vertex numbers (the nodes of cells, in the file's order) */
/* the questions of number_nodes: each distinct node tag of the local cells (used) and
 * tagged facets once, found through a hash set of tag << 1 | used (0: empty), then sorted:
 * a 5.3 M-cell file's 21 M node references are 0.9 M tags, and sorting the references had
 * held them twice. The tags into *out (malloc'ed, *nout of them) */
static void distinct_tags(reader *R, uint64_t **out, long *nout) {
  gmsh_part *G = &R->G;
  size_t cap = 1024;
  long nut = 0;
  uint64_t *ut = calloc(cap, sizeof(uint64_t));
  if (!ut) R->bad = 1;
  for (long long i = 0; !R->bad && i < G->ne; i++) {
    const gmsh_elem *e = &G->e[i];
    int d = mesh_gmsh_type_dim(e->type), cell = d == R->cdim;
    if (!cell && !(d == R->cdim - 1 && e->nphys > 0)) continue;
    for (int j = 0; !R->bad && j < mesh_gmsh_type_nodes(e->type); j++) {
      long long t = G->enodes[e->node + j];
      if (t >= (1LL << 62)) { why(R, "a node tag over 2^62"); break; }
      if (2 * (size_t)(nut + 1) > cap) { /* rehash into twice the room */
        uint64_t *nt = calloc(2 * cap, sizeof(uint64_t));
        if (!nt) { R->bad = 1; break; }
        for (size_t q = 0; q < cap; q++)
          if (ut[q]) {
            size_t h = mix(ut[q] >> 1) & (2 * cap - 1);
            while (nt[h]) h = (h + 1) & (2 * cap - 1);
            nt[h] = ut[q];
          }
        free(ut);
        ut = nt;
        cap *= 2;
      }
      size_t h = mix((uint64_t)t) & (cap - 1);
      while (ut[h] && (long long)(ut[h] >> 1) != t) h = (h + 1) & (cap - 1);
      if (!ut[h]) { ut[h] = (uint64_t)t << 1; nut++; }
      ut[h] |= (uint64_t)cell;
    }
  }
  if (!R->bad) { /* the distinct tags, sorted */
    size_t k = 0;
    for (size_t q = 0; q < cap; q++)
      if (ut[q]) ut[k++] = ut[q];
    if (sort_u64(ut, nut)) R->bad = 1;
  }
  *out = ut;
  *nout = nut;
}

/* the local cells and tagged facets in vertex numbers: at[u] the number of the u-th of
 * the nut sorted distinct tags ut (distinct_tags); dense tags (Gmsh numbers nodes 1..n)
 * through a table from the smallest, others by a binary search */
static void local_elements(reader *R, const uint64_t *ut, long nut, const long *at) {
  gmsh_part *G = &R->G;
  long long tlo = nut ? (long long)(ut[0] >> 1) : 0, span = nut ? (long long)(ut[nut - 1] >> 1) - tlo + 1 : 0;
  int *direct = !R->bad && span <= 4LL * nut + 1024 ? malloc(sizeof(int) * ((size_t)span + 1)) : NULL;
  if (direct) {
    for (long long t = 0; t < span; t++) direct[t] = -1;
    for (long u = 0; u < nut; u++) direct[(long long)(ut[u] >> 1) - tlo] = (int)at[u];
  }
#define TAG_ANSWER(t) (direct ? direct[(t) - tlo] : answer_of(ut, nut, at, (t)))
  long ncells = 0, nfacets = 0;
  for (long long i = 0; i < G->ne; i++) {
    int d = mesh_gmsh_type_dim(G->e[i].type);
    ncells += d == R->cdim;
    nfacets += d == R->cdim - 1 && G->e[i].nphys > 0;
  }
  int nvc = R->nvc;
  R->cv = malloc(sizeof(int) * (size_t)nvc * ((size_t)ncells + 1));
  R->ctag = malloc(sizeof(int) * ((size_t)ncells + 1));
  R->cidx = malloc(sizeof(int) * ((size_t)ncells + 1));
  R->fv = malloc(sizeof(int) * 4 * ((size_t)nfacets + 1));
  R->fidx = malloc(sizeof(int) * ((size_t)nfacets + 1));
  R->fph = malloc(sizeof(int) * ((size_t)nfacets + 1));
  R->fnp = malloc(sizeof(int) * ((size_t)nfacets + 1));
  if (!R->cv || !R->ctag || !R->cidx || !R->fv || !R->fidx || !R->fph || !R->fnp) R->bad = 1;
  int ftype = R->cdim == 1 ? 15 : R->cdim == 2 ? 1 : R->ct == CELL_TETRAHEDRON ? 2 : 3;
  for (long long i = 0; !R->bad && i < G->ne; i++) {
    const gmsh_elem *e = &G->e[i];
    int d = mesh_gmsh_type_dim(e->type), nn1 = mesh_gmsh_type_nodes(e->type);
    if (d == R->cdim) {
      int *v = R->cv + (size_t)nvc * (size_t)R->ncl;
      for (int j = 0; j < nn1; j++) {
        v[j] = (int)TAG_ANSWER(G->enodes[e->node + j]);
        for (int k = 0; k < j; k++)
          if (v[k] == v[j]) why(R, "a collapsed cell");
      }
      for (int j = 1; j < e->nphys; j++)
        if (G->phys[e->phys + j] != G->phys[e->phys]) why(R, "a cell in two physical groups");
      R->ctag[R->ncl] = e->nphys ? G->phys[e->phys] : 0;
      R->cidx[R->ncl++] = (int)i;
    } else if (d == R->cdim - 1 && e->nphys > 0) {
      int *v = R->fv + 4 * (size_t)R->nfl;
      if (e->type != ftype) why(R, "a tagged facet of another type than the cells'");
      for (int j = 0; j < nn1; j++) v[j] = (int)TAG_ANSWER(G->enodes[e->node + j]);
      R->fph[R->nfl] = e->phys;
      R->fnp[R->nfl] = e->nphys;
      R->fidx[R->nfl++] = (int)i;
    }
  }
#undef TAG_ANSWER
  free(direct);
}

static void number_nodes(reader *R) {
  int P = R->P, *cnt = R->cnt, *rcnt = cnt + P, *qcnt = cnt + 2 * P, *qrcnt = cnt + 3 * P;
  gmsh_part *G = &R->G;
  lg_box bn = {sizeof(rnode), 0, 0, NULL, NULL}, bq = {sizeof(rask), 0, 0, NULL, NULL};
  for (long long i = 0; !R->bad && i < G->nn; i++) {
    rnode *r = lg_box_add(&bn, tag_rank(G->ntag[i], P), &R->bad);
    if (r) { r->tag = G->ntag[i]; r->F = G->node_first + i; memcpy(r->x, G->nx + 3 * i, sizeof r->x); }
  }
  long nn = 0, nq = 0, *qord = NULL;
  rnode *nodes = (rnode *)lg_box_send(&bn, cnt, rcnt, NULL, &nn, &R->bad);
  lg_box_free(&bn);
  long nut = 0;
  uint64_t *ut = NULL;
  distinct_tags(R, &ut, &nut);
  for (long i = 0; !R->bad && i < nut; i++) {
    rask *q = lg_box_add(&bq, tag_rank((long long)(ut[i] >> 1), P), &R->bad);
    if (q) { q->tag = (long long)(ut[i] >> 1); q->used = (int)(ut[i] & 1); }
  }
  rask *asks = (rask *)lg_box_send(&bq, qcnt, qrcnt, &qord, &nq, &R->bad);
  /* the tags' homes: unique tags (the first of equal nodes; the same tag at other
   * coordinates is the whole reader's error), each question's node, the used ones marked */
  long nu = 0;
  if (!R->bad) {
    qsort(nodes, (size_t)nn, sizeof(rnode), cmp_rnode);
    for (long i = 0; i < nn; i++) {
      if (nu && nodes[i].tag == nodes[nu - 1].tag) {
        if (memcmp(nodes[i].x, nodes[nu - 1].x, sizeof nodes[i].x)) why(R, "a node defined twice");
        continue;
      }
      nodes[nu++] = nodes[i];
    }
  }
  long *which = malloc(sizeof(long) * ((size_t)nq + 1));
  char *used = calloc((size_t)nu + 1, 1);
  if (!which || !used) R->bad = 1;
  for (long i = 0; !R->bad && i < nq; i++) {
    long lo = 0, hi = nu;
    while (lo < hi) {
      long c = (lo + hi) / 2;
      if (nodes[c].tag < asks[i].tag) lo = c + 1;
      else hi = c;
    }
    which[i] = lo < nu && nodes[lo].tag == asks[i].tag ? lo : -1;
    if (which[i] < 0) why(R, "an element refers to a node not in $Nodes");
    else if (asks[i].used) used[which[i]] = 1;
  }
  /* the used nodes' indices to their readers, who number them in the file's order */
  lg_box bu = {sizeof(long long), 0, 0, NULL, NULL};
  for (long u = 0; !R->bad && u < nu; u++)
    if (used[u]) {
      long long *f = lg_box_add(&bu, node_reader(&R->L, nodes[u].F), &R->bad);
      if (f) *f = nodes[u].F;
    }
  int *ucnt = cnt + 4 * P, *urcnt = cnt + 5 * P;
  long nf = 0, *uord = NULL;
  long long *fs = (long long *)lg_box_send(&bu, ucnt, urcnt, &uord, &nf, &R->bad);
  char *mine = calloc((size_t)G->nn + 1, 1);
  int *num = malloc(sizeof(int) * ((size_t)G->nn + 1));
  if (!mine || !num) R->bad = 1;
  for (long i = 0; !R->bad && i < nf; i++) {
    long long k = fs[i] - G->node_first;
    if (k < 0 || k >= G->nn) R->bad = 1;
    else mine[k] = 1;
  }
  int nused = 0;
  for (long long k = 0; !R->bad && k < G->nn; k++) nused += mine[k];
  int base = 0, total = 0;
  (void)MPI_Exscan(&nused, &base, 1, MPI_INT, MPI_SUM, PETSC_COMM_WORLD);
  if (R->rank == 0) base = 0;
  (void)MPI_Allreduce(&nused, &total, 1, MPI_INT, MPI_SUM, PETSC_COMM_WORLD);
  R->ux = malloc(sizeof(double) * 3 * ((size_t)nused + 1));
  if (!R->ux) R->bad = 1;
  for (long long k = 0, n = 0; !R->bad && k < G->nn; k++)
    if (mine[k]) {
      num[k] = base + (int)n;
      const double *p = G->nx + 3 * k;
      memcpy(R->ux + 3 * n++, p, 3 * sizeof(double));
      /* a 1D mesh on the x axis, a 2D one in the plane z = 0 (the whole reader's checks) */
      if ((R->cdim == 1 && (fabs(p[1]) > 1e-12 * (1 + fabs(p[0])) || fabs(p[2]) > 1e-12 * (1 + fabs(p[0])))) ||
          (R->cdim == 2 && fabs(p[2]) > 1e-12 * (1 + fabs(p[0]) + fabs(p[1]))))
        why(R, "a node off the mesh's line or plane");
    }
  /* the numbers back to the tags' homes, then to the questions */
  int *ans = malloc(sizeof(int) * ((size_t)nf + 1));
  if (!ans) R->bad = 1;
  for (long i = 0; !R->bad && i < nf; i++) ans[i] = num[fs[i] - G->node_first];
  int *unum = (int *)lg_reply((char *)ans, sizeof(int), urcnt, ucnt, &R->bad);
  int *vnum = malloc(sizeof(int) * ((size_t)nu + 1)), *uat = malloc(sizeof(int) * ((size_t)bu.n + 1));
  if (!vnum || !uat) R->bad = 1;
  for (long k = 0; !R->bad && k < bu.n; k++) uat[uord[k]] = unum[k]; /* back in the box's order */
  for (long u = 0, k = 0; !R->bad && u < nu; u++) vnum[u] = used[u] ? uat[k++] : -1;
  int *qa = malloc(sizeof(int) * ((size_t)nq + 1));
  if (!qa) R->bad = 1;
  for (long i = 0; !R->bad && i < nq; i++) qa[i] = vnum[which[i]];
  int *back = (int *)lg_reply((char *)qa, sizeof(int), qrcnt, qcnt, &R->bad);
  /* the local cells and tagged facets in vertex numbers (each tag's answer found among the
   * sorted distinct tags) */
  long *at = malloc(sizeof(long) * ((size_t)bq.n + 1));
  if (!at) R->bad = 1;
  for (long k = 0; !R->bad && k < bq.n; k++) at[qord[k]] = back[k];
  local_elements(R, ut, nut, at);
  R->nvg = total;
  R->vbase = base;
  R->nused = nused;
  free(nodes); free(asks); free(qord); free(which); free(used); free(fs); free(mine); free(num); free(ans);
  /* the elements and nodes as read are done with (their physical tags stay) */
  free(G->e); free(G->enodes); free(G->ntag); free(G->nx);
  G->e = NULL;
  G->enodes = NULL;
  G->ntag = NULL;
  G->nx = NULL;
  free(unum); free(vnum); free(uat); free(uord); free(qa); free(back); free(at); free(ut);
  lg_box_free(&bq); lg_box_free(&bu);
}

/* step 2: cells repeated in the file are one (the first; its region the last nonzero tag,
 * two different ones the whole reader's error), numbered in the file's order */
/* a cell's key: the hash of its sorted vertices */
static uint64_t cell_hash(const int *v, int nvc, int *sorted) {
  memcpy(sorted, v, sizeof(int) * (size_t)nvc);
  sort_small(sorted, nvc);
  return key_hash(sorted, nvc);
}

static void number_cells(reader *R) {
  int P = R->P, nvc = R->nvc, *cnt = R->cnt, *rcnt = cnt + P;
  if (R->L.nelems > INT32_MAX) why(R, "over 2^31 elements");
  /* each cell's key hash, place in the file and tag to the hash's home; only where hashes
   * meet (a repeated cell, or a collision) the keys themselves follow, in a second round */
  lg_box b = {sizeof(rhash), 0, 0, NULL, NULL};
  int k8[8];
  for (int c = 0; !R->bad && c < R->ncl; c++) {
    uint64_t x = cell_hash(R->cv + (size_t)nvc * c, nvc, k8);
    rhash *r = lg_box_add(&b, (int)(x % (uint64_t)P), &R->bad);
    if (r) { r->h = x; r->index = (int)(R->efirst + R->cidx[c]); r->tag = R->ctag[c]; }
  }
  long n = 0, *ord = NULL;
  rhash *d = (rhash *)lg_box_send(&b, cnt, rcnt, &ord, &n, &R->bad);
  /* the homes: by hash (radix); a lone hash is a cell kept with its tag; a shared one asks
   * for the keys (answer 2, with the record's place here) */
  int *ans = malloc(sizeof(int) * 3 * ((size_t)n + 1));
  kv *h = malloc(sizeof(kv) * ((size_t)n + 1));
  if (!ans || !h) R->bad = 1;
  for (long i = 0; !R->bad && i < n; i++) h[i] = (kv){d[i].h, i};
  if (!R->bad && sort_kv(h, n)) R->bad = 1;
  for (long i = 0; !R->bad && i < n;) {
    long j = i + 1;
    while (j < n && h[j].k == h[i].k) j++;
    for (long k = i; k < j; k++) {
      ans[3 * h[k].i] = j - i > 1 ? 2 : 1;
      ans[3 * h[k].i + 1] = d[h[k].i].tag;
      ans[3 * h[k].i + 2] = (int)h[k].i;
    }
    i = j;
  }
  free(h);
  int *back = (int *)lg_reply((char *)ans, 3 * sizeof(int), rcnt, cnt, &R->bad);
  free(ans);
  R->keep = malloc(sizeof(int) * ((size_t)R->ncl + 1));
  if (!R->keep) R->bad = 1;
  lg_box bk = {sizeof(rdup), 0, 0, NULL, NULL};
  long *kcell = malloc(sizeof(long) * ((size_t)b.n + 1)); /* the cell of each key sent */
  if (!kcell) R->bad = 1;
  for (long k = 0; !R->bad && k < b.n; k++) {
    long c = ord[k];
    R->keep[c] = back[3 * k];
    R->ctag[c] = back[3 * k + 1];
    if (back[3 * k] != 2) continue;
    rdup *r = lg_box_add(&bk, (int)(cell_hash(R->cv + (size_t)nvc * c, nvc, k8) % (uint64_t)P), &R->bad);
    if (r) { memset(r->key, 0, sizeof r->key); memcpy(r->key, k8, sizeof(int) * (size_t)nvc); r->index = back[3 * k + 2]; kcell[bk.n - 1] = c; }
  }
  free(back);
  long nk = 0, *kord = NULL;
  int *kcnt = cnt + 2 * P, *krcnt = cnt + 3 * P;
  rdup *keys = (rdup *)lg_box_send(&bk, kcnt, krcnt, &kord, &nk, &R->bad);
  /* the shared hashes' keys: equal keys by place in the file, the first kept, its region the
   * last nonzero tag (two different ones: the whole reader's error) */
  int *kans = malloc(sizeof(int) * 2 * ((size_t)nk + 1));
  rdup *g = malloc(sizeof(rdup) * ((size_t)nk + 1));
  if (!kans || !g) R->bad = 1;
  for (long i = 0; !R->bad && i < nk; i++) {
    if (keys[i].index < 0 || keys[i].index >= n) { R->bad = 1; break; }
    g[i] = keys[i];
    g[i].tag = d[keys[i].index].tag;
    g[i].index = d[keys[i].index].index;
    g[i].pad = (int)i; /* the place received */
  }
  if (!R->bad) qsort(g, (size_t)nk, sizeof(rdup), cmp_rdup);
  for (long a0 = 0; !R->bad && a0 < nk;) {
    long a1 = a0;
    int tag = g[a0].tag;
    while (a1 + 1 < nk && !key_cmp(g[a1 + 1].key, g[a0].key, nvc)) {
      a1++;
      if (g[a1].tag && tag && g[a1].tag != tag) why(R, "a cell repeated in another physical group");
      if (g[a1].tag) tag = g[a1].tag;
    }
    for (long k = a0; k <= a1; k++) {
      kans[2 * g[k].pad] = k == a0;
      kans[2 * g[k].pad + 1] = tag;
    }
    a0 = a1 + 1;
  }
  int *kback = (int *)lg_reply((char *)kans, 2 * sizeof(int), krcnt, kcnt, &R->bad);
  for (long k = 0; !R->bad && k < bk.n; k++) {
    long c = kcell[kord[k]]; /* the asking cell */
    R->keep[c] = kback[2 * k];
    R->ctag[c] = kback[2 * k + 1];
  }
  free(d); free(ord); free(keys); free(kord); free(kans); free(g); free(kback); free(kcell);
  lg_box_free(&b);
  lg_box_free(&bk);
  int kept = 0, base = 0, total = 0;
  for (int c = 0; !R->bad && c < R->ncl; c++) kept += R->keep[c];
  (void)MPI_Exscan(&kept, &base, 1, MPI_INT, MPI_SUM, PETSC_COMM_WORLD);
  if (R->rank == 0) base = 0;
  (void)MPI_Allreduce(&kept, &total, 1, MPI_INT, MPI_SUM, PETSC_COMM_WORLD);
  /* the kept cells first, in order */
  for (int c = 0, k = 0; !R->bad && c < R->ncl; c++)
    if (R->keep[c]) {
      memmove(R->cv + (size_t)nvc * (size_t)k, R->cv + (size_t)nvc * (size_t)c, (size_t)nvc * sizeof(int));
      R->ctag[k] = R->ctag[c];
      R->cidx[k++] = R->cidx[c];
    }
  R->ncl = kept;
  R->cbase = base;
  R->ncg = total;
}

/* the window: the cells this rank owns, its ghost layers (each time every cell around the
 * vertices so far), the owners and coordinates of their vertices; the tagged facets of its
 * cells (each in the window of the last cell holding it, where the whole mesh's part keeps
 * it); then the part. A cell travels as w = 3 + nvc ints: number, part, region tag, vertices */
#define CG(r) (r)[0]
#define CP(r) (r)[1]
#define CT(r) (r)[2]
#define CV(r) ((r) + 3)

/* the window's vertices' local numbers: an open-addressing map from the global number */
typedef struct { int *key, *val; size_t mask; } vmap;
static int vmap_build(vmap *M, const int *v, long n) {
  size_t cap = 16;
  while (cap < 2 * (size_t)n + 16) cap <<= 1;
  M->key = malloc(sizeof(int) * cap);
  M->val = malloc(sizeof(int) * cap);
  M->mask = cap - 1;
  if (!M->key || !M->val) return 1;
  for (size_t i = 0; i < cap; i++) M->key[i] = -1;
  for (long i = 0; i < n; i++) {
    size_t h = mix((uint64_t)v[i]) & M->mask;
    while (M->key[h] >= 0) h = (h + 1) & M->mask;
    M->key[h] = v[i];
    M->val[h] = (int)i;
  }
  return 0;
}
static int vmap_get(const vmap *M, int v) {
  size_t h = mix((uint64_t)v) & M->mask;
  while (M->key[h] >= 0) {
    if (M->key[h] == v) return M->val[h];
    h = (h + 1) & M->mask;
  }
  return -1;
}
static void vmap_free(vmap *M) { free(M->key); free(M->val); }

typedef struct {         /* the vertex homes' state: this rank's run lo .. lo + n - 1 */
  int lo, n;
  int *cells;            /* the cells around them (w ints each), by number */
  long ncells;
  int *vs, *vc;          /* vertex v's cells: vc[vs[v - lo] .. vs[v - lo + 1] - 1] */
  int *own;              /* owners (mesh_vertex_owners' vote) */
  double *x;             /* coordinates, 3 each */
  char *onf;             /* on a tagged facet */
} vhomes;

typedef struct {
  int *c;                /* the window's cells (w ints each), by number */
  long nc;
  int *v;                /* its vertices, by number */
  long nv;
  rvert *vx;             /* their owners, flags (pad: on a tagged facet) and coordinates */
  vmap map;              /* global number -> place in v */
  rfacet *f;             /* its tagged facets, in the file's order */
  long nf;
  int *btags, nbt;       /* every boundary tag of the whole mesh */
} window;

/* records of w ints sorted by their first int (radix on it, then a gather) */
static int sort_records(int *r, long n, int w) {
  int sorted = 1;
  for (long i = 1; i < n && sorted; i++) sorted = r[(size_t)w * i] >= r[(size_t)w * (i - 1)];
  if (sorted) return 0;
  kv *k = malloc(sizeof(kv) * ((size_t)n + 1));
  int *t = malloc(sizeof(int) * (size_t)w * ((size_t)n + 1));
  if (!k || !t) { free(k); free(t); return 1; }
  for (long i = 0; i < n; i++) k[i] = (kv){(uint64_t)(unsigned)r[(size_t)w * i], i};
  if (sort_kv(k, n)) { free(k); free(t); return 1; }
  for (long i = 0; i < n; i++) memcpy(t + (size_t)w * i, r + (size_t)w * k[i].i, sizeof(int) * (size_t)w);
  memcpy(r, t, sizeof(int) * (size_t)w * (size_t)n);
  free(k);
  free(t);
  return 0;
}

/* the home of a cell's vertex k (v: its vertices), or -1 where an earlier vertex has the
 * same home: a cell goes to each of its vertices' homes once */
static int new_home(const int *v, int k, int nvg, int P) {
  int h = vhome(v[k], nvg, P);
  for (int i = 0; i < k; i++)
    if (vhome(v[i], nvg, P) == h) return -1;
  return h;
}
/* local cell c's number in the whole mesh */
static int cell_number(const reader *R, int c) { return R->cglob ? R->cglob[c] : R->cbase + c; }

/* each cell's part in the numbering's runs: that of its lowest vertex (mesh_vertex_runs) */
static void runs_parts(reader *R) {
  int nvc = R->nvc;
  if (!(R->cpart = malloc(sizeof(int) * ((size_t)R->ncl + 1)))) { R->bad = 1; return; }
  for (int c = 0; c < R->ncl; c++) {
    const int *v = R->cv + (size_t)nvc * c;
    int lo = v[0];
    for (int k = 1; k < nvc; k++) lo = v[k] < lo ? v[k] : lo;
    R->cpart[c] = vhome(lo, R->nvg, R->P);
  }
}

/* the cells (with their runs' parts) to the homes of their vertices, each home's list of its
 * vertices' cells, and the coordinates from the nodes' readers */
static void home_cells(reader *R, vhomes *H) {
  int P = R->P, nvc = R->nvc, nvg = R->nvg, w = 3 + nvc;
  int *cnt = R->cnt, *rcnt = cnt + P;
  H->lo = vlo(R->rank, nvg, P);
  H->n = vlo(R->rank + 1, nvg, P) - H->lo;
  lg_box bh = {sizeof(int) * (size_t)w, 0, 0, NULL, NULL};
  for (int c = 0; !R->bad && c < R->ncl; c++) {
    const int *v = R->cv + (size_t)nvc * (size_t)c;
    for (int k = 0; k < nvc; k++) {
      int h = new_home(v, k, nvg, P), *x = h < 0 ? NULL : lg_box_add(&bh, h, &R->bad);
      if (!x) continue;
      CG(x) = cell_number(R, c);
      CP(x) = R->cpart[c];
      CT(x) = R->ctag[c];
      memcpy(CV(x), v, sizeof(int) * (size_t)nvc);
    }
  }
  /* the readers' cells are in the file's order and ranks send in rank order: they arrive
   * sorted by number (sort_records checks) */
  H->cells = (int *)lg_box_send(&bh, cnt, rcnt, NULL, &H->ncells, &R->bad);
  if (!R->bad && sort_records(H->cells, H->ncells, w)) R->bad = 1;
  int lo = H->lo, n = H->n;
  H->vs = calloc((size_t)n + 2, sizeof(int));
  H->vc = malloc(sizeof(int) * ((size_t)H->ncells * nvc + 1));
  H->own = malloc(sizeof(int) * ((size_t)n + 1));
  H->x = malloc(sizeof(double) * 3 * ((size_t)n + 1));
  H->onf = calloc((size_t)n + 1, 1);
  if (!H->vs || !H->vc || !H->own || !H->x || !H->onf) R->bad = 1;
  if (!R->bad) {
    for (long i = 0; i < H->ncells; i++)
      for (int k = 0; k < nvc; k++) {
        int v = CV(H->cells + (size_t)w * i)[k];
        if (v >= lo && v < lo + n) H->vs[v - lo + 2]++;
      }
    for (int v = 0; v < n; v++) H->vs[v + 2] += H->vs[v + 1];
    for (long i = 0; i < H->ncells; i++)
      for (int k = 0; k < nvc; k++) {
        int v = CV(H->cells + (size_t)w * i)[k];
        if (v >= lo && v < lo + n) H->vc[H->vs[v - lo + 1]++] = (int)i;
      }
  }
  lg_box bx = {sizeof(rcoord), 0, 0, NULL, NULL};
  for (int k = 0; !R->bad && k < R->nused; k++) {
    rcoord *x = lg_box_add(&bx, vhome(R->vbase + k, nvg, P), &R->bad);
    if (x) { x->v = R->vbase + k; memcpy(x->x, R->ux + 3 * (size_t)k, sizeof x->x); }
  }
  long nx = 0;
  rcoord *xs = (rcoord *)lg_box_send(&bx, cnt, rcnt, NULL, &nx, &R->bad);
  for (long i = 0; !R->bad && i < nx; i++) {
    if (xs[i].v < lo || xs[i].v >= lo + n) { R->bad = 1; break; }
    memcpy(H->x + 3 * (size_t)(xs[i].v - lo), xs[i].x, sizeof xs[i].x);
  }
  free(xs);
  free(R->ux); /* the homes have the coordinates now */
  R->ux = NULL;
}

/* the vertex graph's row of home vertex v (lo + v): the other vertices of its cells, sorted
 * and unique, into nb (grown); their count */
static int graph_row(const vhomes *H, int w, int v, int **nb, int *cap) {
  int nvc = w - 3, m = 0, need = (H->vs[v + 1] - H->vs[v]) * nvc;
  if (need > *cap) {
    int *q = realloc(*nb, sizeof(int) * (size_t)(*cap = 2 * need));
    if (!q) return -1;
    *nb = q;
  }
  for (int i = H->vs[v]; i < H->vs[v + 1]; i++)
    for (int k = 0; k < nvc; k++) {
      int u = CV(H->cells + (size_t)w * H->vc[i])[k];
      if (u != v + H->lo) (*nb)[m++] = u;
    }
  qsort(*nb, (size_t)m, sizeof(int), cmp_int);
  int u = 0;
  for (int i = 0; i < m; i++)
    if (!u || (*nb)[i] != (*nb)[u - 1]) (*nb)[u++] = (*nb)[i];
  return u;
}

/* each cell's part: the numbering's runs (runs_parts), kept by auto where they cut little as
 * for a whole mesh, or a graph partitioner on the vertex graph, whose rows are the vertex
 * homes' (from their cells' lists), each cell then in the part of most of its vertices, which
 * the homes' copies of the cells learn too */
static void partition(reader *R, vhomes *H) {
  int P = R->P, nvc = R->nvc, nvg = R->nvg, d = R->cdim, w = 3 + nvc, lo = H->lo, nloc = H->n;
  int *cnt = R->cnt, *rcnt = cnt + P;
  lg_env *env = R->env;
  char method[64] = "auto";
  PetscOptionsGetString(NULL, NULL, "-lugal_partitioner", method, sizeof method, NULL);
  if (!strcmp(method, "natural")) return;
  if (!strcmp(method, "auto")) {
    /* the vertices the runs cut, counted at their homes; the runs' smallest part */
    lg_box b = {sizeof(int), 0, 0, NULL, NULL};
    long *pc = calloc((size_t)P, sizeof(long)), *pt = calloc((size_t)P, sizeof(long));
    if (!pc || !pt) R->bad = 1;
    for (int c = 0; !R->bad && c < R->ncl; c++) {
      const int *v = R->cv + (size_t)nvc * (size_t)c;
      int cut = 0;
      pc[R->cpart[c]]++;
      for (int k = 1; k < nvc; k++) cut |= vhome(v[k], nvg, P) != vhome(v[0], nvg, P);
      for (int k = 0; cut && k < nvc; k++) {
        int *x = lg_box_add(&b, vhome(v[k], nvg, P), &R->bad);
        if (x) *x = v[k];
      }
    }
    long n = 0;
    int *got = (int *)lg_box_send(&b, cnt, rcnt, NULL, &n, &R->bad);
    long have = R->bad ? 0 : unique_ints(got, n), all = 0, fewest = -1;
    if (have < 0) R->bad = 1;
    (void)MPI_Allreduce(&have, &all, 1, MPI_LONG, MPI_SUM, PETSC_COMM_WORLD);
    if (pc && pt) MPI_Allreduce(pc, pt, P, MPI_LONG, MPI_SUM, PETSC_COMM_WORLD);
    for (int r = 0; pt && r < P; r++) fewest = fewest < 0 || pt[r] < fewest ? pt[r] : fewest;
    int verbose = env->verbose;
    env->verbose = verbose && R->rank == 0;
    int keep = lg_runs_kept(env, all, lg_runs_cut_little(all, nvg, d, P) ? fewest : -1, nvg, R->ncg, d, P);
    env->verbose = verbose;
    free(got); free(pc); free(pt);
    lg_box_free(&b);
    if (keep) return;
#ifdef PETSC_HAVE_PTSCOTCH
    strcpy(method, MATPARTITIONINGPTSCOTCH);
#else
    strcpy(method, MATPARTITIONINGCURRENT);
#endif
  }
  double t0 = lg_now_ms();
  /* the rows, counted in a first pass and written in a second */
  int *nb = NULL, cap = 0;
  PetscInt *ia = NULL, *ja = NULL;
  if (!R->bad && PetscMalloc1(nloc + 1, &ia)) R->bad = 1;
  for (int pass = 0; pass < 2 && !R->bad; pass++) {
    long at = 0;
    for (int v = 0; v < nloc && !R->bad; v++) {
      int u = graph_row(H, w, v, &nb, &cap);
      if (u < 0) { R->bad = 1; break; }
      if (pass) for (int i = 0; i < u; i++) ja[at + i] = nb[i];
      else ia[v] = (PetscInt)at;
      at += u;
    }
    if (!pass && !R->bad) {
      ia[nloc] = (PetscInt)at;
      if (PetscMalloc1(at + 1, &ja)) R->bad = 1;
    }
  }
  free(nb);
  /* every rank creates the graph and partitions (the others wait for a failed one) */
  int *vpart = NULL;
  if (any(R)) { PetscFree(ia); PetscFree(ja); return; }
  if (!(vpart = malloc(sizeof(int) * ((size_t)nloc + 1)))) { PetscFree(ia); PetscFree(ja); ia = ja = NULL; }
  int nfail = !vpart, fail = 0;
  (void)MPI_Allreduce(&nfail, &fail, 1, MPI_INT, MPI_MAX, PETSC_COMM_WORLD);
  /* lg_partition_graph owns ia and ja from the call on, failed or not (it freed them: freeing
   * them here too aborted the run with "double free or corruption" on an unknown
   * -lugal_partitioner) */
  if (fail || lg_partition_graph(env, PETSC_COMM_WORLD, nloc, nvg, ia, ja, P, method, vpart)) why(R, "the partitioner failed");
  /* each cell in the part of most of its vertices (the lowest of those that tie) */
  lg_box q = {sizeof(int), 0, 0, NULL, NULL};
  for (int c = 0; !R->bad && c < R->ncl; c++)
    for (int k = 0; k < nvc; k++) {
      int *x = lg_box_add(&q, vhome(R->cv[(size_t)nvc * c + k], nvg, P), &R->bad);
      if (x) *x = R->cv[(size_t)nvc * c + k];
    }
  long nq = 0, *ord = NULL;
  int *qs = (int *)lg_box_send(&q, cnt, rcnt, &ord, &nq, &R->bad);
  for (long i = 0; !R->bad && i < nq; i++) qs[i] = vpart[qs[i] - lo];
  int *back = (int *)lg_reply((char *)qs, sizeof(int), rcnt, cnt, &R->bad), *at = malloc(sizeof(int) * ((size_t)q.n + 1));
  if (!at) R->bad = 1;
  for (long k = 0; !R->bad && k < q.n; k++) at[ord[k]] = back[k];
  for (int c = 0; !R->bad && c < R->ncl; c++) R->cpart[c] = lg_majority_part(at + (size_t)c * nvc, nvc);
  free(vpart); free(ord); free(qs); free(back); free(at);
  lg_box_free(&q);
  /* the homes' copies of the cells take their parts: (number, part) to the homes they went to */
  lg_box bp = {2 * sizeof(int), 0, 0, NULL, NULL};
  for (int c = 0; !R->bad && c < R->ncl; c++) {
    const int *v = R->cv + (size_t)nvc * (size_t)c;
    for (int k = 0; k < nvc; k++) {
      int h = new_home(v, k, nvg, P), *x = h < 0 ? NULL : lg_box_add(&bp, h, &R->bad);
      if (x) { x[0] = cell_number(R, c); x[1] = R->cpart[c]; }
    }
  }
  long ng = 0;
  int *gp = (int *)lg_box_send(&bp, cnt, rcnt, NULL, &ng, &R->bad);
  for (long i = 0, j = 0; !R->bad && i < ng; i++) { /* both by number */
    while (j < H->ncells && CG(H->cells + (size_t)w * j) < gp[2 * i]) j++;
    if (j == H->ncells || CG(H->cells + (size_t)w * j) != gp[2 * i]) { R->bad = 1; break; }
    CP(H->cells + (size_t)w * j) = gp[2 * i + 1];
  }
  free(gp);
  if (env->verbose && R->rank == 0 && !R->bad)
    fprintf(stderr, "[lugal] partition: %d cells into %d parts by %s on the distributed vertex graph in %.1f ms\n", R->ncg, P,
            method, lg_now_ms() - t0);
}

/* the owners of the homes' vertices (mesh_vertex_owners' vote, in cell order), and each
 * rank's own cells, the window's start */
static void owners(reader *R, vhomes *H, window *W) {
  int P = R->P, nvc = R->nvc, w = 3 + nvc;
  int *cnt = R->cnt, *rcnt = cnt + P;
  int *votes = calloc((size_t)H->n + 1, sizeof(int)); /* lg_vote's counts */
  if (!votes) R->bad = 1;
  for (int v = 0; votes && !R->bad && v < H->n; v++) {
    H->own[v] = -1;
    for (int i = H->vs[v]; i < H->vs[v + 1]; i++) lg_vote(H->own, votes, v, CP(H->cells + (size_t)w * H->vc[i]));
    if (H->own[v] < 0) why(R, "a vertex of no cell");
  }
  free(votes);
  lg_box bo = {sizeof(int) * (size_t)w, 0, 0, NULL, NULL};
  for (int c = 0; !R->bad && c < R->ncl; c++) {
    int *x = lg_box_add(&bo, R->cpart[c], &R->bad);
    if (!x) break;
    CG(x) = cell_number(R, c);
    CP(x) = R->cpart[c];
    CT(x) = R->ctag[c];
    memcpy(CV(x), R->cv + (size_t)nvc * (size_t)c, sizeof(int) * (size_t)nvc);
  }
  W->c = (int *)lg_box_send(&bo, cnt, rcnt, NULL, &W->nc, &R->bad);
  if (!R->bad && sort_records(W->c, W->nc, w)) R->bad = 1;
}

/* the ghost layers: each round the cells around the window's vertices not asked for yet,
 * from their homes (each cell once per asking rank and round), merged in by number */
static void window_layers(reader *R, vhomes *H, window *W, int layers) {
  int P = R->P, nvc = R->nvc, nvg = R->nvg, w = 3 + nvc, lo = H->lo;
  int *cnt = R->cnt, *rcnt = cnt + P;
  long nasked = 0; /* the vertices asked for so far, sorted */
  int *asked = NULL;
  for (int round = 0; round < layers; round++) {
    long nfr = 0;
    int *fr = malloc(sizeof(int) * ((size_t)W->nc * nvc + 1));
    if (!fr) R->bad = 1;
    for (long i = 0; !R->bad && i < W->nc; i++) memcpy(fr + (size_t)nvc * i, CV(W->c + (size_t)w * i), sizeof(int) * (size_t)nvc);
    if (!R->bad) nfr = unique_ints(fr, W->nc * nvc);
    if (nfr < 0) R->bad = 1;
    /* minus those asked before (both sorted), then added to them */
    long k = 0;
    for (long i = 0, j = 0; !R->bad && i < nfr; i++) {
      while (j < nasked && asked[j] < fr[i]) j++;
      if (j < nasked && asked[j] == fr[i]) continue;
      fr[k++] = fr[i];
    }
    nfr = k;
    int *na = R->bad ? NULL : malloc(sizeof(int) * ((size_t)(nasked + nfr) + 1));
    if (!na) R->bad = 1;
    else {
      long i = 0, j = 0, m = 0;
      while (i < nasked || j < nfr) na[m++] = j >= nfr || (i < nasked && asked[i] < fr[j]) ? asked[i++] : fr[j++];
      free(asked);
      asked = na;
      nasked = m;
    }
    lg_box bq = {sizeof(int), 0, 0, NULL, NULL};
    for (long i = 0; !R->bad && i < nfr; i++) {
      int *x = lg_box_add(&bq, vhome(fr[i], nvg, P), &R->bad);
      if (x) *x = fr[i];
    }
    free(fr);
    long nq = 0;
    int *qs = (int *)lg_box_send(&bq, cnt, rcnt, NULL, &nq, &R->bad);
    /* the answers: per asking rank the cells around its vertices, each once */
    lg_box ba = {sizeof(int) * (size_t)w, 0, 0, NULL, NULL};
    long at = 0;
    for (int src = 0; !R->bad && src < P; src++) {
      long n = 0;
      for (long i = at; i < at + rcnt[src]; i++) n += H->vs[qs[i] - lo + 1] - H->vs[qs[i] - lo];
      int *cl = malloc(sizeof(int) * ((size_t)n + 1));
      if (!cl) { R->bad = 1; break; }
      n = 0;
      /* the asker holds its own cells from the start: the others only */
      for (long i = at; i < at + rcnt[src]; i++)
        for (int j = H->vs[qs[i] - lo]; j < H->vs[qs[i] - lo + 1]; j++)
          if (CP(H->cells + (size_t)w * H->vc[j]) != src) cl[n++] = H->vc[j];
      if ((n = unique_ints(cl, n)) < 0) R->bad = 1;
      for (long i = 0; i < n; i++) {
        int *x = lg_box_add(&ba, src, &R->bad);
        if (x) memcpy(x, H->cells + (size_t)w * cl[i], sizeof(int) * (size_t)w);
      }
      free(cl);
      at += rcnt[src];
    }
    free(qs);
    long ng = 0;
    int *got = (int *)lg_box_send(&ba, cnt, rcnt, NULL, &ng, &R->bad);
    /* the new cells, sorted, merged into the window's by number */
    if (!R->bad && sort_records(got, ng, w)) R->bad = 1;
    int *all = R->bad ? NULL : malloc(sizeof(int) * (size_t)w * ((size_t)(W->nc + ng) + 1));
    if (!all) R->bad = 1;
    else {
      long i = 0, j = 0, m = 0;
      while (i < W->nc || j < ng) {
        const int *a = i < W->nc ? W->c + (size_t)w * i : NULL, *b = j < ng ? got + (size_t)w * j : NULL;
        /* a cell may come from the homes of several of its vertices: each once */
        if (a && (!b || CG(a) < CG(b))) { memcpy(all + (size_t)w * m++, a, sizeof(int) * (size_t)w); i++; }
        else {
          if ((!a || CG(a) != CG(b)) && (!m || CG(all + (size_t)w * (m - 1)) != CG(b))) memcpy(all + (size_t)w * m++, b, sizeof(int) * (size_t)w);
          j++;
        }
      }
      free(W->c);
      W->c = all;
      W->nc = m;
    }
    free(got);
  }
  free(asked);
}

/* the file's tagged facets of this rank's run as records (vertices, tag, place in the file) */
static void file_facets(reader *R, lg_box *bf) {
  int nvf = R->nvf;
  for (int i = 0; !R->bad && i < R->nfl; i++) {
    const int *v = R->fv + 4 * (size_t)i;
    int ok = 1;
    for (int k = 0; k < nvf; k++) ok &= v[k] >= 0;
    if (!ok) continue; /* a tagged facet away from the cells carries nothing */
    for (int j = 0; j < R->fnp[i]; j++) {
      rfacet *x = lg_box_add(bf, 0, &R->bad);
      if (!x) break;
      memcpy(x->v, v, sizeof(int) * (size_t)nvf);
      x->tag = R->G.phys[R->fph[i] + j];
      x->j = j;
      x->index = R->efirst + R->fidx[i];
    }
  }
}

/* the tagged facets (the records of bf, keyed and sent here) at their keys' homes, each
 * (facet, tag) once: the first in the file; their vertices flagged at the vertex homes (only
 * faces of flagged vertices are asked for) */
static rfacet *facet_homes(reader *R, vhomes *H, lg_box *bf, long *nfh) {
  int P = R->P, nvf = R->nvf, nvg = R->nvg;
  int *cnt = R->cnt, *rcnt = cnt + P;
  for (long i = 0; !R->bad && i < bf->n; i++) {
    rfacet *x = (rfacet *)(bf->data + sizeof(rfacet) * (size_t)i);
    memset(x->key, 0, sizeof x->key);
    memcpy(x->key, x->v, sizeof(int) * (size_t)nvf);
    sort_small(x->key, nvf);
    bf->dest[i] = hash_rank(x->key, 4, P);
  }
  long nf = 0;
  rfacet *fs = (rfacet *)lg_box_send(bf, cnt, rcnt, NULL, &nf, &R->bad);
  if (!R->bad) {
    qsort(fs, (size_t)nf, sizeof(rfacet), cmp_rfacet);
    long k = 0;
    for (long i = 0; i < nf; i++)
      if (!k || key_cmp(fs[i].key, fs[k - 1].key, 4) || fs[i].tag != fs[k - 1].tag) fs[k++] = fs[i];
    nf = k;
  }
  lg_box bv = {sizeof(int), 0, 0, NULL, NULL};
  for (long i = 0; !R->bad && i < nf; i++)
    for (int k = 0; k < nvf; k++) {
      int *x = lg_box_add(&bv, vhome(fs[i].v[k], nvg, P), &R->bad);
      if (x) *x = fs[i].v[k];
    }
  long nv = 0;
  int *vs = (int *)lg_box_send(&bv, cnt, rcnt, NULL, &nv, &R->bad);
  for (long i = 0; !R->bad && i < nv; i++) H->onf[vs[i] - H->lo] = 1;
  free(vs);
  *nfh = nf;
  return fs;
}

/* the window's vertices: owners, flags and coordinates from their homes */
static void window_vertices(reader *R, vhomes *H, window *W) {
  int P = R->P, nvc = R->nvc, nvg = R->nvg, w = 3 + nvc, lo = H->lo;
  int *cnt = R->cnt, *rcnt = cnt + P;
  W->v = malloc(sizeof(int) * ((size_t)W->nc * nvc + 1));
  if (!W->v) R->bad = 1;
  for (long i = 0; !R->bad && i < W->nc; i++) memcpy(W->v + (size_t)nvc * i, CV(W->c + (size_t)w * i), sizeof(int) * (size_t)nvc);
  if (!R->bad && (W->nv = unique_ints(W->v, W->nc * nvc)) < 0) R->bad = 1;
  if (!R->bad && vmap_build(&W->map, W->v, W->nv)) R->bad = 1;
  lg_box bv = {sizeof(int), 0, 0, NULL, NULL};
  for (long i = 0; !R->bad && i < W->nv; i++) {
    int *x = lg_box_add(&bv, vhome(W->v[i], nvg, P), &R->bad);
    if (x) *x = W->v[i];
  }
  long nq = 0, *ord = NULL;
  int *qs = (int *)lg_box_send(&bv, cnt, rcnt, &ord, &nq, &R->bad);
  rvert *ans = malloc(sizeof(rvert) * ((size_t)nq + 1));
  if (!ans) R->bad = 1;
  for (long i = 0; !R->bad && i < nq; i++) {
    ans[i].owner = H->own[qs[i] - lo];
    ans[i].pad = H->onf[qs[i] - lo];
    memcpy(ans[i].x, H->x + 3 * (size_t)(qs[i] - lo), sizeof ans[i].x);
  }
  rvert *back = (rvert *)lg_reply((char *)ans, sizeof(rvert), rcnt, cnt, &R->bad);
  W->vx = malloc(sizeof(rvert) * ((size_t)W->nv + 1));
  if (!W->vx) R->bad = 1;
  for (long k = 0; !R->bad && k < bv.n; k++) W->vx[ord[k]] = back[k];
  free(ord); free(qs); free(ans); free(back);
}

/* the tagged facets of the window's cells: the faces whose vertices are all flagged, with
 * the cell's number, to the facets' homes; each facet to the windows of its last cell (a
 * facet of no cell is the whole reader's error); the boundary tags of the whole mesh */
static void window_facets(reader *R, rfacet *fs, long nf, window *W) {
  int P = R->P, nvf = R->nvf, nvc = R->nvc, w = 3 + nvc, nfc = cell_nfacets(R->ct);
  int *cnt = R->cnt, *rcnt = cnt + P;
  lg_box bq = {sizeof(rface), 0, 0, NULL, NULL};
  for (long i = 0; !R->bad && i < W->nc; i++) {
    const int *c = W->c + (size_t)w * i;
    for (int f = 0; f < nfc; f++) {
      const int *fv = cell_facet_verts(R->ct, f);
      int key[4] = {0, 0, 0, 0}, all = 1;
      for (int k = 0; k < nvf && all; k++) {
        key[k] = CV(c)[fv[k]];
        all = W->vx[vmap_get(&W->map, key[k])].pad;
      }
      if (!all) continue;
      sort_small(key, nvf);
      rface *x = lg_box_add(&bq, hash_rank(key, 4, P), &R->bad);
      if (x) { memcpy(x->key, key, sizeof key); x->g = CG(c); }
    }
  }
  long nq = 0;
  rface *qs = (rface *)lg_box_send(&bq, cnt, rcnt, NULL, &nq, &R->bad);
  rface_at *qa = malloc(sizeof(rface_at) * ((size_t)nq + 1));
  if (!qa) R->bad = 1;
  for (int src = 0, at = 0; !R->bad && src < P; src++)
    for (int i = 0; i < rcnt[src]; i++, at++) {
      memcpy(qa[at].key, qs[at].key, sizeof qa[at].key);
      qa[at].g = qs[at].g;
      qa[at].src = src;
    }
  free(qs);
  lg_box ba = {sizeof(rfacet), 0, 0, NULL, NULL};
  if (!R->bad) {
    qsort(qa, (size_t)nq, sizeof(rface_at), cmp_rface_at);
    long a = 0;
    for (long i = 0; i < nf && !R->bad; i++) {
      while (a < nq && key_cmp(qa[a].key, fs[i].key, 4) < 0) a++;
      long b = a;
      while (b < nq && !key_cmp(qa[b].key, fs[i].key, 4)) b++;
      if (a == b) { why(R, "a tagged facet of no cell"); break; }
      int gmax = qa[b - 1].g;
      for (long k = a; k < b; k++)
        if (qa[k].g == gmax) {
          rfacet *x = lg_box_add(&ba, qa[k].src, &R->bad);
          if (x) *x = fs[i];
        }
    }
  }
  free(qa);
  W->f = (rfacet *)lg_box_send(&ba, cnt, rcnt, NULL, &W->nf, &R->bad);
  if (!R->bad) qsort(W->f, (size_t)W->nf, sizeof(rfacet), cmp_rfacet_order);
  /* the boundary tags: each home's, gathered */
  int nt = 0, *tags = malloc(sizeof(int) * ((size_t)nf + 1)), *counts = malloc(sizeof(int) * 2 * (size_t)P), total = 0;
  if (!tags || !counts) R->bad = 1;
  for (long i = 0; !R->bad && i < nf; i++) tags[nt++] = fs[i].tag;
  if (!R->bad) nt = (int)unique_ints(tags, nt);
  if (R->bad || nt < 0) nt = 0;
  if (counts) {
    (void)MPI_Allgather(&nt, 1, MPI_INT, counts, 1, MPI_INT, PETSC_COMM_WORLD);
    for (int r = 0; r < P; r++) { counts[P + r] = total; total += counts[r]; }
    W->btags = malloc(sizeof(int) * ((size_t)total + 1));
    if (!W->btags) R->bad = 1;
    (void)MPI_Allgatherv(tags, nt, MPI_INT, W->btags ? W->btags : tags, counts, counts + P, MPI_INT, PETSC_COMM_WORLD);
    if (W->btags) W->nbt = (int)unique_ints(W->btags, total);
  }
  free(tags); free(counts);
}

static void vhomes_free(vhomes *H) {
  free(H->cells); free(H->vs); free(H->vc); free(H->own); free(H->x); free(H->onf);
  memset(H, 0, sizeof *H);
}

/* the window as a mesh, oriented as the whole reader orients the whole mesh, and the part
 * cut from it */
static mesh_part *make_part(reader *R, window *W, int layers) {
  char err[MESH_ERRLEN] = "";
  int nvc = R->nvc, nvf = R->nvf, dim = R->cdim, nown = 0, w = 3 + nvc;
  double *x = malloc(sizeof(double) * (size_t)dim * ((size_t)W->nv + 1));
  int *cells = malloc(sizeof(int) * (size_t)nvc * ((size_t)W->nc + 1)), *vglob = W->v, *cglob = malloc(sizeof(int) * ((size_t)W->nc + 1)),
      *part = malloc(sizeof(int) * ((size_t)W->nc + 1)), *vown = malloc(sizeof(int) * ((size_t)W->nv + 1));
  char *owned = calloc((size_t)W->nc + 1, 1);
  mesh *m = NULL;
  mesh_part *P = NULL;
  if (!x || !cells || !cglob || !part || !vown || !owned) R->bad = 1;
  if (!R->bad && (W->nc == 0 || W->nv == 0)) why(R, "a rank with no cells");
  for (long i = 0; !R->bad && i < W->nv; i++) {
    memcpy(x + (size_t)dim * i, W->vx[i].x, sizeof(double) * (size_t)dim);
    vown[i] = W->vx[i].owner;
  }
  for (long i = 0; !R->bad && i < W->nc; i++) {
    const int *c = W->c + (size_t)w * i;
    for (int k = 0; k < nvc; k++) cells[(size_t)nvc * i + k] = vmap_get(&W->map, CV(c)[k]);
    cglob[i] = CG(c);
    part[i] = CP(c);
    owned[i] = part[i] == R->rank;
    nown += owned[i];
  }
  if (!R->bad && !(m = mesh_create(R->ct, (int)W->nv, x, (int)W->nc, cells, err))) why(R, err);
  free(x);
  free(cells);
  for (long i = 0; m && i < W->nc; i++) m->cell_tag[i] = CT(W->c + (size_t)w * i);
  free(W->c); /* the mesh has them */
  W->c = NULL;
  /* every owned cell negative on every rank: the whole mesh is, and is flipped */
  int neg = m && !R->bad ? (nown == 0 || mesh_cells_negative(m, owned)) : 1, all = 0, some = nown > 0, anyown = 0;
  (void)MPI_Allreduce(&neg, &all, 1, MPI_INT, MPI_MIN, PETSC_COMM_WORLD);
  (void)MPI_Allreduce(&some, &anyown, 1, MPI_INT, MPI_MAX, PETSC_COMM_WORLD);
  if (m && all && anyown) mesh_flip_cells(m);
  if (m && W->nf) {
    m->bf_verts = malloc(sizeof(int) * (size_t)nvf * (size_t)W->nf);
    m->bf_tag = malloc(sizeof(int) * (size_t)W->nf);
    if (!m->bf_verts || !m->bf_tag) R->bad = 1;
    for (long b = 0; !R->bad && b < W->nf; b++) {
      for (int k = 0; k < nvf; k++) {
        long lv = vmap_get(&W->map, W->f[b].v[k]);
        if (lv < 0) { why(R, "a facet outside its window"); break; }
        m->bf_verts[(size_t)nvf * b + k] = (int)lv;
      }
      m->bf_tag[b] = W->f[b].tag;
    }
    if (!R->bad) m->nbf = (int)W->nf;
  }
  /* the names as the whole reader sets them: the file's, then the unnamed boundary tags';
   * a generated mesh's own */
  for (int i = 0; m && !R->bad && R->names && i < R->names->nbname; i++)
    if (mesh_set_boundary_name(m, R->names->bnames[i].tag, R->names->bnames[i].name)) R->bad = 1;
  for (int i = 0; m && !R->bad && R->names && i < R->names->ncname; i++)
    if (mesh_set_region_name(m, R->names->cnames[i].tag, R->names->cnames[i].name)) R->bad = 1;
  for (int i = 0; m && !R->bad && !R->names && i < R->G.nname; i++) {
    int rc = 0;
    if (R->G.name_dim[i] == dim) rc = mesh_set_region_name(m, R->G.names[i].tag, R->G.names[i].name);
    else if (R->G.name_dim[i] == dim - 1) rc = mesh_set_boundary_name(m, R->G.names[i].tag, R->G.names[i].name);
    if (rc) R->bad = 1;
  }
  for (int t = 0; m && !R->bad && !R->names && t < W->nbt; t++) {
    int named = 0;
    for (int i = 0; i < m->nbname && !named; i++) named = m->bnames[i].tag == W->btags[t];
    char nm[16];
    snprintf(nm, sizeof nm, "%d", W->btags[t]);
    if (!named && mesh_set_boundary_name(m, W->btags[t], nm)) R->bad = 1;
  }
  if (m && !R->bad && !(P = mesh_part_extract_window(m, vglob, cglob, R->nvg, R->ncg, part, vown, R->rank, layers, err)))
    why(R, err);
  mesh_free(m);
  free(cglob); free(part); free(vown); free(owned);
  return P;
}

static void reader_free(reader *R, window *W) {
  mesh_gmsh_layout_free(&R->L);
  mesh_gmsh_part_free(&R->G);
  free(R->ux); free(R->cv); free(R->ctag); free(R->keep); free(R->cidx); free(R->fv); free(R->fidx); free(R->cpart);
  free(R->fph); free(R->fnp); free(R->cnt); free(R->cglob);
  free(W->c); free(W->v); free(W->vx); free(W->f); free(W->btags);
  vmap_free(&W->map);
}

/* from the cells numbered on the ranks that hold them on: the partition, the vertex homes,
 * the ghost layers, the tagged facets (bf: this rank's, as records), the window's vertices,
 * the part; ts[0..3]: when each phase ended. NULL on every rank where any failed */
static mesh_part *finish(reader *R, window *W, lg_box *bf, int layers, double *ts) {
  vhomes H;
  memset(&H, 0, sizeof H);
  rfacet *fh = NULL;
  long nfh = 0;
  if (!any(R)) runs_parts(R);
  if (!any(R)) home_cells(R, &H);
  if (!any(R)) partition(R, &H);
  ts[0] = lg_now_ms();
  if (!any(R)) owners(R, &H, W);
  if (!any(R)) window_layers(R, &H, W, layers);
  ts[1] = lg_now_ms();
  if (!any(R)) fh = facet_homes(R, &H, bf, &nfh);
  lg_box_free(bf);
  if (!any(R)) window_vertices(R, &H, W);
  vhomes_free(&H);
  if (!any(R)) window_facets(R, fh, nfh, W);
  free(fh);
  ts[2] = lg_now_ms();
  mesh_part *P = NULL;
  if (!any(R)) P = make_part(R, W, layers);
  ts[3] = lg_now_ms();
  return P;
}

/* a reader and its window, empty, for this rank (out of memory: R->bad, which
 * every rank learns at the first any()) */
static void reader_init(reader *R, window *W, lg_env *env) {
  memset(R, 0, sizeof *R);
  memset(W, 0, sizeof *W);
  R->env = env;
  R->rank = lg_mpi_rank();
  R->P = lg_mpi_size();
  if (!(R->cnt = malloc(sizeof(int) * 6 * (size_t)R->P))) R->bad = 1;
}

/* the part on every rank, or NULL on every rank where any failed */
static mesh_part *agree(reader *R, mesh_part *P) {
  if (!any(R)) return P;
  mesh_part_free(P);
  return NULL;
}

/* -lugal_read_parts_min: the least cells a rank below which rank 0 reads the file whole */
static PetscInt read_parts_min(void) {
  PetscInt least = 8;
  PetscOptionsGetInt(NULL, NULL, "-lugal_read_parts_min", &least, NULL);
  return least;
}

int lg_read_parts_wanted(void) {
  PetscBool on = PETSC_TRUE, set = PETSC_FALSE;
  PetscOptionsGetBool(NULL, NULL, "-lugal_read_parts", &on, &set);
  (void)read_parts_min(); /* read on one rank too, so that a serial run does not report it unused */
  return on;
}

mesh_part *lg_part_read(lg_env *env, const char *path) {
  double t0 = lg_now_ms();
  int layers = lg_ghost_layers();
  if (layers < 0) return NULL; /* the whole path gives the message */
  reader R;
  window W;
  reader_init(&R, &W, env);
  R.path = path;
  /* the layout: rank 0's scan, sent to every rank */
  char *buf = NULL;
  size_t len = 0;
  if (R.rank == 0) {
    mesh_gmsh_layout(path, R.P, &R.L);
    if (!R.L.ok) why(&R, R.L.why);
    else if (mesh_gmsh_layout_pack(&R.L, &buf, &len)) R.bad = 1;
    mesh_gmsh_layout_free(&R.L);
  }
  int st = R.bad;
  (void)MPI_Bcast(&st, 1, MPI_INT, 0, PETSC_COMM_WORLD);
  if (st) R.bad = 1;
  else if (lg_bcast_bytes(&buf, &len) || mesh_gmsh_layout_unpack(buf, len, &R.L)) R.bad = 1;
  free(buf);
  char err[MESH_ERRLEN] = "";
  if (!R.bad && mesh_gmsh_read_part(path, &R.L, R.rank, &R.G, err)) why(&R, err);
  R.efirst = R.L.nelems * R.rank / R.P;
  double t1 = lg_now_ms();
  if (!any(&R)) {
    /* the cells: the elements of the highest dimension, of one type */
    int cdim = 0, tmin = INT32_MAX, tmax = 0, d = 0, t[2];
    for (long long i = 0; i < R.G.ne; i++) cdim = mesh_gmsh_type_dim(R.G.e[i].type) > cdim ? mesh_gmsh_type_dim(R.G.e[i].type) : cdim;
    (void)MPI_Allreduce(&cdim, &d, 1, MPI_INT, MPI_MAX, PETSC_COMM_WORLD);
    for (long long i = 0; i < R.G.ne; i++)
      if (mesh_gmsh_type_dim(R.G.e[i].type) == d) {
        tmin = R.G.e[i].type < tmin ? R.G.e[i].type : tmin;
        tmax = R.G.e[i].type > tmax ? R.G.e[i].type : tmax;
      }
    t[0] = -tmin;
    t[1] = tmax;
    int tg[2];
    (void)MPI_Allreduce(t, tg, 2, MPI_INT, MPI_MAX, PETSC_COMM_WORLD);
    if (d < 1 || -tg[0] != tg[1]) why(&R, "no cells, or cells of two types");
    else {
      R.cdim = d;
      R.ctype = tg[1];
      R.ct = mesh_gmsh_type_cell(R.ctype);
      R.nvc = cell_nverts(R.ct);
      R.nvf = cell_nvf(R.ct);
    }
  }
  double ts[7];
  ts[0] = lg_now_ms();
  if (!any(&R)) number_nodes(&R);
  ts[1] = lg_now_ms();
  if (!any(&R)) number_cells(&R);
  ts[2] = lg_now_ms();
  /* fewer than 8 cells a rank (-lugal_read_parts_min): rank 0 cuts such a mesh, as it does a
   * generated one (runs, some parts maybe empty); 0 lets the ranks take tiny files too (the
   * tests' hostile corpus) */
  if (!any(&R) && R.ncg < read_parts_min() * R.P) why(&R, "few cells for the ranks");
  lg_box bf = {sizeof(rfacet), 0, 0, NULL, NULL};
  if (!any(&R)) file_facets(&R, &bf);
  mesh_part *P = agree(&R, finish(&R, &W, &bf, layers, ts + 3));
  if (!P) {
    if (env->verbose && R.rank == 0) fprintf(stderr, "[lugal] read: %s read whole by rank 0 (%s)\n", path, R.why);
  } else if (env->verbose)
    fprintf(stderr, "[lugal] distribute: rank %d holds %d cells (%d owned, %d ghosts) and %d vertices of %d, read here (nodes %lld.., "
                    "elements %lld..) in %.1f ms: parsing %.1f, nodes %.1f, cells %.1f, partition %.1f, ghost layers %.1f, facets %.1f, "
                    "part %.1f\n",
            R.rank, P->m->ncell, P->nown_cell, P->m->ncell - P->nown_cell, P->m->nvert, P->nvert_global, R.G.node_first, R.efirst,
            lg_now_ms() - t0, t1 - t0, ts[1] - ts[0], ts[2] - ts[1], ts[3] - ts[2], ts[4] - ts[3], ts[5] - ts[4], ts[6] - ts[5]);
  reader_free(&R, &W);
  return P;
}

mesh_part *lg_part_from_window(lg_env *env, mesh *m, const int *vglob, const int *cglob, int nvg, int ncg, int layers) {
  double t0 = lg_now_ms();
  reader R;
  window W;
  reader_init(&R, &W, env);
  R.cdim = m->dim;
  R.ct = m->type;
  R.nvc = m->nvc;
  R.nvf = m->nvf;
  R.nvg = nvg;
  R.ncg = ncg;
  R.names = m;
  int P = R.P, nvc = R.nvc, lo = vlo(R.rank, nvg, P), hi = vlo(R.rank + 1, nvg, P);
  /* this rank's run: the cells whose lowest vertex is in its run of the numbering (each
   * cell in exactly one run), and the run's vertices, as if read */
  int *part = malloc(sizeof(int) * ((size_t)m->ncell + 1));
  char *have = calloc((size_t)(hi - lo) + 1, 1);
  if (!part || !have || mesh_build_boundary_cells(m)) R.bad = 1;
  if (!R.bad) {
    mesh_vertex_runs(m, vglob, nvg, P, part);
    for (int c = 0; c < m->ncell; c++) R.ncl += part[c] == R.rank;
    R.cv = malloc(sizeof(int) * (size_t)nvc * ((size_t)R.ncl + 1));
    R.ctag = malloc(sizeof(int) * ((size_t)R.ncl + 1));
    R.cglob = malloc(sizeof(int) * ((size_t)R.ncl + 1));
    R.ux = calloc(3 * ((size_t)(hi - lo) + 1), sizeof(double));
    if (!R.cv || !R.ctag || !R.cglob || !R.ux) R.bad = 1;
  }
  for (int c = 0, k = 0; !R.bad && c < m->ncell; c++) {
    if (part[c] != R.rank) continue;
    for (int j = 0; j < nvc; j++) R.cv[(size_t)nvc * k + j] = vglob[m->cells[(size_t)nvc * c + j]];
    R.ctag[k] = m->cell_tag[c];
    R.cglob[k++] = cglob[c];
  }
  for (int v = 0; !R.bad && v < m->nvert; v++)
    if (vglob[v] >= lo && vglob[v] < hi) {
      memcpy(R.ux + 3 * (size_t)(vglob[v] - lo), m->x + (size_t)m->dim * v, sizeof(double) * (size_t)m->dim);
      have[vglob[v] - lo] = 1;
    }
  for (int v = 0; !R.bad && v < hi - lo; v++)
    if (!have[v]) why(&R, "a run's vertex outside the window");
  R.vbase = lo;
  R.nused = hi - lo;
  /* the tagged facets of the run's cells, in the order of their cells' numbers and places */
  lg_box bf = {sizeof(rfacet), 0, 0, NULL, NULL};
  for (int b = 0; !R.bad && b < m->nbf; b++) {
    int c = m->bf_cell[b];
    if (c < 0 || part[c] != R.rank) continue;
    rfacet *x = lg_box_add(&bf, 0, &R.bad);
    if (!x) break;
    for (int k = 0; k < m->nvf; k++) x->v[k] = vglob[m->bf_verts[(size_t)m->nvf * b + k]];
    x->tag = m->bf_tag[b];
    x->index = (long long)cglob[c] * 8 + m->bf_local[b];
    x->j = 0;
  }
  free(part);
  free(have);
  double ts[4];
  mesh_part *Pt = agree(&R, finish(&R, &W, &bf, layers, ts));
  if (!Pt) {
    if (env->verbose && R.rank == 0) fprintf(stderr, "[lugal] distribute: the mesh generated whole on rank 0 (%s)\n", R.why);
  } else if (env->verbose)
    fprintf(stderr, "[lugal] distribute: rank %d holds %d cells (%d owned, %d ghosts) and %d vertices of %d, generated here and partitioned "
                    "on every rank in %.1f ms: partition %.1f, ghost layers %.1f, facets %.1f, part %.1f\n",
            R.rank, Pt->m->ncell, Pt->nown_cell, Pt->m->ncell - Pt->nown_cell, Pt->m->nvert, Pt->nvert_global, lg_now_ms() - t0, ts[0] - t0,
            ts[1] - ts[0], ts[2] - ts[1], ts[3] - ts[2]);
  reader_free(&R, &W);
  return Pt;
}
