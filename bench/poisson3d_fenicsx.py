"""bench/poisson3d_fenicsx.py [N] — FEniCSx counterpart of bench/poisson3d.lua: -Δu = f on
the unit cube (N×N×N cubes, 6 tetrahedra each), u = sin(πx) sin(πy) sin(πz), u = 0 on the
boundary, P1, CG + GAMG to a relative residual of 1e-8, then the L2 error (degree 6, as in
bench/poisson3d.lua: its own estimate takes 1000 points per cell)."""
import sys

from mpi4py import MPI
import numpy as np
import dolfinx
import dolfinx.fem.petsc
import ufl
from petsc4py import PETSc

N = int(sys.argv[1]) if len(sys.argv) > 1 else 64
mesh = dolfinx.mesh.create_unit_cube(MPI.COMM_WORLD, N, N, N, dolfinx.mesh.CellType.tetrahedron)
V = dolfinx.fem.FunctionSpace(mesh, ("Lagrange", 1))
u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
x = ufl.SpatialCoordinate(mesh)
exact = ufl.sin(ufl.pi * x[0]) * ufl.sin(ufl.pi * x[1]) * ufl.sin(ufl.pi * x[2])
mesh.topology.create_connectivity(2, 3)
facets = dolfinx.mesh.exterior_facet_indices(mesh.topology)
dofs = dolfinx.fem.locate_dofs_topological(V, 2, facets)
bc = dolfinx.fem.dirichletbc(PETSc.ScalarType(0), dofs, V)
problem = dolfinx.fem.petsc.LinearProblem(ufl.inner(ufl.grad(u), ufl.grad(v)) * ufl.dx, 3 * ufl.pi**2 * exact * v * ufl.dx,
                                          bcs=[bc], petsc_options={"ksp_type": "cg", "pc_type": "gamg", "ksp_rtol": 1e-8})
uh = problem.solve()
its = problem.solver.getIterationNumber()
e = uh - exact
l2 = np.sqrt(mesh.comm.allreduce(dolfinx.fem.assemble_scalar(dolfinx.fem.form(e**2 * ufl.dx(metadata={"quadrature_degree": 6}))), op=MPI.SUM))
import resource
hwm = mesh.comm.allreduce(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, op=MPI.MAX)
if mesh.comm.rank == 0:
    print("fenicsx poisson3d N=%d P1 dofs=%d iterations=%d L2=%.6e ranks=%d peak_rss_mb_rank=%.0f" % (
        N, V.dofmap.index_map.size_global, its, l2, mesh.comm.size, hwm))
