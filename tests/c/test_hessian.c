/* test_hessian.c — the derivatives of the untangling energy: a vertex's star energy and its
 * gradient, which the sliding smoother's 3D slides descend (ut_energy_vertex: d Σ 1/q of the
 * mean ratio over the star, its gradient against central differences), and the projected
 * corner Hessians (untangle_global.c,
 * included here to reach its static functions): on one simplex whose W⁻¹ is the identity and
 * whose vertex 0 is the origin, J's columns are vertices 1..d, so the block of the vertex
 * Hessian in vertices 1..d is the Hessian in J. It must equal the finite-difference Hessian of
 * the analytic gradient (corner_energy) with its negative eigenvalues set to 0 — for the
 * closed forms (2D conformal/anticonformal, 3D SVD modes) and the numeric 3D fallback alike —
 * and be positive semidefinite, for the smoother's energy (θ = 0, ε = 0) and the untangler's
 * (θ = 1/2, ε > 0, inverted corners too); and the closed-form 3×3 eigensystem behind the 3D
 * modes (dense_sym_eigen3) against known spectra. */
#include "../../src/mesh/untangle/untangle_global.c"

#include "../../src/mesh/quality/quality.h"
#include "check.h"

static unsigned rng = 12345;
static double rnd(void) { /* in [-1, 1) */
  rng = rng * 1103515245u + 12345u;
  return (double)((rng >> 8) & 0xffffff) / 8388608.0 - 1;
}

/* the objective of one simplex with vertices x (d + 1 of them) */
static void setup(int d, double *x, mesh *m, ctx *C, objective *o, int *cellv, int *cells) {
  memset(m, 0, sizeof *m);
  m->type = d == 2 ? CELL_TRIANGLE : CELL_TETRAHEDRON;
  m->dim = d;
  m->nvc = d + 1;
  m->nvert = d + 1;
  m->x = x;
  m->ncell = 1;
  for (int k = 0; k <= d; k++) cellv[k] = k;
  m->cells = cellv;
  memset(C, 0, sizeof *C);
  C->m = m;
  C->d = d;
  C->nvc = d + 1;
  C->ncorner = 1;
  for (int k = 0; k <= d; k++) C->ct[0][k] = k;
  memset(o, 0, sizeof *o);
  o->C = C;
  cells[0] = 0;
  o->cells = cells;
  for (int a = 0; a < d; a++) o->winv[a * d + a] = 1;
}

/* one case: J given (columns = vertices 1..d), energy parameters θ, ε */
static void check_case(int d, double J[3][3], double theta, double eps, const char *what) {
  double x[12] = {0}, hk[144], g1[12], g2[12];
  int cellv[4], cells[1];
  mesh m;
  ctx C;
  objective o;
  for (int k = 1; k <= d; k++)
    for (int a = 0; a < d; a++) x[k * d + a] = J[a][k - 1];
  setup(d, x, &m, &C, &o, cellv, cells);
  o.theta = theta;
  o.eps = eps;
  int nx = (d + 1) * d, n = d * d;
  CHECK(!corner_hessian(&o, x, 0, 0, hk), "%s: a finite energy", what);
  /* the finite-difference Hessian in J, from the analytic gradient in vertices 1..d */
  double H[81], scale = 0;
  for (int e = 0; e < d; e++)
    for (int m2 = 0; m2 < d; m2++) { /* J entry (e, m2) = x of vertex m2 + 1, coordinate e */
      double *p = x + (m2 + 1) * d + e, p0 = *p, h = 1e-6 * (1 + fabs(p0));
      *p = p0 + h;
      corner_energy(&o, x, 0, 0, g1);
      *p = p0 - h;
      corner_energy(&o, x, 0, 0, g2);
      *p = p0;
      for (int a = 0; a < d; a++)
        for (int b = 0; b < d; b++) /* row (a, b): ∂f/∂J_ab is the gradient in vertex b + 1 */
          H[(a * d + b) * n + e * d + m2] = (g1[(b + 1) * d + a] - g2[(b + 1) * d + a]) / (2 * h);
    }
  for (int i = 0; i < n; i++)
    for (int j = 0; j < i; j++) H[i * n + j] = H[j * n + i] = 0.5 * (H[i * n + j] + H[j * n + i]);
  for (int i = 0; i < n * n; i++) scale = fmax(scale, fabs(H[i]));
  /* its nearest positive semidefinite matrix, Σ_{λ > 0} λ m mᵀ */
  double lam[9], md[9][9];
  sym_psd_modes(n, H, lam, md);
  memset(H, 0, sizeof H);
  for (int k = 0; k < n; k++)
    for (int i = 0; i < n && lam[k] > 0; i++)
      for (int j = 0; j < n; j++) H[i * n + j] += lam[k] * md[k][i] * md[k][j];
  double err = 0;
  for (int a = 0; a < d; a++)
    for (int b = 0; b < d; b++)
      for (int e = 0; e < d; e++)
        for (int m2 = 0; m2 < d; m2++)
          err = fmax(err, fabs(hk[((b + 1) * d + a) * nx + (m2 + 1) * d + e] - H[(a * d + b) * n + e * d + m2]));
  CHECK(err <= 1e-5 * scale, "%s: projected Hessian off by %.3g (scale %.3g)", what, err, scale);
  /* positive semidefinite over all d + 1 vertices, and symmetric */
  double w[12], v[144], hc[144], asym = 0;
  memcpy(hc, hk, sizeof(double) * nx * nx);
  for (int i = 0; i < nx; i++)
    for (int j = 0; j < nx; j++) asym = fmax(asym, fabs(hk[i * nx + j] - hk[j * nx + i]));
  CHECK(asym <= 1e-12 * scale, "%s: symmetric (%.3g)", what, asym);
  /* sym_eigen takes n ≤ 9: check vᵀ H v ≥ 0 on random directions instead */
  (void)w; (void)v;
  for (int t = 0; t < 50; t++) {
    double u[12], s = 0;
    for (int i = 0; i < nx; i++) u[i] = rnd();
    for (int i = 0; i < nx; i++)
      for (int j = 0; j < nx; j++) s += u[i] * hc[i * nx + j] * u[j];
    CHECK(s >= -1e-10 * scale * nx, "%s: uᵀHu = %.3g < 0", what, s);
  }
}

/* dense_sym_eigen3 on a = Q diag(l) Qᵀ, Q a random rotation: ascending eigenvalues within
 * a rounding error of |a| of l, orthonormal vectors, residuals |a v − w v| at rounding level
 * (the backward stability the 3D Hessian modes rely on), repeated and nearly repeated
 * eigenvalues included, and the answer of the cyclic method */
static void check_eigen3(const double *l, double scale, const char *what) {
  double q[9], a[9], w[3], v[9], ls[3] = {l[0], l[1], l[2]}, amax = 0;
  /* a random rotation, from a random unit quaternion (orthonormal to rounding) */
  double qw = rnd(), qx = rnd(), qy = rnd(), qz = rnd(), qn = sqrt(qw * qw + qx * qx + qy * qy + qz * qz);
  qw /= qn; qx /= qn; qy /= qn; qz /= qn;
  double rot[9] = {1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw),     2 * (qx * qz + qy * qw),
                   2 * (qx * qy + qz * qw),     1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw),
                   2 * (qx * qz - qy * qw),     2 * (qy * qz + qx * qw),     1 - 2 * (qx * qx + qy * qy)};
  memcpy(q, rot, sizeof rot);
  for (int i = 0; i < 3; i++)
    for (int j = 0; j < 3; j++) {
      a[i * 3 + j] = 0;
      for (int k = 0; k < 3; k++) a[i * 3 + j] += q[i * 3 + k] * l[k] * scale * q[j * 3 + k];
    }
  for (int i = 0; i < 3; i++)
    for (int j = 0; j < i; j++) a[i * 3 + j] = a[j * 3 + i];
  for (int i = 0; i < 9; i++) amax = fmax(amax, fabs(a[i]));
  dense_sym_eigen3(a, w, v);
  for (int i = 0; i < 3; i++) /* sort l */
    for (int j = i + 1; j < 3; j++)
      if (ls[j] < ls[i]) { double t = ls[i]; ls[i] = ls[j]; ls[j] = t; }
  double ew = 0, eo = 0, er = 0;
  for (int k = 0; k < 3; k++) {
    ew = fmax(ew, fabs(w[k] - ls[k] * scale));
    for (int j = 0; j < 3; j++) {
      double d = 0;
      for (int i = 0; i < 3; i++) d += v[i * 3 + k] * v[i * 3 + j];
      eo = fmax(eo, fabs(d - (j == k)));
    }
    for (int i = 0; i < 3; i++) {
      double t = -w[k] * v[i * 3 + k];
      for (int j = 0; j < 3; j++) t += a[i * 3 + j] * v[j * 3 + k];
      er = fmax(er, fabs(t));
    }
  }
  CHECK(ew <= 1e-14 * amax + 1e-300, "%s: eigenvalues off by %.3g (|a| %.3g)", what, ew, amax);
  CHECK(eo <= 1e-14, "%s: VᵀV − I %.3g", what, eo);
  CHECK(er <= 1e-14 * amax + 1e-300, "%s: residual %.3g (|a| %.3g)", what, er, amax);
  CHECK(w[0] <= w[1] && w[1] <= w[2], "%s: ascending %.17g %.17g %.17g", what, w[0], w[1], w[2]);
  if (scale != 1) return; /* the cyclic method's squared sums overflow at 1e±200 */
  double t[9], vj[9];
  memcpy(t, a, sizeof t);
  dense_sym_eigen(3, t, vj, 0, 1e-30);
  double jw[3] = {t[0], t[4], t[8]};
  for (int i = 0; i < 3; i++)
    for (int j = i + 1; j < 3; j++)
      if (jw[j] < jw[i]) { double x = jw[i]; jw[i] = jw[j]; jw[j] = x; }
  for (int k = 0; k < 3; k++)
    CHECK(fabs(jw[k] - w[k]) <= 1e-14 * amax + 1e-300, "%s: eigenvalue %d %.17g, the cyclic method's %.17g", what, k, w[k], jw[k]);
}

static void check_eigen3_all(void) {
  char what[128];
  static const double cases[][3] = {
      {1, 2, 3},         {-1, 0.5, 4},      {2, 2, 2},          {1, 1, 3},          {1, 3, 3},         {0, 0, 0},
      {0, 0, 1},         {-5, -5, 1},       {1, 1 + 1e-6, 2},   {1, 1 + 1e-10, 2},  {1, 1 + 1e-15, 2}, {1, 2, 2 + 1e-12},
      {1, 1 + 1e-9, 1 + 2e-9}, {1, 1, 1 + 1e-13}, {1e-8, 1, 1e8}, {-1, 0, 1},       {3, -3, 0},        {1e-300, 1, 2}};
  for (int c = 0; c < (int)(sizeof cases / sizeof cases[0]); c++)
    for (double sc = 1e-200; sc < 1e201; sc *= 1e100)
      for (int t = 0; t < 20; t++) {
        snprintf(what, sizeof what, "eigen3 (%g, %g, %g) x %g, rotation %d", cases[c][0], cases[c][1], cases[c][2], sc, t);
        check_eigen3(cases[c], sc, what);
      }
  double z[9] = {0}, w[3], v[9], I[9] = {4, 0, 0, 0, 4, 0, 0, 0, 4};
  dense_sym_eigen3(z, w, v);
  CHECK(w[0] == 0 && w[2] == 0 && v[0] == 1 && v[4] == 1 && v[8] == 1, "eigen3 of 0: 0 and I");
  dense_sym_eigen3(I, w, v);
  CHECK(w[0] == 4 && w[1] == 4 && w[2] == 4 && v[0] == 1 && v[1] == 0, "eigen3 of 4 I: 4 and I");
}

/* ut_energy_vertex on a perturbed 3×3×3 tetrahedral box at ε = 0, θ = 0, J relative to a
 * regular tetrahedron (the energy smoother's objective): its value is 3 Σ 1/q over the cells
 * around the vertex (q the mean ratio mesh_cell_quality reports) and its gradient the
 * central differences of that value, at interior, face, edge and corner vertices */
static void check_vertex_energy(void) {
  char err[MESH_ERRLEN];
  mesh_box_opts bo = {3, 3, 3, 0, 1, 0, 1, 0, 1, CELL_TETRAHEDRON, 0, 0, 0};
  mesh *m = mesh_box(&bo, err);
  CHECK(m != NULL, "box: %s", err);
  if (!m) return;
  for (int v = 0; v < m->nvert; v++)
    for (int a = 0; a < 3; a++) {
      double *p = m->x + 3 * v + a;
      if (*p > 0 && *p < 1) *p += 0.07 * rnd();
    }
  ctx C;
  CHECK(!ut_ctx_init(&C, m, 1, err), "context: %s", err);
  objective o;
  memset(&o, 0, sizeof o);
  o.C = &C;
  o.smooth = 2;
  ut_regular_winv(3, 1.0, o.winv);
  int checked = 0;
  for (int v = 0; v < m->nvert; v++) {
    double g[3], gp[3], sq = 0, f = ut_energy_vertex(&o, m->x, v, g), gmax = 0;
    for (int p = C.vc_off[v]; p < C.vc_off[v + 1]; p++) sq += 1 / mesh_cell_quality(m, C.vc[p], QM_MEAN_RATIO);
    CHECK(fabs(f - 3 * sq) <= 1e-12 * f, "vertex %d: star energy %.17g, 3 sum 1/q %.17g", v, f, 3 * sq);
    for (int a = 0; a < 3; a++) gmax = fmax(gmax, fabs(g[a]));
    for (int a = 0; a < 3; a++) {
      double *p = m->x + 3 * v + a, p0 = *p, h = 1e-6;
      *p = p0 + h;
      double fp = ut_energy_vertex(&o, m->x, v, gp);
      *p = p0 - h;
      double fm = ut_energy_vertex(&o, m->x, v, gp);
      *p = p0;
      CHECK(fabs((fp - fm) / (2 * h) - g[a]) <= 1e-6 * (1 + gmax), "vertex %d, coordinate %d: gradient %.12g, central "
            "differences %.12g", v, a, g[a], (fp - fm) / (2 * h));
    }
    checked++;
  }
  CHECK(checked == 64, "%d vertices", checked);
  ut_ctx_free(&C);
  mesh_free(m);
}

int main(void) {
  char what[128];
  check_eigen3_all();
  check_vertex_energy();
  for (int d = 2; d <= 3; d++)
    for (int t = 0; t < 40; t++) {
      double J[3][3];
      for (int a = 0; a < d; a++)
        for (int b = 0; b < d; b++) J[a][b] = (a == b) + 0.6 * rnd();
      double D = d == 2 ? J[0][0] * J[1][1] - J[0][1] * J[1][0]
                        : J[0][0] * (J[1][1] * J[2][2] - J[1][2] * J[2][1]) - J[0][1] * (J[1][0] * J[2][2] - J[1][2] * J[2][0]) +
                              J[0][2] * (J[1][0] * J[2][1] - J[1][1] * J[2][0]);
      if (D > 0) {
        snprintf(what, sizeof what, "%dD case %d, smoother (theta 0, eps 0)", d, t);
        check_case(d, J, 0, 0, what);
      }
      snprintf(what, sizeof what, "%dD case %d, untangler (theta 0.5, eps 0.05), det %.3g", d, t, D);
      check_case(d, J, 0.5, 0.05, what);
    }
  /* a conformal 2D map (s = 0) and an isotropic 3D one (repeated singular values) */
  double Jc[3][3] = {{0.8, -0.6, 0}, {0.6, 0.8, 0}, {0, 0, 0}}, Ji[3][3] = {{2, 0, 0}, {0, 2, 0}, {0, 0, 2}};
  check_case(2, Jc, 0, 0, "2D conformal");
  check_case(3, Ji, 0, 0, "3D isotropic");
  /* nearly repeated singular values (the closed-form eigensystem's hard case): a rotation
   * times diag(1, 1, 1 + δ) and diag(1, 1 + δ, 2) */
  double th = 0.7, c = cos(th), sn = sin(th);
  for (int k = 0; k < 3; k++) {
    double dl = k == 0 ? 1e-5 : k == 1 ? 1e-9 : 1e-14, sv[2][3] = {{1, 1, 1 + dl}, {1, 1 + dl, 2}};
    for (int j = 0; j < 2; j++) {
      double Jr[3][3] = {{c * sv[j][0], -sn * sv[j][1], 0}, {sn * sv[j][0], c * sv[j][1], 0}, {0, 0, sv[j][2]}};
      snprintf(what, sizeof what, "3D singular values (%g, %g, %g)", sv[j][0], sv[j][1], sv[j][2]);
      check_case(3, Jr, 0, 0, what);
      check_case(3, Jr, 0.5, 0.05, what);
    }
  }
  return CHECK_DONE();
}
