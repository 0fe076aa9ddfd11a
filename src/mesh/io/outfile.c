/* outfile.c — safe output files (outfile.h): write to a temporary name, rename at the end. */
#include "outfile.h"

#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <signal.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

/* ---------------------------------------------------------------- tracked temporary files */

/* The temporary files that exist now, for the signal handler to remove. Process-wide by
 * nature (a signal handler has no context to be given): written only by the thread that
 * writes files, each slot's path set after its string is complete and cleared before it is
 * freed, so that the handler sees either a whole path or none. */
#define TRACKED 64
static char *volatile tracked_path[TRACKED];
static volatile pid_t tracked_pid[TRACKED];

int outfile_track(const char *path, pid_t pid) {
  for (int i = 0; i < TRACKED; i++)
    if (!tracked_path[i]) {
      char *p = strdup(path);
      if (!p) return -1;
      tracked_pid[i] = pid;
      tracked_path[i] = p;
      return i;
    }
  return -1; /* more at once than tracked: still written safely, only not removed on a signal */
}

void outfile_untrack(int slot) {
  if (slot < 0 || slot >= TRACKED) return;
  char *p = tracked_path[slot];
  tracked_path[slot] = NULL;
  tracked_pid[slot] = 0;
  free(p);
}

/* (async-signal-safe calls only: kill, waitpid, unlink, nanosleep, signal, raise) */
static void on_signal(int sig) {
  int waited = 0;
  for (int i = 0; i < TRACKED; i++) {
    pid_t pid = tracked_pid[i];
    if (pid <= 0) continue;
    /* the compiler's whole process group (its driver, the assembler, the linker), then the
     * driver reaped, so that nothing writes the output after it is removed */
    kill(-pid, SIGTERM);
    kill(pid, SIGTERM);
    while (waitpid(pid, NULL, 0) < 0 && errno == EINTR) {}
    waited = 1;
  }
  for (int pass = 0; pass < 1 + waited; pass++) {
    if (pass) { /* a killed linker may have created its output as it died */
      struct timespec ts = {0, 20000000};
      nanosleep(&ts, NULL);
    }
    for (int i = 0; i < TRACKED; i++) {
      char *p = tracked_path[i];
      if (p) unlink(p);
    }
  }
  signal(sig, SIG_DFL);
  raise(sig);
}

void outfile_on_signals(void) {
  static const int sigs[] = {SIGINT, SIGTERM, SIGHUP, SIGQUIT};
  for (size_t i = 0; i < sizeof sigs / sizeof sigs[0]; i++) {
    struct sigaction old, sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sigemptyset(&sa.sa_mask);
    /* a signal the run was started ignoring (nohup) stays ignored */
    if (sigaction(sigs[i], NULL, &old) == 0 && old.sa_handler == SIG_IGN) continue;
    sigaction(sigs[i], &sa, NULL);
  }
  signal(SIGXFSZ, SIG_IGN);
}

/* ---------------------------------------------------------------- one output file */

/* the file path names once its symbolic links are followed (a link's relative target is
 * relative to the link's folder); NULL and errno when there are too many or one cannot be
 * read */
static char *follow_links(const char *path) {
  char *cur = strdup(path);
  for (int hop = 0; cur && hop < 40; hop++) {
    struct stat st;
    if (lstat(cur, &st) || !S_ISLNK(st.st_mode)) return cur;
    char to[PATH_MAX];
    ssize_t n = readlink(cur, to, sizeof to - 1);
    if (n < 0) { free(cur); return NULL; }
    to[n] = 0;
    const char *slash = strrchr(cur, '/');
    size_t dl = to[0] == '/' || !slash ? 0 : (size_t)(slash - cur) + 1;
    char *next = malloc(dl + (size_t)n + 1);
    if (next) {
      memcpy(next, cur, dl);
      memcpy(next + dl, to, (size_t)n + 1);
    }
    free(cur);
    cur = next;
  }
  if (cur) { free(cur); errno = ELOOP; }
  return NULL;
}

static void untrack_free(outfile *o) {
  outfile_untrack(o->slot);
  free(o->path);
  free(o->tmp);
  o->path = o->tmp = NULL;
  o->slot = -1;
}

int outfile_open(outfile *o, const char *path, char *err, size_t errlen) {
  memset(o, 0, sizeof *o);
  o->slot = -1;
  err[0] = 0;
  size_t n = strlen(path);
  if (n == 0) { snprintf(err, errlen, "cannot write a file with an empty name"); return 1; }
  if (path[n - 1] == '/') { snprintf(err, errlen, "cannot write %s: it names a folder", path); return 1; }
  if (!(o->path = follow_links(path))) {
    snprintf(err, errlen, "cannot write %s: %s", path, errno == ELOOP ? "too many levels of symbolic links" : strerror(errno));
    return 1;
  }
  /* the temporary file beside the file replaced, under a short name: a target name of any
   * legal length leaves room for it */
  const char *slash = strrchr(o->path, '/');
  size_t dl = slash ? (size_t)(slash - o->path) + 1 : 0;
  o->tmp = malloc(dl + 48);
  if (!o->tmp) {
    untrack_free(o);
    snprintf(err, errlen, "cannot write %s: out of memory", path);
    return 1;
  }
  struct stat st;
  int existing = !stat(o->path, &st) && S_ISREG(st.st_mode);
  if (!existing && !stat(o->path, &st) && !S_ISDIR(st.st_mode)) {
    /* a device or a pipe (/dev/stdout, a FIFO): written in place, there is nothing to replace */
    free(o->tmp);
    o->tmp = NULL;
    if (!(o->f = fopen(o->path, "w"))) {
      snprintf(err, errlen, "cannot write %s: %s", path, strerror(errno));
      untrack_free(o);
      return 1;
    }
    return 0;
  }
  static unsigned counter;
  for (int attempt = 0; attempt < 100; attempt++) {
    memcpy(o->tmp, o->path, dl);
    snprintf(o->tmp + dl, 48, ".lugal%lx-%x.tmp", (unsigned long)getpid(), counter++);
    int fd = open(o->tmp, O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
    if (fd < 0) {
      if (errno == EEXIST) continue;
      snprintf(err, errlen, "cannot write %s: %s", path, strerror(errno));
      break;
    }
    o->slot = outfile_track(o->tmp, 0);
    /* rewriting a file keeps its permissions (a chmod 600 result stays private) */
    if (existing) (void)fchmod(fd, st.st_mode & 07777);
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
  untrack_free(o);
  return 1;
}

int outfile_finish(outfile *o, char *err, size_t errlen) {
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
  if (bad) {
    snprintf(err, errlen, "error writing %s: %s", o->path, strerror(e ? e : EIO));
    if (o->tmp) unlink(o->tmp);
    untrack_free(o);
  } else if (!o->tmp) untrack_free(o); /* written in place: nothing to publish */
  return bad;
}

int outfile_publish(outfile *o, char *err, size_t errlen) {
  if (!o->path) return 0; /* written in place (a device or a pipe) */
  if (!o->tmp || o->f) { snprintf(err, errlen, "internal error: no finished output file"); return 1; }
  int bad = rename(o->tmp, o->path) != 0;
  if (bad) {
    snprintf(err, errlen, "error writing %s: %s", o->path, strerror(errno));
    unlink(o->tmp);
  }
  untrack_free(o);
  return bad;
}

int outfile_commit(outfile *o, char *err, size_t errlen) {
  return outfile_finish(o, err, errlen) || outfile_publish(o, err, errlen);
}

int outfile_end(outfile *o, outfile *staged, char *err, size_t errlen) {
  if (!staged) return outfile_commit(o, err, errlen);
  int rc = outfile_finish(o, err, errlen);
  *staged = *o;
  return rc;
}

void outfile_abort(outfile *o) {
  if (o->f) fclose(o->f);
  o->f = NULL;
  if (o->tmp) unlink(o->tmp);
  untrack_free(o);
}
