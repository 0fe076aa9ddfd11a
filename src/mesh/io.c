/* io.c — mesh files: the Gmsh MSH 2.2 / 4.1 ASCII reader, an MSH 2.2 writer, the VTK
 * XML unstructured-grid (.vtu) writer and .pvd collections for ParaView. */
#include "mesh.h"

#include <ctype.h>
#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---------------------------------------------------------------- tokenizer */

typedef struct {
  char *buf;
  size_t len, pos;
  int line;
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
  snprintf(l->err, MESH_ERRLEN, "%.200s:%d: %.290s", l->path, l->line, msg);
  l->failed = 1;
}

/* next whitespace-delimited token (NUL-terminated in place); NULL at end of file */
static char *tok(lex *l) {
  if (l->failed) return NULL;
  while (l->pos < l->len && isspace((unsigned char)l->buf[l->pos])) {
    if (l->buf[l->pos] == '\n') l->line++;
    l->pos++;
  }
  if (l->pos >= l->len) return NULL;
  char *s = l->buf + l->pos;
  if (*s == '"') { /* quoted string */
    l->pos++;
    s++;
    while (l->pos < l->len && l->buf[l->pos] != '"' && l->buf[l->pos] != '\n') l->pos++;
    if (l->pos < l->len && l->buf[l->pos] == '"') l->buf[l->pos++] = 0;
    return s;
  }
  while (l->pos < l->len && !isspace((unsigned char)l->buf[l->pos])) l->pos++;
  if (l->pos < l->len) {
    if (l->buf[l->pos] == '\n') { l->buf[l->pos] = 0; l->pos++; l->line++; }
    else l->buf[l->pos++] = 0;
  }
  return s;
}

static long tok_long(lex *l, const char *what) {
  char *t = tok(l);
  if (!t) { lex_err(l, "file ends early: expected %s", what); return 0; }
  char *end;
  errno = 0;
  long v = strtol(t, &end, 10);
  if (*end || errno) { lex_err(l, "expected %s (an integer), found \"%.32s\"", what, t); return 0; }
  return v;
}

static double tok_double(lex *l, const char *what) {
  char *t = tok(l);
  if (!t) { lex_err(l, "file ends early: expected %s", what); return 0; }
  char *end;
  double v = strtod(t, &end);
  if (*end) { lex_err(l, "expected %s (a number), found \"%.32s\"", what, t); return 0; }
  return v;
}

static void expect(lex *l, const char *word) {
  char *t = tok(l);
  if (!t) { lex_err(l, "file ends early: expected %s", word); return; }
  if (strcmp(t, word)) lex_err(l, "expected %s, found \"%.32s\"", word, t);
}

/* skip to the end marker of an unknown section */
static void skip_section(lex *l, const char *name) {
  char end[80];
  snprintf(end, sizeof end, "$End%s", name + 1);
  for (char *t; (t = tok(l));)
    if (!strcmp(t, end)) return;
  lex_err(l, "section %s is not closed by %s", name, end);
}

/* ---------------------------------------------------------------- gmsh */

/* nodes per element for Gmsh element types 1..15 (0 = unsupported) */
static int gmsh_nnodes(int type) {
  static const int n[] = {0, 2, 3, 4, 4, 8, 6, 5, 3, 6, 9, 10, 27, 18, 14, 1};
  if (type >= 1 && type <= 15) return n[type];
  return 0;
}
/* dimension and lugal cell type of a first-order Gmsh type; -1 when not first order */
static int gmsh_kind(int type, int *dim) {
  switch (type) {
  case 15: *dim = 0; return -2;
  case 1: *dim = 1; return -3;
  case 2: *dim = 2; return CELL_TRIANGLE;
  case 3: *dim = 2; return CELL_QUADRILATERAL;
  case 4: *dim = 3; return CELL_TETRAHEDRON;
  case 5: *dim = 3; return CELL_HEXAHEDRON;
  default: *dim = -1; return -1;
  }
}

typedef struct {
  int type, dim, phys, nn;
  long nodes[8];
} gelem;

typedef struct {
  long n, cap;
  gelem *e;
} gelems;

static int push_elem(gelems *g, const gelem *e) {
  if (g->n == g->cap) {
    long cap = g->cap ? 2 * g->cap : 1024;
    gelem *ne = realloc(g->e, sizeof(gelem) * (size_t)cap);
    if (!ne) return 1;
    g->e = ne;
    g->cap = cap;
  }
  g->e[g->n++] = *e;
  return 0;
}

typedef struct {
  int dim, tag, phys;
} gentity;

static char *read_file(const char *path, size_t *len, char *err) {
  FILE *f = fopen(path, "rb");
  if (!f) {
    snprintf(err, MESH_ERRLEN, "cannot open %s: %s", path, strerror(errno));
    return NULL;
  }
  if (fseek(f, 0, SEEK_END)) { fclose(f); snprintf(err, MESH_ERRLEN, "cannot read %s", path); return NULL; }
  long n = ftell(f);
  rewind(f);
  if (n < 0) { fclose(f); snprintf(err, MESH_ERRLEN, "cannot read %s", path); return NULL; }
  char *buf = malloc((size_t)n + 1);
  if (!buf) { fclose(f); snprintf(err, MESH_ERRLEN, "out of memory reading %s", path); return NULL; }
  size_t got = fread(buf, 1, (size_t)n, f);
  fclose(f);
  buf[got] = 0;
  *len = got;
  return buf;
}

mesh *mesh_read_gmsh(const char *path, char *err) {
  size_t len;
  char *buf = read_file(path, &len, err);
  if (!buf) return NULL;
  lex l = {buf, len, 0, 1, path, err, 0};
  int version = 0;
  long nnodes = 0;
  long *ntag = NULL;
  double *nx = NULL;
  gelems ge = {0, 0, NULL};
  gentity *ents = NULL;
  long nent = 0;
  mesh_name pn[MESH_MAXNAMES];
  int pdim[MESH_MAXNAMES], npn = 0;
  mesh *m = NULL;
  int have_nodes = 0, have_elems = 0;

  char *t;
  while (!l.failed && (t = tok(&l))) {
    if (!strcmp(t, "$MeshFormat")) {
      char *v = tok(&l);
      if (!v) { lex_err(&l, "file ends in $MeshFormat"); break; }
      double ver = atof(v);
      long ft = tok_long(&l, "file type");
      tok_long(&l, "data size");
      if (l.failed) break;
      if (ft != 0) { lex_err(&l, "binary MSH files are not supported; save as ASCII"); break; }
      if (fabs(ver - 2.2) < 1e-9 || fabs(ver - 2.0) < 1e-9 || fabs(ver - 2.1) < 1e-9) version = 2;
      else if (fabs(ver - 4.1) < 1e-9) version = 4;
      else { lex_err(&l, "MSH version %s is not supported (2.2 and 4.1 are)", v); break; }
      expect(&l, "$EndMeshFormat");
    } else if (!strcmp(t, "$PhysicalNames")) {
      long n = tok_long(&l, "number of physical names");
      for (long i = 0; i < n && !l.failed; i++) {
        int d = (int)tok_long(&l, "physical dimension");
        int tg = (int)tok_long(&l, "physical tag");
        char *nm = tok(&l);
        if (!nm) { lex_err(&l, "file ends in $PhysicalNames"); break; }
        if (npn < MESH_MAXNAMES) {
          pn[npn].tag = tg;
          snprintf(pn[npn].name, sizeof pn[npn].name, "%s", nm);
          pdim[npn++] = d;
        }
      }
      expect(&l, "$EndPhysicalNames");
    } else if (!strcmp(t, "$Entities")) {
      long cnt[4];
      for (int d = 0; d < 4; d++) cnt[d] = tok_long(&l, "number of entities");
      if (l.failed) break;
      nent = cnt[0] + cnt[1] + cnt[2] + cnt[3];
      if (nent < 0 || nent > 100000000) { lex_err(&l, "bad entity count"); break; }
      ents = calloc((size_t)nent + 1, sizeof *ents);
      if (!ents) { lex_err(&l, "out of memory"); break; }
      long k = 0;
      for (int d = 0; d < 4 && !l.failed; d++)
        for (long i = 0; i < cnt[d] && !l.failed; i++, k++) {
          ents[k].dim = d;
          ents[k].tag = (int)tok_long(&l, "entity tag");
          int nb = d == 0 ? 3 : 6;
          for (int j = 0; j < nb; j++) tok_double(&l, "entity bounding box");
          long np = tok_long(&l, "number of physical tags");
          ents[k].phys = 0;
          for (long j = 0; j < np; j++) {
            int p = (int)tok_long(&l, "physical tag");
            if (j == 0) ents[k].phys = p;
          }
          if (d > 0) {
            long nbd = tok_long(&l, "number of bounding entities");
            for (long j = 0; j < nbd && !l.failed; j++) tok_long(&l, "bounding entity");
          }
        }
      expect(&l, "$EndEntities");
    } else if (!strcmp(t, "$Nodes")) {
      if (!version) { lex_err(&l, "$Nodes before $MeshFormat"); break; }
      have_nodes = 1;
      if (version == 2) {
        nnodes = tok_long(&l, "number of nodes");
        if (l.failed) break;
        if (nnodes <= 0 || nnodes > 1000000000L) { lex_err(&l, "bad node count %ld", nnodes); break; }
        ntag = malloc(sizeof(long) * (size_t)nnodes);
        nx = malloc(sizeof(double) * 3 * (size_t)nnodes);
        if (!ntag || !nx) { lex_err(&l, "out of memory"); break; }
        for (long i = 0; i < nnodes && !l.failed; i++) {
          ntag[i] = tok_long(&l, "node tag");
          for (int d = 0; d < 3; d++) nx[3 * i + d] = tok_double(&l, "node coordinate");
        }
      } else {
        long nb = tok_long(&l, "number of node blocks");
        nnodes = tok_long(&l, "number of nodes");
        tok_long(&l, "min node tag");
        tok_long(&l, "max node tag");
        if (l.failed) break;
        if (nnodes <= 0 || nnodes > 1000000000L) { lex_err(&l, "bad node count %ld", nnodes); break; }
        ntag = malloc(sizeof(long) * (size_t)nnodes);
        nx = malloc(sizeof(double) * 3 * (size_t)nnodes);
        if (!ntag || !nx) { lex_err(&l, "out of memory"); break; }
        long k = 0;
        for (long b = 0; b < nb && !l.failed; b++) {
          tok_long(&l, "entity dimension");
          tok_long(&l, "entity tag");
          long par = tok_long(&l, "parametric flag");
          long n = tok_long(&l, "nodes in block");
          if (l.failed) break;
          if (n < 0 || k + n > nnodes) { lex_err(&l, "node blocks hold more nodes than declared"); break; }
          for (long i = 0; i < n; i++) ntag[k + i] = tok_long(&l, "node tag");
          for (long i = 0; i < n && !l.failed; i++) {
            for (int d = 0; d < 3; d++) nx[3 * (k + i) + d] = tok_double(&l, "node coordinate");
            if (par) { lex_err(&l, "parametric nodes are not supported"); break; }
          }
          k += n;
        }
        if (!l.failed && k != nnodes) lex_err(&l, "node blocks hold %ld nodes, header says %ld", k, nnodes);
      }
      expect(&l, "$EndNodes");
    } else if (!strcmp(t, "$Elements")) {
      if (!version) { lex_err(&l, "$Elements before $MeshFormat"); break; }
      have_elems = 1;
      if (version == 2) {
        long n = tok_long(&l, "number of elements");
        for (long i = 0; i < n && !l.failed; i++) {
          gelem e;
          tok_long(&l, "element tag");
          e.type = (int)tok_long(&l, "element type");
          long nt = tok_long(&l, "number of element tags");
          e.phys = 0;
          for (long j = 0; j < nt; j++) {
            long v = tok_long(&l, "element tag");
            if (j == 0) e.phys = (int)v;
          }
          if (l.failed) break;
          e.nn = gmsh_nnodes(e.type);
          int kind = gmsh_kind(e.type, &e.dim);
          if (kind == -1) {
            lex_err(&l, "Gmsh element type %d is not supported: lugal reads first-order "
                        "points, lines, triangles, quadrilaterals, tetrahedra and hexahedra "
                        "(set Mesh.ElementOrder = 1)", e.type);
            break;
          }
          for (int j = 0; j < e.nn; j++) e.nodes[j] = tok_long(&l, "element node");
          if (!l.failed && push_elem(&ge, &e)) lex_err(&l, "out of memory");
        }
      } else {
        long nb = tok_long(&l, "number of element blocks");
        tok_long(&l, "number of elements");
        tok_long(&l, "min element tag");
        tok_long(&l, "max element tag");
        for (long b = 0; b < nb && !l.failed; b++) {
          int ed = (int)tok_long(&l, "entity dimension");
          int et = (int)tok_long(&l, "entity tag");
          int type = (int)tok_long(&l, "element type");
          long n = tok_long(&l, "elements in block");
          if (l.failed) break;
          gelem e;
          e.type = type;
          e.nn = gmsh_nnodes(type);
          int kind = gmsh_kind(type, &e.dim);
          if (kind == -1) {
            lex_err(&l, "Gmsh element type %d is not supported: lugal reads first-order "
                        "points, lines, triangles, quadrilaterals, tetrahedra and hexahedra "
                        "(set Mesh.ElementOrder = 1)", type);
            break;
          }
          e.phys = 0;
          for (long k = 0; k < nent; k++)
            if (ents[k].dim == ed && ents[k].tag == et) { e.phys = ents[k].phys; break; }
          for (long i = 0; i < n && !l.failed; i++) {
            tok_long(&l, "element tag");
            for (int j = 0; j < e.nn; j++) e.nodes[j] = tok_long(&l, "element node");
            if (!l.failed && push_elem(&ge, &e)) lex_err(&l, "out of memory");
          }
        }
      }
      expect(&l, "$EndElements");
    } else if (t[0] == '$') {
      skip_section(&l, t);
    } else {
      lex_err(&l, "unexpected \"%.32s\" outside any section", t);
    }
  }
  if (l.failed) goto fail;
  if (!version) { snprintf(err, MESH_ERRLEN, "%s: not a Gmsh MSH file (no $MeshFormat)", path); goto fail; }
  if (!have_nodes || !have_elems) {
    snprintf(err, MESH_ERRLEN, "%s: file is truncated or incomplete: no %s section", path,
             have_nodes ? "$Elements" : "$Nodes");
    goto fail;
  }
  {
    /* the cells are the elements of the highest dimension */
    int cdim = 0, ctype = -1;
    for (long i = 0; i < ge.n; i++)
      if (ge.e[i].dim > cdim) cdim = ge.e[i].dim;
    if (cdim < 2) { snprintf(err, MESH_ERRLEN, "%s: no 2D or 3D elements", path); goto fail; }
    long nc = 0;
    for (long i = 0; i < ge.n; i++) {
      if (ge.e[i].dim != cdim) continue;
      int d, k = gmsh_kind(ge.e[i].type, &d);
      if (ctype < 0) ctype = k;
      else if (ctype != k) {
        snprintf(err, MESH_ERRLEN, "%s: mixes %s and %s cells; lugal meshes have one cell type",
                 path, cell_name((cell_type)ctype), cell_name((cell_type)k));
        goto fail;
      }
      nc++;
    }
    /* node tag → index */
    long maxtag = 0;
    for (long i = 0; i < nnodes; i++) {
      if (ntag[i] <= 0) { snprintf(err, MESH_ERRLEN, "%s: node tag %ld is not positive", path, ntag[i]); goto fail; }
      if (ntag[i] > maxtag) maxtag = ntag[i];
    }
    if (maxtag > 20 * nnodes + 1000000) {
      snprintf(err, MESH_ERRLEN, "%s: node tags are too sparse (max %ld for %ld nodes)", path, maxtag, nnodes);
      goto fail;
    }
    long *map = malloc(sizeof(long) * (size_t)(maxtag + 1));
    int *newid = malloc(sizeof(int) * (size_t)nnodes);
    if (!map || !newid) { free(map); free(newid); snprintf(err, MESH_ERRLEN, "out of memory"); goto fail; }
    for (long i = 0; i <= maxtag; i++) map[i] = -1;
    for (long i = 0; i < nnodes; i++) map[ntag[i]] = i;
    for (long i = 0; i < nnodes; i++) newid[i] = -1;
    /* keep only nodes used by cells, in file order */
    for (long i = 0; i < ge.n; i++) {
      for (int j = 0; j < ge.e[i].nn; j++) {
        long tg = ge.e[i].nodes[j];
        if (tg <= 0 || tg > maxtag || map[tg] < 0) {
          snprintf(err, MESH_ERRLEN, "%s: an element refers to node %ld, which is not in $Nodes", path, tg);
          free(map); free(newid);
          goto fail;
        }
        if (ge.e[i].dim == cdim) newid[map[tg]] = 0;
      }
    }
    int nv = 0;
    for (long i = 0; i < nnodes; i++)
      if (newid[i] == 0) newid[i] = nv++;
    double *x = malloc(sizeof(double) * (size_t)nv * (size_t)cdim);
    int *cells = malloc(sizeof(int) * (size_t)nc * 8);
    if (!x || !cells) { free(x); free(cells); free(map); free(newid); snprintf(err, MESH_ERRLEN, "out of memory"); goto fail; }
    for (long i = 0; i < nnodes; i++) {
      if (newid[i] < 0) continue;
      for (int d = 0; d < cdim; d++) x[(size_t)newid[i] * cdim + d] = nx[3 * i + d];
      if (cdim == 2 && fabs(nx[3 * i + 2]) > 1e-12 * (1 + fabs(nx[3 * i]) + fabs(nx[3 * i + 1]))) {
        snprintf(err, MESH_ERRLEN, "%s: a 2D mesh must lie in the plane z = 0 (node %ld has z = %g)",
                 path, ntag[i], nx[3 * i + 2]);
        free(x); free(cells); free(map); free(newid);
        goto fail;
      }
    }
    int nvc = cell_nverts((cell_type)ctype);
    long c = 0;
    for (long i = 0; i < ge.n; i++) {
      if (ge.e[i].dim != cdim) continue;
      for (int j = 0; j < nvc; j++) cells[c * nvc + j] = newid[map[ge.e[i].nodes[j]]];
      c++;
    }
    m = mesh_create((cell_type)ctype, nv, x, (int)nc, cells, err);
    free(x);
    free(cells);
    if (!m) { free(map); free(newid); goto fail; }
    c = 0;
    for (long i = 0; i < ge.n; i++)
      if (ge.e[i].dim == cdim) m->cell_tag[c++] = ge.e[i].phys;
    /* a mesh whose every cell is negatively oriented was written with the opposite
     * convention: flip all (a mixed mesh is left as is: it is tangled) */
    if (ctype == CELL_TRIANGLE || ctype == CELL_TETRAHEDRON) {
      long neg = 0;
      for (int k = 0; k < m->ncell; k++) neg += mesh_cell_signed_measure(m, k) < 0;
      if (neg == m->ncell)
        for (int k = 0; k < m->ncell; k++) {
          int *v = m->cells + (size_t)k * nvc, tt = v[nvc - 1];
          v[nvc - 1] = v[nvc - 2];
          v[nvc - 2] = tt;
        }
    }
    /* facets with a physical tag become tagged boundary facets */
    int nvf = m->nvf;
    int fv[4];
    for (long i = 0; i < ge.n; i++) {
      if (ge.e[i].dim != cdim - 1 || ge.e[i].phys == 0) continue;
      if (ge.e[i].nn != nvf) {
        snprintf(err, MESH_ERRLEN, "%s: facet element of type %d does not match %s cells",
                 path, ge.e[i].type, cell_name(m->type));
        free(map); free(newid);
        goto fail;
      }
      int ok = 1;
      for (int j = 0; j < nvf; j++) {
        fv[j] = newid[map[ge.e[i].nodes[j]]];
        if (fv[j] < 0) ok = 0;
      }
      if (!ok) continue; /* a tagged facet away from the cells: ignore */
      if (mesh_add_boundary_facets(m, 1, fv, ge.e[i].phys, NULL)) {
        snprintf(err, MESH_ERRLEN, "%.200s: %.300s", path, m->err);
        free(map); free(newid);
        goto fail;
      }
    }
    free(map);
    free(newid);
    for (int i = 0; i < npn; i++) {
      if (pdim[i] == cdim) mesh_set_region_name(m, pn[i].tag, pn[i].name);
      else if (pdim[i] == cdim - 1) mesh_set_boundary_name(m, pn[i].tag, pn[i].name);
    }
    /* unnamed boundary tags are reachable by their number as a name */
    for (int b = 0; b < m->nbf; b++) {
      int named = 0;
      for (int i = 0; i < m->nbname; i++) named |= m->bnames[i].tag == m->bf_tag[b];
      if (!named) {
        char nm[32];
        snprintf(nm, sizeof nm, "%d", m->bf_tag[b]);
        mesh_set_boundary_name(m, m->bf_tag[b], nm);
      }
    }
    if (mesh_build_boundary_cells(m)) {
      snprintf(err, MESH_ERRLEN, "%.200s: %.300s", path, m->err);
      goto fail;
    }
  }
  free(buf); free(ntag); free(nx); free(ge.e); free(ents);
  return m;
fail:
  mesh_free(m);
  free(buf); free(ntag); free(nx); free(ge.e); free(ents);
  return NULL;
}

int mesh_write_gmsh(mesh *m, const char *path) {
  FILE *f = fopen(path, "w");
  if (!f) { snprintf(m->err, MESH_ERRLEN, "cannot write %s: %s", path, strerror(errno)); return 1; }
  static const int ctype[] = {2, 3, 4, 5};
  int ftype = m->dim == 2 ? 1 : (m->nvf == 3 ? 2 : 3);
  fprintf(f, "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n");
  if (m->nbname + m->ncname) {
    fprintf(f, "$PhysicalNames\n%d\n", m->nbname + m->ncname);
    for (int i = 0; i < m->nbname; i++) fprintf(f, "%d %d \"%s\"\n", m->dim - 1, m->bnames[i].tag, m->bnames[i].name);
    for (int i = 0; i < m->ncname; i++) fprintf(f, "%d %d \"%s\"\n", m->dim, m->cnames[i].tag, m->cnames[i].name);
    fprintf(f, "$EndPhysicalNames\n");
  }
  fprintf(f, "$Nodes\n%d\n", m->nvert);
  for (int i = 0; i < m->nvert; i++)
    fprintf(f, "%d %.17g %.17g %.17g\n", i + 1, m->x[m->dim * i], m->x[m->dim * i + 1],
            m->dim == 3 ? m->x[3 * i + 2] : 0.0);
  fprintf(f, "$EndNodes\n$Elements\n%d\n", m->nbf + m->ncell);
  int id = 1;
  for (int b = 0; b < m->nbf; b++) {
    fprintf(f, "%d %d 2 %d %d", id++, ftype, m->bf_tag[b], m->bf_tag[b]);
    for (int j = 0; j < m->nvf; j++) fprintf(f, " %d", m->bf_verts[b * m->nvf + j] + 1);
    fputc('\n', f);
  }
  for (int c = 0; c < m->ncell; c++) {
    fprintf(f, "%d %d 2 %d %d", id++, ctype[m->type], m->cell_tag[c], m->cell_tag[c] ? m->cell_tag[c] : 1);
    for (int j = 0; j < m->nvc; j++) fprintf(f, " %d", m->cells[(size_t)c * m->nvc + j] + 1);
    fputc('\n', f);
  }
  fprintf(f, "$EndElements\n");
  if (fclose(f)) { snprintf(m->err, MESH_ERRLEN, "error writing %s", path); return 1; }
  return 0;
}

/* ---------------------------------------------------------------- VTK */

static void xml_name(FILE *f, const char *s) {
  for (; *s; s++) {
    if (*s == '"') fputs("&quot;", f);
    else if (*s == '&') fputs("&amp;", f);
    else if (*s == '<') fputs("&lt;", f);
    else if (*s == '>') fputs("&gt;", f);
    else fputc(*s, f);
  }
}

int mesh_write_vtu(mesh *m, const char *path, int nfield, const mesh_field *fl) {
  FILE *f = fopen(path, "w");
  if (!f) { snprintf(m->err, MESH_ERRLEN, "cannot write %s: %s", path, strerror(errno)); return 1; }
  static const int vtk_type[] = {5, 9, 10, 12};
  fprintf(f, "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"0.1\" "
             "byte_order=\"LittleEndian\">\n<UnstructuredGrid>\n"
             "<Piece NumberOfPoints=\"%d\" NumberOfCells=\"%d\">\n", m->nvert, m->ncell);
  for (int pass = 0; pass < 2; pass++) {
    int any = 0;
    for (int i = 0; i < nfield; i++) any |= fl[i].on_cells == pass;
    if (!any) continue;
    fprintf(f, pass ? "<CellData>\n" : "<PointData>\n");
    for (int i = 0; i < nfield; i++) {
      if (fl[i].on_cells != pass) continue;
      fprintf(f, "<DataArray type=\"Float64\" Name=\"");
      xml_name(f, fl[i].name);
      fprintf(f, "\" NumberOfComponents=\"%d\" format=\"ascii\">\n", fl[i].ncomp);
      int n = pass ? m->ncell : m->nvert;
      for (long k = 0; k < (long)n * fl[i].ncomp; k++)
        fprintf(f, "%.17g%c", fl[i].val[k], (k + 1) % fl[i].ncomp ? ' ' : '\n');
      fprintf(f, "</DataArray>\n");
    }
    fprintf(f, pass ? "</CellData>\n" : "</PointData>\n");
  }
  fprintf(f, "<Points>\n<DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"ascii\">\n");
  for (int i = 0; i < m->nvert; i++)
    fprintf(f, "%.17g %.17g %.17g\n", m->x[m->dim * i], m->x[m->dim * i + 1],
            m->dim == 3 ? m->x[3 * i + 2] : 0.0);
  fprintf(f, "</DataArray>\n</Points>\n<Cells>\n"
             "<DataArray type=\"Int32\" Name=\"connectivity\" format=\"ascii\">\n");
  for (int c = 0; c < m->ncell; c++) {
    for (int j = 0; j < m->nvc; j++) fprintf(f, "%d ", m->cells[(size_t)c * m->nvc + j]);
    fputc('\n', f);
  }
  fprintf(f, "</DataArray>\n<DataArray type=\"Int32\" Name=\"offsets\" format=\"ascii\">\n");
  for (int c = 0; c < m->ncell; c++) fprintf(f, "%d\n", (c + 1) * m->nvc);
  fprintf(f, "</DataArray>\n<DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">\n");
  for (int c = 0; c < m->ncell; c++) fprintf(f, "%d\n", vtk_type[m->type]);
  fprintf(f, "</DataArray>\n</Cells>\n</Piece>\n</UnstructuredGrid>\n</VTKFile>\n");
  if (fclose(f)) { snprintf(m->err, MESH_ERRLEN, "error writing %s", path); return 1; }
  return 0;
}

int mesh_write_pvd(const char *pvd, int nstep, const double *times, char **files, char *err) {
  FILE *f = fopen(pvd, "w");
  if (!f) { snprintf(err, MESH_ERRLEN, "cannot write %s: %s", pvd, strerror(errno)); return 1; }
  fprintf(f, "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\">\n<Collection>\n");
  for (int i = 0; i < nstep; i++) {
    /* the data set path is relative to the .pvd's folder */
    const char *slash = strrchr(files[i], '/');
    fprintf(f, "<DataSet timestep=\"%.17g\" part=\"0\" file=\"", times[i]);
    xml_name(f, slash ? slash + 1 : files[i]);
    fprintf(f, "\"/>\n");
  }
  fprintf(f, "</Collection>\n</VTKFile>\n");
  if (fclose(f)) { snprintf(err, MESH_ERRLEN, "error writing %s", pvd); return 1; }
  return 0;
}
