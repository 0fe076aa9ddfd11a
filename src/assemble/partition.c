/* partition.c — a mesh's cells split into parts, one per rank of a parallel run: PETSc's
 * MatPartitioning (PTScotch, which Debian's PETSc has) on the dual graph, cells adjacent
 * through a facet, or the numbering's order ("natural": the rows split in the problem's
 * order); "auto" (the default) takes the numbering's order where its split is nearly as good
 * as flat cuts (generated meshes) and PTScotch elsewhere. Rank 0 partitions and every rank
 * receives its result, so that all hold the same partition. The problems number their rows
 * part by part (problem.c), so that a rank owns the rows of its cells. */
#include "problem_int.h"

#include <math.h>
#include <petscmat.h>
#include <stdlib.h>
#include <string.h>

/* the facet ids of every cell (nf per cell): vertices in 1D, edges in 2D, faces in 3D */
static const int *cell_facet_ids(mesh *m, int *nf) {
  switch (cell_dim(m->type)) {
  case 1: *nf = 2; return m->cells;
  case 2: *nf = cell_nedges(m->type); return mesh_build_edges(m) ? NULL : m->cell_edges;
  default: *nf = cell_nfacets(m->type); return mesh_build_faces(m) ? NULL : m->cell_faces;
  }
}

/* the dual graph in CSR (PetscMalloc'ed: MatCreateMPIAdj takes them): cells sharing a facet */
static int dual_graph(lg_env *env, mesh *m, PetscInt **ia_out, PetscInt **ja_out) {
  int nf;
  const int *cf = cell_facet_ids(m, &nf);
  if (!cf) { lg_seterr(env, "the partition: %s", m->err); return 1; }
  int nfacet = 0;
  for (size_t k = 0; k < (size_t)m->ncell * (size_t)nf; k++) nfacet = cf[k] + 1 > nfacet ? cf[k] + 1 : nfacet;
  /* each facet's first two cells (a third would be a non-manifold facet: left out) */
  int *fc = malloc(sizeof(int) * 2 * ((size_t)nfacet + 1));
  PetscInt *ia = NULL, *ja = NULL;
  if (!fc || PetscMalloc1(m->ncell + 1, &ia)) goto oom;
  for (int f = 0; f < 2 * nfacet; f++) fc[f] = -1;
  for (int c = 0; c < m->ncell; c++)
    for (int k = 0; k < nf; k++) {
      int f = cf[(size_t)c * nf + k];
      if (fc[2 * f] < 0) fc[2 * f] = c;
      else if (fc[2 * f + 1] < 0 && fc[2 * f] != c) fc[2 * f + 1] = c;
    }
  memset(ia, 0, sizeof(PetscInt) * ((size_t)m->ncell + 1));
  for (int f = 0; f < nfacet; f++)
    if (fc[2 * f + 1] >= 0) { ia[fc[2 * f] + 1]++; ia[fc[2 * f + 1] + 1]++; }
  for (int c = 0; c < m->ncell; c++) ia[c + 1] += ia[c];
  if (PetscMalloc1(ia[m->ncell] + 1, &ja)) goto oom;
  PetscInt *at = malloc(sizeof(PetscInt) * ((size_t)m->ncell + 1));
  if (!at) goto oom;
  memcpy(at, ia, sizeof(PetscInt) * (size_t)m->ncell);
  for (int f = 0; f < nfacet; f++)
    if (fc[2 * f + 1] >= 0) { ja[at[fc[2 * f]]++] = fc[2 * f + 1]; ja[at[fc[2 * f + 1]]++] = fc[2 * f]; }
  free(at);
  free(fc);
  /* MPIAdj wants each row's columns sorted */
  for (int c = 0; c < m->ncell; c++)
    for (PetscInt i = ia[c] + 1; i < ia[c + 1]; i++)
      for (PetscInt j = i; j > ia[c] && ja[j - 1] > ja[j]; j--) { PetscInt t = ja[j]; ja[j] = ja[j - 1]; ja[j - 1] = t; }
  *ia_out = ia;
  *ja_out = ja;
  return 0;
oom:
  free(fc);
  PetscFree(ia);
  PetscFree(ja);
  lg_seterr(env, "out of memory for the partition's graph of %d cells", m->ncell);
  return 1;
}

/* rank 0's part of the work: the partition of m into nparts by the method (a
 * MatPartitioningType) into part */
static int partition_cells(lg_env *env, mesh *m, int nparts, const char *method, int *part) {
  PetscInt *ia, *ja;
  double tg = now_ms();
  if (dual_graph(env, m, &ia, &ja)) return 1;
  if (env->verbose) fprintf(stderr, "[lugal] partition: the dual graph in %.1f ms\n", now_ms() - tg);
  Mat adj = NULL;
  MatPartitioning mp = NULL;
  IS is = NULL;
  PetscErrorCode ierr = MatCreateMPIAdj(PETSC_COMM_SELF, m->ncell, m->ncell, ia, ja, NULL, &adj);
  if (ierr) { PetscFree(ia); PetscFree(ja); }
  if (!ierr) ierr = MatPartitioningCreate(PETSC_COMM_SELF, &mp);
  if (!ierr) ierr = MatPartitioningSetAdjacency(mp, adj);
  if (!ierr) ierr = MatPartitioningSetNParts(mp, nparts);
  if (!ierr) ierr = MatPartitioningSetType(mp, method);
  if (!ierr) ierr = MatPartitioningApply(mp, &is);
  const PetscInt *pv = NULL;
  if (!ierr) ierr = ISGetIndices(is, &pv);
  if (!ierr) {
    for (int c = 0; c < m->ncell; c++) part[c] = (int)pv[c];
    ISRestoreIndices(is, &pv);
  }
  ISDestroy(&is);
  MatPartitioningDestroy(&mp);
  MatDestroy(&adj);
  if (ierr) return lg_petsc_fail(env, ierr, "the partition of the mesh (-lugal_partitioner)");
  for (int c = 0; c < m->ncell; c++)
    if (part[c] < 0 || part[c] >= nparts) {
      lg_seterr(env, "the partitioner %s put cell %d in part %d of %d", method, c + 1, part[c], nparts);
      return 1;
    }
  return 0;
}

/* the vertices of cells whose vertices lie in different parts when the vertices are split
 * into nparts runs of their numbering: what the rows split in the problem's order (a P1
 * problem's, and a proxy for every degree) exchange, about two layers along each cut */
static long natural_interface(const mesh *m, int nparts) {
  char *mark = calloc((size_t)m->nvert + 1, 1);
  if (!mark) return -1;
  long n = 0;
  for (int c = 0; c < m->ncell; c++) {
    const int *v = m->cells + (size_t)c * (size_t)m->nvc;
    long p0 = (long)v[0] * nparts / m->nvert;
    int cut = 0;
    for (int k = 1; k < m->nvc && !cut; k++) cut = (long)v[k] * nparts / m->nvert != p0;
    for (int k = 0; cut && k < m->nvc; k++)
      if (!mark[v[k]]) { mark[v[k]] = 1; n++; }
  }
  free(mark);
  return n;
}

int lg_mesh_partition(lg_env *env, lg_mesh *lm, int nparts, const int **part) {
  *part = NULL;
  if (lm->nparts == nparts) { *part = lm->part; return 0; }
  char method[64] = "auto";
  PetscBool set = PETSC_FALSE;
  PetscOptionsGetString(NULL, NULL, "-lugal_partitioner", method, sizeof method, &set);
  mesh *m = lm->m;
  /* a handful of cells per part is not worth a graph partitioner (nor safe: parts may be
   * empty); consecutive runs of cells are the identity numbering */
  if (!strcmp(method, "natural") || nparts < 2 || m->ncell < 8 * nparts) return 0;
  double t0 = now_ms();
  if (!strcmp(method, "auto")) {
    /* a graph partition costs about a setup (1.57 M tetrahedra: 2 s); take it where the
     * numbering's split is poor: more than twice the vertices along nparts - 1 flat cuts
     * (two layers of V^((d-1)/d) each) */
    long have = natural_interface(m, nparts);
    double flat = 2.0 * (nparts - 1) * pow((double)m->nvert, (double)(cell_dim(m->type) - 1) / cell_dim(m->type));
    int keep = have >= 0 && have <= 2 * flat;
    if (env->verbose && lg_mpi_rank() == 0)
      fprintf(stderr, "[lugal] partition: the numbering's split into %d has %ld vertices on its cuts (flat cuts: %.0f): %s\n",
              nparts, have, flat, keep ? "kept" : "PTScotch");
    if (keep) {
      lm->nparts = nparts;
      free(lm->part);
      lm->part = NULL;
      return 0;
    }
#ifdef PETSC_HAVE_PTSCOTCH
    strcpy(method, MATPARTITIONINGPTSCOTCH);
#else
    strcpy(method, MATPARTITIONINGCURRENT);
#endif
  }
  int *pt = malloc(sizeof(int) * ((size_t)m->ncell + 1));
  if (!pt) { lg_seterr(env, "out of memory for the partition of %d cells", m->ncell); return 1; }
  /* rank 0 partitions, every rank gets its outcome and the parts */
  int rc = lg_mpi_rank() == 0 ? partition_cells(env, m, nparts, method, pt) : 0;
  rc = lg_root_result(rc, env->err, sizeof env->err);
  if (!rc && lg_mpi_size() > 1 && MPI_Bcast(pt, m->ncell, MPI_INT, 0, PETSC_COMM_WORLD) != MPI_SUCCESS) {
    lg_seterr(env, "the partition could not be sent to every rank");
    rc = 1;
  }
  if (rc) { free(pt); return 1; }
  if (env->verbose && lg_mpi_rank() == 0)
    fprintf(stderr, "[lugal] partition: %d cells into %d parts by %s in %.1f ms\n", m->ncell, nparts, method, now_ms() - t0);
  free(lm->part);
  lm->part = pt;
  lm->nparts = nparts;
  *part = pt;
  return 0;
}
