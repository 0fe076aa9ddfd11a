-- cahn_hilliard.lua — phase separation: the Cahn-Hilliard equation in mixed form (FEniCSx's
-- demo problem), c_t = div(M grad mu), mu = f'(c) - lambda lap c, f = 100 c^2 (1 - c)^2, on
-- the unit square with P1 x P1 (c, mu), Crank-Nicolson in mu (theta = 1/2), Newton each
-- step from the last. Checks that the total concentration is conserved, the free energy
-- falls, and Newton takes few iterations per step (full steps, lugal's default).
-- Run: lugal examples/cahn_hilliard.lua [n] [steps]
local lg = require "lugal"
local n = tonumber(arg and arg[1]) or 32
local steps = tonumber(arg and arg[2]) or 20
local lambda, dt, theta = 1e-2, 5e-6, 0.5
local mesh = lg.mesh.rectangle{nx = n}
local P1 = lg.lagrange(1)
local c, mu = lg.unknown(P1, "c"), lg.unknown(P1, "mu")
local q, v = lg.test(P1, "q"), lg.test(P1, "v")
-- the previous step, and the initial state: c = 0.63 + 0.02 (random - 1/2)
local c0, mu0 = lg.zero_function(P1, mesh, "c0"), lg.zero_function(P1, mesh, "mu0")
math.randomseed(2)
local init = {}
for i = 1, c0:ndof() do init[i] = 0.63 + 0.02*(math.random() - 0.5) end
c0:assign(init)
local dfdc = 200*c*(1 - c)^2 - 200*c^2*(1 - c)          -- f'(c)
local mu_mid = (1 - theta)*mu0 + theta*mu
local F = lg.integral(mesh:cells(), (c - c0)*q + dt*lg.dot(lg.grad(mu_mid), lg.grad(q))
                                    + mu*v - dfdc*v - lambda*lg.dot(lg.grad(c), lg.grad(v)))
local prob = lg.nonlinear_problem{mesh = mesh, eqn = F, test = {q, v}, unknown = {c, mu}}
lg.options("-snes_rtol 1e-6")
local function energy(ch) return lg.integrate(mesh, 100*ch^2*(1 - ch)^2 + lambda/2*lg.dot(lg.grad(ch), lg.grad(ch))) end
local mass0, e0 = lg.integrate(mesh, c0), energy(c0)
local t0, its, worst = lg.wtime(), 0, 0
local ch, muh = c0, mu0
for s = 1, steps do
  local info
  ch, muh, info = prob:solve({ch, muh})
  c0:assign(ch)
  mu0:assign(muh)
  its = its + info.iterations
  worst = math.max(worst, info.iterations)
end
local mass, e = lg.integrate(mesh, ch), energy(ch)
mesh:write("cahn_hilliard.vtu", {c = ch, mu = muh})
print(string.format("cahn_hilliard: %dx%d, %d steps of dt = %g in %.2f s: Newton %.1f iterations per step (at most %d); " ..
                    "mass %.12f -> %.12f, free energy %.6f -> %.6f", n, n, steps, dt, lg.wtime() - t0, its/steps, worst,
                    mass0, mass, e0, e))
assert(math.abs(mass - mass0) < 1e-10, "the total concentration is conserved")
assert(e < e0, "the free energy falls")
assert(worst <= 6, "Newton converges in a few full steps")
