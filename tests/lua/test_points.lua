-- Point values of discrete functions: uh(x, y[, z]) equals the dof value at every dof
-- point, is exact for polynomials of the space at random points (2D P3, 3D P2, a vector
-- P1), follows the mesh when it moves, and refuses points outside the mesh.
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local T = require "testlib"
local lg = require "lugal"
local x, y, z = lg.x, lg.y, lg.z
math.randomseed(7)

-- at the dof points, the dof values
do
  local mesh = lg.mesh.rectangle{nx = 6, ny = 4, diagonal = "crossed"}
  local f = lg.interpolate(lg.lagrange(2), mesh, lg.sin(3*x)*lg.exp(y))
  local pts, vals = f:dof_coordinates(), f:values()
  T.check(#pts == f:ndof(), "one point per dof")
  local worst = 0
  for i, p in ipairs(pts) do worst = math.max(worst, math.abs(f(p[1], p[2]) - vals[i])) end
  T.check(worst < 1e-13, "f at its dof points is its dof values (%.2e)", worst)
end

-- exact for the space's polynomials: a cubic in P3 (2D), a quadratic in P2 (3D)
do
  local mesh = lg.mesh.rectangle{nx = 5, ny = 7, x0 = -1, x1 = 2, y1 = 0.5}
  local cubic = function(a, b) return 1 - a + 2*b + a^2*b - 3*b^3 + a^3 end
  local f = lg.interpolate(lg.lagrange(3), mesh, cubic(x, y))
  local worst = 0
  for _ = 1, 200 do
    local a, b = -1 + 3*math.random(), 0.5*math.random()
    worst = math.max(worst, math.abs(f(a, b) - cubic(a, b)))
  end
  T.check(worst < 1e-12, "P3 in 2D reproduces a cubic at random points (%.2e)", worst)
  local cube = lg.mesh.box{nx = 3, ny = 2, nz = 4}
  local quad = function(a, b, c) return a*b - c^2 + 2*a + 0.5 end
  local g = lg.interpolate(lg.lagrange(2), cube, quad(x, y, z))
  local pts, worst3 = {}, 0
  for i = 1, 100 do pts[i] = {math.random(), math.random(), math.random()} end
  local vals = g:eval(pts)
  for i, p in ipairs(pts) do worst3 = math.max(worst3, math.abs(vals[i] - quad(p[1], p[2], p[3]))) end
  T.check(worst3 < 1e-12, "P2 in 3D reproduces a quadratic at random points (%.2e)", worst3)
  -- corners and facets: points shared by cells
  T.close(g(1, 1, 1), quad(1, 1, 1), 1e-13, "a corner of the box")
  T.close(g(0.5, 0, 0.25), quad(0.5, 0, 0.25), 1e-13, "a boundary face")
end

-- vector functions return their components
do
  local mesh = lg.mesh.rectangle{nx = 3}
  local w = lg.interpolate(lg.vector(lg.lagrange(1)), mesh, {1 + x - y, 2*y})
  local a, b = w(0.3, 0.6)
  T.close(a, 0.7, 1e-14, "component 1")
  T.close(b, 1.2, 1e-14, "component 2")
  local t = w:eval({{0.5, 0.5}})
  T.check(#t == 1 and #t[1] == 2, "eval of a vector: tables of components")
end

-- a moved mesh: the locator is rebuilt for the new geometry
do
  local mesh = lg.mesh.rectangle{nx = 4}
  local f = lg.interpolate(lg.lagrange(1), mesh, x)
  T.close(f(0.9, 0.5), 0.9, 1e-14, "before the move")
  for i = 1, mesh:nvertices() do
    local a, b = mesh:coordinates(i)
    mesh:set_coordinates(i, 2*a, b)
  end
  -- the dofs did not change: the function is now x/2 on [0, 2]
  T.close(f(1.8, 0.5), 0.9, 1e-13, "after stretching the mesh to [0, 2]")
end

-- outside, and bad arguments
local mesh = lg.mesh.rectangle{nx = 2}
local f = lg.interpolate(lg.lagrange(1), mesh, x)
T.fails(function() return f(1.5, 0.5) end, "the point (1.5, 0.5) is outside the mesh")
T.fails(function() return f(0.5, -1e-3) end, "outside the mesh")
T.fails(function() return f(0.5) end, "give the 2 coordinates")
T.fails(function() return f(0/0, 0.5) end, "not finite")
T.fails(function() return f:eval({{0.5, 0.5}, {3, 3}}) end, "point 2", "outside the mesh")
T.fails(function() return f:eval({{0.5}}) end, "point 1 must be a table of 2 coordinates")
T.fails(function() return mesh:coordinates() end, "mesh:coordinates: argument 1 must be a vertex number")
T.fails(function() return mesh:coordinates(99) end, "vertex 99 out of range")
T.fails(function() return mesh:set_coordinates(1, "a", 0) end, "mesh:set_coordinates: argument 2 must be coordinate 1")
print("point values: all checks passed")
