"""bench/quality_vtk.py N — VTK counterpart of bench/quality.lua: the same N×N×N box of
6N^3 Kuhn tetrahedra (same vertex numbering, cell order and orientation as
lg.mesh.box), then vtkMeshQuality's tetrahedron Shape (Verdict's mean ratio) and
ScaledJacobian, timed single-threaded; prints cells per second and the mean values (which
must equal lugal's: same mesh, same measures)."""
import sys
import time

import numpy as np
import vtk
from vtk.util import numpy_support as ns

N = int(sys.argv[1]) if len(sys.argv) > 1 else 119
n1 = N + 1
t0 = time.perf_counter()
a, b, c = np.indices((n1, n1, n1)).reshape(3, -1)          # id = (a*n1 + b)*n1 + c
pts = np.column_stack((c / N, b / N, a / N)).astype(np.float64)
k, j, i = np.indices((N, N, N)).reshape(3, -1)               # cubes with i fastest
base = (k * n1 + j) * n1 + i
step = np.array([1, n1, n1 * n1])
perms = [(0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0)]
conn = np.empty((base.size, 6, 4), dtype=np.int64)
for p, (p0, p1, p2) in enumerate(perms):
    conn[:, p, 0] = base
    conn[:, p, 1] = base + step[p0]
    conn[:, p, 2] = base + step[p0] + step[p1]
    conn[:, p, 3] = base + step.sum()
conn = conn.reshape(-1, 4)
x = pts[conn]
det = np.einsum("ij,ij->i", x[:, 1] - x[:, 0], np.cross(x[:, 2] - x[:, 0], x[:, 3] - x[:, 0]))
neg = det < 0
conn[neg, 2], conn[neg, 3] = conn[neg, 3].copy(), conn[neg, 2].copy()
ncell = conn.shape[0]
grid = vtk.vtkUnstructuredGrid()
vpts = vtk.vtkPoints()
vpts.SetData(ns.numpy_to_vtk(pts, deep=1))
grid.SetPoints(vpts)
cells = vtk.vtkCellArray()
offsets = np.arange(0, 4 * ncell + 1, 4, dtype=np.int64)
cells.SetData(ns.numpy_to_vtkIdTypeArray(offsets, deep=1), ns.numpy_to_vtkIdTypeArray(conn.ravel().copy(), deep=1))
grid.SetCells(vtk.VTK_TETRA, cells)
tbuild = time.perf_counter() - t0
print("vtk %s: %d tetrahedra built in %.1f s" % (vtk.vtkVersion.GetVTKVersion(), ncell, tbuild))
for name, setter in (("mean_ratio (Shape)", "SetTetQualityMeasureToShape"),
                     ("scaled_jacobian (ScaledJacobian)", "SetTetQualityMeasureToScaledJacobian")):
    dt = float("inf")
    for _ in range(5):  # best of 5, as bench/quality.lua
        q = vtk.vtkMeshQuality()
        q.SetInputData(grid)
        getattr(q, setter)()
        t0 = time.perf_counter()
        q.Update()
        dt = min(dt, time.perf_counter() - t0)
    vals = ns.vtk_to_numpy(q.GetOutput().GetCellData().GetArray("Quality"))
    print("vtk %-34s %.3f s  %.1f M cells/s  mean %.12f  min %.12f" % (name, dt, ncell / dt / 1e6, vals.mean(), vals.min()))
