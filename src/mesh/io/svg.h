/* svg.h — SVG pictures of 2D meshes coloured by a per-cell value, and histograms */
#ifndef LUGAL_SVG_H
#define LUGAL_SVG_H
#include "../mesh.h"
/* cells coloured by val over [lo, hi]; invalid cells (non-positive area or corner
 * Jacobian) outlined in red */
int mesh_write_svg(const mesh *m, const char *path, const double *val, double lo, double hi,
                   const char *title, char *err);
int write_svg_histogram(const char *path, const int *counts, int nbins, double lo, double hi,
                        const char *title, char *err);
#endif
