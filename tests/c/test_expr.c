/* test_expr.c — the symbolic engine: canonical forms of simplification (hash-consing
 * makes equal expressions the same pointer), derivatives against finite differences at
 * random points, spatial derivatives pushed to the leaves, shape errors, and the
 * linearization of a form into coefficient tables. */
#include "../../src/expr/expr.h"
#include "check.h"

#include <stdlib.h>
#include <string.h>

static expr_ctx *C;
static double vals[8]; /* values of the FIELD leaves u, w (by function id) and coords */

static int leaf(void *ud, const expr *e, double *v) {
  (void)ud;
  if (e->kind == E_COORD) { *v = vals[4 + e->i0]; return 0; }
  if (e->kind == E_FIELD && e->order == 0) { *v = vals[e->i0]; return 0; }
  return 1;
}

static double eval(expr *e) {
  expr_tape t;
  if (expr_tape_build(C, 1, &e, &t)) return NAN;
  double *w = malloc(sizeof(double) * (size_t)(t.n + 1)), out = NAN;
  if (expr_tape_eval(&t, expr_param_values(C), leaf, NULL, w, &out)) out = NAN;
  free(w);
  expr_tape_free(&t);
  return out;
}

static double urand(double a, double b) { return a + (b - a) * rand() / (double)RAND_MAX; }

int main(void) {
  srand(12345);
  C = expr_ctx_new();
  unsigned char z[3] = {0, 0, 0};
  int fu = expr_func_new(C, FK_UNKNOWN, "u", 1, 1, NULL);
  int fw = expr_func_new(C, FK_DISCRETE, "w", 1, 1, NULL);
  int fv = expr_func_new(C, FK_TEST, "v", 1, 1, NULL);
  expr *u = expr_field(C, fu, 0, z), *w = expr_field(C, fw, 0, z), *v = expr_field(C, fv, 0, z);
  expr *x = expr_coord(C, 0), *y = expr_coord(C, 1);
  expr *two = expr_num(C, 2);

  /* canonical forms: structurally equal results are the same node */
  CHECK(expr_add(C, u, w) == expr_add(C, w, u), "u+w != w+u");
  CHECK(expr_mul(C, u, w) == expr_mul(C, w, u), "u*w != w*u");
  CHECK(expr_add(C, u, u) == expr_mul(C, two, u), "u+u != 2u");
  CHECK(expr_mul(C, u, u) == expr_pow(C, u, two), "u*u != u^2");
  CHECK(expr_sub(C, u, u) == expr_num(C, 0), "u-u != 0");
  CHECK(expr_mul(C, u, expr_num(C, 0)) == expr_num(C, 0), "0*u != 0");
  CHECK(expr_mul(C, u, expr_num(C, 1)) == u, "1*u != u");
  CHECK(expr_div(C, u, u) == expr_num(C, 1), "u/u != 1");
  CHECK(expr_add(C, expr_add(C, u, w), x) == expr_add(C, u, expr_add(C, w, x)), "sum not associative");
  CHECK(expr_mul(C, expr_mul(C, u, w), x) == expr_mul(C, u, expr_mul(C, w, x)), "product not associative");
  CHECK(expr_add(C, expr_num(C, 2), expr_num(C, 3)) == expr_num(C, 5), "2+3 != 5");
  CHECK(expr_apply(C, FN_EXP, expr_apply(C, FN_LOG, u)) == u, "exp(log u) != u");
  expr *a = expr_add(C, expr_mul(C, expr_num(C, 3), u), expr_mul(C, expr_num(C, -3), u));
  CHECK(a == expr_num(C, 0), "3u - 3u != 0");
  CHECK(expr_pow(C, expr_pow(C, u, two), expr_num(C, 3)) == expr_pow(C, u, expr_num(C, 6)), "(u^2)^3 != u^6");

  /* degree estimates (quadrature orders) and whether they are exact (a polynomial) */
  {
    int ex;
    expr *d = expr_mul(C, expr_apply(C, FN_SIN, x), expr_apply(C, FN_SIN, y));
    CHECK(expr_degree_exact(C, expr_pow(C, expr_sub(C, u, d), two), 1, &ex) == 12 && !ex, "(u - sin x sin y)^2: degree 12, inexact");
    CHECK(expr_degree_exact(C, expr_mul(C, expr_mul(C, u, w), x), 1, &ex) == 3 && ex, "u w x: degree 3, exact");
    CHECK(expr_degree_exact(C, expr_pow(C, u, expr_num(C, 0.5)), 1, &ex) == 3 && !ex, "u^0.5: inexact");
    CHECK(expr_degree_exact(C, expr_div(C, w, u), 1, &ex) >= 1 && !ex, "w/u: inexact");
    CHECK(expr_degree_exact(C, expr_mul(C, expr_apply(C, FN_SIN, expr_num(C, 2)), u), 1, &ex) == 1 && ex, "sin(2) u: exact");
  }

  /* derivatives against central finite differences at random points */
  expr *fs[8];
  fs[0] = expr_mul(C, expr_apply(C, FN_SIN, expr_mul(C, u, w)), expr_apply(C, FN_EXP, u));
  fs[1] = expr_div(C, expr_pow(C, u, expr_num(C, 3)), expr_add(C, expr_num(C, 2), expr_mul(C, w, w)));
  fs[2] = expr_apply(C, FN_TANH, expr_sub(C, expr_mul(C, u, x), y));
  fs[3] = expr_pow(C, expr_add(C, expr_mul(C, u, u), expr_num(C, 1)), expr_num(C, 0.5));
  fs[4] = expr_apply(C, FN_LOG, expr_add(C, expr_num(C, 3), expr_apply(C, FN_COS, u)));
  fs[5] = expr_pow(C, expr_add(C, expr_num(C, 2), expr_apply(C, FN_SIN, u)), w);
  fs[6] = expr_apply(C, FN_ATAN, expr_mul(C, u, expr_apply(C, FN_SQRT, expr_add(C, w, expr_num(C, 4)))));
  fs[7] = expr_mul(C, expr_apply(C, FN_ABS, expr_sub(C, u, expr_num(C, 5))), expr_apply(C, FN_COSH, u));
  for (int k = 0; k < 8; k++) {
    expr *d = expr_diff(C, fs[k], u);
    CHECK(d != NULL, "derivative %d failed: %s", k, expr_error(C));
    for (int trial = 0; trial < 200 && d; trial++) {
      vals[fu] = urand(-1.5, 1.5);
      vals[fw] = urand(-1.5, 1.5);
      vals[4] = urand(-1, 1);
      vals[5] = urand(-1, 1);
      double h = 1e-6, u0 = vals[fu];
      vals[fu] = u0 + h;
      double fp = eval(fs[k]);
      vals[fu] = u0 - h;
      double fm = eval(fs[k]);
      vals[fu] = u0;
      double fd = (fp - fm) / (2 * h), ad = eval(d);
      CHECK(fabs(fd - ad) <= 1e-6 * (1 + fabs(ad)), "f%d'(u=%g, w=%g) = %.12g, finite differences %.12g", k,
            u0, vals[fw], ad, fd);
    }
  }

  /* spatial derivatives go to the leaves: d/dx (u^2 x) = 2 u u_x x + u^2 */
  expr_set_dim(C, 2);
  unsigned char ax[3] = {1, 0, 0};
  expr *ux = expr_field(C, fu, 0, ax);
  expr *g = expr_dx(C, expr_mul(C, expr_pow(C, u, two), x), 0);
  expr *want = expr_add(C, expr_prod_n(C, 4, (expr *[]){two, u, ux, x}), expr_pow(C, u, two));
  CHECK(g == want, "d/dx(u^2 x) not in canonical form");
  expr *gr = expr_grad(C, u);
  int rank;
  CHECK(expr_shape(gr, &rank) == 2 && rank == 1, "grad u is not a 2-vector");
  CHECK(expr_dot(C, gr, gr) == expr_add(C, expr_pow(C, ux, two), expr_pow(C, expr_index(C, gr, 1), two)),
        "grad u . grad u");

  /* shape errors name both operands */
  CHECK(expr_add(C, gr, u) == NULL && strstr(expr_error(C), "cannot add a 2-vector and a scalar"), "%s", expr_error(C));
  CHECK(expr_mul(C, gr, gr) == NULL && strstr(expr_error(C), "cannot multiply a 2-vector and a 2-vector"), "%s", expr_error(C));
  expr *l3 = expr_list(C, 3, (expr *[]){u, u, u});
  CHECK(expr_dot(C, gr, l3) == NULL && strstr(expr_error(C), "a 2-vector and a 3-vector"), "%s", expr_error(C));
  CHECK(expr_div(C, u, expr_num(C, 0)) == NULL && strstr(expr_error(C), "division by zero"), "%s", expr_error(C));

  /* linearization: f = grad v . grad u + u^3 v - w v  →  residual and Jacobian tables */
  expr *f = expr_add(C, expr_dot(C, expr_grad(C, v), gr),
                     expr_sub(C, expr_mul(C, expr_pow(C, u, expr_num(C, 3)), v), expr_mul(C, w, v)));
  coef_table tab;
  CHECK(form_linearize(C, f, 1, &fv, 1, &fu, 1, &tab) == 0, "%s", expr_error(C));
  CHECK(tab.nres == 3, "3 residual entries (v, v_x, v_y), got %d", tab.nres);
  CHECK(tab.njac == 3, "3 Jacobian entries (v u: 3u^2, v_x u_x, v_y u_y), got %d", tab.njac);
  for (int i = 0; i < tab.njac; i++) {
    if (tab.jac_test[i] == v) CHECK(tab.jac[i] == expr_mul(C, expr_num(C, 3), expr_pow(C, u, two)), "J_vu != 3u^2");
    else CHECK(tab.jac[i] == expr_num(C, 1), "gradient entry is not 1");
  }
  coef_table_free(&tab);
  CHECK(form_linearize(C, expr_mul(C, v, v), 1, &fv, 1, &fu, 1, &tab) != 0 &&
            strstr(expr_error(C), "not linear in the test function"), "v*v accepted");
  CHECK(form_linearize(C, expr_add(C, expr_mul(C, u, v), w), 1, &fv, 1, &fu, 1, &tab) != 0 &&
            strstr(expr_error(C), "does not contain it"), "a term without v accepted");

  /* code generation names only generated identifiers */
  expr_tape t;
  CHECK(expr_tape_build(C, 1, &fs[0], &t) == 0, "tape");
  printf("tape of f0: %d nodes\n", t.n);
  expr_tape_free(&t);
  expr_ctx_free(C);
  return CHECK_DONE();
}
