/* bench/pagefault.c — the cost of first touches of memory on this machine: 200 MB mapped,
 * one byte written per 4 KiB page, on 4 KiB pages and with MADV_HUGEPAGE (2 MiB pages where
 * the kernel's transparent huge pages allow them), three rounds each; then a memset of the
 * touched memory for comparison. Build and run:
 *   cc -O2 -o /tmp/pagefault bench/pagefault.c && /tmp/pagefault
 * (bench/RESULTS.md, "Issue 11: huge pages, the chunk pipeline and element ranks") */
#include <stdio.h>
#include <string.h>
#include <sys/mman.h>
#include <time.h>

static double now(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return t.tv_sec + t.tv_nsec * 1e-9;
}

int main(void) {
  size_t n = (size_t)200 << 20;
  for (int huge = 0; huge < 2; huge++)
    for (int r = 0; r < 3; r++) {
      double t0 = now();
      char *p = mmap(NULL, n, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
      if (p == MAP_FAILED) { perror("mmap"); return 1; }
      if (huge) madvise(p, n, MADV_HUGEPAGE);
      for (size_t i = 0; i < n; i += 4096) p[i] = 1;
      double t1 = now();
      memset(p, 2, n);
      double t2 = now();
      printf("%s pages: first touch %.1f ms (%.2f us per 4 KiB), memset after %.1f ms\n", huge ? "huge" : "4 KiB",
             (t1 - t0) * 1e3, (t1 - t0) * 1e6 / (double)(n / 4096), (t2 - t1) * 1e3);
      munmap(p, n);
    }
  return 0;
}
