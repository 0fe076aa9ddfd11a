-- bench/burgers_adjoint.lua — the cost of a time-dependent gradient with Newton steps (issue
-- 55): viscous Burgers u_t + u u_x - nu u_xx = f on (0, 1) by backward Euler, P1 on N cells,
-- u = 0 at both ends, u(0) = sin(pi x), nu = 0.01, T = 0.5, a source constant in time as the
-- control, J = 1/2 ∫ (u(T) - d)² + running alpha/2 ∫∫ f² (d = 0.3 sin(2 pi x), alpha = 1e-4).
-- Prints the forward march (rf:value after the control changed: Newton at every step), the
-- backward sweep (rf:gradient right after: one transposed solve per step), their ratio, the
-- Newton iterations of a plain march and the forward steps recomputed, every state kept or s
-- snapshots.
--   lugal bench/burgers_adjoint.lua N steps [snapshots]
local lg = require "lugal"
local N = tonumber(arg[1]) or 1000
local steps = tonumber(arg[2]) or 1000
local snaps = tonumber(arg[3])
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
local _, plain = step:solve()
local J = lg.functional{final = lg.integral(mesh:cells(), 0.5*(u - d)^2), running = lg.integral(mesh:cells(), alpha/2*f^2)}
local rf = lg.reduced_functional{problem = step, functional = J, control = f, checkpoints = snaps or "all"}
local J1 = rf:value(0.1*x)
rf:gradient() -- kernels compiled, solvers set up
local tf, tg = {}, {}
for r = 1, 3 do
  local t0 = lg.wtime()
  rf:value(0.1*x + 0.01*r*x*x)
  local t1 = lg.wtime()
  rf:gradient()
  local t2 = lg.wtime()
  tf[r], tg[r] = t1 - t0, t2 - t1
end
table.sort(tf)
table.sort(tg)
print(string.format("burgers_adjoint N=%d steps=%d checkpoints=%s: forward %.3f s (%.2f Newton iterations per step), gradient "
                    .. "sweep %.3f s (%.2f x the forward), %d steps recomputed, J %.12e", N, steps, snaps and tostring(snaps) or "all",
                    tf[2], plain.iterations / steps, tg[2], tg[2] / tf[2], rf:stats().recomputed, J1))
