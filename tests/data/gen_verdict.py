"""tests/data/gen_verdict.py — regenerates tests/data/verdict_tri.txt: reference values of
VTK 9.1's vtkMeshQuality triangle metrics (Verdict) on a fixed set of triangles, so that
the lugal tests compare with ParaView's numbers without depending on VTK at run time.
Run with Debian's python3-vtk9: /usr/bin/python3 tests/data/gen_verdict.py > tests/data/verdict_tri.txt
Size-relative metrics (RelativeSizeSquared, ShapeAndSize) are left out, as in issue 3."""
import random

import vtk

METRICS = ["Area", "AspectFrobenius", "AspectRatio", "Condition", "Distortion", "EdgeRatio",
           "MaxAngle", "MinAngle", "RadiusRatio", "ScaledJacobian", "Shape"]

random.seed(20261122)
tris = [[(0, 0), (1, 0), (0.5, 3 ** 0.5 / 2)], [(0, 0), (1, 0), (0, 1)], [(0, 0), (4, 0), (2, 0.1)],
        [(0, 0), (1, 0), (1, 1e-3)], [(0, 0), (0, 1), (1, 0)]]      # last: clockwise (inverted)
for _ in range(40):
    tris.append([(random.uniform(-2, 2), random.uniform(-2, 2)) for _ in range(3)])

pts = vtk.vtkPoints()
pts.SetDataTypeToDouble()  # the default float32 would round the coordinates
grid = vtk.vtkUnstructuredGrid()
for t in tris:
    ids = [pts.InsertNextPoint(x, y, 0.0) for x, y in t]
grid.SetPoints(pts)
for k in range(len(tris)):
    grid.InsertNextCell(vtk.VTK_TRIANGLE, 3, [3 * k, 3 * k + 1, 3 * k + 2])
values = {}
for name in METRICS:
    q = vtk.vtkMeshQuality()
    q.SetInputData(grid)
    getattr(q, "SetTriangleQualityMeasureTo" + name)()
    q.Update()
    arr = q.GetOutput().GetCellData().GetArray("Quality")
    values[name] = [arr.GetValue(i) for i in range(len(tris))]
print("# VTK %s vtkMeshQuality triangle metrics; columns: x0 y0 x1 y1 x2 y2 then %s"
      % (vtk.vtkVersion.GetVTKVersion(), " ".join(METRICS)))
for k, t in enumerate(tris):
    coords = " ".join("%.17g %.17g" % p for p in t)
    print(coords + " " + " ".join("%.17g" % values[m][k] for m in METRICS))
