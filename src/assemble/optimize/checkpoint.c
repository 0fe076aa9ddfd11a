/* checkpoint.c — the snapshots of a time-dependent reduced functional (time_adjoint.c): slots
 * in memory and, for the multistage schedule, slots on disk. A slot holds the state X_k of
 * one step k (n values, the same n for every slot until lg_ckstore_resize).
 *
 * Disk slots live in a private directory made under the caller's (mkdtemp, one per store and
 * rank), one file per slot, written atomically (a temporary file renamed over the slot's)
 * with a header naming the step, the number of values and a hash of them (64-bit FNV-1a)
 * that a read checks: a slot read back is the state that was asked for, or an error
 * (tests/fuzz/fuzz_checkpoint.c found a changed value read back before the hash). Files are removed when their slot is
 * freed or the store cleared (at the end of a backward sweep, at an error), and the
 * directory with the store. */
#include "checkpoint.h"

#include <errno.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#define CK_MAGIC 0x4b43474cu /* "LGCK" */

typedef struct {
  uint32_t magic, version;
  int64_t step, n;
  uint64_t store; /* the store's nonce: a file of another store is not read */
  uint64_t hash;  /* of the values' bytes */
} ck_header;

static uint64_t fnv1a(const void *p, size_t n) {
  const unsigned char *b = p;
  uint64_t h = 1469598103934665603ull;
  for (size_t i = 0; i < n; i++) h = (h ^ b[i]) * 1099511628211ull;
  return h;
}

struct lg_ckstore {
  int ram, disk;
  size_t n;        /* values per slot at most */
  int *at;         /* slot i holds X_{at[i]}, -1 free: RAM slots 0 .. ram-1, then disk */
  size_t *len;     /* and len[i] values */
  double **mem;    /* the RAM slots */
  double *buf;     /* a disk slot read back */
  char *dir;       /* the private directory, or NULL */
  uint64_t nonce;
  long writes, reads;
};

lg_ckstore *lg_ckstore_new(lg_env *env, int ram, int disk, const char *parent, size_t n) {
  if (ram < 0 || disk < 0 || ram + disk < 1) { lg_seterr(env, "a checkpoint store holds at least one snapshot"); return NULL; }
  lg_ckstore *s = calloc(1, sizeof *s);
  if (!s) { lg_seterr(env, "out of memory"); return NULL; }
  s->ram = ram;
  s->disk = disk;
  s->n = n;
  s->nonce = ((uint64_t)getpid() << 32) ^ (uint64_t)(uintptr_t)s ^ (uint64_t)lg_now_ms();
  int bad = !(s->at = malloc(sizeof(int) * (size_t)(ram + disk))) || !(s->len = calloc((size_t)(ram + disk), sizeof(size_t))) || !(s->mem = calloc((size_t)ram + 1, sizeof(double *)));
  for (int i = 0; !bad && i < ram; i++) bad = !(s->mem[i] = malloc(sizeof(double) * (n + 1)));
  if (!bad && disk) bad = !(s->buf = malloc(sizeof(double) * (n + 1)));
  if (bad) {
    lg_ckstore_free(s);
    lg_seterr(env, "out of memory for %d snapshots of %zu values: use fewer in memory (checkpoints = {ram = ..., disk = ...})", ram, n);
    return NULL;
  }
  for (int i = 0; i < ram + disk; i++) s->at[i] = -1;
  if (disk) {
    const char *p = parent && *parent ? parent : getenv("TMPDIR");
    if (!p || !*p) p = "/tmp";
    if (mkdir(p, 0700) && errno != EEXIST) {
      lg_seterr(env, "the checkpoint directory %s cannot be made: %s", p, strerror(errno));
      lg_ckstore_free(s);
      return NULL;
    }
    size_t len = strlen(p) + 40;
    if (!(s->dir = malloc(len))) { lg_ckstore_free(s); lg_seterr(env, "out of memory"); return NULL; }
    snprintf(s->dir, len, "%s/lugal-ckpt-%d-XXXXXX", p, lg_mpi_rank()); /* mkdtemp's template: it fills the Xs */
    if (!mkdtemp(s->dir)) {
      lg_seterr(env, "no private checkpoint directory can be made in %s: %s", p, strerror(errno));
      free(s->dir);
      s->dir = NULL;
      lg_ckstore_free(s);
      return NULL;
    }
  }
  return s;
}

static void slot_path(const lg_ckstore *s, int i, int tmp, char *out, size_t len) {
  snprintf(out, len, "%s/slot-%d%s", s->dir, i - s->ram, tmp ? ".tmp" : "");
}

void lg_ckstore_clear(lg_ckstore *s) {
  if (!s) return;
  for (int i = 0; i < s->ram + s->disk; i++) lg_ckstore_drop(s, s->at[i]);
}

void lg_ckstore_free(lg_ckstore *s) {
  if (!s) return;
  if (s->at) lg_ckstore_clear(s);
  if (s->dir) rmdir(s->dir);
  if (s->mem)
    for (int i = 0; i < s->ram; i++) free(s->mem[i]);
  free(s->mem);
  free(s->at);
  free(s->len);
  free(s->buf);
  free(s->dir);
  free(s);
}

int lg_ckstore_resize(lg_env *env, lg_ckstore *s, size_t n) {
  for (int i = 0; i < s->ram; i++) {
    double *m = realloc(s->mem[i], sizeof(double) * (n + 1));
    if (!m) { lg_seterr(env, "out of memory for the snapshots (%zu values each)", n); return 1; }
    s->mem[i] = m;
  }
  if (s->buf) {
    double *m = realloc(s->buf, sizeof(double) * (n + 1));
    if (!m) { lg_seterr(env, "out of memory for the snapshots (%zu values each)", n); return 1; }
    s->buf = m;
  }
  lg_ckstore_clear(s);
  s->n = n;
  return 0;
}

static int find(const lg_ckstore *s, int k) {
  for (int i = 0; k >= 0 && i < s->ram + s->disk; i++)
    if (s->at[i] == k) return i;
  return -1;
}

int lg_ckstore_has(const lg_ckstore *s, int k) { return find(s, k) >= 0; }

void lg_ckstore_drop(lg_ckstore *s, int k) {
  int i = find(s, k);
  if (i < 0) return;
  if (i >= s->ram) {
    char path[4096];
    slot_path(s, i, 0, path, sizeof path);
    unlink(path);
  }
  s->at[i] = -1;
}

/* a free slot: on disk when asked and one is free, else in memory, else any */
static int take(const lg_ckstore *s, int disk) {
  int lo = disk ? s->ram : 0, hi = disk ? s->ram + s->disk : s->ram;
  for (int pass = 0; pass < 2; pass++) {
    for (int i = lo; i < hi; i++)
      if (s->at[i] < 0) return i;
    lo = 0;
    hi = s->ram + s->disk;
  }
  return -1;
}

static int write_file(lg_env *env, lg_ckstore *s, int i, int k, const double *X, size_t len) {
  char tmp[4096], path[4096];
  slot_path(s, i, 1, tmp, sizeof tmp);
  slot_path(s, i, 0, path, sizeof path);
  FILE *f = fopen(tmp, "wb");
  if (!f) { lg_seterr(env, "checkpoint file %s cannot be written: %s", tmp, strerror(errno)); return 1; }
  ck_header h = {CK_MAGIC, 2, k, (int64_t)len, s->nonce, fnv1a(X, sizeof(double) * len)};
  int bad = fwrite(&h, sizeof h, 1, f) != 1 || fwrite(X, sizeof(double), len, f) != len;
  int err = errno;
  bad |= fclose(f) != 0;
  if (bad || rename(tmp, path)) {
    if (!bad) err = errno;
    unlink(tmp);
    lg_seterr(env, "checkpoint file %s: writing the state of step %d failed (%s)", path, k, strerror(err));
    return 1;
  }
  s->writes++;
  return 0;
}

int lg_ckstore_put(lg_env *env, lg_ckstore *s, int k, int disk, const double *X, size_t len) {
  lg_ckstore_drop(s, k);
  int i = take(s, disk);
  if (i < 0 || len > s->n) { lg_seterr(env, "internal error: no free snapshot for step %d", k); return 1; }
  if (i < s->ram) memcpy(s->mem[i], X, sizeof(double) * len);
  else if (write_file(env, s, i, k, X, len)) return 1;
  s->at[i] = k;
  s->len[i] = len;
  return 0;
}

const double *lg_ckstore_get(lg_env *env, lg_ckstore *s, int k, size_t len) {
  int i = find(s, k);
  if (i < 0 || s->len[i] != len) { lg_seterr(env, "internal error: no snapshot of step %d (%zu values)", k, len); return NULL; }
  if (i < s->ram) return s->mem[i];
  char path[4096];
  slot_path(s, i, 0, path, sizeof path);
  FILE *f = fopen(path, "rb");
  if (!f) { lg_seterr(env, "checkpoint file %s (step %d) cannot be read: %s", path, k, strerror(errno)); return NULL; }
  ck_header h;
  int ok = fread(&h, sizeof h, 1, f) == 1 && h.magic == CK_MAGIC && h.version == 2 && h.store == s->nonce && h.step == k &&
           h.n == (int64_t)len && fread(s->buf, sizeof(double), len, f) == len && fgetc(f) == EOF &&
           h.hash == fnv1a(s->buf, sizeof(double) * len);
  fclose(f);
  if (!ok) {
    lg_seterr(env, "checkpoint file %s is not the state of step %d this sweep wrote (changed or truncated on disk?)", path, k);
    return NULL;
  }
  s->reads++;
  return s->buf;
}

void lg_ckstore_stats(const lg_ckstore *s, long *writes, long *reads, const char **dir) {
  if (writes) *writes = s ? s->writes : 0;
  if (reads) *reads = s ? s->reads : 0;
  if (dir) *dir = s ? s->dir : NULL;
}
