-- Time-distributed control of the heat equation (after dolfin-adjoint's demo): find a source
-- f(t, x) with a value per step time that makes the state follow d(t, x):
--   u_t - nu Δu = f on the unit square, u = 0 on the boundary, u(0) = 0, t in (0, 2],
--   min J(f) = 1/2 ∫_0^T ∫ (u - d)² + alpha/2 ∫_0^T ∫ ((f_k - f_{k-1})/dt)²,
--   d = 16 x (1 - x) y (1 - y) sin(pi t),  nu = 1e-5, dt = 0.1, alpha = 0.1.
-- lg.control(..., {per_step = true}) gives f a value per step time and its companion f_prev
-- (the value at the step before), which the rate regularization reads; the running terms use
-- the trapezoidal rule over the step times. The gradient (one backward sweep of adjoint steps,
-- every factorization kept: the step's matrix does not change) and the Hessian action (a
-- tangent march and a second-order backward sweep) pass Taylor tests; L-BFGS and Newton-CG
-- find the same optimum.
--   lugal examples/heat_control.lua [N] [checkpoints]
local lg = require "lugal"
local N = tonumber(arg and arg[1]) or 8
local snaps = arg and tonumber(arg[2]) or "all"
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
local rf = lg.reduced_functional{problem = step, functional = J, control = f, checkpoints = snaps}

local tt = lg.taylor_test(rf, lg.sin(pi*t)*x*y, lg.cos(pi*t)*x, {h = 0.1, steps = 4, hessian = true})
print(tt)
assert(math.abs(tt.rates1[#tt.rates1] - 2) < 0.05, "the gradient fails its Taylor test")
-- J is quadratic in f (a linear step): the second-order remainder is rounding alone
local R2 = tt.remainders2[#tt.remainders2]
assert(math.abs(tt.rates2[#tt.rates2] - 3) < 0.1 or R2 < 1e-12 * math.abs(tt.j), "the Hessian fails its Taylor test")

local J0 = rf:value(0*x)
local Js = {}
for _, method in ipairs{"lmvm", "nls"} do
  rf:value(0*x)
  local t0 = lg.wtime()
  local fopt, info = lg.minimize(rf, {method = method, gttol = 1e-7, gatol = 0, grtol = 0, maxit = 500, monitor = false})
  print(string.format("heat_control: %dx%d P1, %d steps, a control per step time (%d values of %d dofs): %s %d iterations "
                      .. "(%d evaluations, %d Hessian actions), %.2f s: J %.6e -> %.10e", N, N, T/dt, #fopt, fopt[1]:ndof(),
                      method == "lmvm" and "L-BFGS" or "Newton-CG", info.iterations, info.evaluations, info.hessian_products,
                      lg.wtime() - t0, J0, info.J))
  assert(info.converged and info.J < 0.75*J0, "the optimization did not converge")
  Js[#Js + 1] = info.J
end
assert(math.abs(Js[1] - Js[2]) < 1e-8 * Js[1], "L-BFGS and Newton-CG found different optima")
