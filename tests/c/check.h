/* check.h — a minimal assertion harness for the C unit tests: each CHECK prints a line on
 * failure; a test program exits 1 when any check failed. */
#ifndef LUGAL_CHECK_H
#define LUGAL_CHECK_H
#include <math.h>
#include <stdio.h>
static int check_fail = 0, check_count = 0;
#define CHECK(cond, ...) do { check_count++; if (!(cond)) { check_fail++; \
  fprintf(stderr, "%s:%d: check failed: %s: ", __FILE__, __LINE__, #cond); \
  fprintf(stderr, __VA_ARGS__); fputc('\n', stderr); } } while (0)
#define CHECK_CLOSE(a, b, tol) CHECK(fabs((double)(a) - (double)(b)) <= (tol) * (1 + fabs((double)(b))), \
  "%.17g vs %.17g (tol %g)", (double)(a), (double)(b), (double)(tol))
#define CHECK_DONE() (printf("%d checks, %d failed\n", check_count, check_fail), check_fail ? 1 : 0)
#endif
