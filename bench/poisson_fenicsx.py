"""bench/poisson_fenicsx.py [n] — FEniCSx counterpart of examples/poisson.lua: P1 Poisson
on an n×n unit square (right diagonals), u = sin(πx) sin(πy), prints L2 and H1 errors and
writes the solution (VTK), so that whole-process times compare the same work."""
import sys

from mpi4py import MPI
import numpy as np
import dolfinx
import dolfinx.fem.petsc
import ufl
from petsc4py import PETSc

n = int(sys.argv[1]) if len(sys.argv) > 1 else 64
mesh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, n, n, dolfinx.mesh.CellType.triangle)
V = dolfinx.fem.FunctionSpace(mesh, ("Lagrange", 1))
u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
x = ufl.SpatialCoordinate(mesh)
exact = ufl.sin(ufl.pi * x[0]) * ufl.sin(ufl.pi * x[1])
f = 2 * ufl.pi**2 * exact
facets = dolfinx.mesh.locate_entities_boundary(mesh, 1, lambda X: np.full(X.shape[1], True))
dofs = dolfinx.fem.locate_dofs_topological(V, 1, facets)
bc = dolfinx.fem.dirichletbc(PETSc.ScalarType(0), dofs, V)
problem = dolfinx.fem.petsc.LinearProblem(ufl.inner(ufl.grad(u), ufl.grad(v)) * ufl.dx, f * v * ufl.dx,
                                          bcs=[bc], petsc_options={"ksp_type": "preonly", "pc_type": "lu"})
uh = problem.solve()
e = uh - exact
l2 = np.sqrt(mesh.comm.allreduce(dolfinx.fem.assemble_scalar(dolfinx.fem.form(e**2 * ufl.dx)), op=MPI.SUM))
h1 = np.sqrt(mesh.comm.allreduce(dolfinx.fem.assemble_scalar(dolfinx.fem.form(ufl.inner(ufl.grad(e), ufl.grad(e)) * ufl.dx)), op=MPI.SUM))
print("fenicsx poisson: %dx%d P1: L2 error %.3e, H1 error %.3e" % (n, n, l2, h1))
with dolfinx.io.VTKFile(mesh.comm, "poisson_fenicsx.pvd", "w") as vtk:
    vtk.write_function(uh)
