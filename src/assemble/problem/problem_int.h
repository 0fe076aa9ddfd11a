/* problem_int.h — the state of a linear or nonlinear problem, shared by problem.c (setup,
 * assembly, derived operators), rows.c (the rows' owners and numbers), problem_solve.c
 * (solves), sparsity.c (the matrix pattern and null spaces) and solver.c (solvers, kept
 * factorizations). Internal to src/assemble/problem: the interface is problem.h. */
#ifndef LUGAL_PROBLEM_INT_H
#define LUGAL_PROBLEM_INT_H

#include "problem.h"
#include "solver.h"

#include <petscsnes.h>
#include <time.h>


typedef struct {
  region reg;
  int qdeg;
  coef_table tab;
  lg_kernel kmat, kres;
  int have_mat, have_res;
  int nitems;
  int *cells, *facets; /* interior facets: cells holds the '+' cells then the '-' cells */
  int interior;        /* an interior facet term: its element rows and columns are the
                        * problem's fields on the '+' cell, then on the '-' cell */
  field_layout rl, cl; /* the element tensor's rows and columns (the problem's layout, or it twice) */
  size_t rank_off;     /* its first element entry (node pair) in the problem's ranks */
  size_t erow_first;   /* B = 1: its first element row in row_start */
  const PetscInt *rows; /* B = 1: each element row's owned row number, one item after another:
                         * row_start + erow_first, or, for a serial run's term over every cell
                         * of one field numbered from 0 (a Laplacian's), its dof map's cell
                         * list itself (rows_shared; 25 MB not written on 1.57 M tetrahedra) */
  int rows_shared;
  lg_windows wmat, wres; /* its items' windows of the matrix's owned node rows and of the
                          * problem's dofs (lg_assemble_chunks) */
} prob_term;

typedef struct {
  int field;          /* row/column field */
  int comp;           /* its component (vector fields) */
  int points;         /* on vertices (facets[] holds the local vertex), not on facets */
  int src;            /* the boundary condition it comes from (form term index) */
  expr_tape tape;     /* roots: a (coefficient of u), r (rest): u = -r/a */
  expr *g;            /* the value -r/a (controls differentiate it) */
  int nitems;
  int *cells, *facets;
} bc_term;

#define LG_BCD_CACHE 8
struct lg_problem {
  lg_env *env;
  lg_mesh *lm;
  int nonlinear, bc_symmetric;
  field_layout rows, cols;
  dofmap *rdm[KER_MAXFIELD], *cdm[KER_MAXFIELD];
  int rglob[KER_MAXFIELD + 1], cglob[KER_MAXFIELD + 1];
  int N;
  /* a run of several processes (mpiexec): every rank holds the mesh, the dof maps and the
   * discrete functions whole, and owns the rows [lo, hi) of the matrix and the vectors
   * (MPIAIJ on PETSC_COMM_WORLD). It computes the element tensors of the items that touch
   * its rows and adds only into them (no communication in assembly, each entry summed in
   * the serial run's item order); solutions are gathered back to every rank's whole copy */
  int par;
  int lo, hi;
  /* the rows' order in PETSc: the nodes (pB rows each) of every part of the mesh's partition
   * (partition.c) one part after another, each in the problem's own order, so that a rank
   * owns its cells' nodes (a node of cells in several parts goes to the part of most of
   * them). perm: the problem's node -> PETSc's, iperm its inverse; NULL where the orders
   * are the same (a serial run, or rows split in the problem's order). The whole-length
   * arrays (state, solution, rwhole, bc_rows) stay in the problem's order; the matrix's
   * pattern, own_rows and the PETSc vectors are in PETSc's */
  int *perm, *iperm, pB;
  /* on a distributed mesh (lm->dist) the problem's order is the local mesh's: N counts its
   * owned and ghost nodes' dofs, Nglob the whole problem's; perm gives every local node its
   * PETSc node (rows.c), iperm the owned ones' local nodes (PETSc node R at R - ioff),
   * and to_all brings a distributed vector's owned and ghost values to the local arrays */
  int Nglob, ioff;
  VecScatter to_all;    /* a distributed vector to every rank's whole copy */
  Vec whole;            /* that copy */
  double *rwhole;       /* a whole-length residual (parallel runs) */
  int nterm;
  prob_term *t;
  int nbct;
  bc_term *bct;
  int nbc;
  long bc_cap;
  PetscInt *bc_rows;
  PetscScalar *bc_vals;
  /* the essential rows this rank owns (all of them in a serial run, where these point to
   * bc_rows and bc_vals): what MatZeroRows and the vectors' owned parts take */
  int nown;
  PetscInt *own_rows;
  PetscScalar *own_vals;
  int *bc_org;        /* per essential row: the bc term, cell and local node it came from */
  struct { int fid, param, n; expr_tape *tape; } bcd[LG_BCD_CACHE]; /* d g / d control, per bc term */
  int nbcd;
  PetscCount ncoo;      /* element matrix entries */
  /* per element entry (per node pair where every field is a B-vector: B^2 fewer), the rank
   * of its column node in its row node's row: the entry (a, b) of the B x B block is at
   * csr_i[R*B] + a*(csr_i[R*B+1] - csr_i[R*B]) + rank*B + b, R the row node */
  void *rank;
  int rank_w;           /* bytes per rank: 1 (rows of up to 256 nodes), 2 or 4 */
  PetscInt *row_start;  /* B = 1: per element row (item, row) its owned row's number from 0
                         * (-1 for another rank's), so that the scatter reads no dof map (the
                         * loads of cell, dof and row start one after another made the P1
                         * scatter latency-bound); csr_i gives the row's start. A number, not
                         * the start: the pattern's blocks are written before their places
                         * in csr_j are known (lg_problem_setup_matrix's one pass) */
  lg_chunk_bufs chunks; /* element tensors of a run of items per thread (lg_assemble_chunks) */
  PetscInt nnz;
  double setup_ms[2]; /* lg_problem_setup_matrix's phases: pattern, PETSc matrix */
  int pattern_threads; /* the pattern pass's blocks, one per OpenMP thread */
  PetscInt *csr_i, *csr_j; /* the pattern of the owned rows: A's own arrays in a serial run
                            * (MatCreateSeqAIJWithArrays: freed after A); in a parallel one
                            * the order in which each row's entries are ranked (ranks and
                            * row_start), its values in the split blocks below. Columns are
                            * global */
  PetscScalar *csr_a;       /* a serial run's values (NULL in a parallel one) */
  /* a parallel run's matrix is made on split arrays of ours (MatCreateMPIAIJWithSplitArrays:
   * no copy, no CSR preallocation through MatSetValues): the diagonal block (columns lo ..
   * hi - 1, local) and the off-diagonal block (the others, global; PETSc compacts them in
   * place), and per owned row the number of its columns left of the diagonal block. A row's
   * entries in csr order are its left columns, its diagonal block's, the rest: assembly adds
   * each entry at its place in the blocks (lg_split_entry), with no CSR copy of the values
   * beside them (55 MB per rank for P1 on 96³ cubes on 2 ranks) */
  PetscInt *sd_i, *sd_j, *so_i, *so_j;
  PetscScalar *sd_a, *so_a;
  int *s_left;
  size_t bcc_n;         /* symmetric elimination: the essential columns' entries (keep_bc_columns) */
  int *bcc_row, *bcc_col;
  double *bcc_val;
  Mat A;
  Vec b, x;
  KSP ksp;
  SNES snes;
  double *state;      /* current iterate (N) */
  double *solution;   /* the last solution (N), for adjoints */
  int have_solution;
  unsigned long solved_geometry; /* the mesh's geometry count at the last solve */
  int no_keep;        /* never solve with a kept factor of an earlier matrix (lg_problem_replayable) */
  int mass_cg;        /* a mass matrix: CG with Jacobi before LU (lg_problem_mass_solver); 2 once it fell back to LU */
  int iter;           /* a linear problem's default solver (problem_solve.c, choose_solver): 0 not
                       * chosen yet, 1 CG with GAMG, 2 direct, 3 GMRES with GAMG, 4 GMRES with
                       * a Schur complement fieldsplit (a saddle point) */
  int newton_iter;    /* a nonlinear problem's: the same for its SNES's solver (newton_matrix),
                       * -1 iterative but not set up yet */
  KSP kspT;           /* a saddle point's transposed solves under the default fieldsplit: on At, */
  Mat At;             /* A transposed explicitly at assembly At_version (saddle_transpose_solve) */
  unsigned At_version;
  int newton_nocg;    /* CG failed on one of its Jacobians: GMRES from then on */
  unsigned a_version;  /* assemblies into A (lg_problem_assemble_into) */
  unsigned isym_version; /* the a_version whose symmetry isym holds */
  int isym;           /* A symmetric apart from the essential rows (lg_symmetric_besides) */
  int sym_elim;       /* A's essential rows and columns were eliminated (symmetric = true, or
                       * for CG): the solves with it of a problem without symmetric = true
                       * correct for the columns (bcc_*) */
  form *eqn, *bcf;    /* copies of the forms, for derived operators */
  int test[KER_MAXFIELD], unk[KER_MAXFIELD];
  int matrix_ready;   /* lg_problem_solve_vector: the matrix is assembled and factored */
  uint64_t ready_fp;  /* ... from the data of this fingerprint (matrix_fingerprint) */
  int adj_stale;      /* A does not hold the Jacobian at the last solution, factored by the
                       * SNES's solver (nonlinear problems: the adjoint makes it so, and a
                       * Newton solve warm-started at the solution then reuses it) */
  uint64_t matrix_fp; /* linear problems: what the assembled, factored matrix was made from */
  double bc_diag;     /* linear problems: the diagonal of the essential rows of A (their
                       * equations are bc_diag (u_r - g_r) = 0: essential_diagonal); 1 for
                       * nonlinear ones */
  uint64_t adj_fp;    /* nonlinear problems: what the adjoint's Jacobian was made from (besides the state) */
  int nmatpar, *matpar; /* the parameters the matrix terms read (their Jacobian tables): the
                         * only ones matrix_fingerprint mixes in */
  int chord;          /* a warm-started resolve (an optimization's next evaluation): steps may
                       * keep the last Jacobian while it contracts the residual (snes_jacobian) */
  int lag_valid;      /* A holds a Jacobian assembled for this solve's data (any iterate) */
  double lag_fnorm;   /* |F| at the last Jacobian evaluation */
  lg_keep keep;       /* linear problems: the factorization kept while A changes (solver.h) */
  int failed;         /* a callback failed: env->err holds why */
  int nnull;          /* dimension of the null space given with nullspace= (0: none) */
  MatNullSpace null;  /* that null space (constants of some fields, rigid body modes) */
  int null_const[KER_MAXFIELD]; /* fields whose constants are in it: their mean is set to 0 */
  int null_rigid;     /* it is the rigid body modes */
  int near_done;      /* the rigid body modes are the matrix's near null space */
  unsigned long modes_geometry; /* the mesh's geometry count the rigid body modes were made for */
  char prefix[64];
};

/* a parallel run's owned row r in the diagonal block's values da and the off-diagonal
 * block's oa: the entry of rank e (its place in the row's global column order) is at
 * (e < left ? dl : e < mid ? dd : dr) + e. Taken once per row in assembly's hot loop */
typedef struct {
  PetscInt left, mid;
  PetscScalar *dl, *dd, *dr;
} lg_split_row;
static inline lg_split_row lg_split_row_at(const lg_problem *p, PetscInt r, PetscScalar *da, PetscScalar *oa) {
  lg_split_row s;
  s.left = p->s_left[r];
  s.mid = s.left + p->sd_i[r + 1] - p->sd_i[r];
  s.dl = oa + p->so_i[r];
  s.dd = da + p->sd_i[r] - s.left;
  s.dr = oa + p->so_i[r] - (s.mid - s.left);
  return s;
}
static inline PetscScalar *lg_split_row_entry(const lg_split_row *s, PetscInt e) {
  return (e < s->left ? s->dl : e < s->mid ? s->dd : s->dr) + e;
}
/* entry e of owned row r there */
static inline PetscScalar *lg_split_entry(const lg_problem *p, PetscScalar *da, PetscScalar *oa, int r, PetscInt e) {
  lg_split_row s = lg_split_row_at(p, r, da, oa);
  return lg_split_row_entry(&s, e);
}
/* sparsity.c: a parallel run's block values to assemble into (zeroed), and after assembly
 * given back to the matrix (assembled: its state moves on, so that solvers set up again) */
int lg_problem_split_open(lg_env *env, lg_problem *p, PetscScalar **da, PetscScalar **oa);
int lg_problem_split_close(lg_env *env, lg_problem *p, PetscScalar *da, PetscScalar *oa, int assembled);

/* row i of the problem's order in PETSc's, and back (problem_int.h, perm) */
static inline PetscInt lg_petsc_row(const lg_problem *p, PetscInt i) {
  return p->perm ? (PetscInt)p->perm[i / p->pB] * p->pB + i % p->pB : i;
}
static inline PetscInt lg_problem_row(const lg_problem *p, PetscInt r) {
  return p->iperm ? (PetscInt)p->iperm[r / p->pB - p->ioff] * p->pB + r % p->pB : r;
}

/* problem.c: the owned rows of a whole-length array (the problem's order) times sign into
 * owned (PETSc's order, hi - lo values) */
void lg_problem_owned_part(const lg_problem *p, const double *whole, double sign, double *owned);
/* problem.c: the owned part of a whole vector (N values) into v, and every rank's whole
 * copy of v (a gather in a parallel run, a copy in a serial one) */
int lg_problem_vec_set(lg_env *env, lg_problem *p, Vec v, const double *whole);
int lg_problem_vec_get(lg_env *env, lg_problem *p, Vec v, double *whole);

/* problem.c, for problem_solve.c: the unknowns' coefficients bound to state (their count);
 * the matrix at state assembled into A (before boundary conditions), the residual at
 * state into r (N values, before boundary conditions); the essential values and rows */
int lg_problem_bind_unknowns(lg_problem *p, const double *state, coef_binding *extra);
int lg_problem_assemble_into(lg_env *env, lg_problem *p, const double *state, Mat A);
int lg_problem_residual_into(lg_env *env, lg_problem *p, const double *state, double *r);
int lg_problem_compute_bcs(lg_env *env, lg_problem *p);

/* sparsity.c */
/* the global nodes (B components per node) of item it of term t, rows or columns, in the
 * problem's order (petsc = 0: the whole-length arrays') or PETSc's (1: the matrix's) */
void lg_term_nodes(const lg_problem *p, const prob_term *t, int it, int rows, int B, int petsc, PetscInt *out);
/* the number of components when every field has the same, else 1 */
int lg_matrix_block_size(const lg_problem *p);
/* rows.c: the rows this rank owns (lo, hi; whole nodes of lg_matrix_block_size rows) and
 * their PETSc numbers (perm, iperm; Nglob, ioff on a distributed mesh; collective) */
int lg_problem_set_ownership(lg_env *env, lg_problem *p);
/* rows.c: the part of each of the problem's nodes (B dofs each) by the majority vote over
 * its cells (lg_vote), whose parts are part[] (a whole mesh's partition, or a distributed
 * mesh's local cells' owners); owner[] holds Nn = N / B entries; 1 when out of memory */
int lg_problem_node_owners(const lg_problem *p, int B, const int *part, int *owner);
/* rows.c: the place order[g] of each of a distributed problem's Nglob PETSc rows g in
 * the order of its fields' gathered values (f:values()'s, field after field), on every
 * rank: for a whole dense matrix (collective) */
int lg_dist_problem_order(lg_env *env, const lg_problem *p, int *order);
/* the pattern, the element entries' places, the matrix and its vectors */
int lg_problem_setup_matrix(lg_env *env, lg_problem *p);
/* a single vector field of the mesh's dimension (elasticity): the rigid body modes as the
 * near null space, which GAMG needs to coarsen it well; set once, before the first solve
 * with ksp, unless ksp's preconditioner is a factorization (LU, Cholesky), which ignores it */
int lg_problem_near_nullspace(lg_env *env, lg_problem *p, KSP ksp);
/* nullspace= */
int lg_problem_setup_nullspace(lg_env *env, lg_problem *p, const lg_problem_spec *s);
/* the rigid body modes (null space, near null space) made again when the mesh has moved
 * since they were made: they are the moved nodes' rotations; collective */
int lg_problem_follow_geometry(lg_env *env, lg_problem *p);

#endif
