-- stokes.lua — the lid-driven cavity, Stokes flow with Taylor-Hood elements (vector P2
-- velocity, P1 pressure) on the unit square. The velocity is given on the whole boundary,
-- so the pressure is determined only up to a constant: nullspace = p tells the solver
-- (MUMPS finds the null pivot, the solution comes back with mean pressure zero).
-- Prints the kinetic energy, the pressure's range and the divergence, and checks them.
-- Run: lugal examples/stokes.lua [n]
local lg = require "lugal"
local n = tonumber(arg and arg[1]) or 32
local mesh = lg.mesh.rectangle{nx = n}
local V, Q = lg.vector(lg.lagrange(2)), lg.lagrange(1)
local u, p = lg.unknown(V, "u"), lg.unknown(Q, "p")
local v, q = lg.test(V, "v"), lg.test(Q, "q")
local nu = 1.0
local eqn = lg.integral(mesh:cells(), nu*lg.inner(lg.grad(u), lg.grad(v)) - p*lg.div(v) - q*lg.div(u))
-- walls at rest, the lid (y = 1) moves to the right with the regularized profile
-- 16 x^2 (1 - x)^2, which vanishes at the corners (a lid at speed 1 makes the velocity
-- discontinuous there and the pressure infinite)
local x = lg.x
local bc = {lg.essential_bc(mesh:boundary("left", "right", "bottom"), lg.dot(v, u)),
            lg.essential_bc(mesh:boundary("top"), lg.dot(v, u - {16*x^2*(1 - x)^2, 0}))}
local t0 = lg.wtime()
local uh, ph, info = lg.linear_problem{mesh = mesh, eqn = eqn, bc = bc, test = {v, q}, unknown = {u, p},
                                       nullspace = p}:solve()
local t = lg.wtime() - t0
local energy = 0.5*lg.integrate(mesh, lg.dot(uh, uh))
local pmean = lg.integrate(mesh, ph)
local div = math.sqrt(lg.integrate(mesh, lg.div(uh)^2))
local plo, phi = math.huge, -math.huge
for _, x in ipairs(ph:values()) do plo, phi = math.min(plo, x), math.max(phi, x) end
mesh:write("stokes.vtu", {velocity = uh, pressure = ph})
print(string.format("stokes: %dx%d Taylor-Hood, %d dofs, solved in %.2f s: kinetic energy %.10f, mean pressure %.1e, " ..
                    "|div u| %.2e, pressure in [%.2f, %.2f]", n, n, info.dofs, t, energy, pmean, div, plo, phi))
assert(math.abs(pmean) < 1e-10, "the pressure has mean zero")
assert(div < 12/n^2, "|div u| falls as h^2 (4.5e-3 at 32x32)")
assert(math.abs(energy - 0.018624) < 1e-5, "the kinetic energy of the regularized Stokes cavity, 0.018624 (converged to 6 digits at 64x64)")
