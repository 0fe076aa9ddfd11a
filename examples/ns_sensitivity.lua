-- ns_sensitivity.lua — sensitivities of a transient Navier-Stokes flow: the lid-driven
-- cavity spinning up from rest (the lid's speed ramps as 1 - exp(-t/0.1)), Taylor-Hood
-- elements (P2 velocity, P1 pressure, its constant the null space), backward Euler steps
-- solved by Newton. How does the kinetic energy at t = T depend on the Reynolds number?
--   * step:sensitivity(Re): the tangent-linear march, du/dRe at every step, E'(Re) = ∫ u.du
--   * the adjoint: lg.reduced_functional on E = 1/2 ∫|u(T)|^2, one backward sweep
--   * central differences of two more marches
-- Checks that the three agree (ns_sensitivity.vtu: u(T), p(T) and du(T)/dRe), and a Taylor test of the gradient with respect to Re and a
-- body force at once (rate 2).
-- Run: lugal examples/ns_sensitivity.lua [n] [steps]
local lg = require "lugal"
local n = tonumber(arg and arg[1]) or 10
local steps = tonumber(arg and arg[2]) or 10
local dt = 0.05
local mesh = lg.mesh.rectangle{nx = n, diagonal = "crossed"}
local V, Q = lg.vector(lg.lagrange(2)), lg.lagrange(1)
local u, p = lg.unknown(V, "u"), lg.unknown(Q, "p")
local v, q = lg.test(V, "v"), lg.test(Q, "q")
local u0, p0 = lg.zero_function(V, mesh, "u0"), lg.zero_function(Q, mesh, "p0")
local Re = lg.parameter("Re", 100)
local t = lg.parameter("t", 0)
local f = lg.control(V, mesh, "f", {0, 0})                  -- a body force (zero to start)
local F = lg.integral(mesh:cells(), lg.dot(u - u0, v)/dt + 1/Re*lg.inner(lg.grad(u), lg.grad(v))
                                    + lg.dot(lg.dot(lg.grad(u), u), v) - p*lg.div(v) - q*lg.div(u) - lg.dot(f, v))
local lid = 1 - lg.exp(-t/0.1)
local bc = {lg.essential_bc(mesh:boundary("left", "right", "bottom"), lg.dot(v, u)),
            lg.essential_bc(mesh:boundary("top"), lg.dot(v, u - {lid, 0}))}
local step = lg.time_problem{mesh = mesh, test = {v, q}, unknown = {u, p}, previous = {u0, p0}, eqn = F, bc = bc,
                             nullspace = p, nonlinear = true, dt = dt, steps = steps, time = t, monitor = false}
local t0 = lg.wtime()
local uT, pT, info = step:solve()
local E = lg.integrate(mesh, 0.5*lg.dot(uT, uT))
print(string.format("ns_sensitivity: %dx%d crossed, %d steps of %g: E(T) = %.10f, %d Newton iterations, %.2f s",
                    n, n, steps, dt, E, info.iterations, info.seconds))
-- 1. the tangent march
local du = step:sensitivity(Re)
local dE_tangent = lg.integrate(mesh, lg.dot(uT, du))
mesh:write("ns_sensitivity.vtu", {velocity = uT, pressure = pT, velocity_dRe = du})
-- 2. the adjoint
local J = lg.functional{final = lg.integral(mesh:cells(), 0.5*lg.dot(u, u))}
local rf = lg.reduced_functional{problem = step, functional = J, control = Re}
local dE_adjoint = rf:gradient(100)
-- 3. central differences
local h = 1e-3
Re:set(100 + h)
local up = step:solve()
local Ep = lg.integrate(mesh, 0.5*lg.dot(up, up))
Re:set(100 - h)
local um = step:solve()
local Em = lg.integrate(mesh, 0.5*lg.dot(um, um))
Re:set(100)
local dE_fd = (Ep - Em)/(2*h)
print(string.format("ns_sensitivity: dE/dRe: tangent %.10e, adjoint %.10e, central differences %.10e", dE_tangent,
                    dE_adjoint, dE_fd))
assert(math.abs(dE_tangent - dE_adjoint) < 1e-9*math.abs(dE_adjoint), "the tangent and the adjoint agree")
assert(math.abs(dE_fd - dE_adjoint) < 1e-5*math.abs(dE_adjoint), "central differences agree")
-- the gradient with respect to Re and the body force at once
local rf2 = lg.reduced_functional{problem = step, functional = J, control = {Re, f}}
local tt = lg.taylor_test(rf2, {100, {0, 0}}, {20, {lg.sin(math.pi*lg.y), 0.5*lg.x}}, {h = 0.5, steps = 4})
print(tt)
assert(math.abs(tt.rates1[#tt.rates1] - 2) < 0.1, "Taylor rate 2 for (Re, f)")
print(string.format("ns_sensitivity: %.2f s in all", lg.wtime() - t0))
