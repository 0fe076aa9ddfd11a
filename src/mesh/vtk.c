/* vtk.c — output for ParaView: the VTK XML unstructured-grid (.vtu) writer with point and
 * cell data, and .pvd collections for time series. Written through outfile.h. */
#include "mesh.h"
#include "outfile.h"

#include <stdio.h>
#include <string.h>

static void xml_name(FILE *f, const char *s) {
  for (; *s; s++) {
    if (*s == '"') fputs("&quot;", f);
    else if (*s == '&') fputs("&amp;", f);
    else if (*s == '<') fputs("&lt;", f);
    else if (*s == '>') fputs("&gt;", f);
    else fputc(*s, f);
  }
}

int mesh_write_vtu(mesh *m, const char *path, int nfield, const mesh_field *fl) {
  outfile o;
  if (outfile_open(&o, path, m->err, MESH_ERRLEN)) return 1;
  FILE *f = o.f;
  static const int vtk_type[] = {5, 9, 10, 12, 3};
  fprintf(f, "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"0.1\" "
             "byte_order=\"LittleEndian\">\n<UnstructuredGrid>\n"
             "<Piece NumberOfPoints=\"%d\" NumberOfCells=\"%d\">\n", m->nvert, m->ncell);
  for (int pass = 0; pass < 2; pass++) {
    int any = 0;
    for (int i = 0; i < nfield; i++) any |= fl[i].on_cells == pass;
    if (!any) continue;
    fprintf(f, pass ? "<CellData>\n" : "<PointData>\n");
    for (int i = 0; i < nfield; i++) {
      if (fl[i].on_cells != pass) continue;
      fprintf(f, "<DataArray type=\"Float64\" Name=\"");
      xml_name(f, fl[i].name);
      fprintf(f, "\" NumberOfComponents=\"%d\" format=\"ascii\">\n", fl[i].ncomp);
      int n = pass ? m->ncell : m->nvert;
      for (long k = 0; k < (long)n * fl[i].ncomp; k++)
        fprintf(f, "%.17g%c", fl[i].val[k], (k + 1) % fl[i].ncomp ? ' ' : '\n');
      fprintf(f, "</DataArray>\n");
    }
    fprintf(f, pass ? "</CellData>\n" : "</PointData>\n");
  }
  fprintf(f, "<Points>\n<DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"ascii\">\n");
  for (int i = 0; i < m->nvert; i++)
    fprintf(f, "%.17g %.17g %.17g\n", m->x[m->dim * i], m->dim >= 2 ? m->x[m->dim * i + 1] : 0.0,
            m->dim == 3 ? m->x[3 * i + 2] : 0.0);
  fprintf(f, "</DataArray>\n</Points>\n<Cells>\n"
             "<DataArray type=\"Int32\" Name=\"connectivity\" format=\"ascii\">\n");
  for (int c = 0; c < m->ncell; c++) {
    for (int j = 0; j < m->nvc; j++) fprintf(f, "%d ", m->cells[(size_t)c * m->nvc + j]);
    fputc('\n', f);
  }
  fprintf(f, "</DataArray>\n<DataArray type=\"Int32\" Name=\"offsets\" format=\"ascii\">\n");
  for (int c = 0; c < m->ncell; c++) fprintf(f, "%d\n", (c + 1) * m->nvc);
  fprintf(f, "</DataArray>\n<DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">\n");
  for (int c = 0; c < m->ncell; c++) fprintf(f, "%d\n", vtk_type[m->type]);
  fprintf(f, "</DataArray>\n</Cells>\n</Piece>\n</UnstructuredGrid>\n</VTKFile>\n");
  return outfile_commit(&o, m->err, MESH_ERRLEN);
}

int mesh_write_pvd(const char *pvd, int nstep, const double *times, char **files, char *err) {
  outfile o;
  if (outfile_open(&o, pvd, err, MESH_ERRLEN)) return 1;
  FILE *f = o.f;
  fprintf(f, "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\">\n<Collection>\n");
  for (int i = 0; i < nstep; i++) {
    /* the data set path is relative to the .pvd's folder */
    const char *slash = strrchr(files[i], '/');
    fprintf(f, "<DataSet timestep=\"%.17g\" part=\"0\" file=\"", times[i]);
    xml_name(f, slash ? slash + 1 : files[i]);
    fprintf(f, "\"/>\n");
  }
  fprintf(f, "</Collection>\n</VTKFile>\n");
  return outfile_commit(&o, err, MESH_ERRLEN);
}
