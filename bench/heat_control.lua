-- bench/heat_control.lua — the whole optimization of examples/heat_control.lua's problem
-- (dolfin-adjoint's time-distributed control with lugal's trapezoidal running terms, a
-- control per step time) with lugal's defaults: L-BFGS from f = 0 to a gradient 1e-8 of its
-- first (gttol), timed from the problem's making to the optimum (kernels compiled included),
-- for the side-by-side with bench/heat_control_pyadjoint.py (issue 55).
--   lugal bench/heat_control.lua N
local lg = require "lugal"
local t_start = lg.wtime()
local N = tonumber(arg[1]) or 8
local nu, dt, T, alpha = 1e-5, 0.1, 2.0, 0.1
local mesh = lg.mesh.rectangle{nx = N}
local P1 = lg.lagrange(1)
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
local x, y, pi = lg.x, lg.y, math.pi
local t = lg.parameter("t", 0)
local u0 = lg.interpolate(P1, mesh, 0*x, "u0")
local f, f_prev = lg.control(P1, mesh, "f", 0*x, {per_step = true})
local step = lg.time_problem{mesh = mesh, test = v, unknown = u, previous = u0, dt = dt, t1 = T, time = t, monitor = false,
                             eqn = lg.integral(mesh:cells(), (u - u0)/dt*v + nu*lg.dot(lg.grad(u), lg.grad(v)) - f*v),
                             bc = lg.essential_bc(mesh:boundary(), v*u)}
local d = 16*x*(1 - x)*y*(1 - y)*lg.sin(pi*t)
local J = lg.functional{running = lg.integral(mesh:cells(), 0.5*(u - d)^2 + alpha/2*((f - f_prev)/dt)^2)}
local rf = lg.reduced_functional{problem = step, functional = J, control = f}
local _, info = lg.minimize(rf, {gttol = 1e-8, gatol = 0, grtol = 0, maxit = 2000, monitor = false})
print(string.format("heat_control lugal N=%d: L-BFGS %d iterations (%d evaluations), %.3f s, J* %.12e", N, info.iterations,
                    info.evaluations, lg.wtime() - t_start, info.J))
