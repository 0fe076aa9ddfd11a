/* optimize_int.h — internal to src/assemble/optimize: the reduced functional's state, shared
 * by functional.c (steady problems, and what every reduced functional has) and
 * time_adjoint.c (time-dependent problems: the march, its checkpoints and the backward
 * sweep). The room's interface is optimize.h. */
#ifndef LUGAL_OPTIMIZE_INT_H
#define LUGAL_OPTIMIZE_INT_H

#include "checkpoint.h"
#include "optimize.h"

typedef struct lg_time_rf lg_time_rf;

struct lg_reduced {
  lg_env *env;
  lg_problem *p;
  lg_mesh *lm;
  form *J;
  int nc;
  lg_control c[LG_MAXCONTROL];
  int nf;
  lg_field_info fld[KER_MAXFIELD];
  lg_function *lam[KER_MAXFIELD];   /* the adjoint, one discrete function per state field */
  form *L;                          /* the equation with its tests replaced by the adjoint */
  lg_form_kernels *Jval, *dJdu[KER_MAXFIELD], *dJdm[LG_MAXCONTROL], *dLdm[LG_MAXCONTROL];
  lg_problem *riesz[LG_MAXCONTROL][2]; /* L2 and H1 Gram matrices of field controls */
  double *rhs, *lamv, *lamz;       /* lamz: lamv with the essential rows zero (lg_reduced_set_adjoint) */
  int solved;                       /* the state is the one of the current controls */
  int bcdep[LG_MAXCONTROL];         /* Dirichlet controls: in the essential values (1 affine, 2 not) */
  int grad_fresh;                   /* the adjoint is the one of the current state */
  /* Hessian actions (built on first use): directions, tangent, second-order adjoint */
  int hess_ready;
  lg_function *dmf[LG_MAXCONTROL];  /* the direction of a field control */
  int dpar[LG_MAXCONTROL];          /* the direction of a parameter control: a scratch parameter */
  lg_function *du[KER_MAXFIELD], *dlam[KER_MAXFIELD];
  lg_form_kernels *tan_rhs[KER_MAXFIELD], *soa_rhs[KER_MAXFIELD], *hD[LG_MAXCONTROL], *hG[LG_MAXCONTROL];
  lg_time_rf *tm;                   /* a time-dependent problem's (time_adjoint.c), or NULL */
};

/* functional.c: does F use the function func (or its '-' side restriction) / the
 * parameter param (1, 0; -1 on error) */
int lg_form_uses(lg_env *env, const form *F, int func);
int lg_form_uses_param(lg_env *env, const form *F, int param);
/* a form with each integrand replaced by its derivative with respect to a parameter */
form *lg_form_param_derivative(lg_env *env, const form *F, int param);
/* the state problem's part of a reduced functional: its fields, the controls (checked
 * against the essential conditions), the adjoint functions and the equation with its tests
 * replaced by them (rf->L), the kernels of lam^T dR/dm (dLdm; none for the controls marked
 * in skip) */
int lg_reduced_setup(lg_env *env, lg_reduced *rf, lg_problem *p, int nc, const lg_control *c, const int *skip);
/* a functional's checks (a number of the state's unknowns and the controls) and its kernels:
 * the value, dJ/du per field, dJ/dm per control (NULL for the controls marked in skip) */
int lg_functional_check(lg_env *env, lg_reduced *rf, const form *J);
int lg_functional_kernels(lg_env *env, lg_reduced *rf, const form *J, const int *skip, lg_form_kernels **val,
                          lg_form_kernels **dJdu, lg_form_kernels **dJdm);
/* the derivatives of the essential values for control i: out += s (dg/dm)^T w; and on a
 * distributed mesh a Dirichlet control's derivative completed on the ghost dofs */
int lg_reduced_bc_transpose(lg_env *env, lg_reduced *rf, int i, const double *w, double s, double *out);
int lg_reduced_dirichlet_ghosts(lg_env *env, lg_reduced *rf, int i, double *v);
/* out += (dg/dm_i) dm on the essential rows (a Dirichlet control's tangent there); whether
 * every essential value is affine in the controls (0; 1 with a message naming them) */
int lg_reduced_bc_action(lg_env *env, lg_reduced *rf, int i, const double *dm, double *out);
int lg_reduced_bc_affine(lg_env *env, lg_reduced *rf);
/* lam (N values) into the adjoint functions rf->lam with the essential rows zero (the
 * equation's test space: lam^T dR/dm does not see the rows u_i - g_i) */
int lg_reduced_set_adjoint(lg_env *env, lg_reduced *rf, const double *lam);

/* time_adjoint.c: the value and gradient of a time-dependent reduced functional, and what
 * it frees */
int lg_time_value(lg_env *env, lg_reduced *rf, double *J);
int lg_time_gradient(lg_env *env, lg_reduced *rf, double **g);
int lg_time_hessian(lg_env *env, lg_reduced *rf, double **dm, double **out);
void lg_time_rf_free(lg_reduced *rf);
/* a per-step control's values (N + 1 blocks), and the number of blocks (N + 1; 1 for a
 * steady reduced functional) */
double *lg_time_rf_steps(lg_reduced *rf, int i);
int lg_time_rf_blocks(const lg_reduced *rf);
lg_time *lg_time_rf_time(const lg_reduced *rf);


#endif
