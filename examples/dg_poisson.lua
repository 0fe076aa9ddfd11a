-- examples/dg_poisson.lua [N] — the Poisson equation by the symmetric interior penalty
-- method (SIPG) with discontinuous P1 and P2 elements: the jumps and averages over
-- mesh:interior_facets() read as written on paper, the boundary value is imposed weakly
-- (Nitsche), and the L2 error falls at the rate p + 1.
--   ∫ grad u . grad v - ∫_F ({grad u} . [v n] + {grad v} . [u n]) + ∫_F σ/h [u n] . [v n]
--   - ∫_∂Ω (grad u . n v + grad v . n (u - g)) + ∫_∂Ω σ/h (u - g) v = ∫ f v
local lg = require "lugal"
local x, y, pi = lg.x, lg.y, math.pi
local n0 = tonumber(arg and arg[1]) or 8

local ue = lg.sin(pi*x)*lg.sin(pi*y) + x   -- the exact solution (and the boundary value g)
local f = 2*pi^2*lg.sin(pi*x)*lg.sin(pi*y)

local function solve(p, N)
  local mesh = lg.mesh.rectangle{nx = N}
  local V = lg.discontinuous(p)
  local u, v = lg.unknown(V, "u"), lg.test(V, "v")
  local n, h, sigma = lg.normal(), 1/N, 10*p*p   -- penalty σ/h, σ = 10 p^2
  local F, B = mesh:interior_facets(), mesh:boundary()
  local eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(u), lg.grad(v)) - f*v)
    + lg.integral(F, -lg.dot(lg.avg(lg.grad(u)), lg.jump(v, n)) - lg.dot(lg.avg(lg.grad(v)), lg.jump(u, n))
                     + sigma/h*lg.dot(lg.jump(u, n), lg.jump(v, n)))
    + lg.integral(B, -lg.dot(lg.grad(u), n)*v - lg.dot(lg.grad(v), n)*(u - ue) + sigma/h*(u - ue)*v)
  local uh, info = lg.linear_problem{mesh = mesh, eqn = eqn, test = v, unknown = u}:solve()
  if p == 2 and N == n0 then mesh:write("dg_poisson.vtu", {u = uh}) end
  local e = uh - ue
  -- the jumps of the discrete solution shrink with the error: a consistency check
  local jump = math.sqrt(lg.integrate(F, lg.jump(uh)^2))
  return math.sqrt(lg.integrate(mesh, e^2)), jump, info.dofs
end

for p = 1, 2 do
  local e1, j1, d1 = solve(p, n0)
  local e2, j2, d2 = solve(p, 2*n0)
  local rate = math.log(e1/e2, 2)
  print(string.format("dg_poisson: SIPG DG%d, %d and %d dofs: L2 errors %.3e %.3e, rate %.2f; L2 norm of the jumps %.2e %.2e",
                      p, d1, d2, e1, e2, rate, j1, j2))
  assert(math.abs(rate - (p + 1)) < 0.15, "the L2 rate is p + 1")
  assert(j2 < j1 / 2^p, "the jumps shrink at least as h^p")
end
