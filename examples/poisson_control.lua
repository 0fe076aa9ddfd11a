-- The Poisson "mother problem" of PDE-constrained optimization: find the source f that
-- brings the solution of -lap u = f, u = 0 on the boundary, closest to a target d,
--   min J(u, f) = 1/2 int (u - d)^2 + alpha/2 int f^2,  d = sin(pi x) sin(pi y) / (2 pi^2).
-- The gradient comes from one adjoint solve (no tape: it is a derivative of the forms); a
-- Taylor test checks it (and the Hessian action, one tangent and one second-order adjoint
-- solve), then TAO minimizes in the L2 inner product: L-BFGS by default, or Newton-CG.
--   lugal examples/poisson_control.lua [N] [alpha] [method: lmvm | nls | ntr]
local lg = require "lugal"
local N = tonumber(arg and arg[1]) or 32
local alpha = tonumber(arg and arg[2]) or 1e-6
local method = arg and arg[3] or "lmvm"

local mesh = lg.mesh.rectangle{nx = N}
local P1 = lg.lagrange(1)
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
local f = lg.control(P1, mesh, "f")                       -- starts at 0
local pi = math.pi
local d = lg.sin(pi*lg.x)*lg.sin(pi*lg.y) / (2*pi^2)

local state = lg.linear_problem{mesh = mesh,
  eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) - f*v),
  bc = lg.essential_bc(mesh:boundary(), v*u), test = v, unknown = u}
local J = lg.functional(lg.integral(mesh:cells(), 0.5*(u - d)^2 + alpha/2*f^2))
local rf = lg.reduced_functional{problem = state, functional = J, control = f}

local J0 = rf:value()
local t = lg.taylor_test(rf, lg.x*lg.y, lg.sin(2*pi*lg.x), {hessian = true})
print(t)
assert(math.abs(t.rates1[#t.rates1] - 2) < 0.05, "the gradient fails its Taylor test")
-- j is quadratic here (a linear state): the second-order expansion is exact
assert(t.remainders2[1] < 1e-9 * t.remainders1[1], "the Hessian fails its Taylor test")
f:assign(0*lg.x)

local t0 = lg.wtime()
local fopt, info = lg.minimize(rf, {method = method, gttol = 1e-8, gatol = 0, grtol = 0, monitor = false})
print(string.format("poisson_control: %dx%d, alpha %g: J(0) = %.6e, J* = %.6e after %d %s iterations, %d Hessian products (%s), %.2f s",
                    N, N, alpha, J0, info.J, info.iterations, method, info.hessian_products, info.reason, lg.wtime() - t0))
-- the optimality condition alpha f = lambda (the adjoint) makes the L2 gradient vanish
local g = rf:gradient()
print(string.format("  |grad J*|_L2 = %.2e, |u* - d|_L2 = %.3e", math.sqrt(lg.integrate(mesh, g*g)),
                    math.sqrt(lg.integrate(mesh, (rf:state() - d)^2))))
mesh:write("poisson_control.vtu", {f = fopt, u = rf:state()})
