/* parallel_int.h — internal to src/assemble/parallel: the rendezvous boxes, graph
 * partitions and the tests of the numbering's runs that distribute.c and read_dist.c share.
 * The room's interface is parallel.h. */
#ifndef LUGAL_PARALLEL_INT_H
#define LUGAL_PARALLEL_INT_H

#include "parallel.h"

#include <petscmat.h>

/* rendezvous.c: records of rec bytes, each for a rank (dest), sent through one all-to-all
 * (lg_box_send: the records received, rcnt[r] from rank r in rank order; cnt[r] sent to rank
 * r; *order[k] the box index of the k-th record sent, for answers; the box's storage is
 * freed, its n kept), and answers of rec bytes each to records received with counts rcnt,
 * back to their senders, who sent cnt (lg_reply: the k-th answers their k-th record sent).
 * Collective; bad: this rank failed, set on every rank where any rank cannot exchange */
typedef struct {
  size_t rec;
  long n, cap;
  int *dest;
  char *data;
} lg_box;
void *lg_box_add(lg_box *b, int dest, int *bad);
void lg_box_free(lg_box *b);
char *lg_box_send(lg_box *b, int *cnt, int *rcnt, long **order, long *nrecv, int *bad);
char *lg_reply(const char *ans, size_t rec, int *rcnt, int *cnt, int *bad);
/* partition.c: a graph's rows (nrows here of ncols, CSR ia/ja PetscMalloc'ed, given up: freed by
 * the call, failed or not) partitioned by
 * the MatPartitioningType method into nparts on comm: each row's part into vpart; and the part
 * of most of n parts (the lowest of those that tie), a cell's from its vertices' */
int lg_partition_graph(lg_env *env, MPI_Comm comm, int nrows, int ncols, PetscInt *ia, PetscInt *ja, int nparts,
                       const char *method, int *vpart);
int lg_majority_part(const int *p, int n);
/* auto's test of the numbering's runs (mesh_runs_interface, mesh_vertex_runs): do they cut
 * about as little as compact parts would (have: the vertices on their cuts), and are they
 * kept (also: no part under half its share of the cells; fewest, the smallest part's
 * cells, or -1 when not counted); lg_runs_kept prints the choice with -lugal_verbose */
int lg_runs_cut_little(long have, long nvert, int d, int nparts);
int lg_runs_kept(lg_env *env, long have, long fewest, long nvert, long ncell, int d, int nparts);
/* a generated box or rectangle partitioned by a graph partitioner on every rank: each rank
 * passes its window m of the mesh (its run's cells and every cell around their vertices: the
 * window lg_part_generate makes) with global numbers vglob, cglob of nvg vertices and ncg
 * cells; the run's cells enter the reader's pipeline (partition, ghost layers, facets, part)
 * as if read from a file (read_dist.c). Collective; NULL on every rank where any failed */
mesh_part *lg_part_from_window(lg_env *env, mesh *m, const int *vglob, const int *cglob, int nvg, int ncg, int layers);

#endif
