"""bench/compare_fenicsx.py CASE FILE.vtu — solve what examples/CASE.lua solves with FEniCSx
(Debian python3-dolfinx 0.5), on the mesh lugal wrote to FILE.vtu (the same points and
cells, read from the file), and compare the solutions at the mesh vertices with the point
data lugal wrote there. Run by bench/compare_fenicsx.sh; never part of the build or tests.
  CASE stokes:     the regularized lid-driven cavity, Taylor-Hood P2/P1, mean-zero pressure
  CASE elasticity: the 3D cantilever under its own weight, vector P2, LU"""
import base64
import sys
import xml.etree.ElementTree as ET

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc
import dolfinx
import dolfinx.fem.petsc
import ufl

case, path = sys.argv[1], sys.argv[2]


def read_array(da, header):
    """a DataArray of a lugal VTU: ascii, or VTK's inline binary (base64 of a byte count of
    the header type, then the raw little-endian values)"""
    kind = {"Float64": "<f8", "Int32": "<i4", "UInt8": "u1"}[da.get("type")]
    if da.get("format") == "ascii":
        return np.array(da.text.split(), dtype=float if kind == "<f8" else np.int64)
    raw = base64.b64decode("".join(da.text.split()))
    hs = 8 if header == "UInt64" else 4
    n = int.from_bytes(raw[:hs], "little")
    return np.frombuffer(raw[hs:hs + n], dtype=kind)


def read_vtu(path):
    root = ET.parse(path).getroot()
    header = root.get("header_type", "UInt32")
    piece = root.find(".//Piece")
    x = read_array(piece.find("Points/DataArray"), header).astype(float).reshape(-1, 3)
    conn = read_array(piece.find("Cells/DataArray[@Name='connectivity']"), header).astype(np.int64)
    offs = read_array(piece.find("Cells/DataArray[@Name='offsets']"), header).astype(np.int64)
    nv = offs[0]
    cells = conn.reshape(-1, nv)
    point = {}
    for da in piece.find("PointData").iter("DataArray"):
        nc = int(da.get("NumberOfComponents", "1"))
        point[da.get("Name")] = read_array(da, header).astype(float).reshape(-1, nc)
    return x, cells, point


x, cells, point = read_vtu(path)
dim = 2 if np.all(x[:, 2] == 0) and cells.shape[1] == 3 else 3
cell = ufl.triangle if dim == 2 else ufl.tetrahedron
domain = ufl.Mesh(ufl.VectorElement("Lagrange", cell, 1))
mesh = dolfinx.mesh.create_mesh(MPI.COMM_WORLD, cells, x[:, :dim], domain)
# lugal's vertex i is FEniCSx's geometry node with input index i (P1 geometry: nodes = vertices)
orig = mesh.geometry.input_global_indices
xg = mesh.geometry.x


def vertex_values(fun, ncomp):
    """values of fun at the mesh vertices, in lugal's vertex order"""
    V1 = dolfinx.fem.VectorFunctionSpace(mesh, ("Lagrange", 1), dim=ncomp) if ncomp > 1 else dolfinx.fem.FunctionSpace(mesh, ("Lagrange", 1))
    f1 = dolfinx.fem.Function(V1)
    f1.interpolate(fun)
    # P1 dofs are at the geometry nodes: match them by coordinates
    dof_x = V1.tabulate_dof_coordinates()
    from scipy.spatial import cKDTree
    tree = cKDTree(dof_x)
    out = np.zeros((len(x), ncomp))
    d, idx = tree.query(x)
    assert d.max() < 1e-12
    vals = f1.x.array.reshape(-1, ncomp)
    return vals[idx]


if case == "stokes":
    P2 = ufl.VectorElement("Lagrange", cell, 2)
    P1 = ufl.FiniteElement("Lagrange", cell, 1)
    W = dolfinx.fem.FunctionSpace(mesh, P2 * P1)
    (u, p), (v, q) = ufl.TrialFunctions(W), ufl.TestFunctions(W)
    a = dolfinx.fem.form(ufl.inner(ufl.grad(u), ufl.grad(v)) * ufl.dx - p * ufl.div(v) * ufl.dx - q * ufl.div(u) * ufl.dx)
    zero = dolfinx.fem.Constant(mesh, PETSc.ScalarType(0))
    L = dolfinx.fem.form(zero * q * ufl.dx)
    W0, _ = W.sub(0).collapse()
    walls = dolfinx.fem.Function(W0)
    lid = dolfinx.fem.Function(W0)
    lid.interpolate(lambda X: np.vstack((16 * X[0] ** 2 * (1 - X[0]) ** 2, 0 * X[0])))
    fdim = dim - 1
    wall_f = dolfinx.mesh.locate_entities_boundary(mesh, fdim, lambda X: np.isclose(X[0], 0) | np.isclose(X[0], 1) | np.isclose(X[1], 0))
    lid_f = dolfinx.mesh.locate_entities_boundary(mesh, fdim, lambda X: np.isclose(X[1], 1))
    bcs = [dolfinx.fem.dirichletbc(walls, dolfinx.fem.locate_dofs_topological((W.sub(0), W0), fdim, wall_f), W.sub(0)),
           dolfinx.fem.dirichletbc(lid, dolfinx.fem.locate_dofs_topological((W.sub(0), W0), fdim, lid_f), W.sub(0))]
    A = dolfinx.fem.petsc.assemble_matrix(a, bcs=bcs)
    A.assemble()
    b = dolfinx.fem.petsc.assemble_vector(L)
    dolfinx.fem.petsc.apply_lifting(b, [a], [bcs])
    b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    dolfinx.fem.petsc.set_bc(b, bcs)
    ksp = PETSc.KSP().create(MPI.COMM_WORLD)
    ksp.setOperators(A)
    ksp.setType("preonly")
    pc = ksp.getPC()
    pc.setType("lu")
    pc.setFactorSolverType("mumps")
    pc.setFactorSetUpSolverType()
    F = pc.getFactorMatrix()
    F.setMumpsIcntl(24, 1)
    F.setMumpsCntl(3, -1e-12)
    wh = dolfinx.fem.Function(W)
    ksp.solve(b, wh.vector)
    wh.x.scatter_forward()
    uh, ph = wh.sub(0).collapse(), wh.sub(1).collapse()
    vol = dolfinx.fem.assemble_scalar(dolfinx.fem.form(dolfinx.fem.Constant(mesh, 1.0) * ufl.dx))
    pm = dolfinx.fem.assemble_scalar(dolfinx.fem.form(ph * ufl.dx)) / vol
    ph.x.array[:] -= pm
    energy = 0.5 * dolfinx.fem.assemble_scalar(dolfinx.fem.form(ufl.inner(uh, uh) * ufl.dx))
    uv, pv = vertex_values(uh, 2), vertex_values(ph, 1)
    du = np.abs(uv - point["velocity"][:, :2]).max()
    dp = np.abs(pv - point["pressure"]).max()
    print("fenicsx %s stokes: %d cells, kinetic energy %.10f; max vertex difference from lugal: velocity %.2e, pressure %.2e" % (
        dolfinx.__version__, len(cells), energy, du, dp))
elif case == "elasticity":
    L_, H = 1.0, 0.2
    E, nu, rho_g = 1e4, 0.3, 1.0
    mu, lmbda = E / (2 * (1 + nu)), E * nu / ((1 + nu) * (1 - 2 * nu))
    V = dolfinx.fem.VectorFunctionSpace(mesh, ("Lagrange", 2))
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    eps = lambda w: ufl.sym(ufl.grad(w))
    sigma = lambda w: 2 * mu * eps(w) + lmbda * ufl.tr(eps(w)) * ufl.Identity(3)
    f = dolfinx.fem.Constant(mesh, PETSc.ScalarType((0, 0, -rho_g)))
    a = ufl.inner(sigma(u), eps(v)) * ufl.dx
    L = ufl.dot(f, v) * ufl.dx
    clamp = dolfinx.mesh.locate_entities_boundary(mesh, 2, lambda X: np.isclose(X[0], 0))
    zero = dolfinx.fem.Function(V)
    bcs = [dolfinx.fem.dirichletbc(zero, dolfinx.fem.locate_dofs_topological(V, 2, clamp))]
    problem = dolfinx.fem.petsc.LinearProblem(a, L, bcs=bcs, petsc_options={"ksp_type": "preonly", "pc_type": "lu",
                                                                          "pc_factor_mat_solver_type": "mumps"})
    uh = problem.solve()
    uv = vertex_values(uh, 3)
    du = np.abs(uv - point["displacement"]).max()
    print("fenicsx %s elasticity: %d cells, max |u| %.10f; max vertex difference from lugal %.2e (relative %.2e)" % (
        dolfinx.__version__, len(cells), np.abs(uv).max(), du, du / np.abs(uv).max()))
