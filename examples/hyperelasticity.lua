-- hyperelasticity.lua — a compressible Neo-Hookean cantilever bending under its own weight,
-- large deformation. The stored energy is written as on paper,
--   F = I + grad u,  C = F^T F,  J = det F,
--   psi = mu/2 (tr C - 3) - mu ln J + lambda/2 (ln J)^2,
-- and the residual is its Gateaux derivative, lg.derivative(Pi, u, v); Newton's Jacobian is
-- the engine's second derivative. The load is applied in steps, each Newton solve starting
-- from the last. Prints the Newton residuals of the last step (quadratic convergence) and
-- the tip deflection against the linear one (large rotations make it smaller).
-- Run: lugal examples/hyperelasticity.lua [n] [steps]
local lg = require "lugal"
local n = tonumber(arg and arg[1]) or 2
local steps = tonumber(arg and arg[2]) or 3
local L, H = 1.0, 0.1
local E, nu = 1e3, 0.3
local mu, lambda = E/(2*(1 + nu)), E*nu/((1 + nu)*(1 - 2*nu))

local mesh = lg.mesh.box{nx = 10*n, ny = n, nz = n, x1 = L, y1 = H, z1 = H}
local V = lg.vector(lg.lagrange(2))          -- P2: P1 tetrahedra lock in bending
local u, v = lg.unknown(V, "u"), lg.test(V, "v")
local load = lg.parameter("load", 0)          -- weight per volume, raised step by step

local F = lg.identity(3) + lg.grad(u)
local C = lg.dot(lg.transpose(F), F)
local J = lg.det(F)
local psi = mu/2*(lg.tr(C) - 3) - mu*lg.log(J) + lambda/2*lg.log(J)^2
local Pi = lg.integral(mesh:cells(), psi - lg.dot({0, 0, -load}, u))
local residual = lg.derivative(Pi, u, v)
local bc = lg.essential_bc(mesh:boundary("left"), lg.dot(v, u))
local problem = lg.nonlinear_problem{mesh = mesh, eqn = residual, bc = bc, test = v, unknown = u}
lg.options("-snes_rtol 1e-10 -snes_atol 1e-10")

local q = 3.0                                  -- linear theory: a tip deflection of 0.45 L
local uh, info
local t0 = lg.wtime()
for s = 1, steps do
  load:set(q*s/steps)
  uh, info = problem:solve(uh)
  local tip = lg.integrate(mesh:boundary("right"), uh[3]) / (H*H)
  print(string.format("hyperelasticity: load %.2f, %d Newton iterations, tip deflection %.4f", q*s/steps, info.iterations, tip))
  assert(info.iterations <= 8, "Newton converges in a few steps at every load")
end
local r = info.residuals
for k = 1, #r do
  print(string.format("  iteration %d: |F| = %.3e%s", k - 1, r[k], k > 1 and string.format("  |F_k|/|F_k-1|^2 = %.3g", r[k]/r[k-1]^2) or ""))
end

-- the linear elastic answer at the full load, and the beam theory's
local w = lg.test(V, "w")
local function eps(x) return lg.sym(lg.grad(x)) end
local lin = lg.linear_problem{mesh = mesh, test = w, unknown = u, bc = lg.essential_bc(mesh:boundary("left"), lg.dot(w, u)),
  eqn = lg.integral(mesh:cells(), 2*mu*lg.inner(eps(u), eps(w)) + lambda*lg.div(u)*lg.div(w) - lg.dot({0, 0, -q}, w))}:solve()
local tip = lg.integrate(mesh:boundary("right"), uh[3]) / (H*H)
local tip_lin = lg.integrate(mesh:boundary("right"), lin[3]) / (H*H)
mesh:write("hyperelasticity.vtu", {displacement = uh})
print(string.format("hyperelasticity: %d dofs, %d load steps in %.2f s; tip deflection %.4f, linear %.4f (ratio %.3f)",
                    uh:ndof(), steps, lg.wtime() - t0, tip, tip_lin, tip/tip_lin))
assert(tip < 0 and math.abs(tip) < math.abs(tip_lin) and math.abs(tip) > 0.5*math.abs(tip_lin),
       "the large-deformation tip deflection is below the linear one")
