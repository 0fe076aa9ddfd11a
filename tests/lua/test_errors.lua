-- Bad input gives a clear error naming the function and the problem, never a crash:
-- Lua type and shape errors, unknown boundary names, malformed and truncated .msh files,
-- inverted cells, forms not linear in the test function, singular systems.
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local T = require "testlib"
local lg = require "lugal"
local data = arg[0]:match("(.*/)") .. "../data/"

local mesh = lg.mesh.rectangle{nx = 4, ny = 4}
local P1 = lg.lagrange(1)
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
local n = 0
local function fails(...) n = n + 1; return T.fails(...) end

-- types and shapes
fails(function() return lg.integral(mesh:cells(), lg.grad(v)) end,
      "lg.integral: argument 2 must be a scalar expression, got a 2-vector")
fails(function() return u + lg.grad(u) end, "cannot add a scalar and a 2-vector")
fails(function() return lg.grad(u) * lg.grad(v) end, "cannot multiply a 2-vector and a 2-vector", "lg.dot")
fails(function() return lg.dot(lg.grad(u), lg.list(1, 2, 3)) end, "dot product of a 2-vector and a 3-vector")
fails(function() return lg.grad("x") end, "lg.grad: argument 1 must be an expression", "got string")
fails(function() return lg.sin({}) end, "lg.sin")
fails(function() return lg.lagrange(5) end, "lg.lagrange: argument 1 must be a degree 0 (piecewise constants), 1, 2 or 3, got 5")
fails(function() return lg.unknown(3) end, "lg.unknown: argument 1 must be a basis")
fails(function() return lg.integral(mesh, u*v) end, "lg.integral: argument 1 must be a region")
fails(function() return lg.mesh.rectangle{nx = 0} end, "lg.mesh.rectangle", "at least 1")
fails(function() return lg.mesh.rectangle{nx = 2.5} end, "option 'nx' must be an integer")
fails(function() return lg.mesh.rectangle{n = 3} end, "unknown option 'n'")
fails(function() return lg.mesh.rectangle{cell = "hexagon"} end, "option 'cell' must be")
fails(function() return u / 0 end, "division by zero")
fails(function() return lg.grad(u)[3] end, "index 3 out of range 1..2")

-- names
fails(function() return mesh:boundary("inlet") end,
      "mesh:boundary: unknown boundary name \"inlet\"", "\"left\"", "\"top\"")

-- files
fails(function() return lg.mesh.read("/nonexistent/x.msh") end, "lg.mesh.read: cannot open /nonexistent/x.msh")
local function write(text)
  local path = os.tmpname()
  local f = assert(io.open(path, "w"))
  f:write(text)
  f:close()
  return path
end
local full = assert(io.open(data .. "square_unstructured_v22.msh")):read("a")
local truncated = write(full:sub(1, math.floor(#full / 2)))
fails(function() return lg.mesh.read(truncated) end, "lg.mesh.read", truncated, "truncated")
local malformed = write((full:gsub("\n2 1 2 1 1 5 6\n", "\n2 1 2 x 1 5 6\n", 1)))
fails(function() return lg.mesh.read(malformed) end, "expected element tag (an integer), found \"x\"")
local noelems = write("$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n1\n1 0 0 0\n$EndNodes\n")
fails(function() return lg.mesh.read(noelems) end, "truncated or incomplete: no $Elements")
local badver = write("$MeshFormat\n3.0 0 8\n$EndMeshFormat\n")
fails(function() return lg.mesh.read(badver) end, "MSH version 3.0 is not supported")
local binary = write("$MeshFormat\n4.1 1 8\n$EndMeshFormat\n")
fails(function() return lg.mesh.read(binary) end, "binary MSH files are not supported")
local second = write((full:gsub("\n(%d+) 2 2 (%d+) (%d+) (%d+) (%d+) (%d+)\n", "\n%1 9 2 %2 %3 %4 %5 %6 1 2 3\n", 1)))
fails(function() return lg.mesh.read(second) end, "element type 9 is not supported")
for _, p in ipairs{truncated, malformed, noelems, badver, binary, second} do os.remove(p) end

-- an inverted cell is refused before assembly, with its number
local bad = lg.mesh.new{cell = "triangle", vertices = {{0, 0}, {1, 0}, {0, 1}, {1, 1}},
                        cells = {{1, 2, 3}, {2, 3, 4}}}   -- the second is clockwise
local ub, vb = lg.unknown(P1, "u"), lg.test(P1, "v")
fails(function()
  return lg.linear_problem{mesh = bad, eqn = lg.integral(bad:cells(), ub*vb - vb), test = vb, unknown = ub}
end, "lg.linear_problem", "1 inverted or zero-size cell (cell 2)")
local flat = lg.mesh.new{cell = "triangle", vertices = {{0, 0}, {1, 0}, {2, 0}}, cells = {{1, 2, 3}}}
fails(function() return lg.integrate(flat, 1) end, "zero-size cell")

-- forms
fails(function()
  return lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), v*v*u), test = v, unknown = u}
end, "not linear in the test function")
fails(function()
  return lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), u*v + u^2), test = v, unknown = u}
end, "not linear in the test function", "does not contain it")
fails(function()
  return lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), u^2*v), test = v, unknown = u}
end, "not linear in the unknown u", "lg.nonlinear_problem")
fails(function()
  return lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), u*v), test = u, unknown = u}
end, "option 'test' must be a test function")
fails(function()
  return lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), u*v), bc = lg.essential_bc(mesh:boundary(), v*lg.x),
                           test = v, unknown = u}
end, "essential_bc", "does not contain the unknown u")
fails(function() return lg.essential_bc(mesh:cells(), v*u) end, "must be a boundary region")
fails(function() return lg.integrate(mesh, u) end, "the unknown u", "has no values")

-- a singular system: pure Neumann Poisson has constants in its kernel
local sing = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) - v),
                               test = v, unknown = u}
fails(function() return sing:solve() end, "problem:solve: the matrix is singular", "nullspace")
-- with its null space given: compatible data solve to the mean-zero solution, incompatible
-- data are refused
local nf = lg.cos(math.pi*lg.x)*lg.cos(math.pi*lg.y)
local neu = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) - 2*math.pi^2*nf*v),
                              test = v, unknown = u, nullspace = u}
local un = neu:solve()
T.check(math.abs(lg.integrate(mesh, un)) < 1e-12, "nullspace = u: the solution has mean zero (%.2e)", lg.integrate(mesh, un))
local en = math.sqrt(lg.integrate(mesh, (un - nf)^2))
T.check(en < 0.15 and en > 1e-4, "nullspace = u: the pure Neumann solution (L2 error %.3e on this coarse mesh)", en)
local bad = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) - v),
                              test = v, unknown = u, nullspace = u}
fails(function() return bad:solve() end, "not compatible with the null space")
fails(function() return lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) - v),
                                           test = v, unknown = u, nullspace = u, bc = lg.essential_bc(mesh:boundary(), v*u)} end,
      "has essential conditions")
fails(function() return lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) - v),
                                           test = v, unknown = u, nullspace = "rigid"} end, "single vector unknown")
fails(function() return lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) - v),
                                           test = v, unknown = u, nullspace = "constant"} end, "must be an unknown")

-- Newton that cannot converge is reported (lambda beyond the Bratu turning point)
local lam = lg.parameter("lam", 50)
local nl = lg.nonlinear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) - lam*lg.exp(u)*v),
                                bc = lg.essential_bc(mesh:boundary(), v*u), test = v, unknown = u}
fails(function() return nl:solve() end, "problem:solve: the nonlinear solve did not converge")

-- quadrilaterals have Q0-Q2: a cubic basis there is refused with a message naming the
-- cell type and the degrees it has
local qm = lg.mesh.rectangle{nx = 2, cell = "quadrilateral"}
local P3 = lg.lagrange(3)
local u3, v3 = lg.unknown(P3, "u"), lg.test(P3, "v")
fails(function()
  return lg.linear_problem{mesh = qm, eqn = lg.integral(qm:cells(), u3*v3 - v3), test = v3, unknown = u3}
end, "quadrilaterals", "0, 1 and 2 are")


-- extra arguments are errors that name the function (issue 12), not silently ignored
do
  local m2 = lg.mesh.rectangle{nx = 2}
  local Q1 = lg.lagrange(1)
  local uq, vq = lg.unknown(Q1, "uq"), lg.test(Q1, "vq")
  fails(function() return lg.sin(lg.x, 2) end, "lg.sin: takes at most 1 argument, got 2")
  fails(function() return lg.dot(lg.grad(uq), lg.grad(vq), 3) end, "lg.dot: takes at most 2 arguments, got 3 (argument #3 is extra)")
  fails(function() return lg.integral(m2:cells(), uq*vq, nil, 4) end, "lg.integral: takes at most 3 arguments, got 4")
  fails(function() return lg.normal(1) end, "lg.normal: takes no arguments, got 1")
  fails(function() return m2:hmax(1) end, "mesh:hmax: takes no arguments, got 1")
  fails(function() return m2:quality("mean_ratio"):min(2) end, "q:min: takes no arguments, got 1")
  fails(function() return lg.mesh.rectangle({nx = 2}, 3) end, "lg.mesh.rectangle: takes at most 1 argument, got 2")
  local f = lg.interpolate(Q1, m2, lg.x, "fq")
  fails(function() return f:values(1) end, "f:values: takes no arguments, got 1")
  T.close(lg.integrate(m2, f), 0.5, 1e-14, "the checked functions still work")
end
print(n .. " bad inputs reported as errors")

-- an integrand that reads more discrete functions than a kernel takes names the limit
do
  local mesh = lg.mesh.rectangle{nx = 2}
  local P1 = lg.lagrange(1)
  local u, v = lg.unknown(P1, "ucl"), lg.test(P1, "vcl")
  local e = 0
  for k = 1, 33 do e = e + lg.interpolate(P1, mesh, k*lg.x, "c" .. k) end
  T.fails(function() return lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(u), lg.grad(v)) - e*v),
                                              bc = lg.essential_bc(mesh:boundary(), v*u), test = v, unknown = u}:solve() end,
          "more than 32 discrete functions", "split the integral")
end
