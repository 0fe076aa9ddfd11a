-- Newton's method on the Bratu problem converges quadratically with the symbolic
-- Jacobian: the ratios |F_{k+1}| / |F_k|^2 stay bounded while |F| falls to round-off.
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local T = require "testlib"
local lg = require "lugal"

local mesh = lg.mesh.rectangle{nx = 24, ny = 24}
local P2 = lg.lagrange(2)
local u, v = lg.unknown(P2, "u"), lg.test(P2, "v")
local lambda = lg.parameter("lambda", 5)
local F = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) - lambda*lg.exp(u)*v)
local prob = lg.nonlinear_problem{mesh = mesh, eqn = F, bc = lg.essential_bc(mesh:boundary(), v*u),
                                  test = v, unknown = u}
lg.options("-snes_rtol 1e-14 -snes_atol 1e-13")
local uh, info = prob:solve()
local r = info.residuals
for k = 1, #r do print(string.format("iteration %d: |F| = %.3e%s", k - 1, r[k],
                                     k > 1 and string.format("  ratio %.3f", r[k] / r[k-1]^2) or "")) end
T.check(info.iterations >= 3 and info.iterations <= 6, "Newton took %d iterations", info.iterations)
T.check(r[#r] < 1e-12, "final residual %.3e", r[#r])
-- quadratic: in the last steps with |F| well above round-off, |F_{k+1}| <= C |F_k|^2
local checked = 0
for k = 2, #r do
  if r[k] > 1e-12 and r[k-1] < 1e-2 then
    local ratio = r[k] / r[k-1]^2
    T.check(ratio < 10, "step %d: |F_k|/|F_{k-1}|^2 = %.3g is not bounded", k - 1, ratio)
    checked = checked + 1
  end
end
T.check(checked >= 1, "no step in the quadratic regime was checked")
-- a linear convergence would give ratios growing like 1/|F|: confirm the contraction factor
T.check(r[#r - 1] / r[#r - 2] < 0.05, "contraction %.3g too weak for Newton", r[#r - 1] / r[#r - 2])

-- the parameter can change between solves: larger lambda, larger solution
local m1 = math.max(table.unpack(uh:values()))
lambda:set(6)
local uh2 = prob:solve(uh)
local m2 = math.max(table.unpack(uh2:values()))
print(string.format("max u: lambda 5 -> %.6f, lambda 6 -> %.6f", m1, m2))
T.check(m2 > m1, "max u did not grow with lambda")

-- the p-Laplacian (p = 4, regularized) from zero: PETSc's divergence test stopped the
-- default Newton with DIVERGED_DTOL after one step (|F| grows 1e4-fold there first); with no
-- divergence test by default, as DOLFIN's Newton, it converges (18 steps)
do
  local m = lg.mesh.rectangle{nx = 32}
  local P1 = lg.lagrange(1)
  local w, q = lg.unknown(P1, "w"), lg.test(P1, "q")
  local g2 = lg.dot(lg.grad(w), lg.grad(w))
  local Fp = lg.integral(m:cells(), (1e-2 + g2)*lg.dot(lg.grad(w), lg.grad(q)) - 10*q)
  local function plap(prefix)
    return lg.nonlinear_problem{mesh = m, eqn = Fp, bc = lg.essential_bc(m:boundary(), q*w), test = q, unknown = w, prefix = prefix}
  end
  local _, pinfo = plap("plap_"):solve()
  print(string.format("p-Laplacian from zero: %s after %d Newton steps", pinfo.reason, pinfo.iterations))
  T.check(pinfo.iterations >= 10 and pinfo.iterations <= 30, "p-Laplacian: %d Newton steps", pinfo.iterations)
  -- the message says what to try
  lg.options("-plapd_snes_divergence_tolerance 1e4")
  T.fails(function() return plap("plapd_"):solve() end, "DIVERGED_DTOL after 1 Newton iterations", "try a damped search")
  lg.options("-plapm_snes_max_it 3")
  T.fails(function() return plap("plapm_"):solve() end, "DIVERGED_MAX_IT after 3 Newton iterations", "continuation in a parameter")
end
