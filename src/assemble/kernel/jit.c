/* jit.c — compiling generated kernels: libtcc in memory (sub-millisecond), the system C
 * compiler into a private disk cache, or both in tiers (JIT_AUTO, the default): every kernel
 * starts in libtcc, and one whose assemblies have taken JIT_TIER_MS in all is compiled again
 * by the system compiler in a background process and swapped in when that is ready (polled at
 * each assembly: no threads). libtcc's code runs these kernels 4-5 times slower than gcc -O3
 * (degree-12 quadrature in an optimization loop: bench/RESULTS.md); a short script never
 * waits for gcc. Both tiers give the same bits (CC_FLAGS). */
#include "kernel.h"
#include "vmath.h"

#include "../../config.h"

#include <dlfcn.h>
#include <errno.h>
#ifndef LUGAL_NO_TCC
#include <libtcc.h>
#else
/* the standalone Lua module: Debian's libtcc is a non-PIC static archive that cannot be
 * linked into a shared object, so the module compiles kernels with the C compiler only */
typedef struct TCCState TCCState;
static void tcc_delete(TCCState *s) { (void)s; }
#endif
#include <fcntl.h>
#include <math.h>
#include <pwd.h>
#include <signal.h>
#include <spawn.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "../../mesh/io/outfile.h"

/* a system-compiler build: where its files are */
typedef struct {
  char dir[4200], cpath[4300], sopath[4300], tmpso[4340];
  char key[34]; /* "k" and 32 hex digits: the object's name, sealed into it (cache_seal) */
  int slot;     /* tmpso among the temporary files a signal removes (outfile_track), or -1 */
  int temp; /* no disk cache: a private folder removed after loading */
  int huge;
} cc_job;

typedef struct {
  uint64_t h1, h2;
  kernel_fn fn;  /* the best code so far */
  TCCState *tcc;
  void *dl;
  /* tiers (JIT_AUTO) */
  char *src;     /* kept until the system compiler has it */
  double ms;     /* time spent in assemblies with this kernel */
  double item_ms; /* the last assembly's thread time per item (jit_cost), 0: none yet */
  int tier;      /* JIT_TIER_* */
  pid_t pid;     /* the background compiler */
  cc_job *job;   /* the background build's files (JIT_TIER_COMPILING) */
} jit_entry;

enum { JIT_TIER_TCC, JIT_TIER_COMPILING, JIT_TIER_CC, JIT_TIER_STAYS };

struct lg_jit {
  jit_backend backend;
  char libdir[512];
  size_t n, cap;
  jit_entry *e;
  double tier_ms;
  int nice;           /* the background compilers' nice level (jit_set_nice) */
  int verbose;
  int cc_failed_told; /* the system compiler's failure was reported (once a run) */
};

lg_jit *jit_new(jit_backend b, const char *libdir) {
  lg_jit *j = calloc(1, sizeof *j);
  if (!j) return NULL;
#ifdef LUGAL_NO_TCC
  b = JIT_CC;
#endif
  j->backend = b;
  j->tier_ms = JIT_TIER_MS;
  j->nice = JIT_NICE;
  snprintf(j->libdir, sizeof j->libdir, "%s", libdir ? libdir : "");
  return j;
}

static void job_cleanup(cc_job *c) {
  if (!c) return;
  outfile_untrack(c->slot);
  c->slot = -1;
  unlink(c->tmpso);
  if (c->temp) { unlink(c->sopath); unlink(c->cpath); rmdir(c->dir); }
}

void jit_free(lg_jit *j) {
  if (!j) return;
  for (size_t i = 0; i < j->n; i++) {
    jit_entry *e = &j->e[i];
    if (e->tier == JIT_TIER_COMPILING) { /* a background compiler still running */
      kill(e->pid, SIGTERM);
      while (waitpid(e->pid, NULL, 0) < 0 && errno == EINTR) {}
      job_cleanup(e->job);
    }
    free(e->job);
    if (e->tcc) tcc_delete(e->tcc);
    if (e->dl) dlclose(e->dl);
    free(e->src);
  }
  free(j->e);
  free(j);
}

void jit_set_backend(lg_jit *j, jit_backend b) {
#ifdef LUGAL_NO_TCC
  b = JIT_CC;
#endif
  j->backend = b;
}
void jit_set_tier_ms(lg_jit *j, double ms) { j->tier_ms = ms; }
void jit_set_nice(lg_jit *j, int nice) { j->nice = nice; }
void jit_set_verbose(lg_jit *j, int v) { j->verbose = v; }
int jit_verbose(const lg_jit *j) { return j->verbose; }
size_t jit_count(const lg_jit *j) { return j->n; }

static void hash_src(const char *s, uint64_t *h1, uint64_t *h2) {
  uint64_t a = 1469598103934665603ull, b = 0x9E3779B97F4A7C15ull;
  for (; *s; s++) {
    a = (a ^ (unsigned char)*s) * 1099511628211ull;
    b = (b ^ (unsigned char)*s) * 0xff51afd7ed558ccdull;
    b ^= b >> 31;
  }
  *h1 = a;
  *h2 = b;
}

static double now_ms(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

/* a kernel with vector calls has a pointer to the vector math routine (vmath.c), set
 * when its code is loaded: one routine for both tiers, so that they agree to the bit */
static void set_vmath(void *slot) {
  if (slot) *(void (**)(int, double *, int))slot = lg_vmath;
}

#ifndef LUGAL_NO_TCC
typedef struct {
  char *buf;
  size_t len;
} tcc_errbuf;

static void tcc_err(void *ud, const char *msg) {
  tcc_errbuf *e = ud;
  size_t l = strlen(e->buf);
  if (l + 2 < e->len) snprintf(e->buf + l, e->len - l, "%s%s", l ? "; " : "", msg);
}

static double sign_fn(double x) { return (x > 0) - (x < 0); }

static kernel_fn compile_tcc(lg_jit *j, const char *src, jit_entry *ent, char *err, size_t errlen) {
  TCCState *s = tcc_new();
  if (!s) { snprintf(err, errlen, "libtcc: cannot create a compiler state"); return NULL; }
  err[0] = 0;
  tcc_errbuf eb = {err, errlen};
  tcc_set_error_func(s, &eb, tcc_err);
  if (j->libdir[0]) tcc_set_lib_path(s, j->libdir);
  tcc_set_options(s, "-nostdlib");
  tcc_set_output_type(s, TCC_OUTPUT_MEMORY);
  static const struct { const char *n; const void *f; } syms[] = {
      {"sin", (const void *)sin},   {"cos", (const void *)cos},   {"tan", (const void *)tan},
      {"exp", (const void *)exp},   {"log", (const void *)log},   {"sqrt", (const void *)sqrt},
      {"fabs", (const void *)fabs}, {"tanh", (const void *)tanh}, {"sinh", (const void *)sinh},
      {"cosh", (const void *)cosh}, {"atan", (const void *)atan}, {"asin", (const void *)asin},
      {"acos", (const void *)acos}, {"pow", (const void *)pow},   {"lugal_sign", (const void *)sign_fn}};
  for (size_t i = 0; i < sizeof syms / sizeof syms[0]; i++) tcc_add_symbol(s, syms[i].n, syms[i].f);
  if (tcc_compile_string(s, src) < 0 || tcc_relocate(s, TCC_RELOCATE_AUTO) < 0) {
    char tmp[1024];
    snprintf(tmp, sizeof tmp, "libtcc failed to compile a generated kernel: %s", err);
    snprintf(err, errlen, "%s", tmp);
    tcc_delete(s);
    return NULL;
  }
  kernel_fn fn = (kernel_fn)tcc_get_symbol(s, "lugal_kernel");
  if (!fn) { snprintf(err, errlen, "libtcc: generated kernel has no entry point"); tcc_delete(s); return NULL; }
  set_vmath(tcc_get_symbol(s, "lugal_vmath"));
  ent->tcc = s;
  return fn;
}

#endif

/* ---------------------------------------------------------------- the system compiler */

/* The disk cache of compiled kernels. A cached shared object is code this process will run,
 * so: the folder is private (created 0700; one that others can write to, or that another
 * user owns, is refused), every object is checked the same way before it is loaded, the key
 * covers the compiler, its flags and the CPU (a cache shared between machines must not run
 * AVX-512 code on a CPU without it), and the compiler is run from an argument vector, never
 * through a shell (a path with a quote in it is just a path). Without a home folder there is
 * no disk cache: objects go to a private temporary folder that is removed after loading. */
/* -ffp-contract=off: no fused multiply-adds, so that code from the system compiler gives the
 * same bits as libtcc's (which never fuses): a kernel moved to the faster tier (JIT_AUTO)
 * does not change an answer */
#define CC_FLAGS "-O3 -march=native -ffp-contract=off -fPIC -shared"
#define CC_HUGE (512 << 10) /* bytes of source past which kernels are compiled at -O0 */

static uint64_t fnv(uint64_t h, const void *p, size_t n) {
  const unsigned char *c = p;
  for (size_t i = 0; i < n; i++) h = (h ^ c[i]) * 1099511628211ull;
  return h;
}

/* what a compiled object depends on besides its source: the compiler (path, size, time),
 * its flags and this CPU's model and feature flags */
static uint64_t machine_key(void) {
  static uint64_t key;
  if (key) return key;
  /* the cache's format: objects of an older one (unsealed) keep their names and are never
   * looked at, rather than each reported as damaged */
  uint64_t h = fnv(1469598103934665603ull, "sealed-1", 8);
  h = fnv(h, LUGAL_CC, strlen(LUGAL_CC));
  h = fnv(h, CC_FLAGS, strlen(CC_FLAGS));
  struct stat st;
  if (!stat(LUGAL_CC, &st)) {
    h = fnv(h, &st.st_size, sizeof st.st_size);
    h = fnv(h, &st.st_mtime, sizeof st.st_mtime);
  }
  FILE *f = fopen("/proc/cpuinfo", "r");
  char line[8192];
  int got = 0;
  while (f && got < 2 && fgets(line, sizeof line, f))
    if (!strncmp(line, "flags", 5) || !strncmp(line, "model name", 10)) { h = fnv(h, line, strlen(line)); got++; }
  if (f) fclose(f);
  key = h | 1;
  return key;
}

/* a folder only this user can write to, or a message */
static int private_dir(const char *dir, char *err, size_t errlen) {
  if (mkdir(dir, 0700) && errno != EEXIST) {
    snprintf(err, errlen, "cannot create the kernel cache %s: %s", dir, strerror(errno));
    return 1;
  }
  struct stat st;
  if (lstat(dir, &st)) { snprintf(err, errlen, "cannot use the kernel cache %s: %s", dir, strerror(errno)); return 1; }
  if (!S_ISDIR(st.st_mode) || st.st_uid != geteuid() || (st.st_mode & 022)) {
    snprintf(err, errlen, "the kernel cache %s is not a private folder of this user (a link, another owner, or "
                          "writable by others): lugal will not load code from it (chmod 700 it, or set XDG_CACHE_HOME)", dir);
    return 1;
  }
  return 0;
}

/* the cache folder: $XDG_CACHE_HOME/lugal, else ~/.cache/lugal (home from $HOME or the
 * password database); 0 and an empty dir when there is no home */
static int cache_dir(char *dir, size_t len, char *err, size_t errlen) {
  const char *xdg = getenv("XDG_CACHE_HOME"), *home = getenv("HOME");
  char parent[4096];
  dir[0] = 0;
  if (xdg && xdg[0] == '/') {
    if (strlen(xdg) >= sizeof parent) {
      snprintf(err, errlen, "XDG_CACHE_HOME is %zu bytes long, longer than a path can be (%zu): no kernel cache there", strlen(xdg),
               sizeof parent - 1);
      return 1;
    }
    snprintf(parent, sizeof parent, "%s", xdg);
    mkdir(parent, 0700); /* the XDG base folder may not exist yet */
  } else {
    if (!home || home[0] != '/') {
      struct passwd *pw = getpwuid(geteuid());
      home = pw && pw->pw_dir && pw->pw_dir[0] == '/' ? pw->pw_dir : NULL;
    }
    if (!home || strlen(home) + 8 >= sizeof parent) return 0;
    snprintf(parent, sizeof parent, "%s/.cache", home);
    if (mkdir(parent, 0700) && errno != EEXIST) return 0;
  }
  if (strlen(parent) + 8 >= len) { snprintf(err, errlen, "the cache path %.100s... is too long", parent); return 1; }
  snprintf(dir, len, "%s/lugal", parent);
  return private_dir(dir, err, errlen);
}

/* The seal of a cached object: a line appended after the ELF image (the loader maps only
 * what the program headers name, so it reads past it) holding the key the object was
 * compiled for, the image's length and its hash. Checked before dlopen: another kernel's
 * object under this name, a truncated one (a power cut after the rename) or flipped bytes
 * are found before any of their code runs, and the entry is discarded and built again. */
#define SEAL_LEN 80 /* "\nLUGALSEAL1 " key(33) " " length(16) " " hash(16) padding "\n" */

static int seal_line(char *line, const char *key, unsigned long long len, unsigned long long hash) {
  char tmp[SEAL_LEN + 32];
  int n = snprintf(tmp, sizeof tmp, "\nLUGALSEAL1 %s %016llx %016llx", key, len, hash);
  if (n < 0 || n >= SEAL_LEN) return 1;
  memset(line, ' ', SEAL_LEN);
  memcpy(line, tmp, (size_t)n);
  line[SEAL_LEN - 1] = '\n';
  return 0;
}

/* the hash of the first len bytes of fd (from its start); 1 when they cannot be read */
static int hash_fd(int fd, unsigned long long len, unsigned long long *h) {
  unsigned char buf[65536];
  uint64_t a = 1469598103934665603ull;
  if (lseek(fd, 0, SEEK_SET) != 0) return 1;
  for (unsigned long long left = len; left;) {
    ssize_t got = read(fd, buf, left < sizeof buf ? (size_t)left : sizeof buf);
    if (got < 0 && errno == EINTR) continue;
    if (got <= 0) return 1;
    a = fnv(a, buf, (size_t)got);
    left -= (unsigned long long)got;
  }
  *h = a;
  return 0;
}

/* append the seal to the freshly built object and make it durable (fsync) */
static int cache_seal(const char *path, const char *key, char *err, size_t errlen) {
  int fd = open(path, O_RDWR | O_CLOEXEC);
  struct stat st;
  unsigned long long h;
  char line[SEAL_LEN];
  int bad = fd < 0 || fstat(fd, &st) || hash_fd(fd, (unsigned long long)st.st_size, &h) ||
            seal_line(line, key, (unsigned long long)st.st_size, h) || lseek(fd, 0, SEEK_END) < 0 ||
            write(fd, line, SEAL_LEN) != SEAL_LEN || fsync(fd);
  if (bad) snprintf(err, errlen, "cannot seal the compiled kernel %s: %s", path, strerror(errno ? errno : EIO));
  if (fd >= 0) close(fd);
  return bad;
}

/* 0 when path is an object sealed for key, intact */
static int cache_check(const char *path, const char *key) {
  int fd = open(path, O_RDONLY | O_CLOEXEC);
  if (fd < 0) return 1;
  struct stat st;
  char got[SEAL_LEN], want[SEAL_LEN];
  unsigned long long len, h;
  int bad = fstat(fd, &st) || st.st_size <= SEAL_LEN;
  if (!bad) {
    len = (unsigned long long)st.st_size - SEAL_LEN;
    bad = pread(fd, got, SEAL_LEN, (off_t)len) != SEAL_LEN || hash_fd(fd, len, &h) || seal_line(want, key, len, h) ||
          memcmp(got, want, SEAL_LEN);
  }
  close(fd);
  return bad;
}

/* the folder's entry made durable too (the rename of an object into it) */
static void sync_dir(const char *dir) {
  int fd = open(dir, O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd >= 0) { fsync(fd); close(fd); }
}

/* run the compiler on cpath into sopath; its messages into out */
/* start the compiler on c->cpath into c->tmpso; its messages into outfd (-1: /dev/null) */
static int cc_spawn(cc_job *c, int outfd, pid_t *pid, char *err, size_t errlen) {
  char *opt[] = {(char *)LUGAL_CC, "-O3", "-march=native", "-ffp-contract=off", "-fPIC", "-shared", "-o",
                 (char *)c->tmpso, (char *)c->cpath, "-lm", NULL};
  char *noopt[] = {(char *)LUGAL_CC, "-O0", "-fPIC", "-shared", "-o", (char *)c->tmpso, (char *)c->cpath, "-lm", NULL};
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  if (outfd >= 0) {
    posix_spawn_file_actions_adddup2(&fa, outfd, 1);
    posix_spawn_file_actions_adddup2(&fa, outfd, 2);
  } else {
    posix_spawn_file_actions_addopen(&fa, 1, "/dev/null", O_WRONLY, 0);
    posix_spawn_file_actions_addopen(&fa, 2, "/dev/null", O_WRONLY, 0);
  }
  /* its own process group: a signal that ends the run ends the compiler's whole group
   * (outfile_on_signals), and a Ctrl-C at the terminal reaches lugal, which does that */
  posix_spawnattr_t at;
  posix_spawnattr_init(&at);
  posix_spawnattr_setflags(&at, POSIX_SPAWN_SETPGROUP);
  posix_spawnattr_setpgroup(&at, 0);
  extern char **environ;
  int rc = posix_spawnp(pid, LUGAL_CC, &fa, &at, c->huge ? noopt : opt, environ);
  posix_spawnattr_destroy(&at);
  posix_spawn_file_actions_destroy(&fa);
  if (rc) snprintf(err, errlen, "cannot run the C compiler %s: %s", LUGAL_CC, strerror(rc));
  /* a run ended by a signal ends the compiler and removes its output (Ctrl-C during a
   * background build left gcc's temporary object in the cache for good) */
  else c->slot = outfile_track(c->tmpso, *pid);
  return rc;
}

/* a compiler reaped: its output stays tracked, its pid no longer (it may be reused) */
static void track_done(cc_job *c) {
  outfile_untrack(c->slot);
  c->slot = outfile_track(c->tmpso, 0);
}

/* run the compiler and wait; its messages into out */
static int cc_run(cc_job *c, char *out, size_t outlen) {
  int pfd[2];
  if (pipe(pfd)) { snprintf(out, outlen, "cannot make a pipe: %s", strerror(errno)); return -1; }
  fcntl(pfd[0], F_SETFD, FD_CLOEXEC);
  pid_t pid;
  if (cc_spawn(c, pfd[1], &pid, out, outlen)) { close(pfd[0]); close(pfd[1]); return -1; }
  close(pfd[1]);
  size_t n = 0;
  for (ssize_t got; (got = read(pfd[0], out + n, outlen - 1 - n)) != 0;) {
    if (got < 0) { if (errno == EINTR) continue; break; }
    n += (size_t)got;
    if (n + 1 >= outlen) { /* drain the rest */
      char sink[512];
      while (read(pfd[0], sink, sizeof sink) > 0) {}
      break;
    }
  }
  out[n] = 0;
  close(pfd[0]);
  int status;
  while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {}
  track_done(c);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

/* the source of a build: the kernel and its key as a symbol (checked after loading) */
static int cc_write_source(const cc_job *c, const char *src, char *err, size_t errlen) {
  outfile o;
  if (outfile_open(&o, c->cpath, err, errlen)) return 1;
  fprintf(o.f, "const char lugal_kernel_key[] = \"%s\";\n", c->key);
  fputs("double lugal_sign(double x) { return (x > 0) - (x < 0); }\n", o.f);
  fputs(src, o.f);
  return outfile_commit(&o, err, errlen);
}

/* a damaged cache entry is worth a line: it is removed and built again */
static void jit_note_damaged(const char *why) { fprintf(stderr, "lugal: %s: removed, compiling it again\n", why); }

/* the files of a build, and the source written unless the object is cached: 1 when the
 * object is there already, 0 when it must be compiled, -1 on an error */
static int cc_prepare(const char *src, uint64_t h1, uint64_t h2, cc_job *c, char *err, size_t errlen) {
  memset(c, 0, sizeof *c);
  c->slot = -1;
  if (cache_dir(c->dir, sizeof c->dir, err, errlen)) return -1;
  c->temp = !c->dir[0];
  if (c->temp) {
    const char *t = getenv("TMPDIR");
    if (!t || t[0] != '/' || strlen(t) > 1024) t = "/tmp";
    snprintf(c->dir, sizeof c->dir, "%s/lugal-kernel-XXXXXX", t);
    if (!mkdtemp(c->dir)) { snprintf(err, errlen, "cannot create a temporary folder for a kernel: %s", strerror(errno)); return -1; }
  }
  /* a huge kernel (a very deep expression) takes gcc minutes at -O1 and up, and seconds
   * at -O0 (an 8 MB kernel: > 5 min and 12 s here) */
  c->huge = strlen(src) > CC_HUGE;
  uint64_t mk = machine_key() ^ (c->huge ? 0x9e3779b97f4a7c15ull : 0);
  snprintf(c->key, sizeof c->key, "k%016llx%016llx", (unsigned long long)(h1 ^ mk), (unsigned long long)h2);
  snprintf(c->cpath, sizeof c->cpath, "%s/%s.c", c->dir, c->key);
  snprintf(c->sopath, sizeof c->sopath, "%s/%s.so", c->dir, c->key);
  static unsigned seq;
  snprintf(c->tmpso, sizeof c->tmpso, "%s.%ld.%u.tmp", c->sopath, (long)getpid(), seq++);
  struct stat st;
  int have = !lstat(c->sopath, &st);
  if (have && (!S_ISREG(st.st_mode) || st.st_uid != geteuid() || (st.st_mode & 022))) {
    snprintf(err, errlen, "the cached kernel %s is not a private file of this user: lugal will not load it (remove it)", c->sopath);
    return -1;
  }
  if (have) return 1;
  return cc_write_source(c, src, err, errlen) ? -1 : 0;
}

/* A finished build: the object sealed and put under its name (others may be loading the same
 * one: rename is atomic), then checked and loaded. A cached object that is not the kernel
 * asked for, or not intact, is removed: NULL with *damaged = 1, and the caller builds it
 * again. */
static kernel_fn cc_finish(cc_job *c, int built, jit_entry *ent, int *damaged, char *err, size_t errlen) {
  *damaged = 0;
  if (built) {
    outfile_untrack(c->slot); /* renamed below, or removed */
    c->slot = outfile_track(c->tmpso, 0);
    if (cache_seal(c->tmpso, c->key, err, errlen)) { job_cleanup(c); return NULL; }
    chmod(c->tmpso, 0700);
    if (rename(c->tmpso, c->sopath)) {
      snprintf(err, errlen, "cannot rename %s: %s", c->tmpso, strerror(errno));
      job_cleanup(c);
      return NULL;
    }
    outfile_untrack(c->slot);
    c->slot = -1;
    sync_dir(c->dir);
  }
  void *dl = NULL;
  kernel_fn fn = NULL;
  const char *key = NULL;
  if (cache_check(c->sopath, c->key))
    snprintf(err, errlen, "the cached kernel %s is damaged or another kernel's (its seal does not match)", c->sopath);
  else if (!(dl = dlopen(c->sopath, RTLD_NOW | RTLD_LOCAL)))
    snprintf(err, errlen, "cannot load %s: %s", c->sopath, dlerror());
  else if (!(key = dlsym(dl, "lugal_kernel_key")) || strcmp(key, c->key))
    snprintf(err, errlen, "the cached kernel %s is another kernel's", c->sopath);
  else if (!(fn = (kernel_fn)(uintptr_t)dlsym(dl, "lugal_kernel")))
    snprintf(err, errlen, "%s has no kernel", c->sopath);
  if (!fn) {
    if (dl) dlclose(dl);
    unlink(c->sopath); /* never loaded again; the next build replaces it */
    *damaged = !built;
  }
  if (c->temp) { unlink(c->sopath); unlink(c->cpath); rmdir(c->dir); }
  if (!fn) return NULL;
  set_vmath(dlsym(dl, "lugal_vmath"));
  ent->dl = dl;
  return fn;
}

/* build the object and load it; a cached object found damaged is built again, once */
static kernel_fn compile_cc(const char *src, uint64_t h1, uint64_t h2, jit_entry *ent, char *err, size_t errlen) {
  cc_job c;
  for (int attempt = 0; attempt < 2; attempt++) {
    int have = cc_prepare(src, h1, h2, &c, err, errlen), damaged;
    if (have < 0) return NULL;
    if (!have) {
      char out[512];
      int rc = cc_run(&c, out, sizeof out);
      if (rc != 0) {
        job_cleanup(&c);
        snprintf(err, errlen, "the C compiler failed on a generated kernel (%s): %s", c.cpath, out);
        return NULL;
      }
    }
    kernel_fn f = cc_finish(&c, !have, ent, &damaged, err, errlen);
    if (f || !damaged) return f;
    jit_note_damaged(err);
  }
  return NULL;
}

int jit_compile(lg_jit *j, const char *src, kernel_fn *fn, int *id, double *ms, int *cached, char *err, size_t errlen) {
  uint64_t h1, h2;
  hash_src(src, &h1, &h2);
  h2 ^= (uint64_t)j->backend;
  for (size_t i = 0; i < j->n; i++)
    if (j->e[i].h1 == h1 && j->e[i].h2 == h2) {
      if (ms) *ms = 0;
      if (cached) *cached = 1;
      *fn = j->e[i].fn;
      *id = (int)i;
      return 0;
    }
  if (j->n == j->cap) {
    size_t cap = j->cap ? 2 * j->cap : 16;
    jit_entry *ne = realloc(j->e, sizeof *ne * cap);
    if (!ne) { snprintf(err, errlen, "out of memory"); return 1; }
    j->e = ne;
    j->cap = cap;
  }
  jit_entry ent;
  memset(&ent, 0, sizeof ent);
  ent.h1 = h1;
  ent.h2 = h2;
  double t0 = now_ms();
#ifdef LUGAL_NO_TCC
  kernel_fn f = compile_cc(src, h1, h2, &ent, err, errlen);
  ent.tier = JIT_TIER_CC;
#else
  kernel_fn f = j->backend == JIT_CC ? compile_cc(src, h1, h2, &ent, err, errlen) : compile_tcc(j, src, &ent, err, errlen);
  ent.tier = j->backend == JIT_CC ? JIT_TIER_CC : j->backend == JIT_AUTO ? JIT_TIER_TCC : JIT_TIER_STAYS;
  if (!f && j->backend == JIT_CC) { /* the system compiler or its cache failed: libtcc's code, the same bits */
    if (!j->cc_failed_told++) fprintf(stderr, "lugal: %s; kernels run libtcc's code instead\n", err);
    f = compile_tcc(j, src, &ent, err, errlen);
    ent.tier = JIT_TIER_STAYS;
  }
  if (f && j->backend == JIT_AUTO && !(ent.src = strdup(src))) ent.tier = JIT_TIER_STAYS;
#endif
  if (!f) return 1;
  ent.fn = f;
  j->e[j->n] = ent;
  *id = (int)j->n++;
  *fn = f;
  if (ms) *ms = now_ms() - t0;
  if (cached) *cached = 0;
  return 0;
}

/* the background build of entry e: ended (blocking = 1 waits for it) or not yet */
static int tier_poll(lg_jit *j, jit_entry *e, int blocking) {
  int status = 0;
  pid_t r;
  while ((r = waitpid(e->pid, &status, blocking ? 0 : WNOHANG)) < 0 && errno == EINTR) {}
  if (r == 0) return 0;
  track_done(e->job);
  char err[1024] = "";
  kernel_fn f = NULL;
  int damaged;
  if (r == e->pid && WIFEXITED(status) && WEXITSTATUS(status) == 0) f = cc_finish(e->job, 1, e, &damaged, err, sizeof err);
  else {
    job_cleanup(e->job);
    snprintf(err, sizeof err, "the C compiler failed (status %d)", status);
  }
  free(e->job);
  e->job = NULL;
  if (f) {
    e->fn = f;
    e->tier = JIT_TIER_CC;
  } else e->tier = JIT_TIER_STAYS;
  if (j->verbose)
    fprintf(stderr, "lugal: kernel %d %s after %.0f ms in libtcc code%s%s\n", (int)(e - j->e),
            f ? "now runs the system compiler's code" : "stays in libtcc", e->ms, f ? "" : ": ", f ? "" : err);
  free(e->src);
  e->src = NULL;
  return f != NULL;
}

kernel_fn jit_current(lg_jit *j, int id, kernel_fn fallback) {
  if (id < 0 || (size_t)id >= j->n) return fallback;
  jit_entry *e = &j->e[id];
  if (e->tier == JIT_TIER_COMPILING) tier_poll(j, e, 0);
  return e->fn;
}

void jit_account(lg_jit *j, int id, double ms) {
  if (id < 0 || (size_t)id >= j->n) return;
  jit_entry *e = &j->e[id];
  e->ms += ms;
  if (e->tier != JIT_TIER_TCC || e->ms < j->tier_ms || !e->src) return;
  char err[1024];
  if (!(e->job = malloc(sizeof *e->job))) { e->tier = JIT_TIER_STAYS; return; }
  /* the name the cc backend gives the same source: both share the disk cache */
  uint64_t h2 = e->h2 ^ (uint64_t)JIT_AUTO ^ (uint64_t)JIT_CC;
  int have = cc_prepare(e->src, e->h1, h2, e->job, err, sizeof err), damaged = 0;
  if (have > 0) { /* compiled before (this run or an earlier one): load it now */
    kernel_fn f = cc_finish(e->job, 0, e, &damaged, err, sizeof err);
    if (f) {
      e->fn = f;
      e->tier = JIT_TIER_CC;
      if (j->verbose) fprintf(stderr, "lugal: kernel %d now runs the system compiler's cached code\n", (int)id);
    }
    if (damaged) {
      jit_note_damaged(err);
      have = cc_prepare(e->src, e->h1, h2, e->job, err, sizeof err); /* built again below */
    }
  }
  int spawned = !have && !cc_spawn(e->job, -1, &e->pid, err, sizeof err);
  /* the compiler's whole process group (the driver and the cc1, as and ld it starts) yields
   * to the run: at this nice level it takes a core only where none of the run's threads
   * wants it */
  if (spawned && j->nice > 0) setpriority(PRIO_PGRP, (id_t)e->pid, j->nice);
  if (!spawned) {
    if (!have) job_cleanup(e->job);
    if (e->tier != JIT_TIER_CC) e->tier = JIT_TIER_STAYS;
    free(e->job);
    e->job = NULL;
    free(e->src);
    e->src = NULL;
    return;
  }
  e->tier = JIT_TIER_COMPILING;
  if (j->verbose) fprintf(stderr, "lugal: kernel %d: %.0f ms in libtcc code, compiling it in the background\n", (int)id, e->ms);
}

void jit_cost(lg_jit *j, int id, long items, double thread_ms) {
  if (id < 0 || (size_t)id >= j->n || items <= 0) return;
  j->e[id].item_ms = thread_ms / (double)items;
}

double jit_item_ms(const lg_jit *j, int id) {
  if (id < 0 || (size_t)id >= j->n) return 0;
  return j->e[id].item_ms;
}

int jit_wait(lg_jit *j) {
  int n = 0;
  for (size_t i = 0; i < j->n; i++)
    if (j->e[i].tier == JIT_TIER_COMPILING) n += tier_poll(j, &j->e[i], 1);
  return n;
}

void jit_tiers(const lg_jit *j, int count[4]) {
  for (int t = 0; t < 4; t++) count[t] = 0;
  for (size_t i = 0; i < j->n; i++) count[j->e[i].tier]++;
}
