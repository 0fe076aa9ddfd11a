/* kernel.c — generated element kernels and the JIT. Generated C is self-contained (no
 * #include: it costs milliseconds in libtcc), names only generated identifiers, bakes the
 * basis tabulations in as static tables and hoists parameter-only subexpressions out of
 * the quadrature loop. */
#include "kernel.h"

#include "../config.h"

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
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <pwd.h>
#include <spawn.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "../mesh/outfile.h"

/* ---------------------------------------------------------------- JIT */

typedef struct {
  uint64_t h1, h2;
  kernel_fn fn;
  TCCState *tcc;
  void *dl;
} jit_entry;

struct lg_jit {
  jit_backend backend;
  char libdir[512];
  size_t n, cap;
  jit_entry *e;
};

lg_jit *jit_new(jit_backend b, const char *libdir) {
  lg_jit *j = calloc(1, sizeof *j);
  if (!j) return NULL;
#ifdef LUGAL_NO_TCC
  b = JIT_CC;
#endif
  j->backend = b;
  snprintf(j->libdir, sizeof j->libdir, "%s", libdir ? libdir : "");
  return j;
}

void jit_free(lg_jit *j) {
  if (!j) return;
  for (size_t i = 0; i < j->n; i++) {
    if (j->e[i].tcc) tcc_delete(j->e[i].tcc);
    if (j->e[i].dl) dlclose(j->e[i].dl);
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
#define CC_FLAGS "-O3 -march=native -fPIC -shared"
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
  uint64_t h = fnv(1469598103934665603ull, LUGAL_CC, strlen(LUGAL_CC));
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
  char parent[512];
  dir[0] = 0;
  if (xdg && xdg[0] == '/') {
    snprintf(parent, sizeof parent, "%s", xdg);
    mkdir(parent, 0700); /* the XDG base folder may not exist yet */
  } else {
    if (!home || home[0] != '/') {
      struct passwd *pw = getpwuid(geteuid());
      home = pw && pw->pw_dir && pw->pw_dir[0] == '/' ? pw->pw_dir : NULL;
    }
    if (!home) return 0;
    snprintf(parent, sizeof parent, "%s/.cache", home);
    if (mkdir(parent, 0700) && errno != EEXIST) return 0;
  }
  if (strlen(parent) + 8 >= len) { snprintf(err, errlen, "the cache path %.100s is too long", parent); return 1; }
  snprintf(dir, len, "%s/lugal", parent);
  return private_dir(dir, err, errlen);
}

/* run the compiler on cpath into sopath; its messages into out */
static int run_cc(const char *cpath, const char *sopath, int huge, char *out, size_t outlen) {
  char *opt[] = {(char *)LUGAL_CC, "-O3", "-march=native", "-fPIC", "-shared", "-o", (char *)sopath, (char *)cpath, "-lm", NULL};
  char *noopt[] = {(char *)LUGAL_CC, "-O0", "-fPIC", "-shared", "-o", (char *)sopath, (char *)cpath, "-lm", NULL};
  char **argv = huge ? noopt : opt;
  int pfd[2];
  if (pipe(pfd)) { snprintf(out, outlen, "cannot make a pipe: %s", strerror(errno)); return -1; }
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_adddup2(&fa, pfd[1], 1);
  posix_spawn_file_actions_adddup2(&fa, pfd[1], 2);
  posix_spawn_file_actions_addclose(&fa, pfd[0]);
  pid_t pid;
  extern char **environ;
  int rc = posix_spawnp(&pid, LUGAL_CC, &fa, NULL, argv, environ);
  posix_spawn_file_actions_destroy(&fa);
  close(pfd[1]);
  if (rc) {
    close(pfd[0]);
    snprintf(out, outlen, "cannot run the C compiler %s: %s", LUGAL_CC, strerror(rc));
    return -1;
  }
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
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

static kernel_fn compile_cc(const char *src, uint64_t h1, uint64_t h2, jit_entry *ent, char *err,
                            size_t errlen) {
  char dir[600], base[700], cpath[800], sopath[800];
  if (cache_dir(dir, sizeof dir, err, errlen)) return NULL;
  int temp = !dir[0];
  if (temp) { /* no home: a private folder for this one object */
    const char *t = getenv("TMPDIR");
    snprintf(dir, sizeof dir, "%s/lugal-kernel-XXXXXX", t && t[0] == '/' ? t : "/tmp");
    if (!mkdtemp(dir)) { snprintf(err, errlen, "cannot create a temporary folder for a kernel: %s", strerror(errno)); return NULL; }
  }
  /* a huge kernel (a very deep expression) takes gcc minutes at -O1 and up, and seconds
   * at -O0 (an 8 MB kernel: > 5 min and 12 s here) */
  int huge = strlen(src) > CC_HUGE;
  uint64_t mk = machine_key() ^ (huge ? 0x9e3779b97f4a7c15ull : 0);
  snprintf(base, sizeof base, "%s/k%016llx%016llx", dir, (unsigned long long)(h1 ^ mk), (unsigned long long)h2);
  snprintf(cpath, sizeof cpath, "%s.c", base);
  snprintf(sopath, sizeof sopath, "%s.so", base);
  struct stat st;
  int have = !lstat(sopath, &st);
  if (have && (!S_ISREG(st.st_mode) || st.st_uid != geteuid() || (st.st_mode & 022))) {
    snprintf(err, errlen, "the cached kernel %s is not a private file of this user: lugal will not load it (remove it)", sopath);
    return NULL;
  }
  if (!have) {
    outfile o;
    if (outfile_open(&o, cpath, err, errlen)) return NULL;
    fputs("double lugal_sign(double x) { return (x > 0) - (x < 0); }\n", o.f);
    fputs(src, o.f);
    if (outfile_commit(&o, err, errlen)) return NULL;
    char tmpso[820], out[512];
    static unsigned seq;
    snprintf(tmpso, sizeof tmpso, "%s.%ld.%u.tmp", sopath, (long)getpid(), seq++);
    int rc = run_cc(cpath, tmpso, huge, out, sizeof out);
    if (rc != 0) {
      unlink(tmpso);
      snprintf(err, errlen, "the C compiler failed on a generated kernel (%s): %s", cpath, out);
      return NULL;
    }
    chmod(tmpso, 0700);
    if (rename(tmpso, sopath)) {
      snprintf(err, errlen, "cannot rename %s: %s", tmpso, strerror(errno));
      unlink(tmpso);
      return NULL;
    }
  }
  void *dl = dlopen(sopath, RTLD_NOW | RTLD_LOCAL);
  if (temp) { unlink(sopath); unlink(cpath); rmdir(dir); }
  if (!dl) { snprintf(err, errlen, "cannot load %s: %s", sopath, dlerror()); return NULL; }
  kernel_fn fn = (kernel_fn)(uintptr_t)dlsym(dl, "lugal_kernel");
  if (!fn) { dlclose(dl); snprintf(err, errlen, "%s has no kernel", sopath); return NULL; }
  ent->dl = dl;
  return fn;
}

kernel_fn jit_compile(lg_jit *j, const char *src, double *ms, int *cached, char *err, size_t errlen) {
  uint64_t h1, h2;
  hash_src(src, &h1, &h2);
  h2 ^= (uint64_t)j->backend;
  for (size_t i = 0; i < j->n; i++)
    if (j->e[i].h1 == h1 && j->e[i].h2 == h2) {
      if (ms) *ms = 0;
      if (cached) *cached = 1;
      return j->e[i].fn;
    }
  if (j->n == j->cap) {
    size_t cap = j->cap ? 2 * j->cap : 16;
    jit_entry *ne = realloc(j->e, sizeof *ne * cap);
    if (!ne) { snprintf(err, errlen, "out of memory"); return NULL; }
    j->e = ne;
    j->cap = cap;
  }
  jit_entry ent = {h1, h2, NULL, NULL, NULL};
  double t0 = now_ms();
#ifdef LUGAL_NO_TCC
  kernel_fn fn = compile_cc(src, h1, h2, &ent, err, errlen);
#else
  kernel_fn fn = j->backend == JIT_CC ? compile_cc(src, h1, h2, &ent, err, errlen)
                                      : compile_tcc(j, src, &ent, err, errlen);
#endif
  if (!fn) return NULL;
  ent.fn = fn;
  j->e[j->n++] = ent;
  if (ms) *ms = now_ms() - t0;
  if (cached) *cached = 0;
  return fn;
}

/* ---------------------------------------------------------------- generation */

typedef struct {
  const lg_kernel *k;
  int dim;
} leafctx;

static int coef_index(const lg_kernel *k, int func) {
  for (int i = 0; i < k->ncoef; i++)
    if (k->coef_func[i] == func) return i;
  return -1;
}

static void leafname(void *ud, const expr *e, char *buf, size_t len) {
  leafctx *lc = ud;
  if (e->kind == E_COORD) { snprintf(buf, len, "x%d", e->i0); return; }
  if (e->kind == E_NORMAL) { snprintf(buf, len, "n%d", e->i0); return; }
  int ci = coef_index(lc->k, e->i0);
  int dir = -1;
  for (int d = 0; d < EXPR_MAXDIM; d++)
    if (e->alpha[d]) dir = d;
  if (dir < 0) snprintf(buf, len, "w%dv", ci);
  else snprintf(buf, len, "w%dg%d", ci, dir);
}

static void emit_table(strbuf *b, const char *name, const double *v, long n) {
  sb_printf(b, "static const double %s[%ld] = {", name, n);
  for (long i = 0; i < n; i++) sb_printf(b, "%s%.17g", i ? (i % 4 ? ", " : ",\n  ") : "", v[i]);
  sb_printf(b, "};\n");
}

static int leaf_dir(const expr *e) {
  for (int d = 0; d < EXPR_MAXDIM; d++)
    if (e->alpha[d]) return d;
  return -1;
}

/* name of the basis array for field leaf e of degree p: values b<p> or gradient g<p>_<d> */
static void basis_name(const expr *e, int p, char *buf, size_t len) {
  int d = leaf_dir(e);
  if (d < 0) snprintf(buf, len, "b%d", p);
  else snprintf(buf, len, "g%d_%d", p, d);
}

static int layout_find(const field_layout *l, int func) {
  for (int i = 0; i < l->n; i++)
    if (l->func[i] == func) return i;
  return -1;
}

/* does block (a, b) have any reference tensor */
static int block_used(unsigned char used[4][4]) {
  int any = 0;
  for (int k = 0; k < 4; k++)
    for (int l = 0; l < 4; l++) any |= used[k][l];
  return any;
}

#define KERR(...) do { snprintf(err, errlen, __VA_ARGS__); goto fail; } while (0)

char *kernel_source(expr_ctx *c, cell_type ct, int facet, int qdeg, const kernel_spec *s,
                    const field_layout *rows, const field_layout *cols, lg_kernel *k,
                    char *err, size_t errlen) {
  strbuf b = {0};
  expr_tape tape = {0};
  unsigned char *sel = NULL, *isconst = NULL, *pcls = NULL;
  int *pslot = NULL;
  int dim = cell_dim(ct);
  int nf = facet ? cell_nfacets(ct) : 1;
  memset(k, 0, sizeof *k);
  k->arity = s->arity;
  k->facet = facet;
  k->qdeg = qdeg;
  if (rows) k->rows = *rows;
  if (cols) k->cols = *cols;

  /* the coefficient expressions */
  int nroot = s->arity == 2 ? s->tab->njac : s->arity == 1 ? s->tab->nres : 1;
  expr **roots = malloc(sizeof(expr *) * (size_t)(nroot + 1));
  if (!roots) KERR("out of memory");
  for (int i = 0; i < nroot; i++)
    roots[i] = s->arity == 2 ? s->tab->jac[i] : s->arity == 1 ? s->tab->res[i] : s->integrand;
  if (expr_tape_build(c, nroot, roots, &tape)) { free(roots); KERR("%s", expr_error(c)); }
  free(roots);

  /* leaves: coefficient functions, coordinates, normals */
  int need_val[4] = {0, 0, 0, 0}, need_grad[4] = {0, 0, 0, 0}, need_x = 0, need_n = 0;
  for (int i = 0; i < tape.n; i++) {
    const expr *e = tape.node[i];
    if (e->kind == E_COORD) {
      if (e->i0 >= dim) KERR("the integrand uses the coordinate %c, but the mesh is %dD", "xyz"[e->i0], dim);
      need_x = 1;
    } else if (e->kind == E_NORMAL) {
      if (!facet) KERR("the normal vector can only be used in boundary integrals");
      if (e->i0 >= dim) KERR("the integrand uses normal component %d on a %dD mesh", e->i0 + 1, dim);
      need_n = 1;
    } else if (e->kind == E_FIELD) {
      expr_func_info *fi = expr_func_get(c, e->i0);
      if (!fi) KERR("unknown function in an integrand");
      if (fi->kind == FK_TEST) KERR("the integrand contains the test function %s: integrate it inside a form (lg.integral) and solve a problem instead", fi->name);
      if (e->order > 1) KERR("second and higher derivatives of %s are not supported yet", fi->name);
      int d = leaf_dir(e);
      if (d >= dim) KERR("the integrand differentiates %s in %c, but the mesh is %dD", fi->name, "xyz"[d], dim);
      int ci = coef_index(k, e->i0);
      if (ci < 0) {
        if (k->ncoef == KER_MAXCOEF) KERR("too many coefficient functions in one form (max %d)", KER_MAXCOEF);
        ci = k->ncoef++;
        k->coef_func[ci] = e->i0;
        k->coef_degree[ci] = fi->degree;
      }
      if (fi->degree < 1 || fi->degree > 3) KERR("coefficient %s has unsupported degree %d", fi->name, fi->degree);
      if (d < 0) need_val[fi->degree] = 1;
      else need_grad[fi->degree] = 1;
    }
  }
  /* sort coefficients by function id for a canonical W layout */
  for (int i = 1; i < k->ncoef; i++)
    for (int j = i; j > 0 && k->coef_func[j - 1] > k->coef_func[j]; j--) {
      int t = k->coef_func[j]; k->coef_func[j] = k->coef_func[j - 1]; k->coef_func[j - 1] = t;
      t = k->coef_degree[j]; k->coef_degree[j] = k->coef_degree[j - 1]; k->coef_degree[j - 1] = t;
    }
  lagrange_element el[4];
  for (int p = 1; p <= 3; p++)
    if (lagrange_init(&el[p], ct, p, err)) goto fail;
  k->wsize = 0;
  for (int i = 0; i < k->ncoef; i++) {
    k->coef_off[i] = k->wsize;
    k->wsize += el[k->coef_degree[i]].nloc;
  }
  /* Jacobian entries whose coefficient is constant on the cell (no coordinate, field or
   * normal in it) are integrated exactly on the reference cell ahead of time: on an
   * affine cell their element matrix is a contraction of reference tensors with
   * geometry factors, as in FFC's tensor representation; only the others need the
   * quadrature loop */
  int nent = s->arity == 2 ? s->tab->njac : 0, nvar = 0;
  isconst = calloc((size_t)nent + 1, 1);
  if (!isconst) KERR("out of memory");
  /* with a one-point rule (P1 stiffness) the quadrature loop is the cheaper of the two */
  int nq_est = 1;
  for (int d = 0; d < dim; d++) nq_est *= (qdeg + 2) / 2;
  for (int i = 0; i < nent; i++) {
    isconst[i] = !facet && nq_est > 1 && !(s->tab->jac[i]->dep & DEP_POINT);
    nvar += !isconst[i];
  }
  /* test and trial basis needs */
  if (s->arity >= 1) {
    int n = s->arity == 2 ? s->tab->njac : s->tab->nres;
    for (int i = 0; i < n; i++) {
      if (s->arity == 2 && isconst[i]) continue;
      const expr *tl = s->arity == 2 ? s->tab->jac_test[i] : s->tab->res_leaf[i];
      int fi = layout_find(rows, tl->i0);
      if (fi < 0) KERR("internal error: test function not in the row layout");
      if (tl->order > 1) KERR("second derivatives of test functions are not supported yet");
      if (leaf_dir(tl) >= dim) KERR("the form differentiates a test function in %c on a %dD mesh", "xyz"[leaf_dir(tl)], dim);
      if (tl->order) need_grad[rows->degree[fi]] = 1; else need_val[rows->degree[fi]] = 1;
      if (s->arity == 2) {
        const expr *ul = s->tab->jac_trial[i];
        int fj = layout_find(cols, ul->i0);
        if (fj < 0) KERR("internal error: unknown not in the column layout");
        if (ul->order > 1) KERR("second derivatives of unknowns are not supported yet");
        if (leaf_dir(ul) >= dim) KERR("the form differentiates an unknown in %c on a %dD mesh", "xyz"[leaf_dir(ul)], dim);
        if (ul->order) need_grad[cols->degree[fj]] = 1; else need_val[cols->degree[fj]] = 1;
      }
    }
  }

  /* quadrature */
  quad_rule q;
  if (quad_simplex(facet ? dim - 1 : dim, qdeg, &q)) KERR("no quadrature rule of degree %d", qdeg);
  k->nq = q.n;

  sb_printf(&b, "/* generated by lugal: %s %s kernel, arity %d, quadrature degree %d, %d points */\n",
            cell_name(ct), facet ? "facet" : "cell", s->arity, q.degree, q.n);
  sb_printf(&b, "double sin(double); double cos(double); double tan(double); double exp(double);\n"
                "double log(double); double sqrt(double); double fabs(double); double tanh(double);\n"
                "double sinh(double); double cosh(double); double atan(double); double asin(double);\n"
                "double acos(double); double pow(double, double);\n");
  /* weights and reference points (per facet for facet kernels) */
  double *qx = malloc(sizeof(double) * (size_t)nf * (size_t)q.n * 3);
  if (!qx) KERR("out of memory");
  for (int f = 0; f < nf; f++)
    for (int i = 0; i < q.n; i++) {
      double xi[3] = {0, 0, 0};
      if (facet) ref_facet_point(ct, f, q.x + q.dim * i, xi);
      else memcpy(xi, q.x + dim * i, sizeof(double) * (size_t)dim);
      memcpy(qx + ((size_t)f * q.n + i) * dim, xi, sizeof(double) * (size_t)dim);
    }
  double wsum = 0;
  for (int i = 0; i < q.n; i++) wsum += q.w[i];
  double *qw = malloc(sizeof(double) * (size_t)q.n);
  if (!qw) { free(qx); KERR("out of memory"); }
  for (int i = 0; i < q.n; i++) qw[i] = facet ? q.w[i] / wsum : q.w[i];
  emit_table(&b, "QW", qw, q.n);
  free(qw);
  if (need_x) emit_table(&b, "QX", qx, (long)nf * q.n * dim);
  /* basis tables */
  for (int p = 1; p <= 3; p++) {
    if (!need_val[p] && !need_grad[p]) continue;
    int nl = el[p].nloc;
    double *bv = malloc(sizeof(double) * (size_t)nf * q.n * nl);
    double *bg = malloc(sizeof(double) * (size_t)nf * q.n * nl * dim);
    if (!bv || !bg) { free(bv); free(bg); free(qx); KERR("out of memory"); }
    for (int f = 0; f < nf; f++)
      for (int i = 0; i < q.n; i++) {
        size_t qq = (size_t)f * q.n + i;
        lagrange_eval(&el[p], qx + qq * dim, bv + qq * nl, bg + qq * nl * dim);
      }
    char nm[16];
    if (need_val[p]) { snprintf(nm, sizeof nm, "B%d", p); emit_table(&b, nm, bv, (long)nf * q.n * nl); }
    if (need_grad[p]) { snprintf(nm, sizeof nm, "G%d", p); emit_table(&b, nm, bg, (long)nf * q.n * nl * dim); }
    free(bv);
    free(bg);
  }
  free(qx);
  if (need_n) {
    double nr[18];
    for (int f = 0; f < cell_nfacets(ct); f++) ref_facet_normal(ct, f, nr + f * dim);
    emit_table(&b, "NR", nr, (long)cell_nfacets(ct) * dim);
  }

  /* reference tensors R[a][b][k][l][i][j] = ∫ D_k phi_i D_l psi_j on the reference cell,
   * k, l = 0 for values and 1..dim for derivatives, exact (degree pa + pb) */
  unsigned char rused[KER_MAXFIELD][KER_MAXFIELD][4][4];
  memset(rused, 0, sizeof rused);
  for (int i = 0; i < nent; i++) {
    if (!isconst[i]) continue;
    int a = layout_find(rows, s->tab->jac_test[i]->i0), bb = layout_find(cols, s->tab->jac_trial[i]->i0);
    int da = leaf_dir(s->tab->jac_test[i]), db = leaf_dir(s->tab->jac_trial[i]);
    for (int kk = (da < 0 ? -1 : 0); kk < (da < 0 ? 0 : dim); kk++)
      for (int ll = (db < 0 ? -1 : 0); ll < (db < 0 ? 0 : dim); ll++) rused[a][bb][kk + 1][ll + 1] = 1;
  }
  for (int a = 0; rows && a < rows->n; a++)
    for (int bb = 0; cols && bb < cols->n; bb++) {
      if (!block_used(rused[a][bb])) continue;
      const lagrange_element *ea = &el[rows->degree[a]], *eb = &el[cols->degree[bb]];
      quad_rule rq;
      if (quad_simplex(dim, ea->degree + eb->degree, &rq)) KERR("no reference rule");
      int na = ea->nloc, nb = eb->nloc;
      double *R = calloc((size_t)16 * na * nb, sizeof(double));
      if (!R) KERR("out of memory");
      for (int qi = 0; qi < rq.n; qi++) {
        double va[FEM_MAXLOC], ga[FEM_MAXLOC * 3], vb[FEM_MAXLOC], gb[FEM_MAXLOC * 3];
        lagrange_eval(ea, rq.x + dim * qi, va, ga);
        lagrange_eval(eb, rq.x + dim * qi, vb, gb);
        for (int kk = 0; kk <= dim; kk++)
          for (int ll = 0; ll <= dim; ll++) {
            if (!rused[a][bb][kk][ll]) continue;
            double *r = R + (size_t)(kk * 4 + ll) * na * nb;
            for (int i = 0; i < na; i++) {
              double fi = kk ? ga[i * dim + kk - 1] : va[i];
              for (int j = 0; j < nb; j++) r[i * nb + j] += rq.w[qi] * fi * (ll ? gb[j * dim + ll - 1] : vb[j]);
            }
          }
      }
      for (int kk = 0; kk <= dim; kk++)
        for (int ll = 0; ll <= dim; ll++) {
          if (!rused[a][bb][kk][ll]) continue;
          char nm[32];
          snprintf(nm, sizeof nm, "R%d_%d_%d%d", a, bb, kk, ll);
          emit_table(&b, nm, R + (size_t)(kk * 4 + ll) * na * nb, (long)na * nb);
        }
      free(R);
    }

  sb_printf(&b, "void lugal_kernel(const double *restrict X, const double *restrict W, "
                "const double *restrict P, int facet, double *restrict A, double *restrict C, int cm)\n{\n");
  sb_printf(&b, "  (void)W; (void)P; (void)facet; (void)C; (void)cm;\n");
  /* geometry */
  if (dim == 2) {
    sb_printf(&b, "  const double J00 = X[2] - X[0], J01 = X[4] - X[0], J10 = X[3] - X[1], J11 = X[5] - X[1];\n"
                  "  const double det = J00*J11 - J01*J10, idet = 1.0/det;\n"
                  "  const double K00 = J11*idet, K01 = -J01*idet, K10 = -J10*idet, K11 = J00*idet;\n");
  } else {
    sb_printf(&b, "  const double J00 = X[3] - X[0], J01 = X[6] - X[0], J02 = X[9] - X[0];\n"
                  "  const double J10 = X[4] - X[1], J11 = X[7] - X[1], J12 = X[10] - X[1];\n"
                  "  const double J20 = X[5] - X[2], J21 = X[8] - X[2], J22 = X[11] - X[2];\n"
                  "  const double C00 = J11*J22 - J12*J21, C01 = J02*J21 - J01*J22, C02 = J01*J12 - J02*J11;\n"
                  "  const double det = J00*C00 + J10*C01 + J20*C02, idet = 1.0/det;\n"
                  "  const double K00 = C00*idet, K01 = C01*idet, K02 = C02*idet;\n"
                  "  const double K10 = (J12*J20 - J10*J22)*idet, K11 = (J00*J22 - J02*J20)*idet, K12 = (J02*J10 - J00*J12)*idet;\n"
                  "  const double K20 = (J10*J21 - J11*J20)*idet, K21 = (J01*J20 - J00*J21)*idet, K22 = (J00*J11 - J01*J10)*idet;\n");
  }
  if (!facet) {
    sb_printf(&b, "  const double scale = det < 0.0 ? -det : det;\n");
  } else {
    /* facet measure from the facet's vertices */
    int nvf = dim;
    sb_printf(&b, "  static const int FV[%d][%d] = {", cell_nfacets(ct), nvf);
    for (int f = 0; f < cell_nfacets(ct); f++) {
      const int *fv = cell_facet_verts(ct, f);
      sb_printf(&b, "%s{", f ? ", " : "");
      for (int i = 0; i < nvf; i++) sb_printf(&b, "%s%d", i ? ", " : "", fv[i]);
      sb_printf(&b, "}");
    }
    sb_printf(&b, "};\n");
    if (dim == 2) {
      sb_printf(&b, "  const double *fa = X + 2*FV[facet][0], *fb = X + 2*FV[facet][1];\n"
                    "  const double scale = sqrt((fb[0]-fa[0])*(fb[0]-fa[0]) + (fb[1]-fa[1])*(fb[1]-fa[1]));\n");
    } else {
      sb_printf(&b, "  const double *fa = X + 3*FV[facet][0], *fb = X + 3*FV[facet][1], *fc = X + 3*FV[facet][2];\n"
                    "  const double e0 = fb[0]-fa[0], e1 = fb[1]-fa[1], e2 = fb[2]-fa[2];\n"
                    "  const double h0 = fc[0]-fa[0], h1 = fc[1]-fa[1], h2 = fc[2]-fa[2];\n"
                    "  const double c0 = e1*h2 - e2*h1, c1 = e2*h0 - e0*h2, c2 = e0*h1 - e1*h0;\n"
                    "  const double scale = 0.5*sqrt(c0*c0 + c1*c1 + c2*c2);\n");
    }
    if (need_n) {
      /* n = K^T n_ref normalized; the sign of det keeps it outward for inverted maps */
      for (int d = 0; d < dim; d++) {
        sb_printf(&b, "  double m%d = ", d);
        for (int kk = 0; kk < dim; kk++) sb_printf(&b, "%sK%d%d*NR[facet*%d+%d]", kk ? " + " : "", kk, d, dim, kk);
        sb_printf(&b, ";\n");
      }
      sb_printf(&b, "  const double mn = 1.0/sqrt(m0*m0 + m1*m1%s);\n", dim == 3 ? " + m2*m2" : "");
      for (int d = 0; d < dim; d++) sb_printf(&b, "  const double n%d = m%d*mn;\n", d, d);
    }
  }
  /* hoisted parameter-only subexpressions */
  leafctx lc = {k, dim};
  sel = malloc((size_t)tape.n + 1);
  if (!sel) KERR("out of memory");
  for (int i = 0; i < tape.n; i++) sel[i] = !(tape.node[i]->dep & DEP_POINT);
  expr_codegen(&b, &tape, "t", "P", sel, leafname, &lc, "  ");
  pcls = malloc((size_t)tape.n + 1);
  pslot = malloc(sizeof(int) * ((size_t)tape.n + 1));
  if (!pcls || !pslot) KERR("out of memory");
  k->ncache = expr_tape_point_cache(&tape, pcls, pslot);
  if (k->ncache < 0) KERR("out of memory");
  char ref[128];
  for (int a = 0; rows && a < rows->n; a++)
    for (int bb = 0; cols && bb < cols->n; bb++) {
      if (!block_used(rused[a][bb])) continue;
      for (int kk = 0; kk <= dim; kk++)
        for (int ll = 0; ll <= dim; ll++)
          if (rused[a][bb][kk][ll]) sb_printf(&b, "  double G%d_%d_%d%d = 0.0;\n", a, bb, kk, ll);
      for (int i = 0; i < nent; i++) {
        if (!isconst[i] || layout_find(rows, s->tab->jac_test[i]->i0) != a ||
            layout_find(cols, s->tab->jac_trial[i]->i0) != bb)
          continue;
        int da = leaf_dir(s->tab->jac_test[i]), db = leaf_dir(s->tab->jac_trial[i]);
        expr_codegen_ref(&tape, tape.root[i], "t", leafname, &lc, ref, sizeof ref);
        /* physical derivative d/dx_da = sum_k K[k][da] d/dxi_k */
        for (int kk = (da < 0 ? -1 : 0); kk < (da < 0 ? 0 : dim); kk++)
          for (int ll = (db < 0 ? -1 : 0); ll < (db < 0 ? 0 : dim); ll++) {
            sb_printf(&b, "  G%d_%d_%d%d += %s", a, bb, kk + 1, ll + 1, ref);
            if (da >= 0) sb_printf(&b, "*K%d%d", kk, da);
            if (db >= 0) sb_printf(&b, "*K%d%d", ll, db);
            sb_printf(&b, ";\n");
          }
      }
      int na = rows->nloc[a], nb = cols->nloc[bb];
      sb_printf(&b, "  for (int i = 0; i < %d; ++i) {\n    double *Ai = A + (%d + i)*%d + %d;\n", na,
                rows->off[a], cols->size, cols->off[bb]);
      sb_printf(&b, "    for (int j = 0; j < %d; ++j) Ai[j] += scale*(", nb);
      int first = 1;
      for (int kk = 0; kk <= dim; kk++)
        for (int ll = 0; ll <= dim; ll++) {
          if (!rused[a][bb][kk][ll]) continue;
          sb_printf(&b, "%sG%d_%d_%d%d*R%d_%d_%d%d[i*%d + j]", first ? "" : " + ", a, bb, kk, ll, a, bb, kk, ll, nb);
          first = 0;
        }
      sb_printf(&b, ");\n  }\n");
    }
  if (s->arity == 2 && nvar == 0) {
    /* everything was exact on the reference cell */
    k->ncache = 0;
    sb_printf(&b, "  (void)K00; (void)scale;\n}\n");
    free(sel);
    free(isconst);
    free(pcls);
    free(pslot);
    expr_tape_free(&tape);
    if (b.failed) { sb_free(&b); snprintf(err, errlen, "out of memory generating a kernel"); return NULL; }
    return b.s;
  }
  sb_printf(&b, "  for (int q = 0; q < %d; ++q) {\n", q.n);
  if (facet) sb_printf(&b, "    const int qq = facet*%d + q;\n", q.n);
  else sb_printf(&b, "    const int qq = q;\n");
  sb_printf(&b, "    const double wq = QW[q]*scale;\n");
  if (need_x) {
    for (int d = 0; d < dim; d++) {
      sb_printf(&b, "    const double x%d = X[%d]", d, d);
      for (int kk = 0; kk < dim; kk++) sb_printf(&b, " + J%d%d*QX[qq*%d+%d]", d, kk, dim, kk);
      sb_printf(&b, ";\n");
    }
  }
  for (int p = 1; p <= 3; p++) {
    int nl = el[p].nloc;
    if (need_val[p]) sb_printf(&b, "    const double *b%d = B%d + qq*%d;\n", p, p, nl);
    if (need_grad[p]) {
      sb_printf(&b, "    double ");
      for (int d = 0; d < dim; d++) sb_printf(&b, "%sg%d_%d[%d]", d ? ", " : "", p, d, nl);
      sb_printf(&b, ";\n    for (int i = 0; i < %d; ++i) {\n      const double *gr = G%d + (qq*%d + i)*%d;\n", nl, p, nl, dim);
      for (int d = 0; d < dim; d++) {
        sb_printf(&b, "      g%d_%d[i] = ", p, d);
        for (int kk = 0; kk < dim; kk++) sb_printf(&b, "%sgr[%d]*K%d%d", kk ? " + " : "", kk, kk, d);
        sb_printf(&b, ";\n");
      }
      sb_printf(&b, "    }\n");
    }
  }
  /* coefficient values and gradients */
  for (int i = 0; i < tape.n; i++) {
    const expr *e = tape.node[i];
    if (e->kind != E_FIELD) continue;
    int ci = coef_index(k, e->i0), p = k->coef_degree[ci], nl = el[p].nloc;
    char nm[32], bn[32];
    leafname(&lc, e, nm, sizeof nm);
    basis_name(e, p, bn, sizeof bn);
    sb_printf(&b, "    double %s = 0.0;\n    for (int i = 0; i < %d; ++i) %s += W[%d + i]*%s[i];\n",
              nm, nl, nm, k->coef_off[ci], bn);
  }
  if (k->ncache > 0) {
    /* cached coordinate-only values: read them, or compute (and store) them */
    int nc = k->ncache;
    sb_printf(&b, "    double ");
    for (int i = 0, j = 0; i < tape.n; i++)
      if (pcls[i] == PC_CACHED) sb_printf(&b, "%st%d", j++ ? ", " : "", i);
    sb_printf(&b, ";\n");
    for (int i = 0; i < tape.n; i++) sel[i] = (tape.node[i]->dep & DEP_POINT) && pcls[i] == PC_SHARED;
    expr_codegen(&b, &tape, "t", "P", sel, leafname, &lc, "    ");
    sb_printf(&b, "    if (cm == 2) {\n");
    for (int i = 0; i < tape.n; i++)
      if (pcls[i] == PC_CACHED) sb_printf(&b, "      t%d = C[q*%d + %d];\n", i, nc, pslot[i]);
    sb_printf(&b, "    } else {\n");
    for (int i = 0; i < tape.n; i++)
      sel[i] = pcls[i] == PC_CACHED ? 2 : (tape.node[i]->dep & DEP_POINT) && pcls[i] == PC_INNER;
    expr_codegen(&b, &tape, "t", "P", sel, leafname, &lc, "      ");
    sb_printf(&b, "      if (cm == 1) {\n");
    for (int i = 0; i < tape.n; i++)
      if (pcls[i] == PC_CACHED) sb_printf(&b, "        C[q*%d + %d] = t%d;\n", nc, pslot[i], i);
    sb_printf(&b, "      }\n    }\n");
    for (int i = 0; i < tape.n; i++) sel[i] = (tape.node[i]->dep & DEP_POINT) && pcls[i] == PC_OTHER;
  } else {
    for (int i = 0; i < tape.n; i++) sel[i] = !sel[i];
  }
  expr_codegen(&b, &tape, "t", "P", sel, leafname, &lc, "    ");
  /* contraction */
  if (s->arity == 0) {
    expr_codegen_ref(&tape, tape.root[0], "t", leafname, &lc, ref, sizeof ref);
    sb_printf(&b, "    A[0] += wq*%s;\n", ref);
  } else if (s->arity == 1) {
    for (int a = 0; a < rows->n; a++) {
      int any = 0;
      for (int i = 0; i < s->tab->nres; i++) any |= s->tab->res_leaf[i]->i0 == rows->func[a];
      if (!any) continue;
      sb_printf(&b, "    for (int i = 0; i < %d; ++i) A[%d + i] += wq*(", rows->nloc[a], rows->off[a]);
      int first = 1;
      for (int i = 0; i < s->tab->nres; i++) {
        const expr *tl = s->tab->res_leaf[i];
        if (tl->i0 != rows->func[a]) continue;
        char bn[32];
        basis_name(tl, rows->degree[a], bn, sizeof bn);
        expr_codegen_ref(&tape, tape.root[i], "t", leafname, &lc, ref, sizeof ref);
        sb_printf(&b, "%s%s*%s[i]", first ? "" : " + ", ref, bn);
        first = 0;
      }
      sb_printf(&b, ");\n");
    }
  } else {
    for (int a = 0; a < rows->n; a++)
      for (int bb = 0; bb < cols->n; bb++) {
        /* distinct test leaves for this block */
        const expr *tls[64];
        int nt = 0;
        for (int i = 0; i < s->tab->njac; i++) {
          const expr *tl = s->tab->jac_test[i];
          if (isconst[i] || tl->i0 != rows->func[a] || s->tab->jac_trial[i]->i0 != cols->func[bb]) continue;
          int found = 0;
          for (int t = 0; t < nt; t++) found |= tls[t] == tl;
          if (!found && nt < 64) tls[nt++] = tl;
        }
        if (!nt) continue;
        sb_printf(&b, "    for (int j = 0; j < %d; ++j) {\n", cols->nloc[bb]);
        for (int t = 0; t < nt; t++) {
          sb_printf(&b, "      const double u%d = wq*(", t);
          int first = 1;
          for (int i = 0; i < s->tab->njac; i++) {
            if (isconst[i] || s->tab->jac_test[i] != tls[t] || s->tab->jac_trial[i]->i0 != cols->func[bb]) continue;
            char bn[32];
            basis_name(s->tab->jac_trial[i], cols->degree[bb], bn, sizeof bn);
            expr_codegen_ref(&tape, tape.root[i], "t", leafname, &lc, ref, sizeof ref);
            sb_printf(&b, "%s%s*%s[j]", first ? "" : " + ", ref, bn);
            first = 0;
          }
          sb_printf(&b, ");\n");
        }
        sb_printf(&b, "      double *Aj = A + %d + j;\n", cols->off[bb]);
        sb_printf(&b, "      for (int i = 0; i < %d; ++i) Aj[(%d + i)*%d] += ", rows->nloc[a], rows->off[a], cols->size);
        for (int t = 0; t < nt; t++) {
          char bn[32];
          basis_name(tls[t], rows->degree[a], bn, sizeof bn);
          sb_printf(&b, "%s%s[i]*u%d", t ? " + " : "", bn, t);
        }
        sb_printf(&b, ";\n    }\n");
      }
  }
  sb_printf(&b, "  }\n}\n");
  free(sel);
  free(isconst);
  free(pcls);
  free(pslot);
  expr_tape_free(&tape);
  if (b.failed) { sb_free(&b); snprintf(err, errlen, "out of memory generating a kernel"); return NULL; }
  return b.s;
fail:
  free(sel);
  free(isconst);
  free(pcls);
  free(pslot);
  expr_tape_free(&tape);
  sb_free(&b);
  return NULL;
}

int kernel_build(lg_jit *j, expr_ctx *c, cell_type ct, int facet, int qdeg, const kernel_spec *s,
                 const field_layout *rows, const field_layout *cols, lg_kernel *k, char *err,
                 size_t errlen) {
  char *src = kernel_source(c, ct, facet, qdeg, s, rows, cols, k, err, errlen);
  if (!src) return 1;
  if (getenv("LUGAL_SHOW_KERNELS")) fprintf(stderr, "%s\n", src);
  k->fn = jit_compile(j, src, &k->compile_ms, &k->cached, err, errlen);
  free(src);
  if (!k->fn) return 1;
  if (k->ncache > 0 && !(k->pc = calloc(1, sizeof *k->pc))) {
    snprintf(err, errlen, "out of memory");
    return 1;
  }
  return 0;
}

void kernel_release(lg_kernel *k) {
  if (!k || !k->pc) return;
  free(k->pc->v);
  free(k->pc);
  k->pc = NULL;
}
