/* lugal_mesh.c — the `lugal-mesh` command-line tool. It uses src/mesh only (no PETSc, no
 * Lua): mesh quality tables, SVG pictures and histograms, VTU output. */
#include "../config.h"
#include "mesh.h"
#include "quality.h"
#include "svg.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static void usage(FILE *f) {
  fprintf(f, "usage: lugal-mesh quality FILE.msh [--measure NAME] [--svg HISTOGRAM.svg]\n"
             "                  [--picture MESH.svg] [--vtu OUT.vtu] [--bins N]\n"
             "       lugal-mesh --version | --help\n\n"
             "quality   prints min, mean, max and the worst cell of every measure that applies to\n"
             "          the mesh's cells, and the number of inverted or degenerate cells;\n"
             "          --measure chooses the measure for the pictures (default mean_ratio for\n"
             "          simplices, scaled_jacobian otherwise); --svg writes its histogram,\n"
             "          --picture the mesh coloured by it with invalid cells outlined in red (2D),\n"
             "          --vtu every measure as cell data for ParaView.\n");
}

static int quality_cmd(int argc, char **argv) {
  const char *file = NULL, *measure = NULL, *svg = NULL, *pic = NULL, *vtu = NULL;
  int bins = 20;
  for (int i = 0; i < argc; i++) {
    const char *a = argv[i];
    int has = i + 1 < argc;
    if (!strcmp(a, "--measure") && has) measure = argv[++i];
    else if (!strcmp(a, "--svg") && has) svg = argv[++i];
    else if (!strcmp(a, "--picture") && has) pic = argv[++i];
    else if (!strcmp(a, "--vtu") && has) vtu = argv[++i];
    else if (!strcmp(a, "--bins") && has) bins = atoi(argv[++i]);
    else if (a[0] == '-') { fprintf(stderr, "lugal-mesh quality: unknown or incomplete option %s\n", a); return 2; }
    else if (!file) file = a;
    else { fprintf(stderr, "lugal-mesh quality: one mesh file at a time (got %s and %s)\n", file, a); return 2; }
  }
  if (!file) { usage(stderr); return 2; }
  if (bins < 1 || bins > 1000) { fprintf(stderr, "lugal-mesh quality: --bins must be 1..1000\n"); return 2; }
  char err[MESH_ERRLEN];
  mesh *m = mesh_read_gmsh(file, err);
  if (!m) { fprintf(stderr, "lugal-mesh: %s\n", err); return 1; }
  int simplex = m->type == CELL_TRIANGLE || m->type == CELL_TETRAHEDRON;
  int sel = quality_from_name(measure ? measure : simplex ? "mean_ratio" : "scaled_jacobian");
  if (sel < 0 || !quality_applies(sel, m->type) || quality_is_deformation(sel)) {
    char names[1024];
    quality_names(names, sizeof names);
    fprintf(stderr, "lugal-mesh quality: --measure %s does not apply to %s (measures: %s)\n", measure,
            cell_plural(m->type), names);
    mesh_free(m);
    return 2;
  }
  int ninv, ids[5];
  mesh_count_invalid(m, 5, ids, &ninv);
  printf("%s: %d %s, %d vertices, %d tagged boundary facets\n", file, m->ncell, cell_plural(m->type), m->nvert, m->nbf);
  printf("inverted or degenerate cells: %d", ninv);
  for (int i = 0; i < ninv && i < 5; i++) printf("%s%d", i ? ", " : " (cells ", ids[i] + 1);
  printf("%s\n\n  %-28s %12s %12s %12s %9s\n", ninv ? (ninv > 5 ? ", ...)" : ")") : "", "measure", "min", "mean", "max", "worst");
  /* one buffer per measure only when the VTU wants them all; otherwise one scratch buffer
   * (every measure of a 10-million-cell mesh at once would be gigabytes) */
  double *sv = mesh_big_alloc(sizeof(double) * (size_t)(m->ncell + 1));
  double *scratch = vtu ? NULL : mesh_big_alloc(sizeof(double) * (size_t)(m->ncell + 1));
  mesh_field fl[QM_COUNT];
  int nf = 0;
  if (!sv || (!vtu && !scratch)) { fprintf(stderr, "lugal-mesh: out of memory\n"); mesh_free(m); return 1; }
  for (int q = 0; q < QM_COUNT; q++) {
    if (!quality_applies(q, m->type) || quality_is_deformation(q)) continue;
    double *v = q == sel ? sv : vtu ? mesh_big_alloc(sizeof(double) * (size_t)(m->ncell + 1)) : scratch;
    if (!v) { fprintf(stderr, "lugal-mesh: out of memory for %s\n", quality_name(q)); continue; }
    if (mesh_quality(m, q, NULL, v, err)) {
      fprintf(stderr, "lugal-mesh: %s\n", err);
      if (vtu && v != sv) mesh_big_free(v);
      continue;
    }
    quality_stats st;
    quality_stats_compute(v, m->ncell, &st);
    printf("  %-28s %12.6g %12.6g %12.6g %9d\n", quality_name(q), st.min, st.mean, st.max,
           quality_worst_index(v, m->ncell, quality_larger_is_better(q)) + 1);
    if (vtu) {
      fl[nf].name = quality_name(q);
      fl[nf].ncomp = 1;
      fl[nf].on_cells = 1;
      fl[nf].val = v;
      nf++;
    }
  }
  int rc = 0;
  quality_stats st;
  quality_stats_compute(sv, m->ncell, &st);
  char title[256];
  snprintf(title, sizeof title, "%s: %s", file, quality_name(sel));
  if (svg) {
    int *counts = calloc((size_t)bins, sizeof(int));
    quality_histogram(sv, m->ncell, bins, st.min, st.max, counts);
    if (write_svg_histogram(svg, counts, bins, st.min, st.max, title, err)) { fprintf(stderr, "lugal-mesh: %s\n", err); rc = 1; }
    else printf("\nhistogram of %s: %s\n", quality_name(sel), svg);
    free(counts);
  }
  if (pic) {
    if (mesh_write_svg(m, pic, sv, st.min, st.max, title, err)) { fprintf(stderr, "lugal-mesh: %s\n", err); rc = 1; }
    else printf("picture coloured by %s: %s\n", quality_name(sel), pic);
  }
  if (vtu) {
    if (mesh_write_vtu(m, vtu, nf, fl)) { fprintf(stderr, "lugal-mesh: %s\n", m->err); rc = 1; }
    else printf("every measure as cell data: %s\n", vtu);
  }
  for (int i = 0; i < nf; i++)
    if (fl[i].val != sv) mesh_big_free((double *)fl[i].val);
  mesh_big_free(sv);
  mesh_big_free(scratch);
  mesh_free(m);
  return rc;
}

int main(int argc, char **argv) {
  if (argc < 2) { usage(stderr); return 2; }
  if (!strcmp(argv[1], "--help") || !strcmp(argv[1], "-h")) { usage(stdout); return 0; }
  if (!strcmp(argv[1], "--version")) { printf("lugal-mesh %s\n", LUGAL_VERSION); return 0; }
  if (!strcmp(argv[1], "quality")) return quality_cmd(argc - 2, argv + 2);
  fprintf(stderr, "lugal-mesh: unknown command %s\n", argv[1]);
  usage(stderr);
  return 2;
}
