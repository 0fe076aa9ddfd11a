-- bench/convection3d.lua [N] [b] — 3D P1 convection-diffusion -Δu + b ∂u/∂x = f on the unit cube
-- (N×N×N cubes × 6 tetrahedra), u = 0 on the boundary, solve and the gradient of
-- J = ∫(u − 1/2)² with respect to a source parameter: the default solver (GMRES with GAMG,
-- or the direct solver after GMRES fails) against any options given (-lugal_iterative 0).
local lg = require "lugal"
local N, b = tonumber(arg[1]) or 28, tonumber(arg[2]) or 5
local x, y, z, pi = lg.x, lg.y, lg.z, math.pi
local P1 = lg.lagrange(1)
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
local mesh = lg.mesh.box{nx = N}
local s = lg.parameter("s", 1.0)
local f = s*3*pi^2*lg.sin(pi*x)*lg.sin(pi*y)*lg.sin(pi*z)
local t0 = lg.wtime()
local prob = lg.linear_problem{mesh = mesh, test = v, unknown = u,
  eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) - f*v + b*lg.grad(u)[1]*v),
  bc = lg.essential_bc(mesh:boundary(), v*u)}
local uh, info = prob:solve()
local J = lg.functional(lg.integral(mesh:cells(), (u - 0.5)^2))
local rf = lg.reduced_functional{problem = prob, functional = J, control = s}
local g = rf:gradient()
print(string.format("%s %d its %.3f s |u|^2 %.12e dJ/ds %.12e", info.solver, info.iterations, lg.wtime() - t0, lg.integrate(mesh, uh*uh), g))
