"""tests/data/gen_verdict.py tri|tet — regenerates tests/data/verdict_tri.txt or
verdict_tet.txt: reference values of VTK 9.1's vtkMeshQuality (Verdict) metrics on a
fixed set of cells (regular, degenerate-ish, inverted, 40 random), so that the lugal tests
compare with ParaView's numbers without depending on VTK at run time. Run with Debian's
python3-vtk9:
    /usr/bin/python3 tests/data/gen_verdict.py tri > tests/data/verdict_tri.txt
    /usr/bin/python3 tests/data/gen_verdict.py tet > tests/data/verdict_tet.txt
Size-relative metrics (RelativeSizeSquared, ShapeAndSize) are left out, as in issue 3."""
import random
import sys

import vtk

s3 = 3 ** 0.5
KINDS = {
    "tri": dict(
        setter="SetTriangleQualityMeasureTo", celltype=vtk.VTK_TRIANGLE, seed=20261122,
        metrics=["Area", "AspectFrobenius", "AspectRatio", "Condition", "Distortion", "EdgeRatio",
                 "MaxAngle", "MinAngle", "RadiusRatio", "ScaledJacobian", "Shape"],
        fixed=[[(0, 0, 0), (1, 0, 0), (0.5, s3 / 2, 0)], [(0, 0, 0), (1, 0, 0), (0, 1, 0)],
               [(0, 0, 0), (4, 0, 0), (2, 0.1, 0)], [(0, 0, 0), (1, 0, 0), (1, 1e-3, 0)],
               [(0, 0, 0), (0, 1, 0), (1, 0, 0)]],                       # last: clockwise
        random=lambda: [(random.uniform(-2, 2), random.uniform(-2, 2), 0.0) for _ in range(3)]),
    "tet": dict(
        setter="SetTetQualityMeasureTo", celltype=vtk.VTK_TETRA, seed=112226,
        metrics=["AspectBeta", "AspectFrobenius", "AspectGamma", "AspectRatio", "CollapseRatio", "Condition",
                 "Distortion", "EdgeRatio", "Jacobian", "MinAngle", "RadiusRatio", "ScaledJacobian", "Shape",
                 "Volume"],
        fixed=[[(0, 0, 0), (1, 0, 0), (0.5, s3 / 2, 0), (0.5, s3 / 6, (2 / 3) ** 0.5)],
               [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)],
               [(0, 0, 0), (1, 0, 0.05), (1, 1, 0), (0, 1, 0.05)],        # sliver
               [(0, 0, 0), (0.01, 0, 0), (0, 0.01, 0), (1, 1, 1)],        # needle
               [(0, 0, 0), (0, 1, 0), (1, 0, 0), (0, 0, 1)]],             # inverted
        random=lambda: [tuple(random.uniform(-1, 1) for _ in range(3)) for _ in range(4)]),
}

kind = KINDS[sys.argv[1] if len(sys.argv) > 1 else "tri"]
random.seed(kind["seed"])
cells = kind["fixed"] + [kind["random"]() for _ in range(40)]
nv = len(cells[0])
pts = vtk.vtkPoints()
pts.SetDataTypeToDouble()  # the default float32 would round the coordinates
for c in cells:
    for p in c:
        pts.InsertNextPoint(*p)
grid = vtk.vtkUnstructuredGrid()
grid.SetPoints(pts)
for k in range(len(cells)):
    grid.InsertNextCell(kind["celltype"], nv, [nv * k + i for i in range(nv)])
values = {}
for name in kind["metrics"]:
    q = vtk.vtkMeshQuality()
    q.SetInputData(grid)
    getattr(q, kind["setter"] + name)()
    q.Update()
    arr = q.GetOutput().GetCellData().GetArray("Quality")
    values[name] = [arr.GetValue(i) for i in range(len(cells))]
dim = 2 if kind["celltype"] == vtk.VTK_TRIANGLE else 3
print("# VTK %s vtkMeshQuality metrics; columns: %d coordinates then %s"
      % (vtk.vtkVersion.GetVTKVersion(), nv * dim, " ".join(kind["metrics"])))
for k, c in enumerate(cells):
    coords = " ".join("%.17g" % x for p in c for x in p[:dim])
    print(coords + " " + " ".join("%.17g" % values[m][k] for m in kind["metrics"]))
