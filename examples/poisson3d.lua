-- poisson3d.lua — -Δu = f on the unit cube (6 tetrahedra per cube), u = exact on the
-- boundary, manufactured solution u = sin(πx) sin(πy) sin(πz). Prints errors.
-- Run: lugal examples/poisson3d.lua [n] [degree]
local lg = require "lugal"
local n = tonumber(arg[1]) or 8
local p = tonumber(arg[2]) or 1

local mesh = lg.mesh.box{nx = n, ny = n, nz = n}
local P = lg.lagrange(p)
local u, v = lg.unknown(P, "u"), lg.test(P, "v")
local pi = math.pi
local exact = lg.sin(pi*lg.x) * lg.sin(pi*lg.y) * lg.sin(pi*lg.z)
local f = 3*pi^2 * exact

local eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) - f*v)
local bc = lg.essential_bc(mesh:boundary(), v*(u - exact))
local uh = lg.linear_problem{mesh = mesh, eqn = eqn, bc = bc, test = v, unknown = u}:solve()

local e = uh - exact
local l2 = math.sqrt(lg.integrate(mesh, e^2))
local h1 = math.sqrt(lg.integrate(mesh, lg.dot(lg.grad(e), lg.grad(e))))
print(string.format("poisson3d: %d^3 cubes P%d, %d dofs: L2 error %.3e, H1 error %.3e", n, p, uh:ndof(), l2, h1))
