-- bench/elasticity3d.lua [N] — vector P1 linear elasticity on the unit cube (N×N×N cubes × 6
-- tetrahedra), clamped on the left, its own weight: the default solver against any options
-- given after N (-lugal_iterative 0; -ksp_type cg -pc_type gamg -ksp_rtol 1e-8). Prints the solver,
-- its iterations, the setup-and-solve time and the squared L2 norm of the displacement.
local lg = require "lugal"
local N = tonumber(arg[1]) or 20
local mesh = lg.mesh.box{nx = N}
local V = lg.vector(lg.lagrange(1))
local u, v = lg.unknown(V, "u"), lg.test(V, "v")
local function eps(w) return lg.sym(lg.grad(w)) end
local t0 = lg.wtime()
local prob = lg.linear_problem{mesh = mesh, test = v, unknown = u,
  eqn = lg.integral(mesh:cells(), 2*lg.inner(eps(u), eps(v)) + 1.25*lg.div(u)*lg.div(v) + v[3]),
  bc = lg.essential_bc(mesh:boundary("left"), lg.dot(v, u))}
local uh, info = prob:solve()
print(string.format("%s %d its %.3f s  |u|^2 %.10e", info.solver, info.iterations, lg.wtime() - t0, lg.integrate(mesh, lg.dot(uh, uh))))
