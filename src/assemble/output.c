/* output.c — fields on a mesh written for ParaView by the ranks of a run: a .vtu by rank 0
 * (a distributed mesh's gathered there first, lg_dist_gather), or the pieces of a .pvtu by
 * every rank and the collection by rank 0, published together (all or none). */
#include "assemble.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* names[k] = path without ".pvtu" + "_p<k>.vtu" for k < npiece */
static char **piece_names(const char *path, int npiece) {
  size_t len = strlen(path) + 24;
  char **names = calloc((size_t)npiece, sizeof(char *));
  for (int k = 0; names && k < npiece; k++) {
    if (!(names[k] = malloc(len))) {
      for (int j = 0; j < k; j++) free(names[j]);
      free(names);
      return NULL;
    }
    snprintf(names[k], len, "%.*s_p%d.vtu", (int)(strlen(path) - 5), path, k);
  }
  return names;
}

/* A .pvtu and its pieces are one dataset: each rank's pieces and rank 0's .pvtu are written
 * under temporary names (staged: n files here, the .pvtu last), and put in place only when
 * every rank wrote all of its files, else all removed, so that a write failing part way (a
 * full disk at piece 2) leaves the earlier dataset of the same name whole instead of new
 * pieces 0-1 beside old pieces 2-3. rc: this rank's outcome so far */
static int publish_collection(outfile *staged, int n, int rc, char *err) {
  rc = lg_any_result(rc, err, MESH_ERRLEN);
  for (int i = 0; i < n; i++) {
    if (rc) outfile_abort(&staged[i]);
    else rc = outfile_publish(&staged[i], err, MESH_ERRLEN);
  }
  return lg_any_result(rc, err, MESH_ERRLEN);
}

/* a distributed mesh: a .pvtu is a piece per rank, its owned cells; a .vtu is gathered on
 * rank 0 (lg_dist_gather) and written whole */
static int dist_write_vtu(lg_env *env, lg_mesh *lm, const char *path, int nf, const mesh_field *fl, int format, int npiece, char *err) {
  int rank = lg_mpi_rank(), size = lg_mpi_size(), rc = 0;
  if (!npiece) {
    mesh *W;
    double **vals;
    if (lg_dist_gather(env, lm->dist, nf, fl, &W, &vals)) {
      snprintf(err, MESH_ERRLEN, "%.*s", MESH_ERRLEN - 1, env->err);
      rc = 1;
    } else if (rank == 0) {
      mesh_field *wf = malloc(sizeof(mesh_field) * ((size_t)nf + 1));
      for (int f = 0; wf && f < nf; f++) { wf[f] = fl[f]; wf[f].val = vals[f]; }
      rc = !wf || mesh_write_vtu_format(W, path, nf, wf, format);
      if (rc) snprintf(err, MESH_ERRLEN, "%s", wf ? W->err : "out of memory");
      for (int f = 0; f < nf; f++) free(vals[f]);
      free(vals);
      free(wf);
      mesh_free(W);
    }
    return lg_root_result(rc, err, MESH_ERRLEN);
  }
  if (npiece != size) {
    snprintf(err, MESH_ERRLEN, "a distributed mesh is written in one piece per rank (%d), not %d", size, npiece);
    return 1;
  }
  const mesh_part *P = lm->dist;
  char **names = piece_names(path, npiece);
  int *cells = malloc(sizeof(int) * ((size_t)P->m->ncell + 1)), nc = 0, ns = 0;
  outfile staged[2];
  if (!names || !cells) rc = 1, snprintf(err, MESH_ERRLEN, "out of memory for %d pieces", npiece);
  for (int c = 0; !rc && c < P->m->ncell; c++)
    if (P->cowner[c] == rank) cells[nc++] = c;
  if (!rc && (rc = mesh_write_vtu_piece(P->m, names[rank], nf, fl, format, cells, nc, &staged[ns]))) snprintf(err, MESH_ERRLEN, "%s", P->m->err);
  else if (!rc) ns++;
  free(cells);
  if (!rc && rank == 0 && !(rc = mesh_write_pvtu(path, nf, fl, npiece, names, err, &staged[ns]))) ns++;
  rc = publish_collection(staged, ns, rc, err);
  for (int k = 0; names && k < npiece; k++) free(names[k]);
  free(names);
  return rc;
}

int lg_write_vtu(lg_env *env, lg_mesh *lm, const char *path, int nf, const mesh_field *fl, int format, int npiece, char *err) {
  mesh *m = lm->m;
  if (lm->dist) return dist_write_vtu(env, lm, path, nf, fl, format, npiece, err);
  if (!npiece) {
    int rc = lg_mpi_rank() == 0 ? mesh_write_vtu_format(m, path, nf, fl, format) : 0;
    if (rc) snprintf(err, MESH_ERRLEN, "%s", m->err);
    return lg_root_result(rc, err, MESH_ERRLEN);
  }
  const int *part = NULL;
  if (lg_mesh_partition(env, lm, npiece, &part)) {
    snprintf(err, MESH_ERRLEN, "%.*s", MESH_ERRLEN - 1, env->err);
    return 1;
  }
  int rank = lg_mpi_rank(), size = lg_mpi_size(), rc = 0;
  char **names = piece_names(path, npiece);
  /* the cells piece by piece (a counting sort by part): cells[start[k] .. start[k + 1]) */
  int *cells = malloc(sizeof(int) * ((size_t)m->ncell + 1)), *start = calloc((size_t)npiece + 2, sizeof(int));
  int *runs = part ? NULL : malloc(sizeof(int) * ((size_t)m->ncell + 1));
  if (!names || !cells || !start || (!part && !runs)) rc = 1, snprintf(err, MESH_ERRLEN, "out of memory for %d pieces", npiece);
  if (!rc) {
    if (!part) mesh_vertex_runs(m, NULL, m->nvert, npiece, runs);
    const int *pc = part ? part : runs;
    for (int c = 0; c < m->ncell; c++) start[pc[c] + 2]++;
    for (int k = 0; k < npiece; k++) start[k + 2] += start[k + 1];
    for (int c = 0; c < m->ncell; c++) cells[start[pc[c] + 1]++] = c;
  }
  free(runs);
  /* this rank's pieces (every size-th) and rank 0's .pvtu, staged (publish_collection) */
  int ns = 0;
  outfile *staged = malloc(sizeof(outfile) * ((size_t)(npiece / size) + 2));
  if (!staged && !rc) rc = 1, snprintf(err, MESH_ERRLEN, "out of memory for %d pieces", npiece);
  for (int k = rank; k < npiece && !rc; k += size)
    if ((rc = mesh_write_vtu_piece(m, names[k], nf, fl, format, cells + start[k], start[k + 1] - start[k], &staged[ns])))
      snprintf(err, MESH_ERRLEN, "%s", m->err);
    else ns++;
  free(cells);
  free(start);
  if (!rc && rank == 0 && !(rc = mesh_write_pvtu(path, nf, fl, npiece, names, err, &staged[ns]))) ns++;
  rc = publish_collection(staged, ns, rc, err);
  free(staged);
  for (int k = 0; names && k < npiece; k++) free(names[k]);
  free(names);
  return rc;
}


lg_series *lg_series_new(lg_env *env, const char *path) {
  size_t l = strlen(path);
  if (l < 5 || strcmp(path + l - 4, ".pvd")) { lg_seterr(env, "a series is a path ending in .pvd, got \"%s\"", path); return NULL; }
  lg_series *s = calloc(1, sizeof *s);
  if (!s || !(s->path = strdup(path))) { free(s); lg_seterr(env, "out of memory"); return NULL; }
  return s;
}

int lg_series_write(lg_env *env, lg_series *s, lg_mesh *lm, int nf, const mesh_field *fl, double t) {
  if (s->n == s->cap) {
    int cap = s->cap ? 2 * s->cap : 16;
    double *nt = realloc(s->t, sizeof(double) * (size_t)cap);
    if (nt) s->t = nt;
    char **nfl = realloc(s->files, sizeof(char *) * (size_t)cap);
    if (nfl) s->files = nfl;
    if (!nt || !nfl) { lg_seterr(env, "out of memory"); return 1; }
    s->cap = cap;
  }
  int size = lg_mpi_size();
  size_t l = strlen(s->path);
  char *file = malloc(l + 32);
  if (!file) { lg_seterr(env, "out of memory"); return 1; }
  snprintf(file, l + 32, "%.*s_%04d.%s", (int)(l - 4), s->path, s->n, size > 1 ? "pvtu" : "vtu");
  char err[MESH_ERRLEN] = "";
  if (lg_write_vtu(env, lm, file, nf, fl, VTU_BINARY, size > 1 ? size : 0, err)) { lg_seterr(env, "%s", err); free(file); return 1; }
  s->files[s->n] = file;
  s->t[s->n++] = t;
  int rc = lg_mpi_rank() == 0 ? mesh_write_pvd(s->path, s->n, s->t, s->files, err) : 0;
  if (lg_root_result(rc, err, sizeof err)) { lg_seterr(env, "%s", err); return 1; }
  return 0;
}

void lg_series_free(lg_series *s) {
  if (!s) return;
  for (int i = 0; i < s->n; i++) free(s->files[i]);
  free(s->files);
  free(s->t);
  free(s->path);
  free(s);
}
