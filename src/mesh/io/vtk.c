/* vtk.c — output for ParaView: the VTK XML unstructured-grid (.vtu) writer with point and
 * cell data, of a whole mesh or of a piece of its cells, the parallel collections of pieces
 * (.pvtu), and .pvd collections for time series. Written through outfile.h. */
#include "io.h"
#include "outfile.h"

#include "deflate.h"

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static void xml_name(FILE *f, const char *s) {
  for (; *s; s++) {
    if (*s == '"') fputs("&quot;", f);
    else if (*s == '&') fputs("&amp;", f);
    else if (*s == '<') fputs("&lt;", f);
    else if (*s == '>') fputs("&gt;", f);
    else fputc(*s, f);
  }
}

/* VTK's inline binary: base64 of a 64-bit byte count followed by the raw little-endian data
 * (header_type="UInt64"), streamed three bytes at a time into a buffer that goes to the file
 * a block at a time (an fwrite per four characters was a tenth of heat.lua's run) */
typedef struct {
  FILE *f;
  unsigned char buf[3];
  int n;
  int on;
  char out[4096];
} b64;

static void b64_flush(b64 *e, int final) {
  static const char al[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  if (e->n == 3 || (final && e->n)) {
    unsigned v = (unsigned)e->buf[0] << 16 | (unsigned)(e->n > 1 ? e->buf[1] : 0) << 8 | (e->n > 2 ? e->buf[2] : 0);
    char *o = e->out + e->on;
    o[0] = al[v >> 18 & 63];
    o[1] = al[v >> 12 & 63];
    o[2] = e->n > 1 ? al[v >> 6 & 63] : '=';
    o[3] = e->n > 2 ? al[v & 63] : '=';
    e->on += 4;
    e->n = 0;
  }
  if (e->on && (final || e->on + 4 > (int)sizeof e->out)) {
    fwrite(e->out, 1, (size_t)e->on, e->f);
    e->on = 0;
  }
}

static void b64_put(b64 *e, const void *p, size_t n) {
  const unsigned char *c = p;
  for (size_t i = 0; i < n; i++) {
    e->buf[e->n++] = c[i];
    if (e->n == 3) b64_flush(e, 0);
  }
}

/* one array's values, in ascii or binary: kind 0 doubles, 1 int32, 2 uint8; value i of get */
typedef double (*value_fn)(const void *ud, long i);

/* the little-endian bytes of value v of a kind into w; their count */
static int value_bytes(int kind, double v, unsigned char *w) {
  if (kind == 0) {
    uint64_t u;
    memcpy(&u, &v, 8);
    for (int k = 0; k < 8; k++) w[k] = (unsigned char)(u >> (8 * k));
    return 8;
  }
  if (kind == 1) {
    uint32_t u = (uint32_t)(int32_t)v;
    for (int k = 0; k < 4; k++) w[k] = (unsigned char)(u >> (8 * k));
    return 4;
  }
  w[0] = (unsigned char)v;
  return 1;
}

static void put_u64(b64 *e, uint64_t x) {
  unsigned char h[8];
  for (int k = 0; k < 8; k++) h[k] = (unsigned char)(x >> (8 * k));
  b64_put(e, h, 8);
}

/* VTK's zlib-compressed inline binary (compressor="vtkZLibDataCompressor"): the raw bytes in
 * blocks of VTU_BLOCK, each a zlib stream; the header (blocks, block size, the last block's
 * size or 0 when full, each compressed size, as UInt64) base64-encoded on its own, then the
 * streams. Returns 1 out of memory */
#define VTU_BLOCK 32768
static int write_array_zlib(FILE *f, int kind, long n, value_fn get, const void *ud) {
  static const int size[] = {8, 4, 1};
  size_t bytes = (size_t)n * (size_t)size[kind], nb = bytes ? (bytes + VTU_BLOCK - 1) / VTU_BLOCK : 0;
  unsigned char *raw = malloc(bytes + 1), *z = malloc(nb * mesh_zlib_bound(VTU_BLOCK) + 1);
  uint64_t *cs = malloc(sizeof(uint64_t) * (nb + 1));
  if (!raw || !z || !cs) { free(raw); free(z); free(cs); return 1; }
  size_t at = 0, zn = 0;
  for (long i = 0; i < n; i++) at += (size_t)value_bytes(kind, get(ud, i), raw + at);
  for (size_t b = 0; b < nb; b++) {
    size_t len = b + 1 < nb ? VTU_BLOCK : bytes - b * VTU_BLOCK;
    size_t c = mesh_zlib_compress(raw + b * VTU_BLOCK, len, z + zn, mesh_zlib_bound(VTU_BLOCK));
    if (!c) { free(raw); free(z); free(cs); return 1; }
    cs[b] = c;
    zn += c;
  }
  b64 e = {f, {0, 0, 0}, 0, 0, {0}};
  put_u64(&e, nb);
  put_u64(&e, VTU_BLOCK);
  put_u64(&e, bytes % VTU_BLOCK);
  for (size_t b = 0; b < nb; b++) put_u64(&e, cs[b]);
  b64_flush(&e, 1);
  b64_put(&e, z, zn);
  b64_flush(&e, 1);
  fputc('\n', f);
  free(raw);
  free(z);
  free(cs);
  return 0;
}

static void write_array(FILE *f, int binary, int kind, long n, int per_line, value_fn get, const void *ud) {
  if (!binary) {
    for (long i = 0; i < n; i++) {
      double v = get(ud, i);
      if (kind == 0) fprintf(f, "%.17g", v);
      else fprintf(f, "%ld", (long)v);
      fputc((i + 1) % per_line ? ' ' : '\n', f);
    }
    return;
  }
  static const int size[] = {8, 4, 1};
  uint64_t bytes = (uint64_t)n * (uint64_t)size[kind];
  b64 e = {f, {0, 0, 0}, 0, 0, {0}};
  unsigned char h[8];
  for (int k = 0; k < 8; k++) h[k] = (unsigned char)(bytes >> (8 * k));
  b64_put(&e, h, 8);
  for (long i = 0; i < n; i++) {
    unsigned char w[8];
    b64_put(&e, w, (size_t)value_bytes(kind, get(ud, i), w));
  }
  b64_flush(&e, 1);
  fputc('\n', f);
}

/* what the value functions read: nc cells of a mesh (cl: their ids, NULL for every cell)
 * and the vertices they use (pv: the piece's nv vertices in increasing order, NULL for
 * every vertex; lv: each vertex's place in pv), and one field */
typedef struct {
  const mesh *m;
  int nc, nv;
  const int *cl, *pv, *lv;
  const mesh_field *fl;
} piece;

static double get_field(const void *ud, long i) {
  const piece *p = ud;
  long nc = p->fl->ncomp, e = i / nc, j = i % nc;
  long at = p->fl->on_cells ? (p->cl ? p->cl[e] : e) : p->pv ? p->pv[e] : e;
  return p->fl->val[at * nc + j];
}
static double get_point(const void *ud, long i) {
  const piece *p = ud;
  long v = p->pv ? p->pv[i / 3] : i / 3;
  int d = (int)(i % 3);
  return d < p->m->dim ? p->m->x[(size_t)v * (size_t)p->m->dim + (size_t)d] : 0.0;
}
static double get_conn(const void *ud, long i) {
  const piece *p = ud;
  size_t nvc = (size_t)p->m->nvc, c = p->cl ? (size_t)p->cl[i / (long)nvc] : (size_t)i / nvc;
  int v = p->m->cells[c * nvc + (size_t)i % nvc];
  return p->lv ? p->lv[v] : v;
}
static double get_offset(const void *ud, long i) { return (double)((i + 1) * ((const piece *)ud)->m->nvc); }
static double get_type(const void *ud, long i) {
  static const int vtk_type[] = {5, 9, 10, 12, 3};
  (void)i;
  return vtk_type[((const piece *)ud)->m->type];
}

/* one array in the file's format; 1 out of memory */
static int put_array(FILE *f, int format, int kind, long n, int per_line, value_fn get, const void *ud) {
  if (format == VTU_ZLIB) return write_array_zlib(f, kind, n, get, ud);
  write_array(f, format == VTU_BINARY, kind, n, per_line, get, ud);
  return 0;
}

/* whether some field is on the cells (on_cells 1) or on the points (0): its section is written */
static int any_field_on(int nfield, const mesh_field *fl, int on_cells) {
  for (int i = 0; i < nfield; i++)
    if (fl[i].on_cells == on_cells) return 1;
  return 0;
}

/* the file written whole and put in place, or finished into *staged (outfile.h) */
static int write_piece(mesh *m, const char *path, int nfield, const mesh_field *fl, int format, piece *pc, outfile *staged) {
  outfile o;
  if (format != VTU_BINARY && format != VTU_ASCII && format != VTU_ZLIB) {
    snprintf(m->err, MESH_ERRLEN, "unknown VTU format %d", format);
    return 1;
  }
  if (outfile_open(&o, path, m->err, MESH_ERRLEN)) return 1;
  FILE *f = o.f;
  int bin = format != VTU_ASCII, oom = 0;
  const char *fmt = bin ? "binary" : "ascii";
  fprintf(f, "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"0.1\" "
             "byte_order=\"LittleEndian\"%s%s>\n<UnstructuredGrid>\n"
             "<Piece NumberOfPoints=\"%d\" NumberOfCells=\"%d\">\n", bin ? " header_type=\"UInt64\"" : "",
          format == VTU_ZLIB ? " compressor=\"vtkZLibDataCompressor\"" : "", pc->nv, pc->nc);
  for (int pass = 0; pass < 2; pass++) {
    if (!any_field_on(nfield, fl, pass)) continue;
    fprintf(f, pass ? "<CellData>\n" : "<PointData>\n");
    for (int i = 0; i < nfield; i++) {
      if (fl[i].on_cells != pass) continue;
      fprintf(f, "<DataArray type=\"Float64\" Name=\"");
      xml_name(f, fl[i].name);
      fprintf(f, "\" NumberOfComponents=\"%d\" format=\"%s\">\n", fl[i].ncomp, fmt);
      long n = (long)(pass ? pc->nc : pc->nv) * fl[i].ncomp;
      pc->fl = &fl[i];
      oom |= put_array(f, format, 0, n, fl[i].ncomp, get_field, pc);
      fprintf(f, "</DataArray>\n");
    }
    fprintf(f, pass ? "</CellData>\n" : "</PointData>\n");
  }
  fprintf(f, "<Points>\n<DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"%s\">\n", fmt);
  oom |= put_array(f, format, 0, 3L * pc->nv, 3, get_point, pc);
  fprintf(f, "</DataArray>\n</Points>\n<Cells>\n<DataArray type=\"Int32\" Name=\"connectivity\" format=\"%s\">\n", fmt);
  oom |= put_array(f, format, 1, (long)pc->nc * m->nvc, m->nvc, get_conn, pc);
  fprintf(f, "</DataArray>\n<DataArray type=\"Int32\" Name=\"offsets\" format=\"%s\">\n", fmt);
  oom |= put_array(f, format, 1, pc->nc, 1, get_offset, pc);
  fprintf(f, "</DataArray>\n<DataArray type=\"UInt8\" Name=\"types\" format=\"%s\">\n", fmt);
  oom |= put_array(f, format, 2, pc->nc, 1, get_type, pc);
  fprintf(f, "</DataArray>\n</Cells>\n</Piece>\n</UnstructuredGrid>\n</VTKFile>\n");
  if (oom) {
    outfile_abort(&o);
    snprintf(m->err, MESH_ERRLEN, "out of memory compressing %s", path);
    return 1;
  }
  return outfile_end(&o, staged, m->err, MESH_ERRLEN);
}

int mesh_write_vtu_format(mesh *m, const char *path, int nfield, const mesh_field *fl, int format) {
  piece pc = {m, m->ncell, m->nvert, NULL, NULL, NULL, NULL};
  return write_piece(m, path, nfield, fl, format, &pc, NULL);
}

int mesh_write_vtu_piece(mesh *m, const char *path, int nfield, const mesh_field *fl, int format, const int *cells, int nc,
                         outfile *staged) {
  for (int i = 0; i < nc; i++)
    if (cells[i] < 0 || cells[i] >= m->ncell) {
      snprintf(m->err, MESH_ERRLEN, "cell %d of a piece is not a cell of a mesh of %d", cells[i] + 1, m->ncell);
      return 1;
    }
  int *lv = malloc(sizeof(int) * ((size_t)m->nvert + 1)), *pv = malloc(sizeof(int) * ((size_t)m->nvert + 1)), nv = 0;
  if (!lv || !pv) {
    free(lv); free(pv);
    snprintf(m->err, MESH_ERRLEN, "out of memory for a piece of %d cells", nc);
    return 1;
  }
  for (int v = 0; v < m->nvert; v++) lv[v] = -1;
  for (int i = 0; i < nc; i++)
    for (int k = 0; k < m->nvc; k++) lv[m->cells[(size_t)cells[i] * (size_t)m->nvc + (size_t)k]] = 0;
  for (int v = 0; v < m->nvert; v++)
    if (!lv[v]) { lv[v] = nv; pv[nv++] = v; }
  piece pc = {m, nc, nv, cells, pv, lv, NULL};
  int rc = write_piece(m, path, nfield, fl, format, &pc, staged);
  free(lv);
  free(pv);
  return rc;
}

/* the file name of a path: what a collection names its parts by (relative to its folder) */
static const char *base_name(const char *path) {
  const char *slash = strrchr(path, '/');
  return slash ? slash + 1 : path;
}

int mesh_write_pvtu(const char *path, int nfield, const mesh_field *fl, int npiece, char **pieces, char *err, outfile *staged) {
  outfile o;
  if (outfile_open(&o, path, err, MESH_ERRLEN)) return 1;
  FILE *f = o.f;
  fprintf(f, "<?xml version=\"1.0\"?>\n<VTKFile type=\"PUnstructuredGrid\" version=\"0.1\" "
             "byte_order=\"LittleEndian\" header_type=\"UInt64\">\n<PUnstructuredGrid GhostLevel=\"0\">\n");
  for (int pass = 0; pass < 2; pass++) {
    if (!any_field_on(nfield, fl, pass)) continue;
    fprintf(f, pass ? "<PCellData>\n" : "<PPointData>\n");
    for (int i = 0; i < nfield; i++) {
      if (fl[i].on_cells != pass) continue;
      fprintf(f, "<PDataArray type=\"Float64\" Name=\"");
      xml_name(f, fl[i].name);
      fprintf(f, "\" NumberOfComponents=\"%d\"/>\n", fl[i].ncomp);
    }
    fprintf(f, pass ? "</PCellData>\n" : "</PPointData>\n");
  }
  fprintf(f, "<PPoints>\n<PDataArray type=\"Float64\" NumberOfComponents=\"3\"/>\n</PPoints>\n");
  for (int r = 0; r < npiece; r++) {
    fprintf(f, "<Piece Source=\"");
    xml_name(f, base_name(pieces[r]));
    fprintf(f, "\"/>\n");
  }
  fprintf(f, "</PUnstructuredGrid>\n</VTKFile>\n");
  return outfile_end(&o, staged, err, MESH_ERRLEN);
}

int mesh_write_vtu(mesh *m, const char *path, int nfield, const mesh_field *fl) {
  return mesh_write_vtu_format(m, path, nfield, fl, VTU_BINARY);
}

int mesh_write_pvd(const char *pvd, int nstep, const double *times, char **files, char *err) {
  outfile o;
  if (outfile_open(&o, pvd, err, MESH_ERRLEN)) return 1;
  FILE *f = o.f;
  fprintf(f, "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\">\n<Collection>\n");
  for (int i = 0; i < nstep; i++) {
    /* the data set path is relative to the .pvd's folder */
    fprintf(f, "<DataSet timestep=\"%.17g\" part=\"0\" file=\"", times[i]);
    xml_name(f, base_name(files[i]));
    fprintf(f, "\"/>\n");
  }
  fprintf(f, "</Collection>\n</VTKFile>\n");
  return outfile_commit(&o, err, MESH_ERRLEN);
}
