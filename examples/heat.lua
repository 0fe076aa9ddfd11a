-- heat.lua — the heat equation u_t = Δu + f on the unit square by backward Euler, with
-- the manufactured solution u = e^{-t} sin(πx) sin(πy) (so f = (2π² - 1) u). The previous
-- step is a discrete function updated in place with uold:assign(uh); the time is a
-- parameter. Writes heat.pvd (+ heat_NNNN.vtu) for ParaView and prints the final error.
-- Run: lugal examples/heat.lua [n] [steps] [outdir]
local lg = require "lugal"
local n = tonumber(arg[1]) or 32
local steps = tonumber(arg[2]) or 20
local outdir = arg[3] or "."
local T = 0.5
local dt = T / steps

local mesh = lg.mesh.rectangle{nx = n, ny = n}
local P1 = lg.lagrange(1)
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
local t = lg.parameter("t", 0)
local pi = math.pi
local exact = lg.exp(-t) * lg.sin(pi*lg.x) * lg.sin(pi*lg.y)
local f = (2*pi^2 - 1) * exact

local uold = lg.interpolate(P1, mesh, exact, "uold")
local eqn = lg.integral(mesh:cells(), (u - uold)/dt*v + lg.dot(lg.grad(v), lg.grad(u)) - f*v)
local bc = lg.essential_bc(mesh:boundary(), v*u)
local prob = lg.linear_problem{mesh = mesh, eqn = eqn, bc = bc, test = v, unknown = u}

local series = lg.series(outdir .. "/heat.pvd")
series:write(mesh, {u = uold}, 0)
local uh
for k = 1, steps do
  t:set(k*dt)                      -- f and the boundary data are evaluated at the new time
  uh = prob:solve()
  uold:assign(uh)
  if k % 5 == 0 or k == steps then series:write(mesh, {u = uh}, k*dt) end
end
local err = math.sqrt(lg.integrate(mesh, (uh - exact)^2))
print(string.format("heat: %dx%d P1, %d backward Euler steps to t = %g: L2 error %.3e", n, n, steps, T, err))
