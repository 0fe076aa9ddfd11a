/* partition.c — a mesh's cells split into parts, one per rank of a parallel run: PETSc's
 * MatPartitioning (PTScotch, which Debian's PETSc has) on the vertex graph, vertices
 * adjacent through a cell, each cell then in the part of most of its vertices; or the
 * vertex numbering's runs, each cell with its lowest vertex; or none ("natural": the rows
 * split in the problems' order). "auto" (the default) takes the numbering's runs where they
 * cut about as little as compact parts would (a generator's numbering, a few parts) and
 * PTScotch elsewhere. Rank 0 partitions and every rank receives its result, so that all
 * hold the same partition (a box or rectangle generated rank by rank, distribute.c, takes
 * auto's test, lg_runs_kept, on counts reduced over the ranks instead). The problems number their rows part by part (problem.c), so that
 * a rank owns the rows of its cells. */
#include "parallel_int.h"

#include <math.h>
#include <petscmat.h>
#include <stdlib.h>
#include <string.h>

/* the vertex graph in CSR (PetscMalloc'ed: MatCreateMPIAdj takes them), vertices adjacent
 * when they share a cell: a P1 matrix's graph, 5.6 times fewer nodes than the dual graph's
 * on tetrahedra and built from the cells alone (the dual graph's facet numbering took 0.8 s
 * of a 1.3 s partition on 663 552 tetrahedra) */
static int vertex_graph(lg_env *env, const mesh *m, PetscInt **ia_out, PetscInt **ja_out) {
  int nv = m->nvert, nvc = m->nvc;
  size_t nk = (size_t)m->ncell * (size_t)nvc;
  int *vs = calloc((size_t)nv + 2, sizeof(int)), *vc = malloc(sizeof(int) * (nk + 1)), *mark = malloc(sizeof(int) * ((size_t)nv + 1));
  PetscInt *ia = NULL, *ja = NULL;
  if (!vs || !vc || !mark || PetscMalloc1(nv + 1, &ia)) goto oom;
  /* each vertex's cells */
  for (size_t k = 0; k < nk; k++) vs[m->cells[k] + 2]++;
  for (int v = 0; v < nv; v++) vs[v + 2] += vs[v + 1];
  for (int c = 0; c < m->ncell; c++)
    for (int j = 0; j < nvc; j++) vc[vs[m->cells[(size_t)c * nvc + j] + 1]++] = c;
  /* each vertex's neighbours: counted, then listed (vs[v] .. vs[v + 1] are v's cells) */
  for (int pass = 0; pass < 2; pass++) {
    for (int v = 0; v < nv; v++) mark[v] = -1;
    PetscInt n = 0;
    for (int v = 0; v < nv; v++) {
      if (!pass) ia[v] = n;
      mark[v] = v;
      for (int i = vs[v]; i < vs[v + 1]; i++)
        for (int j = 0; j < nvc; j++) {
          int w = m->cells[(size_t)vc[i] * nvc + j];
          if (mark[w] == v) continue;
          mark[w] = v;
          if (pass) ja[n] = w;
          n++;
        }
      if (pass) /* MPIAdj wants each row's columns sorted */
        for (PetscInt a = ia[v] + 1; a < n; a++)
          for (PetscInt b = a; b > ia[v] && ja[b - 1] > ja[b]; b--) { PetscInt t = ja[b]; ja[b] = ja[b - 1]; ja[b - 1] = t; }
    }
    if (!pass) {
      ia[nv] = n;
      if (PetscMalloc1(n + 1, &ja)) goto oom;
    }
  }
  free(vs); free(vc); free(mark);
  *ia_out = ia;
  *ja_out = ja;
  return 0;
oom:
  free(vs); free(vc); free(mark);
  PetscFree(ia);
  PetscFree(ja);
  lg_seterr(env, "out of memory for the partition's graph of %d vertices", m->nvert);
  return 1;
}

/* is method a partitioner of this PETSc? If not, the message lists those it has */
static int known_partitioner(lg_env *env, const char *method) {
  void (*f)(void) = NULL;
  if (!MatInitializePackage() && !PetscFunctionListFind(MatPartitioningList, method, &f) && f) return 1;
  const char **names = NULL;
  int n = 0;
  char list[512] = "";
  size_t used = 0;
  if (!PetscFunctionListGet(MatPartitioningList, &names, &n))
    for (int i = 0; i < n && used < sizeof list; i++)
      if (names[i]) used += (size_t)snprintf(list + used, sizeof list - used, "%s, ", names[i]);
  PetscFree(names);
  lg_seterr(env, "-lugal_partitioner %s: this PETSc has no such partitioner (it has %sand lugal's auto and natural)", method, list);
  return 0;
}

int lg_partition_graph(lg_env *env, MPI_Comm comm, int nrows, int ncols, PetscInt *ia, PetscInt *ja, int nparts,
                       const char *method, int *vpart) {
  if (!known_partitioner(env, method)) { PetscFree(ia); PetscFree(ja); return 1; }
  Mat adj = NULL;
  MatPartitioning mp = NULL;
  IS is = NULL;
  PetscErrorCode ierr = MatCreateMPIAdj(comm, nrows, ncols, ia, ja, NULL, &adj);
  if (ierr) { PetscFree(ia); PetscFree(ja); }
  if (!ierr) ierr = MatPartitioningCreate(comm, &mp);
  if (!ierr) ierr = MatPartitioningSetAdjacency(mp, adj);
  if (!ierr) ierr = MatPartitioningSetNParts(mp, nparts);
  if (!ierr) ierr = MatPartitioningSetType(mp, method);
  if (!ierr) ierr = MatPartitioningApply(mp, &is);
  const PetscInt *pv = NULL;
  if (!ierr) ierr = ISGetIndices(is, &pv);
  int bad = 0;
  for (int v = 0; !ierr && v < nrows; v++) {
    vpart[v] = (int)pv[v];
    if (!bad && (pv[v] < 0 || pv[v] >= nparts)) {
      lg_seterr(env, "the partitioner %s put vertex %d in part %d of %d", method, v + 1, (int)pv[v], nparts);
      bad = 1;
    }
  }
  if (pv) ISRestoreIndices(is, &pv);
  ISDestroy(&is);
  MatPartitioningDestroy(&mp);
  MatDestroy(&adj);
  if (bad) return 1;
  if (ierr) return lg_petsc_fail(env, ierr, "the partition of the mesh (-lugal_partitioner)");
  return 0;
}

int lg_majority_part(const int *p, int n) {
  int best = p[0], nb = 0;
  for (int j = 0; j < n; j++) {
    int m = 0;
    for (int k = 0; k < n; k++) m += p[k] == p[j];
    if (m > nb || (m == nb && p[j] < best)) { best = p[j]; nb = m; }
  }
  return best;
}

/* rank 0's part of the work: the partition of m into nparts by the method (a
 * MatPartitioningType) into part: its vertices are partitioned, and each cell goes to the
 * part that holds most of its vertices (the lowest of those that tie) */
static int partition_cells(lg_env *env, mesh *m, int nparts, const char *method, int *part) {
  PetscInt *ia, *ja;
  double tg = lg_now_ms();
  if (vertex_graph(env, m, &ia, &ja)) return 1;
  if (env->verbose) fprintf(stderr, "[lugal] partition: the vertex graph in %.1f ms\n", lg_now_ms() - tg);
  int *vp = malloc(sizeof(int) * ((size_t)m->nvert + 1)), pc[8];
  if (!vp) { PetscFree(ia); PetscFree(ja); lg_seterr(env, "out of memory for the partition"); return 1; }
  if (lg_partition_graph(env, PETSC_COMM_SELF, m->nvert, m->nvert, ia, ja, nparts, method, vp)) { free(vp); return 1; }
  for (int c = 0; c < m->ncell; c++) {
    const int *cv = m->cells + (size_t)c * (size_t)m->nvc;
    for (int j = 0; j < m->nvc; j++) pc[j] = vp[cv[j]];
    part[c] = lg_majority_part(pc, m->nvc);
  }
  free(vp);
  return 0;
}

int lg_runs_cut_little(long have, long nvert, int d, int nparts) {
  /* a graph partition costs about a setup (1.57 M tetrahedra: 0.45 s); take it where the
   * numbering's split cuts more than twice what compact parts would: on a cube of V
   * vertices in d dimensions, nparts cubes meet along d (nparts^(1/d) - 1) planes, slabs
   * along nparts - 1 (fewer below 4 parts in 3D), each cut two layers of V^((d-1)/d)
   * vertices. Slabs stay while that holds (a generator's numbering, 2 to 4 parts in 3D),
   * and beyond it their halo is the whole part */
  double planes = fmin(nparts - 1.0, d * (pow(nparts, 1.0 / d) - 1.0));
  double ideal = 2.0 * planes * pow((double)nvert, (double)(d - 1) / d);
  return have >= 0 && have <= 2 * ideal;
}

int lg_runs_kept(lg_env *env, long have, long fewest, long nvert, long ncell, int d, int nparts) {
  /* the numbering's split of the cells (problems of P1 fields keep their rows in their own
   * order, the others number theirs by these parts: see set_ownership), unless a part gets
   * under half its share of the cells (fewest: the smallest part's cells, -1 when the
   * split cuts too much to count them): on a small mesh a cell's lowest vertex is mostly in
   * the first runs (box{nx = 2} on 2 ranks: 48 cells and 0) */
  int keep = lg_runs_cut_little(have, nvert, d, nparts), few = keep && (fewest < 0 || 2L * nparts * fewest < ncell);
  if (env->verbose) {
    double planes = fmin(nparts - 1.0, d * (pow(nparts, 1.0 / d) - 1.0));
    fprintf(stderr, "[lugal] partition: the numbering's split into %d has %ld vertices on its cuts (compact parts: %.0f)%s: %s\n",
            nparts, have, 2.0 * planes * pow((double)nvert, (double)(d - 1) / d), few ? " and a part under half its share of the cells" : "",
            keep && !few ? "kept" : "PTScotch");
  }
  return keep && !few;
}

/* the partition of m's cells into nparts, computed on the calling rank alone: into pt
 * (ncell values) with *runs = 1 where it is the numbering's runs, or nothing (returns -1)
 * where the cells' order is kept (-lugal_partitioner natural, or too few cells); 1 on an
 * error */
int lg_partition_cells(lg_env *env, mesh *m, int nparts, int *pt, int *runs) {
  char method[64] = "auto";
  PetscBool set = PETSC_FALSE;
  PetscOptionsGetString(NULL, NULL, "-lugal_partitioner", method, sizeof method, &set);
  *runs = 0;
  /* a handful of cells per part is not worth a graph partitioner (nor safe: parts may be
   * empty); consecutive runs of cells are the identity numbering */
  if (!strcmp(method, "natural") || nparts < 2 || m->ncell < 8 * nparts) return -1;
  double t0 = lg_now_ms();
  if (!strcmp(method, "auto")) {
    long have = mesh_runs_interface(m, NULL, m->nvert, nparts, 0, m->nvert), fewest = -1;
    if (have >= 0 && lg_runs_cut_little(have, m->nvert, cell_dim(m->type), nparts)) {
      mesh_vertex_runs(m, NULL, m->nvert, nparts, pt);
      int *cnt = calloc((size_t)nparts, sizeof(int));
      for (int c = 0; cnt && c < m->ncell; c++) cnt[pt[c]]++;
      for (int r = 0; cnt && r < nparts; r++) fewest = fewest < 0 || cnt[r] < fewest ? cnt[r] : fewest;
      free(cnt);
    }
    if (lg_runs_kept(env, have, fewest, m->nvert, m->ncell, cell_dim(m->type), nparts)) {
      *runs = 1;
      return 0;
    }
#ifdef PETSC_HAVE_PTSCOTCH
    strcpy(method, MATPARTITIONINGPTSCOTCH);
#else
    strcpy(method, MATPARTITIONINGCURRENT);
#endif
  }
  if (partition_cells(env, m, nparts, method, pt)) return 1;
  if (env->verbose)
    fprintf(stderr, "[lugal] partition: %d cells into %d parts by %s in %.1f ms\n", m->ncell, nparts, method, lg_now_ms() - t0);
  return 0;
}
