-- Initial-condition recovery (data assimilation) for the heat equation: the state u(t) of
--   u_t - nu Δu = 0 on the unit square, u = 0 on the boundary, t in (0, 0.2],
-- is observed with 1% noise at t = 0.1 and t = 0.2; recover the initial state u0 from them:
--   min J(u0) = 1/2 ∫ (u(0.1) - d1)² + 1/2 ∫ (u(0.2) - d2)² + beta/2 ∫ |grad u0|².
-- The march (backward Euler, lg.time_problem) is differentiated without a tape: the adjoint
-- of each step is derived from the step's form. With 8 snapshots of binomial checkpointing
-- the gradient (checked against every state kept, and by a Taylor test) recomputes the
-- fewest forward steps any schedule can; L-BFGS then recovers u0.
--   lugal examples/initial_condition.lua [N] [steps] [checkpoints]
local lg = require "lugal"
local N = tonumber(arg and arg[1]) or 16
local steps = tonumber(arg and arg[2]) or 20
local snaps = tonumber(arg and arg[3]) or 8
local T, nu, beta = 0.2, 0.05, 1e-6
local dt = T / steps

local mesh = lg.mesh.rectangle{nx = N}
local P1 = lg.lagrange(1)
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
local x, y, pi = lg.x, lg.y, math.pi

-- the truth: two bumps; the observations: its march plus deterministic 1% "noise"
local truth = lg.exp(-60*((x - 0.35)^2 + (y - 0.6)^2)) + 0.6*lg.exp(-80*((x - 0.7)^2 + (y - 0.3)^2))
local u0 = lg.control(P1, mesh, "u0", truth)
local eqn = lg.integral(mesh:cells(), (u - u0)/dt*v + nu*lg.dot(lg.grad(u), lg.grad(v)))
local step = lg.time_problem{mesh = mesh, test = v, unknown = u, previous = u0, eqn = eqn, dt = dt, t1 = T,
                             bc = lg.essential_bc(mesh:boundary(), v*u), monitor = false}
local obs = {}
do
  local half = lg.time_problem{mesh = mesh, test = v, unknown = u, previous = u0, eqn = eqn, dt = dt, t1 = T/2,
                               bc = lg.essential_bc(mesh:boundary(), v*u), monitor = false}
  for i, prob in ipairs{half, step} do
    local uT = prob:solve()
    local peak = 0
    for _, val in ipairs(uT:values()) do peak = math.max(peak, math.abs(val)) end
    obs[i] = lg.interpolate(P1, mesh, 0.01*peak*lg.sin(41*x + 7*i)*lg.cos(29*y), "d" .. i)
    obs[i]:assign(obs[i] + uT)
  end
end

local J = lg.functional{at = {[T/2] = lg.integral(mesh:cells(), 0.5*(u - obs[1])^2)},
                        final = lg.integral(mesh:cells(), 0.5*(u - obs[2])^2),
                        initial = lg.integral(mesh:cells(), beta/2*lg.dot(lg.grad(u0), lg.grad(u0)))}
local rf = lg.reduced_functional{problem = step, functional = J, control = u0, checkpoints = snaps}
local all = lg.reduced_functional{problem = step, functional = J, control = u0, checkpoints = "all"}

-- the gradient: the same with 8 snapshots as with every state kept, and a Taylor test
local start = 0.5*lg.exp(-20*((x - 0.5)^2 + (y - 0.5)^2))
u0:assign(start)
local g1, g2 = rf:gradient(nil, {riesz = "none"}), all:gradient(nil, {riesz = "none"})
local a, b, dmax = g1:values(), g2:values(), 0
for i = 1, #a do dmax = math.max(dmax, math.abs(a[i] - b[i]) / (1e-300 + math.abs(b[i]))) end
local st = rf:stats()
print(string.format("initial_condition: %dx%d P1, %d steps; gradient with %d snapshots (%d forward steps recomputed) "
                    .. "against every state kept: largest relative difference %.1e", N, N, steps, snaps, st.recomputed, dmax))
assert(dmax < 1e-10, "the checkpointed gradient differs from the stored one")
local t = lg.taylor_test(rf, start, lg.sin(pi*x)*lg.sin(pi*y), {h = 0.05, steps = 4})
print(t)
assert(math.abs(t.rates1[#t.rates1] - 2) < 0.05, "the gradient fails its Taylor test")

u0:assign(0*x)
local t0 = lg.wtime()
local uopt, info = lg.minimize(rf, {method = "lmvm", gttol = 1e-5, gatol = 0, grtol = 0, maxit = 200, monitor = false})
local err0 = math.sqrt(lg.integrate(mesh, truth^2))
local err = math.sqrt(lg.integrate(mesh, (uopt - truth)^2))
print(string.format("initial_condition: L-BFGS, %d iterations (%d evaluations), %.2f s: J = %.4e, "
                    .. "relative L2 error of u0 %.3f (0 gives 1)", info.iterations, info.evaluations, lg.wtime() - t0,
                    info.J, err / err0))
assert(err / err0 < 0.6, "the initial state was not recovered")
