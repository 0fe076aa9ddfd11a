/* sparsity.c — a problem's matrix: the pattern straight from the dof maps (node-level for
 * vector fields), each element entry's place in the CSR value array, the block size, the
 * rigid body modes as GAMG's near null space, and the null spaces given with nullspace=.
 * The problem's state is problem_int.h's; problem.c assembles into what this builds. */
#include "problem_int.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/* the global nodes of item it of term t for the rows (or the columns) of its element
 * matrix, in its order: with B components per node (every field a B-vector) the dof / B of
 * every B-th local dof, with B = 1 the global dofs. An interior facet term's second half of
 * fields are the problem's fields again, on the '-' cell */
void lg_term_nodes(const lg_problem *p, const prob_term *t, int it, int rows, int B, PetscInt *out) {
  const field_layout *l = rows ? &t->rl : &t->cl;
  dofmap *const *dm = rows ? p->rdm : p->cdm;
  const int *glob = rows ? p->rglob : p->cglob;
  int nf = rows ? p->rows.n : p->cols.n;
  for (int a = 0; a < l->n; a++) {
    int f = a % nf, c = t->interior && a >= nf ? t->cells[t->nitems + it] : t->cells[it];
    const int nl = l->nloc[a], *cd = dm[f]->cell_dofs + (size_t)c * nl;
    PetscInt *o = out + l->off[a] / B, g = glob[f];
    for (int k = 0, i = 0; k < nl; k += B, i++) o[i] = (g + cd[k]) / B;
  }
}

/* rows are short (tens of entries): insertion sort */
static void sort_row(PetscInt *v, size_t n) {
  for (size_t i = 1; i < n; i++) {
    PetscInt x = v[i];
    size_t j = i;
    for (; j > 0 && v[j - 1] > x; j--) v[j] = v[j - 1];
    v[j] = x;
  }
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

/* a single vector field of the mesh's dimension (elasticity): the rigid body modes as the
 * near null space, which PETSc's GAMG needs to coarsen it well (it is ignored by direct
 * solvers and unpreconditioned Krylov methods) */
/* the node coordinates of a single vector field of the mesh's dimension, interlaced like
 * its dofs (what MatNullSpaceCreateRigidBody takes) */
static int node_coordinates(lg_env *env, lg_problem *p, Vec *out) {
  int dim = p->lm->m->dim;
  const dofmap *dm = p->cdm[0];
  Vec X;
  PCHK(VecCreateSeq(PETSC_COMM_SELF, p->N, &X), "VecCreateSeq");
  PCHK(VecSetBlockSize(X, dim), "VecSetBlockSize");
  PetscScalar *x;
  PCHK(VecGetArray(X, &x), "VecGetArray");
  mesh *m = p->lm->m;
  for (int c = 0; c < m->ncell; c++) {
    const int *cd = dm->cell_dofs + (size_t)c * (size_t)dm->nloc;
    for (int k = 0; k < dm->el.nloc; k++) {
      double xyz[3];
      dofmap_node_coords(dm, c, k * dim, xyz);
      for (int j = 0; j < dim; j++) x[cd[k * dim + j]] = xyz[j];
    }
  }
  PCHK(VecRestoreArray(X, &x), "VecRestoreArray");
  *out = X;
  return 0;
}

static int set_near_nullspace(lg_env *env, lg_problem *p) {
  int dim = p->lm->m->dim;
  if (p->cols.n != 1 || p->rows.n != 1 || lg_matrix_block_size(p) != dim || dim < 2 || p->cdm[0]->degree < 1) return 0;
  Vec X;
  if (node_coordinates(env, p, &X)) return 1;
  MatNullSpace ns;
  PetscErrorCode ierr = MatNullSpaceCreateRigidBody(X, &ns);
  if (!ierr) ierr = MatSetNearNullSpace(p->A, ns);
  if (!ierr) ierr = MatNullSpaceDestroy(&ns);
  VecDestroy(&X);
  if (ierr) return lg_petsc_fail(env, ierr, "the rigid body modes (near null space)");
  return 0;
}

int lg_problem_setup_matrix(lg_env *env, lg_problem *p) {
  int N = p->N;
  PetscCount n = N;
  size_t maxsize = 1;
  for (int i = 0; i < p->nterm; i++) {
    prob_term *t = &p->t[i];
    if (!t->have_mat) continue;
    t->coo_off = n;
    n += (PetscCount)t->nitems * t->rl.size * t->cl.size;
    if ((size_t)t->rl.size * (size_t)t->cl.size > maxsize) maxsize = (size_t)t->rl.size * (size_t)t->cl.size;
  }
  p->ncoo = n;
  /* the pattern of nodes: with B components per node everywhere (a vector field, B = bs) the
   * rows and columns come in blocks of B, and the pattern is that of the node graph, each
   * entry a B x B block (9x less work for 3D elasticity, whose rows hold about 250 entries);
   * B = 1 otherwise */
  int B = lg_matrix_block_size(p), Nn = N / B;
  size_t nblk = 0, nstr = 0;
  for (int i = 0; B > 1 && i < p->nterm; i++) {
    prob_term *t = &p->t[i];
    if (!t->have_mat) continue;
    t->blk_off = nblk;
    t->str_off = nstr;
    nblk += (size_t)t->nitems * (size_t)(t->rl.size / B) * (size_t)(t->cl.size / B);
    nstr += (size_t)t->nitems * (size_t)(t->rl.size / B);
  }
  /* the element rows of each node row: (entry of the row's first column, term, item) */
  PetscInt rg[2 * KER_MAXFIELD * FEM_MAXLOC * FEM_MAXBS];
  size_t *start = calloc((size_t)Nn + 2, sizeof(size_t));
  int *mark = malloc(sizeof(int) * ((size_t)Nn + 1));
  PetscInt *nodes = malloc(sizeof(PetscInt) * ((size_t)Nn + 1)); /* one node row */
  if (!start || !mark || !nodes) { free(start); free(mark); free(nodes); lg_seterr(env, "out of memory"); return 1; }
  for (int i = 0; i < p->nterm; i++) {
    prob_term *t = &p->t[i];
    if (!t->have_mat) continue;
    int rn = t->rl.size / B;
    for (int it = 0; it < t->nitems; it++) {
      lg_term_nodes(p, t, it, 1, B, rg);
      for (int r = 0; r < rn; r++) start[rg[r] + 2]++;
    }
  }
  for (int r = 0; r < Nn; r++) start[r + 2] += start[r + 1];
  size_t nent = start[Nn + 1];
  PetscCount *ebase = malloc(sizeof(PetscCount) * (nent + 1));
  int *eterm = malloc(sizeof(int) * (nent + 1)), *eitem = malloc(sizeof(int) * (nent + 1));
  size_t *estr = B > 1 ? malloc(sizeof(size_t) * (nent + 1)) : NULL;
  if (!ebase || !eterm || !eitem || (B > 1 && !estr)) {
    free(start); free(mark); free(nodes); free(ebase); free(eterm); free(eitem); free(estr);
    lg_seterr(env, "out of memory");
    return 1;
  }
  for (int i = 0; i < p->nterm; i++) {
    prob_term *t = &p->t[i];
    if (!t->have_mat) continue;
    int rn = t->rl.size / B, cn = t->cl.size / B;
    for (int it = 0; it < t->nitems; it++) {
      lg_term_nodes(p, t, it, 1, B, rg);
      for (int r = 0; r < rn; r++) {
        size_t q = start[rg[r] + 1]++;
        if (B > 1) {
          ebase[q] = (PetscCount)(t->blk_off + ((size_t)it * rn + (size_t)r) * (size_t)cn);
          estr[q] = t->str_off + (size_t)it * rn + (size_t)r;
        } else ebase[q] = t->coo_off + ((PetscCount)it * rn + r) * cn;
        eterm[q] = i;
        eitem[q] = it;
      }
    }
  }
  /* each node row: the union of its element rows' column nodes (a marker per node, no
   * global sort), sorted, the diagonal always; its B rows are laid out one after another,
   * each the row's nodes times B columns. Then every element entry's place, read from the
   * marker (it holds the column node's position in the row: no search) */
  PetscInt *ia = malloc(sizeof(PetscInt) * ((size_t)N + 1)), *ja = NULL;
  size_t nnz = 0, cap = (size_t)N * 8 + 16;
  ja = malloc(sizeof(PetscInt) * cap);
  if (B > 1) {
    p->blk_pos = malloc(sizeof(int) * (nblk + 1));
    p->blk_stride = malloc(sizeof(int) * (nstr + 1));
  } else p->coo_pos = malloc(sizeof(int) * ((size_t)n + 1));
  p->mbuf = malloc(sizeof(double) * ((size_t)LG_CHUNK * maxsize + 1));
  if (!ia || !ja || (B > 1 ? !p->blk_pos || !p->blk_stride : !p->coo_pos) || !p->mbuf) {
    free(start); free(mark); free(nodes); free(ebase); free(eterm); free(eitem); free(estr); free(ia); free(ja);
    lg_seterr(env, "out of memory for %ld matrix entries", (long)n);
    return 1;
  }
  for (int r = 0; r < Nn; r++) mark[r] = -1;
  int bad = 0;
  /* the column nodes of the row's elements, gathered once for the union and the places */
  size_t bcap = 0, ocap = 0, *eoff = NULL;
  PetscInt *ebuf = NULL;
  for (int R = 0; R < Nn && !bad; R++) {
    size_t ne = start[R + 1] - start[R], tot = 0;
    if (ne + 1 > ocap) {
      ocap = 2 * (ne + 1);
      size_t *no = realloc(eoff, sizeof(size_t) * ocap);
      if (!no) { bad = 1; break; }
      eoff = no;
    }
    for (size_t q = 0; q < ne; q++) {
      eoff[q] = tot;
      tot += (size_t)(p->t[eterm[start[R] + q]].cl.size / B);
    }
    eoff[ne] = tot;
    if (tot > bcap) {
      bcap = 2 * tot;
      PetscInt *nb = realloc(ebuf, sizeof(PetscInt) * bcap);
      if (!nb) { bad = 1; break; }
      ebuf = nb;
    }
    for (size_t q = 0; q < ne; q++) lg_term_nodes(p, &p->t[eterm[start[R] + q]], eitem[start[R] + q], 0, B, ebuf + eoff[q]);
    /* the row's nodes */
    size_t len = 0;
    nodes[len++] = R;
    mark[R] = R;
    for (size_t k = 0; k < tot; k++) {
      PetscInt J = ebuf[k];
      if (mark[J] != R) { mark[J] = R; nodes[len++] = J; }
    }
    sort_row(nodes, len);
    size_t need = nnz + len * (size_t)B * (size_t)B;
    if (need > (size_t)INT32_MAX) { bad = 2; break; }
    if (need > cap) {
      while (cap < need) cap *= 2;
      PetscInt *nj = realloc(ja, sizeof(PetscInt) * cap);
      if (!nj) { bad = 1; break; }
      ja = nj;
    }
    for (int a = 0; a < B; a++) {
      ia[R * B + a] = (PetscInt)nnz;
      for (size_t k = 0; k < len; k++)
        for (int b2 = 0; b2 < B; b2++) ja[nnz++] = nodes[k] * B + b2;
    }
    /* the marker now holds positions (>= Nn would clash with row numbers: use -2 - position) */
    for (size_t k = 0; k < len; k++) mark[nodes[k]] = -2 - (int)k;
    int base = (int)ia[R * B];
    if (B == 1) p->coo_pos[R] = base + (-2 - mark[R]);
    for (size_t q = 0; q < ne; q++) {
      const PetscInt *en = ebuf + eoff[q];
      int cn = (int)(eoff[q + 1] - eoff[q]);
      size_t e = start[R] + q;
      if (B > 1) {
        /* one place per B x B block (its first entry) and the row length, the stride */
        int *bp = p->blk_pos + ebase[e];
        for (int k = 0; k < cn; k++) bp[k] = base + (-2 - mark[en[k]]) * B;
        p->blk_stride[estr[e]] = (int)(len * (size_t)B);
      } else {
        int *pos = p->coo_pos + ebase[e];
        for (int k = 0; k < cn; k++) pos[k] = base + (-2 - mark[en[k]]);
      }
    }
    /* back to "not in row R" for the columns of the next rows */
    for (size_t k = 0; k < len; k++) mark[nodes[k]] = R;
  }
  free(ebuf);
  free(eoff);
  free(nodes);
  free(estr);
  free(start);
  free(mark);
  free(ebase);
  free(eterm);
  free(eitem);
  if (bad) {
    free(ia); free(ja);
    if (bad == 2) lg_seterr(env, "the matrix has more than 2^31 nonzeros: more than lugal indexes");
    else lg_seterr(env, "out of memory for the sparsity pattern");
    return 1;
  }
  ia[N] = (PetscInt)nnz;
  p->nnz = (PetscInt)nnz;
  /* the matrix is made on these arrays, not a copy of them: PETSc's own preallocation from a
   * CSR pattern inserts every entry through MatSetValues (a third of the setup of a vector
   * P2 matrix) and holds a second pattern while ours is alive. The values start as zero
   * pages, touched first by the first assembly */
  PetscInt *jt = realloc(ja, sizeof(PetscInt) * (nnz ? nnz : 1));
  if (jt) ja = jt;
  p->csr_i = ia;
  p->csr_j = ja;
  p->csr_a = calloc(nnz ? nnz : 1, sizeof(PetscScalar));
  if (!p->csr_a) { lg_seterr(env, "out of memory for %ld matrix values", (long)nnz); return 1; }
  int bs = lg_matrix_block_size(p);
  PCHK(MatCreateSeqAIJWithArrays(PETSC_COMM_SELF, N, N, ia, ja, p->csr_a, &p->A), "matrix creation");
  if (p->prefix[0]) PCHK(MatSetOptionsPrefix(p->A, p->prefix), "MatSetOptionsPrefix");
  if (bs > 1) PCHK(MatSetBlockSize(p->A, bs), "MatSetBlockSize");
  /* row replacement must keep the pattern: the element places are reused every assembly */
  PCHK(MatSetOption(p->A, MAT_KEEP_NONZERO_PATTERN, PETSC_TRUE), "MatSetOption");
  PCHK(MatSetOption(p->A, MAT_NEW_NONZERO_LOCATION_ERR, PETSC_TRUE), "MatSetOption");
  PCHK(MatCreateVecs(p->A, &p->x, &p->b), "vector creation");
  return set_near_nullspace(env, p);
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
    Vec X;
    if (node_coordinates(env, p, &X)) return 1;
    ierr = MatNullSpaceCreateRigidBody(X, &ns);
    VecDestroy(&X);
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
        ierr = VecCreateSeq(PETSC_COMM_SELF, p->N, &v[nv]);
        PetscScalar *x;
        if (!ierr) ierr = VecSet(v[nv], 0);
        if (!ierr) ierr = VecGetArray(v[nv], &x);
        if (ierr) break;
        for (int i = j; i < p->cdm[a]->ndof; i += bs) x[p->cglob[a] + i] = 1;
        VecRestoreArray(v[nv], &x);
        ierr = VecNormalize(v[nv], NULL);
        nv++;
      }
    }
    if (!ierr) ierr = MatNullSpaceCreate(PETSC_COMM_SELF, PETSC_FALSE, nv, v, &ns);
    for (int i = 0; i < nv; i++) VecDestroy(&v[i]);
    p->nnull = nv;
  }
  if (!ierr) ierr = MatSetNullSpace(p->A, ns);
  p->null = ns;
  if (ierr) return lg_petsc_fail(env, ierr, "the null space");
  return 0;
}

