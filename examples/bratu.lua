-- bratu.lua — the Bratu problem -Δu = λ e^u on the unit square, u = 0 on the boundary,
-- solved by Newton's method (PETSc SNES) with the Jacobian derived symbolically from the
-- residual. Prints the residual history and the ratios r_{k+1} / r_k^2 that show
-- quadratic convergence.
-- Run: lugal examples/bratu.lua [n] [lambda] [-snes_monitor ...]
local lg = require "lugal"
local n = tonumber(arg[1]) or 32
local lambda = lg.parameter("lambda", tonumber(arg[2]) or 6.0)

local mesh = lg.mesh.rectangle{nx = n, ny = n}
local P1 = lg.lagrange(1)
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")

local F = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) - lambda*lg.exp(u)*v)
local bc = lg.essential_bc(mesh:boundary(), v*u)

local prob = lg.nonlinear_problem{mesh = mesh, eqn = F, bc = bc, test = v, unknown = u}
local uh, info = prob:solve()

print(string.format("bratu: %dx%d P1, lambda = %g: %d Newton iterations (%s)", n, n, lambda:value(),
                    info.iterations, info.reason))
for k, r in ipairs(info.residuals) do
  if k == 1 then
    print(string.format("  iteration 0: |F| = %.3e", r))
  else
    print(string.format("  iteration %d: |F| = %.3e   |F_k|/|F_{k-1}|^2 = %.3g", k - 1, r, r / info.residuals[k-1]^2))
  end
end
print(string.format("  max u = %.6f", math.max(table.unpack(uh:values()))))
