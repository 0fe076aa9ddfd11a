/* process.c — the process layout of a run: PETSc and MPI start-up and shutdown (with fast
 * single-process defaults), the OpenMP threads per rank, the rank and size, reductions of
 * numbers over the ranks, the outcome of rank-0 work or of every rank's part of it shared
 * with every rank, and ending the whole run from one rank (a Lua error on rank 1 must not
 * leave rank 0 waiting in a collective). It knows nothing of meshes or their distribution
 * (src/assemble/parallel) or of output (src/assemble/output.c). */
#include "process.h"

#ifdef _OPENMP
#include <omp.h>
#endif
#include <petscsys.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <fcntl.h>
#include <unistd.h>

double lg_now_ms(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

int lg_runnable_tasks(void) {
  /* /proc/loadavg's fourth field, "running/total": the kernel's count of runnable tasks,
   * the number /proc/stat's procs_running gives, in one short line (/proc/stat, read before,
   * needed a 64 KiB buffer per thread for its interrupt counts and cost the kernel a pass
   * over every core's statistics) */
  char buf[128];
  int fd = open("/proc/loadavg", O_RDONLY | O_CLOEXEC);
  if (fd < 0) return -1;
  ssize_t n = read(fd, buf, sizeof buf - 1);
  close(fd);
  if (n <= 0) return -1;
  buf[n] = 0;
  int run = -1;
  return sscanf(buf, "%*s %*s %*s %d/", &run) == 1 ? run : -1;
}

int lg_threads_for_load(int T) {
#ifdef _OPENMP
  int run = lg_runnable_tasks(), idle = omp_get_num_procs() - run; /* run counts this thread */
  if (run > 0 && T > idle + 1) T = idle < 0 ? 1 : idle + 1;
#endif
  return T;
}

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

void lg_abort_run(const char *msg) {
  int size = lg_mpi_size();
  if (size > 1) fprintf(stderr, "lugal: rank %d of %d: %s\n", lg_mpi_rank(), size, msg);
  else fprintf(stderr, "%s\n", msg);
  fflush(stderr);
  if (size > 1) MPI_Abort(PETSC_COMM_WORLD, 1);
}
