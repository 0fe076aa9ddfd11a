/* outfile.c — safe output files (outfile.h): write to a temporary name, rename at the end. */
#include "outfile.h"

#include <errno.h>
#include <fcntl.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

int outfile_open(outfile *o, const char *path, char *err, size_t errlen) {
  memset(o, 0, sizeof *o);
  err[0] = 0;
  size_t n = strlen(path);
  if (n == 0) { snprintf(err, errlen, "cannot write a file with an empty name"); return 1; }
  if (path[n - 1] == '/') { snprintf(err, errlen, "cannot write %s: it names a folder", path); return 1; }
  o->path = strdup(path);
  o->tmp = malloc(n + 48);
  if (!o->path || !o->tmp) {
    free(o->path); free(o->tmp);
    o->path = o->tmp = NULL;
    snprintf(err, errlen, "cannot write %s: out of memory", path);
    return 1;
  }
  static unsigned counter;
  for (int attempt = 0; attempt < 100; attempt++) {
    snprintf(o->tmp, n + 48, "%s.tmp%ld.%u", path, (long)getpid(), counter++);
    int fd = open(o->tmp, O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
    if (fd < 0) {
      if (errno == EEXIST) continue;
      snprintf(err, errlen, "cannot write %s: %s", path, strerror(errno));
      break;
    }
    o->f = fdopen(fd, "w");
    if (!o->f) {
      snprintf(err, errlen, "cannot write %s: %s", path, strerror(errno));
      close(fd);
      unlink(o->tmp);
      break;
    }
    return 0;
  }
  if (!o->f && !err[0]) snprintf(err, errlen, "cannot write %s: no free temporary name", path);
  free(o->path); free(o->tmp);
  o->path = o->tmp = NULL;
  return 1;
}

int outfile_commit(outfile *o, char *err, size_t errlen) {
  if (!o->f) { snprintf(err, errlen, "internal error: no open output file"); return 1; }
  int bad = 0, e = 0;
  errno = 0;
  if (fflush(o->f) == EOF) { bad = 1; e = errno; }
  if (ferror(o->f) && !bad) {
    /* an earlier write failed and stdio kept no reason: the file is discarded anyway, so a
     * one-byte probe may fail again and tell why (a full disk, a size limit) */
    bad = 1;
    errno = 0;
    e = write(fileno(o->f), "\n", 1) < 0 ? errno : EIO;
  }
  if (fclose(o->f) == EOF && !bad) { bad = 1; e = errno; }
  o->f = NULL;
  if (!bad && rename(o->tmp, o->path)) { bad = 1; e = errno; }
  if (bad) {
    snprintf(err, errlen, "error writing %s: %s", o->path, strerror(e ? e : EIO));
    unlink(o->tmp);
  }
  free(o->path); free(o->tmp);
  o->path = o->tmp = NULL;
  return bad;
}

void outfile_abort(outfile *o) {
  if (o->f) fclose(o->f);
  if (o->tmp) unlink(o->tmp);
  free(o->path); free(o->tmp);
  memset(o, 0, sizeof *o);
}
