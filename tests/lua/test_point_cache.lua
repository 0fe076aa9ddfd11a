-- The per-point cache of coordinate-only transcendental terms (src/expr/codegen.c,
-- expr_tape_point_cache; src/assemble/assemble.c, pcache_mode): kernels that cache the
-- same subexpressions with the same rule on the same items share one group; a small group
-- is stored by its first assembly and read by every later one. The answers must be the
-- same to the last bit as with the cache off (this script run again with
-- -lugal_point_cache 0), on cell and boundary integrals, in functionals, gradients and
-- problem right-hand sides; J's values must serve dJ/du and a new problem's kernels; and a
-- changed geometry must not be answered from the old cache.
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local T = require "testlib"
local lg = require "lugal"

local pi, x, y = math.pi, lg.x, lg.y
local mesh = lg.mesh.rectangle{nx = 10}
local P1 = lg.lagrange(1)
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
local f = lg.control(P1, mesh, "f", 1 + x)
local d = lg.sin(pi*x)*lg.sin(pi*y)/(2*pi^2)
local src = lg.exp(-10*((x - 0.3)^2 + (y - 0.6)^2))
local state = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) - (f + src)*v),
                                bc = lg.essential_bc(mesh:boundary("left", "right"), v*u), test = v, unknown = u}
local J = lg.functional(lg.integral(mesh:cells(), 0.5*(u - d)^2 + 1e-4/2*f^2)
                        + lg.integral(mesh:boundary("top"), lg.cos(3*x)*u^2))
local rf = lg.reduced_functional{problem = state, functional = J, control = f}

local function snapshot(m)
  local j = rf:value(m)
  local g = rf:gradient(nil, {riesz = "none"}):values()
  local s = rf:state():values()
  return j, g, s
end
local function same(a, b, what)
  T.check(#a == #b, "%s: sizes", what)
  for i = 1, #a do
    if a[i] ~= b[i] then T.check(false, "%s: entry %d differs: %.17g against %.17g", what, i, a[i], b[i]) return end
  end
end
local child = arg[1] == "child"
local pc0 = lg.stats().point_cache
-- the same control three times (store, read, read), then another control (read)
local j1, g1, s1 = snapshot(1 + x)
do
  -- J's kernel stored its values on the first assembly; dJ/du (the adjoint's right-hand
  -- side) caches the same target d with the same rule and read them
  local pc = lg.stats().point_cache
  T.check(child or pc.computed == pc0.computed and pc.stored >= pc0.stored + 2 and pc.read >= pc0.read + 1,
          "first evaluation and gradient: computed %d, stored %d, read %d (before: %d, %d, %d)",
          pc.computed, pc.stored, pc.read, pc0.computed, pc0.stored, pc0.read)
  T.check(child or pc.groups >= 2 and pc.bytes > 0, "point cache groups %d, bytes %d", pc.groups, pc.bytes)
end
local j2, g2, s2 = snapshot(1 + x)
local j3, g3, s3 = snapshot(1 + x)
T.check(j1 == j2 and j2 == j3, "J: %.17g %.17g %.17g", j1, j2, j3)
same(g1, g2, "gradient, store"); same(g1, g3, "gradient, read")
same(s1, s2, "state, store"); same(s1, s3, "state, read")
-- a new problem and reduced functional read what the live kernels stored
local function fresh(m)
  local st2 = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) - (f + src)*v),
                                  bc = lg.essential_bc(mesh:boundary("left", "right"), v*u), test = v, unknown = u}
  local r2 = lg.reduced_functional{problem = st2, functional = J, control = f}
  return r2:value(m), r2:gradient(nil, {riesz = "none"}):values()
end
local j4, g4 = snapshot(lg.y)
local pc1 = lg.stats().point_cache
local j5, g5 = fresh(lg.y)
local pc2 = lg.stats().point_cache
T.check(child or pc2.computed == pc1.computed and pc2.stored == pc1.stored and pc2.read > pc1.read,
        "a new problem on the same mesh reads the live caches: computed +%d, stored +%d, read +%d",
        pc2.computed - pc1.computed, pc2.stored - pc1.stored, pc2.read - pc1.read)
T.check(j4 == j5, "another control: cached J %.17g, fresh %.17g", j4, j5)
same(g4, g5, "another control: gradient")
-- lg.integrate keeps its kernels (and their caches) for the next call with the same integrand
local ig = (rf:state() - d)^2*lg.exp(x)
local i1, i2, i3 = lg.integrate(mesh, ig), lg.integrate(mesh, ig), lg.integrate(mesh, ig)
T.check(i1 == i2 and i2 == i3, "lg.integrate: %.17g %.17g %.17g", i1, i2, i3)
local ib1, ib2, ib3 = lg.integrate(mesh:boundary("top"), ig), lg.integrate(mesh:boundary("top"), ig), lg.integrate(mesh:boundary("top"), ig)
T.check(ib1 == ib2 and ib2 == ib3 and ib1 ~= i1, "lg.integrate on a boundary: %.17g %.17g %.17g", ib1, ib2, ib3)
-- move the mesh: the cached values belong to the old geometry
mesh:displace(function(px, py) return 0.05*px*(1 - px)*py, 0 end)
local j6, g6 = snapshot(lg.y)
local j7, g7 = fresh(lg.y)
T.check(j6 ~= j4, "the moved mesh changes J (%.17g)", j6)
-- (rf's state matrix changed with the mesh: its solve is by the kept factorization, to 1e-12;
-- the bit-for-bit comparison of these values is the child run's below)
T.close(j6, j7, 1e-10, "moved mesh: cached J against a new problem's")
local i4 = lg.integrate(mesh, ig)
T.check(i4 ~= i1, "lg.integrate on the moved mesh: %.17g (was %.17g)", i4, i1)
do
  local gmax, gd = 0, 0
  for i = 1, #g7 do gmax = math.max(gmax, math.abs(g7[i])); gd = math.max(gd, math.abs(g6[i] - g7[i])) end
  T.check(#g6 == #g7 and gd <= 1e-9*gmax, "moved mesh: gradient %.2e from a new problem's (max %.2e)", gd, gmax)
end
-- and the Taylor test still holds on the moved mesh with the cache in use
local t = lg.taylor_test(rf, 1 + x*y, lg.sin(2*x))
T.check(math.abs(t.rates1[#t.rates1] - 2) < 0.05, "Taylor rate %.3f\n%s", t.rates1[#t.rates1], tostring(t))
local s1c, s2c
-- a matrix assembled in chunks of items (more cells than one chunk): the cache spans the
-- chunks; a parameter changes between assemblies (a new problem each time, which shares
-- the kernels and their cache, so that each solve is a direct one: the same problem would
-- solve a changed matrix with its kept factorization, to 1e-12 and not to the bit)
do
  local big = lg.mesh.rectangle{nx = 50, ny = 45}
  local a = lg.parameter("a_pc", 1.0)
  local function pb()
    return lg.linear_problem{mesh = big, test = v, unknown = u,
      eqn = lg.integral(big:cells(), (1 + a*lg.sin(7*x)^2*lg.exp(y))*lg.dot(lg.grad(v), lg.grad(u)) - lg.cos(3*x*y)*v),
      bc = lg.essential_bc(big:boundary(), v*u)}
  end
  local s1 = pb():solve():values()           -- stores
  a:set(2.0); local s2 = pb():solve():values() -- reads
  a:set(1.0); local s3 = pb():solve():values()
  a:set(2.0); local s4 = pb():solve():values()
  s1c, s2c = s1, s2
  same(s1, s3, "chunked matrix assembly, read against computed")
  same(s2, s4, "chunked matrix assembly, a = 2")
  T.check(s1[1000] ~= s2[1000], "the parameter changes the solution")
end
-- the same numbers with the cache off, from this script run again with -lugal_point_cache 0
local all = {j1, j3, j4, j6, i1, ib1, i4}
for _, t in ipairs{g1, s1, g4, g6, s1c, s2c} do
  for _, val in ipairs(t) do all[#all + 1] = val end
end
if child then
  for _, val in ipairs(all) do print(string.format("%a", val)) end
  return
end
local cmd = string.format("'%s' '%s' child -lugal_point_cache 0", arg[-1], arg[0])
local pipe = io.popen(cmd)
local off = {}
for line in pipe:lines() do off[#off + 1] = tonumber(line) end
pipe:close()
T.check(#off == #all, "the run without the cache printed %d numbers, expected %d (%s)", #off, #all, cmd)
local ndiff = 0
for i = 1, math.min(#off, #all) do if off[i] ~= all[i] then ndiff = ndiff + 1 end end
T.check(ndiff == 0, "%d of %d numbers differ from the run without the cache", ndiff, #all)
print(string.format("point cache: J, gradient and state identical to the last bit in every mode (J = %.15g); a moved mesh recomputes",
                    j3))
