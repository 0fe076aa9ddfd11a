/* distribute.c — distributed meshes (under mpiexec, unless -lugal_distribute 0): rank 0 cuts the
 * whole mesh into one part per rank (lg_partition_cells) and sends each rank its part with
 * one layer of ghost cells, or more (-lugal_ghost_layers; mesh_part, src/mesh/part.c); the
 * other ranks never hold the whole mesh. A generated box or rectangle is cut rank by rank
 * instead, each rank generating the window of its part. And what goes the other way: a
 * part's mesh and fields gathered whole on rank 0 (output, repairs on one rank), the
 * repaired coordinates sent back, per-cell values (quality) gathered on every rank. */
#include "parallel_int.h"

#include <math.h>
#include <petscsys.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

int lg_ghost_layers(void) {
  PetscInt n = 1;
  PetscBool set = PETSC_FALSE;
  PetscOptionsGetInt(NULL, NULL, "-lugal_ghost_layers", &n, &set);
  return !set ? 1 : n >= 1 && n <= LG_MAX_GHOST_LAYERS ? (int)n : -1;
}

int lg_distribute_wanted(void) {
  /* the default under mpiexec; -lugal_distribute 0 keeps a whole mesh on every rank. Both
   * options are read on one rank too (the ghost layers only for that): the options of a
   * script written for mpiexec are not reported as unused there */
  PetscBool on = PETSC_TRUE, set = PETSC_FALSE;
  PetscOptionsGetBool(NULL, NULL, "-lugal_distribute", &on, &set);
  (void)lg_ghost_layers();
  (void)lg_read_parts_wanted(); /* and the parallel reader's (read_dist.c) */
  return lg_mpi_size() > 1 && on;
}

#define TAG_PART 7301

/* rank 0: partition, then each part extracted, packed and sent in turn (one part in memory
 * at a time besides the whole mesh) */
static int send_parts(lg_env *env, mesh *m, mesh_part **mine) {
  int size = lg_mpi_size(), runs = 0;
  int *part = malloc(sizeof(int) * ((size_t)m->ncell + 1)), *vown = malloc(sizeof(int) * ((size_t)m->nvert + 1));
  if (!part || !vown) { free(part); free(vown); lg_seterr(env, "out of memory for the partition of %d cells", m->ncell); return 1; }
  int layers = lg_ghost_layers(), rc = 0;
  /* the other ranks wait for their parts whatever happens here: errors go through the loop */
  if (layers < 0) {
    char given[64] = "";
    PetscOptionsGetString(NULL, NULL, "-lugal_ghost_layers", given, sizeof given, NULL);
    lg_seterr(env, "-lugal_ghost_layers: expected a whole number from 1 to %d, got %s", LG_MAX_GHOST_LAYERS, given);
    rc = 1;
  }
  if (!rc) rc = lg_partition_cells(env, m, size, part, &runs);
  if (rc == -1) { mesh_vertex_runs(m, NULL, m->nvert, size, part); rc = 0; } /* too few cells for a partitioner */
  if (!rc && mesh_vertex_owners(m, part, vown)) { lg_seterr(env, "out of memory for the vertices' owners"); rc = 1; }
  for (int r = size - 1; r >= 0; r--) { /* rank 0's own part last: it is kept */
    char err[MESH_ERRLEN] = "";
    mesh_part *P = rc ? NULL : mesh_part_extract(m, part, vown, r, layers, err);
    char *buf = NULL;
    size_t len = 0;
    if (!rc && !P) { lg_seterr(env, "%s", err); rc = 1; }
    if (!rc && r > 0 && mesh_part_pack(P, &buf, &len)) { lg_seterr(env, "out of memory packing part %d of the mesh", r + 1); rc = 1; }
    if (r > 0) {
      /* every other rank waits for its message: a failure sends an empty one */
      if (rc) len = 0;
      if (len > (size_t)INT32_MAX) { lg_seterr(env, "part %d of the mesh is over 2 GB packed", r + 1); rc = 1; len = 0; }
      if (MPI_Send(buf, (int)len, MPI_BYTE, r, TAG_PART, PETSC_COMM_WORLD) != MPI_SUCCESS && !rc) {
        lg_seterr(env, "sending part %d of the mesh failed", r + 1);
        rc = 1;
      }
      free(buf);
      mesh_part_free(P);
    } else *mine = P;
  }
  free(part);
  free(vown);
  return rc;
}

static int recv_part(lg_env *env, mesh_part **mine) {
  MPI_Status st;
  int len = 0;
  if (MPI_Probe(0, TAG_PART, PETSC_COMM_WORLD, &st) != MPI_SUCCESS || MPI_Get_count(&st, MPI_BYTE, &len) != MPI_SUCCESS) {
    lg_seterr(env, "receiving this rank's part of the mesh failed");
    return 1;
  }
  /* mapped, not malloc'ed: its pages go back to the system when it is freed (a part of a
   * large mesh is tens of MB, which malloc keeps) */
  char *buf = mesh_big_alloc((size_t)len + 1);
  if (!buf) return 1;
  if (MPI_Recv(buf, len, MPI_BYTE, 0, TAG_PART, PETSC_COMM_WORLD, MPI_STATUS_IGNORE) != MPI_SUCCESS) len = 0;
  char err[MESH_ERRLEN] = "rank 0 failed";
  *mine = len ? mesh_part_unpack(buf, (size_t)len, err) : NULL;
  mesh_big_free(buf);
  if (!*mine) { lg_seterr(env, "this rank's part of the mesh: %s", err); return 1; }
  return 0;
}

mesh_part *lg_part_distribute(lg_env *env, mesh *whole) {
  double t0 = lg_now_ms();
  int rank = lg_mpi_rank();
  mesh_part *P = NULL;
  int rc = rank == 0 ? send_parts(env, whole, &P) : recv_part(env, &P);
  mesh_free(whole);
  if (lg_any_result(rc, env->err, sizeof env->err)) { mesh_part_free(P); return NULL; }
  if (env->verbose) {
    double own[2] = {P->nown_cell, P->m->ncell - P->nown_cell};
    fprintf(stderr, "[lugal] distribute: rank %d holds %d cells (%.0f owned, %.0f ghosts) and %d vertices of %d, %.1f ms\n", rank,
            P->m->ncell, own[0], own[1], P->m->nvert, P->nvert_global, lg_now_ms() - t0);
  }
  return P;
}

mesh_part *lg_part_generate(lg_env *env, const mesh_box_opts *o, int *whole) {
  double t0 = lg_now_ms();
  int rank = lg_mpi_rank(), size = lg_mpi_size(), box = o->type == CELL_TETRAHEDRON || o->type == CELL_HEXAHEDRON;
  long nvg, ncg;
  mesh_box_counts(o, &nvg, &ncg, NULL, NULL);
  char method[64] = "auto";
  PetscOptionsGetString(NULL, NULL, "-lugal_partitioner", method, sizeof method, NULL);
  int layers = lg_ghost_layers(), natural = !strcmp(method, "natural") || ncg < 8L * size;
  /* the whole mesh on rank 0 where the options are refused or the ghost layers bad (its
   * messages), a partitioner is asked for, a run would be empty, or the numbering has no
   * layers (crossed triangles: the centres come last) */
  *whole = 1;
  long vlo, vhi;
  mesh_box_opts w;
  if (!nvg || layers < 0 || o->hi || mesh_box_part_window(o, size, rank, layers, &w, &vlo, &vhi)) return NULL;
  char err[MESH_ERRLEN] = "";
  mesh *m = box ? mesh_box(&w, err) : mesh_rectangle(&w, err);
  int *vglob = m ? malloc(sizeof(int) * ((size_t)m->nvert + 1)) : NULL, *cglob = m ? malloc(sizeof(int) * ((size_t)m->ncell + 1)) : NULL;
  int *part = m ? malloc(sizeof(int) * ((size_t)m->ncell + 1)) : NULL, *vown = m ? malloc(sizeof(int) * ((size_t)m->nvert + 1)) : NULL;
  int rc = !m || !vglob || !cglob || !part || !vown;
  if (m && rc) snprintf(err, sizeof err, "out of memory for this rank's window of the mesh");
  long cnt[2] = {0, 0}; /* the vertices of this run on the runs' cuts, the cells of this part */
  if (!rc) {
    mesh_box_window_numbers(&w, m, vglob, cglob);
    mesh_vertex_runs(m, vglob, (int)nvg, size, part);
    for (int c = 0; c < m->ncell; c++) cnt[1] += part[c] == rank;
    if (!natural && (cnt[0] = mesh_runs_interface(m, vglob, (int)nvg, size, (int)vlo, (int)vhi)) < 0) {
      snprintf(err, sizeof err, "out of memory for the runs' cuts");
      rc = 1;
    }
  }
  mesh_part *P = NULL;
  if ((rc = lg_any_result(rc, err, sizeof err))) goto done;
  /* a graph partitioner on every rank, from the windows' runs (lg_part_from_window), from
   * 4 ranks on; on 2 or 3, rank 0 makes the whole mesh, partitions and cuts it: the box of
   * 1.57 M tetrahedra with PTScotch on 2 ranks took 0.73 s and 183 MB on rank 0 that way
   * against 1.06 s and 248 MB a rank, on 4 ranks 188 MB against 155 (bench/RESULTS.md) */
  int on_ranks = size >= 4;
  if (!natural && strcmp(method, "auto")) { /* a partitioner asked for */
    if (on_ranks && (P = lg_part_from_window(env, m, vglob, cglob, (int)nvg, (int)ncg, layers))) *whole = 0;
    goto done;
  }
  if (!natural) { /* auto: the runs where rank 0, cutting the whole mesh, would keep them */
    long have = 0, fewest = 0;
    int fail = MPI_Allreduce(&cnt[0], &have, 1, MPI_LONG, MPI_SUM, PETSC_COMM_WORLD) != MPI_SUCCESS ||
               MPI_Allreduce(&cnt[1], &fewest, 1, MPI_LONG, MPI_MIN, PETSC_COMM_WORLD) != MPI_SUCCESS;
    int verbose = env->verbose, d = cell_dim(o->type);
    env->verbose = verbose && rank == 0;
    int keep = !fail && lg_runs_kept(env, have, lg_runs_cut_little(have, nvg, d, size) ? fewest : -1, nvg, ncg, d, size);
    env->verbose = verbose;
    if (!keep) { /* PTScotch (where the ranks' run fails, rank 0 makes the whole mesh) */
      if (on_ranks && (P = lg_part_from_window(env, m, vglob, cglob, (int)nvg, (int)ncg, layers))) *whole = 0;
      goto done;
    }
  }
  if (mesh_vertex_owners(m, part, vown)) { snprintf(err, sizeof err, "out of memory for the vertices' owners"); rc = 1; }
  else if (!(P = mesh_part_extract_window(m, vglob, cglob, (int)nvg, (int)ncg, part, vown, rank, layers, err))) rc = 1;
  if (lg_any_result(rc, err, sizeof err)) {
    rc = 1;
    mesh_part_free(P);
    P = NULL;
  } else if (env->verbose)
    fprintf(stderr, "[lugal] distribute: rank %d holds %d cells (%d owned, %d ghosts) and %d vertices of %ld, generated here from a window of %d cells and %d vertices, %.1f ms\n",
            rank, P->m->ncell, P->nown_cell, P->m->ncell - P->nown_cell, P->m->nvert, nvg, m->ncell, m->nvert, lg_now_ms() - t0);
done:
  if (rc) {
    *whole = 0;
    lg_seterr(env, "generating this rank's part of the mesh: %s", err);
  } else if (P) *whole = 0;
  mesh_free(m); free(vglob); free(cglob); free(part); free(vown);
  return P;
}

/* ---------------------------------------------------------------- gathering for output */

/* rank 0 receives every rank's count items of w values of type t (send: this rank's),
 * into recv (the ranks one after another); counts are this rank's numbers of items */
static int gatherv(const void *send, int count, int w, MPI_Datatype t, void *recv, const int *counts, int size) {
  int *rc = NULL, *rd = NULL;
  if (lg_mpi_rank() == 0) {
    rc = malloc(sizeof(int) * 2 * (size_t)size);
    if (!rc) return 1;
    rd = rc + size;
    long at = 0;
    for (int r = 0; r < size; r++) { rc[r] = counts[r] * w; rd[r] = (int)at; at += rc[r]; }
  }
  int bad = MPI_Gatherv((void *)send, count * w, t, recv, rc, rd, t, 0, PETSC_COMM_WORLD) != MPI_SUCCESS;
  free(rc);
  return bad;
}

int lg_dist_gather(lg_env *env, const mesh_part *P, int nf, const mesh_field *fl, mesh **whole, double ***vals) {
  const mesh *m = P->m;
  int rank = lg_mpi_rank(), size = lg_mpi_size(), dim = m->dim, nvc = m->nvc;
  *whole = NULL;
  *vals = NULL;
  int nc = 0, nv = 0;
  for (int c = 0; c < m->ncell; c++) nc += P->cowner[c] == rank;
  for (int v = 0; v < m->nvert; v++) nv += P->vowner[v] == rank;
  int *all = rank == 0 ? malloc(sizeof(int) * 2 * (size_t)size + 2) : NULL;
  int *cg = malloc(sizeof(int) * ((size_t)nc * (size_t)(nvc + 2) + 1)), *vg = malloc(sizeof(int) * ((size_t)nv + 1));
  double *vx = malloc(sizeof(double) * ((size_t)nv * (size_t)dim + 1));
  double *fv = malloc(sizeof(double) * 3 * ((size_t)(nc > nv ? nc : nv) + 1));
  int bad = !cg || !vg || !vx || !fv || (rank == 0 && !all);
  /* this rank's owned cells: global number, tag, global vertices; its owned vertices */
  for (int c = 0, k = 0; !bad && c < m->ncell; c++)
    if (P->cowner[c] == rank) {
      int *o = cg + (size_t)k++ * (size_t)(nvc + 2);
      o[0] = P->cglobal[c];
      o[1] = m->cell_tag[c];
      for (int j = 0; j < nvc; j++) o[2 + j] = P->vglobal[m->cells[(size_t)c * (size_t)nvc + (size_t)j]];
    }
  for (int v = 0, k = 0; !bad && v < m->nvert; v++)
    if (P->vowner[v] == rank) {
      vg[k] = P->vglobal[v];
      memcpy(vx + (size_t)k++ * (size_t)dim, m->x + (size_t)v * (size_t)dim, sizeof(double) * (size_t)dim);
    }
  int anybad = 0;
  MPI_Allreduce(&bad, &anybad, 1, MPI_INT, MPI_MAX, PETSC_COMM_WORLD);
  if (anybad) goto oom;
  /* every rank's cell count, then every rank's vertex count */
  if (MPI_Gather(&nc, 1, MPI_INT, all, 1, MPI_INT, 0, PETSC_COMM_WORLD) != MPI_SUCCESS ||
      MPI_Gather(&nv, 1, MPI_INT, all ? all + size : NULL, 1, MPI_INT, 0, PETSC_COMM_WORLD) != MPI_SUCCESS)
    goto oom;
  int *cc = NULL, *vc = NULL, *rcg = NULL, *rvg = NULL;
  double *rvx = NULL, *rf = NULL;
  long NC = P->ncell_global, NV = P->nvert_global;
  if (rank == 0) {
    cc = all;
    vc = all + size;
    rcg = malloc(sizeof(int) * ((size_t)NC * (size_t)(nvc + 2) + 1));
    rvg = malloc(sizeof(int) * ((size_t)NV + 1));
    rvx = malloc(sizeof(double) * ((size_t)NV * (size_t)dim + 1));
    rf = malloc(sizeof(double) * 3 * ((size_t)(NC > NV ? NC : NV) + 1));
    *vals = calloc((size_t)nf + 1, sizeof(double *));
    bad |= !rcg || !rvg || !rvx || !rf || !*vals;
  }
  /* the root's failure stops everyone before the gathers */
  if (MPI_Bcast(&bad, 1, MPI_INT, 0, PETSC_COMM_WORLD) != MPI_SUCCESS) bad = 1;
  if (bad) goto fail;
  bad = gatherv(cg, nc, nvc + 2, MPI_INT, rcg, cc, size) || gatherv(vg, nv, 1, MPI_INT, rvg, vc, size) ||
        gatherv(vx, nv, dim, MPI_DOUBLE, rvx, vc, size);
  mesh *W = NULL;
  char err[MESH_ERRLEN];
  if (rank == 0 && !bad) {
    int *cells = malloc(sizeof(int) * ((size_t)NC * (size_t)nvc + 1));
    double *x = malloc(sizeof(double) * ((size_t)NV * (size_t)dim + 1));
    if (cells && x) {
      for (long k = 0; k < NC; k++) {
        const int *o = rcg + (size_t)k * (size_t)(nvc + 2);
        memcpy(cells + (size_t)o[0] * (size_t)nvc, o + 2, sizeof(int) * (size_t)nvc);
      }
      for (long k = 0; k < NV; k++) memcpy(x + (size_t)rvg[k] * (size_t)dim, rvx + (size_t)k * (size_t)dim, sizeof(double) * (size_t)dim);
      W = mesh_create(m->type, (int)NV, x, (int)NC, cells, err);
      if (W)
        for (long k = 0; k < NC; k++) W->cell_tag[rcg[(size_t)k * (size_t)(nvc + 2)]] = rcg[(size_t)k * (size_t)(nvc + 2) + 1];
    }
    free(cells);
    free(x);
    if (!W) bad = 1;
  }
  /* each field: the owned cells' or vertices' values, placed by global number */
  for (int f = 0; f < nf && !bad; f++) {
    int oc = fl[f].on_cells, w = fl[f].ncomp;
    for (int i = 0, k = 0; i < (oc ? m->ncell : m->nvert); i++)
      if ((oc ? P->cowner[i] : P->vowner[i]) == rank) memcpy(fv + (size_t)k++ * (size_t)w, fl[f].val + (size_t)i * (size_t)w, sizeof(double) * (size_t)w);
    bad = gatherv(fv, oc ? nc : nv, w, MPI_DOUBLE, rf, oc ? cc : vc, size);
    if (rank == 0 && !bad) {
      long n = oc ? NC : NV;
      double *d = malloc(sizeof(double) * ((size_t)n * (size_t)w + 1));
      if (!d) { bad = 1; break; }
      for (long k = 0; k < n; k++) {
        long g = oc ? rcg[(size_t)k * (size_t)(nvc + 2)] : rvg[k];
        memcpy(d + (size_t)g * (size_t)w, rf + (size_t)k * (size_t)w, sizeof(double) * (size_t)w);
      }
      (*vals)[f] = d;
    }
  }
  free(rcg); free(rvg); free(rvx); free(rf);
  free(cg); free(vg); free(vx); free(fv); free(all);
  if (rank == 0 && bad) {
    mesh_free(W);
    for (int f = 0; *vals && f < nf; f++) free((*vals)[f]);
    free(*vals);
    *vals = NULL;
    lg_seterr(env, "gathering the distributed mesh on rank 0 failed (out of memory)");
    return 1;
  }
  *whole = W;
  return 0;
fail:
  free(rcg); free(rvg); free(rvx); free(rf);
  if (rank == 0 && *vals) free(*vals);
  *vals = NULL;
oom:
  free(cg); free(vg); free(vx); free(fv); free(all);
  lg_seterr(env, "out of memory gathering the distributed mesh on rank 0");
  return 1;
}

/* ---------------------------------------------------------------- per-cell values */

/* every rank's n values v of cells with global numbers gid: all of them on every rank, as
 * (gid, value) pairs (*total of them, malloc'ed) */
static int allgather_cells(const double *v, const int *gid, int n, double **pairs, long *total) {
  int size = lg_mpi_size(), bad = 0, any = 0;
  double *mine = malloc(sizeof(double) * 2 * ((size_t)n + 1));
  int *cnt = malloc(sizeof(int) * 2 * ((size_t)size + 1));
  bad = !mine || !cnt;
  for (int i = 0; !bad && i < n; i++) { mine[2 * i] = gid[i]; mine[2 * i + 1] = v[i]; }
  MPI_Allreduce(&bad, &any, 1, MPI_INT, MPI_MAX, PETSC_COMM_WORLD);
  *pairs = NULL;
  if (!any) {
    int m = 2 * n, *dsp = cnt + size;
    if (MPI_Allgather(&m, 1, MPI_INT, cnt, 1, MPI_INT, PETSC_COMM_WORLD) != MPI_SUCCESS) any = 1;
    long at = 0;
    for (int r = 0; !any && r < size; r++) { dsp[r] = (int)at; at += cnt[r]; }
    *total = at / 2;
    *pairs = any || at > INT32_MAX ? NULL : malloc(sizeof(double) * ((size_t)at + 1));
    int none = !*pairs;
    MPI_Allreduce(&none, &any, 1, MPI_INT, MPI_MAX, PETSC_COMM_WORLD);
    if (!any && MPI_Allgatherv(mine, m, MPI_DOUBLE, *pairs, cnt, dsp, MPI_DOUBLE, PETSC_COMM_WORLD) != MPI_SUCCESS) any = 1;
  }
  free(mine);
  free(cnt);
  if (any) { free(*pairs); *pairs = NULL; }
  return any;
}

int lg_dist_cell_values(lg_env *env, const double *v, const int *gid, int n, long ncell, double *out) {
  double *pairs;
  long total;
  if (allgather_cells(v, gid, n, &pairs, &total)) { lg_seterr(env, "gathering per-cell values failed (out of memory)"); return 1; }
  for (long i = 0; i < ncell; i++) out[i] = NAN;
  for (long i = 0; i < total; i++) {
    long g = (long)pairs[2 * i];
    if (g >= 0 && g < ncell) out[g] = pairs[2 * i + 1];
  }
  free(pairs);
  return 0;
}

int lg_dist_stats(lg_env *env, const double *v, const int *gid, int n, quality_stats *st) {
  quality_stats_compute(v, n, st);
  /* min and max with the lowest global cell where they are reached (a serial run's first) */
  double r[8] = {st->argmin >= 0 ? st->min : INFINITY, st->argmax >= 0 ? -st->max : INFINITY, 0, 0, 0, 0, 0, 0};
  int bad = lg_allreduce(r, 2, LG_MIN);
  double g[2] = {INFINITY, INFINITY};
  if (st->argmin >= 0 && st->min == r[0]) g[0] = gid[st->argmin];
  if (st->argmax >= 0 && -st->max == r[1]) g[1] = gid[st->argmax];
  bad |= lg_allreduce(g, 2, LG_MIN);
  /* the mean: sums of the finite values, counts of NaN and of each infinity */
  double sum = n && isfinite(st->mean) ? st->mean * n : 0;
  double s[5] = {sum, n, n && isnan(st->mean), st->mean == INFINITY, st->mean == -INFINITY};
  bad |= lg_allreduce(s, 5, LG_SUM);
  if (bad) { lg_seterr(env, "the reduction over the ranks failed"); return 1; }
  st->n = (int)s[1];
  st->min = isinf(g[0]) ? NAN : r[0];
  st->max = isinf(g[1]) ? NAN : -r[1];
  st->argmin = isinf(g[0]) ? -1 : (int)g[0];
  st->argmax = isinf(g[1]) ? -1 : (int)g[1];
  if (!st->n || s[2] || (s[3] && s[4])) st->mean = NAN;
  else if (s[3]) st->mean = INFINITY;
  else if (s[4]) st->mean = -INFINITY;
  else st->mean = s[0] / s[1];
  return 0;
}

int lg_dist_worst(lg_env *env, const double *v, const int *gid, int n, int k, int larger_is_better, int *gids, double *vals) {
  /* each rank's k worst, gathered, the k worst of them by the mesh layer's order (its
   * quality_worst on the gathered values; ties to the lower global cell) */
  int kl = k < n ? k : n;
  int *ids = malloc(sizeof(int) * ((size_t)kl + 1));
  double *wv = malloc(sizeof(double) * ((size_t)kl + 1));
  int *wg = malloc(sizeof(int) * ((size_t)kl + 1));
  if (!ids || !wv || !wg) kl = 0;
  if (kl) quality_worst(v, n, kl, larger_is_better, ids);
  for (int i = 0; i < kl; i++) { wv[i] = v[ids[i]]; wg[i] = gid[ids[i]]; }
  double *pairs;
  long total;
  int rc = allgather_cells(wv, wg, kl, &pairs, &total);
  free(ids); free(wv); free(wg);
  if (rc) { lg_seterr(env, "gathering the worst cells failed (out of memory)"); return -1; }
  /* sorted by global cell, so that the mesh layer's first-index ties pick the lowest */
  long m = total;
  double *x = malloc(sizeof(double) * ((size_t)m + 1));
  int *order = malloc(sizeof(int) * ((size_t)m + 1)), *sel = malloc(sizeof(int) * ((size_t)m + 1));
  if (!x || !order || !sel) { free(x); free(order); free(sel); free(pairs); lg_seterr(env, "out of memory"); return -1; }
  for (long i = 0; i < m; i++) order[i] = (int)i;
  for (long i = 1; i < m; i++) /* insertion sort: k per rank, few in all */
    for (long j = i; j > 0 && pairs[2 * order[j]] < pairs[2 * order[j - 1]]; j--) { int t = order[j]; order[j] = order[j - 1]; order[j - 1] = t; }
  for (long i = 0; i < m; i++) x[i] = pairs[2 * order[i] + 1];
  int kk = k < m ? k : (int)m;
  quality_worst(x, (int)m, kk, larger_is_better, sel);
  for (int i = 0; i < kk; i++) { gids[i] = (int)pairs[2 * order[sel[i]]]; vals[i] = x[sel[i]]; }
  free(x); free(order); free(sel); free(pairs);
  return kk;
}

/* ---------------------------------------------------------------- repairs on rank 0 */

int lg_dist_gather_mesh(lg_env *env, const mesh_part *P, mesh **whole) {
  double **vals = NULL;
  *whole = NULL;
  int rc = lg_dist_gather(env, P, 0, NULL, whole, &vals);
  free(vals);
  /* the tagged boundary facets of owned cells (each facet of the whole mesh once), by
   * global vertex numbers, and every name */
  mesh *m = P->m;
  int rank = lg_mpi_rank(), size = lg_mpi_size(), nvf = m->nvf, bad = rc || mesh_build_boundary_cells(m);
  int nb = 0;
  for (int b = 0; !bad && b < m->nbf; b++) nb += P->cowner[m->bf_cell[b]] == rank;
  int *mine = malloc(sizeof(int) * ((size_t)nb * (size_t)(nvf + 1) + 1)), *cnt = malloc(sizeof(int) * 2 * ((size_t)size + 1));
  bad |= !mine || !cnt;
  for (int b = 0, k = 0; !bad && b < m->nbf; b++)
    if (P->cowner[m->bf_cell[b]] == rank) {
      int *o = mine + (size_t)k++ * (size_t)(nvf + 1);
      for (int j = 0; j < nvf; j++) o[j] = P->vglobal[m->bf_verts[(size_t)b * (size_t)nvf + (size_t)j]];
      o[nvf] = m->bf_tag[b];
    }
  int any = 0;
  MPI_Allreduce(&bad, &any, 1, MPI_INT, MPI_MAX, PETSC_COMM_WORLD);
  int *all = NULL, total = 0;
  if (!any) {
    int w = nb * (nvf + 1);
    if (MPI_Gather(&w, 1, MPI_INT, cnt, 1, MPI_INT, 0, PETSC_COMM_WORLD) != MPI_SUCCESS) any = 1;
    int *dsp = cnt + size;
    if (rank == 0) {
      long at = 0;
      for (int r = 0; r < size; r++) { dsp[r] = (int)at; at += cnt[r]; }
      total = (int)(at / (nvf + 1));
      all = malloc(sizeof(int) * ((size_t)at + 1));
      if (!all) any = 1;
    }
    if (MPI_Bcast(&any, 1, MPI_INT, 0, PETSC_COMM_WORLD) != MPI_SUCCESS) any = 1;
    if (!any && MPI_Gatherv(mine, w, MPI_INT, all, cnt, dsp, MPI_INT, 0, PETSC_COMM_WORLD) != MPI_SUCCESS) any = 1;
  }
  mesh *W = *whole;
  if (!any && rank == 0 && W && total) {
    W->bf_verts = malloc(sizeof(int) * (size_t)total * (size_t)nvf);
    W->bf_tag = malloc(sizeof(int) * (size_t)total);
    if (!W->bf_verts || !W->bf_tag) any = 1;
    for (int b = 0; !any && b < total; b++) {
      memcpy(W->bf_verts + (size_t)b * (size_t)nvf, all + (size_t)b * (size_t)(nvf + 1), sizeof(int) * (size_t)nvf);
      W->bf_tag[b] = all[(size_t)b * (size_t)(nvf + 1) + (size_t)nvf];
    }
    if (!any) W->nbf = total;
  }
  for (int i = 0; !any && rank == 0 && W && i < m->nbname; i++) any = mesh_set_boundary_name(W, m->bnames[i].tag, m->bnames[i].name);
  for (int i = 0; !any && rank == 0 && W && i < m->ncname; i++) any = mesh_set_region_name(W, m->cnames[i].tag, m->cnames[i].name);
  free(mine);
  free(cnt);
  free(all);
  if (any || rc) {
    mesh_free(*whole);
    *whole = NULL;
    if (!rc) lg_seterr(env, "gathering the distributed mesh on rank 0 failed (out of memory)");
    return 1;
  }
  return 0;
}

int lg_dist_scatter_coords(lg_env *env, mesh_part *P, const mesh *whole) {
  /* each rank's vertices to rank 0, which answers with their coordinates in W */
  mesh *m = P->m;
  int rank = lg_mpi_rank(), size = lg_mpi_size(), dim = m->dim, n = m->nvert;
  int *cnt = malloc(sizeof(int) * 4 * ((size_t)size + 1)), *ids = NULL, bad = !cnt, any = 0;
  double *x = NULL, *mine = malloc(sizeof(double) * ((size_t)n * (size_t)dim + 1));
  bad |= !mine;
  MPI_Allreduce(&bad, &any, 1, MPI_INT, MPI_MAX, PETSC_COMM_WORLD);
  if (any) { free(cnt); free(mine); lg_seterr(env, "out of memory"); return 1; }
  int *dsp = cnt + size, *xc = dsp + size, *xd = xc + size;
  if (MPI_Gather(&n, 1, MPI_INT, cnt, 1, MPI_INT, 0, PETSC_COMM_WORLD) != MPI_SUCCESS) bad = 1;
  if (rank == 0) {
    long at = 0;
    for (int r = 0; r < size; r++) { dsp[r] = (int)at; xc[r] = cnt[r] * dim; xd[r] = (int)(at * dim); at += cnt[r]; }
    ids = malloc(sizeof(int) * ((size_t)at + 1));
    x = malloc(sizeof(double) * ((size_t)at * (size_t)dim + 1));
    bad |= !ids || !x || at * dim > INT32_MAX;
  }
  if (MPI_Bcast(&bad, 1, MPI_INT, 0, PETSC_COMM_WORLD) != MPI_SUCCESS) bad = 1;
  if (!bad && MPI_Gatherv(P->vglobal, n, MPI_INT, ids, cnt, dsp, MPI_INT, 0, PETSC_COMM_WORLD) != MPI_SUCCESS) bad = 1;
  if (!bad && rank == 0) {
    long at = 0;
    for (int r = 0; r < size; r++) at += cnt[r];
    for (long i = 0; i < at; i++) memcpy(x + (size_t)i * (size_t)dim, whole->x + (size_t)ids[i] * (size_t)dim, sizeof(double) * (size_t)dim);
  }
  if (!bad && MPI_Scatterv(x, xc, xd, MPI_DOUBLE, mine, n * dim, MPI_DOUBLE, 0, PETSC_COMM_WORLD) != MPI_SUCCESS) bad = 1;
  if (!bad) memcpy(m->x, mine, sizeof(double) * (size_t)n * (size_t)dim);
  free(cnt); free(ids); free(x); free(mine);
  if (bad) { lg_seterr(env, "sending the repaired coordinates to every rank failed"); return 1; }
  return 0;
}
