/* fuzz_checkpoint.c — the snapshot store's disk files (src/assemble/optimize/checkpoint.c)
 * read back after arbitrary bytes replaced or changed them: a time-dependent gradient reads
 * its checkpoints from a folder anyone with the user's rights can write. Each input stores
 * three states (one in memory, two on disk), then the first byte chooses what happens to
 * the second disk file: replaced by the input's remaining bytes, those bytes written over it
 * at an offset, or cut to a length. Reading it back must give exactly the state stored
 * (when the file is unchanged) or an error naming the file, never a crash, another state or
 * a read past the data; the other snapshots must read back unchanged; freeing the store must
 * remove the folder. Built with libFuzzer by `make fuzz` (checkpoint.c alone, the three
 * process functions it calls defined here). */
#include "../../src/assemble/optimize/checkpoint.h"

#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#define CFUZZ_CHECK(cond, what)                                                                       \
  do {                                                                                                \
    if (!(cond)) {                                                                                    \
      fprintf(stderr, "fuzz_checkpoint: invariant broken: %s (%s:%d)\n", what, __FILE__, __LINE__);  \
      abort();                                                                                        \
    }                                                                                                 \
  } while (0)

void lg_seterr(lg_env *env, const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(env->err, sizeof env->err, fmt, ap);
  va_end(ap);
}
double lg_now_ms(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}
int lg_mpi_rank(void) { return 0; }

#define NV 37 /* values per state */

static void state(double *X, int k) {
  for (int i = 0; i < NV; i++) X[i] = k + 0.001 * i - 1e-300 * (i == 3);
}

static int same(const double *a, const double *b) { return a && !memcmp(a, b, sizeof(double) * NV); }

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  static lg_env env;
  static char parent[64];
  if (!parent[0]) {
    snprintf(parent, sizeof parent, "/tmp/lugal-fuzz-ckpt-%d", (int)getpid());
    mkdir(parent, 0700);
  }
  lg_ckstore *s = lg_ckstore_new(&env, 1, 2, parent, NV);
  CFUZZ_CHECK(s, "a store in a writable folder");
  double X[3][NV];
  for (int k = 0; k < 3; k++) {
    state(X[k], 10 * k + 1);
    CFUZZ_CHECK(!lg_ckstore_put(&env, s, 10 * k + 1, k > 0, X[k], NV), "three snapshots stored");
  }
  const char *dir;
  lg_ckstore_stats(s, NULL, NULL, &dir);
  char path[512];
  snprintf(path, sizeof path, "%s/slot-1", dir); /* the second disk slot: step 21 */
  int changed = 0;
  if (size > 0) {
    int mode = data[0] % 3;
    data++, size--;
    FILE *f;
    struct stat st;
    CFUZZ_CHECK(!stat(path, &st), "the slot's file exists");
    if (mode == 0 && (f = fopen(path, "wb"))) { /* replaced */
      fwrite(data, 1, size, f);
      fclose(f);
      changed = 1;
    } else if (mode == 1 && size >= 2 && (f = fopen(path, "r+b"))) { /* bytes written at an offset */
      long off = (long)(data[0] | data[1] << 8) % (st.st_size + 8);
      fseek(f, off, SEEK_SET);
      fwrite(data + 2, 1, size - 2, f);
      fclose(f);
      changed = size > 2;
    } else if (mode == 2 && size >= 2) { /* cut */
      long len = (long)(data[0] | data[1] << 8) % (st.st_size + 1);
      CFUZZ_CHECK(!truncate(path, len), "truncate");
      changed = len < st.st_size;
    }
  }
  env.err[0] = 0;
  const double *g = lg_ckstore_get(&env, s, 21, NV);
  if (g) {
    /* a read that succeeds is the state stored: a changed file that still reads must hold
     * the same bytes (the fuzzer wrote them back) */
    CFUZZ_CHECK(same(g, X[2]), "a snapshot read back is the state stored");
  } else {
    CFUZZ_CHECK(changed, "an unchanged file reads back");
    CFUZZ_CHECK(strstr(env.err, "checkpoint file") && strstr(env.err, "slot-1"), "the error names the file");
  }
  CFUZZ_CHECK(same(lg_ckstore_get(&env, s, 1, NV), X[0]), "the snapshot in memory is untouched");
  CFUZZ_CHECK(same(lg_ckstore_get(&env, s, 11, NV), X[1]), "the other disk snapshot is untouched");
  CFUZZ_CHECK(!lg_ckstore_get(&env, s, 21, NV + 1), "a read of another length fails");
  char keep[512];
  snprintf(keep, sizeof keep, "%s", dir);
  lg_ckstore_free(s);
  struct stat st;
  CFUZZ_CHECK(stat(keep, &st) != 0, "the store's folder is removed with it");
  return 0;
}
