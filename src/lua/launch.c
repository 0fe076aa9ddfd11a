/* launch.c — the `lugal` command: sets the process environment that must be in place
 * before the runner (lugal-core: PETSc, MPI, Lua) is loaded, then executes the runner in
 * its place (same process, same arguments, so mpiexec, signals and exit codes are the
 * runner's).
 *
 * What it sets, where asked (-lugal_hugepages 1): glibc's malloc tunable
 * glibc.malloc.hugetlb=1, so that the large arrays of a run (sparsity patterns, element
 * places, matrix values, PETSc's vectors and factors) are backed by transparent huge pages
 * where the kernel offers them (THP in "madvise" mode, Debian's default). glibc reads its
 * tunables once, when the process starts, so the runner cannot set it for itself. It was the
 * default until issue 56: on the virtual machines this project runs on, a 4 KiB page fault
 * had cost 12-20 us. Now it costs 1.5 us there, and the machine hands memory that stays free
 * for about 2 s back to its host (free page reporting, in blocks of 8 MB): a huge page comes
 * from exactly those blocks, and its first touch faults in the host 512 times (7-10 us per
 * 4 KiB). A run after a moment's idleness took 2.5-3.7x as long to set up on huge pages
 * (P2 elasticity N = 24: 0.47 against 0.16 s; the 3D Poisson solve at N = 48, whole
 * process, 1.28 against 1.07 s), and gained 20-40% only when it followed another run
 * within a second (bench/hugepages.sh, bench/RESULTS.md "Huge pages, again").
 *
 * The user keeps control: an existing glibc.malloc.hugetlb in GLIBC_TUNABLES is left as it
 * is, and without -lugal_hugepages 1 the environment is untouched.
 *
 * And GOMP_SPINCOUNT=1000 (libgomp reads it when the runner loads), unless the user set it
 * or OMP_WAIT_POLICY: a thread that waits at a barrier or between parallel regions spins
 * 1000 times (microseconds), not libgomp's default 300 000, before it sleeps. Spinning
 * threads took the core the working thread or the tiered JIT's background compiler needed:
 * beside one busy process the P2 elasticity reassembly at N = 24 took 0.52-0.70 s with the
 * default against 0.36-0.46 s, and the first matrix 1.05-1.34 s against 0.58-0.78 s; on a
 * quiet machine the first matrix 0.31-1.06 s against 0.33-0.38 s, the reassembly about the
 * same (bench/RESULTS.md, issue 56). Links libc only: this costs one exec of a small program
 * (about a millisecond). */
#include <errno.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

/* the runner beside this program (the build tree), or in PREFIX/libexec/lugal (installed) */
static int find_core(char *out, size_t n) {
  char self[PATH_MAX];
  ssize_t len = readlink("/proc/self/exe", self, sizeof self - 1);
  if (len <= 0) return 1;
  self[len] = 0;
  char *slash = strrchr(self, '/');
  if (!slash) return 1;
  *slash = 0;
  static const char *const rel[] = {"/lugal-core", "/../libexec/lugal/lugal-core"};
  for (size_t i = 0; i < sizeof rel / sizeof rel[0]; i++) {
    if ((size_t)snprintf(out, n, "%s%s", self, rel[i]) >= n) continue;
    if (access(out, X_OK) == 0) return 0;
  }
  return 1;
}

static int hugepages_wanted(int argc, char **argv) {
  for (int i = 1; i + 1 < argc; i++)
    if (!strcmp(argv[i], "-lugal_hugepages"))
      return !(!strcmp(argv[i + 1], "0") || !strcmp(argv[i + 1], "false") || !strcmp(argv[i + 1], "no"));
  return 0;
}

int main(int argc, char **argv) {
  char core[PATH_MAX + 64];
  if (find_core(core, sizeof core)) {
    fprintf(stderr, "lugal: cannot find the runner lugal-core beside %s or in ../libexec/lugal (a broken "
                    "installation?)\n", argc > 0 ? argv[0] : "lugal");
    return 127;
  }
  if (hugepages_wanted(argc, argv)) {
    const char *old = getenv("GLIBC_TUNABLES");
    if (!old || !*old) setenv("GLIBC_TUNABLES", "glibc.malloc.hugetlb=1", 1);
    else if (!strstr(old, "glibc.malloc.hugetlb=")) {
      size_t n = strlen(old) + sizeof ":glibc.malloc.hugetlb=1";
      char *v = malloc(n);
      if (v) {
        snprintf(v, n, "%s:glibc.malloc.hugetlb=1", old);
        setenv("GLIBC_TUNABLES", v, 1);
        free(v);
      }
    }
  }
  if (!getenv("GOMP_SPINCOUNT") && !getenv("OMP_WAIT_POLICY")) setenv("GOMP_SPINCOUNT", "1000", 1);
  execv(core, argv);
  fprintf(stderr, "lugal: cannot run %s: %s\n", core, strerror(errno));
  return 127;
}
