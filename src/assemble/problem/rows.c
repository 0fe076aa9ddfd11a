/* rows.c — which rank owns which of a problem's rows, and their numbers in PETSc: a serial
 * run owns them all; on a whole mesh, a parallel run's ranks own the nodes of their parts
 * of the cells, numbered part after part; on a distributed mesh each rank numbers the nodes
 * it owns and learns its ghost nodes' numbers from their owners (lg_rendezvous_number,
 * parallel.h). And the PETSc rows of a distributed problem in the order of its gathered
 * fields (whole dense matrices). */
#include "problem_int.h"

#include <mpi.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---------------------------------------------------------------- a distributed mesh */

/* the key of a problem's node n (B dofs): its first dof's in its field's map, with the
 * field's number */
static void node_key(const lg_problem *p, int n, int B, int *key) {
  int dof = n * B, a = 0;
  while (a + 1 < p->cols.n && dof >= p->cglob[a + 1]) a++;
  lg_dof_key(p->lm->dist, p->cdm[a], dof - p->cglob[a], key);
  key[0] = a;
}

static void problem_node_key(const void *ctx, int n, int *key) {
  const lg_problem *p = ctx;
  node_key(p, n, p->pB, key);
}

static int number_distributed(lg_env *env, lg_problem *p, int B) {
  double t0 = lg_now_ms();
  const mesh_part *P = p->lm->dist;
  int rank = lg_mpi_rank(), Nn = p->N / B;
  int *owner = malloc(sizeof(int) * ((size_t)Nn + 1));
  char *shared = calloc((size_t)Nn + 1, 1), *ivert = lg_other_vertices(P);
  /* each node to the part of most of its cells, the vote set_ownership takes on a whole
   * mesh, in the whole mesh's cell order: exact for the nodes of owned cells, whose cells are
   * all here; a node of ghost cells only is another rank's whatever the vote says */
  int bad = !owner || !shared || !ivert || lg_problem_node_owners(p, B, P->cowner, owner);
  for (int a = 0; !bad && a < p->cols.n; a++) lg_mark_shared(P, ivert, p->cdm[a], p->cglob[a], B, shared);
  free(ivert);
  int first, nown = 0, total;
  for (int i = 0; !bad && i < Nn; i++) nown += owner[i] == rank;
  p->perm = malloc(sizeof(int) * ((size_t)Nn + 1));
  p->iperm = malloc(sizeof(int) * ((size_t)nown + 1));
  bad |= !p->iperm;
  int rc = lg_rendezvous_number(bad, Nn, owner, shared, problem_node_key, p, p->perm, &first, &nown, &total);
  for (int i = 0; !rc && i < Nn; i++)
    if (owner[i] == rank) p->iperm[p->perm[i] - first] = i;
  free(owner);
  free(shared);
  if (rc) {
    if (rc == 2) lg_seterr(env, "the global numbering of a distributed problem's nodes failed: a ghost node without an owner");
    else lg_seterr(env, "out of memory numbering the nodes of a distributed problem");
    return 1;
  }
  p->lo = first * B;
  p->hi = (first + nown) * B;
  p->Nglob = total * B;
  p->ioff = first;
  if (env->verbose && rank == 0)
    fprintf(stderr, "[lugal] distributed nodes: %d in all, numbered in %.1f ms\n", total, lg_now_ms() - t0);
  return 0;
}

/* ---------------------------------------------------------------- a whole mesh */

/* the rows this rank owns: whole nodes (B rows each). A serial run owns them all; a
 * parallel one the nodes of its part of the mesh's cells (lg_mesh_partition; a node of
 * cells in several parts goes to the part of most of them), numbered part after part in
 * PETSc (perm), or with the cells in their order the nodes split evenly in the problem's
 * order */
int lg_problem_set_ownership(lg_env *env, lg_problem *p) {
  int size = lg_mpi_size(), rank = lg_mpi_rank(), B = lg_matrix_block_size(p), Nn = p->N / B;
  p->par = size > 1;
  p->pB = B;
  p->Nglob = p->N;
  if (p->lm->dist) return number_distributed(env, p, B);
  const int *part = NULL;
  if (p->par && lg_mesh_partition(env, p->lm, size, &part)) return 1;
  /* where the parts are the numbering's runs, one continuous P1 field (nodes = vertices)
   * splits as well in its own order, which keeps the pattern on the dof map's own list;
   * several fields, or P2 and up (vertex nodes first, then edges...), would give a rank
   * rows from all over the mesh */
  if (part && p->lm->part_runs && p->cols.n == 1 && p->cdm[0]->degree == 1 && !p->cdm[0]->disc) part = NULL;
  if (!part) {
    long first = (long)Nn * rank / size, last = (long)Nn * (rank + 1) / size;
    p->lo = (int)first * B;
    p->hi = (int)last * B;
    return 0;
  }
  int *owner = malloc(sizeof(int) * ((size_t)Nn + 1)), *start = calloc((size_t)size + 1, sizeof(int));
  p->perm = malloc(sizeof(int) * ((size_t)Nn + 1));
  p->iperm = malloc(sizeof(int) * ((size_t)Nn + 1));
  /* each node to the part of most of its cells: a node of a part's border goes to the side
   * that holds it most, which keeps the parts' row counts near their cell counts (the lowest
   * part took every shared node before: +20% rows on 16 parts) */
  if (!owner || !start || !p->perm || !p->iperm || lg_problem_node_owners(p, B, part, owner)) {
    free(owner); free(start);
    lg_seterr(env, "out of memory for the rows' order of %d nodes", Nn);
    return 1;
  }
  for (int i = 0; i < Nn; i++) start[owner[i] + 1]++;
  for (int r = 0; r < size; r++) start[r + 1] += start[r];
  p->lo = start[rank] * B;
  p->hi = start[rank + 1] * B;
  for (int i = 0; i < Nn; i++) {
    p->perm[i] = start[owner[i]]++;
    p->iperm[p->perm[i]] = i;
  }
  free(owner);
  free(start);
  return 0;
}

int lg_problem_node_owners(const lg_problem *p, int B, const int *part, int *owner) {
  int Nn = p->N / B, *cnt = calloc((size_t)Nn + 1, sizeof(int));
  if (!cnt) return 1;
  for (int i = 0; i < Nn; i++) owner[i] = -1;
  const mesh *m = p->lm->m;
  for (int a = 0; a < p->cols.n; a++) {
    const dofmap *dm = p->cdm[a];
    for (int c = 0; c < m->ncell; c++)
      for (int k = 0; k < dm->nloc; k += B) /* each node once (B > 1: its B dofs in a row) */
        lg_vote(owner, cnt, (p->cglob[a] + dm->cell_dofs[(size_t)c * (size_t)dm->nloc + (size_t)k]) / B, part[c]);
  }
  free(cnt);
  return 0;
}

int lg_dist_problem_order(lg_env *env, const lg_problem *p, int *order) {
  int N = (int)p->Nglob, bad = 0, base = 0;
  for (int g = 0; g < N; g++) order[g] = -1;
  double *zero = calloc((size_t)p->N + 1, sizeof(double));
  if (!zero) bad = 1;
  for (int a = 0; a < p->cols.n; a++) {
    const dofmap *dm = p->cdm[a];
    lg_function f = {p->lm, (dofmap *)dm, dm->degree, zero, -1, 0, NULL};
    lg_dof_rec *all = NULL;
    long total = 0;
    /* collective whatever this rank's state: every rank gathers every field */
    if (lg_function_records(env, &f, 0, &all, &total)) { bad = 1; continue; }
    for (int d = 0; !bad && d < dm->ndof; d++) {
      PetscInt g = lg_petsc_row(p, p->cglob[a] + d);
      if (g < p->lo || g >= p->hi) continue;
      lg_dof_rec r;
      lg_dof_rec_key(p->lm->dist, dm, d, &r);
      const lg_dof_rec *at = bsearch(&r, all, (size_t)total, sizeof(lg_dof_rec), lg_dof_rec_cmp);
      if (at && g < N) order[g] = base + (int)(at - all);
      else bad = 1;
    }
    free(all);
    base += (int)total;
  }
  free(zero);
  /* every rank's owned rows' places, on every rank (the others' entries are -1) */
  if (MPI_Allreduce(MPI_IN_PLACE, order, N, MPI_INT, MPI_MAX, PETSC_COMM_WORLD) != MPI_SUCCESS ||
      MPI_Allreduce(MPI_IN_PLACE, &bad, 1, MPI_INT, MPI_MAX, PETSC_COMM_WORLD) != MPI_SUCCESS || bad || base != N) {
    lg_seterr(env, "ordering a distributed problem's rows failed");
    return 1;
  }
  return 0;
}

