"""bench/assembly_fenicsx.py N degree [repeats] [form] — FEniCSx counterpart of assembly.lua:
reassembly of the P<degree> stiffness matrix of -Δ (form laplace) or of vector P<degree>
linear elasticity (form elasticity) on the unit cube (N×N×N cubes, 6 tetrahedra each)
into an existing PETSc matrix, median of the repeats; form compilation and matrix creation
excluded and reported separately; first_s is the time to the first matrix (function space
with its dof map, matrix creation, first assembly), like lugal's."""
import sys
import time

from mpi4py import MPI
import dolfinx
import dolfinx.fem.petsc
import ufl
import numpy as np

N = int(sys.argv[1]) if len(sys.argv) > 1 else 32
p = int(sys.argv[2]) if len(sys.argv) > 2 else 1
reps = int(sys.argv[3]) if len(sys.argv) > 3 else 5
form = sys.argv[4] if len(sys.argv) > 4 else "laplace"
cell = sys.argv[5] if len(sys.argv) > 5 else "tetrahedron"

t0 = time.perf_counter()
mesh = dolfinx.mesh.create_unit_cube(MPI.COMM_WORLD, N, N, N, dolfinx.mesh.CellType.hexahedron if cell == "hexahedron"
                                     else dolfinx.mesh.CellType.tetrahedron)
tmesh = time.perf_counter() - t0
t0 = time.perf_counter()
if form in ("elasticity", "neohookean"):
    V = dolfinx.fem.VectorFunctionSpace(mesh, ("Lagrange", p))
else:
    V = dolfinx.fem.FunctionSpace(mesh, ("Lagrange", p))
tspace = time.perf_counter() - t0
u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
t0 = time.perf_counter()
if form == "neohookean":
    u0 = dolfinx.fem.Function(V)
    u0.interpolate(lambda X: np.vstack((0.1 * X[0] * X[1], -0.05 * X[1] * X[2], 0.08 * X[0] * X[2])))
    F = ufl.Identity(3) + ufl.grad(u0)
    Jd = ufl.det(F)
    psi = 0.5 * (ufl.tr(F.T * F) - 3) - ufl.ln(Jd) + 1.25 / 2 * ufl.ln(Jd) ** 2
    Pi = psi * ufl.dx(metadata={"quadrature_degree": 4})
    a = dolfinx.fem.form(ufl.derivative(ufl.derivative(Pi, u0, v), u0, u))
elif form == "elasticity":
    eps = lambda w: ufl.sym(ufl.grad(w))
    a = dolfinx.fem.form((2.0 * ufl.inner(eps(u), eps(v)) + 1.25 * ufl.div(u) * ufl.div(v)) * ufl.dx)
else:
    a = dolfinx.fem.form(ufl.inner(ufl.grad(u), ufl.grad(v)) * ufl.dx)
tjit = time.perf_counter() - t0
t0 = time.perf_counter()
A = dolfinx.fem.petsc.create_matrix(a)
tsetup = time.perf_counter() - t0
times = []
for _ in range(reps):
    A.zeroEntries()
    t0 = time.perf_counter()
    dolfinx.fem.petsc.assemble_matrix(A, a)
    A.assemble()
    times.append(time.perf_counter() - t0)
first = tspace + tsetup + times[0]  # time to the first matrix: dof map, pattern, first assembly
times.sort()
ncells = mesh.topology.index_map(3).size_local
print(("fenicsx %s " + form + (" hex" if cell == "hexahedron" else "") + " N=%d P%d cells=%d dofs=%d nnz=%d assemble_median_s=%.4f assemble_min_s=%.4f setup_s=%.3f space_s=%.3f first_s=%.3f mesh_s=%.3f jit_s=%.2f") % (
    dolfinx.__version__, N, p, ncells, V.dofmap.index_map.size_global * V.dofmap.index_map_bs, A.getInfo()["nz_used"],
    times[len(times) // 2], times[0], tsetup, tspace, first, tmesh, tjit))
