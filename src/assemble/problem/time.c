/* time.c — time-dependent problems: a step problem R(u_{n+1}; u_n[, u_{n-1}], t_{n+1}) = 0,
 * written by the user with the previous states as discrete functions ("previous"), marched
 * from t0 by steps of dt. Each step sets the time parameter to the step's new time, lets a
 * hook set what changes from step to step (per-step controls, the script's before_step),
 * solves the step problem from the last state, and shifts the previous states. The state
 * X_n of the march is the previous functions' values after step n (levels 0, 1 of every
 * field): what a checkpoint holds and what step n + 1 reads. A march leaves the previous
 * functions and the time parameter as it found them. */
#include "problem_int.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

struct lg_time {
  lg_problem *p;
  int nf, nlev;
  lg_function *prev[LG_TIME_MAXLEV][KER_MAXFIELD];
  int off[KER_MAXFIELD], ndof[KER_MAXFIELD]; /* each field's place in the problem's arrays */
  int tparam, dtparam, tprevparam;           /* the time, step-size and step-start parameters, or -1 */
  double t0, dt;
  double *times;                             /* t_0 .. t_N for steps of given sizes (then their sizes from times[N + 1]), or NULL */
  int nsteps, adaptive;
  lg_time_hook hook, chook;                  /* the script's (before_step), a reduced functional's (controls) */
  void *hook_ud, *chook_ud;
  long steps;                                /* steps solved since it was made */
  int marching;                              /* between lg_time_begin and lg_time_end */
  double *x0, tsave, dtsave;                 /* what a march found, restored at its end */
};

lg_time *lg_time_new(lg_env *env, const lg_time_spec *s) {
  lg_problem *p = s->step;
  if (s->nlev < 1 || s->nlev > LG_TIME_MAXLEV) {
    lg_seterr(env, "a time-dependent problem reads 1 or %d previous states (got %d)", LG_TIME_MAXLEV, s->nlev);
    return NULL;
  }
  if (!(s->dt > 0) || !isfinite(s->dt) || !isfinite(s->t0)) {
    lg_seterr(env, "the time step must be a positive finite number and t0 finite (dt = %g, t0 = %g)", s->dt, s->t0);
    return NULL;
  }
  if (s->nsteps < 1 && !s->adaptive) { lg_seterr(env, "a time-dependent problem takes at least one step (got %d)", s->nsteps); return NULL; }
  lg_time *T = calloc(1, sizeof *T);
  if (!T) { lg_seterr(env, "out of memory"); return NULL; }
  T->p = p;
  lg_field_info fi[KER_MAXFIELD];
  T->nf = lg_problem_fields(p, fi);
  T->nlev = s->nlev;
  for (int j = 0; j < s->nlev; j++)
    for (int a = 0; a < T->nf; a++) {
      lg_function *f = s->prev[j][a];
      expr_func_info *u = expr_func_get(env->c, fi[a].unknown);
      if (!f || f->dm != fi[a].dm) {
        lg_seterr(env, "previous state %d of the unknown %s must be a discrete function of the unknown's space (degree %d, "
                       "%d component%s) on the step's mesh", j + 1, u ? u->name : "?", fi[a].dm->degree, fi[a].dm->bs,
                  fi[a].dm->bs == 1 ? "" : "s");
        free(T);
        return NULL;
      }
      for (int jj = 0; jj <= j; jj++)
        for (int b = 0; b < (jj == j ? a : T->nf); b++)
          if (s->prev[jj][b] == f) {
            lg_seterr(env, "the same discrete function is given as two previous states (each must be its own function)");
            free(T);
            return NULL;
          }
      T->prev[j][a] = f;
    }
  for (int a = 0; a < T->nf; a++) {
    T->off[a] = fi[a].offset;
    T->ndof[a] = fi[a].dm->ndof;
  }
  T->tparam = s->time_param;
  T->dtparam = s->dt_param;
  T->tprevparam = s->tprev_param;
  T->t0 = s->t0;
  T->dt = s->dt;
  T->nsteps = s->adaptive ? 0 : s->nsteps;
  T->adaptive = s->adaptive;
  if (s->dts && !s->adaptive) {
    if (!(T->times = malloc(sizeof(double) * (2 * (size_t)s->nsteps + 1)))) { free(T); lg_seterr(env, "out of memory"); return NULL; }
    memcpy(T->times + s->nsteps + 1, s->dts, sizeof(double) * (size_t)s->nsteps); /* the sizes as given: the step-size parameter's bits */
    T->times[0] = s->t0;
    for (int k = 1; k <= s->nsteps; k++) {
      double h = s->dts[k - 1];
      if (!(h > 0) || !isfinite(h)) {
        lg_seterr(env, "step size %d must be a positive finite number (got %g)", k, h);
        free(T->times);
        free(T);
        return NULL;
      }
      T->times[k] = T->times[k - 1] + h;
    }
    T->dt = s->dts[0];
  }
  if (!(T->x0 = malloc(sizeof(double) * ((size_t)lg_time_state_size(T) + 1)))) {
    free(T->times);
    free(T);
    lg_seterr(env, "out of memory");
    return NULL;
  }
  /* replayed steps (checkpointing) must give the bits of the first march */
  lg_problem_replayable(p);
  return T;
}

void lg_time_free(lg_time *T) {
  if (!T) return;
  free(T->times);
  free(T->x0);
  free(T);
}

void lg_time_set_hook(lg_time *T, lg_time_hook hook, void *ud) {
  T->hook = hook;
  T->hook_ud = ud;
}

void lg_time_set_control_hook(lg_time *T, lg_time_hook hook, void *ud) {
  T->chook = hook;
  T->chook_ud = ud;
}

lg_problem *lg_time_step_problem(const lg_time *T) { return T->p; }
int lg_time_levels(const lg_time *T) { return T->nlev; }
int lg_time_nsteps(const lg_time *T) { return T->nsteps; }
double lg_time_at(const lg_time *T, int k) { return T->times ? T->times[k] : T->t0 + k * T->dt; }
double lg_time_step_size(const lg_time *T, int k) { return T->times ? T->times[T->nsteps + k] : T->dt; }
long lg_time_steps_solved(const lg_time *T) { return T->steps; }
int lg_time_adaptive(const lg_time *T) { return T->adaptive; }
lg_function *lg_time_previous(const lg_time *T, int lev, int field) { return T->prev[lev][field]; }

int lg_time_state_size(const lg_time *T) {
  int n = 0;
  for (int a = 0; a < T->nf; a++) n += T->ndof[a];
  return n * T->nlev;
}

void lg_time_get_state(const lg_time *T, double *X) {
  for (int j = 0; j < T->nlev; j++)
    for (int a = 0; a < T->nf; a++) {
      memcpy(X, T->prev[j][a]->x, sizeof(double) * (size_t)T->ndof[a]);
      X += T->ndof[a];
    }
}

void lg_time_set_state(lg_time *T, const double *X) {
  for (int j = 0; j < T->nlev; j++)
    for (int a = 0; a < T->nf; a++) {
      memcpy(T->prev[j][a]->x, X, sizeof(double) * (size_t)T->ndof[a]);
      X += T->ndof[a];
    }
}

void lg_time_unknowns(const lg_time *T, const double *X, double *u) {
  for (int a = 0; a < T->nf; a++) {
    memcpy(u + T->off[a], X, sizeof(double) * (size_t)T->ndof[a]);
    X += T->ndof[a];
  }
}

int lg_time_begin(lg_env *env, lg_time *T) {
  if (T->marching) { lg_seterr(env, "the time-dependent problem is already marching (a before_step that solves it?)"); return 1; }
  lg_time_get_state(T, T->x0);
  T->tsave = T->tparam >= 0 ? expr_param_values(env->c)[T->tparam] : 0;
  T->dtsave = T->dtparam >= 0 ? expr_param_values(env->c)[T->dtparam] : 0;
  T->marching = 1;
  return 0;
}

void lg_time_end(lg_env *env, lg_time *T) {
  if (!T->marching) return;
  lg_time_set_state(T, T->x0);
  if (T->tparam >= 0) expr_param_values(env->c)[T->tparam] = T->tsave;
  if (T->dtparam >= 0) expr_param_values(env->c)[T->dtparam] = T->dtsave;
  T->marching = 0;
}

static int prepare_at(lg_env *env, lg_time *T, int k, double t, double dt) {
  if (T->tparam >= 0) expr_param_values(env->c)[T->tparam] = t;
  if (T->dtparam >= 0) expr_param_values(env->c)[T->dtparam] = dt;
  if (T->tprevparam >= 0) expr_param_values(env->c)[T->tprevparam] = k >= 1 ? t - dt : t;
  if (k < 1) return 0;
  if (T->hook && T->hook(env, T->hook_ud, k, t)) return 1;
  return T->chook && T->chook(env, T->chook_ud, k, t);
}

int lg_time_prepare(lg_env *env, lg_time *T, int k) {
  return prepare_at(env, T, k, lg_time_at(T, k), k >= 1 ? lg_time_step_size(T, k) : T->dt);
}

int lg_time_step(lg_env *env, lg_time *T, int k, lg_solve_info *info) {
  return lg_time_step_at(env, T, k, lg_time_at(T, k), lg_time_step_size(T, k), info);
}

int lg_time_step_at(lg_env *env, lg_time *T, int k, double t, double dt, lg_solve_info *info) {
  if (prepare_at(env, T, k, t, dt)) return 1;
  lg_problem *p = T->p;
  if (lg_problem_solve(env, p, T->prev[0], NULL, info)) {
    char why[LG_ERRLEN];
    snprintf(why, sizeof why, "%s", env->err);
    lg_seterr(env, "step %d (t = %.6g, dt = %.6g): %s", k, t, dt, why);
    return 2;
  }
  T->steps++;
  const double *u = lg_problem_solution(p);
  for (int j = T->nlev - 1; j > 0; j--)
    for (int a = 0; a < T->nf; a++) memcpy(T->prev[j][a]->x, T->prev[j - 1][a]->x, sizeof(double) * (size_t)T->ndof[a]);
  for (int a = 0; a < T->nf; a++) memcpy(T->prev[0][a]->x, u + T->off[a], sizeof(double) * (size_t)T->ndof[a]);
  return 0;
}
