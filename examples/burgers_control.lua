-- Distributed control of the viscous Burgers equation (nonlinear time steps):
--   u_t + u u_x - nu u_xx = f(x) on (0, 1), u(0) = u(1) = 0, u(x, 0) = sin(pi x),
-- steer the state at T = 0.5 towards d(x) = 0.3 sin(2 pi x) with a source f constant in time:
--   min J(f) = 1/2 ∫ (u(T) - d)² + alpha/2 ∫_0^T ∫ f² .
-- Each step (backward Euler) is solved by Newton; its adjoint is one transposed solve with the
-- Jacobian at the stored state, derived from the step's form. A Taylor test of the gradient,
-- then L-BFGS.
--   lugal examples/burgers_control.lua [N] [steps] [checkpoints]
local lg = require "lugal"
local N = tonumber(arg and arg[1]) or 48
local steps = tonumber(arg and arg[2]) or 40
local snaps = arg and tonumber(arg[3]) or "all"
local T, nu, alpha = 0.5, 0.01, 1e-4
local dt = T / steps

local mesh = lg.mesh.interval{n = N}
local P1 = lg.lagrange(1)
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
local x, pi = lg.x, math.pi
local u0 = lg.interpolate(P1, mesh, lg.sin(pi*x), "u0")
local f = lg.control(P1, mesh, "f", 0*x)
local d = lg.interpolate(P1, mesh, 0.3*lg.sin(2*pi*x), "d")

local eqn = lg.integral(mesh:cells(), (u - u0)/dt*v + u*lg.grad(u)[1]*v + nu*lg.dot(lg.grad(u), lg.grad(v)) - f*v)
local step = lg.time_problem{mesh = mesh, test = v, unknown = u, previous = u0, eqn = eqn, dt = dt, t1 = T, nonlinear = true,
                             bc = lg.essential_bc(mesh:boundary(), v*u), monitor = false}
local J = lg.functional{final = lg.integral(mesh:cells(), 0.5*(u - d)^2), running = lg.integral(mesh:cells(), alpha/2*f^2)}
local rf = lg.reduced_functional{problem = step, functional = J, control = f, checkpoints = snaps}

local t = lg.taylor_test(rf, 0.5*lg.sin(3*pi*x), lg.cos(pi*x), {h = 0.1, steps = 4})
print(t)
assert(math.abs(t.rates1[#t.rates1] - 2) < 0.05, "the gradient fails its Taylor test")

f:assign(0*x)
local J0 = rf:value()
local t0 = lg.wtime()
local fopt, info = lg.minimize(rf, {method = "lmvm", gttol = 1e-6, gatol = 0, grtol = 0, maxit = 300, monitor = false})
local uT = rf:state()
local miss0 = math.sqrt(lg.integrate(mesh, (0*x - d)^2))
local miss = math.sqrt(lg.integrate(mesh, (uT - d)^2))
print(string.format("burgers_control: %d cells, %d Newton-solved steps; L-BFGS %d iterations (%d evaluations), %.2f s: "
                    .. "J %.4e -> %.4e, |u(T) - d| %.3e (the target's norm %.3e)", N, steps, info.iterations, info.evaluations,
                    lg.wtime() - t0, J0, info.J, miss, miss0))
assert(info.J < 0.05 * J0, "the control did not steer the state")
