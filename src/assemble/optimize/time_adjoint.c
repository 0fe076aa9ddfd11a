/* time_adjoint.c — reduced functionals of time-dependent problems (problem/time.c), without a
 * tape: the adjoint of every step is derived from the step's form as for a steady problem.
 *
 * The march: X_0 (the previous functions as given), and for n = 1 .. N the step residual
 * R_n(u^n; X_{n-1}, t_n, m) = 0 whose solution u^n shifts into X_n. The functional is
 *   J = sum_k sum_terms w(term, k) J_term(u^k, m),
 * a final term (w = 1 at k = N), running terms (the trapezoidal rule: dt/2 at k = 0 and N, dt
 * between) and observations at given step times (w = 1 at that step). The backward sweep,
 * n = N .. 1, with the step's inputs restored (its previous states, time, hook):
 *   (dR_n/du^n)^T lam^n = -sum_terms w(term, n) dJ_term/du(u^n) - pending_n,
 * where pending_n collects (dR_{n+1+j}/d prev_j)^T lam^{n+1+j} from the later steps that read
 * u^n as their level-j previous state (each computed when its step is swept, as the
 * gradient of the step's form with its tests replaced by the adjoint, with respect to that
 * previous function). The gradient: dj/dm = sum_n lam^n^T dR_n/dm + sum_k w dJ/dm, and for an
 * initial state (a previous function as a control) the pending vectors that reach step 0.
 *
 * Checkpoints: every state (checkpoints = 0), or binomial checkpointing (Griewank and
 * Walther's revolve) with s snapshots: the reversal of n steps from a snapshot of X_a splits
 * at the m that minimizes m + t(n - m, s - 1) + t(m, s), t the minimal number of forward
 * steps t(l, s) = r l - C(s + r, s + 1), r the least with C(s + r, s) >= l. The adjoint of
 * step n needs X_{n-1} and X_n: the second is held from the step swept before (its input),
 * and the value's march leaves the snapshots of the first descent, X_{N-1} and X_N, so that
 * a gradient after its value recomputes t(N, s) - N + 1 forward steps, the least any schedule
 * with s snapshots can. */
#include "optimize_int.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct {
  form *J;
  int kind;
  int atk;                 /* LG_TJ_AT: the step */
  lg_form_kernels *val, *dJdu[KER_MAXFIELD], *dJdm[LG_MAXCONTROL];
  lg_form_kernels *dJdp[LG_MAXCONTROL]; /* per-step controls: with respect to the value before */
} tj_term;

struct lg_time_rf {
  lg_time *T;
  int nterm;
  tj_term t[LG_TIME_MAXTERMS];
  int nlev, S, N;          /* levels, state size, steps */
  lg_form_kernels *dLdprev[LG_TIME_MAXLEV][KER_MAXFIELD]; /* lam^T dR/d prev_j[b] */
  int ic[LG_MAXCONTROL];   /* a control that is an initial state: level * KER_MAXFIELD + field, else -1 */
  const int *skip_ic;      /* ic[i] >= 0 (construction only) */
  int snaps, ram;          /* 0: every state kept; else the snapshots of the binomial schedule, ram of them in memory */
  /* the states: every one (all[0 .. N]), or the snapshots (ck), the held X_{k} and the
   * working X_{k-1} the value's march leaves */
  double **all;
  lg_ckstore *ck;
  double *held, *work;
  int held_at, work_at;
  double *u, *rhs, *tmp, *pend[LG_TIME_MAXLEV + 1], *dX0;
  double **g;              /* the gradient being summed (the caller's) */
  int SY;                  /* the stored states' size: S, or 2 S in a Hessian sweep (the tangent after the state) */
  int grown;               /* the buffers hold 2 S values (a Hessian action was asked once) */
  struct tm_hess *hs;      /* Hessian actions' state (built on first use), or NULL */
  double *ps[LG_MAXCONTROL]; /* per-step controls: N + 1 blocks of their dofs */
  double *ps_keep[LG_MAXCONTROL][2]; /* their functions' own values (and the companions'), put back after a sweep */
  lg_form_kernels *dLdp[LG_MAXCONTROL]; /* lam^T dR/d(the value before) */
  double J;
  int fresh;               /* J and the stored states are those of the current controls */
  long recomputed;         /* forward steps the last gradient solved */
  int monitor;             /* a progress line every so many steps, 0 none */
  double t_sweep;          /* when the sweep began (lg_now_ms) */
};

/* Hessian mode (below): states carry their tangents; the step solves the tangent too; the
 * adjoint step solves the second-order adjoint too */
static void ystate_get(lg_reduced *rf, double *Y);
static void ystate_set(lg_reduced *rf, const double *Y);
static int full_step(lg_env *env, lg_reduced *rf, int k);
static int hess_on(const lg_reduced *rf);
static void set_step_directions(lg_reduced *rf, int k);
static int second_order_step(lg_env *env, lg_reduced *rf, int n, const double *Yn, const coef_binding *b, int nb);
static void send_back(lg_reduced *rf, double **pend, double *dX0, int n, int j, int a, const double *v);
static void add_initial(lg_reduced *rf, const double *dX0, double **out);

/* ---------------------------------------------------------------- the binomial schedule */

long lg_revolve_steps(long l, int s) {
  if (l <= 1) return 0;
  if (s < 1) return -1;
  if (s == 1) return l * (l - 1) / 2;
  /* r: the least with C(s + r, s) >= l; beta = C(s + r, s) */
  long r = 0;
  double beta = 1;
  while (beta < (double)l) {
    r++;
    beta = beta * (double)(s + r) / (double)r;
  }
  /* C(s + r, s + 1) = C(s + r, s) r / (s + 1) */
  double c = beta * (double)r / (double)(s + 1);
  return (long)llround((double)r * (double)l - c);
}

/* the split of a reversal of n steps with s snapshots (n >= 2, s >= 2): the m of least
 * m + t(n - m, s - 1) + t(m, s), the largest of those (the fewest steps left below) */
static int best_split(int n, int s) {
  long best = -1;
  int at = 1;
  for (int m = 1; m < n; m++) {
    long c = m + lg_revolve_steps(n - m, s - 1) + lg_revolve_steps(m, s);
    if (best < 0 || c <= best) { best = c; at = m; }
  }
  return at;
}

/* ---------------------------------------------------------------- per-step controls */

double *lg_time_rf_steps(lg_reduced *rf, int i) { return rf->tm ? rf->tm->ps[i] : NULL; }
int lg_time_rf_blocks(const lg_reduced *rf) { return rf->tm ? rf->tm->N + 1 : 1; }
lg_time *lg_time_rf_time(const lg_reduced *rf) { return rf->tm ? rf->tm->T : NULL; }

/* value k of every per-step control into its function */
static void set_step_controls(lg_reduced *rf, int k) {
  lg_time_rf *R = rf->tm;
  for (int i = 0; i < rf->nc; i++)
    if (R->ps[i]) {
      int nd = rf->c[i].f->dm->ndof;
      memcpy(rf->c[i].f->x, R->ps[i] + (size_t)k * (size_t)nd, sizeof(double) * (size_t)nd);
      if (rf->c[i].fprev) memcpy(rf->c[i].fprev->x, R->ps[i] + (size_t)(k > 0 ? k - 1 : 0) * (size_t)nd, sizeof(double) * (size_t)nd);
    }
}

static int step_hook(lg_env *env, void *ud, int k, double t) {
  (void)env;
  (void)t;
  set_step_controls(ud, k);
  if (hess_on(ud)) set_step_directions(ud, k);
  return 0;
}

/* a sweep's start and end: the per-step controls' functions kept and put back, the hook set
 * and cleared */
static void sweep_begin(lg_reduced *rf) {
  lg_time_rf *R = rf->tm;
  R->t_sweep = lg_now_ms();
  for (int i = 0; i < rf->nc; i++)
    if (R->ps[i]) {
      memcpy(R->ps_keep[i][0], rf->c[i].f->x, sizeof(double) * (size_t)rf->c[i].f->dm->ndof);
      if (rf->c[i].fprev) memcpy(R->ps_keep[i][1], rf->c[i].fprev->x, sizeof(double) * (size_t)rf->c[i].f->dm->ndof);
    }
  lg_time_set_control_hook(R->T, step_hook, rf);
}

static void sweep_end(lg_reduced *rf) {
  lg_time_rf *R = rf->tm;
  lg_time_set_control_hook(R->T, NULL, NULL);
  for (int i = 0; i < rf->nc; i++)
    if (R->ps[i]) {
      memcpy(rf->c[i].f->x, R->ps_keep[i][0], sizeof(double) * (size_t)rf->c[i].f->dm->ndof);
      if (rf->c[i].fprev) memcpy(rf->c[i].fprev->x, R->ps_keep[i][1], sizeof(double) * (size_t)rf->c[i].f->dm->ndof);
    }
}

/* ---------------------------------------------------------------- weights and evaluation */

static double weight(const lg_time_rf *R, const tj_term *t, int k) {
  if (t->kind == LG_TJ_FINAL) return k == R->N ? 1 : 0;
  if (t->kind == LG_TJ_AT) return k == t->atk ? 1 : 0;
  if (t->kind == LG_TJ_INITIAL) return k == 0 ? 1 : 0;
  /* the trapezoidal rule on the step times: (t_{k+1} - t_{k-1}) / 2 */
  return 0.5 * ((k < R->N ? lg_time_step_size(R->T, k + 1) : 0) + (k > 0 ? lg_time_step_size(R->T, k) : 0));
}

/* the terms' value at step k, from the state X_k (its level 0: the unknowns u^k) */
static int value_at(lg_env *env, lg_reduced *rf, int k, const double *X, double *J) {
  lg_time_rf *R = rf->tm;
  lg_time_unknowns(R->T, X, R->u);
  coef_binding b[2 * KER_MAXFIELD];
  int nb = lg_problem_bind_values(rf->p, R->u, b);
  for (int i = 0; i < R->nterm; i++) {
    double w = weight(R, &R->t[i], k), v;
    if (w == 0) continue;
    if (lg_form_kernels_eval(env, rf->lm, R->t[i].val, nb, b, &v)) return 1;
    *J += w * v;
  }
  return 0;
}

/* ---------------------------------------------------------------- the forward march */

/* a progress line every R->monitor steps (and at the last), the sweep's seconds so far */
static void monitor_line(const lg_time_rf *R, int k, const char *what) {
  int last = strcmp(what, "adjoint") ? k == R->N : k == 1;
  if (R->monitor > 0 && lg_mpi_rank() == 0 && (last || k % R->monitor == 0)) {
    printf("%s: step %d of %d (t = %.6g), %.3f s\n", what, k, R->N, lg_time_at(R->T, k), 1e-3 * (lg_now_ms() - R->t_sweep));
    fflush(stdout);
  }
}

/* a snapshot for a reversal with s snapshots (its own included) goes to disk when s > ram:
 * the multistage schedule keeps on disk the outer levels' snapshots, read least often (a
 * snapshot of a reversal with s snapshots is read about s times, one with 1 at each step),
 * and in memory the inner ones */
static int put_snapshot(lg_env *env, lg_time_rf *R, int k, int s, const double *X) {
  return lg_ckstore_put(env, R->ck, k, s > R->ram, X, (size_t)R->SY);
}

static const double *get_snapshot(lg_env *env, lg_time_rf *R, int k) { return lg_ckstore_get(env, R->ck, k, (size_t)R->SY); }

/* the positions the schedule's first descent snapshots (at[i], for a reversal with bud[i]
 * snapshots), down to where its innermost reversal starts (one snapshot left, or one step);
 * returns their number (at most snaps) */
static int first_descent(const lg_time_rf *R, int *at, int *bud) {
  int a = 0, n = R->N, s = R->snaps, c = 0;
  at[c] = 0;
  bud[c++] = s;
  while (n >= 2 && s >= 2) {
    int m = best_split(n, s);
    a += m;
    n -= m;
    s--;
    at[c] = a;
    bud[c++] = s;
  }
  return c;
}

/* the value's march: J, and the states the gradient starts from (every one, or the first
 * descent's snapshots, X_{N-1} and X_N) */
static int march(lg_env *env, lg_reduced *rf) {
  lg_time_rf *R = rf->tm;
  lg_time *T = R->T;
  int *at = NULL, *bud = NULL, nsp = 0, next = 1;
  if (R->snaps) {
    at = malloc(sizeof(int) * (size_t)R->snaps * 2 + 8);
    if (!at) { lg_seterr(env, "out of memory"); return 1; }
    bud = at + R->snaps;
    nsp = first_descent(R, at, bud);
    lg_ckstore_clear(R->ck);
  }
  R->fresh = 0;
  if (lg_time_begin(env, T)) { free(at); return 1; }
  sweep_begin(rf);
  double J = 0, *X = R->snaps ? R->held : R->all[0];
  ystate_get(rf, X);
  lg_time_prepare(env, T, 0);
  set_step_controls(rf, 0);
  int rc = R->snaps ? put_snapshot(env, R, 0, R->snaps, X) : 0;
  if (!rc) rc = value_at(env, rf, 0, X, &J);
  for (int k = 1; !rc && k <= R->N; k++) {
    if (R->snaps && k == R->N) memcpy(R->work, R->held, sizeof(double) * (size_t)R->SY); /* X_{N-1} */
    if ((rc = full_step(env, rf, k))) break;
    X = R->snaps ? R->held : R->all[k];
    ystate_get(rf, X);
    if (next < nsp && at[next] == k && k < R->N) {
      rc = put_snapshot(env, R, k, bud[next], X);
      next++;
    }
    if (!rc) rc = value_at(env, rf, k, X, &J);
    monitor_line(R, k, "forward");
  }
  sweep_end(rf);
  lg_time_end(env, T);
  free(at);
  if (rc) {
    lg_ckstore_clear(R->ck);
    return 1;
  }
  R->J = J;
  R->held_at = R->N;
  R->work_at = R->N - 1;
  R->fresh = 1;
  return 0;
}

/* X_b from X_a (a < b) into out, counting the steps */
static int advance(lg_env *env, lg_reduced *rf, const double *Xa, int a, int b, double *out) {
  lg_time_rf *R = rf->tm;
  ystate_set(rf, Xa);
  for (int k = a + 1; k <= b; k++) {
    if (full_step(env, rf, k)) return 1;
    R->recomputed++;
  }
  ystate_get(rf, out);
  return 0;
}

/* ---------------------------------------------------------------- one step's adjoint */

/* the adjoint of step n from its inputs X_{n-1} (Xp) and its output X_n (Xn): lam^n, its
 * terms of the gradient, and what it sends to the earlier steps (pending, dX0) */
static int adjoint_step(lg_env *env, lg_reduced *rf, int n, const double *Xp, const double *Xn) {
  lg_time_rf *R = rf->tm;
  lg_time *T = R->T;
  lg_problem *p = rf->p;
  int N = lg_problem_size(p), L = R->nlev;
  ystate_set(rf, Xp);
  if (lg_time_prepare(env, T, n)) return 1;
  lg_time_unknowns(T, Xn, R->u);
  if (lg_problem_restore(env, p, R->u)) return 1;
  coef_binding b[3 * KER_MAXFIELD];
  int nb = lg_problem_bind_values(p, R->u, b);
  /* the right side: -sum w dJ/du(u^n) - pending_n */
  double *pend = R->pend[n % (L + 1)];
  for (int i = 0; i < N; i++) R->rhs[i] = -pend[i];
  memset(pend, 0, sizeof(double) * (size_t)N);
  for (int i = 0; i < R->nterm; i++) {
    double w = weight(R, &R->t[i], n);
    if (w == 0) continue;
    for (int a = 0; a < rf->nf; a++) {
      if (lg_form_kernels_eval(env, rf->lm, R->t[i].dJdu[a], nb, b, R->tmp)) return 1;
      for (int d = 0; d < rf->fld[a].dm->ndof; d++) R->rhs[rf->fld[a].offset + d] -= w * R->tmp[d];
    }
  }
  if (lg_problem_adjoint(env, p, R->rhs, rf->lamv)) {
    char why[LG_ERRLEN];
    snprintf(why, sizeof why, "%s", env->err);
    lg_seterr(env, "the adjoint of step %d (t = %.6g): %s", n, lg_time_at(T, n), why);
    return 1;
  }
  if (lg_reduced_set_adjoint(env, rf, rf->lamv)) return 1;
  /* the controls' terms: lam^n^T dR_n/dm and the terms' dJ/dm at step n (a Hessian sweep
   * needs the adjoint only) */
  for (int i = 0; i < rf->nc && !hess_on(rf); i++) {
    if (R->ic[i] >= 0) continue;
    int m = lg_reduced_control_size(rf, i);
    double *gi = R->g[i];
    if (R->ps[i]) { /* a per-step control: its block n */
      m /= R->N + 1;
      gi += (size_t)n * (size_t)m;
    }
    if (lg_form_kernels_eval(env, rf->lm, rf->dLdm[i], nb, b, R->tmp)) return 1;
    for (int k = 0; k < m; k++) gi[k] += R->tmp[k];
    for (int t = 0; t < R->nterm; t++) {
      double w = weight(R, &R->t[t], n);
      if (w == 0) continue;
      if (lg_form_kernels_eval(env, rf->lm, R->t[t].dJdm[i], nb, b, R->tmp)) return 1;
      for (int k = 0; k < m; k++) gi[k] += w * R->tmp[k];
    }
    if (rf->bcdep[i] && lg_reduced_bc_transpose(env, rf, i, rf->lamv, -1, gi)) return 1;
    if (R->ps[i] && rf->c[i].fprev) { /* the value before: block n - 1 */
      double *gp = gi - m;
      if (R->dLdp[i]) {
        if (lg_form_kernels_eval(env, rf->lm, R->dLdp[i], nb, b, R->tmp)) return 1;
        for (int k = 0; k < m; k++) gp[k] += R->tmp[k];
      }
      for (int t = 0; t < R->nterm; t++) {
        double w = weight(R, &R->t[t], n);
        if (w == 0 || !R->t[t].dJdp[i]) continue;
        if (lg_form_kernels_eval(env, rf->lm, R->t[t].dJdp[i], nb, b, R->tmp)) return 1;
        for (int k = 0; k < m; k++) gp[k] += w * R->tmp[k];
      }
    }
  }
  /* to the steps that made this one's previous states: level j of X_{n-1} is u^{n-1-j} */
  for (int j = 0; j < L; j++)
    for (int a = 0; a < rf->nf; a++) {
      if (!R->dLdprev[j][a]) continue;
      if (lg_form_kernels_eval(env, rf->lm, R->dLdprev[j][a], nb, b, R->tmp)) return 1;
      send_back(rf, R->pend, R->dX0, n, j, a, R->tmp);
    }
  if (hess_on(rf) && second_order_step(env, rf, n, Xn, b, nb)) return 1;
  monitor_line(R, n, "adjoint");
  return 0;
}

/* ---------------------------------------------------------------- the reversals */

/* steps a + 1 .. a + n reversed, X_a in a snapshot, R->held = X_{a+n}; ends with R->held =
 * X_a. s: the snapshots this reversal may use, X_a's included */
static int reverse(lg_env *env, lg_reduced *rf, int a, int n, int s) {
  lg_time_rf *R = rf->tm;
  size_t bytes = sizeof(double) * (size_t)R->SY;
  const double *Xa; /* read where it is used: a disk snapshot's buffer is the next read's */
  if (n == 1) {
    if (!(Xa = get_snapshot(env, R, a)) || adjoint_step(env, rf, a + 1, Xa, R->held)) return 1;
    memcpy(R->held, Xa, bytes);
    R->held_at = a;
    return 0;
  }
  if (s == 1) { /* each step's input from X_a (the value's march left the last one) */
    for (int k = n; k >= 1; k--) {
      const double *in;
      if (k > 1) {
        if (R->work_at != a + k - 1 && (!(Xa = get_snapshot(env, R, a)) || advance(env, rf, Xa, a, a + k - 1, R->work))) return 1;
        R->work_at = a + k - 1;
        in = R->work;
      } else if (!(in = get_snapshot(env, R, a)))
        return 1;
      if (adjoint_step(env, rf, a + k, in, R->held)) return 1;
      memcpy(R->held, in, bytes);
      R->held_at = a + k - 1;
    }
    return 0;
  }
  int m = best_split(n, s);
  if (!lg_ckstore_has(R->ck, a + m)) {
    if (!(Xa = get_snapshot(env, R, a)) || advance(env, rf, Xa, a, a + m, R->work)) return 1;
    R->work_at = a + m;
    if (put_snapshot(env, R, a + m, s - 1, R->work)) return 1;
  }
  if (reverse(env, rf, a + m, n - m, s - 1)) return 1;
  lg_ckstore_drop(R->ck, a + m);
  return reverse(env, rf, a, m, s);
}

/* ---------------------------------------------------------------- value and gradient */

int lg_time_value(lg_env *env, lg_reduced *rf, double *J) {
  lg_time_rf *R = rf->tm;
  if (!R->all && !R->snaps) { lg_seterr(env, "internal error: a reduced functional made for sensitivities has no value"); return 1; }
  if (!R->fresh || !rf->solved) {
    if (march(env, rf)) return 1;
    rf->solved = 1;
  }
  *J = R->J;
  return 0;
}

static int hessian_step0(lg_env *env, lg_reduced *rf, const double *Y0);

/* the backward sweep after a march: the gradient into g (and, in a Hessian sweep, the
 * Hessian action into the Hessian's buffers) */
static int backward(lg_env *env, lg_reduced *rf, double **g) {
  lg_time_rf *R = rf->tm;
  int N = lg_problem_size(rf->p);
  R->g = g;
  for (int i = 0; i < rf->nc; i++) memset(g[i], 0, sizeof(double) * (size_t)lg_reduced_control_size(rf, i));
  for (int l = 0; l <= R->nlev; l++) memset(R->pend[l], 0, sizeof(double) * (size_t)N);
  memset(R->dX0, 0, sizeof(double) * (size_t)R->S);
  R->recomputed = 0;
  lg_time *T = R->T;
  if (lg_time_begin(env, T)) return 1;
  sweep_begin(rf);
  int rc = 0;
  if (R->snaps) rc = reverse(env, rf, 0, R->N, R->snaps);
  else
    for (int n = R->N; n >= 1 && !rc; n--) rc = adjoint_step(env, rf, n, R->all[n - 1], R->all[n]);
  /* step 0: the terms at the initial state (their dJ/du into dX0's level 0, dJ/dm) */
  const double *X0 = rc ? NULL : R->snaps ? get_snapshot(env, R, 0) : R->all[0];
  if (!X0) rc = 1;
  if (!rc) {
    ystate_set(rf, X0);
    lg_time_prepare(env, T, 0);
    set_step_controls(rf, 0);
    lg_time_unknowns(T, X0, R->u);
    coef_binding b[3 * KER_MAXFIELD];
    int nb = lg_problem_bind_values(rf->p, R->u, b);
    for (int t = 0; t < R->nterm && !rc; t++) {
      double w = weight(R, &R->t[t], 0);
      if (w == 0) continue;
      for (int a = 0, off = 0; a < rf->nf && !rc; off += rf->fld[a].dm->ndof, a++) {
        if ((rc = lg_form_kernels_eval(env, rf->lm, R->t[t].dJdu[a], nb, b, R->tmp))) break;
        for (int d = 0; d < rf->fld[a].dm->ndof; d++) R->dX0[off + d] += w * R->tmp[d];
      }
      for (int i = 0; i < rf->nc && !rc; i++) {
        if (!R->t[t].dJdm[i]) continue; /* an initial state, read only by initial terms */
        if ((rc = lg_form_kernels_eval(env, rf->lm, R->t[t].dJdm[i], nb, b, R->tmp))) break;
        int m = lg_reduced_control_size(rf, i) / lg_reduced_control_blocks(rf, i); /* block 0 of a per-step control */
        for (int k = 0; k < m; k++) g[i][k] += w * R->tmp[k];
        if (R->t[t].dJdp[i]) { /* the value before t0 is value 0 */
          if ((rc = lg_form_kernels_eval(env, rf->lm, R->t[t].dJdp[i], nb, b, R->tmp))) break;
          for (int k = 0; k < m; k++) g[i][k] += w * R->tmp[k];
        }
      }
    }
  }
  if (!rc && hess_on(rf)) rc = hessian_step0(env, rf, X0);
  sweep_end(rf);
  lg_time_end(env, T);
  if (!rc) add_initial(rf, R->dX0, g); /* the initial states' gradients */
  for (int i = 0; i < rf->nc && !rc; i++) rc = lg_reduced_dirichlet_ghosts(env, rf, i, g[i]);
  /* the stored states are spent (the snapshots were reused): the next gradient marches */
  if (R->snaps) {
    R->fresh = 0;
    lg_ckstore_clear(R->ck);
  }
  return rc;
}

int lg_time_gradient(lg_env *env, lg_reduced *rf, double **g) {
  double J;
  if (lg_time_value(env, rf, &J)) return 1;
  int rc = backward(env, rf, g);
  rf->grad_fresh = !rc;
  return rc;
}

void lg_time_rf_stats(const lg_reduced *rf, lg_time_stats *st) {
  const lg_time_rf *R = rf->tm;
  memset(st, 0, sizeof *st);
  if (!R) return;
  st->recomputed = R->recomputed;
  st->states = R->snaps ? R->snaps + 2 : R->N + 1;
  st->in_memory = R->snaps ? R->ram + 2 : R->N + 1;
  lg_ckstore_stats(R->ck, &st->disk_writes, &st->disk_reads, &st->dir);
}

/* ---------------------------------------------------------------- Hessian actions */

/* H dm by a tangent march and a second-order backward sweep under the same schedule. The
 * stored state Y_n is [X_n, dX_n]: the previous functions' values and their tangents (the
 * tangent functions dprev hold dX during the march, as the previous functions hold X). Step n
 * solves u^n, then from its inputs the tangent (dR/du) du^n = -(R_P dP + R_m dm), zero on the
 * essential rows. Backward, after lam^n, with D = the directional derivative of
 * lam^n R_n + sum w J in the direction (du^n, dP, dm) and G = dlam^n R_n:
 *   (dR/du)^T dlam^n = -dD/du^n - pending2_n,  H dm += dD/dm + dG/dm,
 * and dD/dP_j + dG/dP_j go to the step that made P_j (pending2), or to the initial states. */
struct tm_hess {
  int on;
  lg_function *dprev[LG_TIME_MAXLEV][KER_MAXFIELD], *du[KER_MAXFIELD], *dlam[KER_MAXFIELD];
  lg_function *dmf[LG_MAXCONTROL], *dfp[LG_MAXCONTROL]; /* field directions; a per-step companion's */
  int dpar[LG_MAXCONTROL];
  double *dps[LG_MAXCONTROL];                          /* a per-step control's direction, N + 1 blocks */
  lg_form_kernels *tan[KER_MAXFIELD];                  /* R_P dP + R_m dm, by test field */
  lg_form_kernels *jd_u[LG_TIME_MAXTERMS][KER_MAXFIELD], *jd_m[LG_TIME_MAXTERMS][LG_MAXCONTROL];
  lg_form_kernels *jd_p[LG_TIME_MAXTERMS][LG_MAXCONTROL];
  lg_form_kernels *ld_u[KER_MAXFIELD], *ld_P[LG_TIME_MAXLEV][KER_MAXFIELD], *ld_m[LG_MAXCONTROL], *ld_p[LG_MAXCONTROL];
  lg_form_kernels *g_P[LG_TIME_MAXLEV][KER_MAXFIELD], *g_m[LG_MAXCONTROL], *g_p[LG_MAXCONTROL];
  double *pend2[LG_TIME_MAXLEV + 1], *dX0b, *ytmp, *xk, *v;
  double **h;
};

static int hess_on(const lg_reduced *rf) { return rf->tm && rf->tm->hs && rf->tm->hs->on; }

/* the state and, in a Hessian sweep, its tangent: functions <-> a stored state */
static void ystate_get(lg_reduced *rf, double *Y) {
  lg_time_rf *R = rf->tm;
  lg_time_get_state(R->T, Y);
  if (!hess_on(rf)) return;
  double *d = Y + R->S;
  for (int j = 0; j < R->nlev; j++)
    for (int a = 0; a < rf->nf; a++) {
      int nd = rf->fld[a].dm->ndof;
      memcpy(d, R->hs->dprev[j][a]->x, sizeof(double) * (size_t)nd);
      d += nd;
    }
}

static void ystate_set(lg_reduced *rf, const double *Y) {
  lg_time_rf *R = rf->tm;
  lg_time_set_state(R->T, Y);
  if (!hess_on(rf)) return;
  const double *d = Y + R->S;
  for (int j = 0; j < R->nlev; j++)
    for (int a = 0; a < rf->nf; a++) {
      int nd = rf->fld[a].dm->ndof;
      memcpy(R->hs->dprev[j][a]->x, d, sizeof(double) * (size_t)nd);
      d += nd;
    }
}

/* a per-step control's direction at step k (and its companion's, block k - 1) */
static void set_step_directions(lg_reduced *rf, int k) {
  struct tm_hess *H = rf->tm->hs;
  for (int i = 0; i < rf->nc; i++)
    if (H->dps[i]) {
      int nd = rf->c[i].f->dm->ndof;
      memcpy(H->dmf[i]->x, H->dps[i] + (size_t)k * (size_t)nd, sizeof(double) * (size_t)nd);
      if (H->dfp[i]) memcpy(H->dfp[i]->x, H->dps[i] + (size_t)(k > 0 ? k - 1 : 0) * (size_t)nd, sizeof(double) * (size_t)nd);
    }
}

/* step k, and in a Hessian sweep its tangent from the step's inputs */
static int full_step(lg_env *env, lg_reduced *rf, int k) {
  lg_time_rf *R = rf->tm;
  lg_solve_info info;
  if (!hess_on(rf)) return lg_time_step(env, R->T, k, &info);
  struct tm_hess *H = R->hs;
  lg_problem *p = rf->p;
  int N = lg_problem_size(p);
  lg_time_get_state(R->T, H->ytmp); /* X_{k-1}; the tangents dX_{k-1} stay in dprev */
  if (lg_time_step(env, R->T, k, &info)) return 1;
  lg_time_get_state(R->T, H->xk);
  memcpy(R->u, lg_problem_solution(p), sizeof(double) * (size_t)N);
  lg_time_set_state(R->T, H->ytmp);
  if (lg_time_prepare(env, R->T, k) || lg_problem_restore(env, p, R->u)) return 1;
  coef_binding b[3 * KER_MAXFIELD];
  int nb = lg_problem_bind_values(p, R->u, b);
  for (int a = 0; a < rf->nf; a++)
    if (lg_form_kernels_eval(env, rf->lm, H->tan[a], nb, b, R->rhs + rf->fld[a].offset)) return 1;
  for (int i = 0; i < N; i++) R->rhs[i] = -R->rhs[i];
  lg_problem_zero_essential(p, R->rhs);
  for (int i = 0; i < rf->nc; i++) /* a Dirichlet control's rows: du_r = dg_r/dm dm at step k */
    if (rf->bcdep[i]) {
      const double *d = rf->c[i].kind == LG_CONTROL_PARAM ? &expr_param_values(env->c)[H->dpar[i]] : H->dmf[i]->x;
      if (lg_reduced_bc_action(env, rf, i, d, R->rhs)) return 1;
    }
  if (lg_problem_tangent(env, p, R->rhs, H->v)) return 1;
  /* the new state and its tangent: the levels shifted, level 0 du^k */
  lg_time_set_state(R->T, H->xk);
  for (int j = R->nlev - 1; j > 0; j--)
    for (int a = 0; a < rf->nf; a++)
      memcpy(H->dprev[j][a]->x, H->dprev[j - 1][a]->x, sizeof(double) * (size_t)rf->fld[a].dm->ndof);
  for (int a = 0; a < rf->nf; a++)
    memcpy(H->dprev[0][a]->x, H->v + rf->fld[a].offset, sizeof(double) * (size_t)rf->fld[a].dm->ndof);
  return 0;
}

/* the place of level lev of field a in a state X */
static int state_offset(const lg_reduced *rf, int lev, int a) {
  int off = 0;
  for (int j = 0; j < lev; j++)
    for (int aa = 0; aa < rf->nf; aa++) off += rf->fld[aa].dm->ndof;
  for (int aa = 0; aa < a; aa++) off += rf->fld[aa].dm->ndof;
  return off;
}

/* v (field a's values) added at the step that made level j of step n's inputs (pending, in
 * the problem's numbering), or for level -m of the initial state X_0 into dX0 */
static void send_back(lg_reduced *rf, double **pend, double *dX0, int n, int j, int a, const double *v) {
  int m = n - 1 - j, nd = rf->fld[a].dm->ndof;
  double *to = m >= 1 ? pend[m % (rf->tm->nlev + 1)] + rf->fld[a].offset : dX0 + state_offset(rf, -m, a);
  for (int d = 0; d < nd; d++) to[d] += v[d];
}

/* the initial states' parts of dX0 added to their controls' vectors */
static void add_initial(lg_reduced *rf, const double *dX0, double **out) {
  lg_time_rf *R = rf->tm;
  for (int i = 0; i < rf->nc; i++) {
    if (R->ic[i] < 0) continue;
    int a = R->ic[i] % KER_MAXFIELD, off = state_offset(rf, R->ic[i] / KER_MAXFIELD, a);
    for (int d = 0; d < rf->fld[a].dm->ndof; d++) out[i][d] += dX0[off + d];
  }
}

/* out += s K (evaluated); a per-step control's block `blk` */
static int add_eval(lg_env *env, lg_reduced *rf, lg_form_kernels *K, const coef_binding *b, int nb, int i, int blk, double *out) {
  if (!K) return 0;
  lg_time_rf *R = rf->tm;
  int m = lg_reduced_control_size(rf, i) / lg_reduced_control_blocks(rf, i);
  if (lg_form_kernels_eval(env, rf->lm, K, nb, b, R->tmp)) return 1;
  double *o = out + (R->ps[i] ? (size_t)blk * (size_t)m : 0);
  for (int k = 0; k < m; k++) o[k] += R->tmp[k];
  return 0;
}

/* the second-order adjoint of step n (lam^n set, step n's inputs and their tangents dX_{n-1}
 * restored) from its output Yn, and its terms */
static int second_order_step(lg_env *env, lg_reduced *rf, int n, const double *Yn, const coef_binding *b, int nb) {
  lg_time_rf *R = rf->tm;
  struct tm_hess *H = R->hs;
  lg_problem *p = rf->p;
  int N = lg_problem_size(p), L = R->nlev;
  /* du^n: level 0 of dX_n */
  for (int a = 0, off = R->S; a < rf->nf; off += rf->fld[a].dm->ndof, a++)
    memcpy(H->du[a]->x, Yn + off, sizeof(double) * (size_t)rf->fld[a].dm->ndof);
  double *pend = H->pend2[n % (L + 1)];
  for (int i = 0; i < N; i++) R->rhs[i] = -pend[i];
  memset(pend, 0, sizeof(double) * (size_t)N);
  for (int a = 0; a < rf->nf; a++) {
    int nd = rf->fld[a].dm->ndof;
    double *r = R->rhs + rf->fld[a].offset;
    if (lg_form_kernels_eval(env, rf->lm, H->ld_u[a], nb, b, R->tmp)) return 1;
    for (int d = 0; d < nd; d++) r[d] -= R->tmp[d];
    for (int t = 0; t < R->nterm; t++) {
      double w = weight(R, &R->t[t], n);
      if (w == 0 || !H->jd_u[t][a]) continue;
      if (lg_form_kernels_eval(env, rf->lm, H->jd_u[t][a], nb, b, R->tmp)) return 1;
      for (int d = 0; d < nd; d++) r[d] -= w * R->tmp[d];
    }
  }
  if (lg_problem_adjoint(env, p, R->rhs, H->v)) return 1;
  for (int i = 0; i < rf->nc; i++) /* a Dirichlet control's rows u_r - g_r(m), affine in m: -dlam_r dg_r/dm */
    if (rf->bcdep[i]) {
      int m = lg_reduced_control_size(rf, i) / lg_reduced_control_blocks(rf, i);
      if (lg_reduced_bc_transpose(env, rf, i, H->v, -1, H->h[i] + (R->ps[i] ? (size_t)n * (size_t)m : 0))) return 1;
    }
  lg_problem_zero_essential(p, H->v);
  for (int a = 0; a < rf->nf; a++) memcpy(H->dlam[a]->x, H->v + rf->fld[a].offset, sizeof(double) * (size_t)rf->fld[a].dm->ndof);
  /* H dm: dD/dm + dG/dm (a per-step control's block n, its companion's block n - 1) */
  for (int i = 0; i < rf->nc; i++) {
    if (R->ic[i] >= 0) continue;
    if (add_eval(env, rf, H->ld_m[i], b, nb, i, n, H->h[i]) || add_eval(env, rf, H->g_m[i], b, nb, i, n, H->h[i]) ||
        add_eval(env, rf, H->ld_p[i], b, nb, i, n - 1, H->h[i]) || add_eval(env, rf, H->g_p[i], b, nb, i, n - 1, H->h[i]))
      return 1;
    for (int t = 0; t < R->nterm; t++) {
      double w = weight(R, &R->t[t], n);
      if (w == 0) continue;
      double *save = R->tmp; /* weighted: through a scaled copy */
      int m = lg_reduced_control_size(rf, i) / lg_reduced_control_blocks(rf, i);
      for (int pass = 0; pass < 2; pass++) {
        lg_form_kernels *K = pass ? H->jd_p[t][i] : H->jd_m[t][i];
        if (!K) continue;
        if (lg_form_kernels_eval(env, rf->lm, K, nb, b, save)) return 1;
        int blk = pass ? n - 1 : n;
        double *o = H->h[i] + (R->ps[i] ? (size_t)blk * (size_t)m : 0);
        for (int k = 0; k < m; k++) o[k] += w * save[k];
      }
    }
  }
  /* to the steps that made the inputs */
  for (int j = 0; j < L; j++)
    for (int a = 0; a < rf->nf; a++)
      for (int pass = 0; pass < 2; pass++) {
        lg_form_kernels *K = pass ? H->g_P[j][a] : H->ld_P[j][a];
        if (!K) continue;
        if (lg_form_kernels_eval(env, rf->lm, K, nb, b, R->tmp)) return 1;
        send_back(rf, H->pend2, H->dX0b, n, j, a, R->tmp);
      }
  return 0;
}

/* the terms at the initial state: dD/du^0 into the initial states, dD/dm */
static int hessian_step0(lg_env *env, lg_reduced *rf, const double *Y0) {
  lg_time_rf *R = rf->tm;
  struct tm_hess *H = R->hs;
  set_step_directions(rf, 0);
  for (int a = 0, off = R->S; a < rf->nf; off += rf->fld[a].dm->ndof, a++)
    memcpy(H->du[a]->x, Y0 + off, sizeof(double) * (size_t)rf->fld[a].dm->ndof);
  coef_binding b[3 * KER_MAXFIELD];
  int nb = lg_problem_bind_values(rf->p, R->u, b); /* R->u: u^0, set by the first-order step 0 */
  for (int t = 0; t < R->nterm; t++) {
    double w = weight(R, &R->t[t], 0);
    if (w == 0) continue;
    for (int a = 0, off = 0; a < rf->nf; off += rf->fld[a].dm->ndof, a++) {
      if (!H->jd_u[t][a]) continue;
      if (lg_form_kernels_eval(env, rf->lm, H->jd_u[t][a], nb, b, R->tmp)) return 1;
      for (int d = 0; d < rf->fld[a].dm->ndof; d++) H->dX0b[off + d] += w * R->tmp[d];
    }
    for (int i = 0; i < rf->nc; i++) {
      int m = lg_reduced_control_size(rf, i) / lg_reduced_control_blocks(rf, i);
      for (int pass = 0; pass < 2; pass++) {
        lg_form_kernels *K = pass ? H->jd_p[t][i] : H->jd_m[t][i];
        if (!K) continue;
        if (lg_form_kernels_eval(env, rf->lm, K, nb, b, R->tmp)) return 1;
        for (int k = 0; k < m; k++) H->h[i][k] += w * R->tmp[k]; /* block 0 (the value before t0 is value 0) */
      }
    }
  }
  return 0;
}


/* the direction expression of e: its derivative along every control's direction (fields,
 * per-step companions, parameters) and every previous function's (dprev); with du, along the
 * unknowns' too */
static expr *direction_of(lg_env *env, lg_reduced *rf, expr *e, int with_du) {
  lg_time_rf *R = rf->tm;
  struct tm_hess *H = R->hs;
  expr_ctx *c = env->c;
  expr *sum = expr_num(c, 0);
  for (int i = 0; i < rf->nc && sum; i++) {
    const lg_control *ci = &rf->c[i];
    if (R->ic[i] >= 0) continue; /* an initial state: along dprev below */
    if (ci->kind == LG_CONTROL_PARAM)
      sum = expr_add(c, sum, expr_mul(c, expr_diff(c, e, expr_param(c, ci->param)), expr_param(c, H->dpar[i])));
    else {
      sum = expr_add(c, sum, form_directional(c, e, ci->f->fid, H->dmf[i]->fid));
      if (H->dfp[i]) sum = expr_add(c, sum, form_directional(c, e, ci->fprev->fid, H->dfp[i]->fid));
    }
  }
  for (int j = 0; j < R->nlev && sum; j++)
    for (int a = 0; a < rf->nf && sum; a++)
      sum = expr_add(c, sum, form_directional(c, e, lg_time_previous(R->T, j, a)->fid, H->dprev[j][a]->fid));
  for (int a = 0; with_du && a < rf->nf && sum; a++) sum = expr_add(c, sum, form_directional(c, e, rf->fld[a].unknown, H->du[a]->fid));
  return sum;
}

/* a form of each term's direction (or G: the equation with its tests replaced by dlam) */
static form *hess_form(lg_env *env, lg_reduced *rf, const form *F, int kind) {
  form *D = form_new();
  for (int i = 0; D && i < F->n; i++) {
    expr *e = F->t[i].integrand;
    if (kind == 2)
      for (int a = 0; a < rf->nf && e; a++) e = form_replace_function(env->c, e, rf->fld[a].test, rf->tm->hs->dlam[a]->fid);
    else e = direction_of(env, rf, e, kind == 1);
    if (!e || form_add_term(D, &F->t[i].reg, e, F->t[i].order)) { form_free(D); D = NULL; }
  }
  if (!D) lg_seterr(env, "%s", expr_error(env->c)[0] ? expr_error(env->c) : "out of memory");
  return D;
}

/* the gradient kernels of F with respect to function fid (space dm), or NULL where F does
 * not use it; param >= 0: the derivative with respect to that parameter (a number). 1 on
 * failure */
static int kern(lg_env *env, lg_reduced *rf, const form *F, int fid, const dofmap *dm, int param, lg_form_kernels **out) {
  *out = NULL;
  if (param >= 0) {
    int u = lg_form_uses_param(env, F, param);
    if (u < 0) { lg_seterr(env, "%s", expr_error(env->c)); return 1; }
    if (!u) return 0;
    form *dF = lg_form_param_derivative(env, F, param);
    if (!dF) { lg_seterr(env, "%s", expr_error(env->c)); return 1; }
    *out = lg_form_kernels_new(env, rf->lm, dF, -1, NULL);
    form_free(dF);
    return !*out;
  }
  if (!lg_form_uses(env, F, fid)) return 0;
  return !(*out = lg_form_kernels_new(env, rf->lm, F, fid, dm));
}

/* a form's kernels with respect to the controls: ctl[i] (the control), cp[i] (a per-step
 * companion); initial states only with ic_too */
static int control_kernels(lg_env *env, lg_reduced *rf, const form *F, int ic_too, lg_form_kernels **ctl, lg_form_kernels **cp) {
  lg_time_rf *R = rf->tm;
  for (int i = 0; i < rf->nc; i++) {
    const lg_control *c = &rf->c[i];
    if (R->ic[i] >= 0 && !ic_too) continue;
    if (kern(env, rf, F, c->kind == LG_CONTROL_FIELD ? c->f->fid : -1, c->kind == LG_CONTROL_FIELD ? c->f->dm : NULL,
             c->kind == LG_CONTROL_PARAM ? c->param : -1, &ctl[i]))
      return 1;
    if (cp && c->kind == LG_CONTROL_FIELD && R->ps[i] && c->fprev && kern(env, rf, F, c->fprev->fid, c->fprev->dm, -1, &cp[i])) return 1;
  }
  return 0;
}

static void hess_free(lg_reduced *rf) {
  struct tm_hess *H = rf->tm->hs;
  if (!H) return;
  lg_env *env = rf->env;
#define KF(k) lg_form_kernels_free(k)
  for (int a = 0; a < KER_MAXFIELD; a++) {
    KF(H->tan[a]); KF(H->ld_u[a]);
    for (int j = 0; j < LG_TIME_MAXLEV; j++) { KF(H->ld_P[j][a]); KF(H->g_P[j][a]); }
    for (int t = 0; t < LG_TIME_MAXTERMS; t++) KF(H->jd_u[t][a]);
  }
  for (int i = 0; i < LG_MAXCONTROL; i++) {
    KF(H->ld_m[i]); KF(H->ld_p[i]); KF(H->g_m[i]); KF(H->g_p[i]);
    for (int t = 0; t < LG_TIME_MAXTERMS; t++) { KF(H->jd_m[t][i]); KF(H->jd_p[t][i]); }
    free(H->dps[i]);
  }
#undef KF
  lg_function *fs[3 * KER_MAXFIELD + LG_TIME_MAXLEV * KER_MAXFIELD + 2 * LG_MAXCONTROL];
  int nfs = 0;
  for (int a = 0; a < KER_MAXFIELD; a++) { fs[nfs++] = H->du[a]; fs[nfs++] = H->dlam[a]; }
  for (int j = 0; j < LG_TIME_MAXLEV; j++)
    for (int a = 0; a < KER_MAXFIELD; a++) fs[nfs++] = H->dprev[j][a];
  for (int i = 0; i < LG_MAXCONTROL; i++) { fs[nfs++] = H->dmf[i]; fs[nfs++] = H->dfp[i]; }
  for (int k = 0; k < nfs; k++)
    if (fs[k]) {
      expr_func_forget_user(env->c, fs[k]->fid);
      lg_function_free(fs[k]);
    }
  for (int l = 0; l <= LG_TIME_MAXLEV; l++) free(H->pend2[l]);
  free(H->dX0b); free(H->ytmp); free(H->xk); free(H->v);
  free(H);
  rf->tm->hs = NULL;
}

/* a scratch function of the space dm */
static lg_function *scratch(lg_env *env, lg_reduced *rf, const dofmap *dm, const char *name) {
  return lg_function_new(env, rf->lm, (dofmap *)dm, name);
}

/* the stored states made room for their tangents (2 S values each) */
static int grow_states(lg_env *env, lg_time_rf *R) {
  size_t bytes = sizeof(double) * (2 * (size_t)R->S + 1);
  double **bufs[3] = {R->all, &R->held, &R->work};
  int counts[3] = {R->all ? R->N + 1 : 0, R->held ? 1 : 0, R->work ? 1 : 0};
  for (int b = 0; b < 3; b++)
    for (int k = 0; k < counts[b]; k++) {
      double *n = realloc(bufs[b][k], bytes);
      if (!n) { lg_seterr(env, "out of memory for the states' tangents (Hessian actions)"); return 1; }
      bufs[b][k] = n;
    }
  if (R->ck && lg_ckstore_resize(env, R->ck, 2 * (size_t)R->S)) return 1;
  R->grown = 1;
  return 0;
}

static int hess_setup(lg_env *env, lg_reduced *rf) {
  lg_time_rf *R = rf->tm;
  if (R->hs) return 0;
  struct tm_hess *H = R->hs = calloc(1, sizeof *H);
  if (!H) { lg_seterr(env, "out of memory"); return 1; }
  int N = lg_problem_size(rf->p), rc = 0;
  for (int a = 0; a < rf->nf && !rc; a++) {
    rc |= !(H->du[a] = scratch(env, rf, rf->fld[a].dm, "du")) || !(H->dlam[a] = scratch(env, rf, rf->fld[a].dm, "dlambda"));
    for (int j = 0; j < R->nlev && !rc; j++) rc |= !(H->dprev[j][a] = scratch(env, rf, rf->fld[a].dm, "dprev"));
  }
  for (int i = 0; i < rf->nc && !rc; i++) {
    const lg_control *c = &rf->c[i];
    if (R->ic[i] >= 0) continue;
    if (c->kind == LG_CONTROL_PARAM) rc |= (H->dpar[i] = expr_param_new(env->c, "dm", 0)) < 0;
    else {
      rc |= !(H->dmf[i] = scratch(env, rf, c->f->dm, "dm"));
      if (!rc && R->ps[i]) rc |= !(H->dps[i] = malloc(sizeof(double) * (size_t)c->f->dm->ndof * ((size_t)R->N + 1) + 8));
      if (!rc && R->ps[i] && c->fprev) rc |= !(H->dfp[i] = scratch(env, rf, c->f->dm, "dm_prev"));
    }
  }
  for (int l = 0; l <= R->nlev && !rc; l++) rc |= !(H->pend2[l] = malloc(sizeof(double) * ((size_t)N + 1)));
  if (!rc) rc = !(H->dX0b = malloc(sizeof(double) * ((size_t)R->S + 1))) || !(H->ytmp = malloc(sizeof(double) * ((size_t)R->S + 1))) ||
                !(H->xk = malloc(sizeof(double) * ((size_t)R->S + 1))) || !(H->v = malloc(sizeof(double) * ((size_t)N + 1)));
  if (rc) { if (!env->err[0]) lg_seterr(env, "out of memory"); hess_free(rf); return 1; }
  const form *F = lg_problem_equation(rf->p);
  form *T = hess_form(env, rf, F, 0), *DL = hess_form(env, rf, rf->L, 1), *G = hess_form(env, rf, F, 2);
  rc = !T || !DL || !G;
  for (int a = 0; a < rf->nf && !rc; a++) {
    rc = kern(env, rf, T, rf->fld[a].test, rf->fld[a].dm, -1, &H->tan[a]) || kern(env, rf, DL, rf->fld[a].unknown, rf->fld[a].dm, -1, &H->ld_u[a]);
    if (!rc && !H->tan[a]) rc = !(H->tan[a] = lg_form_kernels_new(env, rf->lm, T, rf->fld[a].test, rf->fld[a].dm)); /* zero, but evaluated */
    if (!rc && !H->ld_u[a]) rc = !(H->ld_u[a] = lg_form_kernels_new(env, rf->lm, DL, rf->fld[a].unknown, rf->fld[a].dm));
    for (int j = 0; j < R->nlev && !rc; j++) {
      lg_function *pf = lg_time_previous(R->T, j, a);
      rc = kern(env, rf, DL, pf->fid, pf->dm, -1, &H->ld_P[j][a]) || kern(env, rf, G, pf->fid, pf->dm, -1, &H->g_P[j][a]);
    }
  }
  if (!rc) rc = control_kernels(env, rf, DL, 0, H->ld_m, H->ld_p) || control_kernels(env, rf, G, 0, H->g_m, H->g_p);
  for (int t = 0; t < R->nterm && !rc; t++) {
    form *DJ = hess_form(env, rf, R->t[t].J, 1);
    rc = !DJ;
    for (int a = 0; a < rf->nf && !rc; a++) rc = kern(env, rf, DJ, rf->fld[a].unknown, rf->fld[a].dm, -1, &H->jd_u[t][a]);
    if (!rc) rc = control_kernels(env, rf, DJ, R->t[t].kind == LG_TJ_INITIAL, H->jd_m[t], H->jd_p[t]);
    form_free(DJ);
  }
  form_free(T);
  form_free(DL);
  form_free(G);
  if (!rc && !R->grown) rc = grow_states(env, R);
  if (rc) { hess_free(rf); return 1; }
  return 0;
}

/* the directions dm: fields and parameters, per-step blocks, initial states as dX_0 */
static void set_directions(lg_env *env, lg_reduced *rf, double **dm) {
  lg_time_rf *R = rf->tm;
  struct tm_hess *H = R->hs;
  for (int j = 0; j < R->nlev; j++)
    for (int a = 0; a < rf->nf; a++) memset(H->dprev[j][a]->x, 0, sizeof(double) * (size_t)rf->fld[a].dm->ndof);
  for (int i = 0; i < rf->nc; i++) {
    int n = lg_reduced_control_size(rf, i);
    if (R->ic[i] >= 0) {
      lg_function *f = H->dprev[R->ic[i] / KER_MAXFIELD][R->ic[i] % KER_MAXFIELD];
      memcpy(f->x, dm[i], sizeof(double) * (size_t)f->dm->ndof);
    } else if (rf->c[i].kind == LG_CONTROL_PARAM) expr_param_values(env->c)[H->dpar[i]] = dm[i][0];
    else if (H->dps[i]) memcpy(H->dps[i], dm[i], sizeof(double) * (size_t)n);
    else memcpy(H->dmf[i]->x, dm[i], sizeof(double) * (size_t)n);
  }
}

/* the tangent-linear march along dm, level 0's tangent handed to rec at every step */
int lg_time_sensitivity(lg_env *env, lg_reduced *rf, double **dm, lg_time_tangent_cb rec, void *ud) {
  lg_time_rf *R = rf->tm;
  if (!R) { lg_seterr(env, "internal error: a sensitivity of a steady reduced functional"); return 1; }
  if (hess_setup(env, rf)) return 1;
  struct tm_hess *H = R->hs;
  set_directions(env, rf, dm);
  if (lg_time_begin(env, R->T)) return 1;
  H->on = 1;
  sweep_begin(rf);
  lg_time_prepare(env, R->T, 0);
  set_step_controls(rf, 0);
  double *du[KER_MAXFIELD];
  for (int a = 0; a < rf->nf; a++) du[a] = H->dprev[0][a]->x;
  rec(ud, 0, (const double *const *)du);
  int rc = 0;
  for (int k = 1; k <= R->N && !rc; k++) {
    if (!(rc = full_step(env, rf, k))) rec(ud, k, (const double *const *)du);
    monitor_line(R, k, "tangent");
  }
  sweep_end(rf);
  H->on = 0;
  lg_time_end(env, R->T);
  return rc;
}

int lg_time_hessian(lg_env *env, lg_reduced *rf, double **dm, double **out) {
  lg_time_rf *R = rf->tm;
  if (lg_reduced_bc_affine(env, rf) || hess_setup(env, rf)) return 1;
  struct tm_hess *H = R->hs;
  int N = lg_problem_size(rf->p);
  set_directions(env, rf, dm);
  for (int i = 0; i < rf->nc; i++) memset(out[i], 0, sizeof(double) * (size_t)lg_reduced_control_size(rf, i));
  for (int l = 0; l <= R->nlev; l++) memset(H->pend2[l], 0, sizeof(double) * (size_t)N);
  memset(H->dX0b, 0, sizeof(double) * (size_t)R->S);
  H->h = out;
  double *g[LG_MAXCONTROL] = {NULL};
  int rc = 0;
  for (int i = 0; i < rf->nc && !rc; i++) rc = !(g[i] = malloc(sizeof(double) * ((size_t)lg_reduced_control_size(rf, i) + 1)));
  if (rc) lg_seterr(env, "out of memory");
  H->on = 1;
  R->SY = 2 * R->S;
  if (!rc) rc = march(env, rf) || backward(env, rf, g);
  H->on = 0;
  R->SY = R->S;
  R->fresh = 0; /* the stored states held tangents: the next value marches again */
  for (int i = 0; i < rf->nc; i++) free(g[i]);
  if (!rc) add_initial(rf, H->dX0b, out); /* the initial states' part */
  for (int i = 0; i < rf->nc && !rc; i++) rc = lg_reduced_dirichlet_ghosts(env, rf, i, out[i]);
  return rc;
}

/* ---------------------------------------------------------------- construction */

void lg_time_rf_free(lg_reduced *rf) {
  lg_time_rf *R = rf->tm;
  if (!R) return;
  hess_free(rf);
  for (int i = 0; i < R->nterm; i++) {
    form_free(R->t[i].J);
    lg_form_kernels_free(R->t[i].val);
    for (int a = 0; a < KER_MAXFIELD; a++) lg_form_kernels_free(R->t[i].dJdu[a]);
    for (int c = 0; c < LG_MAXCONTROL; c++) lg_form_kernels_free(R->t[i].dJdm[c]);
  }
  for (int j = 0; j < LG_TIME_MAXLEV; j++)
    for (int a = 0; a < KER_MAXFIELD; a++) lg_form_kernels_free(R->dLdprev[j][a]);
  if (R->all)
    for (int k = 0; k <= R->N; k++) free(R->all[k]);
  lg_ckstore_free(R->ck);
  free(R->all); free(R->held); free(R->work);
  free(R->u); free(R->rhs); free(R->tmp); free(R->dX0);
  for (int l = 0; l <= LG_TIME_MAXLEV; l++) free(R->pend[l]);
  for (int i = 0; i < LG_MAXCONTROL; i++) {
    free(R->ps[i]);
    free(R->ps_keep[i][0]);
    free(R->ps_keep[i][1]);
    lg_form_kernels_free(R->dLdp[i]);
    for (int t = 0; t < R->nterm; t++) lg_form_kernels_free(R->t[t].dJdp[i]);
  }
  free(R);
  rf->tm = NULL;
}

/* the functional's terms: checked, copied, their kernels; every control used somewhere */
static int setup_terms(lg_env *env, lg_reduced *rf, int nterm, const lg_time_term *terms) {
  lg_time_rf *R = rf->tm;
  if (nterm < 0 || nterm > LG_TIME_MAXTERMS) { /* 0: for sensitivities (j = 0) */
    lg_seterr(env, "a time-dependent functional has 1 to %d terms (got %d)", LG_TIME_MAXTERMS, nterm);
    return 1;
  }
  for (int i = 0; i < nterm; i++) {
    tj_term *t = &R->t[R->nterm];
    t->kind = terms[i].kind;
    if (t->kind == LG_TJ_AT) {
      long k = -1; /* the step whose time it is, to 1e-9 of a step */
      for (int j = 0; j <= R->N && k < 0; j++) {
        double h = lg_time_step_size(R->T, j > 0 ? j : 1);
        if (fabs(terms[i].at - lg_time_at(R->T, j)) <= 1e-9 * h * (1 + j)) k = j;
      }
      if (k < 0) {
        lg_seterr(env, "an observation at t = %.9g is not at a step's time (t_k, k = 0 .. %d)", terms[i].at, R->N);
        return 1;
      }
      t->atk = (int)k;
    }
    if (!(t->J = form_copy(terms[i].J))) { lg_seterr(env, "out of memory"); return 1; }
    R->nterm++;
    if (lg_functional_check(env, rf, t->J)) return 1;
    /* the previous states are the march's: a functional reads the unknowns (u^k); only an
     * initial term reads them (their initial values, as the unknowns' there) */
    for (int j = 0; j < R->nlev && t->kind != LG_TJ_INITIAL; j++)
      for (int a = 0; a < rf->nf; a++)
        if (lg_form_uses(env, t->J, lg_time_previous(R->T, j, a)->fid)) {
          lg_seterr(env, "the functional reads a previous state of the problem (%s): write it in the unknowns, whose value "
                         "at each step the functional's terms take", expr_func_get(env->c, lg_time_previous(R->T, j, a)->fid)->name);
          return 1;
        }
    if (lg_functional_kernels(env, rf, t->J, t->kind == LG_TJ_INITIAL ? NULL : R->skip_ic, &t->val, t->dJdu, t->dJdm)) return 1;
  }
  return 0;
}

lg_reduced *lg_reduced_new_time(lg_env *env, lg_time *T, int nterm, const lg_time_term *terms, int nc, const lg_control *c,
                                const lg_checkpoints *ck, int monitor) {
  if (lg_time_adaptive(T)) {
    lg_seterr(env, "the problem's step sizes are adaptive (dt a function): an adjoint, a Hessian or a sensitivity replays the "
                   "steps at fixed times; give dt a number (or march adaptively first and use the step sizes it chose)");
    return NULL;
  }
  lg_reduced *rf = calloc(1, sizeof *rf);
  lg_time_rf *R = calloc(1, sizeof *R);
  if (!rf || !R) { free(rf); free(R); lg_seterr(env, "out of memory"); return NULL; }
  rf->tm = R;
  R->T = T;
  R->nlev = lg_time_levels(T);
  R->N = lg_time_nsteps(T);
  R->S = R->SY = lg_time_state_size(T);
  R->monitor = monitor;
  lg_problem *p = lg_time_step_problem(T);
  int nf0 = lg_problem_fields(p, rf->fld);
  /* the initial states among the controls: not differentiated as fields of the step */
  for (int i = 0; i < nc && i < LG_MAXCONTROL; i++) {
    R->ic[i] = -1;
    for (int j = 0; j < R->nlev; j++)
      for (int a = 0; a < nf0; a++)
        if (c[i].kind == LG_CONTROL_FIELD && c[i].f == lg_time_previous(T, j, a)) R->ic[i] = j * KER_MAXFIELD + a;
  }
  int skip[LG_MAXCONTROL] = {0};
  for (int i = 0; i < nc && i < LG_MAXCONTROL; i++) skip[i] = R->ic[i] >= 0;
  R->skip_ic = skip; /* for the terms' kernels (setup_terms), during construction */
  if (lg_reduced_setup(env, rf, p, nc, c, skip)) goto fail;
  /* per-step controls: every step's value the function's, to start */
  for (int i = 0; i < nc; i++) {
    if (!c[i].per_step) continue;
    if (c[i].kind != LG_CONTROL_FIELD || R->ic[i] >= 0) {
      lg_seterr(env, "control %d: a value per step is for a field the step reads (not a parameter or an initial state)", i + 1);
      goto fail;
    }
    int nd = c[i].f->dm->ndof;
    R->ps[i] = malloc(sizeof(double) * (size_t)nd * ((size_t)R->N + 1) + 8);
    R->ps_keep[i][0] = malloc(sizeof(double) * (size_t)nd + 8);
    R->ps_keep[i][1] = malloc(sizeof(double) * (size_t)nd + 8);
    if (!R->ps[i] || !R->ps_keep[i][0] || !R->ps_keep[i][1]) { lg_seterr(env, "out of memory for control %d's values per step", i + 1); goto fail; }
    for (int k = 0; k <= R->N; k++) memcpy(R->ps[i] + (size_t)k * (size_t)nd, c[i].f->x, sizeof(double) * (size_t)nd);
  }
  for (int i = 0; i < nc; i++)
    if (R->ic[i] >= 0 && rf->bcdep[i]) {
      lg_seterr(env, "control %d, an initial state, appears in an essential condition of the step", i + 1);
      goto fail;
    }
  if (setup_terms(env, rf, nterm, terms)) goto fail;
  /* a per-step control's companion (its value at the step before): the step's and the
   * terms' derivatives with respect to it */
  for (int i = 0; i < nc; i++) {
    lg_function *fp = R->ps[i] ? c[i].fprev : NULL;
    if (!fp) continue;
    if (lg_form_uses(env, lg_problem_equation(p), fp->fid) && !(R->dLdp[i] = lg_form_kernels_new(env, rf->lm, rf->L, fp->fid, fp->dm)))
      goto fail;
    for (int t = 0; t < R->nterm; t++)
      if (lg_form_uses(env, R->t[t].J, fp->fid) && !(R->t[t].dJdp[i] = lg_form_kernels_new(env, rf->lm, R->t[t].J, fp->fid, fp->dm)))
        goto fail;
  }
  /* every control used: in the step, a term, or an essential condition; an initial state
   * in the step */
  const form *F = lg_problem_equation(p);
  for (int i = 0; i < nc; i++) {
    int used = rf->bcdep[i] != 0, fid = c[i].kind == LG_CONTROL_FIELD ? c[i].f->fid : -1;
    for (int t = -1; t < R->nterm && !used; t++) {
      const form *G = t < 0 ? F : R->t[t].J;
      int u = fid >= 0 ? lg_form_uses(env, G, fid) : lg_form_uses_param(env, G, c[i].param);
      if (u < 0) { lg_seterr(env, "%s", expr_error(env->c)); goto fail; }
      used = u;
    }
    if (!used) {
      lg_seterr(env, "control %d appears in neither the step nor the functional", i + 1);
      goto fail;
    }
  }
  /* lam^T dR/d prev: the step's form with its tests replaced by the adjoint, differentiated
   * with respect to each previous function it reads */
  for (int j = 0; j < R->nlev; j++)
    for (int a = 0; a < rf->nf; a++) {
      lg_function *f = lg_time_previous(T, j, a);
      if (!lg_form_uses(env, F, f->fid)) continue;
      if (!(R->dLdprev[j][a] = lg_form_kernels_new(env, rf->lm, rf->L, f->fid, f->dm))) goto fail;
    }
  /* the states */
  int N = lg_problem_size(p), mx = 0;
  for (int a = 0; a < rf->nf; a++) mx = rf->fld[a].dm->ndof > mx ? rf->fld[a].dm->ndof : mx;
  R->u = malloc(sizeof(double) * ((size_t)N + 1));
  R->rhs = malloc(sizeof(double) * ((size_t)N + 1));
  R->tmp = malloc(sizeof(double) * ((size_t)(mx > N ? mx : N) + 8));
  R->dX0 = malloc(sizeof(double) * ((size_t)R->S + 1));
  int bad = !R->u || !R->rhs || !R->tmp || !R->dX0;
  for (int l = 0; l <= R->nlev; l++) bad |= !(R->pend[l] = malloc(sizeof(double) * ((size_t)N + 1)));
  int ram = ck ? ck->ram : 0, disk = ck ? ck->disk : 0;
  if (ram + disk > 0 && ram + disk < R->N + 1) {
    R->snaps = ram + disk;
    R->ram = ram;
    R->held = malloc(sizeof(double) * ((size_t)R->S + 1));
    R->work = malloc(sizeof(double) * ((size_t)R->S + 1));
    bad |= !R->held || !R->work;
    if (!bad && !(R->ck = lg_ckstore_new(env, ram, disk, ck->dir, (size_t)R->S))) goto fail;
  } else if (nterm > 0) { /* (made for sensitivities, it stores no state) */
    R->all = calloc((size_t)R->N + 1, sizeof(double *));
    bad |= !R->all;
    for (int k = 0; !bad && k <= R->N; k++) bad |= !(R->all[k] = malloc(sizeof(double) * ((size_t)R->S + 1)));
  }
  if (bad) {
    lg_seterr(env, "out of memory for the states of %d steps (%d values each): use fewer checkpoints", R->N, R->S);
    goto fail;
  }
  return rf;
fail:
  lg_reduced_free(rf);
  return NULL;
}
