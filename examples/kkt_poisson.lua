-- The Poisson mother problem in full space (Sundance's route): one Lagrangian
--   L(u, lambda, f) = 1/2 int (u - d)^2 + alpha/2 int f^2 + int grad(lambda).grad(u) - f lambda,
-- whose variations in lambda, u and f are the state equation, the adjoint equation and the
-- optimality condition alpha f = lambda, solved as one coupled problem (Newton on the KKT
-- system; the state's u = 0 becomes lambda = 0 for the adjoint). The same optimum as the
-- reduced route (the gradient by an adjoint, TAO's Newton-CG on j(f)) to 1e-8 in J.
--   lugal examples/kkt_poisson.lua [N] [alpha]
local lg = require "lugal"
local N = tonumber(arg and arg[1]) or 32
local alpha = tonumber(arg and arg[2]) or 1e-6

local mesh = lg.mesh.rectangle{nx = N}
local P1 = lg.lagrange(1)
local pi = math.pi
local d = lg.sin(pi*lg.x)*lg.sin(pi*lg.y) / (2*pi^2)
local u, lam, f = lg.unknown(P1, "u"), lg.unknown(P1, "lambda"), lg.unknown(P1, "f")
local v = lg.test(P1, "v")
local bc = lg.essential_bc(mesh:boundary(), v*u)

-- full space
local Lag = lg.integral(mesh:cells(), 0.5*(u - d)^2 + alpha/2*f^2 + lg.dot(lg.grad(lam), lg.grad(u)) - f*lam)
local kkt = lg.kkt_problem{mesh = mesh, lagrangian = Lag, state = u, adjoint = lam, control = f, bc = bc}
local t0 = lg.wtime()
local uh, lh, fh, sinfo = kkt:solve()
local t_kkt = lg.wtime() - t0
local J_kkt = lg.integrate(mesh, 0.5*(uh - d)^2 + alpha/2*fh^2)

-- reduced
local fc = lg.control(P1, mesh, "f_reduced")
local state = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) - fc*v),
                                bc = bc, test = v, unknown = u}
local rf = lg.reduced_functional{problem = state, control = fc,
                                 functional = lg.functional(lg.integral(mesh:cells(), 0.5*(u - d)^2 + alpha/2*fc^2))}
t0 = lg.wtime()
local fopt, info = lg.minimize(rf, {method = "nls", gttol = 1e-10, gatol = 0, grtol = 0, monitor = false})
local t_red = lg.wtime() - t0

print(string.format("kkt_poisson: %dx%d, alpha %g: full space J* = %.12e (%d Newton step, %d dofs, %.3f s)", N, N, alpha, J_kkt,
                    sinfo.iterations, sinfo.dofs, t_kkt))
print(string.format("             reduced    J* = %.12e (%d nls iterations, %d Hessian products, %.3f s)", info.J,
                    info.iterations, info.hessian_products, t_red))
local df = math.sqrt(lg.integrate(mesh, (fh - fopt)^2) / lg.integrate(mesh, fh^2))
-- optimality: alpha f = lambda
local opt = math.sqrt(lg.integrate(mesh, (alpha*fh - lh)^2) / lg.integrate(mesh, lh^2))
print(string.format("  relative |J_kkt - J_reduced| = %.2e, |f_kkt - f_reduced| / |f| = %.2e, |alpha f - lambda| / |lambda| = %.2e",
                    math.abs(J_kkt - info.J) / J_kkt, df, opt))
assert(math.abs(J_kkt - info.J) < 1e-8 * J_kkt, "the full-space and reduced optima differ")
assert(opt < 1e-8, "the optimality condition alpha f = lambda does not hold")
mesh:write("kkt_poisson.vtu", {u = uh, lambda = lh, f = fh})
