-- Neumann boundary control of a nonlinear state: find the flux g on the right side that
-- brings the solution of
--   -div((1 + u^2) grad u) = 0,  u = 0 on the left,  (1 + u^2) du/dn = g on the right,
--   du/dn = 0 on the top and the bottom,
-- closest to a target: min J = 1/2 int (u - d)^2 + alpha/2 int_right g^2, d = x (1 + y/2).
-- The gradient and the Hessian (tangent + second-order adjoint) pass Taylor tests; TAO's
-- Newton-CG (nls) with Hessian actions minimizes.
--   lugal examples/boundary_control.lua [N] [method: nls | ntr | lmvm] [alpha]
local lg = require "lugal"
local N = tonumber(arg and arg[1]) or 32
local method = arg and arg[2] or "nls"
local alpha = tonumber(arg and arg[3]) or 1e-4

local mesh = lg.mesh.rectangle{nx = N}
local P1 = lg.lagrange(1)
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
local g = lg.control(P1, mesh, "g")          -- only its values on the right side matter
local x, y = lg.x, lg.y
local d = x*(1 + y/2)

local state = lg.nonlinear_problem{mesh = mesh,
  eqn = lg.integral(mesh:cells(), (1 + u^2)*lg.dot(lg.grad(v), lg.grad(u))) - lg.integral(mesh:boundary("right"), g*v),
  bc = lg.essential_bc(mesh:boundary("left"), v*u), test = v, unknown = u}
local J = lg.functional(lg.integral(mesh:cells(), 0.5*(u - d)^2) + lg.integral(mesh:boundary("right"), alpha/2*g^2))
local rf = lg.reduced_functional{problem = state, functional = J, control = g}

local t = lg.taylor_test(rf, 1 + y, lg.cos(3*y), {hessian = true, h = 0.2, steps = 5})
print(t)
assert(math.abs(t.rates1[#t.rates1] - 2) < 0.05, "the gradient fails its Taylor test")
assert(math.abs(t.rates2[#t.rates2] - 3) < 0.1, "the Hessian fails its Taylor test")
g:assign(0*x)

local J0 = rf:value()
local t0 = lg.wtime()
local gopt, info = lg.minimize(rf, {method = method, gttol = 1e-8, gatol = 0, grtol = 0, monitor = false})
local uopt = rf:state()
print(string.format("boundary_control: %dx%d, alpha %g, %s: J %.6e -> %.6e in %d iterations, %d Hessian products (%s), %.2f s",
                    N, N, alpha, method, J0, info.J, info.iterations, info.hessian_products, info.reason, lg.wtime() - t0))
local gbar = lg.integrate(mesh:boundary("right"), gopt)
print(string.format("  mean flux on the right %.4f, |u - d|_L2 = %.3e (from %.3e at g = 0)", gbar,
                    math.sqrt(lg.integrate(mesh, (uopt - d)^2)), math.sqrt(2*J0)))
assert(info.converged, "the optimization did not converge")
assert(info.J < 0.05 * J0, "J did not fall by 20x")
mesh:write("boundary_control.vtu", {g = gopt, u = uopt})
