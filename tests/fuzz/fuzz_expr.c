/* fuzz_expr.c — the symbolic engine driven by a byte string: a small stack machine whose
 * instructions push leaves (coordinates, parameters, fields and their derivatives,
 * constants including huge, tiny and zero), combine them (+ - * / ^, the functions, lists,
 * dot, inner, grad, div, dx, index, lazy sums and products as scripts build them), and
 * finally differentiate, substitute, print, estimate degrees, linearize a form, build a
 * tape, evaluate it and generate C. Nothing may crash, hang or leak; a NULL result must come
 * with a message; equal expressions built two ways must be the same node (hash-consing).
 * Built with libFuzzer by `make fuzz`; the inputs of tests/data/hostile/expr replay in
 * `make check` (tests/c/test_hostile.c). */
#include "../../src/expr/expr.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define EFUZZ_CHECK(cond, what)                                                                 \
  do {                                                                                          \
    if (!(cond)) {                                                                              \
      fprintf(stderr, "fuzz_expr: invariant broken: %s (%s:%d)\n", what, __FILE__, __LINE__);  \
      abort();                                                                                  \
    }                                                                                           \
  } while (0)

static int efuzz_leaf(void *ud, const expr *e, double *v) {
  (void)ud;
  *v = e->kind == E_COORD ? 0.25 + 0.1 * e->i0 : e->kind == E_NORMAL ? 0.6 : 0.5 + 0.01 * e->i0 + 0.1 * e->order;
  return 0;
}

static void efuzz_name(void *ud, const expr *e, char *buf, size_t len) {
  (void)ud;
  snprintf(buf, len, "L%d", e->id);
}

#define STACK 32

int fuzz_expr_run(const uint8_t *data, size_t size) {
  expr_ctx *c = expr_ctx_new();
  if (!c) return 0;
  expr_set_budget(c, 1 << 20); /* small: a blow-up is refused quickly */
  expr_set_dim(c, 2 + (size && (data[0] & 1)));
  int fu = expr_func_new(c, FK_UNKNOWN, "u", 2, 1, NULL), fv = expr_func_new(c, FK_TEST, "v", 2, 1, NULL);
  int fw = expr_func_new(c, FK_DISCRETE, "w", 1, 1, NULL);
  int pa = expr_param_new(c, "a", 1.5);
  expr *st[STACK];
  int sp = 0, ops = 0;
  unsigned char z[3] = {0, 0, 0};
  for (size_t i = 1; i < size && ops < 4096; i++, ops++) {
    unsigned op = data[i] % 40, arg = i + 1 < size ? data[i + 1] : 0;
    expr *r = NULL;
    int pops = 0;
    expr *a = sp > 0 ? st[sp - 1] : NULL, *b = sp > 1 ? st[sp - 2] : NULL;
    switch (op) {
    case 0: r = expr_coord(c, arg % 3); i++; break;
    case 1: r = expr_param(c, pa); break;
    case 2: {
      unsigned char al[3] = {(unsigned char)(arg & 1), (unsigned char)((arg >> 1) & 1), 0};
      r = expr_field(c, (int)(arg >> 2) % 3 == 0 ? fu : (arg >> 2) % 3 == 1 ? fv : fw, 0, al);
      i++;
      break;
    }
    case 3: {
      static const double k[] = {0, 1, -1, 2, 0.5, -0.5, 3, 1e300, 1e-300, 1e-320, 1e308, 7};
      r = expr_num(c, k[arg % 12]);
      i++;
      break;
    }
    case 4: case 5: case 6: case 7: case 8: case 9: case 10: case 11:
      if (!a || !b) continue;
      pops = 2;
      switch (op) {
      case 4: r = expr_add(c, b, a); break;
      case 5: r = expr_sub(c, b, a); break;
      case 6: r = expr_mul(c, b, a); break;
      case 7: r = expr_div(c, b, a); break;
      case 8: r = expr_pow(c, b, a); break;
      case 9: r = expr_add_lazy(c, b, a); break;
      case 10: r = expr_mul_lazy(c, b, a); break;
      default: r = expr_sub_lazy(c, b, a); break;
      }
      break;
    case 12: case 13: case 14: case 15: case 16: case 17: case 18:
      if (!a) continue;
      pops = 1;
      r = expr_apply(c, (expr_fn)((op - 12) * 2 + (arg & 1)) , a);
      i++;
      break;
    case 19: if (!a) continue; pops = 1; r = expr_neg(c, a); break;
    case 20: { /* a list of the top k */
      int k = 1 + arg % 4;
      if (sp < k) continue;
      expr *items[4];
      for (int j = 0; j < k; j++) items[j] = st[sp - k + j];
      pops = k;
      r = expr_list(c, k, items);
      i++;
      break;
    }
    case 21: if (!a || !b) continue; pops = 2; r = expr_dot(c, b, a); break;
    case 22: if (!a || !b) continue; pops = 2; r = expr_inner(c, b, a); break;
    case 23: if (!a) continue; pops = 1; r = expr_grad(c, a); break;
    case 24: if (!a) continue; pops = 1; r = expr_div_op(c, a); break;
    case 25: if (!a) continue; pops = 1; r = expr_dx(c, a, arg % 3); i++; break;
    case 26: if (!a) continue; pops = 1; r = expr_index(c, a, arg % 4); i++; break;
    case 27: if (!a) continue; r = a; break; /* dup */
    case 28: if (!a || !b) continue; st[sp - 1] = b; st[sp - 2] = a; continue; /* swap */
    case 29: { /* a long lazy sum or product: what scripts build in loops */
      if (!a) continue;
      pops = 1;
      r = a;
      for (int j = 0; j < 40 + (int)(arg % 64) && r; j++)
        r = (op + j) & 1 ? expr_add_lazy(c, r, expr_mul(c, expr_num(c, j), a)) : expr_add_lazy(c, r, expr_coord(c, j % 2));
      i++;
      break;
    }
    case 30: { /* a deep chain */
      if (!a) continue;
      pops = 1;
      r = a;
      for (int j = 0; j < 20 * (1 + (int)(arg % 4)) && r; j++) r = expr_apply(c, j % 3 ? FN_SIN : FN_EXP, r);
      i++;
      break;
    }
    case 31: if (!a) continue; pops = 1; r = expr_diff(c, a, expr_field(c, fu, 0, z)); break;
    case 32: if (!a) continue; pops = 1; r = expr_diff(c, a, expr_param(c, pa)); break;
    case 33: { /* substitute u by the next item down */
      if (!a || !b) continue;
      pops = 2;
      expr *from = expr_field(c, fu, 0, z);
      r = b->kind == E_LIST ? a : expr_subs(c, a, 1, &from, &b);
      break;
    }
    default:
      continue;
    }
    if (!r) {
      EFUZZ_CHECK(expr_error(c)[0] != 0, "a failed construction leaves a message");
      expr_set_error(c, "%s", "");
      continue;
    }
    sp -= pops;
    if (sp < STACK) st[sp++] = r;
  }
  /* everything the rest of lugal does with an integrand, on what is left */
  char buf[512];
  for (int k = 0; k < sp; k++) {
    expr *e = expr_canon(c, st[k]);
    if (!e) continue;
    expr_print(c, e, buf, sizeof buf);
    int rank;
    expr_shape(e, &rank);
    expr_degree(c, e, 1);
    expr_uses(c, e, E_COORD, NULL);
    /* hash-consing: the same sum built the other way round is the same node */
    if (k > 0 && st[k - 1] && rank == 0 && expr_shape(st[k - 1], NULL) == 0) {
      expr *p = expr_add(c, e, st[k - 1]), *q = expr_add(c, st[k - 1], e);
      EFUZZ_CHECK(!p || !q || p == q, "a + b and b + a are the same node");
    }
    if (rank) continue;
    int test[1] = {fv}, unk[1] = {fu};
    coef_table tab;
    if (!form_linearize(c, e, 1, test, 1, unk, 1, &tab)) coef_table_free(&tab);
    expr_tape t;
    if (!expr_tape_build(c, 1, &e, &t)) {
      double *w = malloc(sizeof(double) * (size_t)(t.n + 1)), out;
      if (w) expr_tape_eval(&t, expr_param_values(c), efuzz_leaf, NULL, w, &out);
      free(w);
      unsigned char *sel = malloc((size_t)t.n + 1);
      if (sel) {
        memset(sel, 1, (size_t)t.n + 1);
        strbuf sb = {0};
        expr_codegen(&sb, &t, "t", "P", sel, efuzz_name, NULL, "");
        sb_free(&sb);
        free(sel);
      }
      expr_tape_free(&t);
    }
  }
  expr_ctx_free(c);
  return 0;
}

#ifdef LUGAL_LIBFUZZER
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) { return fuzz_expr_run(data, size); }
#endif
