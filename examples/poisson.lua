-- poisson.lua — -Δu = f on the unit square, u = 0 on the boundary, with the manufactured
-- solution u = sin(πx) sin(πy). Prints the L2 and H1-seminorm errors and writes poisson.vtu.
-- Run: lugal examples/poisson.lua [n] [degree] [PETSc options]
local lg = require "lugal"

local n = tonumber(arg[1]) or 64
local p = tonumber(arg[2]) or 1

local mesh = lg.mesh.rectangle{nx = n, ny = n}
local P = lg.lagrange(p)
local u, v = lg.unknown(P, "u"), lg.test(P, "v")
local x, y = lg.x, lg.y
local pi = math.pi

local exact = lg.sin(pi*x) * lg.sin(pi*y)
local f = 2*pi^2 * exact

local eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) - f*v)
local bc = lg.essential_bc(mesh:boundary("left", "right", "bottom", "top"), v*(u - 0))

local prob = lg.linear_problem{mesh = mesh, eqn = eqn, bc = bc, test = v, unknown = u}
local uh = prob:solve()

local e = uh - exact
local l2 = math.sqrt(lg.integrate(mesh, e^2))
local h1 = math.sqrt(lg.integrate(mesh, lg.dot(lg.grad(e), lg.grad(e))))
print(string.format("poisson: %dx%d P%d, %d dofs: L2 error %.3e, H1 error %.3e", n, n, p, uh:ndof(), l2, h1))
mesh:write("poisson.vtu", {u = uh})
