/* optimize.h — the room src/assemble/optimize: functionals of a problem's solution,
 * their adjoints and reduced functionals (functional.c), and minimization through TAO
 * (optimize.c). Time-dependent adjoints and shape derivatives belong here. Uses
 * problem.h and the rooms below it. */
#ifndef LUGAL_OPTIMIZE_H
#define LUGAL_OPTIMIZE_H

#include "../problem/problem.h"

/* ---- functionals, adjoints, reduced functionals (functional.c) */

/* the compiled kernels of a form, for a number (func < 0) or the vector of its gradient
 * with respect to function func in the space dm (func need not enter linearly) */
typedef struct lg_form_kernels lg_form_kernels;
lg_form_kernels *lg_form_kernels_new(lg_env *env, lg_mesh *lm, const form *F, int func, const dofmap *dm);
void lg_form_kernels_free(lg_form_kernels *K);
int lg_form_kernels_empty(const lg_form_kernels *K);
/* evaluate with the given extra bindings (unknowns bound to values): out[0], or out[dm->ndof] */
int lg_form_kernels_eval(lg_env *env, lg_mesh *lm, lg_form_kernels *K, int nextra, const coef_binding *extra, double *out);

#define LG_MAXCONTROL 8
enum { LG_CONTROL_FIELD, LG_CONTROL_PARAM };
enum { LG_RIESZ_NONE, LG_RIESZ_L2, LG_RIESZ_H1 };
typedef struct {
  int kind;
  lg_function *f;   /* a field control: a discrete function the problem's forms use */
  int param;        /* a parameter control: its index */
  int per_step;     /* a field control of a time-dependent problem with a value per step time
                     * (t0 + k dt, k = 0 .. N; step k and the terms at t_k read value k) */
  lg_function *fprev; /* a per-step control's companion: value k - 1 at step k (value 0 at t0), or NULL */
} lg_control;

/* j(m) = J(u(m), m) for a state problem and a functional (a form without test functions);
 * the controls must appear in the problem or the functional, not (yet) in its essential
 * conditions */
typedef struct lg_reduced lg_reduced;
lg_reduced *lg_reduced_new(lg_env *env, lg_problem *p, const form *J, int nc, const lg_control *c);
void lg_reduced_free(lg_reduced *rf);
int lg_reduced_ncontrols(const lg_reduced *rf);
const lg_control *lg_reduced_control(const lg_reduced *rf, int i);
int lg_reduced_control_size(const lg_reduced *rf, int i); /* dofs of a field, 1 for a parameter, (N + 1) x dofs per step */
/* where control i's value lives: the parameter's value, the field's dofs, or a per-step
 * control's N + 1 blocks of dofs (lg_reduced_control_size values) */
double *lg_reduced_control_values(lg_reduced *rf, int i);
/* the time-dependent problem of a reduced functional, or NULL */
lg_time *lg_reduced_time(const lg_reduced *rf);
/* a per-step control's blocks: N + 1, or 1 for any other control */
int lg_reduced_control_blocks(const lg_reduced *rf, int i);
lg_problem *lg_reduced_problem(const lg_reduced *rf);
/* a control's values changed: the next value or gradient solves the state again */
void lg_reduced_changed(lg_reduced *rf);
/* rf and from have the same state problem and from's state is that of the current controls
 * (which both see): rf takes it without solving again; returns 1 if it did */
int lg_reduced_share_state(lg_reduced *rf, const lg_reduced *from);
int lg_reduced_value(lg_env *env, lg_reduced *rf, double *J);
/* the gradient dj/dm_i as dual vectors (g[i] has lg_reduced_control_size values): one
 * adjoint solve with the state's factorization */
int lg_reduced_gradient(lg_env *env, lg_reduced *rf, double **g);
/* sum_i <a_i, b_i> over the controls' vectors (dual against primal: dofs paired one to one;
 * a distributed mesh's owned dofs summed over the ranks, collective) */
int lg_reduced_dot(lg_env *env, lg_reduced *rf, double **a, double **b, double *out);
/* the Hessian action H dm (dual vectors, like the gradient) at the current controls: a
 * tangent-linear and a second-order adjoint solve with the state's factorization */
int lg_reduced_hessian(lg_env *env, lg_reduced *rf, double **dm, double **out);
/* the Riesz representative of a dual vector of control i: none, L2 (mass) or H1 */
int lg_reduced_riesz(lg_env *env, lg_reduced *rf, int i, int kind, const double *dual, double *out);
/* the Gram matrix problem of field control i (L2: mass; H1: mass + stiffness) */
lg_problem *lg_reduced_gram(lg_env *env, lg_reduced *rf, int i, int h1);

/* du/da at the last solution of p, for a parameter a of its equation (not of its essential
 * conditions): one tangent-linear solve with the state's factorization; du has N values */
int lg_sensitivity(lg_env *env, lg_problem *p, int param, double *du);

/* ---- minimization through TAO (optimize.c) */
#define LG_MAXCONS 16
enum { LG_CON_LE, LG_CON_GE, LG_CON_EQ };
typedef struct {
  const char *method;          /* quasi-Newton "lmvm", "blmvm" (bounds); Newton-Krylov with Hessian
                                * actions "nls", "ntr", "bnls", "bntr" (bounds); "almm" (constraints) */
  int maxit;                   /* 0: TAO's default */
  double gatol, grtol, gttol;  /* TAO's: |g| < gatol, |g|/|J| < grtol, |g|/|g0| < gttol; < 0: TAO's defaults */
  int monitor;                 /* a line per iteration on stdout */
  int riesz;                   /* the inner product of field controls: LG_RIESZ_L2 (default) or NONE */
  const double *lower[LG_MAXCONTROL], *upper[LG_MAXCONTROL]; /* per control, NULL: none */
  const char *series;          /* a .pvd of the field controls per iteration, or NULL */
  /* functional constraints g_j(m) <= c_j, >= c_j or == c_j ("almm": TAO's augmented
   * Lagrangian); each g_j a reduced functional of the same controls */
  int ncons;
  struct { lg_reduced *rf; int kind; double c; } cons[LG_MAXCONS];
} lg_minimize_opts;
typedef struct {
  int iterations, evaluations, hessian_products;
  double J, gnorm, cnorm;
  char reason[64];
  int converged;
  double g[LG_MAXCONS];        /* the constraints' values g_j at the minimizer */
  double lambda[LG_MAXCONS];   /* multipliers: grad J + sum_j lambda_j grad g_j = 0 */
} lg_minimize_info;
/* minimize the reduced functional over its controls, from their current values; they hold
 * the minimizer on return. Fails (with a message) on a state solve that fails, a non-finite
 * functional, or TAO not converging. */
int lg_minimize(lg_env *env, lg_reduced *rf, const lg_minimize_opts *o, lg_minimize_info *info);

/* ---- time-dependent reduced functionals (time_adjoint.c) */
/* the functional's terms: at the final time, running (the trapezoidal rule over the steps'
 * times: dt/2 at t0 and t1, dt between), at a step's time (an observation), or at the
 * initial state (the only terms that may read the previous functions: a regularization of
 * an initial-state control) */
enum { LG_TJ_FINAL, LG_TJ_RUNNING, LG_TJ_AT, LG_TJ_INITIAL };
#define LG_TIME_MAXTERMS 16
typedef struct {
  const form *J;
  int kind;
  double at;
} lg_time_term;
/* where the states go: ram + disk = 0 (or NULL) keeps every state; else ram + disk
 * snapshots of the binomial schedule (the initial state's included; ram + disk >= N + 1
 * keeps every state), the outer levels' disk snapshots in files of a private directory
 * made under dir (NULL: TMPDIR, else /tmp) */
typedef struct {
  int ram, disk;
  const char *dir;
} lg_checkpoints;
/* j(m) = J(u^0 .. u^N, m) of the march of T (problem.h, lg_time): the controls are fields
 * or parameters the step or the terms read, and initial states (a previous function of T).
 * monitor: a progress line every so many steps of each sweep (0: none). lg_reduced_value, lg_reduced_gradient,
 * lg_reduced_hessian (not with a Dirichlet control yet) and what uses them (lg_minimize)
 * work on it as on a steady reduced functional */
lg_reduced *lg_reduced_new_time(lg_env *env, lg_time *T, int nterm, const lg_time_term *terms, int nc, const lg_control *c,
                                const lg_checkpoints *ck, int monitor);
/* the last gradient's forward steps beyond the value's march, the states held at most
 * (snapshots + 2, or N + 1) and of them in memory, the checkpoint files written and read
 * since the reduced functional was made, and their directory (NULL without disk) */
typedef struct {
  long recomputed, disk_writes, disk_reads;
  int states, in_memory;
  const char *dir;
} lg_time_stats;
void lg_time_rf_stats(const lg_reduced *rf, lg_time_stats *st);
/* the tangent-linear march (sensitivities) of rf's problem along the controls' direction dm
 * (as for lg_reduced_hessian): rec(ud, k, du) gets du^k = (du^k/dm) dm, one array per field
 * of the step (k = 0 .. N). rf may have no terms (nterm = 0: made for sensitivities only) */
typedef void (*lg_time_tangent_cb)(void *ud, int k, const double *const *du);
int lg_time_sensitivity(lg_env *env, lg_reduced *rf, double **dm, lg_time_tangent_cb rec, void *ud);
/* Griewank and Walther's minimal number of forward steps of a reversal of l steps with s
 * snapshots, t(l, s) = r l - C(s + r, s + 1), r the least with C(s + r, s) >= l */
long lg_revolve_steps(long l, int s);

#endif
