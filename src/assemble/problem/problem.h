/* problem.h — the room src/assemble/problem: linear and nonlinear problems (a form, its
 * essential conditions, its unknowns) set up, assembled into PETSc matrices and solved
 * with kept factorizations; and what derived operators (adjoints, tangents, sensitivities)
 * need of a problem. Uses the assembly core (assemble.h) and the rooms below it. */
#ifndef LUGAL_PROBLEM_H
#define LUGAL_PROBLEM_H

#include "../assemble.h"

typedef struct lg_problem lg_problem;

typedef struct {
  lg_mesh *mesh;
  const form *eqn;
  const form *bc;        /* may be NULL */
  int nfield;
  const int *test;       /* expr function ids */
  const int *unknown;
  int nonlinear;
  int bc_symmetric;      /* eliminate BC columns too (keeps a symmetric operator symmetric) */
  const char *prefix;    /* PETSc options prefix, may be NULL */
  /* a singular problem's null space (nullspace=): the constants of these unknowns (one
   * vector per component; the solution's mean is set to zero), or the rigid body modes of
   * the single vector unknown (null_rigid) */
  int nnull;
  const int *null_fields;
  int null_rigid;
} lg_problem_spec;

lg_problem *lg_problem_new(lg_env *env, const lg_problem_spec *s);
void lg_problem_free(lg_problem *p);
/* solve; out[i] receives a new discrete function for unknown i (caller owns).
 * initial: optional initial guesses (nonlinear), one per unknown (may contain NULL) */
typedef struct {
  int iterations;        /* SNES (nonlinear) or KSP iterations */
  int linear_iterations;
  int nres;
  double res[128];       /* residual norm history (nonlinear) */
  char reason[64];
  char solver[64];       /* "lu/petsc", "lu/mumps", or the KSP and PC types ("cg/gamg") */
  double assemble_ms, solve_ms, setup_ms;
} lg_solve_info;
int lg_problem_solve(lg_env *env, lg_problem *p, lg_function **initial, lg_function **out,
                     lg_solve_info *info);
/* the length of the problem's arrays (its dofs; a distributed mesh's: the local nodes'),
 * and the whole problem's dofs */
int lg_problem_size(const lg_problem *p);
int lg_problem_global_size(const lg_problem *p);
/* this rank's share of the problem's matrix: its rows, and the columns its rows read that
 * other ranks own (the values a product with the matrix receives), -1 before the matrix */
void lg_problem_ownership(const lg_problem *p, int *rows, long *ghosts);
/* out[i] may be NULL: the solution is kept in the problem (lg_problem_solution) either way */

/* ---- what derived operators (adjoints, sensitivities) need of a problem */
typedef struct {
  int test, unknown;   /* expr function ids */
  const dofmap *dm;
  int offset;          /* of the field in the problem's vector */
} lg_field_info;
int lg_problem_fields(const lg_problem *p, lg_field_info *f); /* returns the number of fields */
const form *lg_problem_equation(const lg_problem *p);
const form *lg_problem_bcs(const lg_problem *p);   /* the essential conditions (maybe empty) */
/* solve again (after a control changed), a nonlinear problem from its last solution */
int lg_problem_resolve(lg_env *env, lg_problem *p, lg_solve_info *info);
lg_mesh *lg_problem_mesh(const lg_problem *p);
int lg_problem_is_nonlinear(const lg_problem *p);
/* the last solution (N values), NULL before the first solve */
const double *lg_problem_solution(const lg_problem *p);
/* the rows of the essential conditions at the last solve (in the problem's numbering) */
int lg_problem_essential_rows(const lg_problem *p, int *rows, int max); /* returns how many; writes up to max */
/* v (N values in the problem's numbering) zero on those rows (a tangent's right side, an
 * adjoint as a test function) */
void lg_problem_zero_essential(const lg_problem *p, double *v);
/* essential values g_r that depend on a control (a discrete function fid, or the parameter
 * param when fid < 0): 0 not at all, 1 linearly, 2 nonlinearly, -1 error (a derivative of
 * the control in a condition) */
int lg_problem_bc_dependence(lg_env *env, const lg_problem *p, int fid, int param);
int lg_problem_bc_symmetric(const lg_problem *p);
/* is the second derivative of some essential value with respect to two controls nonzero?
 * (1 yes, 0 no, -1 error) */
int lg_problem_bc_mixed(lg_env *env, const lg_problem *p, int fid1, int param1, int fid2, int param2); /* the columns of the essential rows are eliminated too */
/* their derivatives dg_r/dm_j at the last solve: triplets (problem row, control dof (0 for a
 * parameter), value), allocated; returns how many, -1 on failure */
int lg_problem_bc_derivative(lg_env *env, lg_problem *p, int fid, int param, int **rows, int **cols, double **vals);
/* is row r of the problem's arrays one this rank owns in PETSc's matrix (always, serially) */
int lg_problem_row_owned(const lg_problem *p, int r);
/* bindings of the unknowns (and of their '-' side copies, interior facets) to the last solution:
 * up to 2 per unknown; returns how many */
int lg_problem_bind_state(const lg_problem *p, coef_binding *b);
/* the problem's last solution set to u (N values), as if solved at the current values of
 * the functions and parameters it reads (a step of a time-dependent problem restored from
 * a checkpoint, for its adjoint): the next adjoint or tangent solve uses the Jacobian at u.
 * A linear problem's matrix is assembled and factored again only when its fingerprint
 * changed; a nonlinear problem's Jacobian is assembled at u by the next such solve */
int lg_problem_restore(lg_env *env, lg_problem *p, const double *u);
/* bindings of the unknowns (and their '-' side copies) to the values u (N values in the
 * problem's numbering); returns how many (up to 2 per unknown) */
int lg_problem_bind_values(const lg_problem *p, const double *u, coef_binding *b);
/* never solve with a kept factor of an earlier matrix (solver.h, lg_keep): every solve of
 * the same data gives the same bits, as replayed time steps must */
void lg_problem_replayable(lg_problem *p);
/* the problem's matrix is a mass matrix (a Gram matrix in L2): its solves by CG with Jacobi
 * to a relative residual of 1e-14 (the Jacobi-scaled mass matrix is well conditioned
 * whatever the mesh size: about 30 iterations, no factor in memory), falling back to LU
 * when CG does not get there; before the options (-ksp_type, ...) without a prefix */
void lg_problem_mass_solver(lg_problem *p);
/* the adjoint: (dR/du)^T lam = rhs at the last solution (N values each), R the discrete
 * residual whose essential rows are u_i - g_i */
int lg_problem_adjoint(lg_env *env, lg_problem *p, const double *rhs, double *lam);
/* the tangent-linear solve: (dR/du) du = rhs at the last solution */
int lg_problem_tangent(lg_env *env, lg_problem *p, const double *rhs, double *du);
/* x = A^-1 rhs for the problem's matrix at u = 0 with homogeneous essential rows (Riesz
 * maps); the factorization is kept */
int lg_problem_solve_vector(lg_env *env, lg_problem *p, const double *rhs, double *x);
/* y = A x with that matrix (N values each), and its Frobenius norm */
int lg_problem_matrix_mult(lg_env *env, lg_problem *p, const double *x, double *y);
/* the diagonal and the row sums of the problem's matrix (assembled at u = 0, essential rows
 * identity), N values each */
int lg_problem_matrix_diagonal(lg_env *env, lg_problem *p, double *diag, double *rowsum);
int lg_problem_matrix_norm(lg_env *env, lg_problem *p, double *norm);

/* assembled operators for tests and benchmarks: the matrix (values into a dense n*n array
 * when n is small) */
int lg_problem_dense_matrix(lg_env *env, lg_problem *p, double *dense, int n);
/* reassemble the matrix only (benchmarks); returns milliseconds */
int lg_problem_assemble_matrix(lg_env *env, lg_problem *p, double *ms);
long lg_problem_nnz(const lg_problem *p);

/* ---- time-dependent problems (time.c) */
/* a step problem R(u_{n+1}; u_n[, u_{n-1}], t) = 0 (its unknowns the new state, the
 * previous states discrete functions it reads: prev[level][field], level 0 u_n) marched
 * from t0 by nsteps steps of dt; the time parameter (or -1) is set to each step's new
 * time t0 + k dt, the step-size parameter (or -1) to dt, before it is solved. adaptive: the
 * caller gives each step's size (lg_time_step_at; nsteps 0, no reduced functional). The
 * step problem's kept factorizations are turned off (lg_problem_replayable): a step solved
 * again gives the same bits */
#define LG_TIME_MAXLEV 2
typedef struct lg_time lg_time;
typedef struct {
  lg_problem *step;
  int nlev;
  lg_function *prev[LG_TIME_MAXLEV][KER_MAXFIELD];
  int time_param, dt_param, tprev_param; /* tprev: set to the step's start time t - dt (a theta scheme's explicit part) */
  double t0, dt;
  const double *dts;  /* or each step's size (nsteps of them, copied): fixed, not uniform */
  int nsteps, adaptive;
} lg_time_spec;
lg_time *lg_time_new(lg_env *env, const lg_time_spec *s);
void lg_time_free(lg_time *T);
/* called before step k is solved, after the time parameter is set to t (k = 1 .. nsteps):
 * what changes from step to step (per-step controls, a script's before_step); nonzero with
 * the message in env stops the march */
typedef int (*lg_time_hook)(lg_env *env, void *ud, int k, double t);
void lg_time_set_hook(lg_time *T, lg_time_hook hook, void *ud);
/* a second hook, after the first: a reduced functional's (the controls' values per step) */
void lg_time_set_control_hook(lg_time *T, lg_time_hook hook, void *ud);
lg_problem *lg_time_step_problem(const lg_time *T);
int lg_time_levels(const lg_time *T);
int lg_time_nsteps(const lg_time *T);
double lg_time_at(const lg_time *T, int k);      /* t0 + k dt, or t0 + the first k sizes */
double lg_time_step_size(const lg_time *T, int k); /* t_k - t_{k-1} (k >= 1) */
long lg_time_steps_solved(const lg_time *T);     /* steps solved since it was made */
int lg_time_adaptive(const lg_time *T);           /* its step sizes come from the caller */
lg_function *lg_time_previous(const lg_time *T, int lev, int field);
/* the march's state X_n: the previous functions' values after step n, level after level,
 * field after field (lg_time_state_size values); lg_time_unknowns puts level 0 of X into
 * the step problem's numbering (u, lg_problem_size values) */
int lg_time_state_size(const lg_time *T);
void lg_time_get_state(const lg_time *T, double *X);
void lg_time_set_state(lg_time *T, const double *X);
void lg_time_unknowns(const lg_time *T, const double *X, double *u);
/* a march: lg_time_begin keeps the previous functions' values and the time parameter,
 * lg_time_end puts them back (the march's initial state: what the script gave) */
int lg_time_begin(lg_env *env, lg_time *T);
void lg_time_end(lg_env *env, lg_time *T);
/* step k from the current state: the time parameter and the hook (lg_time_prepare; k = 0:
 * the time parameter at t0 only, for what is evaluated at the initial state), the
 * step problem solved from level 0 as its initial guess, the levels shifted */
int lg_time_prepare(lg_env *env, lg_time *T, int k);
int lg_time_step(lg_env *env, lg_time *T, int k, lg_solve_info *info);
/* step k to the time t by a step of dt (an adaptive march's): 0; 1 when the hooks failed;
 * 2 when the step's solve failed (the state is the one before the step: it may be tried
 * again with a smaller dt) */
int lg_time_step_at(lg_env *env, lg_time *T, int k, double t, double dt, lg_solve_info *info);

#endif
