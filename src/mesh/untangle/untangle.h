/* untangle.h — mesh repair and motion by vertex repositioning: the three-stage untangler
 * of the seed's "Untangling of 2D triangular and quadrilateral meshes in ALE simulations"
 * (feasible set, optimization of eq. 3.3, feasible set with a minimum corner Jacobian β),
 * quality-guarded smoothing, and the Laplacian mesh motion with variable diffusivity of
 * "Morphing and modification of unstructured meshes" (eqs. 1.1–1.3). libc + libm only.
 *
 * Validity is the untangling paper's: every corner Jacobian determinant positive (for
 * simplices the one corner is the cell). Corner Jacobians are affine in each vertex, so the
 * feasible set of a vertex is a convex polygon/polyhedron cut out by half-spaces. */
#ifndef LUGAL_UNTANGLE_H
#define LUGAL_UNTANGLE_H

#include "../mesh.h"

typedef struct {
  double beta;         /* target minimum corner Jacobian; < 0 selects the paper's default */
  int max_iterations;  /* passes of stages 1 and 3, and the cap on optimizer iterations / 10 */
  int slide;           /* 2D: boundary vertices slide along the boundary polyline (corners fixed) */
  int placement;       /* stage 1/3 position in the feasible set: 0 Chebyshev centre, 1 mean of
                          three LP corners (the paper) */
  int verbose;         /* stage reports on stdout as they finish */
  const double *xref;  /* the global stage aims at each cell's (each corner's) shape in this
                          configuration of the same mesh (nvert*dim), and once valid the
                          touched vertices move towards those shapes; NULL: regular cells */
  double motion_weight; /* >= 0: stage 2 and the global stage add w Σ |x − x_input|² / h²
                           (h a typical edge), for the smallest motion (ALE remap); 0 none */
  int no_global;        /* 1: no global stage (only the local stages, which keep the mesh
                           away from the tangles bit for bit) */
  int reference_escape; /* with xref: its shapes are only a way out of the tangle (the Tutte
                           fallback's disk shapes): the global stage minimizes by projected
                           Newton and ends at the first valid state, and no final move goes
                           towards those shapes (C only, not in Lua) */
  double progress;      /* a line on stderr every so many seconds of a run longer than that
                         * (2: the Lua and command-line default; 0: none) */
} untangle_opts;

typedef struct {
  const char *name;
  int invalid_before, invalid_after; /* cells with a corner Jacobian <= 0 */
  int below_beta_after;              /* cells with a corner Jacobian < beta */
  int moved;                         /* vertices this stage moved */
  int iterations;                    /* passes (stages 1, 3) or optimizer iterations (2) */
  double seconds;
} untangle_stage;

typedef struct {
  double beta;
  int invalid_before, invalid_after;
  int moved;                        /* vertices whose coordinates changed */
  double max_displacement, mean_displacement; /* over the moved vertices */
  double seconds;
  int nstage;
  untangle_stage stage[3];
  int kept_stage;                   /* the state returned: after stage 3, or an earlier better
                                       one (0: the input) when the stages made it worse */
  int passes;                       /* runs of the three stages: another follows one that
                                       left fewer but some invalid cells (stage[] is the first's) */
  int fallback_tried;               /* the passes stalled with invalid cells: the other
                                       placement was tried from there */
  int fallback_placement;           /* and repaired more (0 chebyshev, 1 corners); -1: not used */
  int tutte_tried, tutte_kept;      /* 2D disks still invalid after those: a run aiming at the
                                       cells' shapes in the mesh's Tutte embedding on a circle
                                       was tried, and kept (it left fewer invalid cells) */
} untangle_report;

void untangle_defaults(untangle_opts *o);
/* repair m in place; returns 0 when run (check r->invalid_after), nonzero with a message in
 * err (MESH_ERRLEN) on bad input (non-finite coordinates, a bad option) or out of memory.
 * The mesh returned is the best state seen (fewest invalid cells, then the largest smallest
 * corner Jacobian), never worse than the input. Meshes of any scale (1e-200 or 1e300) are
 * repaired in coordinates scaled to unit size and mapped back; vertices that did not move
 * keep their coordinates bit for bit. */
int mesh_untangle(mesh *m, const untangle_opts *o, untangle_report *r, char *err);
void untangle_report_print(const untangle_report *r, const mesh *m);
/* the paper's default β: (10% of the bounding-box diagonal / cells per direction)^d, a
 * length raised to the dimension so that it compares with corner Jacobians */
double untangle_default_beta(const mesh *m);

typedef struct {
  int measure;     /* a quality_measure that is larger-is-better and positive on valid cells */
  int iterations;  /* sweeps */
  int slide;       /* 2D: boundary vertices slide along the boundary polyline */
  int verbose;
  int global;      /* 0: vertex by vertex; 1: all interior vertices together (L-BFGS) */
  int energy;      /* with global: no floor on the smallest q during the descent, only the
                    * validity barrier of Σ 1/q; the result is kept when its smallest q is
                    * above the input's, else the input is restored */
  const double *xref; /* energy (mean ratio on simplices, corner condition on quadrilaterals
                    * and hexahedra): the shapes aimed at are those of this configuration of
                    * the same mesh (nvert*dim), q the mean ratio of each cell's (worst
                    * corner's) map from its reference shape; NULL: regular cells */
  int optimizer;   /* energy: SMOOTH_AUTO (projected Newton in 2D, L-BFGS in 3D), SMOOTH_NEWTON
                    * or SMOOTH_LBFGS */
  int sliding;     /* energy, its own measure, a sliding boundary: SMOOTH_SLIDE_NONE runs both
                    * passes and keeps the higher minimum; SMOOTH_SLIDE_INNER or
                    * SMOOTH_SLIDE_LOCAL runs that pass alone */
  int then_energy; /* the default method ("auto"): local first, then the energy method from
                    * there when the minimum stays below SMOOTH_AUTO_MIN (kept only if it
                    * raises the minimum) */
  double progress; /* a line on stderr every so many seconds of a run longer than that
                    * (2: the Lua and command-line default; 0: none) */
} smooth_opts;

/* the minimum quality below which "auto" goes on from the local method to the energy
 * method: the local method left 10 of 72 untangling benchmark meshes at 0.02-0.11 where the
 * energy method reaches 0.38-0.99999 */
#define SMOOTH_AUTO_MIN 0.3

enum { SMOOTH_AUTO, SMOOTH_NEWTON, SMOOTH_LBFGS };
/* the energy method's own measure on cells of a type: the mean ratio on simplices, the
 * corner condition on quadrilaterals and hexahedra (the one whose energy has an analytic
 * gradient and Newton's Hessian, and whose sliding passes can be chosen) */
int smooth_energy_measure(int cell_type);
/* whether o smooths m by the two sliding passes (smooth_opts.sliding chooses among them):
 * the energy method, its own measure, a sliding boundary, no reference shapes */
int smooth_has_sliding_passes(const mesh *m, const smooth_opts *o);
/* how a sliding boundary moves in a pass of the global smoothing, and the pass kept
 * (smooth_report.sliding): not at all, by guarded local steps between the optimizer's
 * rounds, or inside the optimizer */
enum { SMOOTH_SLIDE_NONE, SMOOTH_SLIDE_LOCAL, SMOOTH_SLIDE_INNER };

typedef struct {
  int measure, sweeps, moved;
  int optimizer;    /* energy: SMOOTH_NEWTON or SMOOTH_LBFGS, the one that ran */
  int multigrid;    /* Newton: its conjugate gradients took the aggregation multigrid (block
                     * Jacobi needed more than 40 iterations on 32 768 free vertices or more) */
  int iterations;   /* energy: the optimizer's iterations over all rounds (and passes) */
  int sliding;      /* the energy method's own measure with a sliding boundary: the pass kept,
                     * SMOOTH_SLIDE_INNER or SMOOTH_SLIDE_LOCAL; SMOOTH_SLIDE_NONE otherwise */
  int then_energy;  /* "auto": the energy method ran after the local one (its minimum stayed
                     * below SMOOTH_AUTO_MIN); min_local is where the local method left it */
  double min_local;
  double min_before, min_after, mean_before, mean_after, seconds;
} smooth_report;

/* quality-guarded smoothing of Σ 1/q (q the measure). Local: each free vertex descends its
 * star's sum and a step is taken only when every cell around it stays valid and the smallest
 * q around it does not decrease. Global: L-BFGS over all interior vertices, a step taken only
 * when every cell stays valid and the mesh's smallest q does not decrease. Either way the
 * mesh minimum never decreases. Energy (global + energy): L-BFGS on Σ 1/q with only its
 * barrier (every cell stays valid), so the descent may lower the minimum on its way to a
 * better mesh (the floor is what stalls the global method on bent and anisotropic meshes);
 * the result is kept only if its minimum beats the input's. The mesh must be valid.
 * iterations: sweeps (local) or rounds of up to 20 L-BFGS iterations (global, energy). */
int mesh_smooth(mesh *m, const smooth_opts *o, smooth_report *r, char *err);
/* what ran, for a one-line summary: "local", "global", "energy, L-BFGS", "energy, Newton" or
 * "energy, Newton, multigrid" */
const char *smooth_method_label(const smooth_opts *o, const smooth_report *r);
/* the pass kept with a sliding boundary, for the same summary: "" when there was no choice,
 * else ", boundary slid in the optimizer" or ", boundary slid by local steps" */
const char *smooth_sliding_label(const smooth_report *r);
/* smooth_opts.optimizer from its name, "auto", "newton" or "lbfgs" (-1 for another); the name
 * of one (smooth_report.optimizer: "newton" or "lbfgs", the one that ran) */
int smooth_optimizer_from_name(const char *name);
const char *smooth_optimizer_name(int optimizer);
/* smooth_opts.sliding from its name, "best", "optimizer" or "local" (-1 for another); the
 * name of a kept pass (smooth_report.sliding: "optimizer" or "local", NULL for none) */
int smooth_sliding_from_name(const char *name);
const char *smooth_sliding_name(int sliding);

typedef struct {
  int iterations;  /* CG iterations used per component */
  double residual; /* final relative residual */
  double tau_max;  /* largest diffusivity Vmax/Vmin-ish */
  int invalid_after;
  double seconds;
} move_report;

/* Laplacian mesh motion (morphing paper eqs. 1.1–1.3): vertices with fixed[v] != 0 move by
 * disp[v*dim..], every other vertex by the solution of Σ_k σ_0k (u_k − u_0) = 0 with edge
 * weights σ_0k = Σ τ_j over the cells j around the edge and τ = 1 + (Vmax − Vmin)/V; the
 * fixed point of the Jacobi iteration (1.3), reached by Jacobi-preconditioned CG. */
int mesh_move(mesh *m, const double *disp, const unsigned char *fixed, move_report *r, char *err);

/* topological boundary vertices (on a facet of one cell only): flags[nvert] */
int mesh_boundary_vertices(const mesh *m, unsigned char *flags, char *err);

#endif
