/* io.h — the mesh layer's file formats, its io/ room's public face: the Gmsh MSH reader
 * (whole, and in parts for a parallel read) and writer, the VTU, PVTU and PVD writers; safe
 * output files are outfile.h's, SVG pictures svg.h's. Uses the mesh core only. */
#ifndef LUGAL_MESH_IO_H
#define LUGAL_MESH_IO_H

#include "../mesh.h"
#include "outfile.h"

/* Gmsh MSH 2.2 and 4.1 ASCII (gmsh.c): from a file (a regular file or a pipe) or from
 * len bytes in memory (name labels the messages). Hostile input gives an error naming the
 * file, line and what was expected, never a crash, a hang or an allocation beyond what the
 * data can hold. */
mesh *mesh_read_gmsh(const char *path, char *err);
mesh *mesh_read_gmsh_buffer(const char *buf, size_t len, const char *name, char *err);
/* Gmsh MSH 2.2 ASCII writer (cells, tagged boundary facets, physical names with `"`, `\`
 * and newlines escaped as the reader unescapes them) */
int mesh_write_gmsh(mesh *m, const char *path);

/* A file read in parts, one per process of a parallel run (src/assemble/parallel/read_dist.c joins
 * them into each process's part of the mesh). One process scans the file's lines once with
 * constant memory (mesh_gmsh_layout, gmsh_layout.c): where its sections are, the MSH 4 blocks, and where
 * each of nparts even runs of the nodes and of the elements begins. Each process then reads
 * its runs and the small sections only (mesh_gmsh_read_part), with the whole reader's checks.
 * The layout does not judge the contents: a file it cannot cut (a pipe, repeated $Nodes or
 * $Elements, a line over 4 MB, a count that does not match the lines) has ok = 0 and a
 * reason, and is read whole; so is one whose part fails to parse, which then gets the whole
 * reader's message. */
#define GMSH_MAX_SMALL 16
typedef struct { long long off, end, line; } gmsh_span;  /* bytes off .. end - 1, line of off */
typedef struct {
  long long first, count; /* items (nodes or elements) first .. first + count - 1 of the file */
  int edim, par, type;    /* an MSH 4 block's entity dimension, parametric flag, element type */
  long long etag;         /* and entity tag */
  gmsh_span a, b;         /* the lines: MSH 4 nodes' tags (a) and coordinates (b), else a */
} gmsh_block;
typedef struct { long long aoff, aline, boff, bline; } gmsh_pos;
typedef struct {
  int ok, version, nparts;
  char why[200];
  int nsmall;
  gmsh_span small[GMSH_MAX_SMALL]; /* the sections other than $Nodes and $Elements */
  long long nnodes, nelems;
  int nnb, neb;
  gmsh_block *nb, *eb;
  gmsh_pos *np, *ep; /* nparts + 1 each: where node / element (k * total / nparts) starts */
} gmsh_layout;
int mesh_gmsh_layout(const char *path, int nparts, gmsh_layout *L);
/* where run k of nparts even runs of total items starts (the layout's and the part reader's) */
static inline long long gmsh_run_start(long long total, int nparts, int k) { return total * k / nparts; }
int mesh_gmsh_layout_pack(const gmsh_layout *L, char **buf, size_t *len);
int mesh_gmsh_layout_unpack(const char *buf, size_t len, gmsh_layout *L);
void mesh_gmsh_layout_free(gmsh_layout *L);
typedef struct {
  int type, nphys, phys;     /* Gmsh type; physical tags: nphys at gmsh_part.phys + phys */
  long long node;            /* its node tags: gmsh_part.enodes + node, as many as the type has */
} gmsh_elem;
typedef struct {
  int version;
  long long node_first, nn; /* nodes node_first .. node_first + nn - 1 of the file */
  long long *ntag;
  double *nx;               /* 3 per node */
  long long elem_first, ne; /* elements elem_first .. elem_first + ne - 1 of the file */
  gmsh_elem *e;             /* in the file's order */
  long long *enodes;
  int *phys;
  int nname, *name_dim;     /* $PhysicalNames: dimension, tag, name */
  mesh_name *names;
} gmsh_part;
int mesh_gmsh_read_part(const char *path, const gmsh_layout *L, int p, gmsh_part *out, char *err);
void mesh_gmsh_part_free(gmsh_part *g);
/* a Gmsh element type's dimension, nodes (0: not read by lugal) and cell type */
int mesh_gmsh_type_dim(int type);
int mesh_gmsh_type_nodes(int type);
cell_type mesh_gmsh_type_cell(int type);

/* VTU output (vtk.c): point and cell data arrays of ncomp components (1 or 3). Every
 * writer of the mesh layer writes to a temporary file renamed over the target (outfile.h). */
typedef struct {
  const char *name;
  int ncomp;
  int on_cells;      /* 0: point data (nvert values), 1: cell data */
  const double *val; /* n*ncomp */
} mesh_field;
int mesh_write_vtu(mesh *m, const char *path, int nfield, const mesh_field *f);
/* the same in a format: VTU_BINARY (VTK's inline base64 with 64-bit headers: values exact,
 * 10.7 characters per double against about 24 for full-precision ascii, and faster to
 * read; what mesh_write_vtu writes), VTU_ASCII, or VTU_ZLIB (the binary data in zlib-
 * compressed blocks, compressor="vtkZLibDataCompressor", as ParaView writes it) */
enum { VTU_BINARY = 0, VTU_ASCII = 1, VTU_ZLIB = 2 };
int mesh_write_vtu_format(mesh *m, const char *path, int nfield, const mesh_field *f, int format);
/* a piece of the mesh: the nc cells listed (0-based) and the vertices they use (numbered
 * in increasing order), with the fields' values there. With staged (an outfile, outfile.h)
 * the file is left finished under its temporary name, for the caller to publish with the
 * other files of its collection once all are written (or to abort), else it is put in place */
int mesh_write_vtu_piece(mesh *m, const char *path, int nfield, const mesh_field *f, int format, const int *cells, int nc,
                         outfile *staged);
/* the .pvtu collection of npiece piece files (named relative to its folder) of the fields
 * (their names and components; the pieces hold the values); staged as above */
int mesh_write_pvtu(const char *path, int nfield, const mesh_field *f, int npiece, char **pieces, char *err, outfile *staged);
/* append (time, file) to a .pvd collection, rewriting it; step 0 starts a new file */
int mesh_write_pvd(const char *pvd, int nstep, const double *times, char **files,
                   char *err);

#endif
