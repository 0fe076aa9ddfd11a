/* lugal_mesh.c — the `lugal-mesh` command-line tool. It uses src/mesh only (no PETSc, no
 * Lua): mesh quality tables, SVG pictures and histograms, VTU output. */
#include "../../config.h"
#include "../io/io.h"
#include "../quality/quality.h"
#include "../io/svg.h"
#include "../untangle/untangle.h"

#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static void usage(FILE *f) {
  fprintf(f, "usage: lugal-mesh quality FILE.msh [--measure NAME] [--svg HISTOGRAM.svg]\n"
             "                  [--picture MESH.svg] [--vtu OUT.vtu] [--bins N]\n"
             "       lugal-mesh untangle IN.msh OUT.msh [--beta B] [--boundary slide|fixed]\n"
             "                  [--placement chebyshev|corners] [--max-iterations N] [--reference REST.msh]\n"
             "                  [--motion-weight W] [--no-global] [--report] [--progress S]\n"
             "       lugal-mesh smooth IN.msh OUT.msh [--measure NAME] [--iterations N]\n"
             "                  [--method auto|local|global|energy] [--reference REST.msh] [--boundary slide|fixed]\n"
             "                  [--optimizer auto|newton|lbfgs] [--sliding best|optimizer|local] [--progress S]\n"
             "       lugal-mesh --version | --help\n\n"
             "untangle and smooth print a progress line on stderr every S seconds (default 2; 0:\n"
             "none) of a run that takes longer.\n\n"
             "quality   prints min, mean, max and the worst cell of every measure that applies to\n"
             "          the mesh's cells, and the number of inverted or degenerate cells;\n"
             "          --measure chooses the measure for the pictures (default mean_ratio for\n"
             "          simplices, scaled_jacobian otherwise); --svg writes its histogram,\n"
             "          --picture the mesh coloured by it with invalid cells outlined in red (2D),\n"
             "          --vtu every measure as cell data for ParaView.\n"
             "untangle  repairs inverted cells by moving vertices (feasible set, optimization,\n"
             "          feasible set with J >= beta) and writes OUT.msh (MSH 2.2); --report prints\n"
             "          each stage; exit status 3 when invalid cells remain; --reference REST.msh\n"
             "          makes the global stage aim at each cell's shape in REST.msh;\n"
             "          --motion-weight W weighs the distance to the input (smallest motion),\n"
             "          --no-global keeps to the local stages.\n"
             "smooth    raises the quality (default mean_ratio, corner_condition for quads and\n"
             "          hexes) without ever lowering the minimum; the mesh must be valid;\n"
             "          --method auto (default) runs local, then energy when the minimum stays\n"
             "          below 0.3; local moves one vertex at a time, global all interior\n"
             "          vertices together by L-BFGS on the sum of 1/quality, energy the same\n"
             "          without the floor on the minimum during the descent (only validity), kept\n"
             "          when its minimum beats the input's: for bent and anisotropic meshes;\n"
             "          --optimizer (energy) newton takes projected Newton steps, lbfgs L-BFGS\n"
             "          ones, auto (default) Newton in 2D and L-BFGS in 3D;\n"
             "          --sliding (energy, sliding boundary) optimizer moves the boundary inside\n"
             "          the optimizer, local by guarded steps between its rounds, best (default)\n"
             "          runs both and keeps the higher minimum;\n"
             "          --reference REST.msh (energy; the mean ratio on simplices, the corner\n"
             "          condition on quadrilaterals and hexahedra) aims at each cell's shape in\n"
             "          REST.msh, the same mesh at rest, instead of regular cells.\n");
}

/* an integer option in lo..hi, or -1 with a message */
static int int_option(const char *cmd, const char *opt, const char *v, long lo, long hi) {
  char *end;
  errno = 0;
  long x = strtol(v, &end, 10);
  if (end == v || *end || errno || x < lo || x > hi) {
    fprintf(stderr, "lugal-mesh %s: %s must be an integer from %ld to %ld, got %s\n", cmd, opt, lo, hi, v);
    return -1;
  }
  return (int)x;
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
    else if (!strcmp(a, "--bins") && has) {
      if ((bins = int_option("quality", "--bins", argv[++i], 1, 1000)) < 0) return 2;
    }
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

static int parse_boundary(const char *cmd, const char *v) {
  if (!strcmp(v, "slide")) return 1;
  if (!strcmp(v, "fixed")) return 0;
  fprintf(stderr, "lugal-mesh %s: --boundary must be slide or fixed, got %s\n", cmd, v);
  return -1;
}

/* untangle and smooth: IN OUT and options */
static int repair_cmd(const char *cmd, int argc, char **argv) {
  const char *in = NULL, *out = NULL, *measure = NULL, *refpath = NULL;
  untangle_opts uo;
  untangle_defaults(&uo);
  int report = 0, iterations = 20, slide = 1, global = 0, energy = 0, method_given = 0, optimizer = SMOOTH_AUTO, then_energy = 1,
      sliding = -1;
  double progress = 2;
  for (int i = 0; i < argc; i++) {
    const char *a = argv[i];
    int has = i + 1 < argc;
    char *end = NULL;
    if (!strcmp(a, "--beta") && has) {
      uo.beta = strtod(argv[++i], &end);
      if (end == argv[i] || *end || !(uo.beta >= 0) || !isfinite(uo.beta)) {
        fprintf(stderr, "lugal-mesh %s: --beta must be a finite number >= 0, got %s\n", cmd, argv[i]);
        return 2;
      }
    } else if (!strcmp(a, "--motion-weight") && has && !strcmp(cmd, "untangle")) {
      uo.motion_weight = strtod(argv[++i], &end);
      if (end == argv[i] || *end || !(uo.motion_weight >= 0) || !isfinite(uo.motion_weight)) {
        fprintf(stderr, "lugal-mesh untangle: --motion-weight must be a finite number >= 0, got %s\n", argv[i]);
        return 2;
      }
    } else if (!strcmp(a, "--progress") && has) {
      progress = strtod(argv[++i], &end);
      if (end == argv[i] || *end || !(progress >= 0) || !isfinite(progress)) {
        fprintf(stderr, "lugal-mesh %s: --progress must be the seconds between progress lines (>= 0; 0: none), got %s\n", cmd,
                argv[i]);
        return 2;
      }
    } else if (!strcmp(a, "--no-global") && !strcmp(cmd, "untangle")) {
      uo.no_global = 1;
    } else if (!strcmp(a, "--boundary") && has) {
      if ((slide = parse_boundary(cmd, argv[++i])) < 0) return 2;
    } else if (!strcmp(a, "--placement") && has && !strcmp(cmd, "untangle")) {
      const char *v = argv[++i];
      if (!strcmp(v, "chebyshev")) uo.placement = 0;
      else if (!strcmp(v, "corners")) uo.placement = 1;
      else { fprintf(stderr, "lugal-mesh untangle: --placement must be chebyshev or corners\n"); return 2; }
    } else if (!strcmp(a, "--method") && has && !strcmp(cmd, "smooth")) {
      const char *v = argv[++i];
      method_given = 1;
      then_energy = !strcmp(v, "auto");
      if (!strcmp(v, "local") || !strcmp(v, "auto")) global = 0;
      else if (!strcmp(v, "global")) global = 1;
      else if (!strcmp(v, "energy")) global = energy = 1;
      else { fprintf(stderr, "lugal-mesh smooth: --method must be auto, local, global or energy\n"); return 2; }
    } else if (!strcmp(a, "--sliding") && has && !strcmp(cmd, "smooth")) {
      if ((sliding = smooth_sliding_from_name(argv[++i])) < 0) {
        fprintf(stderr, "lugal-mesh smooth: --sliding must be best, optimizer or local\n");
        return 2;
      }
    } else if (!strcmp(a, "--optimizer") && has && !strcmp(cmd, "smooth")) {
      if ((optimizer = smooth_optimizer_from_name(argv[++i])) < 0) {
        fprintf(stderr, "lugal-mesh smooth: --optimizer must be auto, newton or lbfgs\n");
        return 2;
      }
    } else if (!strcmp(a, "--max-iterations") && has) {
      if ((uo.max_iterations = int_option(cmd, "--max-iterations", argv[++i], 1, 1000000)) < 0) return 2;
    } else if (!strcmp(a, "--iterations") && has) {
      if ((iterations = int_option(cmd, "--iterations", argv[++i], 1, 1000000)) < 0) return 2;
    } else if (!strcmp(a, "--reference") && has) {
      refpath = argv[++i];
    } else if (!strcmp(a, "--measure") && has) measure = argv[++i];
    else if (!strcmp(a, "--report")) report = 1;
    else if (a[0] == '-') { fprintf(stderr, "lugal-mesh %s: unknown or incomplete option %s\n", cmd, a); return 2; }
    else if (!in) in = a;
    else if (!out) out = a;
    else { fprintf(stderr, "lugal-mesh %s: too many files (%s)\n", cmd, a); return 2; }
  }
  if (!in || !out) { usage(stderr); return 2; }
  char err[MESH_ERRLEN];
  mesh *m = mesh_read_gmsh(in, err);
  if (!m) { fprintf(stderr, "lugal-mesh: %s\n", err); return 1; }
  int rc = 0;
  mesh *ref = NULL;
  if (refpath) {
    /* reference shapes: the same mesh in its rest configuration */
    if (!(ref = mesh_read_gmsh(refpath, err))) { fprintf(stderr, "lugal-mesh: %s\n", err); mesh_free(m); return 1; }
    if (ref->type != m->type || ref->nvert != m->nvert || ref->ncell != m->ncell ||
        memcmp(ref->cells, m->cells, sizeof(int) * (size_t)m->ncell * (size_t)m->nvc)) {
      fprintf(stderr, "lugal-mesh %s: the reference %s must be the same mesh (same cells) as %s\n", cmd, refpath, in);
      mesh_free(ref); mesh_free(m);
      return 2;
    }
  }
  if (!strcmp(cmd, "untangle")) {
    untangle_report r;
    uo.slide = slide;
    uo.verbose = report;
    uo.progress = progress; /* a line on stderr every so many seconds of a long run */
    uo.xref = ref ? ref->x : NULL;
    int bad = mesh_untangle(m, &uo, &r, err);
    mesh_free(ref);
    if (bad) { fprintf(stderr, "lugal-mesh untangle: %s\n", err); mesh_free(m); return 1; }
    if (!report) untangle_report_print(&r, m);
    rc = r.invalid_after ? 3 : 0;
  } else {
    /* reference shapes are the energy method's */
    if (ref && !method_given) global = energy = 1;
    if (optimizer != SMOOTH_AUTO && !energy) {
      fprintf(stderr, "lugal-mesh smooth: --optimizer needs --method energy (or --reference)\n");
      mesh_free(ref); mesh_free(m);
      return 2;
    }
    smooth_opts so = {measure ? quality_from_name(measure) : smooth_energy_measure(m->type), iterations, slide, report, global,
                      energy, ref ? ref->x : NULL, optimizer, sliding < 0 ? SMOOTH_SLIDE_NONE : sliding, then_energy,
                      progress};
    if (so.measure < 0) { fprintf(stderr, "lugal-mesh smooth: unknown measure %s\n", measure); mesh_free(ref); mesh_free(m); return 2; }
    if (sliding >= 0 && !smooth_has_sliding_passes(m, &so)) {
      fprintf(stderr, "lugal-mesh smooth: --sliding needs --method energy with a sliding boundary, the measure %s and no "
                      "--reference\n", quality_name(smooth_energy_measure(m->type)));
      mesh_free(ref);
      mesh_free(m);
      return 2;
    }
    smooth_report r;
    int bad = mesh_smooth(m, &so, &r, err);
    mesh_free(ref);
    if (bad) { fprintf(stderr, "lugal-mesh smooth: %s\n", err); mesh_free(m); return 1; }
    printf("smooth (%s%s): %s%s min %.4g -> %.4g, mean %.4g -> %.4g, %d vertices moved, %d %s, %.3f s\n",
           smooth_method_label(&so, &r), smooth_sliding_label(&r),
           quality_name(so.measure), refpath ? " relative to the reference" : "",
           r.min_before, r.min_after, r.mean_before, r.mean_after,
           r.moved, r.sweeps, global ? "rounds" : "sweeps", r.seconds);
  }
  if (mesh_write_gmsh(m, out)) { fprintf(stderr, "lugal-mesh: %s\n", m->err); rc = 1; }
  else printf("wrote %s%s\n", out, rc == 3 ? " (invalid cells remain)" : "");
  mesh_free(m);
  return rc;
}

int main(int argc, char **argv) {
  if (argc < 2) { usage(stderr); return 2; }
  if (!strcmp(argv[1], "--help") || !strcmp(argv[1], "-h")) { usage(stdout); return 0; }
  if (!strcmp(argv[1], "--version")) { printf("lugal-mesh %s\n", LUGAL_VERSION); return 0; }
  outfile_on_signals(); /* a signal removes the temporary files; ulimit -f gives EFBIG */
  if (!strcmp(argv[1], "quality")) return quality_cmd(argc - 2, argv + 2);
  if (!strcmp(argv[1], "untangle") || !strcmp(argv[1], "smooth")) return repair_cmd(argv[1], argc - 2, argv + 2);
  fprintf(stderr, "lugal-mesh: unknown command %s\n", argv[1]);
  usage(stderr);
  return 2;
}
