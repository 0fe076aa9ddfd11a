/* fem.h — reference-cell numerics of the assembly layer: Gauss quadrature on simplices
 * and their facets, Lagrange P1–P3 elements on triangles and tetrahedra, and dof maps.
 * No PETSc here: this part is plain C on top of src/mesh. */
#ifndef LUGAL_FEM_H
#define LUGAL_FEM_H

#include "../../mesh/mesh.h"

#define FEM_MAXQ 1331
#define FEM_MAXLOC 27 /* Q2 hexahedron */
#define FEM_MAXBS 3   /* components of a vector space */

/* a rule on the reference cell (or facet): points in reference coordinates and weights
 * summing to the reference measure (cells) or to 1 (facets, scaled by the facet size) */
typedef struct {
  int dim, n, degree;
  double x[FEM_MAXQ * 3];
  double w[FEM_MAXQ];
} quad_rule;

/* Gauss–Jacobi nodes and weights on [-1,1] for (1-x)^a (1+x)^b; returns 0 on success */
int gauss_jacobi(int n, double a, double b, double *x, double *w);
/* a rule exact for polynomials of total degree `degree` on the reference simplex of
 * dimension dim (1: [0,1], 2: triangle, 3: tetrahedron): the symmetric rules of quadtab.c
 * where there is one (triangles to degree 20, tetrahedra to 10: degree 12 on a triangle 33
 * points instead of 49, degree 8 on a tetrahedron 46 instead of 125), else a collapsed
 * (Stroud) product of Gauss-Jacobi rules */
int quad_simplex(int dim, int degree, quad_rule *q);
/* the symmetric rule of quadtab.c for (dim, degree), or 1 when there is none */
int quad_table_rule(int dim, int degree, quad_rule *q);
/* max degree offered: 20 on every simplex (beyond the 10 / 8 the design asks for) */
#define FEM_MAXDEG 20

typedef struct {
  cell_type cell;
  int dim, degree, nloc;
  double node[FEM_MAXLOC * 3]; /* reference node coordinates */
  int nmono;
  int mono[FEM_MAXLOC][3];     /* monomial exponents */
  double coef[FEM_MAXLOC * FEM_MAXLOC]; /* basis n = sum_m coef[m*nloc+n] mono_m */
  int nfacet_dofs;             /* dofs on one facet */
  int facet_dofs[6][FEM_MAXLOC];
  /* entity of each local node: 0 vertex, 1 edge, 2 face, 3 interior; and its index */
  int ent_dim[FEM_MAXLOC], ent_id[FEM_MAXLOC], ent_k[FEM_MAXLOC];
  double mean[FEM_MAXLOC];     /* mean of each basis function over the cell (they sum to 1) */
} lagrange_element;

int lagrange_init(lagrange_element *e, cell_type cell, int degree, char *err);
/* values (nloc) and reference gradients (nloc*dim) at a reference point */
void lagrange_eval(const lagrange_element *e, const double *xi, double *val, double *grad);

/* reference cells: triangles and tetrahedra (the unit simplex), quadrilaterals and
 * hexahedra (the unit square and cube, mapped by their bilinear / trilinear map) */
int cell_is_simplex(cell_type t);
const double *ref_vertex(cell_type t, int v); /* 3 coordinates */
/* the rule of a cell (facet = 0) or of its facets (1): simplex rules on simplices and on a
 * quadrilateral's edges, Gauss-Legendre products on the square and cube and a
 * hexahedron's faces, exact to `degree` (in each variable on the products) */
int quad_cell(cell_type t, int facet, int degree, quad_rule *q);
/* reference facet geometry: a facet rule's point s to cell coordinates, the facet's
 * reference tangents (t1 unused on 2D cells), its outward reference normal */
void ref_facet_point(cell_type t, int f, const double *s, double *xi);
void ref_facet_tangents(cell_type t, int f, double t0[3], double t1[3]);
void ref_facet_normal(cell_type t, int f, double *n);
/* the bilinear / trilinear map of a quadrilateral / hexahedron: vertex shape values N (4 or
 * 8, may be NULL) and reference gradients dN (nv*dim) at xi */
void q1_shape(cell_type t, const double *xi, double *N, double *dN);
/* the map's Jacobian J[d][k] = dx_d/dxi_k and its inverse at xi (simplices: constant, xi
 * unused); returns det J */
double cell_jacobian(const mesh *m, int c, const double *xi, double J[3][3], double K[3][3]);

/* a Lagrange space of some degree on a mesh: global numbering. A vector space of bs
 * components (bs > 1) interlaces them: local dof i*bs + j is component j at node i of the
 * element, global dof bs*n + j component j at scalar dof n (the block layout PETSc's
 * MatSetBlockSize and GAMG expect); nloc and ndof count every component */
typedef struct {
  mesh *m;
  int degree, nloc, ndof, bs;
  int disc;       /* discontinuous: every cell owns its nodes (dof c*nloc + k) */
  lagrange_element el;
  int *cell_dofs; /* ncell*nloc */
  int alias;      /* cell_dofs is the mesh's own cell list (continuous P1/Q1: dof = vertex) */
} dofmap;

/* the space of Lagrange degree `degree`, continuous, or discontinuous (disc = 1: the same
 * element with every node owned by its cell) */
dofmap *dofmap_new(mesh *m, int degree, int disc, char *err);
/* the bs-component space over a scalar one (bs = 1 .. 3) */
dofmap *dofmap_block(const dofmap *scalar, int bs, char *err);
void dofmap_free(dofmap *d);
/* the mesh entity that holds scalar dof s of a scalar dof map (dofmap_new's numbering):
 * kind 0 a vertex, 1 an edge, 2 a face, 3 a cell (a discontinuous map's every dof); its
 * index and the dof's place j among the entity's dofs (an edge's from its lower vertex) */
void dofmap_dof_entity(const dofmap *d, int s, int *kind, int *id, int *j);
/* physical coordinates of local dof k of cell c (its node: k / bs) */
void dofmap_node_coords(const dofmap *d, int c, int k, double *x);
/* reference coordinates of local dof k (3 values) */
const double *dofmap_node_ref(const dofmap *d, int k);

/* affine map of a simplex: x = X0 + J xi; J[d][k] = dx_d/dxi_k, K = J^-1; returns det J */
double simplex_jacobian(const mesh *m, int c, double J[3][3], double K[3][3]);

#endif
