-- Coefficient inversion: recover the conductivity k(x) >= k_min in -div(k grad u) = 1,
-- u = 0 on the boundary, from noisy observations of u, with H1 (gradient) regularization:
--   min J(u, k) = 1/2 int (u - u_obs)^2 + beta/2 int |grad k|^2,   k_min <= k.
-- The observations come from a known k_true plus 1% noise; the gradient (one adjoint solve)
-- and the Hessian (one tangent and one second-order adjoint solve) pass Taylor tests, then
-- TAO minimizes with bounds: blmvm (L-BFGS) or bnls (Newton-CG).
--   lugal examples/coefficient_inversion.lua [N] [method: blmvm | bnls] [beta]
local lg = require "lugal"
local N = tonumber(arg and arg[1]) or 32
local method = arg and arg[2] or "blmvm"
local beta = tonumber(arg and arg[3]) or 1e-8
local kmin = 1.0   -- the background: the bump only adds

local mesh = lg.mesh.rectangle{nx = N}
local P1 = lg.lagrange(1)
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
local pi = math.pi
local x, y = lg.x, lg.y
-- the truth: a bump of 2 on a background of 1
local k_true = 1 + lg.exp(-40*((x - 0.4)^2 + (y - 0.6)^2))

-- the observations: the state at k_true, plus deterministic 1% "noise"
local kt = lg.interpolate(P1, mesh, k_true, "k_true")
local fwd = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), kt*lg.dot(lg.grad(v), lg.grad(u)) - v),
                              bc = lg.essential_bc(mesh:boundary(), v*u), test = v, unknown = u}
local ut = fwd:solve()
local peak = 0
for _, val in ipairs(ut:values()) do peak = math.max(peak, math.abs(val)) end
local uobs = lg.interpolate(P1, mesh, 0.01*peak*lg.sin(37*x)*lg.cos(23*y), "u_obs")
uobs:assign(uobs + ut)

-- the inverse problem, from k = 1
local k = lg.control(P1, mesh, "k", 1 + 0*x)
local state = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), k*lg.dot(lg.grad(v), lg.grad(u)) - v),
                                bc = lg.essential_bc(mesh:boundary(), v*u), test = v, unknown = u}
local J = lg.functional(lg.integral(mesh:cells(), 0.5*(u - uobs)^2 + beta/2*lg.dot(lg.grad(k), lg.grad(k))))
local rf = lg.reduced_functional{problem = state, functional = J, control = k}

local t = lg.taylor_test(rf, 1 + 0.3*x*y, lg.sin(pi*x)*lg.sin(pi*y), {hessian = true, h = 0.1, steps = 5})
print(t)
assert(math.abs(t.rates1[#t.rates1] - 2) < 0.05, "the gradient fails its Taylor test")
assert(math.abs(t.rates2[#t.rates2] - 3) < 0.1, "the Hessian fails its Taylor test")
k:assign(1 + 0*x)

local J0 = rf:value()
local t0 = lg.wtime()
local kopt, info = lg.minimize(rf, {method = method, bounds = {kmin, nil}, gttol = 1e-6, gatol = 0, grtol = 0,
                                    monitor = false})
local err0 = math.sqrt(lg.integrate(mesh, (1 - k_true)^2) / lg.integrate(mesh, k_true^2))
local err = math.sqrt(lg.integrate(mesh, (kopt - k_true)^2) / lg.integrate(mesh, k_true^2))
local lo = math.huge
for _, val in ipairs(kopt:values()) do lo = math.min(lo, val) end
print(string.format("coefficient_inversion: %dx%d, beta %g, %s: J %.4e -> %.4e in %d iterations, %d Hessian products (%s), %.2f s",
                    N, N, beta, method, J0, info.J, info.iterations, info.hessian_products, info.reason,
                    lg.wtime() - t0))
print(string.format("  |k - k_true| / |k_true| = %.3f (from %.3f at k = 1), min k = %.3f (k_min %.2f)", err, err0, lo, kmin))
assert(info.converged, "the inversion did not converge")
assert(lo >= kmin - 1e-12, "the bound k >= k_min is violated")
assert(err < 0.5 * err0, "the recovered k is not closer to k_true than the initial guess")
mesh:write("coefficient_inversion.vtu", {k = kopt, k_true = kt, u = rf:state(), u_obs = uobs})
