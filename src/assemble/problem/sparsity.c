/* sparsity.c — a problem's matrix: the pattern straight from the dof maps (node-level for
 * vector fields), each element entry's place in the CSR value array, the block size, the
 * rigid body modes as GAMG's near null space, and the null spaces given with nullspace=.
 * The problem's state is problem_int.h's; problem.c assembles into what this builds. */
#include "problem_int.h"

#ifdef _OPENMP
#include <omp.h>
#endif

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/* the global nodes of item it of term t for the rows (or the columns) of its element
 * matrix, in its order: with B components per node (every field a B-vector) the dof / B of
 * every B-th local dof, with B = 1 the global dofs; numbered in PETSc's order when petsc is
 * set. An interior facet term's second half of fields are the problem's fields again, on
 * the '-' cell */
void lg_term_nodes(const lg_problem *p, const prob_term *t, int it, int rows, int B, int petsc, PetscInt *out) {
  const field_layout *l = rows ? &t->rl : &t->cl;
  dofmap *const *dm = rows ? p->rdm : p->cdm;
  const int *glob = rows ? p->rglob : p->cglob;
  int nf = rows ? p->rows.n : p->cols.n;
  for (int a = 0; a < l->n; a++) {
    int f = a % nf, c = t->interior && a >= nf ? t->cells[t->nitems + it] : t->cells[it];
    const int nl = l->nloc[a], *cd = dm[f]->cell_dofs + (size_t)c * nl;
    PetscInt *o = out + l->off[a] / B, g = glob[f];
    if (petsc && p->perm) { /* B is the matrix's block size or 1 */
      if (B == 1)
        for (int k = 0; k < nl; k++) o[k] = lg_petsc_row(p, g + cd[k]);
      else
        for (int k = 0, i = 0; k < nl; k += B, i++) o[i] = p->perm[(g + cd[k]) / B];
    } else if (B == 1)
      for (int k = 0; k < nl; k++) o[k] = g + cd[k];
    else
      for (int k = 0, i = 0; k < nl; k += B, i++) o[i] = (g + cd[k]) / B;
  }
}

/* every item's row (or column) nodes of term t in PETSc's order, one after another: the dof
 * map's own cell list where that is what they are (one field numbered from 0 over every
 * cell in order, B = 1, no reordering: a Laplacian's, 25 MB not copied on 1.57 M
 * tetrahedra), *owned = 0; else gathered */
static const PetscInt *term_node_lists(const lg_problem *p, const prob_term *t, int rows, int B, int petsc, int *owned) {
  const field_layout *l = rows ? &t->rl : &t->cl;
  const dofmap *dm = (rows ? p->rdm : p->cdm)[0];
  int direct = sizeof(PetscInt) == sizeof(int) && B == 1 && l->n == 1 && !t->interior && !p->perm &&
               (rows ? p->rglob : p->cglob)[0] == 0 && l->nloc[0] == dm->nloc && t->nitems == dm->m->ncell;
  for (int it = 0; direct && it < t->nitems; it++) direct = t->cells[it] == it;
  *owned = !direct;
  if (direct) return (const PetscInt *)dm->cell_dofs;
  int n = l->size / B;
  PetscInt *o = malloc(sizeof(PetscInt) * ((size_t)t->nitems * (size_t)n + 1));
  for (int it = 0; o && it < t->nitems; it++) lg_term_nodes(p, t, it, rows, B, petsc, o + (size_t)it * n);
  return o;
}

/* the matrix term that holds item e (erow_off: each term's first, numbered across terms) */
static int find_term(const size_t *erow_off, int nterm, size_t e) {
  int i = 0;
  while (i + 1 < nterm && erow_off[i + 1] <= e) i++;
  return i;
}

/* rows are short (tens of entries): insertion sort, by the nodes' PETSc numbers (perm: a
 * distributed mesh's local node -> PETSc's; NULL: the nodes are PETSc's) */
static void sort_row(PetscInt *v, size_t n, const int *perm) {
  for (size_t i = 1; i < n; i++) {
    PetscInt x = v[i], kx = perm ? perm[x] : x;
    size_t j = i;
    for (; j > 0 && (perm ? perm[v[j - 1]] : v[j - 1]) > kx; j--) v[j] = v[j - 1];
    v[j] = x;
  }
}

/* the pattern passes over the node rows R0..R1 of one block (lg_problem_setup_matrix) */
typedef struct {
  lg_problem *p;
  int B, Nn, R0;         /* R0: the first owned node row; ia counts from it */
  /* a distributed mesh's problem: the node lists, markers and row lists are in local node
   * numbers (Nn of them, not the whole problem's), perm gives their PETSc numbers and
   * iperm the local node of PETSc row R0 + j; NULL elsewhere (the nodes are PETSc's) */
  const int *perm, *iperm;
  const size_t *start, *erow_off;
  const uint32_t *erow;  /* each node row's element rows: their items, numbered across terms */
  const PetscInt *const *rnod, *const *cnod;
  PetscInt *ia, *ja;     /* row starts (after the count pass), the final column array */
  int one_pass;          /* no count pass: each block writes its rows from ja0 on and sets
                          * their starts in ia (places in its region, moved later) */
} pattern_in;

typedef struct {
  int R0, R1;
  size_t nnz, maxlen;    /* the count pass: the block's entries, its longest node row */
  int *mark;             /* a marker per node, -1 outside rows */
  PetscInt *nodes;       /* one node row */
  int bad;               /* 1 out of memory */
  size_t ja0;            /* the one pass: the block's region in ja (its rows' upper bound) */
} pattern_block;

/* the node in the lists' numbering of PETSc's node row R */
#define ROW_NODE(in, R) ((in)->iperm ? (in)->iperm[(R) - (in)->R0] : (R))

/* each element row's term (a short scan: problems have few terms) */
static inline int erow_term(const pattern_in *in, int *last, size_t item) {
  const size_t *eo = in->erow_off;
  if (!(eo[*last] <= item && item < eo[*last + 1])) *last = find_term(eo, in->p->nterm, item);
  return *last;
}

/* node row R: the union of its element rows' column nodes, the diagonal first (a marker
 * per node, which holds R for the nodes already in the row: no global sort) */
static size_t row_nodes(const pattern_in *in, int R, int *last, int *mark, PetscInt *nodes) {
  size_t len = 0;
  nodes[len++] = R;
  mark[R] = R;
  for (size_t q = in->start[R]; q < in->start[R + 1]; q++) {
    int i = erow_term(in, last, in->erow[q]);
    int cn = in->p->t[i].cl.size / in->B;
    const PetscInt *en = in->cnod[i] + (in->erow[q] - in->erow_off[i]) * (size_t)cn;
    for (int k = 0; k < cn; k++) {
      PetscInt J = en[k];
      if (mark[J] != R) { mark[J] = R; nodes[len++] = J; }
    }
  }
  return len;
}

static void block_marks(const pattern_in *in, pattern_block *bk) {
  if (!bk->mark) {
    bk->mark = malloc(sizeof(int) * ((size_t)in->Nn + 1));
    bk->nodes = malloc(sizeof(PetscInt) * ((size_t)in->Nn + 1));
    if (!bk->mark || !bk->nodes) { bk->bad = 1; return; }
  }
  for (int r = 0; r < in->Nn; r++) bk->mark[r] = -1;
}

/* the count pass: each node row's length, its B rows' entries in ia[R * B] */
static void pattern_count(const pattern_in *in, pattern_block *bk) {
  block_marks(in, bk);
  if (bk->bad) return;
  int B = in->B, last = 0;
  size_t nnz = 0, maxlen = 0;
  for (int R = bk->R0; R < bk->R1; R++) {
    size_t len = row_nodes(in, ROW_NODE(in, R), &last, bk->mark, bk->nodes);
    in->ia[(size_t)(R - in->R0) * B] = (PetscInt)(len * (size_t)B);
    nnz += len * (size_t)B * (size_t)B;
    if (len > maxlen) maxlen = len;
  }
  bk->nnz = nnz;
  bk->maxlen = maxlen;
}

/* the fill pass: each node row's nodes again, sorted; its B rows written at their final
 * places in ja, each the row's nodes times B columns; then every element entry's rank in
 * its node row, read from the marker (it holds the column node's position in the row: no
 * search), and for B = 1 each element row's row start. An item that has node R in several
 * of its rows (an interior facet's shared nodes) is listed once per such row, one after
 * another: the k-th listing is the k-th such row */
static void pattern_fill(const pattern_in *in, pattern_block *bk) {
  if (in->one_pass) {
    block_marks(in, bk);
    if (bk->bad) return;
  } else
    for (int r = 0; r < in->Nn; r++) bk->mark[r] = -1;
  size_t cur = bk->ja0; /* the one pass: where the next row goes */
  lg_problem *p = in->p;
  int B = in->B, last = 0, w = p->rank_w;
  int *mark = bk->mark;
  PetscInt *nodes = bk->nodes, *ja = in->ja;
  for (int RP = bk->R0; RP < bk->R1; RP++) {
    int R = ROW_NODE(in, RP); /* the row's node in the lists' numbering */
    size_t len = row_nodes(in, R, &last, mark, nodes);
    sort_row(nodes, len, in->perm);
    PetscInt *iar = in->ia + (size_t)(RP - in->R0) * B;
    if (in->one_pass)
      for (int a = 0; a < B; a++, cur += len * (size_t)B) iar[a] = (PetscInt)cur;
    size_t nz = (size_t)iar[0];
    for (int a = 0; a < B; a++)
      for (size_t k = 0; k < len; k++)
        for (int b2 = 0; b2 < B; b2++) ja[nz++] = (in->perm ? in->perm[nodes[k]] : nodes[k]) * B + b2;
    /* the marker now holds positions (>= Nn would clash with row numbers: use -2 - position) */
    for (size_t k = 0; k < len; k++) mark[nodes[k]] = -2 - (int)k;
    int r = -1;
    for (size_t q = in->start[R]; q < in->start[R + 1]; q++) {
      size_t item = in->erow[q];
      int i = erow_term(in, &last, item);
      const prob_term *t = &p->t[i];
      int rn = t->rl.size / B, cn = t->cl.size / B;
      size_t local = item - in->erow_off[i];
      const PetscInt *rg = in->rnod[i] + local * (size_t)rn, *en = in->cnod[i] + local * (size_t)cn;
      r = q > in->start[R] && in->erow[q - 1] == item ? r + 1 : 0;
      while (rg[r] != R) r++;
      size_t at = t->rank_off + (local * (size_t)rn + (size_t)r) * (size_t)cn;
      if (B == 1 && !t->rows_shared) p->row_start[t->erow_first + local * (size_t)rn + (size_t)r] = (PetscInt)(RP - in->R0);
      if (w == 1)
        for (int k = 0; k < cn; k++) ((uint8_t *)p->rank)[at + k] = (uint8_t)(-2 - mark[en[k]]);
      else if (w == 2)
        for (int k = 0; k < cn; k++) ((uint16_t *)p->rank)[at + k] = (uint16_t)(-2 - mark[en[k]]);
      else
        for (int k = 0; k < cn; k++) ((uint32_t *)p->rank)[at + k] = (uint32_t)(-2 - mark[en[k]]);
    }
    /* back to "not in row R" for the columns of the next rows */
    for (size_t k = 0; k < len; k++) mark[nodes[k]] = R;
  }
  if (in->one_pass) bk->nnz = cur - bk->ja0;
}

/* The sparsity pattern straight from the dof maps: the rows of the cells that matrix terms
 * integrate over, each row the union of its cells' column dofs (a marker per column, no
 * global sort), sorted per row, and the diagonal always (row replacement and ILU need it).
 * Then each element matrix entry's place in the CSR value array, so that assembly adds the
 * element matrices straight into the matrix (no MatSetValues search, no COO scatter). This
 * replaced MatSetPreallocationCOO, which sorted every (row, column) pair: 70% of the setup of
 * a P1 Laplacian on 1.5 M tetrahedra (issue 11). */
/* the block size of the matrix: the number of components when every field has the same
 * (an elasticity problem: 2 or 3), else 1 (Taylor-Hood, scalar systems) */
int lg_matrix_block_size(const lg_problem *p) {
  int bs = p->cdm[0]->bs;
  for (int a = 0; a < p->cols.n; a++)
    if (p->cdm[a]->bs != bs || p->rdm[a]->bs != bs) return 1;
  return p->rows.n == p->cols.n ? bs : 1;
}

/* the node coordinates of a single vector field of the mesh's dimension, interlaced like
 * its dofs (what MatNullSpaceCreateRigidBody takes) */
static int node_coordinates(lg_env *env, lg_problem *p, Vec *out) {
  int dim = p->lm->m->dim;
  const dofmap *dm = p->cdm[0];
  Vec X;
  PCHK(MatCreateVecs(p->A, &X, NULL), "MatCreateVecs"); /* the matrix's layout and block size */
  PetscScalar *x;
  PCHK(VecGetArray(X, &x), "VecGetArray");
  mesh *m = p->lm->m;
  for (int c = 0; c < m->ncell; c++) {
    const int *cd = dm->cell_dofs + (size_t)c * (size_t)dm->nloc;
    if (p->par) { /* a cell with none of the owned nodes */
      int mine = 0;
      for (int k = 0; k < dm->el.nloc; k++) {
        PetscInt r = lg_petsc_row(p, cd[k * dim]);
        mine |= r >= p->lo && r < p->hi;
      }
      if (!mine) continue;
    }
    for (int k = 0; k < dm->el.nloc; k++) {
      PetscInt r = lg_petsc_row(p, cd[k * dim]); /* the node's first row, in the matrix's order */
      if (r < p->lo || r >= p->hi) continue;
      double xyz[3];
      dofmap_node_coords(dm, c, k * dim, xyz);
      for (int j = 0; j < dim; j++) x[r + j - p->lo] = xyz[j];
    }
  }
  PCHK(VecRestoreArray(X, &x), "VecRestoreArray");
  *out = X;
  return 0;
}

/* the rigid body modes of the mesh's current geometry (translations, rotations about its
 * node coordinates) */
static int rigid_modes(lg_env *env, lg_problem *p, MatNullSpace *ns) {
  Vec X;
  if (node_coordinates(env, p, &X)) return 1;
  PetscErrorCode ierr = MatNullSpaceCreateRigidBody(X, ns);
  VecDestroy(&X);
  if (ierr) return lg_petsc_fail(env, ierr, "the rigid body modes");
  return 0;
}

int lg_problem_near_nullspace(lg_env *env, lg_problem *p, KSP ksp) {
  int dim = p->lm->m->dim;
  if (p->near_done || p->cols.n != 1 || p->rows.n != 1 || lg_matrix_block_size(p) != dim || dim < 2 ||
      p->cdm[0]->degree < 1)
    return 0;
  /* a factorization never reads it: the default direct solves skip the 6 vectors (5 ms and
   * 5 MB on a 108 k-dof Neo-Hookean problem, 15 ms on memory the VM has not touched lately) */
  PC pc;
  PCType type;
  PCHK(KSPGetPC(ksp, &pc), "KSPGetPC");
  PCHK(PCGetType(pc, &type), "PCGetType");
  if (type && (!strcmp(type, PCLU) || !strcmp(type, PCCHOLESKY))) return 0;
  p->near_done = 1;
  p->modes_geometry = p->lm->geometry;
  MatNullSpace ns;
  if (rigid_modes(env, p, &ns)) return 1;
  PetscErrorCode ierr = MatSetNearNullSpace(p->A, ns);
  MatNullSpaceDestroy(&ns);
  if (ierr) return lg_petsc_fail(env, ierr, "the rigid body modes (near null space)");
  return 0;
}

int lg_problem_follow_geometry(lg_env *env, lg_problem *p) {
  if (p->modes_geometry == p->lm->geometry || (!p->null_rigid && !p->near_done)) return 0;
  p->modes_geometry = p->lm->geometry;
  MatNullSpace ns;
  if (rigid_modes(env, p, &ns)) return 1;
  PetscErrorCode ierr = 0;
  if (p->null_rigid) {
    ierr = MatSetNullSpace(p->A, ns);
    if (!ierr) {
      MatNullSpaceDestroy(&p->null);
      p->null = ns;
      PetscObjectReference((PetscObject)ns);
    }
  }
  if (!ierr && p->near_done) ierr = MatSetNearNullSpace(p->A, ns);
  MatNullSpaceDestroy(&ns);
  if (ierr) return lg_petsc_fail(env, ierr, "the rigid body modes of the moved mesh");
  return 0;
}

/* a parallel run: the owned rows' pattern (csr_i, csr_j, n rows) split into the diagonal
 * block, columns lo .. hi - 1 numbered from 0, and the off-diagonal block, global columns,
 * each row's order kept (problem_int.h, sd_* and so_*) */
static int split_blocks(lg_env *env, lg_problem *p, int n) {
  const PetscInt *ia = p->csr_i, *ja = p->csr_j;
  size_t nd = 0, no = 0;
  for (PetscInt e = 0; e < ia[n]; e++) {
    if (ja[e] >= p->lo && ja[e] < p->hi) nd++;
    else no++;
  }
  p->sd_i = malloc(sizeof(PetscInt) * ((size_t)n + 1));
  p->so_i = malloc(sizeof(PetscInt) * ((size_t)n + 1));
  p->sd_j = malloc(sizeof(PetscInt) * (nd + 1));
  p->so_j = malloc(sizeof(PetscInt) * (no + 1));
  p->sd_a = calloc(nd + 1, sizeof(PetscScalar));
  p->so_a = calloc(no + 1, sizeof(PetscScalar));
  p->s_left = malloc(sizeof(int) * ((size_t)n + 1));
  if (!p->sd_i || !p->so_i || !p->sd_j || !p->so_j || !p->sd_a || !p->so_a || !p->s_left) {
    lg_seterr(env, "out of memory for the matrix's diagonal and off-diagonal blocks (%ld values)", (long)ia[n]);
    return 1;
  }
  p->sd_i[0] = p->so_i[0] = 0;
  for (int r = 0; r < n; r++) {
    PetscInt d = p->sd_i[r], o = p->so_i[r];
    int left = 0;
    for (PetscInt e = ia[r]; e < ia[r + 1]; e++) {
      if (ja[e] >= p->lo && ja[e] < p->hi) p->sd_j[d++] = ja[e] - p->lo;
      else {
        left += ja[e] < p->lo;
        p->so_j[o++] = ja[e];
      }
    }
    p->sd_i[r + 1] = d;
    p->so_i[r + 1] = o;
    p->s_left[r] = left;
  }
  return 0;
}

/* the element rows of the matrix terms: every item's row and column nodes, once per term
 * (rnod, cnod: the dof map's own list where it is that; rown, cown: the list is the term's
 * own, to free), and the element rows of each node row, by their items (erow, from
 * start[r + 1]; an element row is named by its item, numbered across terms from
 * erow_off). 1 out of memory, 2 too many items */
typedef struct {
  size_t *erow_off, *start;
  const PetscInt **rnod, **cnod;
  int *rown, *cown;
  uint32_t *erow;
} elem_rows;

static void elem_rows_free(const lg_problem *p, elem_rows *E) {
  for (int i = 0; E->rnod && E->cnod && E->rown && E->cown && i < p->nterm; i++) {
    if (E->cown[i]) free((void *)E->cnod[i]);
    if (E->rown[i]) free((void *)E->rnod[i]);
  }
  free(E->rnod); free(E->cnod); free(E->rown); free(E->cown);
  free(E->erow_off);
  free(E->erow);
  free(E->start);
}

static int element_rows(const lg_problem *p, int B, int local, int Nn, elem_rows *E) {
  memset(E, 0, sizeof *E);
  size_t *erow_off = E->erow_off = calloc((size_t)p->nterm + 1, sizeof(size_t)); /* each term's first item */
  const PetscInt **rnod = E->rnod = calloc((size_t)p->nterm + 1, sizeof(PetscInt *));
  const PetscInt **cnod = E->cnod = calloc((size_t)p->nterm + 1, sizeof(PetscInt *));
  int *rown = E->rown = calloc((size_t)p->nterm + 1, sizeof(int)), *cown = E->cown = calloc((size_t)p->nterm + 1, sizeof(int));
  size_t *start = E->start = calloc((size_t)Nn + 2, sizeof(size_t));
  int bad = !erow_off || !rnod || !cnod || !rown || !cown || !start;
  size_t nitem = 0;
  for (int i = 0; i < p->nterm && !bad; i++) {
    prob_term *t = &p->t[i];
    erow_off[i] = nitem;
    if (!t->have_mat) continue;
    int rn = t->rl.size / B;
    nitem += (size_t)t->nitems;
    rnod[i] = term_node_lists(p, t, 1, B, !local, &rown[i]);
    /* a square term (the same fields, dof maps and numbering for rows and columns, as a
     * Laplacian's) shares one list */
    int same = t->rl.n == t->cl.n && t->rl.size == t->cl.size && !memcmp(t->rl.nloc, t->cl.nloc, sizeof t->rl.nloc) &&
               !memcmp(t->rl.off, t->cl.off, sizeof t->rl.off) && !memcmp(t->rl.bs, t->cl.bs, sizeof t->rl.bs) &&
               p->rows.n == p->cols.n &&
               !memcmp(p->rdm, p->cdm, sizeof(dofmap *) * (size_t)p->rows.n) &&
               !memcmp(p->rglob, p->cglob, sizeof(int) * (size_t)(p->rows.n + 1));
    cnod[i] = same ? rnod[i] : term_node_lists(p, t, 0, B, !local, &cown[i]);
    if (!rnod[i] || !cnod[i]) { bad = 1; break; }
    const PetscInt *rg = rnod[i];
    for (size_t e = 0, ne = (size_t)t->nitems * (size_t)rn; e < ne; e++) start[rg[e] + 2]++;
  }
  if (erow_off) erow_off[p->nterm] = nitem;
  if (nitem > UINT32_MAX) bad = 2;
  /* the element rows of each node row, by their items */
  uint32_t *erow = NULL;
  if (!bad) {
    for (int r = 0; r < Nn; r++) start[r + 2] += start[r + 1];
    erow = E->erow = malloc(sizeof(uint32_t) * (start[Nn + 1] + 1));
    bad = !erow;
  }
  for (int i = 0; i < p->nterm && !bad; i++) {
    prob_term *t = &p->t[i];
    if (!t->have_mat) continue;
    int rn = t->rl.size / B;
    const PetscInt *rg = rnod[i];
    for (int it = 0; it < t->nitems; it++, rg += rn)
      for (int r = 0; r < rn; r++) erow[start[rg[r] + 1]++] = (uint32_t)(erow_off[i] + (size_t)it);
  }
  return bad;
}

/* the PETSc matrix on the pattern ia, ja of the n owned rows (nnz entries), and its
 * vectors */
static int create_matrix(lg_env *env, lg_problem *p, int n, size_t nnz, PetscInt *ia, PetscInt *ja) {
  int N = p->N;
  ia[n] = (PetscInt)nnz;
  p->nnz = (PetscInt)nnz;
  /* the matrix is made on these arrays, not a copy of them: PETSc's own preallocation from a
   * CSR pattern inserts every entry through MatSetValues (a third of the setup of a vector
   * P2 matrix) and holds a second pattern while ours is alive. The values start as zero
   * pages, touched first by the first assembly */
  p->csr_i = ia;
  p->csr_j = ja;
  if (!p->par && !(p->csr_a = calloc(nnz ? nnz : 1, sizeof(PetscScalar)))) {
    lg_seterr(env, "out of memory for %ld matrix values", (long)nnz);
    return 1;
  }
  int bs = lg_matrix_block_size(p);
  if (p->par) {
    if (split_blocks(env, p, n)) return 1;
    PCHK(MatCreateMPIAIJWithSplitArrays(PETSC_COMM_WORLD, n, n, p->Nglob, p->Nglob, p->sd_i, p->sd_j, p->sd_a, p->so_i, p->so_j, p->so_a,
                                        &p->A), "matrix creation");
  } else PCHK(MatCreateSeqAIJWithArrays(PETSC_COMM_SELF, N, N, ia, ja, p->csr_a, &p->A), "matrix creation");
  if (p->prefix[0]) PCHK(MatSetOptionsPrefix(p->A, p->prefix), "MatSetOptionsPrefix");
  if (bs > 1) PCHK(MatSetBlockSize(p->A, bs), "MatSetBlockSize");
  /* row replacement must keep the pattern: the element places are reused every assembly */
  PCHK(MatSetOption(p->A, MAT_KEEP_NONZERO_PATTERN, PETSC_TRUE), "MatSetOption");
  PCHK(MatSetOption(p->A, MAT_NEW_NONZERO_LOCATION_ERR, PETSC_TRUE), "MatSetOption");
  PCHK(MatCreateVecs(p->A, &p->x, &p->b), "vector creation");
  return 0;
}

/* the count pass, then the fill pass at the counted places (lg_problem_setup_matrix) */
static int pattern_two_passes(lg_problem *p, pattern_in *in, pattern_block *blk, int nb, size_t nrank, size_t nerow,
                              size_t *nnzout, PetscInt **jaout) {
  int B = in->B, R0 = in->R0, R1 = p->hi / B, bad = 0;
  size_t nnz = 0, maxlen = 0;
#ifdef _OPENMP
#pragma omp parallel for schedule(static, 1) if (nb > 1)
#endif
  for (int b = 0; b < nb; b++) pattern_count(in, &blk[b]);
  for (int b = 0; b < nb && !bad; b++) {
    bad = blk[b].bad;
    nnz += blk[b].nnz;
    if (blk[b].maxlen > maxlen) maxlen = blk[b].maxlen;
  }
  if (!bad && nnz > (size_t)INT32_MAX) bad = 3;
  if (bad) return bad;
  /* row starts from the counts (ia[R * B] holds each of the node row's B rows' length) */
  size_t at = 0;
  for (int R = R0; R < R1; R++) {
    PetscInt *r = in->ia + (size_t)(R - R0) * B, len = r[0];
    for (int a = 0; a < B; a++, at += (size_t)len) r[a] = (PetscInt)at;
  }
  p->rank_w = maxlen <= 256 ? 1 : maxlen <= 65536 ? 2 : 4;
  PetscInt *ja = *jaout = malloc(sizeof(PetscInt) * (nnz ? nnz : 1));
  p->rank = malloc((size_t)p->rank_w * (nrank + 1));
  if (B == 1 && nerow) p->row_start = malloc(sizeof(PetscInt) * (nerow + 1));
  if (!ja || !p->rank || (B == 1 && nerow && !p->row_start)) return 1;
  /* element rows of rows another rank owns: -1, skipped by the scatter */
  if (B == 1 && nerow && p->par) memset(p->row_start, 0xff, sizeof(PetscInt) * (nerow + 1));
  in->ja = ja;
#ifdef _OPENMP
#pragma omp parallel for schedule(static, 1) if (nb > 1)
#endif
  for (int b = 0; b < nb; b++) pattern_fill(in, &blk[b]);
  *nnzout = nnz;
  return 0;
}

/* the pattern's passes over the blocks of node rows. Where no row can have more than 256
 * nodes (its element rows' columns and the diagonal: 1-byte ranks whatever the count), one
 * pass: each block writes its rows into a region of ja sized for that bound, from its start,
 * and the regions are then moved together. Untouched memory costs nothing, and the count
 * pass was a quarter of the pattern's time (P1 on 1.57 M tetrahedra: 41 of 170 ms). Else
 * the count pass first. *nnzout: the entries, *jaout: the column array (returned with 1 on
 * failure too, to free) */
static int pattern_passes(lg_problem *p, pattern_in *in, pattern_block *blk, int nb, size_t nrank, size_t nerow,
                          size_t *nnzout, PetscInt **jaout) {
  int B = in->B, R0 = in->R0, cnmax = 0;
  for (int i = 0; i < p->nterm; i++)
    if (p->t[i].have_mat && p->t[i].cl.size / B > cnmax) cnmax = p->t[i].cl.size / B;
  size_t ubmax = 0, ubtot = 0;
  for (int b = 0; b < nb; b++) {
    blk[b].ja0 = ubtot;
    for (int R = blk[b].R0; R < blk[b].R1; R++) {
      int r = ROW_NODE(in, R);
      size_t ub = 1 + (in->start[r + 1] - in->start[r]) * (size_t)cnmax;
      if (ub > ubmax) ubmax = ub;
      ubtot += ub * (size_t)B * (size_t)B;
    }
  }
  if (ubmax > 256 || ubtot > (size_t)INT32_MAX) return pattern_two_passes(p, in, blk, nb, nrank, nerow, nnzout, jaout);
  p->rank_w = 1;
  PetscInt *ja = *jaout = malloc(sizeof(PetscInt) * (ubtot ? ubtot : 1));
  p->rank = malloc(nrank + 1);
  if (B == 1 && nerow) p->row_start = malloc(sizeof(PetscInt) * (nerow + 1));
  if (!ja || !p->rank || (B == 1 && nerow && !p->row_start)) return 1;
  if (B == 1 && nerow && p->par) memset(p->row_start, 0xff, sizeof(PetscInt) * (nerow + 1));
  in->ja = ja;
  in->one_pass = 1;
#ifdef _OPENMP
#pragma omp parallel for schedule(static, 1) if (nb > 1)
#endif
  for (int b = 0; b < nb; b++) pattern_fill(in, &blk[b]);
  /* the blocks' rows together (a block moves down, never over a later block's rows) */
  size_t at = 0;
  for (int b = 0; b < nb; b++) {
    if (blk[b].bad) return 1;
    size_t shift = blk[b].ja0 - at;
    if (shift) {
      memmove(ja + at, ja + blk[b].ja0, sizeof(PetscInt) * blk[b].nnz);
      for (size_t i = (size_t)(blk[b].R0 - R0) * B; i < (size_t)(blk[b].R1 - R0) * B; i++) in->ia[i] -= (PetscInt)shift;
    }
    at += blk[b].nnz;
  }
  /* the untouched rest of the region back (a shrinking realloc keeps the rows) */
  PetscInt *fit = realloc(ja, sizeof(PetscInt) * (at ? at : 1));
  if (fit) *jaout = fit;
  *nnzout = at;
  return 0;
}

int lg_problem_setup_matrix(lg_env *env, lg_problem *p) {
  double t0 = lg_now_ms();
  PetscCount nentry = 0;
  for (int i = 0; i < p->nterm; i++) {
    prob_term *t = &p->t[i];
    if (t->have_mat) nentry += (PetscCount)t->nitems * t->rl.size * t->cl.size;
  }
  p->ncoo = nentry;
  /* the pattern of nodes: with B components per node everywhere (a vector field, B = bs) the
   * rows and columns come in blocks of B, and the pattern is that of the node graph, each
   * entry a B x B block (9x less work for 3D elasticity, whose rows hold about 250 entries);
   * B = 1 otherwise. Each element entry (node pair) keeps its column node's rank in its row
   * node's row: 1 byte where rows have at most 256 nodes (4 bytes per entry before), and for
   * B = 1 each element row its row's start (P1 on 1.57 M tetrahedra: 50 MB instead of 102) */
  /* node arrays are indexed by PETSc's node numbers, or on a distributed mesh by its local
   * nodes' (no array of the whole problem's size on any rank) */
  int B = lg_matrix_block_size(p), local = p->lm->dist != NULL, Nn = (local ? p->N : p->Nglob) / B;
  elem_rows E;
  int bad = element_rows(p, B, local, Nn, &E);
  size_t nrank = 0, nerow = 0;
  for (int i = 0; i < p->nterm && !bad; i++) {
    prob_term *t = &p->t[i];
    if (!t->have_mat) continue;
    t->rank_off = nrank;
    t->erow_first = nerow;
    nrank += (size_t)t->nitems * (size_t)(t->rl.size / B) * (size_t)(t->cl.size / B);
    /* a serial run's rows are its dofs: where the row list is the dof map's own, it is the
     * rows' numbers too */
    t->rows_shared = B == 1 && !p->par && !E.rown[i];
    if (!t->rows_shared) nerow += (size_t)t->nitems * (size_t)t->rl.size;
  }
  int *mark = malloc(sizeof(int) * ((size_t)Nn + 1));
  PetscInt *nodes = malloc(sizeof(PetscInt) * ((size_t)Nn + 1)); /* one node row */
  if (!bad && (!mark || !nodes)) bad = 1;
  /* each node row: the union of its element rows' column nodes (a marker per node, no
   * global sort), sorted, the diagonal always; its B rows are laid out one after another,
   * each the row's nodes times B columns, every column and element rank written once at its
   * place (no growing array: on the virtual machines this runs on, every new page of memory
   * is expensive): in one pass into regions of a bound's size, or after a count pass
   * (pattern_passes) */
  /* the owned rows only (all of them in a serial run): node rows R0 .. R1 - 1 */
  int n = p->hi - p->lo, R0 = p->lo / B, R1 = p->hi / B;
  PetscInt *ia = malloc(sizeof(PetscInt) * ((size_t)n + 1)), *ja = NULL;
  size_t nnz = 0;
  if (!ia) bad = 1;
  /* the rows in contiguous blocks, one per OpenMP thread (balanced by element rows), each
   * with its own marker. The same pattern and ranks for any thread count */
  size_t nown = 0;
  pattern_in in = {p, B, Nn, R0, local ? p->perm : NULL, local ? p->iperm : NULL, E.start, E.erow_off, E.erow, E.rnod, E.cnod, ia, NULL, 0};
  for (int R = R0; !bad && R < R1; R++) nown += E.start[ROW_NODE(&in, R) + 1] - E.start[ROW_NODE(&in, R)];
  int nb = 1;
#ifdef _OPENMP
  /* threads for the idle cores: the blocks are static, and a block whose thread waits for a
   * busy core holds up the pass */
  if (nown > 200000) nb = lg_threads_for_load(omp_get_max_threads());
  if (nb > 64) nb = 64;
#endif
  p->pattern_threads = nb;
  pattern_block blk[64];
  memset(blk, 0, sizeof blk);
  size_t acc = 0; /* element rows of the rows before R */
  for (int b = 0, R = R0; b < nb; b++) {
    blk[b].R0 = R;
    size_t goal = nown / (size_t)nb * (size_t)(b + 1);
    while (R < R1 && (b == nb - 1 || acc < goal)) { acc += E.start[ROW_NODE(&in, R) + 1] - E.start[ROW_NODE(&in, R)]; R++; }
    blk[b].R1 = b == nb - 1 ? R1 : R;
  }
  blk[0].mark = mark;
  blk[0].nodes = nodes;
  if (!bad) bad = pattern_passes(p, &in, blk, nb, nrank, nerow, &nnz, &ja);
  for (int i = 0; i < p->nterm && !bad; i++)
    if (p->t[i].have_mat && B == 1) p->t[i].rows = p->t[i].rows_shared ? E.rnod[i] : p->row_start + p->t[i].erow_first;
  for (int b = 1; b < nb; b++) { free(blk[b].mark); free(blk[b].nodes); }
  elem_rows_free(p, &E);
  free(nodes);
  free(mark);
  if (bad) {
    free(ia); free(ja);
    if (bad == 3) lg_seterr(env, "the matrix has more than 2^31 nonzeros: more than lugal indexes");
    else if (bad == 2) lg_seterr(env, "more than 2^32 items in the matrix terms: more than lugal indexes");
    else lg_seterr(env, "out of memory for the sparsity pattern (%ld element matrix entries)", (long)nentry);
    return 1;
  }
  double t1 = lg_now_ms();
  p->setup_ms[0] = t1 - t0;
  if (create_matrix(env, p, n, nnz, ia, ja)) return 1;
  p->setup_ms[1] = lg_now_ms() - t1;
  return 0;
}

int lg_problem_split_open(lg_env *env, lg_problem *p, PetscScalar **da, PetscScalar **oa) {
  Mat Ad, Ao;
  const PetscInt *garray;
  PCHK(MatMPIAIJGetSeqAIJ(p->A, &Ad, &Ao, &garray), "MatMPIAIJGetSeqAIJ");
  PCHK(MatSeqAIJGetArray(Ad, da), "MatSeqAIJGetArray");
  PCHK(MatSeqAIJGetArray(Ao, oa), "MatSeqAIJGetArray");
  int n = p->hi - p->lo;
  memset(*da, 0, sizeof(PetscScalar) * (size_t)p->sd_i[n]);
  memset(*oa, 0, sizeof(PetscScalar) * (size_t)p->so_i[n]);
  return 0;
}

int lg_problem_split_close(lg_env *env, lg_problem *p, PetscScalar *da, PetscScalar *oa, int assembled) {
  Mat Ad, Ao;
  const PetscInt *garray;
  PCHK(MatMPIAIJGetSeqAIJ(p->A, &Ad, &Ao, &garray), "MatMPIAIJGetSeqAIJ");
  PCHK(MatSeqAIJRestoreArray(Ao, &oa), "MatSeqAIJRestoreArray");
  PCHK(MatSeqAIJRestoreArray(Ad, &da), "MatSeqAIJRestoreArray");
  if (!assembled) return 0;
  /* the matrix's state moves on, so that solvers refactor or set up again */
  PCHK(MatAssemblyBegin(p->A, MAT_FINAL_ASSEMBLY), "MatAssemblyBegin");
  PCHK(MatAssemblyEnd(p->A, MAT_FINAL_ASSEMBLY), "MatAssemblyEnd");
  return 0;
}

/* nullspace=: the constants of some unknowns (one unit vector per component), or the rigid
 * body modes; attached to the matrix (MatSetNullSpace) for Krylov solvers, and the count
 * that MUMPS's null pivots may reach */
int lg_problem_setup_nullspace(lg_env *env, lg_problem *p, const lg_problem_spec *s) {
  if (!s->nnull && !s->null_rigid) return 0;
  int dim = p->lm->m->dim;
  MatNullSpace ns = NULL;
  PetscErrorCode ierr = 0;
  if (s->null_rigid) {
    if (p->cols.n != 1 || p->cdm[0]->bs != dim || dim < 2 || p->cdm[0]->degree < 1) {
      lg_seterr(env, "nullspace = \"rigid\": the rigid body modes need a single vector unknown of the mesh's dimension (%d "
                     "components)", dim);
      return 1;
    }
    for (int i = 0; i < p->nbct; i++) {
      lg_seterr(env, "nullspace = \"rigid\": the problem has essential conditions, which already fix the rigid motions");
      return 1;
    }
    if (rigid_modes(env, p, &ns)) return 1;
    p->modes_geometry = p->lm->geometry;
    p->nnull = dim == 2 ? 3 : 6;
    p->null_rigid = 1;
  } else {
    Vec v[KER_MAXFIELD * FEM_MAXBS] = {0};
    int nv = 0;
    for (int k = 0; k < s->nnull; k++) {
      int a = -1;
      for (int j = 0; j < p->cols.n; j++)
        if (p->cols.func[j] == s->null_fields[k]) a = j;
      expr_func_info *fi = expr_func_get(env->c, s->null_fields[k]);
      if (a < 0) {
        lg_seterr(env, "nullspace: %s is not an unknown of the problem", fi ? fi->name : "?");
        for (int i = 0; i < nv; i++) VecDestroy(&v[i]);
        return 1;
      }
      for (int i = 0; i < p->nbct; i++)
        if (p->bct[i].field == a) {
          lg_seterr(env, "nullspace: %s has essential conditions, which fix its constant already", fi ? fi->name : "?");
          for (int t = 0; t < nv; t++) VecDestroy(&v[t]);
          return 1;
        }
      p->null_const[a] = 1;
      int bs = p->cdm[a]->bs;
      for (int j = 0; j < bs && !ierr; j++) {
        ierr = MatCreateVecs(p->A, &v[nv], NULL);
        PetscScalar *x;
        if (!ierr) ierr = VecSet(v[nv], 0);
        if (!ierr) ierr = VecGetArray(v[nv], &x);
        if (ierr) break;
        for (int i = j; i < p->cdm[a]->ndof; i += bs) {
          PetscInt r = lg_petsc_row(p, p->cglob[a] + i);
          if (r >= p->lo && r < p->hi) x[r - p->lo] = 1;
        }
        VecRestoreArray(v[nv], &x);
        ierr = VecNormalize(v[nv], NULL);
        nv++;
      }
    }
    if (!ierr) ierr = MatNullSpaceCreate(PetscObjectComm((PetscObject)p->A), PETSC_FALSE, nv, v, &ns);
    for (int i = 0; i < nv; i++) VecDestroy(&v[i]);
    p->nnull = nv;
  }
  if (!ierr) ierr = MatSetNullSpace(p->A, ns);
  p->null = ns;
  if (ierr) return lg_petsc_fail(env, ierr, "the null space");
  return 0;
}

