/* distributed.c — the assembly core's meshes on the ranks of a run: an lg_mesh over a
 * rank's part (lg_mesh_distribute, lg_mesh_generate_part, lg_mesh_read_parts wrap what
 * src/assemble/parallel cuts, generates or reads), the partition of a whole mesh kept with
 * it (lg_mesh_partition), a dof map's dofs as one distributed vector (owners, ghost values,
 * sums over owned dofs), and discrete functions gathered in the whole mesh's order and
 * assigned from it. */
#include "assemble.h"
#include "parallel/parallel.h"

#include <mpi.h>
#include <petscvec.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---------------------------------------------------------------- meshes over parts */

lg_mesh *lg_mesh_wrap_part(mesh_part *P) {
  lg_mesh *lm = lg_mesh_wrap(P->m);
  if (lm) lm->dist = P;
  return lm;
}

long lg_mesh_global_cells(const lg_mesh *lm) { return lm->dist ? lm->dist->ncell_global : lm->m->ncell; }
long lg_mesh_global_vertices(const lg_mesh *lm) { return lm->dist ? lm->dist->nvert_global : lm->m->nvert; }

/* the part P (every rank's, or NULL on every rank) as an lg_mesh on every rank, or NULL
 * on every rank where any failed; collective where P is not NULL */
static lg_mesh *adopt(lg_env *env, mesh_part *P) {
  if (!P) return NULL;
  lg_mesh *lm = lg_mesh_wrap_part(P);
  char err[LG_ERRLEN] = "out of memory";
  if (!lg_any_result(!lm, err, sizeof err)) return lm;
  lg_seterr(env, "%s", err);
  if (lm) lg_mesh_free(lm);
  else mesh_part_free(P);
  return NULL;
}

lg_mesh *lg_mesh_distribute(lg_env *env, mesh *whole) { return adopt(env, lg_part_distribute(env, whole)); }

lg_mesh *lg_mesh_generate_part(lg_env *env, const mesh_box_opts *o, int *whole) {
  mesh_part *P = lg_part_generate(env, o, whole);
  return adopt(env, P);
}

lg_mesh *lg_mesh_read_parts(lg_env *env, const char *path) { return adopt(env, lg_part_read(env, path)); }

int lg_mesh_partition(lg_env *env, lg_mesh *lm, int nparts, const int **part) {
  *part = NULL;
  if (lm->nparts == nparts) { *part = lm->part; return 0; }
  mesh *m = lm->m;
  int *pt = malloc(sizeof(int) * ((size_t)m->ncell + 1)), runs = 0;
  if (!pt) { lg_seterr(env, "out of memory for the partition of %d cells", m->ncell); return 1; }
  /* rank 0 partitions, every rank gets its outcome and the parts (a numbering's split is
   * everyone's own: it reads the mesh only) */
  int verbose = env->verbose;
  env->verbose = verbose && lg_mpi_rank() == 0;
  int rc = lg_mpi_rank() == 0 ? lg_partition_cells(env, m, nparts, pt, &runs) : 0;
  env->verbose = verbose;
  int keep = rc == -1;
  if (keep) rc = 0;
  if (lg_mpi_size() > 1) {
    int st[3] = {rc, keep, runs};
    if (MPI_Bcast(st, 3, MPI_INT, 0, PETSC_COMM_WORLD) != MPI_SUCCESS) st[0] = 1;
    rc = lg_root_result(st[0], env->err, sizeof env->err);
    keep = st[1];
    runs = st[2];
    if (!rc && !keep && MPI_Bcast(pt, m->ncell, MPI_INT, 0, PETSC_COMM_WORLD) != MPI_SUCCESS) {
      lg_seterr(env, "the partition could not be sent to every rank");
      rc = 1;
    }
  }
  if (rc || keep) { free(pt); return rc; }
  free(lm->part);
  lm->part = pt;
  lm->nparts = nparts;
  lm->part_runs = runs;
  *part = pt;
  return 0;
}

/* ---------------------------------------------------------------- discrete functions */

/* the owner of each node of dm (owner[nn]): the part of most of its cells, as a problem's
 * nodes */
static int dof_owners(const lg_mesh *lm, const dofmap *dm, int *owner) {
  const mesh_part *P = lm->dist;
  int bs = dm->bs, nn = dm->ndof / bs;
  int *cnt = calloc((size_t)nn + 1, sizeof(int));
  if (!cnt) return 1;
  for (int i = 0; i < nn; i++) owner[i] = -1; /* a tie leaves the count at 0, not the owner */
  for (int c = 0; c < P->m->ncell; c++)
    for (int k = 0; k < dm->nloc; k += bs) {
      int node = dm->cell_dofs[(size_t)c * (size_t)dm->nloc + (size_t)k] / bs;
      lg_vote(owner, cnt, node, P->cowner[c]);
    }
  free(cnt);
  return 0;
}

/* the dofs of dm this rank owns (own[d] = 1) */
static int owned_dofs(const lg_mesh *lm, const dofmap *dm, char *own) {
  int rank = lg_mpi_rank(), bs = dm->bs, nn = dm->ndof / bs;
  int *owner = malloc(sizeof(int) * ((size_t)nn + 1));
  if (!owner || dof_owners(lm, dm, owner)) { free(owner); return 1; }
  for (int d = 0; d < dm->ndof; d++) own[d] = owner[d / bs] == rank;
  free(owner);
  return 0;
}

/* ---------------------------------------------------------------- a dof map's layout */

/* a dof map's dofs on a distributed mesh as a distributed vector: each rank's owned dofs
 * (in its local order, after the lower ranks'), and the scatter that brings every local
 * dof, owned or ghost, its owner's value. Built on first use, kept with the mesh */
struct lg_dist_dofs {
  const dofmap *dm;
  const mesh_part *P;
  int nown;   /* owned dofs */
  char *own;  /* per local dof */
  Vec g, l;   /* the owned dofs (all ranks': the global vector), the local ones */
  VecScatter sc;
  struct lg_dist_dofs *next;
};

void lg_dist_dofs_free(lg_dist_dofs *D) {
  while (D) {
    lg_dist_dofs *n = D->next;
    free(D->own);
    if (D->sc) VecScatterDestroy(&D->sc);
    if (D->g) VecDestroy(&D->g);
    if (D->l) VecDestroy(&D->l);
    free(D);
    D = n;
  }
}

static void dm_node_key(const void *ctx, int n, int *key) {
  const lg_dist_dofs *D = ctx;
  lg_dof_key(D->P, D->dm, n * D->dm->bs, key);
}

static lg_dist_dofs *dist_dofs(lg_env *env, lg_mesh *lm, const dofmap *dm) {
  for (lg_dist_dofs *D = lm->ddofs; D; D = D->next)
    if (D->dm == dm) return D;
  const mesh_part *P = lm->dist;
  int rank = lg_mpi_rank(), bs = dm->bs, nn = dm->ndof / bs;
  lg_dist_dofs *D = calloc(1, sizeof *D);
  int *owner = malloc(sizeof(int) * ((size_t)nn + 1)), *perm = malloc(sizeof(int) * ((size_t)nn + 1));
  char *shared = calloc((size_t)nn + 1, 1), *ivert = lg_other_vertices(P);
  int bad = !D || !owner || !perm || !shared || !ivert || dof_owners(lm, dm, owner);
  if (D) {
    D->dm = dm;
    D->P = P;
    bad |= !(D->own = malloc((size_t)dm->ndof + 1));
  }
  if (!bad) lg_mark_shared(P, ivert, dm, 0, bs, shared);
  free(ivert);
  int first = 0, nown = 0, total = 0;
  int rc = lg_rendezvous_number(bad, nn, owner, shared, dm_node_key, D, perm, &first, &nown, &total);
  free(shared);
  PetscInt *idx = rc ? NULL : malloc(sizeof(PetscInt) * ((size_t)dm->ndof + 1));
  IS is = NULL;
  PetscErrorCode ierr = !idx;
  if (!ierr) {
    for (int d = 0; d < dm->ndof; d++) {
      D->own[d] = owner[d / bs] == rank;
      idx[d] = (PetscInt)perm[d / bs] * bs + d % bs;
    }
    D->nown = nown * bs;
    ierr = VecCreateMPI(PETSC_COMM_WORLD, D->nown, PETSC_DETERMINE, &D->g) ||
           VecCreateSeq(PETSC_COMM_SELF, dm->ndof, &D->l) ||
           ISCreateGeneral(PETSC_COMM_SELF, dm->ndof, idx, PETSC_COPY_VALUES, &is) ||
           VecScatterCreate(D->g, is, D->l, NULL, &D->sc);
  }
  if (is) ISDestroy(&is);
  free(idx);
  free(owner);
  free(perm);
  if (rc || ierr) {
    lg_dist_dofs_free(D);
    lg_seterr(env, rc == 2 ? "the global numbering of a distributed function's dofs failed: a ghost dof without an owner"
                           : "out of memory numbering the dofs of a distributed function");
    return NULL;
  }
  D->next = lm->ddofs;
  lm->ddofs = D;
  return D;
}

const char *lg_dist_owned(lg_env *env, lg_mesh *lm, const dofmap *dm, int *nown) {
  lg_dist_dofs *D = dist_dofs(env, lm, dm);
  if (!D) return NULL;
  if (nown) *nown = D->nown;
  return D->own;
}

int lg_dist_ghosts(lg_env *env, lg_mesh *lm, const dofmap *dm, double *x) {
  lg_dist_dofs *D = dist_dofs(env, lm, dm);
  if (!D) return 1;
  PetscScalar *a;
  PCHK(VecGetArray(D->g, &a), "VecGetArray");
  for (int d = 0, k = 0; d < dm->ndof; d++)
    if (D->own[d]) a[k++] = x[d];
  PCHK(VecRestoreArray(D->g, &a), "VecRestoreArray");
  PCHK(VecScatterBegin(D->sc, D->g, D->l, INSERT_VALUES, SCATTER_FORWARD), "VecScatterBegin");
  PCHK(VecScatterEnd(D->sc, D->g, D->l, INSERT_VALUES, SCATTER_FORWARD), "VecScatterEnd");
  const PetscScalar *b;
  PCHK(VecGetArrayRead(D->l, &b), "VecGetArrayRead");
  if (dm->ndof) memcpy(x, b, sizeof(double) * (size_t)dm->ndof);
  PCHK(VecRestoreArrayRead(D->l, &b), "VecRestoreArrayRead");
  return 0;
}

double lg_dist_dot(const char *own, int n, const double *a, const double *b) {
  double s = 0;
  for (int d = 0; d < n; d++)
    if (own[d]) s += a[d] * b[d];
  return s;
}

long lg_function_global_ndof(lg_env *env, const lg_function *f) {
  const dofmap *dm = f->dm;
  if (!f->mesh->dist) return dm->ndof;
  char *own = malloc((size_t)dm->ndof + 1);
  int bad = !own || owned_dofs(f->mesh, dm, own);
  double n = 0;
  for (int d = 0; !bad && d < dm->ndof; d++) n += own[d];
  double v[2] = {n, bad};
  free(own);
  if (lg_allreduce(v, 2, LG_SUM) || v[1]) { lg_seterr(env, "counting the dofs of a distributed function failed"); return -1; }
  return (long)v[0];
}

/* two records in the whole function's order */
int lg_dof_rec_cmp(const void *a, const void *b) {
  const int *x = ((const lg_dof_rec *)a)->k, *y = ((const lg_dof_rec *)b)->k;
  for (int i = 0; i < 7; i++)
    if (x[i] != y[i]) return x[i] < y[i] ? -1 : 1;
  return 0;
}

/* dof d's place in the whole function's order */
void lg_dof_rec_key(const mesh_part *P, const dofmap *dm, int d, lg_dof_rec *r) {
  int key[LG_KEYLEN];
  lg_dof_key(P, dm, d, key);
  r->k[0] = key[2];
  memcpy(r->k + 1, key + 4, sizeof(int) * 4);
  r->k[5] = key[3];
  r->k[6] = key[1];
}

/* every rank's owned dofs of f with their values (coords = 0) or node coordinates, on
 * every rank, sorted into the whole function's order */
int lg_function_records(lg_env *env, const lg_function *f, int coords, lg_dof_rec **out, long *n) {
  const dofmap *dm = f->dm;
  const mesh *m = dm->m;
  int size = lg_mpi_size(), dim = m->dim;
  *out = NULL;
  *n = 0;
  char *own = malloc((size_t)dm->ndof + 1);
  double *xc = coords ? malloc(sizeof(double) * 3 * ((size_t)dm->ndof + 1)) : NULL;
  int bad = !own || (coords && !xc) || owned_dofs(f->mesh, dm, own), nown = 0;
  for (int d = 0; !bad && d < dm->ndof; d++) nown += own[d];
  if (!bad && coords) /* each dof's node coordinates, from its first cell */
    for (int c = 0; c < m->ncell; c++)
      for (int k = 0; k < dm->nloc; k++) dofmap_node_coords(dm, c, k, xc + 3 * (size_t)dm->cell_dofs[(size_t)c * (size_t)dm->nloc + (size_t)k]);
  lg_dof_rec *mine = malloc(sizeof(lg_dof_rec) * ((size_t)nown + 1));
  bad |= !mine;
  for (int d = 0, i = 0; !bad && d < dm->ndof; d++) {
    if (!own[d]) continue;
    lg_dof_rec *r = mine + i++;
    lg_dof_rec_key(f->mesh->dist, dm, d, r);
    memset(r->v, 0, sizeof r->v);
    if (coords) memcpy(r->v, xc + 3 * (size_t)d, sizeof(double) * (size_t)dim);
    else r->v[0] = f->x[d];
  }
  free(own);
  free(xc);
  int *cnt = malloc(sizeof(int) * 2 * ((size_t)size + 1)), any = 0;
  bad |= !cnt;
  MPI_Allreduce(&bad, &any, 1, MPI_INT, MPI_MAX, PETSC_COMM_WORLD);
  long total = 0;
  lg_dof_rec *all = NULL;
  if (!any) {
    int *dsp = cnt + size, bytes = nown * (int)sizeof(lg_dof_rec);
    if (MPI_Allgather(&bytes, 1, MPI_INT, cnt, 1, MPI_INT, PETSC_COMM_WORLD) != MPI_SUCCESS) bytes = 0;
    long at = 0;
    for (int r = 0; r < size; r++) { dsp[r] = (int)at; at += cnt[r]; }
    total = at / (long)sizeof(lg_dof_rec);
    all = at > INT32_MAX ? NULL : malloc((size_t)at + 1);
    int none = all == NULL, anynone = 0;
    MPI_Allreduce(&none, &anynone, 1, MPI_INT, MPI_MAX, PETSC_COMM_WORLD);
    if (anynone || MPI_Allgatherv(mine, bytes, MPI_BYTE, all, cnt, dsp, MPI_BYTE, PETSC_COMM_WORLD) != MPI_SUCCESS) any = 1;
  }
  free(mine);
  free(cnt);
  if (any) {
    free(all);
    lg_seterr(env, "gathering a distributed function's values failed (out of memory, or more than 2 GB of them)");
    return 1;
  }
  qsort(all, (size_t)total, sizeof(lg_dof_rec), lg_dof_rec_cmp);
  *out = all;
  *n = total;
  return 0;
}

int lg_function_gather(lg_env *env, const lg_function *f, int coords, double **out, long *n) {
  lg_dof_rec *all;
  long total;
  *out = NULL;
  if (lg_function_records(env, f, coords, &all, &total)) return 1;
  int w = coords ? f->dm->m->dim : 1;
  double *o = malloc(sizeof(double) * ((size_t)total * (size_t)w + 1));
  if (!o) { free(all); lg_seterr(env, "out of memory for %ld values", total); return 1; }
  for (long i = 0; i < total; i++) memcpy(o + (size_t)i * (size_t)w, all[i].v, sizeof(double) * (size_t)w);
  free(all);
  *out = o;
  *n = total;
  return 0;
}

int lg_function_assign_whole(lg_env *env, lg_function *f, const double *v, long n) {
  lg_dof_rec *all;
  long total;
  if (lg_function_records(env, f, 0, &all, &total)) return 1;
  if (total != n) {
    free(all);
    lg_seterr(env, "the table has %ld values, the function %ld dofs", n, total);
    return 1;
  }
  const dofmap *dm = f->dm;
  for (int d = 0; d < dm->ndof; d++) { /* every local dof, owned or ghost, from its place */
    lg_dof_rec r;
    lg_dof_rec_key(f->mesh->dist, dm, d, &r);
    const lg_dof_rec *at = bsearch(&r, all, (size_t)total, sizeof(lg_dof_rec), lg_dof_rec_cmp);
    if (at) f->x[d] = v[at - all];
  }
  free(all);
  return 0;
}

