-- bench/gradient_cost.lua [N] — the mother problem (bench/optimization.lua): one gradient (no Riesz
-- map) against one warm state evaluation (rf:value at a new control: the matrix and its
-- factorization kept), medians of 21 of each, wall time (issue 56: gradient <= 1.2x).
local lg = require "lugal"
local N = tonumber(arg[1]) or 128
local pi, x, y = math.pi, lg.x, lg.y
local mesh = lg.mesh.rectangle{nx = N}
local P1 = lg.lagrange(1)
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
local bc = lg.essential_bc(mesh:boundary(), v*u)
local f = lg.control(P1, mesh, "f")
local st = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) - f*v), bc = bc, test = v, unknown = u}
local d = lg.sin(pi*x)*lg.sin(pi*y)/(2*pi^2)
local J = lg.functional(lg.integral(mesh:cells(), 0.5*(u - d)^2 + 1e-6/2*f^2))
local rf = lg.reduced_functional{problem = st, functional = J, control = f}
rf:value(1 + x); rf:gradient(nil, {riesz = "none"})
local tv, tg = {}, {}
for k = 1, 21 do
  local c = lg.wtime(); rf:value(1 + x + 0.01*k*y); tv[k] = lg.wtime() - c
  c = lg.wtime(); rf:gradient(nil, {riesz = "none"}); tg[k] = lg.wtime() - c
end
table.sort(tv); table.sort(tg)
print(string.format("N=%d warm value %.5f s, gradient %.5f s, ratio %.2f", N, tv[11], tg[11], tg[11]/tv[11]))
