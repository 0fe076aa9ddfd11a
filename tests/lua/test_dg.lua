-- Discontinuous Lagrange spaces (lg.discontinuous): every cell owns its nodes, so a field
-- with a jump along mesh lines is represented exactly (its L2 projection onto DG1 is exact,
-- onto P1 it is not), dofs count cells x nodes, point values differ on the two sides of the
-- jump, DG controls differentiate (Taylor rates 2 and 3), and VTU output averages the cells'
-- values at each vertex.
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local T = require "testlib"
local lg = require "lugal"
local x, y = lg.x, lg.y

local mesh = lg.mesh.rectangle{nx = 8}
local DG1, P1 = lg.discontinuous(1), lg.lagrange(1)
T.check(tostring(DG1) == "discontinuous Lagrange P1", "basis name: %s", tostring(DG1))
-- a jump at x = 1/2 (a mesh line), linear on each side
local step = function(a, b) return a < 0.5 and 1 + a + b or 3 - 2*b end
local f = lg.sign(x - 0.5)
local g = (1 - f)/2*(1 + x + y) + (1 + f)/2*(3 - 2*y)
local function project(B)
  local u, v = lg.unknown(B, "u"), lg.test(B, "v")
  return lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), u*v - g*v, {order = 4}), test = v, unknown = u}:solve()
end
local pd, pc = project(DG1), project(P1)
local ed = math.sqrt(lg.integrate(mesh, (pd - g)^2, {order = 4}))
local ec = math.sqrt(lg.integrate(mesh, (pc - g)^2, {order = 4}))
print(string.format("L2 projection of a jump: DG1 error %.2e, P1 error %.2e", ed, ec))
T.check(ed < 1e-12, "DG1 represents the jump exactly (%.2e)", ed)
T.check(ec > 1e-2, "P1 cannot (%.2e)", ec)
T.check(pd:ndof() == 3*mesh:ncells() and pc:ndof() == mesh:nvertices(), "DG1 has 3 dofs per triangle (%d)", pd:ndof())
-- point values on both sides of the jump
T.close(pd(0.5 - 1e-9, 0.25), step(0.5 - 1e-9, 0.25), 1e-8, "left of the jump")
T.close(pd(0.5 + 1e-9, 0.25), step(0.5 + 1e-9, 0.25), 1e-8, "right of the jump")
-- interpolation of a smooth function: DG2 equals P2 at every point
local h = lg.sin(3*x)*lg.cos(2*y)
local d2, c2 = lg.interpolate(lg.discontinuous(2), mesh, h), lg.interpolate(lg.lagrange(2), mesh, h)
T.check(math.sqrt(lg.integrate(mesh, (d2 - c2)^2)) < 1e-13, "DG2 and P2 interpolants of a smooth function agree")
-- a DG1 control: Taylor rates 2 and 3
do
  local P2 = lg.lagrange(2)
  local u, v = lg.unknown(P2, "u"), lg.test(P2, "v")
  local c = lg.control(DG1, mesh, "c")
  local st = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(u), lg.grad(v)) - c*v),
                               bc = lg.essential_bc(mesh:boundary(), v*u), test = v, unknown = u}
  local J = lg.functional(lg.integral(mesh:cells(), 100*u^4 + 1e-3*c^2))
  local rf = lg.reduced_functional{problem = st, functional = J, control = c}
  local t = lg.taylor_test(rf, 1 + x, g, {hessian = true})
  for k = 1, #t.rates1 do T.close(t.rates1[k], 2, 0.05, "DG1 control: first-order rate") end
  for k = 1, #t.rates2 do T.close(t.rates2[k], 3, 0.1 / 3, "DG1 control: second-order rate") end
  local gr = rf:gradient(1 + x)
  T.check(gr:ndof() == 3*mesh:ncells(), "the L2 gradient lives in DG1")
end
-- VTU: the mean of the cells' values at each vertex
do
  local path = os.tmpname() .. ".vtu"
  mesh:write(path, {p = pd}, {format = "ascii"})
  local fh = io.open(path)
  local text = fh:read("a")
  fh:close()
  os.remove(path)
  T.check(text:find('Name="p" NumberOfComponents="1"', 1, true) ~= nil, "a DG field is point data")
end
T.fails(function() return lg.discontinuous(4) end, "degree 0, 1, 2 or 3")
T.fails(function() return lg.discontinuous(1, 2) end, "takes one argument")
print("discontinuous spaces: all checks passed")
