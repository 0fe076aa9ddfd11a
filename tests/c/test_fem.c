/* test_fem.c — Gauss quadrature exact to its degree on the reference triangle and
 * tetrahedron (monomials against the exact Beta-function values) and Lagrange bases that
 * are nodal (Kronecker at the nodes) and sum to one, with gradients summing to zero. */
#include "../../src/assemble/fem/fem.h"
#include "check.h"

/* exact ∫ x^a y^b z^c over the reference simplex = a! b! c! / (a+b+c+d)! */
static double fact(int n) { double f = 1; for (int i = 2; i <= n; i++) f *= i; return f; }

int main(void) {
  for (int dim = 1; dim <= 3; dim++) {
    for (int deg = 0; deg <= FEM_MAXDEG; deg++) {
      quad_rule q;
      CHECK(quad_simplex(dim, deg, &q) == 0, "rule dim %d degree %d", dim, deg);
      CHECK(q.degree >= deg, "dim %d degree %d: the rule has degree %d", dim, deg, q.degree);
      /* positive weights, points strictly inside */
      for (int i = 0; i < q.n; i++) {
        double sx = 0;
        int inside = q.w[i] > 0;
        for (int d = 0; d < dim; d++) { inside &= q.x[dim * i + d] > 0; sx += q.x[dim * i + d]; }
        CHECK(inside && sx < 1, "dim %d degree %d: point %d outside or a weight not positive", dim, deg, i);
      }
      /* the symmetric tables where they exist: fewer points than the collapsed product */
      static const int tri_n[21] = {1, 1, 3, 6, 6, 7, 12, 15, 16, 19, 25, 28, 33, 37, 42, 49, 60, 60, 67, 73, 79};
      static const int tet_n[11] = {1, 1, 4, 8, 14, 14, 24, 35, 46, 59, 81};
      if (dim == 2) CHECK(q.n == tri_n[deg], "triangle degree %d: %d points (want %d)", deg, q.n, tri_n[deg]);
      if (dim == 3 && deg <= 10) CHECK(q.n == tet_n[deg], "tetrahedron degree %d: %d points (want %d)", deg, q.n, tet_n[deg]);
      for (int a = 0; a <= deg; a++)
        for (int b = 0; a + b <= deg && (dim >= 2 || b == 0); b++)
          for (int c = 0; a + b + c <= deg && (dim == 3 || c == 0); c++) {
            double s = 0;
            for (int i = 0; i < q.n; i++) {
              double v = pow(q.x[dim * i], a);
              if (dim >= 2) v *= pow(q.x[dim * i + 1], b);
              if (dim == 3) v *= pow(q.x[dim * i + 2], c);
              s += q.w[i] * v;
            }
            double exact = fact(a) * fact(b) * fact(c) / fact(a + b + c + dim);
            CHECK(fabs(s - exact) <= 1e-14 + 1e-12 * exact, "dim %d degree %d: x^%d y^%d z^%d: %.17g vs %.17g",
                  dim, deg, a, b, c, s, exact);
          }
    }
  }
  for (int ct = 0; ct < 2; ct++) {
    cell_type t = ct ? CELL_TETRAHEDRON : CELL_TRIANGLE;
    for (int p = 1; p <= 3; p++) {
      lagrange_element e;
      char err[256];
      CHECK(lagrange_init(&e, t, p, err) == 0, "%s", err);
      static const int expect[2][4] = {{0, 3, 6, 10}, {0, 4, 10, 20}};
      CHECK(e.nloc == expect[ct][p], "P%d on %s: %d dofs", p, cell_name(t), e.nloc);
      double val[FEM_MAXLOC], grad[FEM_MAXLOC * 3];
      for (int n = 0; n < e.nloc; n++) {
        lagrange_eval(&e, e.node + 3 * n, val, NULL);
        for (int k = 0; k < e.nloc; k++) CHECK(fabs(val[k] - (k == n)) < 1e-12, "phi_%d(node %d) = %g", k, n, val[k]);
      }
      double xi[3] = {0.21, 0.33, 0.17};
      lagrange_eval(&e, xi, val, grad);
      double s = 0, g[3] = {0, 0, 0};
      for (int k = 0; k < e.nloc; k++) {
        s += val[k];
        for (int d = 0; d < e.dim; d++) g[d] += grad[k * e.dim + d];
      }
      CHECK(fabs(s - 1) < 1e-12, "partition of unity %g", s);
      for (int d = 0; d < e.dim; d++) CHECK(fabs(g[d]) < 1e-11, "gradients sum %g", g[d]);
      /* each facet holds the right number of nodes: P1 d, P2 2d (tri 3, tet 6), P3 */
      static const int fd[2][4] = {{0, 2, 3, 4}, {0, 3, 6, 10}};
      CHECK(e.nfacet_dofs == fd[ct][p], "P%d %s: %d dofs per facet", p, cell_name(t), e.nfacet_dofs);
    }
  }
  return CHECK_DONE();
}
