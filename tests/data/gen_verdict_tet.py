"""tests/data/gen_verdict_tet.py — regenerates tests/data/verdict_tet.txt: VTK 9.1's
vtkMeshQuality tetrahedron metrics (Verdict) on a fixed set of tetrahedra (regular, right,
sliver, needle, inverted, random). Run with Debian's python3-vtk9:
/usr/bin/python3 tests/data/gen_verdict_tet.py > tests/data/verdict_tet.txt"""
import random

import vtk

METRICS = ["AspectBeta", "AspectFrobenius", "AspectGamma", "AspectRatio", "CollapseRatio", "Condition",
           "Distortion", "EdgeRatio", "Jacobian", "MinAngle", "RadiusRatio", "ScaledJacobian", "Shape", "Volume"]
random.seed(112226)
s3 = 3 ** 0.5
tets = [[(0, 0, 0), (1, 0, 0), (0.5, s3 / 2, 0), (0.5, s3 / 6, (2 / 3) ** 0.5)],
        [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)],
        [(0, 0, 0), (1, 0, 0.05), (1, 1, 0), (0, 1, 0.05)],          # sliver
        [(0, 0, 0), (0.01, 0, 0), (0, 0.01, 0), (1, 1, 1)],          # needle
        [(0, 0, 0), (0, 1, 0), (1, 0, 0), (0, 0, 1)]]                # inverted
for _ in range(40):
    tets.append([tuple(random.uniform(-1, 1) for _ in range(3)) for _ in range(4)])
pts = vtk.vtkPoints()
pts.SetDataTypeToDouble()
grid = vtk.vtkUnstructuredGrid()
for t in tets:
    for p in t:
        pts.InsertNextPoint(*p)
grid.SetPoints(pts)
for k in range(len(tets)):
    grid.InsertNextCell(vtk.VTK_TETRA, 4, [4 * k + i for i in range(4)])
values = {}
for name in METRICS:
    q = vtk.vtkMeshQuality()
    q.SetInputData(grid)
    getattr(q, "SetTetQualityMeasureTo" + name)()
    q.Update()
    arr = q.GetOutput().GetCellData().GetArray("Quality")
    values[name] = [arr.GetValue(i) for i in range(len(tets))]
print("# VTK %s vtkMeshQuality tetrahedron metrics; columns: 12 coordinates then %s"
      % (vtk.vtkVersion.GetVTKVersion(), " ".join(METRICS)))
for k, t in enumerate(tets):
    print(" ".join("%.17g" % c for p in t for c in p) + " " + " ".join("%.17g" % values[m][k] for m in METRICS))
