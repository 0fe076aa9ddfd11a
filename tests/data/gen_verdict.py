"""tests/data/gen_verdict.py tri|tet|quad|hex — regenerates tests/data/verdict_KIND.txt:
reference values of VTK 9.1's vtkMeshQuality (Verdict) metrics on a
fixed set of cells (regular, degenerate-ish, inverted, 40 random), so that the lugal tests
compare with ParaView's numbers without depending on VTK at run time. Run with Debian's
python3-vtk9:
    /usr/bin/python3 tests/data/gen_verdict.py tri > tests/data/verdict_tri.txt
    /usr/bin/python3 tests/data/gen_verdict.py tet > tests/data/verdict_tet.txt
    /usr/bin/python3 tests/data/gen_verdict.py quad > tests/data/verdict_quad.txt
    /usr/bin/python3 tests/data/gen_verdict.py hex > tests/data/verdict_hex.txt
Size-relative metrics (RelativeSizeSquared, ShapeAndSize) are left out, as in issue 3."""
import random
import sys

import vtk

s3 = 3 ** 0.5
CUBE = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]
KINDS = {
    "tri": dict(
        setter="SetTriangleQualityMeasureTo", celltype=vtk.VTK_TRIANGLE, seed=20261122,
        metrics=["Area", "AspectFrobenius", "AspectRatio", "Condition", "Distortion", "EdgeRatio",
                 "MaxAngle", "MinAngle", "RadiusRatio", "ScaledJacobian", "Shape"],
        fixed=[[(0, 0, 0), (1, 0, 0), (0.5, s3 / 2, 0)], [(0, 0, 0), (1, 0, 0), (0, 1, 0)],
               [(0, 0, 0), (4, 0, 0), (2, 0.1, 0)], [(0, 0, 0), (1, 0, 0), (1, 1e-3, 0)],
               [(0, 0, 0), (0, 1, 0), (1, 0, 0)]],                       # last: clockwise
        random=lambda k: [(random.uniform(-2, 2), random.uniform(-2, 2), 0.0) for _ in range(3)]),
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
        random=lambda k: [tuple(random.uniform(-1, 1) for _ in range(3)) for _ in range(4)]),
    "quad": dict(
        setter="SetQuadQualityMeasureTo", celltype=vtk.VTK_QUAD, seed=20261123,
        metrics=["Area", "AspectRatio", "Condition", "Distortion", "EdgeRatio", "Jacobian", "MaxAngle",
                 "MaxAspectFrobenius", "MaxEdgeRatios", "MedAspectFrobenius", "MinAngle", "Oddy",
                 "RadiusRatio", "ScaledJacobian", "Shape", "Shear", "Skew", "Stretch", "Taper", "Warpage"],
        fixed=[[(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)],
               [(0, 0, 0), (3, 0, 0), (3, 1, 0), (0, 1, 0)],             # rectangle
               [(0, 0, 0), (2, 0, 0), (2.5, 1, 0), (0.5, 1, 0)],         # parallelogram
               [(0, 0, 0), (3, 0, 0), (2, 1, 0), (1, 1, 0)],             # trapezoid
               [(0, 0, 0), (2, 0, 0), (0.5, 0.5, 0), (0, 2, 0)],         # non-convex dart
               [(0, 0, 0), (1, 0, 0), (0.5, 1, 0), (0.5, 1, 0)],         # collapsed: P3 = P2
               [(0, 0, 0), (0, 1, 0), (1, 1, 0), (1, 0, 0)],             # clockwise
               [(0, 0, 0), (1, 1, 0), (1, 0, 0), (0, 1, 0)],             # crossed (bow tie)
               [(0, 0, 0), (1, 0, 0), (2, 0, 0), (0, 1, 0)]],            # straight corner
        # 30 perturbed unit squares (mostly convex), then 10 arbitrary quadrilaterals
        random=lambda k: [(x + random.uniform(-0.3, 0.3), y + random.uniform(-0.3, 0.3), 0.0)
                          for x, y in ((0, 0), (1, 0), (1, 1), (0, 1))] if k < 30 else
        [(random.uniform(-2, 2), random.uniform(-2, 2), 0.0) for _ in range(4)]),
    "hex": dict(
        setter="SetHexQualityMeasureTo", celltype=vtk.VTK_HEXAHEDRON, seed=20261124,
        metrics=["Condition", "Diagonal", "Dimension", "Distortion", "EdgeRatio", "Jacobian",
                 "MaxAspectFrobenius", "MaxEdgeRatios", "MedAspectFrobenius", "Oddy", "ScaledJacobian",
                 "Shape", "Shear", "Skew", "Stretch", "Taper", "Volume"],
        fixed=[CUBE,
               [(x, 2 * y, 3 * z) for x, y, z in CUBE],                 # box
               [(x + 0.5 * y + 0.3 * z, y + 0.2 * z, z) for x, y, z in CUBE],   # parallelepiped
               [(x * (1 - 0.5 * z), y * (1 - 0.5 * z), z) for x, y, z in CUBE],  # tapered
               [(x, y, -z) for x, y, z in CUBE],                         # inverted
               [(x, y, 1e-3 * z) for x, y, z in CUBE]],                  # flat
        # unit cubes with vertices moved by up to 0.25 (30), then by up to 0.45 (10, some tangled)
        random=lambda k: [tuple(c + random.uniform(-0.25, 0.25) if k < 30 else c + random.uniform(-0.45, 0.45)
                                for c in p) for p in CUBE]),
}

kind = KINDS[sys.argv[1] if len(sys.argv) > 1 else "tri"]
random.seed(kind["seed"])
cells = kind["fixed"] + [kind["random"](k) for k in range(40)]
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
dim = 2 if kind["celltype"] in (vtk.VTK_TRIANGLE, vtk.VTK_QUAD) else 3
print("# VTK %s vtkMeshQuality metrics; columns: %d coordinates then %s"
      % (vtk.vtkVersion.GetVTKVersion(), nv * dim, " ".join(kind["metrics"])))
for k, c in enumerate(cells):
    coords = " ".join("%.17g" % x for p in c for x in p[:dim])
    print(coords + " " + " ".join("%.17g" % values[m][k] for m in kind["metrics"]))
