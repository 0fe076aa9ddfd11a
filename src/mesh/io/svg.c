/* svg.c — pictures for people: a 2D mesh with cells coloured by a per-cell value and
 * invalid cells outlined in red, and a histogram of a per-cell value. Plain SVG 1.1. */
#include "svg.h"
#include "outfile.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

/* a perceptually ordered map (viridis stops): t in [0, 1] → rgb */
static void colormap(double t, int *r, int *g, int *b) {
  static const double stops[6][3] = {{68, 1, 84}, {65, 68, 135}, {42, 120, 142},
                                     {34, 168, 132}, {122, 209, 81}, {253, 231, 37}};
  if (!(t >= 0)) t = 0;
  if (t > 1) t = 1;
  double s = t * 5;
  int i = (int)s;
  if (i > 4) i = 4;
  double f = s - i;
  *r = (int)lround(stops[i][0] + f * (stops[i + 1][0] - stops[i][0]));
  *g = (int)lround(stops[i][1] + f * (stops[i + 1][1] - stops[i][1]));
  *b = (int)lround(stops[i][2] + f * (stops[i + 1][2] - stops[i][2]));
}

static void xml_text(FILE *f, const char *s) {
  for (; *s; s++) {
    if (*s == '<') fputs("&lt;", f);
    else if (*s == '>') fputs("&gt;", f);
    else if (*s == '&') fputs("&amp;", f);
    else fputc(*s, f);
  }
}

int mesh_write_svg(const mesh *m, const char *path, const double *val, double lo, double hi,
                   const char *title, char *err) {
  if (m->dim != 2) { snprintf(err, MESH_ERRLEN, "pictures are for 2D meshes (this one is %dD)", m->dim); return 1; }
  outfile o;
  if (outfile_open(&o, path, err, MESH_ERRLEN)) return 1;
  FILE *f = o.f;
  double xmin = INFINITY, xmax = -INFINITY, ymin = INFINITY, ymax = -INFINITY;
  for (int v = 0; v < m->nvert; v++) {
    xmin = fmin(xmin, m->x[2 * v]); xmax = fmax(xmax, m->x[2 * v]);
    ymin = fmin(ymin, m->x[2 * v + 1]); ymax = fmax(ymax, m->x[2 * v + 1]);
  }
  double w = xmax - xmin, h = ymax - ymin, size = fmax(w, h);
  if (!(size > 0)) size = 1;
  const double W = 800, margin = 20, legend = 70;
  double sc = (W - 2 * margin) / size;
  double pw = w * sc + 2 * margin + legend, ph = h * sc + 2 * margin + 30;
  fprintf(f, "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
             "<svg xmlns=\"http://www.w3.org/2000/svg\" version=\"1.1\" width=\"%.0f\" height=\"%.0f\" "
             "viewBox=\"0 0 %.0f %.0f\">\n<rect width=\"100%%\" height=\"100%%\" fill=\"white\"/>\n",
          pw, ph, pw, ph);
  fprintf(f, "<text x=\"%.0f\" y=\"18\" font-family=\"sans-serif\" font-size=\"14\">", margin);
  xml_text(f, title ? title : "");
  fprintf(f, "</text>\n<g stroke=\"#555\" stroke-width=\"0.5\" stroke-linejoin=\"round\">\n");
  int ninv;
  mesh_count_invalid(m, 0, NULL, &ninv);
#define PX(v) (margin + (m->x[2 * (v)] - xmin) * sc)
#define PY(v) (30 + margin + (ymax - m->x[2 * (v) + 1]) * sc)
  for (int pass = 0; pass < 2; pass++) {
    if (pass == 1) fprintf(f, "</g>\n<g fill=\"none\" stroke=\"#e00\" stroke-width=\"2.5\" stroke-linejoin=\"round\">\n");
    for (int c = 0; c < m->ncell; c++) {
      const int *v = m->cells + (size_t)c * m->nvc;
      int invalid = !(mesh_cell_relative_validity(m, c) > 1e-13);
      if (pass == 1 && !invalid) continue;
      fprintf(f, "<polygon points=\"");
      for (int i = 0; i < m->nvc; i++) fprintf(f, "%s%.2f,%.2f", i ? " " : "", PX(v[i]), PY(v[i]));
      if (pass == 0) {
        int r, g, b;
        double t = hi > lo ? (val[c] - lo) / (hi - lo) : 1;
        colormap(t, &r, &g, &b);
        fprintf(f, "\" fill=\"rgb(%d,%d,%d)\"/>\n", r, g, b);
      } else fprintf(f, "\"/>\n");
    }
  }
#undef PX
#undef PY
  fprintf(f, "</g>\n");
  /* colour bar */
  double bx = pw - legend + 10, by = 30 + margin, bh = fmin(300, h * sc);
  for (int i = 0; i < 50; i++) {
    int r, g, b;
    colormap(1 - i / 49.0, &r, &g, &b);
    fprintf(f, "<rect x=\"%.1f\" y=\"%.1f\" width=\"16\" height=\"%.2f\" fill=\"rgb(%d,%d,%d)\"/>\n", bx,
            by + i * bh / 50, bh / 50 + 0.5, r, g, b);
  }
  fprintf(f, "<text x=\"%.1f\" y=\"%.1f\" font-family=\"sans-serif\" font-size=\"11\">%.3g</text>\n", bx + 20, by + 9, hi);
  fprintf(f, "<text x=\"%.1f\" y=\"%.1f\" font-family=\"sans-serif\" font-size=\"11\">%.3g</text>\n", bx + 20, by + bh, lo);
  if (ninv)
    fprintf(f, "<text x=\"%.1f\" y=\"%.1f\" font-family=\"sans-serif\" font-size=\"11\" fill=\"#e00\">%d invalid</text>\n",
            bx - 10, by + bh + 20, ninv);
  fprintf(f, "</svg>\n");
  return outfile_commit(&o, err, MESH_ERRLEN);
}

int write_svg_histogram(const char *path, const int *counts, int nbins, double lo, double hi,
                        const char *title, char *err) {
  outfile o;
  if (outfile_open(&o, path, err, MESH_ERRLEN)) return 1;
  FILE *f = o.f;
  const double W = 640, H = 400, L = 60, R = 20, T = 40, B = 50;
  int cmax = 1;
  long total = 0;
  for (int i = 0; i < nbins; i++) {
    if (counts[i] > cmax) cmax = counts[i];
    total += counts[i];
  }
  fprintf(f, "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
             "<svg xmlns=\"http://www.w3.org/2000/svg\" version=\"1.1\" width=\"%.0f\" height=\"%.0f\">\n"
             "<rect width=\"100%%\" height=\"100%%\" fill=\"white\"/>\n"
             "<text x=\"%.0f\" y=\"24\" font-family=\"sans-serif\" font-size=\"15\">", W, H, L);
  xml_text(f, title ? title : "");
  fprintf(f, " (%ld cells)</text>\n", total);
  double pw = W - L - R, ph = H - T - B, bw = pw / nbins;
  for (int i = 0; i < nbins; i++) {
    double bh = ph * counts[i] / cmax;
    int r, g, b;
    colormap((i + 0.5) / nbins, &r, &g, &b);
    fprintf(f, "<rect x=\"%.2f\" y=\"%.2f\" width=\"%.2f\" height=\"%.2f\" fill=\"rgb(%d,%d,%d)\" stroke=\"white\" stroke-width=\"0.5\"/>\n",
            L + i * bw, T + ph - bh, bw, bh, r, g, b);
  }
  fprintf(f, "<g stroke=\"black\" stroke-width=\"1\"><line x1=\"%.0f\" y1=\"%.0f\" x2=\"%.0f\" y2=\"%.0f\"/>"
             "<line x1=\"%.0f\" y1=\"%.0f\" x2=\"%.0f\" y2=\"%.0f\"/></g>\n",
          L, T + ph, L + pw, T + ph, L, T, L, T + ph);
  for (int k = 0; k <= 4; k++) {
    double xv = lo + (hi - lo) * k / 4, px = L + pw * k / 4;
    fprintf(f, "<text x=\"%.1f\" y=\"%.1f\" font-family=\"sans-serif\" font-size=\"11\" text-anchor=\"middle\">%.3g</text>\n",
            px, T + ph + 16, xv);
    double yv = (double)cmax * k / 4.0, py = T + ph - ph * k / 4;
    fprintf(f, "<text x=\"%.1f\" y=\"%.1f\" font-family=\"sans-serif\" font-size=\"11\" text-anchor=\"end\">%.0f</text>\n",
            L - 6, py + 4, yv);
  }
  fprintf(f, "<text x=\"%.0f\" y=\"%.0f\" font-family=\"sans-serif\" font-size=\"12\" text-anchor=\"middle\">value</text>\n",
          L + pw / 2, H - 12);
  fprintf(f, "<text x=\"14\" y=\"%.0f\" font-family=\"sans-serif\" font-size=\"12\" transform=\"rotate(-90 14 %.0f)\" "
             "text-anchor=\"middle\">cells</text>\n</svg>\n", T + ph / 2, T + ph / 2);
  return outfile_commit(&o, err, MESH_ERRLEN);
}
