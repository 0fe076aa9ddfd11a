-- Transcendental functions of the coordinates evaluated for all quadrature points of an
-- item at once (src/expr/codegen.c, expr_tape_vector_calls; src/assemble/kernel/vmath.c): known
-- integrals on triangles, quadrilaterals, tetrahedra and boundary facets; nested calls (a
-- call in another's argument, and a chain deeper than the vectorized levels); calls under
-- the point cache; and the same numbers to 1e-14 as this script run again with
-- -lugal_vector_math 0 (every call per point through libm).
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local T = require "testlib"
local lg = require "lugal"

local child = arg[1] == "child"
local pi, x, y, z = math.pi, lg.x, lg.y, lg.z
local sq = lg.mesh.rectangle{nx = 16}
local quad = lg.mesh.rectangle{nx = 12, cell = "quadrilateral"}
local function deep(e, n) for _ = 1, n do e = lg.sin(e + 0.01) end return e end
local vals = {
  lg.integrate(sq, lg.sin(pi*x)*lg.sin(pi*y)),                    -- 4/pi^2
  lg.integrate(quad, lg.exp(x + y)),                               -- (e - 1)^2
  lg.integrate(sq:boundary("top"), lg.exp(x)*lg.cos(pi*y)),       -- -(e - 1)
  lg.integrate(sq, lg.sin(lg.exp(x))*lg.atan(y)),                 -- nested: level 2
  lg.integrate(sq, deep(x*y, 9)),                                  -- deeper than the vector levels
  lg.integrate(quad, lg.cosh(x - y) + lg.tanh(3*x)*lg.asin(0.9*y) + lg.acos(0.5*x)*lg.sinh(y) + lg.log(1 + x)*lg.tan(y)),
}
-- a problem whose right-hand side and a functional cache their values (read on later solves)
local P1 = lg.lagrange(1)
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
local a = lg.parameter("a_vm", 1.0)
-- (a new problem for each value: the kernels and their caches are shared, and each solve is
-- a direct one; a kept factorization would solve the third iteratively, to 1e-12, not to the bit)
local function problem()
  return lg.linear_problem{mesh = sq, test = v, unknown = u,
    eqn = lg.integral(sq:cells(), a*lg.dot(lg.grad(v), lg.grad(u)) - 2*pi^2*lg.sin(pi*x)*lg.sin(pi*y)*v),
    bc = lg.essential_bc(sq:boundary(), v*u)}
end
for _, av in ipairs{1.0, 2.0, 1.0} do
  a:set(av)
  local uh = problem():solve()
  vals[#vals + 1] = lg.integrate(sq, (uh - lg.sin(pi*x)*lg.sin(pi*y))^2)
end
-- (a 3D mesh last: lg.grad's dimension follows the meshes made so far)
local cube = lg.mesh.box{nx = 6, ny = 6, nz = 6}
vals[#vals + 1] = lg.integrate(cube, lg.sin(pi*x)*lg.sin(pi*y)*lg.sin(pi*z)) -- 8/pi^3
if child then
  for _, val in ipairs(vals) do print(string.format("%a", val)) end
  return
end
local e = math.exp(1)
T.close(vals[1], 4/pi^2, 1e-12)
T.close(vals[2], (e - 1)^2, 1e-7)  -- Gauss on quadrilaterals at the estimated degree
T.close(vals[3], -(e - 1), 1e-12)
T.check(vals[7] == vals[9] and vals[7] ~= vals[8], "the cached solve repeats its error to the bit: %.17g %.17g %.17g",
        vals[7], vals[8], vals[9])
T.check(vals[7] > 1e-6 and vals[7] < 1e-4, "P1 squared L2 error %.3e (16 x 16 cells)", vals[7])
T.close(vals[10], 8/pi^3, 1e-6)
local pipe = io.popen(string.format("'%s' '%s' child -lugal_vector_math 0", arg[-1], arg[0]))
local off = {}
for line in pipe:lines() do off[#off + 1] = tonumber(line) end
pipe:close()
T.check(#off == #vals, "the scalar run printed %d numbers, expected %d", #off, #vals)
local worst = 0
for i = 1, math.min(#off, #vals) do
  local r = math.abs(vals[i] - off[i]) / math.max(math.abs(off[i]), 1e-300)
  if r > worst then worst = r end
end
T.check(worst < 1e-14, "vector and scalar math differ by %.2e relative", worst)
print(string.format("vector math: known integrals, nested and deep calls, cached solves; %.1e from scalar libm", worst))
