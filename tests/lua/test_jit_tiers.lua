-- The tiered JIT (src/assemble/kernel/jit.c): kernels start in libtcc and move to the system
-- compiler's code once their assemblies have taken tier_ms; both tiers must give the same
-- answers to the last bit (the system compiler runs with -ffp-contract=off: no fused
-- multiply-adds, as libtcc), for matrices, right-hand sides, integrals, functionals and
-- gradients, on cells and facets, with transcendental coefficients and parameters.
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local T = require "testlib"
local lg = require "lugal"

lg.jit("auto", {tier_ms = 0})   -- every kernel moves after its first assembly
local x, y = lg.x, lg.y
local mesh = lg.mesh.rectangle{nx = 6}
local P2 = lg.lagrange(2)
local u, v = lg.unknown(P2, "u"), lg.test(P2, "v")
local a = lg.parameter("a", 0.7)
local w = lg.interpolate(P2, mesh, lg.exp(x*y), "w")
local eqn = lg.integral(mesh:cells(), (1 + a*w^2 + lg.sin(3*x)^2)*lg.dot(lg.grad(v), lg.grad(u)) + u*v/(1 + y)
                        - lg.exp(-(x - 0.3)^2/0.1)*lg.cos(5*y)*v)
          + lg.integral(mesh:boundary("top"), lg.sqrt(1 + x)*u*v - lg.atan(x)*v)
local prob = lg.linear_problem{mesh = mesh, eqn = eqn, bc = lg.essential_bc(mesh:boundary("left"), v*u), test = v, unknown = u}

local function snapshot()
  local A = prob:matrix()
  local uh = prob:solve()
  local I = lg.integrate(mesh, lg.sin(uh)*w + lg.exp(x)*uh^2)
  return A, uh:values(), I
end
local A1, u1, I1 = snapshot()          -- libtcc code
local before = lg.jit_status()
local st = lg.jit_status(true)         -- waits for the background builds
T.check(st.cc > 0 and st.compiling == 0, "kernels moved to the system compiler: %d (before: %d in libtcc, %d compiling)",
        st.cc, before.tcc, before.compiling)
local A2, u2, I2 = snapshot()          -- the system compiler's code
local diff = 0
for i = 1, #A1 do
  for j = 1, #A1 do if A1[i][j] ~= A2[i][j] then diff = diff + 1 end end
end
T.check(diff == 0, "%d matrix entries differ between the tiers", diff)
local du = 0
for i = 1, #u1 do if u1[i] ~= u2[i] then du = du + 1 end end
T.check(du == 0, "%d solution values differ between the tiers", du)
T.check(I1 == I2, "the integral differs between the tiers: %.17g against %.17g", I1, I2)
-- a reduced functional: value and gradient the same in both tiers
local P1 = lg.lagrange(1)
local p, q = lg.unknown(P1, "p"), lg.test(P1, "q")
local f = lg.control(P1, mesh, "f", 1 + x)
local st2 = lg.nonlinear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), (1 + p^2)*lg.dot(lg.grad(q), lg.grad(p)) - f*q),
                                 bc = lg.essential_bc(mesh:boundary(), q*p), test = q, unknown = p}
local rf = lg.reduced_functional{problem = st2, control = f,
                                 functional = lg.functional(lg.integral(mesh:cells(), (p - lg.sin(math.pi*x)*y)^2 + 0.01*f^2))}
local j1, g1 = rf:value(), rf:gradient(nil, {riesz = "none"}):values()
lg.jit_status(true)
f:assign(1 + x)
local j2, g2 = rf:value(), rf:gradient(nil, {riesz = "none"}):values()
local dg = 0
for i = 1, #g1 do if g1[i] ~= g2[i] then dg = dg + 1 end end
T.check(j1 == j2 and dg == 0, "reduced functional: J %.17g against %.17g, %d gradient entries differ", j1, j2, dg)
T.fails(function() return lg.jit("gcc") end, "lg.jit: argument 1 must be \"tcc\", \"cc\" or \"auto\"")
T.fails(function() return lg.jit("auto", {tier_ms = -1}) end, "option 'tier_ms' must be a finite number >= 0")
print(string.format("jit tiers: %d kernels moved to the system compiler; matrix, solution, integral, J and gradient identical to the last bit",
                    lg.jit_status().cc))
