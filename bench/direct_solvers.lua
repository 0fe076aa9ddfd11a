-- bench/direct_solvers.lua DIM N P — one factorization and one solve of the P-th degree
-- Lagrange Laplacian on the unit square (DIM 2, N x N x 2 triangles) or cube (DIM 3,
-- N^3 x 6 tetrahedra), with whatever direct solver the options choose; bench/direct_solvers.sh
-- runs it with PETSc's LU (nested dissection) and with MUMPS and reads -log_view.
local lg = require "lugal"
local dim, N, deg = tonumber(arg[1]), tonumber(arg[2]), tonumber(arg[3])
assert(dim and N and deg, "usage: lugal bench/direct_solvers.lua DIM N P [petsc options]")
local mesh = dim == 2 and lg.mesh.rectangle{nx = N} or lg.mesh.box{nx = N}
local P = lg.lagrange(deg)
local u, v = lg.unknown(P, "u"), lg.test(P, "v")
local pr = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) - v),
                             bc = lg.essential_bc(mesh:boundary(), v*u), test = v, unknown = u}
local _, info = pr:solve()
print(string.format("dim=%d N=%d P%d dofs=%d solver=%s", dim, N, deg, info.dofs, info.solver))
