-- The matrix scatter (src/assemble/problem/sparsity.c, problem.c): each element entry is kept as
-- its column node's rank in its row node's row, 1 byte where rows have at most 256 nodes,
-- 2 bytes beyond; B = 1 rows start from a per-element-row table, vector fields (B > 1)
-- from their node. Each path is checked against the functional the matrix represents,
-- which lugal assembles without the matrix: w^T A z = the integral of the bilinear form at
-- (w, z), for w, z interpolants of smooth functions; and row sums of a Laplacian vanish.
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local T = require "testlib"
local lg = require "lugal"
local x, y, z = lg.x, lg.y, lg.z

local function check(mesh, V, a_of, what)
  local u, v = lg.unknown(V, "u"), lg.test(V, "v")
  local A = lg.assemble(lg.integral(mesh:cells(), a_of(u, v)))
  local fw, fz = lg.sin(x + 2*y - z), x*y*z + y
  if mesh:dim() == 2 then fw, fz = lg.sin(x + 2*y + 0.3), x*y*y + 1 end
  local w = lg.interpolate(V, mesh, fw, "w")
  local zz = lg.interpolate(V, mesh, fz, "zz")
  local exact = lg.integrate(mesh, a_of(w, zz))
  local got = A:dot(w, zz)
  T.close(got, exact, 1e-12 * math.max(1, math.abs(exact)), what .. ": w^T A z against the functional")
  return A
end

-- a fan: one vertex in 400 triangles, its row 401 nodes long (2-byte ranks)
local nf = 400
local verts, cells, bnd = {{0, 0}}, {}, {}
for k = 0, nf - 1 do
  local t = 2*math.pi*k/nf
  verts[#verts + 1] = {math.cos(t), math.sin(t)}
end
for k = 1, nf do
  cells[#cells + 1] = {1, k + 1, k % nf + 2}
  bnd[#bnd + 1] = {k + 1, k % nf + 2}
end
local fan = lg.mesh.new{cell = "triangle", vertices = verts, cells = cells, boundary = {rim = bnd}}
local P1 = lg.lagrange(1)
local K = check(fan, P1, function(u, v) return lg.dot(lg.grad(u), lg.grad(v)) + u*v end, "P1 fan (2-byte ranks)")
local L = lg.assemble(lg.integral(fan:cells(), lg.dot(lg.grad(lg.unknown(P1, "p")), lg.grad(lg.test(P1, "q")))))
T.check(L:mult(lg.interpolate(P1, fan, 1 + 0*x)):norm() < 1e-12, "the fan Laplacian annihilates constants")
T.check(L:nnz() == (nf + 1) + nf * 4, "fan nonzeros %d (centre row %d, rim rows 4)", L:nnz(), nf + 1)

-- 1-byte ranks: P1 and P3 on a box of tetrahedra, P2 on triangles
local box = lg.mesh.box{nx = 3, ny = 2, nz = 2}
check(box, P1, function(u, v) return lg.dot(lg.grad(u), lg.grad(v)) end, "P1 tetrahedra")
check(box, lg.lagrange(3), function(u, v) return (1 + x)*lg.dot(lg.grad(u), lg.grad(v)) + u*v end, "P3 tetrahedra")
check(lg.mesh.rectangle{nx = 5, ny = 4}, lg.lagrange(2), function(u, v) return lg.dot(lg.grad(u), lg.grad(v)) + y*u*v end,
      "P2 triangles")

-- vector P2 (B = 3: ranks per node pair, rows from their node); grad and div take the
-- dimension of the newest mesh
box = lg.mesh.box{nx = 3, ny = 2, nz = 2}
local V = lg.vector(lg.lagrange(2), 3)
local uu, vv = lg.unknown(V, "uu"), lg.test(V, "vv")
local E = lg.assemble(lg.integral(box:cells(), lg.inner(lg.grad(uu), lg.grad(vv)) + 2*lg.div(uu)*lg.div(vv)))
local w3 = lg.interpolate(V, box, {lg.sin(x + y), x*z, y - z*z}, "w3")
local z3 = lg.interpolate(V, box, {x*y, lg.cos(z), x + y*z}, "z3")
local e3 = lg.integrate(box, lg.inner(lg.grad(w3), lg.grad(z3)) + 2*lg.div(w3)*lg.div(z3))
T.close(E:dot(w3, z3), e3, 1e-12 * math.abs(e3), "vector P2 (B = 3): w^T A z against the functional")

-- (interior facet terms, whose items list a node of each side, go through the same fill
-- and scatter: examples/dg_poisson.lua and tests/lua/test_dg.lua check their rates)
print(string.format("ranks: fan %d nonzeros, vector P2 %d", L:nnz(), E:nnz()))
