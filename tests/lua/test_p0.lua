-- Piecewise constants (lg.lagrange(0), one value per cell): interpolation at the centroids,
-- integrals, the L2 projection (error O(h)), P0 unknowns and controls (first- and
-- second-order Taylor tests on triangles and tetrahedra, minimization), cell data in VTU,
-- and an essential condition on a P0 field refused.
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local T = require "testlib"
local lg = require "lugal"

local P0, P1 = lg.lagrange(0), lg.lagrange(1)
local x, y = lg.x, lg.y
-- the centroid value integrates linear functions exactly
local m8 = lg.mesh.rectangle{nx = 8}
local r = lg.interpolate(P0, m8, 1 + 2*x + 3*y, "r")
T.check(#r:values() == m8:ncells(), "one value per cell: %d for %d cells", #r:values(), m8:ncells())
T.close(lg.integrate(m8, r), 1 + 1 + 1.5, 1e-13, "integral of a P0 interpolant of a linear function")
-- L2 projection onto P0: error O(h)
local p, q = lg.unknown(P0, "p"), lg.test(P0, "q")
local errs = {}
for k, n in ipairs({8, 16, 32}) do
  local mk = lg.mesh.rectangle{nx = n}
  local g = lg.sin(3*x)*lg.exp(y)
  local ph = lg.linear_problem{mesh = mk, eqn = lg.integral(mk:cells(), p*q - g*q), test = q, unknown = p}:solve()
  errs[k] = math.sqrt(lg.integrate(mk, (ph - g)^2))
end
for k = 2, 3 do
  local rate = math.log(errs[k - 1]/errs[k], 2)
  T.check(math.abs(rate - 1) < 0.05, "P0 projection: rate %.3f from %d to %d cells per side", rate, 4*2^k, 8*2^k)
end
-- a P0 control of the Poisson mother problem: Taylor rates 2 and 3 (j is quadratic: the
-- second-order remainder is at rounding level), minimization
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
local function mother(mesh, d)
  local f = lg.control(P0, mesh, "f")
  local st = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) - f*v),
                               bc = lg.essential_bc(mesh:boundary(), v*u), test = v, unknown = u}
  return lg.reduced_functional{problem = st, control = f,
                               functional = lg.functional(lg.integral(mesh:cells(), 0.5*(u - d)^2 + 1e-6/2*f^2))}, f
end
local d2 = lg.sin(math.pi*x)*lg.sin(math.pi*y)/(2*math.pi^2)
local rf, f = mother(m8, d2)
local t = lg.taylor_test(rf, 1 + x, lg.sin(3*x)*y, {hessian = true})
T.check(math.abs(t.rates1[#t.rates1] - 2) < 0.05, "P0 control: Taylor rate %.3f\n%s", t.rates1[#t.rates1], tostring(t))
T.check(t.remainders2[1] < 1e-9 * t.remainders1[1], "P0 control: exact second-order expansion\n%s", tostring(t))
local _, info = lg.minimize(rf, {gttol = 1e-8, gatol = 0, grtol = 0, monitor = false})
T.check(info.converged and info.J < 1e-3 * rf:value(0*x), "P0 control minimized: J = %g (%s, %d iterations)", info.J, info.reason,
        info.iterations)
local out = arg[0]:match("(.*/)") .. "../out/"
os.execute("mkdir -p '" .. out .. "'")
m8:write(out .. "p0_control.vtu", {f = f, u = rf:state()})
local fh = io.open(out .. "p0_control.vtu")
local text = fh:read("a")
fh:close()
T.check(text:find('<CellData>%s*<DataArray type="Float64" Name="f"') ~= nil, "the P0 control is cell data in the VTU")
-- an SVG picture of the P0 control: one polygon per cell
m8:write(out .. "p0_control.svg", {f = f})
fh = io.open(out .. "p0_control.svg")
text = fh:read("a")
fh:close()
local npoly = select(2, text:gsub("<polygon", ""))
T.check(npoly == m8:ncells(), "the SVG has %d polygons for %d cells", npoly, m8:ncells())
T.fails(function() return m8:write(out .. "x.svg", {u = rf:state()}) end, "must be piecewise constant (P0), or write a .vtu")
T.fails(function() return m8:write(out .. "x.svg", {f = f, g = f}) end, "an SVG picture shows one field")
T.fails(function() return lg.mesh.box{nx = 2}:write(out .. "x.svg", {}) end, "an SVG picture is of a 2D mesh")
-- tetrahedra, a nonlinear state
local box = lg.mesh.box{nx = 3}
local P1t = lg.lagrange(1)
local ut, vt = lg.unknown(P1t, "ut"), lg.test(P1t, "vt")
local ft = lg.control(P0, box, "ft")
local stt = lg.nonlinear_problem{mesh = box, eqn = lg.integral(box:cells(), (1 + ut^2)*lg.dot(lg.grad(vt), lg.grad(ut)) - ft*vt),
                                 bc = lg.essential_bc(box:boundary(), vt*ut), test = vt, unknown = ut}
local rft = lg.reduced_functional{problem = stt, control = ft, functional = lg.functional(lg.integral(box:cells(), (ut - lg.z)^2))}
local tt = lg.taylor_test(rft, 1 + lg.x, lg.y*lg.z, {hessian = true, h = 2, steps = 3})
T.check(math.abs(tt.rates1[#tt.rates1] - 2) < 0.05 and math.abs(tt.rates2[#tt.rates2] - 3) < 0.1,
        "P0 control on tetrahedra, nonlinear state: rates %.3f and %.3f\n%s", tt.rates1[#tt.rates1], tt.rates2[#tt.rates2], tostring(tt))
-- an essential condition on a P0 field has no boundary dofs
T.fails(function() return lg.linear_problem{mesh = m8, eqn = lg.integral(m8:cells(), p*q - q), test = q, unknown = p,
                                            bc = lg.essential_bc(m8:boundary(), q*p)}:solve() end,
        "problem:solve: essential_bc: boundary condition 1 is on a piecewise-constant (P0) field")
print(string.format("P0: projection errors %.3e %.3e %.3e (rate 1), Taylor rates 2 and 3, minimized in %d iterations",
                    errs[1], errs[2], errs[3], info.iterations))
