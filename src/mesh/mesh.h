/* mesh.h — the mesh core's public face: the mesh data structure of lugal and what derives
 * from it: generators, uniform refinement, derived adjacency (edges, faces, boundary
 * facets), geometry, the validity check, packing and parts for distribution. Reading and
 * writing files are io/io.h's; quality measures quality/quality.h's; untangling, smoothing
 * and motion untangle/untangle.h's (docs/architecture.md).
 *
 * Depends on libc, libm and OpenMP only. Every fallible function returns 0 on success and a
 * nonzero code on failure, leaving a message in the mesh (or in the caller's buffer
 * for constructors).
 */
#ifndef LUGAL_MESH_H
#define LUGAL_MESH_H

#include <stddef.h>

typedef enum {
  CELL_TRIANGLE = 0,
  CELL_QUADRILATERAL = 1,
  CELL_TETRAHEDRON = 2,
  CELL_HEXAHEDRON = 3,
  CELL_INTERVAL = 4   /* 1D: two vertices; its facets are points ("left", "right") */
} cell_type;

#define MESH_ERRLEN 512

/* a (tag, name) pair: physical names of Gmsh, or generator names. Names have any length;
 * several tags may share a name (a name then means all of them), a tag has one name. */
typedef struct {
  int tag;
  char *name; /* owned by the mesh */
} mesh_name;

typedef struct mesh {
  cell_type type;
  int dim;        /* topological = geometric dimension: 1, 2 or 3 */
  int nvc;        /* vertices per cell */
  int nvf;        /* vertices per facet */
  int nvert;
  double *x;      /* nvert*dim coordinates */
  int ncell;
  int *cells;     /* ncell*nvc vertex ids, 0-based */
  int *cell_tag;  /* ncell region tags (0 when untagged) */
  int nbf;        /* tagged boundary facets */
  int *bf_verts;  /* nbf*nvf */
  int *bf_tag;    /* nbf */
  int nbname, ncname, capbname, capcname;
  mesh_name *bnames; /* boundary tag names */
  mesh_name *cnames; /* cell region names */

  /* derived, built on demand (mesh_build_*), freed with the mesh */
  int nedge;
  int *edges;      /* nedge*2, sorted vertex pairs */
  int *cell_edges; /* ncell*nedges_per_cell */
  int nface;       /* faces of tetrahedra and hexahedra */
  int *faces;      /* nface*nvf */
  int *cell_faces; /* ncell*nfacets */
  int *bf_cell;    /* nbf: owning cell of each tagged boundary facet */
  int *bf_local;   /* nbf: local facet index in that cell */
  int nif;         /* interior facets (shared by two cells), mesh_build_interior_facets */
  int *if_cell;    /* nif*2: the '+' cell (the lower index) and the '-' cell */
  int *if_local;   /* nif*2: the facet's local index in each */
  int *if_perm;    /* nif: the rank, among the permutations of nvf items in lexicographic
                    * order, of p with facet vertex k of '+' = facet vertex p[k] of '-' (each
                    * in its cell's local facet order) */

  char err[MESH_ERRLEN];
} mesh;

/* number of facets / edges of a cell type, and local numbering tables */
int cell_nfacets(cell_type t);
int cell_nedges(cell_type t);
int cell_dim(cell_type t);
int cell_nverts(cell_type t);
int cell_nvf(cell_type t); /* vertices per facet */
const char *cell_name(cell_type t);
/* "triangles", "quadrilaterals", "tetrahedra", "hexahedra" */
const char *cell_plural(cell_type t);
/* local vertex ids of local facet f (nvf entries), local edge e (2 entries) */
const int *cell_facet_verts(cell_type t, int f);
const int *cell_edge_verts(cell_type t, int e);

/* large arrays (coordinates, connectivity, per-cell values): blocks of 2 MiB and more are
 * mapped on their own, with transparent huge pages where glibc's malloc uses them too (the
 * launcher's -lugal_hugepages 1); smaller ones come from malloc. Free with mesh_big_free. */
void *mesh_big_alloc(size_t bytes);
void mesh_big_free(void *p);

/* construction; on failure return NULL and write a reason to err (MESH_ERRLEN) */
mesh *mesh_create(cell_type t, int nvert, const double *x, int ncell, const int *cells,
                  char *err);
void mesh_free(mesh *m);
mesh *mesh_copy(const mesh *m);
/* pack.c: the mesh (coordinates, cells, tags, boundary facets, names) as one malloc'ed byte
 * buffer, for another process of the same build, and a mesh from such a buffer (every
 * length checked; NULL and a reason in err) */
int mesh_pack(const mesh *m, char **buf, size_t *len);
/* the packed size of m, and m packed at `at` (that many bytes; returns the end) */
size_t mesh_pack_size(const mesh *m);
char *mesh_pack_into(const mesh *m, char *at);
mesh *mesh_unpack(const char *buf, size_t len, char *err);
int mesh_add_boundary_facets(mesh *m, int n, const int *verts, int tag, const char *name);
int mesh_set_boundary_name(mesh *m, int tag, const char *name);
int mesh_set_region_name(mesh *m, int tag, const char *name);
/* the tags named `name` (every tag of that name, in tag order): returns how many there are
 * (0 when the name is unknown) and writes up to max of them */
int mesh_boundary_tags(const mesh *m, const char *name, int *tags, int max);
int mesh_region_tags(const mesh *m, const char *name, int *tags, int max);
/* the distinct tags in use: boundary facet tags or cell region tags (0, untagged, excluded),
 * ascending; returns how many and writes up to max */
int mesh_used_boundary_tags(const mesh *m, int *tags, int max);
int mesh_used_region_tags(const mesh *m, int *tags, int max);
/* is tag t used by a boundary facet / a cell */
int mesh_has_boundary_tag(const mesh *m, int tag);
int mesh_has_region_tag(const mesh *m, int tag);
/* comma-separated list of known boundary / region names into buf ("..." when cut) */
void mesh_boundary_names(const mesh *m, char *buf, size_t len);
void mesh_region_names(const mesh *m, char *buf, size_t len);

typedef struct {
  int nx, ny, nz;
  double x0, x1, y0, y1, z0, z1;
  cell_type type;
  int diagonal; /* triangles: 0 right, 1 left, 2 crossed */
  /* a window of the mesh (hi > 0): the cell layers lo .. hi - 1 along the last axis (y for
   * a rectangle, z for a box), their vertices and the boundary facets of those cells, in
   * the whole mesh's order, with every name (mesh_box_window_numbers gives their global
   * numbers). What a rank of a distributed run generates instead of the whole mesh. */
  int lo, hi;
} mesh_box_opts;

/* the rectangle (triangles or quadrilaterals; vertices row by row, y outermost) or its
 * window; NULL and the reason in err */
mesh *mesh_rectangle(const mesh_box_opts *o, char *err);
/* [x0, x1] in nx intervals; boundary points "left" (tag 1) and "right" (tag 2) */
mesh *mesh_interval(int nx, double x0, double x1, char *err);
/* the box (tetrahedra, six per cube, or hexahedra; vertices layer by layer, z outermost)
 * or its window */
mesh *mesh_box(const mesh_box_opts *o, char *err);
/* the whole mesh's vertex and cell counts (0 when the options are refused), and the cell
 * layers along the last axis and the vertices per vertex layer (each output may be NULL) (a window's vertex v has
 * the global number lo * per_layer + v, its cell c lo * ncells / layers + c); the crossed
 * triangles' centre vertices, numbered after every grid vertex, have no such layers:
 * *layers is then 0 */
void mesh_box_counts(const mesh_box_opts *o, long *nvert, long *ncell, int *layers, long *per_layer);
/* the window w (o with lo, hi set) holding part p of nparts of the numbering's runs
 * (mesh_vertex_runs; the part's vertex run is *vlo .. *vhi - 1), its `layers` ghost layers
 * and every cell around their vertices: what mesh_part_extract_window needs. 1 where
 * there is none: no layers (crossed triangles), fewer vertices than parts, bad arguments */
int mesh_box_part_window(const mesh_box_opts *o, int nparts, int p, int layers, mesh_box_opts *w, long *vlo, long *vhi);
/* the global numbers of the vertices and cells of w, the window made with o */
void mesh_box_window_numbers(const mesh_box_opts *o, const mesh *w, int *vglob, int *cglob);

/* derived adjacency */
int mesh_build_edges(mesh *m);
int mesh_build_faces(mesh *m);
int mesh_build_boundary_cells(mesh *m);
/* the facets shared by two cells (a facet in more than two cells is an error: the mesh is
 * not a manifold there) */
int mesh_build_interior_facets(mesh *m);
/* permutation rank r of n items (lexicographic) into p, and its inverse */
void mesh_perm_of_rank(int n, int r, int *p);
int mesh_perm_rank(int n, const int *p);

/* geometry */
double mesh_cell_signed_measure(const mesh *m, int c);
/* the coordinates of cell c (nvc*dim values) translated to its first vertex and scaled by a
 * power of two (exact) so that the largest coordinate difference lies in [0.5, 1); returns
 * the binary exponent e of the scale (true coordinates = out * 2^e + vertex 0), so that
 * scale-invariant measures and signs are computed without overflow or underflow at any
 * scale (1e-200 or 1e300). A cell whose vertices coincide gets zeros and e = 0; a cell with
 * a non-finite coordinate gets NaN. */
int mesh_cell_normalized(const mesh *m, int c, double *out);
/* the same for nv points of dimension d */
int points_normalized(int nv, int d, const double *in, double *out);
/* signed measure of cell c relative to its longest edge to the power dim (scale-free; about
 * 0.43 for an equilateral triangle); for quadrilaterals and hexahedra the smallest corner
 * Jacobian relative to the same; NaN for non-finite coordinates */
double mesh_cell_relative_validity(const mesh *m, int c);
/* the validity check run before assembly: counts cells that are inverted or degenerate
 * (relative validity not above 1e-13, or non-finite coordinates); writes up to maxids ids */
int mesh_count_invalid(const mesh *m, int maxids, int *ids, int *ninv);
double mesh_hmax(const mesh *m);
/* both in one pass (one read of each cell's vertices for triangles and tetrahedra): the
 * invalid cells as mesh_count_invalid (the same count and cells), the longest edge as
 * mesh_hmax to rounding (a tetrahedron's edges from the differences to its first vertex;
 * NaN for a NaN coordinate; 1 for a mesh without cells) */
int mesh_validate(const mesh *m, double *hmax, int maxids, int *ids, int *ninv);
/* minimum corner Jacobian determinant of a quadrilateral or hexahedron (the untangling
 * paper's validity: every corner Jacobian positive) */
double mesh_min_corner_jacobian(const mesh *m, int c);
/* signed volume of a hexahedron given its 8 vertices (24 coordinates) */
double hex_signed_volume(const double *x);
/* the three neighbours of hexahedron corner i, in right-handed order */
const int *hex_corner_neighbors(int i);

/* a mesh whose every cell is negatively oriented was written with the opposite convention
 * (clockwise): reverse every cell (simplices swap their last two vertices, quadrilaterals
 * reverse their cycle, hexahedra swap their bottom and top faces). A mixed mesh is left as
 * it is (it is tangled). Returns 1 when it flipped the cells. */
int mesh_orient_consistently(mesh *m);
/* its two steps: 1 when every cell (with `which`, every cell c with which[c]) is negatively
 * oriented; every cell reversed */
int mesh_cells_negative(const mesh *m, const char *which);
void mesh_flip_cells(mesh *m);

/* part.c: one part of a mesh whose cells are split into parts, as a process of a
 * distributed run holds it: the cells of the part (owned) and every cell sharing a vertex
 * with one of them (ghosts), in the whole mesh's order, their vertices in increasing
 * global order, the tagged boundary facets of those cells, every name. */
typedef struct {
  mesh *m;                /* the local mesh (no cells when the part is empty) */
  int nvert_global, ncell_global, part;
  int *vglobal, *cglobal; /* m->nvert / m->ncell: global numbers, increasing */
  int *vowner, *cowner;   /* the part owning each local vertex / cell */
  int nown_vert, nown_cell;
  int layers;             /* ghost layers (1: the cells around the owned cells' vertices) */
} mesh_part;
/* the part owning each vertex: the part of most of its cells (Boyer-Moore's vote in cell
 * order, the first cell's where there is no majority); 1 when out of memory */
int mesh_vertex_owners(const mesh *m, const int *part, int *owner);
/* grows the vertex set `mark` (nvert flags) by n vertex layers: each time, every vertex of a
 * cell with a marked vertex is marked. 1 when out of memory (mark then unchanged past the
 * layers done) */
int mesh_grow_vertex_layers(const mesh *m, char *mark, int n);
/* part p of m, whose cells have the parts `part` and vertices the owners vowner; NULL and
 * a reason in err (MESH_ERRLEN) on failure */
mesh_part *mesh_part_extract(mesh *m, const int *part, const int *vowner, int p, int layers, char *err);
/* the same from a window of the whole mesh (mesh_box_opts): m's vertices and cells have
 * the global numbers vglob and cglob (increasing) of a mesh of nvert_global vertices and
 * ncell_global cells; m must hold every cell of part p, its ghost layers and every cell
 * around their vertices (vowner must be the whole mesh's owners there), and then the
 * part is the one mesh_part_extract makes from the whole mesh, to the byte */
mesh_part *mesh_part_extract_window(mesh *m, const int *vglob, const int *cglob, int nvert_global, int ncell_global,
                                    const int *part, const int *vowner, int p, int layers, char *err);
/* the numbering's runs: each cell in the part of its lowest vertex, the vertices (global
 * numbers vglob, or m's own when NULL, of nvert_global) split into nparts runs */
void mesh_vertex_runs(const mesh *m, const int *vglob, int nvert_global, int nparts, int *part);
/* the vertices with global numbers in vlo .. vhi - 1 on cells that those runs cut (cells
 * whose vertices lie in different runs): what the rows split in the problems' order
 * exchange; -1 when out of memory */
long mesh_runs_interface(const mesh *m, const int *vglob, int nvert_global, int nparts, int vlo, int vhi);
void mesh_part_free(mesh_part *P);
int mesh_part_pack(const mesh_part *P, char **buf, size_t *len);
mesh_part *mesh_part_unpack(const char *buf, size_t len, char *err);

/* uniform refinement: triangles and quadrilaterals into 4, tetrahedra into 8 (Bey),
 * hexahedra into 8; boundary facets and tags follow */
mesh *mesh_refine(const mesh *m, char *err);

#endif
