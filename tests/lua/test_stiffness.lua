-- The P1 stiffness matrix of the reference triangle and tetrahedron, entry by entry, and
-- the P1 mass matrix of the reference triangle.
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local T = require "testlib"
local lg = require "lugal"

local function matrix(mesh, form_of)
  local P1 = lg.lagrange(1)
  local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
  local prob = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), form_of(u, v)), test = v, unknown = u}
  return prob:matrix()
end

local function compare(name, A, E)
  for i = 1, #E do
    for j = 1, #E do T.close(A[i][j], E[i][j], 1e-14, string.format("%s[%d][%d]", name, i, j)) end
  end
  print(name .. ": " .. #E .. "x" .. #E .. " entries match")
end

local tri = lg.mesh.new{cell = "triangle", vertices = {{0, 0}, {1, 0}, {0, 1}}, cells = {{1, 2, 3}}}
compare("triangle stiffness", matrix(tri, function(u, v) return lg.dot(lg.grad(v), lg.grad(u)) end),
        {{1, -0.5, -0.5}, {-0.5, 0.5, 0}, {-0.5, 0, 0.5}})
compare("triangle mass", matrix(tri, function(u, v) return u*v end),
        {{1/12, 1/24, 1/24}, {1/24, 1/12, 1/24}, {1/24, 1/24, 1/12}})

local tet = lg.mesh.new{cell = "tetrahedron", vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}},
                        cells = {{1, 2, 3, 4}}}
local s = 1/6
compare("tetrahedron stiffness", matrix(tet, function(u, v) return lg.dot(lg.grad(v), lg.grad(u)) end),
        {{3*s, -s, -s, -s}, {-s, s, 0, 0}, {-s, 0, s, 0}, {-s, 0, 0, s}})

-- a scaled and rotated triangle: the stiffness matrix is invariant under similarity
local c, sn = math.cos(0.7), math.sin(0.7)
local rot = lg.mesh.new{cell = "triangle", vertices = {{2, 3}, {2 + 3*c, 3 + 3*sn}, {2 - 3*sn, 3 + 3*c}},
                        cells = {{1, 2, 3}}}
compare("rotated triangle stiffness", matrix(rot, function(u, v) return lg.dot(lg.grad(v), lg.grad(u)) end),
        {{1, -0.5, -0.5}, {-0.5, 0.5, 0}, {-0.5, 0, 0.5}})
