/* parallel.h — the room src/assemble/parallel: meshes across the ranks of a run. Partitions
 * of a mesh's cells (partition.c), a mesh cut into one part per rank and sent, generated
 * rank by rank, or read from a Gmsh file in parallel (distribute.c, read_dist.c), the
 * global numbering of the nodes of a part (numbering.c, through the rendezvous of
 * rendezvous.c), and a part's mesh, fields and per-cell values gathered back. It works on
 * src/mesh's meshes and parts (mesh_part) and fem's dof maps, below the meshes with dof
 * maps of the assembly core (lg_mesh wraps a part: lg_mesh_distribute, assemble.h). Uses
 * process.h (ranks, errors). */
#ifndef LUGAL_PARALLEL_H
#define LUGAL_PARALLEL_H

#include "../../mesh/io/io.h"
#include "../../mesh/quality/quality.h"
#include "../fem/fem.h"
#include "../process/process.h"

/* ---- partitions (partition.c) */
/* the part of every cell of m (ncell values into pt) for nparts ranks, on the calling rank
 * alone: by -lugal_partitioner (a MatPartitioningType, "auto" by default: the numbering's
 * runs where they split well, else PTScotch; or "natural"); *runs = 1 where they are the
 * numbering's runs; returns -1 where the cells' order is kept (no partition: natural, one
 * part, or fewer than 8 cells per part), 1 on error */
int lg_partition_cells(lg_env *env, mesh *m, int nparts, int *pt, int *runs);
/* Boyer-Moore's majority vote, one cell's ballot for a node: owner is the candidate, cnt
 * its count (0: none yet, or a tie so far); after all ballots in cell order owner is the
 * part of most of the node's cells where there is a majority */
static inline void lg_vote(int *owner, int *cnt, int node, int part) {
  if (!cnt[node]) { owner[node] = part; cnt[node] = 1; }
  else cnt[node] += owner[node] == part ? 1 : -1;
}

/* ---- distributed meshes (distribute.c, read_dist.c) */
/* Are meshes distributed in this run: several ranks and not -lugal_distribute 0 */
int lg_distribute_wanted(void);
/* the ghost layers a distributed mesh gets (-lugal_ghost_layers, default 1; 2 for interior
 * facet terms with a continuous test function); -1 when the option is not 1 to
 * LG_MAX_GHOST_LAYERS */
#define LG_MAX_GHOST_LAYERS 8
int lg_ghost_layers(void);
/* the mesh `whole` (rank 0's; other ranks pass NULL, or their own copy; freed on every
 * rank) cut into one part per rank (the partition of lg_partition_cells, rank 0's work),
 * each rank getting its part with one layer of ghost cells, or more (mesh_part);
 * collective. NULL and the reason in env->err on every rank when any failed */
mesh_part *lg_part_distribute(lg_env *env, mesh *whole);
/* a generated box or rectangle (o) distributed without a whole mesh anywhere: each rank
 * generates the window of cell layers that holds its part (the numbering's runs), its ghost
 * layers and the cells around their vertices, and extracts from it the part
 * lg_part_distribute would send it (the same to the byte); collective. Where the runs are
 * not the partition (PTScotch's choice, -lugal_partitioner, crossed diagonals, refused
 * options) NULL with *whole = 1 on every rank: rank 0 then generates the whole mesh for
 * lg_part_distribute. NULL with *whole = 0 and the reason in env->err on failure */
mesh_part *lg_part_generate(lg_env *env, const mesh_box_opts *o, int *whole);
/* a Gmsh file read in parallel, no rank reading the whole file or holding the whole mesh:
 * each rank's part, the one lg_part_distribute would send it with the same partition (to
 * the byte; PTScotch's partition is computed in parallel, so it may differ); collective.
 * NULL on every rank where this path cannot take the file (its layout, its contents,
 * -lugal_read_parts 0): rank 0 then reads it whole for lg_part_distribute, which reads what
 * can be read and gives the whole reader's messages */
mesh_part *lg_part_read(lg_env *env, const char *path);
/* -lugal_read_parts (default 1): 0 keeps the whole-file read on rank 0 */
int lg_read_parts_wanted(void);

/* ---- the global numbering of a part's nodes (numbering.c) */
#define LG_KEYLEN 8 /* field, component, entity kind, place j, up to four global vertex numbers */
/* the key of dof d of dof map dm on the part P: field 0, its component, the entity that
 * holds its node and the node's place there, the entity's global vertex numbers sorted (a
 * cell's: its global number) */
void lg_dof_key(const mesh_part *P, const dofmap *dm, int d, int *key);
/* the vertices of P's cells of other parts and, with more ghost layers, of the cells
 * within the further layers of those (ivert[v] = 1; malloc'ed, NULL when out of memory),
 * and the nodes (B dofs from off on: dof map dm in a problem's vector) of owned cells with
 * a vertex there: the owned nodes another rank may hold (shared[node] = 1) */
char *lg_other_vertices(const mesh_part *P);
void lg_mark_shared(const mesh_part *P, const char *ivert, const dofmap *dm, int off, int B, char *shared);
/* the global numbers perm[Nn] of a part's nodes: the owned ones (owner[i] == rank) after the
 * lower ranks' in the local order, the others the numbers their owners gave them, learnt
 * through a rendezvous on the nodes' keys (key(ctx, node, key): LG_KEYLEN ints). *first:
 * this rank's first number, *nown its count, *total all ranks'. Collective, bad = this rank
 * failed already (it still takes part); returns 0, or on every rank 1 (out of memory) or 2
 * (a ghost node without an owner) */
typedef void (*lg_node_key_fn)(const void *ctx, int node, int *key);
int lg_rendezvous_number(int bad, int Nn, const int *owner, const char *shared, lg_node_key_fn key, const void *ctx,
                         int *perm, int *first, int *nown, int *total);

/* ---- back to one rank, or to every rank (distribute.c) */
/* the whole mesh and the fields' whole arrays (point or cell data of fl) on rank 0, from
 * every rank's owned cells and vertices of P (for output); other ranks get NULLs; collective */
int lg_dist_gather(lg_env *env, const mesh_part *P, int nf, const mesh_field *fl, mesh **whole, double ***vals);
/* the whole mesh (cells, tags, tagged boundary facets, names) on rank 0 (NULL elsewhere),
 * and the coordinates of rank 0's whole mesh back to every rank's local vertices: how a
 * distributed mesh is repaired (untangled, smoothed) on one rank; collective */
int lg_dist_gather_mesh(lg_env *env, const mesh_part *P, mesh **whole);
int lg_dist_scatter_coords(lg_env *env, mesh_part *P, const mesh *whole);
/* per-cell values of a distributed mesh, each rank's n values v of its cells with global
 * numbers gid (collective): all ncell of them in the global order on every rank (NaN where
 * none came); their statistics as quality_stats_compute gives them on the whole mesh
 * (argmin/argmax global cells, quality.h); the k worst (quality_worst) into gids and vals,
 * returning how many (-1 on failure) */
int lg_dist_cell_values(lg_env *env, const double *v, const int *gid, int n, long ncell, double *out);
int lg_dist_stats(lg_env *env, const double *v, const int *gid, int n, quality_stats *st);
int lg_dist_worst(lg_env *env, const double *v, const int *gid, int n, int k, int larger_is_better, int *gids, double *vals);

#endif
