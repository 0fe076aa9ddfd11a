/* parallel.c — the process layout of a run: PETSc and MPI start-up and shutdown (with fast
 * single-process defaults), the OpenMP threads per rank, the rank and size, reductions of
 * numbers over the ranks, the outcome of rank-0 work or of every rank's part of it shared
 * with every rank, ParaView output written so (a .vtu by rank 0, the pieces of a .pvtu by
 * every rank), and ending the whole run from one rank (a Lua error on rank 1 must not leave
 * rank 0 waiting in a collective). Data that every rank holds whole (meshes, dof maps, discrete functions)
 * stays identical on all ranks; what is distributed lives in the problems (problem.c). */
#include "assemble.h"

#ifdef _OPENMP
#include <omp.h>
#endif
#include <petscsys.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

int lg_petsc_init(int *argc, char ***argv) {
  /* OpenMPI singleton start-up is slow (a helper daemon); when not started by mpiexec,
   * default to the in-process settings unless the user set them (PERFORMANCE-NOTES). A
   * single process talks to no one: no network reachability (netlink), only the collectives
   * and one-sided components a communicator of one uses, and hwloc maps the cores and memory
   * but not the PCI devices, whose configuration space costs 2.5 ms a device to read in a
   * virtual machine, nor its OpenCL, GL and libxml plugins (MPI_Init 40 -> 17 ms here;
   * bench/RESULTS.md "Start-up") */
  const char *local = getenv("OMPI_COMM_WORLD_LOCAL_SIZE");
  if (!getenv("OMPI_COMM_WORLD_SIZE") && !getenv("PMI_RANK") && !getenv("PMIX_RANK")) {
    static const char *kv[][2] = {{"OMPI_MCA_ess_singleton_isolated", "1"}, {"OMPI_MCA_btl", "self"},
                                  {"OMPI_MCA_pml", "ob1"}, {"OMPI_MCA_mtl", "^ofi,psm2"},
                                  {"OMPI_MCA_osc", "sm,pt2pt"}, {"OMPI_MCA_coll", "basic,self,libnbc"},
                                  {"OMPI_MCA_reachable", "weighted"}, {"OMPI_MCA_errmgr", "default_app"},
                                  {"HWLOC_COMPONENTS", "-linuxio"},
                                  {"HWLOC_PLUGINS_BLACKLIST", "hwloc_pci,hwloc_opencl,hwloc_gl,hwloc_xml_libxml"}};
    for (size_t i = 0; i < sizeof kv / sizeof kv[0]; i++) setenv(kv[i][0], kv[i][1], 0);
  } else if (local && getenv("OMPI_COMM_WORLD_SIZE") && !strcmp(local, getenv("OMPI_COMM_WORLD_SIZE"))) {
    /* Open MPI's mpiexec with every rank on this machine: its point-to-point layer ob1 (shared
     * memory), the one it selects here anyway, without first probing the network libraries
     * of its other layers (psm, psm2, ofi): a 2-rank run of an empty script 0.52 -> 0.33 s.
     * Not where the ranks span machines (the network layers are the point there), nor where
     * the user set OMPI_MCA_pml */
    setenv("OMPI_MCA_pml", "ob1", 0);
  }
#ifdef _OPENMP
  /* ranks on one machine share its cores: each takes its share of OpenMP threads (two ranks
   * on two cores with two threads each spin against each other), unless OMP_NUM_THREADS
   * says otherwise */
  if (local && atoi(local) > 1 && !getenv("OMP_NUM_THREADS")) {
    long cores = sysconf(_SC_NPROCESSORS_ONLN);
    int per = (int)(cores / atoi(local));
    omp_set_num_threads(per > 1 ? per : 1);
  }
#else
  (void)local;
#endif
  PetscErrorCode ierr = PetscInitialize(argc, argv, NULL, NULL);
  if (ierr) return 1;
  /* errors come back as codes with messages; lugal reports them, PETSc does not print */
  PetscPushErrorHandler(PetscReturnErrorHandler, NULL);
  /* output into a closed pipe (lugal run.lua | head) ends the run quietly, as any Unix
   * tool's does, not with PETSc's signal report and an MPI_ABORT */
  signal(SIGPIPE, SIG_DFL);
  return 0;
}

void lg_petsc_finalize(void) {
  PetscPopErrorHandler();
  PetscFinalize();
}

int lg_petsc_report_unused_options(void) {
  PetscInt n = 0;
  char **names = NULL, **values = NULL;
  if (PetscOptionsLeftGet(NULL, &n, &names, &values)) return 0;
  for (PetscInt i = 0; i < n && lg_mpi_rank() == 0; i++)
    fprintf(stderr, "lugal: warning: the option -%s%s%s was not used (misspelt? -help lists the options of the solvers the "
                    "script creates)\n", names[i], values[i] ? " " : "", values[i] ? values[i] : "");
  PetscOptionsLeftRestore(NULL, &n, &names, &values);
  return (int)n;
}

static int mpi_up(void) {
  int up = 0, down = 0;
  MPI_Initialized(&up);
  if (up) MPI_Finalized(&down);
  return up && !down;
}

int lg_mpi_size(void) {
  int size = 1;
  if (mpi_up()) MPI_Comm_size(PETSC_COMM_WORLD, &size);
  return size;
}

int lg_mpi_rank(void) {
  int rank = 0;
  if (mpi_up()) MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  return rank;
}

int lg_allreduce(double *x, int n, lg_reduce_op op) {
  if (lg_mpi_size() == 1) return 0;
  MPI_Op o = op == LG_SUM ? MPI_SUM : op == LG_MAX ? MPI_MAX : MPI_MIN;
  return MPI_Allreduce(MPI_IN_PLACE, x, n, MPI_DOUBLE, o, PETSC_COMM_WORLD) != MPI_SUCCESS;
}

int lg_root_result(int rc, char *msg, size_t len) {
  if (lg_mpi_size() == 1) return rc;
  int v = rc;
  if (MPI_Bcast(&v, 1, MPI_INT, 0, PETSC_COMM_WORLD) != MPI_SUCCESS) return 1;
  if (v && msg && len) {
    msg[len - 1] = 0;
    if (MPI_Bcast(msg, (int)len, MPI_CHAR, 0, PETSC_COMM_WORLD) != MPI_SUCCESS) return 1;
  }
  return v;
}

int lg_any_result(int rc, char *msg, size_t len) {
  int size = lg_mpi_size();
  if (size == 1) return rc;
  int mine = rc ? lg_mpi_rank() : size, first = size;
  if (MPI_Allreduce(&mine, &first, 1, MPI_INT, MPI_MIN, PETSC_COMM_WORLD) != MPI_SUCCESS) return 1;
  if (first == size) return 0;
  if (msg && len) {
    msg[len - 1] = 0;
    if (MPI_Bcast(msg, (int)len, MPI_CHAR, first, PETSC_COMM_WORLD) != MPI_SUCCESS) return 1;
  }
  return 1;
}

int lg_bcast_bytes(char **buf, size_t *len) {
  if (lg_mpi_size() == 1) return 0;
  int root = lg_mpi_rank() == 0;
  unsigned long long n = root ? *len : 0;
  if (MPI_Bcast(&n, 1, MPI_UNSIGNED_LONG_LONG, 0, PETSC_COMM_WORLD) != MPI_SUCCESS) return 1;
  if (!root) {
    *len = (size_t)n;
    *buf = malloc((size_t)n + 1);
  }
  double ok = *buf ? 0 : 1; /* every rank must have room before any sends */
  if (lg_allreduce(&ok, 1, LG_MAX) || ok) {
    if (!root) { free(*buf); *buf = NULL; }
    return 1;
  }
  for (size_t at = 0; at < (size_t)n; at += 1u << 30) {
    int part = (int)((size_t)n - at < (1u << 30) ? (size_t)n - at : 1u << 30);
    if (MPI_Bcast(*buf + at, part, MPI_CHAR, 0, PETSC_COMM_WORLD) != MPI_SUCCESS) return 1;
  }
  return 0;
}

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
    if (lg_dist_gather(env, lm, nf, fl, &W, &vals)) {
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

void lg_abort_run(const char *msg) {
  int size = lg_mpi_size();
  if (size > 1) fprintf(stderr, "lugal: rank %d of %d: %s\n", lg_mpi_rank(), size, msg);
  else fprintf(stderr, "%s\n", msg);
  fflush(stderr);
  if (size > 1) MPI_Abort(PETSC_COMM_WORLD, 1);
}
