/* checkpoint.h — internal to src/assemble/optimize: the snapshot store of the binomial
 * schedules (checkpoint.c). It needs the process room alone (errors, the clock, the rank),
 * so that tests/fuzz/fuzz_checkpoint.c builds it on its own. */
#ifndef LUGAL_CHECKPOINT_H
#define LUGAL_CHECKPOINT_H

#include "../process/process.h"

#include <stddef.h>

/* checkpoint.c: the snapshots of the binomial schedules, slots of at most n values in
 * memory (ram) and on disk (disk, files in a private directory made under parent: TMPDIR or
 * /tmp when NULL). put stores X_k (len values; on disk when asked and a disk slot is free,
 * else in memory); get gives X_k (a disk slot read into a buffer valid until the next get,
 * its header checked: the step and len); drop frees k's slot (and its file), clear every
 * slot; resize changes n (and clears); stats: files written and read, the directory. */
typedef struct lg_ckstore lg_ckstore;
lg_ckstore *lg_ckstore_new(lg_env *env, int ram, int disk, const char *parent, size_t n);
void lg_ckstore_free(lg_ckstore *s);
int lg_ckstore_put(lg_env *env, lg_ckstore *s, int k, int disk, const double *X, size_t len);
const double *lg_ckstore_get(lg_env *env, lg_ckstore *s, int k, size_t len);
int lg_ckstore_has(const lg_ckstore *s, int k);
void lg_ckstore_drop(lg_ckstore *s, int k);
void lg_ckstore_clear(lg_ckstore *s);
int lg_ckstore_resize(lg_env *env, lg_ckstore *s, size_t n);
void lg_ckstore_stats(const lg_ckstore *s, long *writes, long *reads, const char **dir);

#endif
