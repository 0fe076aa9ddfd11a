/* fuzz_untangle.c — the untangler, the smoother and the mesh motion on meshes made from
 * arbitrary bytes: a small structured mesh of a type and size the first bytes choose, its
 * vertices displaced by the following bytes (folds, collapses, huge, tiny and non-finite
 * values among them), and options from the bytes (beta, placement, boundary sliding).
 *
 * What must hold: bad input (a non-finite coordinate) is refused with a message; a report
 * of "no invalid cells" is true of the mesh; the untangler never returns a mesh with more
 * invalid cells than it was given; smoothing never lowers the minimum quality; coordinates
 * stay finite. A broken invariant aborts (a finding). Built with libFuzzer by `make fuzz`
 * and replayed over tests/data/hostile/untangle by `make check` (tests/c/test_hostile.c). */
#include "../../src/mesh/io/io.h"
#include "../../src/mesh/quality/quality.h"
#include "../../src/mesh/untangle/untangle.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define UFUZZ_CHECK(cond, what)                                                                     \
  do {                                                                                              \
    if (!(cond)) {                                                                                  \
      fprintf(stderr, "fuzz_untangle: invariant broken: %s (%s:%d)\n", what, __FILE__, __LINE__);  \
      abort();                                                                                      \
    }                                                                                               \
  } while (0)

typedef struct {
  const uint8_t *p;
  size_t n, i;
} bytes;

static unsigned next(bytes *b) { return b->i < b->n ? b->p[b->i++] : 0; }

/* a displacement from one byte: mostly small, sometimes large, rarely extreme */
static double displacement(bytes *b, double h) {
  unsigned v = next(b);
  switch (v) {
  case 255: return NAN;
  case 254: return INFINITY;
  case 253: return 1e300;
  case 252: return 1e-300;
  default: return ((double)v - 126) / 126 * (v & 1 ? 3 * h : 0.4 * h);
  }
}

static int invalid_cells(const mesh *m) {
  int n;
  mesh_count_invalid(m, 0, NULL, &n);
  return n;
}

int fuzz_untangle_run(const uint8_t *data, size_t size) {
  bytes b = {data, size, 0};
  unsigned t = next(&b) % 4, nx = 1 + next(&b) % 6, ny = 1 + next(&b) % 6, nz = 1 + next(&b) % 3;
  unsigned scale = next(&b) % 4;
  double L = scale == 0 ? 1 : scale == 1 ? 1e-200 : scale == 2 ? 1e200 : 1e-3;
  mesh_box_opts o = {(int)nx, (int)ny, (int)nz, 0, L, 0, L, 0, L, (cell_type)t, (int)(next(&b) % 3), 0, 0};
  char err[MESH_ERRLEN];
  mesh *m = t <= CELL_QUADRILATERAL ? mesh_rectangle(&o, err) : mesh_box(&o, err);
  UFUZZ_CHECK(m != NULL, "a structured mesh");
  double h = L / (nx > ny ? nx : ny);
  /* displace some vertices: a byte picks the vertex, then one per coordinate */
  unsigned nmove = next(&b);
  for (unsigned k = 0; k < nmove && b.i < b.n; k++) {
    int v = (int)(next(&b) * 256u + next(&b)) % m->nvert;
    for (int j = 0; j < m->dim; j++) m->x[(size_t)v * m->dim + j] += displacement(&b, h);
  }
  int finite = 1;
  for (size_t i = 0; i < (size_t)m->nvert * m->dim; i++) finite &= isfinite(m->x[i]) != 0;
  unsigned flags = next(&b);
  untangle_opts uo;
  untangle_defaults(&uo);
  uo.max_iterations = 1 + (int)(flags % 8);
  uo.slide = (flags >> 3) & 1;
  uo.placement = (flags >> 4) & 1;
  if ((flags >> 5) & 1) uo.beta = next(&b) * 1e-4 * pow(h, m->dim);
  int before = finite ? invalid_cells(m) : 0;
  untangle_report r;
  int rc = mesh_untangle(m, &uo, &r, err);
  if (!finite) UFUZZ_CHECK(rc != 0 && (strstr(err, "non-finite") || strstr(err, "beta must be")), "non-finite coordinates are refused");
  if (!rc) {
    int after = invalid_cells(m);
    for (size_t i = 0; i < (size_t)m->nvert * m->dim; i++) UFUZZ_CHECK(isfinite(m->x[i]), "finite coordinates after untangling");
    if (!r.invalid_after)
      for (int c = 0; c < m->ncell; c++) UFUZZ_CHECK(!(mesh_cell_relative_validity(m, c) < -1e-9), "a reported success is true");
    UFUZZ_CHECK(r.invalid_after <= r.invalid_before, "never worse than the input (the report)");
    UFUZZ_CHECK(after <= before || after <= r.invalid_after, "never worse than the input (the mesh)");
    if (!after) {
      /* the optimizer and the sliding passes from one more byte (flags is a byte: its bits
       * past 7 were always 0, so the optimizer was always the default) */
      unsigned sflags = next(&b);
      smooth_opts so = {smooth_energy_measure(t), 1 + (int)(flags % 3),
                        uo.slide, 0, (flags >> 6) & 1, (flags >> 6) & (flags >> 7) & 1, NULL, (int)(sflags % 3),
                        (int)((sflags / 3) % 3), (int)((sflags / 9) & 1), 0};
      smooth_report sr;
      if (!mesh_smooth(m, &so, &sr, err)) UFUZZ_CHECK(!(sr.min_after < sr.min_before * (1 - 1e-12)), "smoothing keeps the minimum");
    }
    /* motion of the boundary by the remaining bytes */
    unsigned char *fixed = calloc((size_t)m->nvert + 1, 1);
    double *disp = calloc((size_t)m->nvert * m->dim + 1, sizeof(double));
    if (fixed && disp && !mesh_boundary_vertices(m, fixed, err)) {
      for (int v = 0; v < m->nvert && b.i < b.n; v++)
        if (fixed[v])
          for (int j = 0; j < m->dim; j++) disp[(size_t)v * m->dim + j] = displacement(&b, h) * 0.1;
      move_report mr;
      if (!mesh_move(m, disp, fixed, &mr, err))
        for (size_t i = 0; i < (size_t)m->nvert * m->dim; i++) UFUZZ_CHECK(isfinite(m->x[i]), "finite coordinates after motion");
    }
    free(fixed);
    free(disp);
  }
  mesh_free(m);
  return 0;
}

#ifdef LUGAL_LIBFUZZER
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) { return fuzz_untangle_run(data, size); }
#endif
