/* bench/mesh_passes.c [N] — the mesh room's passes that a first assembly or a P2 dof map
 * runs, on the unit cube in N×N×N cubes × 6 tetrahedra (default 64): the validity check as
 * two passes (mesh_hmax, mesh_count_invalid) and as one (mesh_validate), and the numbering
 * of the edges and faces (mesh_build_edges, mesh_build_faces) with a checksum of the
 * numbers (equal before and after a change of the algorithm means the same numbering).
 * Three rounds. Build and run, after make:
 *   cc -O2 -fopenmp -Isrc/mesh -o /tmp/mesh_passes bench/mesh_passes.c build/liblugal.a -lm -lz
 *   OMP_NUM_THREADS=1 /tmp/mesh_passes 64
 * (bench/RESULTS.md, "Setup again", issue 56) */
#include "mesh.h"
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

static double now_ms(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return t.tv_sec * 1e3 + t.tv_nsec * 1e-6;
}

int main(int argc, char **argv) {
  int N = argc > 1 ? atoi(argv[1]) : 64;
  mesh_box_opts o = {0};
  o.nx = o.ny = o.nz = N;
  o.x1 = o.y1 = o.z1 = 1;
  o.type = CELL_TETRAHEDRON;
  char err[MESH_ERRLEN];
  for (int r = 0; r < 3; r++) {
    mesh *m = mesh_box(&o, err);
    if (!m) { fprintf(stderr, "mesh_box: %s\n", err); return 1; }
    int ids[5], n1, n2;
    double t0 = now_ms(), h1 = mesh_hmax(m);
    double t1 = now_ms();
    mesh_count_invalid(m, 5, ids, &n1);
    double t2 = now_ms(), h2;
    mesh_validate(m, &h2, 5, ids, &n2);
    double t3 = now_ms();
    mesh_build_edges(m);
    double t4 = now_ms();
    mesh_build_faces(m);
    double t5 = now_ms();
    unsigned long es = 0, fs = 0;
    for (long i = 0; i < 6L * m->ncell; i++) es = es * 31 + (unsigned)m->cell_edges[i];
    for (long i = 0; i < 2L * m->nedge; i++) es = es * 17 + (unsigned)m->edges[i];
    for (long i = 0; i < 4L * m->ncell; i++) fs = fs * 31 + (unsigned)m->cell_faces[i];
    for (long i = 0; i < 3L * m->nface; i++) fs = fs * 17 + (unsigned)m->faces[i];
    printf("N=%d cells=%d: hmax %.1f ms + invalid %.1f ms (%.17g, %d) | validate %.1f ms (%.17g, %d) | edges %.1f ms (%d, %lx) | faces %.1f ms (%d, %lx)\n",
           N, m->ncell, t1 - t0, t2 - t1, h1, n1, t3 - t2, h2, n2, t4 - t3, m->nedge, es, t5 - t4, m->nface, fs);
    mesh_free(m);
  }
  return 0;
}
