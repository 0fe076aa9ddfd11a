-- burgers1d.lua — the steady viscous Burgers equation on [0, 1], u u' = nu u'', with
-- u(0) = 1, u(1) = -1: a shock of width ~nu at x = 1/2, exactly u = -tanh((x - 1/2)/(2 nu)).
-- P2 on intervals (lg.mesh.interval), Newton from u = 1 - 2x with continuation in nu.
-- Checks the L2 error against the exact solution and the rate under refinement.
-- Run: lugal examples/burgers1d.lua [n]
local lg = require "lugal"
local n = tonumber(arg and arg[1]) or 64
local x = lg.x
local nu_final = 0.02

local function solve(cells)
  local mesh = lg.mesh.interval{n = cells}
  local P2 = lg.lagrange(2)
  local u, v = lg.unknown(P2, "u"), lg.test(P2, "v")
  local nu = lg.parameter("nu", 0.2)
  local F = lg.integral(mesh:cells(), u*lg.dx(u, 1)*v + nu*lg.dx(u, 1)*lg.dx(v, 1))
  local bc = {lg.essential_bc(mesh:boundary("left"), v*(u - 1)), lg.essential_bc(mesh:boundary("right"), v*(u + 1))}
  local prob = lg.nonlinear_problem{mesh = mesh, eqn = F, bc = bc, test = v, unknown = u}
  local uh = lg.interpolate(P2, mesh, 1 - 2*x)
  local its = 0
  for _, s in ipairs{0.2, 0.1, 0.05, nu_final} do
    nu:set(s)
    local info
    uh, info = prob:solve(uh)
    its = its + info.iterations
  end
  local exact = -lg.tanh((x - 0.5)/(2*nu_final))
  return mesh, uh, math.sqrt(lg.integrate(mesh, (uh - exact)^2)), its
end

local mesh, uh, e1, its = solve(n)
local _, _, e2 = solve(2*n)
local rate = math.log(e1/e2, 2)
mesh:write("burgers1d.vtu", {u = uh})
print(string.format("burgers1d: nu = %g, %d P2 intervals: %d Newton iterations over 4 continuation steps, u(0.45) = %.6f " ..
                    "(exact %.6f), L2 error %.3e, rate %.2f to %d intervals", nu_final, n, its, uh(0.45),
                    -math.tanh(-0.05/(2*nu_final)), e1, rate, 2*n))
assert(e1 < 2e-4 * (64/n)^3, "close to the exact solution (1.2e-4 at 64 intervals)")
assert(math.abs(rate - 3) < 0.2, "P2: L2 rate 3")
