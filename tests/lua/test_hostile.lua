-- Hostile and careless input to the Lua module (issue 9): every case gets an error that names
-- the cause, or the right answer; nothing crashes, corrupts the interpreter or answers wrongly.
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local T = require "testlib"
local lg = require "lugal"

local mesh = lg.mesh.rectangle{nx = 4, ny = 4}
local P1 = lg.lagrange(1)
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
local n = 0
local function fails(...) n = n + 1; return T.fails(...) end
local function poisson(m, bc, extra)
  local spec = {mesh = m, eqn = lg.integral(m:cells(), lg.dot(lg.grad(v), lg.grad(u)) - v), bc = bc, test = v, unknown = u}
  for k, x in pairs(extra or {}) do spec[k] = x end
  return lg.linear_problem(spec)
end

-- field names are never registry keys: these used to corrupt the interpreter
local tmp = os.tmpname()
local vtu = tmp .. ".vtu"
local vals = {}
for i = 1, mesh:nvertices() do vals[i] = i end
mesh:write(vtu, {["lugal.Mesh"] = vals, _LOADED = vals, _CLIBS = vals, ["lugal.env"] = vals})
T.check(require("lugal") == lg and mesh:ncells() == 32 and #tostring(mesh) > 0, "the interpreter survives")
local text = assert(io.open(vtu)):read("a")
T.check(text:find('Name="_CLIBS"', 1, true) and text:find('Name="lugal.Mesh"', 1, true), "the fields are written")
fails(function() mesh:write(vtu, {x = {1, 2, "three"}}) end, "mesh:write", "array 'x' has 3 entries")
local bad = {}
for i = 1, mesh:nvertices() do bad[i] = i end
bad[3] = "three"
fails(function() mesh:write(vtu, {x = bad}) end, "array 'x' entry 3 must be a number, got string")
os.remove(vtu)
os.remove(tmp)

-- boundary tags: no 16-tag limit, unknown tags are errors
local verts, cells, boundary = {}, {}, {}
local N = 20 -- a 20-gon fan: 20 boundary edges, each its own name
verts[1] = {0, 0}
for i = 1, N do
  local t = 2 * math.pi * (i - 1) / N
  verts[i + 1] = {math.cos(t), math.sin(t)}
end
for i = 1, N do
  local a, b = i + 1, i % N + 2
  cells[i] = {1, a, b}
  boundary[string.format("side%02d", i)] = {{a, b}}
end
local fan = lg.mesh.new{cell = "triangle", vertices = verts, cells = cells, boundary = boundary}
local perimeter = lg.integrate(fan:boundary(), 1)
T.close(perimeter, 2 * N * math.sin(math.pi / N), 1e-12, "mesh:boundary() covers all 20 tags")
T.close(lg.integrate(fan:boundary("side01", "side02", "side01"), 1), 2 * 2 * math.sin(math.pi / N), 1e-12,
        "a name given twice counts once")
fails(function() return mesh:cells(99) end, "mesh:cells: no cell has tag 99")
fails(function() return mesh:boundary(12345) end, "mesh:boundary: no boundary facet has tag 12345", "1, 2, 3, 4")
fails(function() return mesh:boundary(2^40) end, "no boundary facet has tag 1099511627776")
fails(function() return mesh:boundary(1.5) end, "mesh:boundary: argument 2 must be a boundary name or an integer tag")
fails(function() return lg.mesh.new{vertices = {{0, 0}, {1, 0}, {0, 1}}, cells = {{1, 2, 3}}}:boundary() end,
      "this mesh has no tagged boundary facets")

-- integers are checked as the C int they become
fails(function() return lg.mesh.rectangle{nx = 2^32 + 2} end, "option 'nx' is too large (4294967298")
fails(function() return lg.mesh.rectangle{nx = 1e9} end, "too large")
fails(function() return lg.mesh.rectangle{nx = 1e300} end, "option 'nx' is too large")
fails(function() return lg.mesh.rectangle{nx = 2.5} end, "option 'nx' must be an integer, got a fraction (2.5)")
fails(function() return lg.mesh.rectangle{nx = 0/0} end, "option 'nx' must be an integer, got nan")
T.check(lg.mesh.rectangle{nx = 2.0}:ncells() == 8, "an integral float is an integer")
fails(function() return lg.lagrange(2^32 + 2) end, "got 4294967298")
fails(function() return mesh:quality("mean_ratio"):histogram(2^33) end, "q:histogram: argument 2 is too large")

-- non-finite data is an error that says so and where
do -- a matrix coefficient that is NaN in the cells right of x = 0.75 only (the branch-free
   -- check of the element matrices, then the search for the first culprit)
  local bad = lg.linear_problem{mesh = mesh, test = v, unknown = u,
    eqn = lg.integral(mesh:cells(), (1 + lg.sqrt(0.75 - lg.x))*lg.dot(lg.grad(v), lg.grad(u)) - v),
    bc = lg.essential_bc(mesh:boundary(), v*u)}
  fails(function() return bad:solve() end, "problem:solve", "the matrix is not finite", "in cell 7, near (0.916667, 0.0833333)", "from term 1",
        "log or square root of a negative value")
end
fails(function() return lg.interpolate(P1, mesh, lg.log(lg.x)) end, "lg.interpolate", "is not finite (-inf) at (0, 0)")
local a = lg.parameter("a", 1)
fails(function() a:set(0 / 0) end, "set: parameter a must be set to a finite number")
fails(function() return lg.parameter("b", math.huge) end, "lg.parameter: argument 2", "must be a finite number")
local w = lg.zero_function(P1, mesh, "w")
local nan = {}
for i = 1, w:ndof() do nan[i] = 0 end
nan[7] = 0 / 0
fails(function() w:assign(nan) end, "f:assign: entry 7 of the table is not finite")
local wl = lg.interpolate(P1, mesh, lg.x + 1, "wl")
local inv = lg.nonlinear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) + lg.log(u - 1)*v),
                                 bc = lg.essential_bc(mesh:boundary(), v*(u - 2)), test = v, unknown = u}
fails(function() return inv:solve(lg.interpolate(P1, mesh, 0*lg.x)) end,
      "at the initial guess", "residual is not finite", "log or square root of a negative value")
local lin = poisson(mesh, lg.essential_bc(mesh:boundary(), v*u))
local guess = lg["function"](P1, mesh, "g") -- the old spelling still works
local gv = {}
for i = 1, guess:ndof() do gv[i] = 1 end
guess:assign(gv)
T.check(lin:solve(), "a good problem solves")
local coef = lg.zero_function(P1, mesh, "k")
local kv = {}
for i = 1, coef:ndof() do kv[i] = 1 end
coef:assign(kv)
local withk = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), coef*lg.dot(lg.grad(v), lg.grad(u)) - v),
                                bc = lg.essential_bc(mesh:boundary(), v*u), test = v, unknown = u}
T.check(withk:solve(), "a finite coefficient solves")
fails(function() coef:assign(lg.exp(1000 * (1 + lg.x))) end, "f:assign", "is not finite (inf) at (0, 0)")
fails(function() return lg.integrate(mesh, 1 / (lg.x - lg.x)) end, "division by zero")
fails(function() return lg.integrate(mesh, lg.sqrt(lg.x - 2)) end, "lg.integrate: the integral is not finite")

-- the untangler and mesh motion refuse non-finite coordinates and displacements
local mm = lg.mesh.rectangle{nx = 3}
fails(function() mm:displace(function(x, y) return x < 0.5 and 0/0 or 0, 0 end) end,
      "mesh:displace: the displacement of vertex 1 is not finite", "unchanged")
T.check(mm:check() == 0, "the mesh is unchanged")
fails(function() mm:move{displacement = function(x, y) return math.huge, 0 end, quiet = true} end,
      "mesh:move: the displacement of vertex 1 is not finite")
mm:set_coordinates(5, 0.5, 0.5)
fails(function() mm:set_coordinates(5, 0/0, 0.5) end, "mesh:set_coordinates: argument 3 is not finite")
fails(function() mm:untangle{beta = math.huge, quiet = true} end, "beta must be a finite number")
fails(function() mm:untangle{max_iterations = 2^31, quiet = true} end, "option 'max_iterations' is too large")

-- a fold at 1e-200 scale is repaired like one at unit scale (the untangler works at unit size)
local tiny = lg.mesh.rectangle{nx = 4, x1 = 1e-200, y1 = 1e-200}
local tx, ty = tiny:coordinates(7)
tiny:set_coordinates(7, tx + 0.35e-200, ty)
T.check(tiny:check() > 0, "the fold inverts cells")
local rep = tiny:untangle{quiet = true}
T.check(rep.success and tiny:check() == 0, "untangled at 1e-200: %s", tostring(rep))
T.check(rep.max_displacement > 1e-203 and rep.max_displacement < 1e-199, "displacements in the mesh's units (%g)", rep.max_displacement)

-- essential conditions that do nothing or contradict each other, repeated unknowns
fails(function() return poisson(mesh, lg.essential_bc(mesh:boundary(), 0*v*u)):solve() end,
      "boundary condition 1 is zero: it constrains nothing")
fails(function()
  return poisson(mesh, {lg.essential_bc(mesh:boundary("left"), v*(u - 0)), lg.essential_bc(mesh:boundary("left"), v*(u - 1))}):solve()
end, "boundary conditions 1 and 2 give different values on the same dofs")
-- conditions that only meet at corners: the later one wins there, documented, not an error
local corners = poisson(mesh, {lg.essential_bc(mesh:boundary("left", "right", "bottom"), v*u),
                               lg.essential_bc(mesh:boundary("top"), v*(u - 1))})
local uc = corners:solve()
T.close(lg.integrate(mesh:boundary("top"), uc), 1, 1e-12, "the top condition wins at its corners")
fails(function()
  return lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), u*v), test = {v, v}, unknown = {u, u}}
end, "option 'test' lists v twice (entries 1 and 2)")
local u2 = lg.unknown(P1, "u2")
fails(function()
  return lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), u*v + u2*v), test = {v, lg.test(P1, "q")}, unknown = {u, u}}
end, "option 'unknown' lists u twice")
fails(function() return lg.mesh.new{vertices = {{0, 0}, {1, 0}, {0, 1}, {5, 5}}, cells = {{1, 2, 3}}} end,
      "lg.mesh.new: vertex 4 is not in any cell")
fails(function() return lg.mesh.new{vertices = {{0, 0}, {1, 0}, {0, 1}}, cells = {{1, 2, 7}}} end,
      "cell 1 entry 3 is too large (7; at most 3)")
fails(function() return lg.mesh.new{vertices = {{0, 0}, {1, 0 / 0}, {0, 1}}, cells = {{1, 2, 3}}} end,
      "vertex 2 coordinate 2 is not finite")
fails(function() return poisson(mesh, lg.essential_bc(mesh:boundary(), v*u), {prefix = "bad prefix"}) end,
      "the options prefix \"bad prefix\" must be")
fails(function() return poisson(mesh, lg.essential_bc(mesh:boundary(), v*u), {prefix = "-ksp_"}) end, "options prefix \"-ksp_\"")

-- deep and long expressions: no stack overflow, no quadratic cost (asserted through the node count)
local nodes0 = lg.stats().nodes
local s = 0
for i = 1, 20000 do s = s + lg.x^i end
T.check(#tostring(s) > 100, "a 20000-term sum prints")
T.close(lg.integrate(mesh, s - s), 0, 0, "s - s")
T.check(lg.stats().nodes - nodes0 < 10 * 20000, "20000 terms made %d nodes (linear, not quadratic)", lg.stats().nodes - nodes0)
local e = lg.x
for i = 1, 100000 do e = lg.sin(e) end
T.check(#tostring(e) > 10, "a 100000-deep chain prints")
local g = lg.grad(e)
T.check(#g == 2, "and has a gradient")
local r = 0.5
for i = 1, 100000 do r = math.sin(r) end
T.close(lg.integrate(mesh:boundary("left"), 0*lg.x + lg.sin(0*lg.y + 0.5)), math.sin(0.5), 1e-14, "integrate")
local nested = 1
for i = 1, 9 do nested = {nested} end
fails(function() return lg.list(nested) end, "nest at most 8 deep")
local row = {}
for i = 1, 64 do row[i] = lg.x end
local b2 = lg.list(row)
local rows = {}
for i = 1, 64 do rows[i] = b2 end
local b3 = lg.list(rows)          -- 64 x 64 = 4096 entries: fine
T.check(#b3 == 64, "a 64x64 list")
local cube = {}
for i = 1, 64 do cube[i] = b3 end
fails(function() return lg.list(cube) end, "a list of 262144 scalar entries is too large (at most 65536)")
local dag = lg.x
for i = 1, 60 do dag = dag * dag + dag end
T.check(#tostring(dag) <= 2047, "a shared DAG prints truncated, at once")

print(n .. " hostile inputs reported as errors")
