-- bench/stokes3d.lua [N] [Re] [options...] — 3D Stokes channel flow, Taylor–Hood (vector P2
-- velocity, P1 pressure) on the unit cube with N×N×N cubes × 6 tetrahedra: a parabolic
-- inflow at x = 0, no slip on y = 0, 1 and z = 0, 1, the natural (do-nothing) outflow at
-- x = 1; with a Reynolds number Re, Navier–Stokes (1/Re Δu and the convection term, Newton
-- from zero), and then the gradient of the dissipation with respect to the inflow's
-- amplitude and Re. The default solver against any options given after N and Re
-- (-lugal_iterative 0: the direct solver). Prints the solver, its iterations, the
-- setup-and-solve time, the kinetic energy and the pressure drop ∫_{x=0} p − ∫_{x=1} p.
local lg = require "lugal"
local N = tonumber(arg[1]) or 10
local mesh = lg.mesh.box{nx = N}
local V, Q = lg.vector(lg.lagrange(2)), lg.lagrange(1)
local u, p = lg.unknown(V, "u"), lg.unknown(Q, "p")
local v, q = lg.test(V, "v"), lg.test(Q, "q")
local y, z = lg.y, lg.z
local re = arg[2] and tonumber(arg[2])
local amp, Re = lg.parameter("amp", 1), lg.parameter("Re", re or 1)
local eqn = lg.inner(lg.grad(u), lg.grad(v)) - p*lg.div(v) - q*lg.div(u)
if re then eqn = 1/Re*lg.inner(lg.grad(u), lg.grad(v)) + lg.dot(lg.dot(lg.grad(u), u), v) - p*lg.div(v) - q*lg.div(u) end
local t0 = lg.wtime()
local prob = (re and lg.nonlinear_problem or lg.linear_problem){mesh = mesh, test = {v, q}, unknown = {u, p},
  eqn = lg.integral(mesh:cells(), eqn),
  bc = {lg.essential_bc(mesh:boundary("left"), lg.dot(v, u - {amp*16*y*(1 - y)*z*(1 - z), 0, 0})),
        lg.essential_bc(mesh:boundary("front", "back", "bottom", "top"), lg.dot(v, u))}}
local uh, ph, info = prob:solve()
local t = lg.wtime() - t0
local grad = ""
if re then
  local t1 = lg.wtime()
  local rf = lg.reduced_functional{problem = prob, control = {amp, Re},
    functional = lg.functional(lg.integral(mesh:cells(), lg.inner(lg.grad(u), lg.grad(u))))}
  local ga, gr = rf:gradient()
  grad = string.format(" gradient_s=%.3f damp=%.12e dRe=%.12e", lg.wtime() - t1, ga, gr)
end
print(string.format("%s dofs=%d its=%d solve_s=%.3f energy=%.12e dp=%.12e%s", info.solver, info.dofs, info.iterations, t,
                    0.5*lg.integrate(mesh, lg.dot(uh, uh)),
                    lg.integrate(mesh:boundary("left"), ph) - lg.integrate(mesh:boundary("right"), ph), grad))
