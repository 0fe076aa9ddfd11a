/* gmsh.c — Gmsh MSH files: the 2.2 and 4.1 ASCII reader (partitioned 4.1 files included)
 * and an MSH 2.2 writer.
 *
 * The reader treats its input as hostile. Every count is checked against the bytes left in
 * the file before anything is allocated or looped over (an item needs at least two bytes
 * per token), so a 90-byte file cannot declare 10^9 nodes; every integer is read as a
 * 64-bit value and range-checked as the type it becomes; every loop stops at the first
 * error; sections may repeat (the format allows it) and append; every failure names the
 * file, the line and what was expected. */
#include "io.h"
#include "outfile.h"

#include <ctype.h>
#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

/* ---------------------------------------------------------------- tokenizer */

typedef struct {
  char *buf;
  size_t len, pos;
  long line;   /* line of the next character */
  long tline;  /* line of the last token */
  const char *path;
  char *err;
  int failed;
} lex;

static void lex_err(lex *l, const char *fmt, ...) {
  if (l->failed) return;
  char msg[MESH_ERRLEN];
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(msg, sizeof msg, fmt, ap);
  va_end(ap);
  snprintf(l->err, MESH_ERRLEN, "%.200s:%ld: %.290s", l->path, l->tline, msg);
  l->failed = 1;
}

/* an upper bound on the tokens left: each needs a character and a separator */
static size_t tokens_left(const lex *l) { return (l->len - l->pos) / 2 + 1; }

/* next whitespace-delimited token, NUL-terminated in place; NULL at the end of the file
 * or after an error. A token starting with " is a quoted name that ends at the next
 * unescaped " on the same line; \" \\ \n and \r inside it stand for ", \, a newline and a
 * carriage return (what mesh_write_gmsh writes for them). */
static char *tok(lex *l) {
  if (l->failed) return NULL;
  while (l->pos < l->len && isspace((unsigned char)l->buf[l->pos])) {
    if (l->buf[l->pos] == '\n') l->line++;
    l->pos++;
  }
  l->tline = l->line;
  if (l->pos >= l->len) return NULL;
  char *s = l->buf + l->pos;
  if (*s == '"') {
    char *w = s;
    l->pos++;
    for (;;) {
      if (l->pos >= l->len || l->buf[l->pos] == '\n' || l->buf[l->pos] == 0) {
        lex_err(l, "unterminated quoted name (a name must end with \" on its line)");
        return NULL;
      }
      char c = l->buf[l->pos++];
      if (c == '"') break;
      if (c == '\\' && l->pos < l->len && strchr("\"\\nr", l->buf[l->pos]) && l->buf[l->pos]) {
        c = l->buf[l->pos++];
        if (c == 'n') c = '\n';
        else if (c == 'r') c = '\r';
      }
      *w++ = c;
    }
    *w = 0;
    return s;
  }
  while (l->pos < l->len && !isspace((unsigned char)l->buf[l->pos]) && l->buf[l->pos] != 0) l->pos++;
  if (l->pos < l->len && l->buf[l->pos] == 0) {
    lex_err(l, "binary data (a zero byte) in the file: lugal reads ASCII MSH files");
    return NULL;
  }
  if (l->pos < l->len) {
    if (l->buf[l->pos] == '\n') l->line++;
    l->buf[l->pos++] = 0;
  }
  return s;
}

static int64_t tok_int(lex *l, const char *what, int64_t lo, int64_t hi) {
  char *t = tok(l);
  if (!t) { lex_err(l, "file ends early: expected %s", what); return 0; }
  /* the common token, an optional sign and up to 18 digits, without strtoll (a fifth of a
   * large file's parsing); anything else takes strtoll's path and messages */
  const char *p = t + (*t == '-' || *t == '+');
  int nd = 0;
  int64_t u = 0;
  while (nd < 18 && p[nd] >= '0' && p[nd] <= '9') u = u * 10 + (p[nd++] - '0');
  if (nd && !p[nd]) { /* 18 digits at most: no overflow */
    int64_t v = *t == '-' ? -u : u;
    if (v >= lo && v <= hi) return v;
  }
  char *end;
  errno = 0;
  long long v = strtoll(t, &end, 10);
  if (end == t || *end) { lex_err(l, "expected %s (an integer), found \"%.32s\"", what, t); return 0; }
  if (errno == ERANGE || v < lo || v > hi) {
    lex_err(l, "%s %.32s is out of range (%lld to %lld)", what, t, (long long)lo, (long long)hi);
    return 0;
  }
  return v;
}

/* a count of items that need at least ntok tokens each: it must fit in the rest of the file */
static long tok_count(lex *l, const char *what, int ntok) {
  int64_t v = tok_int(l, what, 0, INT64_MAX);
  if (l->failed) return 0;
  size_t room = tokens_left(l) / (size_t)(ntok > 0 ? ntok : 1);
  if ((uint64_t)v > (uint64_t)room) {
    lex_err(l, "%s %lld is more than the rest of the file can hold (%zu bytes left): the file "
               "is truncated or corrupt", what, (long long)v, l->len - l->pos);
    return 0;
  }
  return (long)v;
}

static double tok_real(lex *l, const char *what) {
  char *t = tok(l);
  if (!t) { lex_err(l, "file ends early: expected %s", what); return 0; }
  char *end;
  double v = strtod(t, &end);
  if (end == t || *end) { lex_err(l, "expected %s (a number), found \"%.32s\"", what, t); return 0; }
  return v;
}

static void expect(lex *l, const char *word) {
  char *t = tok(l);
  if (l->failed) return;
  if (!t) { lex_err(l, "file ends early: expected %s", word); return; }
  if (strcmp(t, word)) lex_err(l, "expected %s, found \"%.32s\"", word, t);
}

/* skip to the end marker of a section lugal does not read, line by line (its contents
 * need not be tokens: comments, post-processing data) */
static void skip_section(lex *l, const char *name) {
  char end[80];
  snprintf(end, sizeof end, "$End%.70s", name + 1);
  size_t n = strlen(end);
  long start = l->tline;
  while (l->pos < l->len) {
    char *nl = memchr(l->buf + l->pos, '\n', l->len - l->pos);
    size_t stop = nl ? (size_t)(nl - l->buf) : l->len;
    size_t a = l->pos, b = stop;
    while (a < b && isspace((unsigned char)l->buf[a])) a++;
    while (b > a && isspace((unsigned char)l->buf[b - 1])) b--;
    int hit = b - a == n && !memcmp(l->buf + a, end, n);
    l->pos = nl ? stop + 1 : stop;
    if (nl) l->line++;
    if (hit) return;
  }
  l->tline = start;
  lex_err(l, "section %.60s is not closed by %.70s", name, end);
}

/* ---------------------------------------------------------------- growable arrays */

static int grow(void **p, size_t *cap, size_t need, size_t elem) {
  if (need <= *cap) return 0;
  size_t c = *cap ? *cap : 64;
  while (c < need) {
    if (c > SIZE_MAX / 2 / elem) return 1;
    c *= 2;
  }
  void *q = realloc(*p, c * elem);
  if (!q) return 1;
  *p = q;
  *cap = c;
  return 0;
}

/* ---------------------------------------------------------------- what the file holds */

/* nodes per element for the first-order Gmsh types lugal reads (0: not read) */
static int gmsh_nnodes(int64_t type) {
  switch (type) {
  case 1: return 2;  /* line */
  case 2: return 3;  /* triangle */
  case 3: return 4;  /* quadrangle */
  case 4: return 4;  /* tetrahedron */
  case 5: return 8;  /* hexahedron */
  case 15: return 1; /* point */
  default: return 0;
  }
}
static int gmsh_dim(int type) { return type == 15 ? 0 : type == 1 ? 1 : type <= 3 ? 2 : 3; }
static cell_type gmsh_cell(int type) {
  return type == 1 ? CELL_INTERVAL : type == 2 ? CELL_TRIANGLE : type == 3 ? CELL_QUADRILATERAL : type == 4 ? CELL_TETRAHEDRON
                                                                                                : CELL_HEXAHEDRON;
}

typedef struct {
  int type, nn;
  int phys;        /* MSH 2: the physical tag (0 = none) */
  int edim;        /* MSH 4: the entity the element is classified on */
  int64_t etag;
  int64_t id;      /* the file's element tag, for messages */
  long line;
  int64_t nodes[8];
} gelem;

typedef struct {
  int dim, partitioned;
  int64_t tag;
  size_t phys_off;
  int nphys;
  long line;
} gentity;

typedef struct {
  int dim, tag;
  char *name;
} gname;

typedef struct {
  int version;                /* 2 or 4 */
  int have_nodes, have_elems;
  size_t nn, capn;            /* nodes */
  int64_t *ntag;
  double *nx;                 /* 3 per node */
  size_t ne, cape;
  gelem *e;
  size_t nent, capent;
  gentity *ent;
  size_t nphys, capphys;
  int *phys;                  /* physical tags of entities */
  size_t nname, capname;
  gname *names;
} gfile;

static void gfile_free(gfile *g) {
  free(g->ntag); free(g->nx); free(g->e); free(g->ent); free(g->phys);
  for (size_t i = 0; i < g->nname; i++) free(g->names[i].name);
  free(g->names);
}

#define GROW(l, arr, cap, need) \
  (grow((void **)&(arr), &(cap), (need), sizeof *(arr)) ? (lex_err((l), "out of memory"), 1) : 0)

static void read_format(lex *l, gfile *g) {
  char *v = tok(l);
  if (!v) { lex_err(l, "file ends in $MeshFormat"); return; }
  char ver[16];
  snprintf(ver, sizeof ver, "%.15s", v);
  int64_t ft = tok_int(l, "file type", 0, 1);
  tok_int(l, "data size", 1, 16);
  if (l->failed) return;
  if (ft != 0) { lex_err(l, "binary MSH files are not supported; save the mesh as ASCII"); return; }
  int version;
  if (!strcmp(ver, "2") || !strcmp(ver, "2.0") || !strcmp(ver, "2.1") || !strcmp(ver, "2.2")) version = 2;
  else if (!strcmp(ver, "4.1")) version = 4;
  else { lex_err(l, "MSH version %s is not supported (2.2 and 4.1 are)", ver); return; }
  if (g->version && g->version != version) { lex_err(l, "a second $MeshFormat with another version"); return; }
  g->version = version;
  expect(l, "$EndMeshFormat");
}

static void read_names(lex *l, gfile *g) {
  long n = tok_count(l, "number of physical names", 3);
  for (long i = 0; i < n && !l->failed; i++) {
    int d = (int)tok_int(l, "physical dimension", 0, 3);
    int tg = (int)tok_int(l, "physical tag", 1, INT_MAX);
    char *nm = tok(l);
    if (l->failed) return;
    if (!nm) { lex_err(l, "file ends in $PhysicalNames"); return; }
    if (GROW(l, g->names, g->capname, g->nname + 1)) return;
    char *s = strdup(nm);
    if (!s) { lex_err(l, "out of memory"); return; }
    g->names[g->nname++] = (gname){d, tg, s};
  }
  expect(l, "$EndPhysicalNames");
}

/* one entity of $Entities or $PartitionedEntities */
static void read_entity(lex *l, gfile *g, int d, int partitioned) {
  gentity en = {d, partitioned, 0, g->nphys, 0, l->line};
  en.tag = tok_int(l, "entity tag", 1, INT_MAX);
  en.line = l->tline;
  /* an entity of a partitioned file whose parent has a higher dimension is an interface
   * between partitions (gmsh -part gives it the parent's physical tags): its elements are
   * not boundary facets, whatever tags it carries */
  int interface = 0;
  if (partitioned) {
    interface = tok_int(l, "parent dimension", 0, 3) > d;
    tok_int(l, "parent tag", INT_MIN, INT_MAX);
    long np = tok_count(l, "number of partitions", 1);
    for (long j = 0; j < np && !l->failed; j++) tok_int(l, "partition tag", INT_MIN, INT_MAX);
  }
  for (int j = 0; j < (d == 0 ? 3 : 6) && !l->failed; j++) tok_real(l, "entity bounding box");
  long np = tok_count(l, "number of physical tags", 1);
  if (np > INT_MAX) np = INT_MAX;
  for (long j = 0; j < np && !l->failed; j++) {
    int p = (int)tok_int(l, "physical tag", -(int64_t)INT_MAX, INT_MAX);
    if (l->failed) return;
    if (p == 0) { lex_err(l, "physical tag 0 of entity %lld (tags are nonzero)", (long long)en.tag); return; }
    /* a negative physical tag marks a reversed orientation: the group is the same */
    if (p < 0) p = -p;
    if (interface) continue;
    if (GROW(l, g->phys, g->capphys, g->nphys + 1)) return;
    g->phys[g->nphys++] = p;
    en.nphys++;
  }
  if (d > 0) {
    long nb = tok_count(l, "number of bounding entities", 1);
    for (long j = 0; j < nb && !l->failed; j++) tok_int(l, "bounding entity", INT_MIN, INT_MAX);
  }
  if (l->failed) return;
  if (GROW(l, g->ent, g->capent, g->nent + 1)) return;
  g->ent[g->nent++] = en;
}

static void read_entities(lex *l, gfile *g, int partitioned) {
  if (partitioned) {
    tok_int(l, "number of partitions", 0, INT_MAX);
    long ng = tok_count(l, "number of ghost entities", 2);
    for (long i = 0; i < ng && !l->failed; i++) {
      tok_int(l, "ghost entity tag", INT_MIN, INT_MAX);
      tok_int(l, "ghost partition", INT_MIN, INT_MAX);
    }
  }
  long cnt[4];
  for (int d = 0; d < 4; d++) cnt[d] = tok_count(l, "number of entities", 5);
  if (l->failed) return;
  if ((size_t)(cnt[0] + cnt[1] + cnt[2] + cnt[3]) > tokens_left(l) / 5) {
    lex_err(l, "the entity counts are more than the rest of the file can hold");
    return;
  }
  for (int d = 0; d < 4 && !l->failed; d++)
    for (long i = 0; i < cnt[d] && !l->failed; i++) read_entity(l, g, d, partitioned);
  expect(l, partitioned ? "$EndPartitionedEntities" : "$EndEntities");
}

/* room for `more` nodes: tags and coordinates grow together */
static int node_reserve(lex *l, gfile *g, size_t more) {
  size_t cap = g->capn;
  if (GROW(l, g->ntag, cap, g->nn + more)) return 1;
  if (cap != g->capn || !g->nx) {
    double *nx = realloc(g->nx, sizeof(double) * 3 * cap);
    if (!nx) { lex_err(l, "out of memory"); return 1; }
    g->nx = nx;
    g->capn = cap;
  }
  return 0;
}

static void read_coords(lex *l, int64_t tag, double *x) {
  for (int d = 0; d < 3 && !l->failed; d++) {
    x[d] = tok_real(l, "node coordinate");
    if (!l->failed && !isfinite(x[d]))
      lex_err(l, "node %lld has a non-finite coordinate %c = %g", (long long)tag, "xyz"[d], x[d]);
  }
}

/* the header of an MSH 4 $Nodes or $Elements section: blocks, total, min and max tag */
static void block_header(lex *l, const char *what, int ntok, long *nb, long *total) {
  char a[64], b[64], c[64], d[64];
  snprintf(a, sizeof a, "number of %s blocks", what);
  snprintf(b, sizeof b, "number of %ss", what);
  snprintf(c, sizeof c, "min %s tag", what);
  snprintf(d, sizeof d, "max %s tag", what);
  *nb = tok_count(l, a, 4);
  *total = tok_count(l, b, ntok);
  tok_int(l, c, 0, INT64_MAX);
  tok_int(l, d, 0, INT64_MAX);
}

static void read_nodes(lex *l, gfile *g) {
  g->have_nodes = 1;
  if (g->version == 2) {
    long n = tok_count(l, "number of nodes", 4);
    for (long i = 0; i < n && !l->failed; i++) {
      double x[3];
      int64_t tag = tok_int(l, "node tag", 1, INT64_MAX);
      read_coords(l, tag, x);
      if (l->failed || node_reserve(l, g, 1)) break;
      g->ntag[g->nn] = tag;
      memcpy(g->nx + 3 * g->nn, x, sizeof x);
      g->nn++;
    }
  } else {
    long nb, total, k = 0;
    block_header(l, "node", 4, &nb, &total);
    for (long b = 0; b < nb && !l->failed; b++) {
      int edim = (int)tok_int(l, "entity dimension", 0, 3);
      tok_int(l, "entity tag", INT_MIN, INT_MAX);
      int par = (int)tok_int(l, "parametric flag", 0, 1);
      long n = tok_count(l, "nodes in block", 4);
      if (l->failed) break;
      size_t first = g->nn;
      if (node_reserve(l, g, (size_t)n)) break;
      for (long i = 0; i < n && !l->failed; i++) g->ntag[first + (size_t)i] = tok_int(l, "node tag", 1, INT64_MAX);
      for (long i = 0; i < n && !l->failed; i++) {
        read_coords(l, g->ntag[first + (size_t)i], g->nx + 3 * (first + (size_t)i));
        for (int j = 0; par && j < edim && !l->failed; j++) tok_real(l, "parametric coordinate");
      }
      if (l->failed) break;
      g->nn = first + (size_t)n;
      k += n;
    }
    if (!l->failed && k != total) lex_err(l, "node blocks hold %ld nodes, the header says %ld", k, total);
  }
  expect(l, "$EndNodes");
}

static int unsupported_type(lex *l, int64_t type) {
  lex_err(l, "Gmsh element type %lld is not supported: lugal reads first-order points, lines, "
             "triangles, quadrilaterals, tetrahedra and hexahedra (set Mesh.ElementOrder = 1)",
          (long long)type);
  return 1;
}

/* an MSH 2 element's tag, type and tags into e (its nodes follow); 1 on an error */
static int read_elem2_head(lex *l, gelem *e) {
  memset(e, 0, sizeof *e);
  e->id = tok_int(l, "element tag", 1, INT64_MAX);
  e->line = l->tline;
  int64_t type = tok_int(l, "element type", 1, INT_MAX);
  long nt = tok_count(l, "number of element tags", 1);
  for (long j = 0; j < nt && !l->failed; j++) {
    int64_t v = tok_int(l, "element tag", j == 0 ? 0 : INT_MIN, INT_MAX);
    if (j == 0) e->phys = (int)v;
  }
  if (l->failed) return 1;
  e->nn = gmsh_nnodes(type);
  if (!e->nn && unsupported_type(l, type)) return 1;
  e->type = (int)type;
  e->edim = -1;
  return 0;
}

static void read_elements(lex *l, gfile *g) {
  g->have_elems = 1;
  if (g->version == 2) {
    long n = tok_count(l, "number of elements", 4);
    for (long i = 0; i < n && !l->failed; i++) {
      gelem e;
      if (read_elem2_head(l, &e)) break;
      for (int j = 0; j < e.nn && !l->failed; j++) e.nodes[j] = tok_int(l, "element node", 1, INT64_MAX);
      if (l->failed) break;
      /* points are the facets of a 1D mesh (and carry nothing in 2D and 3D) */
      if (GROW(l, g->e, g->cape, g->ne + 1)) break;
      g->e[g->ne++] = e;
    }
  } else {
    long nb, total, k = 0;
    block_header(l, "element", 2, &nb, &total);
    for (long b = 0; b < nb && !l->failed; b++) {
      gelem e;
      memset(&e, 0, sizeof e);
      e.edim = (int)tok_int(l, "entity dimension", 0, 3);
      e.etag = tok_int(l, "entity tag", INT_MIN, INT_MAX);
      int64_t type = tok_int(l, "element type", 1, INT_MAX);
      if (l->failed) break;
      e.nn = gmsh_nnodes(type);
      if (!e.nn && unsupported_type(l, type)) break;
      e.type = (int)type;
      if (gmsh_dim(e.type) != e.edim) {
        lex_err(l, "an element block of type %d (dimension %d) on an entity of dimension %d", e.type,
                gmsh_dim(e.type), e.edim);
        break;
      }
      long n = tok_count(l, "elements in block", 1 + e.nn);
      if (l->failed) break;
      if (GROW(l, g->e, g->cape, g->ne + (size_t)n)) break;
      for (long i = 0; i < n && !l->failed; i++) {
        e.id = tok_int(l, "element tag", 1, INT64_MAX);
        e.line = l->tline;
        for (int j = 0; j < e.nn && !l->failed; j++) e.nodes[j] = tok_int(l, "element node", 1, INT64_MAX);
        if (!l->failed) g->e[g->ne++] = e;
      }
      k += n;
    }
    if (!l->failed && k != total) lex_err(l, "element blocks hold %ld elements, the header says %ld", k, total);
  }
  expect(l, "$EndElements");
}

/* ---------------------------------------------------------------- from the file to a mesh */

/* node tag → index in the file's node arrays: a direct table when the tags are dense, a
 * binary search over the sorted tags otherwise */
typedef struct {
  int64_t lo;
  size_t n;
  long *direct;     /* tag - lo → index or -1 */
  int64_t *stag;    /* sorted tags */
  long *sidx;       /* their indices */
} nodemap;

typedef struct { int64_t tag; long idx; } tagidx;
static int tagidx_cmp(const void *a, const void *b) {
  int64_t x = ((const tagidx *)a)->tag, y = ((const tagidx *)b)->tag;
  return (x > y) - (x < y);
}

/* a node listed twice with the same coordinates (as partitioned files may) is one node */
static int same_node(const gfile *g, size_t a, size_t b) { return !memcmp(g->nx + 3 * a, g->nx + 3 * b, sizeof(double) * 3); }
static int twice(const gfile *g, size_t i, char *err, const char *path) {
  snprintf(err, MESH_ERRLEN, "%.200s: node %lld is defined twice in $Nodes, with different coordinates", path,
           (long long)g->ntag[i]);
  return 1;
}

static int nodemap_build(nodemap *m, const gfile *g, char *err, const char *path) {
  memset(m, 0, sizeof *m);
  if (!g->nn) { snprintf(err, MESH_ERRLEN, "%.200s: the file has no nodes", path); return 1; }
  int64_t lo = g->ntag[0], hi = g->ntag[0];
  for (size_t i = 1; i < g->nn; i++) {
    if (g->ntag[i] < lo) lo = g->ntag[i];
    if (g->ntag[i] > hi) hi = g->ntag[i];
  }
  m->lo = lo;
  if ((uint64_t)(hi - lo) < 2 * (uint64_t)g->nn + 1024) {
    m->n = (size_t)(hi - lo) + 1;
    m->direct = malloc(sizeof(long) * m->n);
    if (!m->direct) { snprintf(err, MESH_ERRLEN, "%.200s: out of memory", path); return 1; }
    for (size_t i = 0; i < m->n; i++) m->direct[i] = -1;
    for (size_t i = 0; i < g->nn; i++) {
      long *slot = &m->direct[g->ntag[i] - lo];
      if (*slot >= 0) {
        if (same_node(g, (size_t)*slot, i)) continue;
        return twice(g, i, err, path);
      }
      *slot = (long)i;
    }
    return 0;
  }
  tagidx *t = malloc(sizeof(tagidx) * g->nn);
  m->stag = malloc(sizeof(int64_t) * g->nn);
  m->sidx = malloc(sizeof(long) * g->nn);
  if (!t || !m->stag || !m->sidx) { free(t); snprintf(err, MESH_ERRLEN, "%.200s: out of memory", path); return 1; }
  for (size_t i = 0; i < g->nn; i++) t[i] = (tagidx){g->ntag[i], (long)i};
  qsort(t, g->nn, sizeof(tagidx), tagidx_cmp);
  size_t k = 0;
  for (size_t i = 0; i < g->nn; i++) {
    if (k && t[i].tag == m->stag[k - 1]) {
      if (same_node(g, (size_t)m->sidx[k - 1], (size_t)t[i].idx)) continue;
      size_t bad = (size_t)t[i].idx;
      free(t);
      return twice(g, bad, err, path);
    }
    m->stag[k] = t[i].tag;
    m->sidx[k] = t[i].idx;
    k++;
  }
  m->n = k;
  free(t);
  return 0;
}

static long nodemap_get(const nodemap *m, int64_t tag) {
  if (m->direct) {
    if (tag < m->lo || (uint64_t)(tag - m->lo) >= m->n) return -1;
    return m->direct[tag - m->lo];
  }
  size_t a = 0, b = m->n;
  while (a < b) {
    size_t c = a + (b - a) / 2;
    if (m->stag[c] < tag) a = c + 1;
    else b = c;
  }
  return a < m->n && m->stag[a] == tag ? m->sidx[a] : -1;
}

static void nodemap_free(nodemap *m) { free(m->direct); free(m->stag); free(m->sidx); }

/* (partitioned, dim, tag) → entity, by binary search over the sorted entities */
static int ent_cmp(const void *pa, const void *pb) {
  const gentity *a = pa, *b = pb;
  if (a->partitioned != b->partitioned) return a->partitioned < b->partitioned ? -1 : 1;
  if (a->dim != b->dim) return a->dim < b->dim ? -1 : 1;
  return (a->tag > b->tag) - (a->tag < b->tag);
}
static const gentity *ent_find(const gfile *g, int partitioned, int dim, int64_t tag) {
  gentity key = {dim, partitioned, tag, 0, 0, 0};
  return g->nent ? bsearch(&key, g->ent, g->nent, sizeof(gentity), ent_cmp) : NULL;
}

/* the physical tags of element e: *n of them at the returned pointer (or the one in *one) */
static const int *elem_phys(const gfile *g, const gelem *e, int *n, int *one) {
  if (e->edim < 0) {
    *one = e->phys;
    *n = e->phys != 0;
    return one;
  }
  /* partitioned files classify elements on partitioned entities, which carry the tags */
  const gentity *en = ent_find(g, 1, e->edim, e->etag);
  if (!en) en = ent_find(g, 0, e->edim, e->etag);
  *n = en ? en->nphys : 0;
  return en ? g->phys + en->phys_off : one;
}

/* rows of k ints: for each row the index of the first identical row (a row is compared as
 * the sorted set of its first ks entries followed by the rest as they are) */
static int64_t row_key(const int *r, int k, int ks, int *sorted) {
  memcpy(sorted, r, sizeof(int) * (size_t)k);
  for (int i = 1; i < ks; i++) {
    int v = sorted[i], j = i - 1;
    while (j >= 0 && sorted[j] > v) { sorted[j + 1] = sorted[j]; j--; }
    sorted[j + 1] = v;
  }
  uint64_t h = 1469598103934665603ull;
  for (int i = 0; i < k; i++) {
    h ^= (uint64_t)(uint32_t)sorted[i];
    h *= 0x9E3779B97F4A7C15ull;
    h ^= h >> 31;
  }
  return (int64_t)h;
}
static int first_duplicates(const int *rows, long n, int k, int ks, long *first) {
  size_t cap = 16;
  while (cap < 2 * (size_t)n + 16) cap <<= 1;
  long *slot = malloc(sizeof(long) * cap);
  if (!slot) return 1;
  for (size_t i = 0; i < cap; i++) slot[i] = -1;
  int a[10], b[10];
  for (long i = 0; i < n; i++) {
    size_t h = (size_t)row_key(rows + (size_t)i * k, k, ks, a) & (cap - 1);
    first[i] = i;
    while (slot[h] >= 0) {
      row_key(rows + (size_t)slot[h] * k, k, ks, b);
      if (!memcmp(a, b, sizeof(int) * (size_t)k)) { first[i] = slot[h]; break; }
      h = (h + 1) & (cap - 1);
    }
    if (first[i] == i) slot[h] = i;
  }
  free(slot);
  return 0;
}

/* the file's sections present, its entities defined once, and its cells: the elements of
 * the highest dimension (*cdim), of one type (*ctype), nc of them; 1 with the message */
static int cell_kind(gfile *g, const char *path, int *cdim_out, int *ctype_out, long *nc_out, char *err) {
  if (!g->version) { snprintf(err, MESH_ERRLEN, "%.200s: not a Gmsh MSH file (no $MeshFormat)", path); return 1; }
  if (!g->have_nodes || !g->have_elems) {
    snprintf(err, MESH_ERRLEN, "%.200s: the file is truncated or incomplete: no %s section", path,
             g->have_nodes ? "$Elements" : "$Nodes");
    return 1;
  }
  if (g->nent) qsort(g->ent, g->nent, sizeof(gentity), ent_cmp);
  for (size_t i = 1; i < g->nent; i++)
    if (!ent_cmp(&g->ent[i], &g->ent[i - 1])) {
      snprintf(err, MESH_ERRLEN, "%.200s:%ld: entity %lld of dimension %d is defined twice", path, g->ent[i].line,
               (long long)g->ent[i].tag, g->ent[i].dim);
      return 1;
    }
  /* the cells are the elements of the highest dimension, of one type */
  int cdim = 0, ctype = -1;
  for (size_t i = 0; i < g->ne; i++)
    if (gmsh_dim(g->e[i].type) > cdim) cdim = gmsh_dim(g->e[i].type);
  if (cdim < 1) {
    snprintf(err, MESH_ERRLEN, "%.200s: no 1D, 2D or 3D elements (lugal reads lines, triangles, quadrilaterals, "
                               "tetrahedra and hexahedra)", path);
    return 1;
  }
  long nc = 0;
  for (size_t i = 0; i < g->ne; i++) {
    if (gmsh_dim(g->e[i].type) != cdim) continue;
    if (ctype < 0) ctype = g->e[i].type;
    else if (ctype != g->e[i].type) {
      snprintf(err, MESH_ERRLEN, "%.200s:%ld: mixes %s and %s cells; lugal meshes have one cell type", path,
               g->e[i].line, cell_name(gmsh_cell(ctype)), cell_name(gmsh_cell(g->e[i].type)));
      return 1;
    }
    nc++;
  }
  if (nc > INT_MAX / 8) { snprintf(err, MESH_ERRLEN, "%.200s: too many cells (%ld)", path, nc); return 1; }
  *cdim_out = cdim;
  *ctype_out = ctype;
  *nc_out = nc;
  return 0;
}

/* facets with physical tags become tagged boundary facets of m, one per (facet, tag), the
 * same facet under the same tag once (it would be integrated twice); newid maps the file's
 * node indices to m's vertices (-1: no cell uses it). 1 with the message */
static int tagged_facets(gfile *g, mesh *m, const nodemap *nm, const int *newid, int cdim, const char *path, char *err) {
  cell_type ct = m->type;
  int *fv = NULL, *ftag = NULL;
  long *first = NULL;
  int nvf = m->nvf, ftype = cdim == 1 ? 15 : cdim == 2 ? 1 : ct == CELL_TETRAHEDRON ? 2 : 3;
  size_t nf = 0, capf = 0, capt = 0;
  for (size_t i = 0; i < g->ne; i++) {
    const gelem *e = &g->e[i];
    if (gmsh_dim(e->type) != cdim - 1) continue;
    int np, one;
    const int *ph = elem_phys(g, e, &np, &one);
    if (!np) continue;
    if (e->type != ftype) {
      snprintf(err, MESH_ERRLEN, "%.200s:%ld: element %lld is a facet of type %d, which does not match %s cells", path,
               e->line, (long long)e->id, e->type, cell_name(ct));
      goto fail;
    }
    int v[4], ok = 1;
    for (int j = 0; j < nvf; j++) {
      long k = nodemap_get(nm, e->nodes[j]);
      if (k < 0) {
        snprintf(err, MESH_ERRLEN, "%.200s:%ld: element %lld refers to node %lld, which is not in $Nodes", path,
                 e->line, (long long)e->id, (long long)e->nodes[j]);
        goto fail;
      }
      v[j] = newid[k];
      if (v[j] < 0) ok = 0;
    }
    if (!ok) continue; /* a tagged facet away from the cells carries nothing */
    for (int j = 0; j < np; j++) {
      if (grow((void **)&fv, &capf, (nf + 1) * (size_t)(nvf + 1), sizeof(int)) ||
          grow((void **)&ftag, &capt, nf + 1, sizeof(int)))
        goto oom;
      memcpy(fv + nf * (size_t)(nvf + 1), v, sizeof(int) * (size_t)nvf);
      fv[nf * (size_t)(nvf + 1) + nvf] = ph[j];
      ftag[nf] = ph[j];
      nf++;
    }
  }
  /* the same facet under the same tag twice would be integrated twice: keep one */
  first = malloc(sizeof(long) * nf + 1);
  if (!first || first_duplicates(fv, (long)nf, nvf + 1, nvf, first)) goto oom;
  size_t k = 0;
  for (size_t i = 0; i < nf; i++)
    if (first[i] == (long)i) k++;
  if (k > (size_t)INT_MAX / 4) { snprintf(err, MESH_ERRLEN, "%.200s: too many boundary facets", path); goto fail; }
  m->bf_verts = malloc(sizeof(int) * k * (size_t)nvf + 1);
  m->bf_tag = malloc(sizeof(int) * k + 1);
  if (!m->bf_verts || !m->bf_tag) goto oom;
  k = 0;
  for (size_t i = 0; i < nf; i++) {
    if (first[i] != (long)i) continue;
    memcpy(m->bf_verts + k * (size_t)nvf, fv + i * (size_t)(nvf + 1), sizeof(int) * (size_t)nvf);
    m->bf_tag[k] = ftag[i];
    k++;
  }
  m->nbf = (int)k;
  free(fv); free(ftag); free(first);
  return 0;
oom:
  snprintf(err, MESH_ERRLEN, "%.200s: out of memory", path);
fail:
  free(fv); free(ftag); free(first);
  return 1;
}

/* the physical names of the cells' and facets' dimensions, and every unnamed boundary tag
 * named by its number; 1 when out of memory */
static int set_names(const gfile *g, mesh *m, int cdim) {
  for (size_t i = 0; i < g->nname; i++) {
    int rc = 0;
    if (g->names[i].dim == cdim) rc = mesh_set_region_name(m, g->names[i].tag, g->names[i].name);
    else if (g->names[i].dim == cdim - 1) rc = mesh_set_boundary_name(m, g->names[i].tag, g->names[i].name);
    if (rc) return 1;
  }
  /* unnamed boundary tags are reachable by their number as a name */
  {
    int ntags = mesh_used_boundary_tags(m, NULL, 0);
    int *tags = malloc(sizeof(int) * (size_t)(ntags > 0 ? ntags : 1));
    if (ntags < 0 || !tags) { free(tags); return 1; }
    mesh_used_boundary_tags(m, tags, ntags);
    for (int t = 0; t < ntags; t++) {
      int named = 0;
      for (int i = 0; i < m->nbname && !named; i++) named = m->bnames[i].tag == tags[t];
      char nmb[16];
      snprintf(nmb, sizeof nmb, "%d", tags[t]);
      if (!named && mesh_set_boundary_name(m, tags[t], nmb)) { free(tags); return 1; }
    }
    free(tags);
  }
  return 0;
}

static mesh *build_mesh(gfile *g, const char *path, char *err) {
  int cdim, ctype;
  long nc;
  if (cell_kind(g, path, &cdim, &ctype, &nc, err)) return NULL;
  cell_type ct = gmsh_cell(ctype);
  int nvc = cell_nverts(ct);
  nodemap nm;
  if (nodemap_build(&nm, g, err, path)) { nodemap_free(&nm); return NULL; }
  mesh *m = NULL;
  int *cells = NULL, *ctag = NULL, *newid = NULL;
  long *first = NULL, *elem_of = NULL;
  double *x = NULL;
  if (g->nn > (size_t)INT_MAX) { snprintf(err, MESH_ERRLEN, "%.200s: too many nodes", path); goto fail; }
  cells = malloc(sizeof(int) * (size_t)nc * (size_t)nvc + 1);
  ctag = malloc(sizeof(int) * (size_t)nc + 1);
  elem_of = malloc(sizeof(long) * (size_t)nc + 1);
  newid = malloc(sizeof(int) * g->nn);
  if (!cells || !ctag || !elem_of || !newid) goto oom;
  for (size_t i = 0; i < g->nn; i++) newid[i] = -1;
  /* cells as node indices, each with its one region tag */
  long c = 0;
  for (size_t i = 0; i < g->ne; i++) {
    const gelem *e = &g->e[i];
    if (gmsh_dim(e->type) != cdim) continue;
    for (int j = 0; j < nvc; j++) {
      long k = nodemap_get(&nm, e->nodes[j]);
      if (k < 0) {
        snprintf(err, MESH_ERRLEN, "%.200s:%ld: element %lld refers to node %lld, which is not in $Nodes", path, e->line,
                 (long long)e->id, (long long)e->nodes[j]);
        goto fail;
      }
      for (int i = 0; i < j; i++)
        if (cells[(size_t)c * nvc + i] == (int)k) {
          snprintf(err, MESH_ERRLEN, "%.200s:%ld: element %lld uses node %lld twice (a collapsed cell)", path, e->line,
                   (long long)e->id, (long long)e->nodes[j]);
          goto fail;
        }
      cells[(size_t)c * nvc + j] = (int)k;
      newid[k] = 0;
    }
    int np, one;
    const int *ph = elem_phys(g, e, &np, &one);
    for (int j = 1; j < np; j++)
      if (ph[j] != ph[0]) {
        snprintf(err, MESH_ERRLEN, "%.200s:%ld: element %lld belongs to two physical groups (%d and %d); lugal gives "
                                   "each cell one region: put it in one physical group", path, e->line,
                 (long long)e->id, ph[0], ph[j]);
        goto fail;
      }
    ctag[c] = np ? ph[0] : 0;
    elem_of[c] = (long)i;
    c++;
  }
  /* an element listed twice (MSH 2 repeats an element for each of its physical groups;
   * partitioned files may repeat ghost cells) is one cell */
  first = malloc(sizeof(long) * (size_t)nc + 1);
  if (!first || first_duplicates(cells, nc, nvc, nvc, first)) goto oom;
  long ncu = 0;
  for (long i = 0; i < nc; i++) {
    long f = first[i];
    if (f != i) {
      if (ctag[i] && ctag[f] && ctag[i] != ctag[f]) {
        const gelem *e = &g->e[elem_of[i]], *e0 = &g->e[elem_of[f]];
        snprintf(err, MESH_ERRLEN, "%.200s:%ld: element %lld repeats the cell of element %lld in another physical "
                                   "group (%d and %d); lugal gives each cell one region: put it in one physical group",
                 path, e->line, (long long)e->id, (long long)e0->id, ctag[f], ctag[i]);
        goto fail;
      }
      if (ctag[i]) ctag[f] = ctag[i];
      continue;
    }
    ncu++;
  }
  {
    long k = 0;
    for (long i = 0; i < nc; i++) {
      if (first[i] != i) continue;
      memmove(cells + (size_t)k * nvc, cells + (size_t)i * nvc, sizeof(int) * (size_t)nvc);
      ctag[k] = ctag[i];
      k++;
    }
  }
  /* keep the nodes used by cells, in file order */
  int nv = 0;
  for (size_t i = 0; i < g->nn; i++)
    if (newid[i] == 0) newid[i] = nv++;
  x = malloc(sizeof(double) * (size_t)nv * (size_t)cdim + 1);
  if (!x) goto oom;
  for (size_t i = 0; i < g->nn; i++) {
    if (newid[i] < 0) continue;
    const double *p = g->nx + 3 * i;
    for (int d = 0; d < cdim; d++) x[(size_t)newid[i] * cdim + d] = p[d];
    if (cdim == 1 && (fabs(p[1]) > 1e-12 * (1 + fabs(p[0])) || fabs(p[2]) > 1e-12 * (1 + fabs(p[0])))) {
      snprintf(err, MESH_ERRLEN, "%.200s: a 1D mesh must lie on the x axis (node %lld has y = %g, z = %g)", path,
               (long long)g->ntag[i], p[1], p[2]);
      goto fail;
    }
    if (cdim == 2 && fabs(p[2]) > 1e-12 * (1 + fabs(p[0]) + fabs(p[1]))) {
      snprintf(err, MESH_ERRLEN, "%.200s: a 2D mesh must lie in the plane z = 0 (node %lld has z = %g)", path,
               (long long)g->ntag[i], p[2]);
      goto fail;
    }
  }
  for (long i = 0; i < ncu * nvc; i++) cells[i] = newid[cells[i]];
  m = mesh_create(ct, nv, x, (int)ncu, cells, err);
  if (!m) goto fail;
  memcpy(m->cell_tag, ctag, sizeof(int) * (size_t)ncu);
  mesh_orient_consistently(m);
  if (tagged_facets(g, m, &nm, newid, cdim, path, err)) goto fail;
  if (set_names(g, m, cdim)) goto oom;
  if (mesh_build_boundary_cells(m)) {
    snprintf(err, MESH_ERRLEN, "%.200s: %.300s", path, m->err);
    goto fail;
  }
  nodemap_free(&nm);
  free(cells); free(ctag); free(newid); free(first); free(elem_of); free(x);
  return m;
oom:
  snprintf(err, MESH_ERRLEN, "%.200s: out of memory", path);
fail:
  nodemap_free(&nm);
  free(cells); free(ctag); free(newid); free(first); free(elem_of); free(x);
  mesh_free(m);
  return NULL;
}

/* the reader proper, on a NUL-terminated copy it may modify */
/* the sections the lexer holds, into g (the whole file; or a part's small sections) */
static void read_sections(lex *l, gfile *g) {
  char *t;
  while (!l->failed && (t = tok(l))) {
    if (!strcmp(t, "$MeshFormat")) read_format(l, g);
    else if (t[0] == '$' && !g->version) lex_err(l, "%.40s before $MeshFormat: not a Gmsh MSH file", t);
    else if (!strcmp(t, "$PhysicalNames")) read_names(l, g);
    else if (!strcmp(t, "$Entities") && g->version == 4) read_entities(l, g, 0);
    else if (!strcmp(t, "$PartitionedEntities") && g->version == 4) read_entities(l, g, 1);
    else if (!strcmp(t, "$Nodes")) read_nodes(l, g);
    else if (!strcmp(t, "$Elements")) read_elements(l, g);
    else if (t[0] == '$') skip_section(l, t);
    else if (!g->version) lex_err(l, "not a Gmsh MSH file (it does not start with $MeshFormat)");
    else lex_err(l, "unexpected \"%.32s\" outside any section", t);
  }
}

static mesh *parse(char *buf, size_t len, const char *path, char *err) {
  lex l = {buf, len, 0, 1, 1, path, err, 0};
  gfile g;
  memset(&g, 0, sizeof g);
  read_sections(&l, &g);
  mesh *m = l.failed ? NULL : build_mesh(&g, path, err);
  gfile_free(&g);
  return m;
}

mesh *mesh_read_gmsh_buffer(const char *data, size_t len, const char *name, char *err) {
  char *buf = malloc(len + 1);
  if (!buf) { snprintf(err, MESH_ERRLEN, "%.200s: out of memory for %zu bytes", name, len); return NULL; }
  memcpy(buf, data, len);
  buf[len] = 0;
  mesh *m = parse(buf, len, name, err);
  free(buf);
  return m;
}

/* the whole file: a regular file by its size, a pipe or device until its end */
#define PIPE_LIMIT ((size_t)8 << 30)
#define HEAD_BYTES 4096 /* what a pipe or device must start like a mesh file within */

/* do the first n bytes of a stream start like an MSH file: text whose first word is a
 * section ($MeshFormat, or $Comments and the like)? /dev/zero and endless pipes of anything
 * else were read for gigabytes before the parser saw them */
static int head_like_msh(const char *b, size_t n) {
  size_t i = 0;
  if (n >= 3 && !memcmp(b, "\xef\xbb\xbf", 3)) i = 3; /* a UTF-8 byte order mark */
  while (i < n && (b[i] == ' ' || b[i] == '\t' || b[i] == '\r' || b[i] == '\n')) i++;
  if (i < n && b[i] != '$') return 0;
  return memchr(b, 0, n) == NULL;
}

static char *read_all(const char *path, size_t *len, char *err) {
  int fd = open(path, O_RDONLY | O_CLOEXEC);
  if (fd < 0) { snprintf(err, MESH_ERRLEN, "cannot open %.200s: %s", path, strerror(errno)); return NULL; }
  struct stat st;
  if (fstat(fd, &st)) {
    snprintf(err, MESH_ERRLEN, "cannot read %.200s: %s", path, strerror(errno));
    close(fd);
    return NULL;
  }
  if (S_ISDIR(st.st_mode)) {
    snprintf(err, MESH_ERRLEN, "cannot read %.200s: %s", path, strerror(EISDIR));
    close(fd);
    return NULL;
  }
  size_t cap = S_ISREG(st.st_mode) ? (size_t)st.st_size + 1 : 1 << 16, n = 0;
  char *buf = malloc(cap);
  if (!buf) {
    snprintf(err, MESH_ERRLEN, "cannot read %.200s: out of memory for %zu bytes", path, cap);
    close(fd);
    return NULL;
  }
  for (;;) {
    if (S_ISREG(st.st_mode) && n >= (size_t)st.st_size) break; /* what fstat said; growth is ignored */
    if (n + 1 >= cap) { /* a pipe or a device */
      if (cap >= PIPE_LIMIT) {
        snprintf(err, MESH_ERRLEN, "cannot read %.200s: more than %zu GiB from a pipe or device", path, PIPE_LIMIT >> 30);
        free(buf);
        close(fd);
        return NULL;
      }
      char *nb = realloc(buf, 2 * cap);
      if (!nb) {
        snprintf(err, MESH_ERRLEN, "cannot read %.200s: out of memory after %zu bytes", path, n);
        free(buf);
        close(fd);
        return NULL;
      }
      buf = nb;
      cap *= 2;
    }
    ssize_t got = read(fd, buf + n, cap - 1 - n);
    if (got < 0) {
      if (errno == EINTR) continue;
      snprintf(err, MESH_ERRLEN, "cannot read %.200s: %s", path, strerror(errno));
      free(buf);
      close(fd);
      return NULL;
    }
    size_t before = n;
    if (got > 0) n += (size_t)got;
    if (!S_ISREG(st.st_mode) && before < HEAD_BYTES && (n >= HEAD_BYTES || got == 0) &&
        !head_like_msh(buf, n < HEAD_BYTES ? n : HEAD_BYTES)) {
      snprintf(err, MESH_ERRLEN, "cannot read %.200s: it does not start like a Gmsh MSH file (its first %d bytes are not "
                                 "text opening with a $MeshFormat section)", path, HEAD_BYTES);
      free(buf);
      close(fd);
      return NULL;
    }
    if (got == 0) break;
  }
  close(fd);
  buf[n] = 0;
  *len = n;
  return buf;
}

mesh *mesh_read_gmsh(const char *path, char *err) {
  size_t len;
  char *buf = read_all(path, &len, err);
  if (!buf) return NULL;
  mesh *m = parse(buf, len, path, err);
  free(buf);
  return m;
}

/* ---------------------------------------------------------------- a file read in parts */

int mesh_gmsh_type_dim(int type) { return gmsh_dim(type); }
int mesh_gmsh_type_nodes(int type) { return gmsh_nnodes(type); }
cell_type mesh_gmsh_type_cell(int type) { return gmsh_cell(type); }

/* n bytes of the file from off into b; 1 on a read error or an early end */
static int pread_all(int fd, char *b, size_t n, long long off) {
  for (size_t got = 0; got < n;) {
    ssize_t r = pread(fd, b + got, n - got, (off_t)(off + (long long)got));
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0) return 1;
    got += (size_t)r;
  }
  return 0;
}
/* bytes off .. end - 1 of the file into a NUL-terminated buffer */
static char *read_span(int fd, long long off, long long end) {
  if (end < off) return NULL;
  size_t n = (size_t)(end - off);
  char *b = malloc(n + 1);
  if (b && pread_all(fd, b, n, off)) { free(b); return NULL; }
  if (b) b[n] = 0;
  return b;
}

/* a chunk's items parsed: nothing may follow them */
static int span_done(lex *l) {
  if (l->failed) return 1;
  if (tok(l)) { lex_err(l, "more data than the layout's items"); return 1; }
  return 0;
}

/* a span read in chunks of whole lines, each at most SPAN_CHUNK bytes (a line is at most
 * the layout's 4 MB), so that a part's text is never in memory at once: each chunk a lexer
 * and its count of non-blank lines, one item each as the layout counted them */
#define SPAN_CHUNK ((size_t)8 << 20)
typedef struct {
  int fd;
  long long off, end, line;
  char *buf;
  const char *path;
  char *err;
} spanrd;

static long long span_next(spanrd *r, lex *l) {
  if (r->off >= r->end) return 0;
  if (!r->buf && !(r->buf = malloc(SPAN_CHUNK + 1))) { snprintf(r->err, MESH_ERRLEN, "%.200s: out of memory", r->path); return -1; }
  size_t want = (size_t)(r->end - r->off) < SPAN_CHUNK ? (size_t)(r->end - r->off) : SPAN_CHUNK;
  if (pread_all(r->fd, r->buf, want, r->off)) { snprintf(r->err, MESH_ERRLEN, "%.200s: cannot read", r->path); return -1; }
  size_t len = want;
  if (r->off + (long long)want < r->end) { /* whole lines only */
    while (len && r->buf[len - 1] != '\n') len--;
    if (!len) { snprintf(r->err, MESH_ERRLEN, "%.200s: a line over %zu bytes", r->path, SPAN_CHUNK); return -1; }
  }
  r->buf[len] = 0;
  long long items = 0, lines = 0;
  int text = 0;
  for (size_t i = 0; i < len; i++) {
    char c = r->buf[i];
    if (c == '\n') { items += text; text = 0; lines++; }
    else if (!isspace((unsigned char)c)) text = 1;
  }
  items += text;
  *l = (lex){r->buf, len, 0, r->line, r->line, r->path, r->err, 0};
  r->line += lines;
  r->off += (long long)len;
  return items;
}

/* the span of part p's run within block B (second: MSH 4 nodes' coordinates) */
static int run_span(const gmsh_block *B, const gmsh_pos *pos, long long lo, long long hi, int p, int second,
                    gmsh_span *s, long long *first, long long *count) {
  long long a = lo > B->first ? lo : B->first, e = hi < B->first + B->count ? hi : B->first + B->count;
  if (a >= e) return 0;
  const gmsh_span *bs = second ? &B->b : &B->a;
  s->off = a == B->first ? bs->off : second ? pos[p].boff : pos[p].aoff;
  s->line = a == B->first ? bs->line : second ? pos[p].bline : pos[p].aline;
  s->end = e == B->first + B->count ? bs->end : second ? pos[p + 1].boff : pos[p + 1].aoff;
  *first = a;
  *count = e - a;
  return 1;
}

void mesh_gmsh_part_free(gmsh_part *g) {
  free(g->ntag); free(g->nx); free(g->e); free(g->enodes); free(g->phys); free(g->name_dim);
  for (int i = 0; i < g->nname; i++) free(g->names[i].name);
  free(g->names);
  memset(g, 0, sizeof *g);
}

/* the nodes lo .. hi - 1 of the file (this part's run) into g, from the layout's node
 * blocks (MSH 4: tags and coordinates in two spans); 1 with the message */
static int read_run_nodes(int fd, const gmsh_layout *L, int p, long long lo, long long hi, gfile *g, lex *lp, const char *path, char *err) {
  lex l = *lp;
  if (node_reserve(&l, g, (size_t)(hi - lo) + 1)) goto fail;
  for (int b = 0; b < L->nnb; b++) {
    const gmsh_block *B = &L->nb[b];
    gmsh_span s;
    long long first, count;
    if (!run_span(B, L->np, lo, hi, p, 0, &s, &first, &count)) continue;
    size_t at = (size_t)(first - lo);
    for (int second = 0; second <= (L->version == 4); second++) {
      if (second) run_span(B, L->np, lo, hi, p, 1, &s, &first, &count);
      spanrd sr = {fd, s.off, s.end, s.line, NULL, path, err};
      long long k, i = 0;
      while ((k = span_next(&sr, &l)) > 0) {
        for (long long j = 0; j < k && i < count && !l.failed; j++, i++) {
          size_t q = at + (size_t)i;
          if (!second) {
            g->ntag[q] = tok_int(&l, "node tag", 1, INT64_MAX);
            if (L->version == 2) read_coords(&l, g->ntag[q], g->nx + 3 * q);
          } else {
            read_coords(&l, g->ntag[q], g->nx + 3 * q);
            for (int d = 0; B->par && d < B->edim && !l.failed; d++) tok_real(&l, "parametric coordinate");
          }
        }
        if (span_done(&l)) break;
      }
      free(sr.buf);
      if (k < 0 || l.failed || i != count) {
        if (!err[0]) snprintf(err, MESH_ERRLEN, "%.200s: a node run does not hold its nodes", path);
        goto fail;
      }
    }
  }
  *lp = l;
  return 0;
fail:
  *lp = l;
  return 1;
}

/* the elements lo .. hi - 1 of the file (this part's run) into out (out->e, out->enodes,
 * out->phys allocated), their physical tags the entities' of g (MSH 4) or their own (MSH
 * 2); 1 with the message */
static int read_run_elements(int fd, const gmsh_layout *L, int p, long long lo, long long hi, gfile *g, gmsh_part *out, size_t capn,
                             lex *lp, const char *path, char *err) {
  lex l = *lp;
  size_t nnodes = 0;
  int nph = 0;
  for (int b = 0; b < L->neb; b++) {
    const gmsh_block *B = &L->eb[b];
    gmsh_span s;
    long long first, count;
    if (!run_span(B, L->ep, lo, hi, p, 0, &s, &first, &count)) continue;
    gelem e;
    memset(&e, 0, sizeof e);
    int enp = 0, eoff = 0;
    if (L->version == 4) {
      e.edim = B->edim;
      e.etag = B->etag;
      e.nn = gmsh_nnodes(B->type);
      if (!e.nn || gmsh_dim(B->type) != e.edim) {
        snprintf(err, MESH_ERRLEN, "%.200s: an element block of type %d on an entity of dimension %d", path, B->type, B->edim);
        goto fail;
      }
      e.type = B->type;
      int one;
      const int *ph = elem_phys(g, &e, &enp, &one);
      eoff = enp ? (int)(ph - g->phys) : 0;
    }
    spanrd sr = {fd, s.off, s.end, s.line, NULL, path, err};
    long long k, i = 0;
    while ((k = span_next(&sr, &l)) > 0) {
      for (long long j = 0; j < k && i < count && !l.failed; j++, i++) {
        gmsh_elem *o = &out->e[out->ne];
        memset(o, 0, sizeof *o);
        if (L->version == 2) {
          if (read_elem2_head(&l, &e)) break;
          o->type = e.type;
          o->nphys = e.phys != 0;
          o->phys = nph;
          if (e.phys) out->phys[nph++] = e.phys;
        } else {
          tok_int(&l, "element tag", 1, INT64_MAX);
          o->type = e.type;
          o->nphys = enp;
          o->phys = eoff;
        }
        if (nnodes + 8 > capn && GROW(&l, out->enodes, capn, nnodes + 8)) break;
        o->node = (long long)nnodes;
        for (int q = 0; q < e.nn && !l.failed; q++) out->enodes[nnodes++] = tok_int(&l, "element node", 1, INT64_MAX);
        if (!l.failed) out->ne++;
      }
      if (span_done(&l)) break;
    }
    free(sr.buf);
    if (k < 0 || l.failed || i != count) {
      if (!err[0]) snprintf(err, MESH_ERRLEN, "%.200s: an element run does not hold its elements", path);
      goto fail;
    }
  }
  *lp = l;
  return 0;
fail:
  *lp = l;
  return 1;
}

int mesh_gmsh_read_part(const char *path, const gmsh_layout *L, int p, gmsh_part *out, char *err) {
  memset(out, 0, sizeof *out);
  err[0] = 0;
  gfile g;
  memset(&g, 0, sizeof g);
  lex l = {NULL, 0, 0, 1, 1, path, err, 0};
  int fd = open(path, O_RDONLY | O_CLOEXEC), rc = 1;
  char *buf = NULL;
  if (fd < 0) { snprintf(err, MESH_ERRLEN, "cannot open %.200s: %s", path, strerror(errno)); return 1; }
  if (!L->ok || p < 0 || p >= L->nparts) { snprintf(err, MESH_ERRLEN, "%.200s: no layout for part %d", path, p); goto done; }
  /* the small sections, as the whole reader takes them */
  for (int i = 0; i < L->nsmall; i++) {
    const gmsh_span *sp = &L->small[i];
    if (!(buf = read_span(fd, sp->off, sp->end))) { snprintf(err, MESH_ERRLEN, "%.200s: cannot read", path); goto done; }
    l = (lex){buf, (size_t)(sp->end - sp->off), 0, sp->line, sp->line, path, err, 0};
    read_sections(&l, &g);
    free(buf);
    buf = NULL;
    if (l.failed) goto done;
  }
  if (g.version != L->version) { snprintf(err, MESH_ERRLEN, "%.200s: the layout's version differs", path); goto done; }
  if (g.nent) qsort(g.ent, g.nent, sizeof(gentity), ent_cmp);
  for (size_t i = 1; i < g.nent; i++)
    if (!ent_cmp(&g.ent[i], &g.ent[i - 1])) { snprintf(err, MESH_ERRLEN, "%.200s: an entity defined twice", path); goto done; }
  /* the nodes of this part's run */
  long long lo = gmsh_run_start(L->nnodes, L->nparts, p), hi = gmsh_run_start(L->nnodes, L->nparts, p + 1);
  out->node_first = lo;
  /* the runs' counts against their bytes before anything is allocated, as the whole reader
   * checks its counts: a node takes 4 tokens (8 bytes), an element 2 at least (4 bytes) */
  for (int pass = 0; pass < 2; pass++) {
    long long a = gmsh_run_start(pass ? L->nelems : L->nnodes, L->nparts, p), e = gmsh_run_start(pass ? L->nelems : L->nnodes, L->nparts, p + 1),
              bytes = 0, first, count;
    for (int b = 0; b < (pass ? L->neb : L->nnb); b++) {
      gmsh_span sa, sb;
      const gmsh_block *B = pass ? &L->eb[b] : &L->nb[b];
      const gmsh_pos *pos = pass ? L->ep : L->np;
      if (!run_span(B, pos, a, e, p, 0, &sa, &first, &count)) continue;
      bytes += sa.end - sa.off;
      if (!pass && L->version == 4 && run_span(B, pos, a, e, p, 1, &sb, &first, &count)) bytes += sb.end - sb.off;
    }
    if ((e - a) * (pass ? 4 : 8) > bytes + 8) {
      snprintf(err, MESH_ERRLEN, "%.200s: %lld %s in %lld bytes", path, e - a, pass ? "elements" : "nodes", bytes);
      goto done;
    }
  }
  if (read_run_nodes(fd, L, p, lo, hi, &g, &l, path, err)) goto done;
  g.nn = (size_t)(hi - lo);
  /* the elements of this part's run, straight into out: their physical tags are the
   * entities' (MSH 4: out->phys is the entities' list) or their own (MSH 2: one each) */
  lo = gmsh_run_start(L->nelems, L->nparts, p);
  hi = gmsh_run_start(L->nelems, L->nparts, p + 1);
  out->version = g.version;
  out->elem_first = lo;
  out->e = malloc(sizeof(gmsh_elem) * ((size_t)(hi - lo) + 1));
  out->phys = malloc(sizeof(int) * ((L->version == 2 ? (size_t)(hi - lo) : g.nphys) + 1));
  size_t capn = 4 * (size_t)(hi - lo) + 16; /* grown for hexahedra */
  out->enodes = malloc(sizeof(long long) * capn);
  if (!out->e || !out->phys || !out->enodes) { snprintf(err, MESH_ERRLEN, "%.200s: out of memory", path); goto done; }
  if (L->version == 4) memcpy(out->phys, g.phys, sizeof(int) * g.nphys);
  if (read_run_elements(fd, L, p, lo, hi, &g, out, capn, &l, path, err)) goto done;
  /* out: the nodes as read, the names */
  out->nn = (long long)g.nn;
  out->ntag = (long long *)g.ntag; /* int64_t and long long: both 64 bits here */
  out->nx = g.nx;
  g.ntag = NULL;
  g.nx = NULL;
  out->names = calloc(g.nname + 1, sizeof(mesh_name));
  out->name_dim = malloc(sizeof(int) * (g.nname + 1));
  if (!out->names || !out->name_dim) { snprintf(err, MESH_ERRLEN, "%.200s: out of memory", path); goto done; }
  for (size_t i = 0; i < g.nname; i++) {
    out->names[i].tag = g.names[i].tag;
    out->names[i].name = g.names[i].name;
    out->name_dim[i] = g.names[i].dim;
    g.names[i].name = NULL;
    out->nname++;
  }
  rc = 0;
done:
  close(fd);
  free(buf);
  gfile_free(&g);
  if (rc) mesh_gmsh_part_free(out);
  return rc;
}

/* ---------------------------------------------------------------- writer */

/* a quoted name with ", \ and newlines escaped as the reader unescapes them */
static void write_name(FILE *f, const char *s) {
  fputc('"', f);
  for (; *s; s++) {
    if (*s == '"' || *s == '\\') { fputc('\\', f); fputc(*s, f); }
    else if (*s == '\n') fputs("\\n", f);
    else if (*s == '\r') fputs("\\r", f);
    else fputc(*s, f);
  }
  fputc('"', f);
}

int mesh_write_gmsh(mesh *m, const char *path) {
  outfile o;
  if (outfile_open(&o, path, m->err, MESH_ERRLEN)) return 1;
  FILE *f = o.f;
  static const int ctype[] = {2, 3, 4, 5, 1};
  int ftype = m->dim == 1 ? 15 : m->dim == 2 ? 1 : (m->nvf == 3 ? 2 : 3);
  fprintf(f, "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n");
  if (m->nbname + m->ncname) {
    fprintf(f, "$PhysicalNames\n%d\n", m->nbname + m->ncname);
    for (int i = 0; i < m->nbname; i++) {
      fprintf(f, "%d %d ", m->dim - 1, m->bnames[i].tag);
      write_name(f, m->bnames[i].name);
      fputc('\n', f);
    }
    for (int i = 0; i < m->ncname; i++) {
      fprintf(f, "%d %d ", m->dim, m->cnames[i].tag);
      write_name(f, m->cnames[i].name);
      fputc('\n', f);
    }
    fprintf(f, "$EndPhysicalNames\n");
  }
  fprintf(f, "$Nodes\n%d\n", m->nvert);
  for (int i = 0; i < m->nvert; i++)
    fprintf(f, "%d %.17g %.17g %.17g\n", i + 1, m->x[(size_t)m->dim * i], m->dim >= 2 ? m->x[(size_t)m->dim * i + 1] : 0.0,
            m->dim == 3 ? m->x[3 * (size_t)i + 2] : 0.0);
  fprintf(f, "$EndNodes\n$Elements\n%d\n", m->nbf + m->ncell);
  int id = 1;
  for (int b = 0; b < m->nbf; b++) {
    fprintf(f, "%d %d 2 %d %d", id++, ftype, m->bf_tag[b], m->bf_tag[b]);
    for (int j = 0; j < m->nvf; j++) fprintf(f, " %d", m->bf_verts[(size_t)b * m->nvf + j] + 1);
    fputc('\n', f);
  }
  for (int c = 0; c < m->ncell; c++) {
    fprintf(f, "%d %d 2 %d %d", id++, ctype[m->type], m->cell_tag[c], m->cell_tag[c] ? m->cell_tag[c] : 1);
    for (int j = 0; j < m->nvc; j++) fprintf(f, " %d", m->cells[(size_t)c * m->nvc + j] + 1);
    fputc('\n', f);
  }
  fprintf(f, "$EndElements\n");
  return outfile_commit(&o, m->err, MESH_ERRLEN);
}
