-- The sparsity pattern pass on OpenMP threads (src/assemble/problem/sparsity.c, pattern_rows): the
-- node rows in contiguous blocks, one per thread, put end to end. Matrices big enough to
-- take the threaded path (more than 200 000 element rows: a P1 Laplacian on 82 944
-- tetrahedra, a vector P1 elasticity operator on the same mesh) must be the same to the bit
-- with 1, 2 and 3 threads: this script runs itself as a child with OMP_NUM_THREADS set and
-- compares the nonzero counts, Frobenius norms and bilinear forms the children print; and
-- the Laplacian annihilates constants, its nonzero count that of the tetrahedral grid.
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local T = require "testlib"
local lg = require "lugal"

if arg[1] == "child" then
  local x, y, z = lg.x, lg.y, lg.z
  local mesh = lg.mesh.box{nx = 24}
  local P1 = lg.lagrange(1)
  local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
  local A = lg.assemble(lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u))))
  local f = lg.interpolate(P1, mesh, lg.sin(3*x)*y + z, "f")
  local g = lg.interpolate(P1, mesh, x*x - y*z, "g")
  local one = lg.interpolate(P1, mesh, 1 + 0*x, "one")
  print(string.format("laplace %d %a %a %a", A:nnz(), A:norm(), A:dot(f, g), A:mult(one):norm()))
  local V = lg.vector(P1, 3)
  local w, q = lg.unknown(V, "w"), lg.test(V, "q")
  local E = lg.assemble(lg.integral(mesh:cells(), lg.inner(lg.grad(q), lg.grad(w)) + lg.div(q)*lg.div(w)))
  print(string.format("elasticity %d %a", E:nnz(), E:norm()))
  os.exit(0)
end

local function run(threads) return T.child("child", "OMP_NUM_THREADS=" .. threads) end
local one, two, three = run(1), run(2), run(3)
local nnz, norm, fg, c = one:match("laplace (%d+) (%S+) (%S+) (%S+)")
T.check(nnz ~= nil and one:find("elasticity %d+"), "the child printed its matrices:\n%s", one)
-- the P1 pattern of a 25^3-vertex grid of 6-tetrahedra cubes: each interior vertex has 14
-- neighbours and itself (the Freudenthal split), fewer on the faces
local n1 = 25
local count = 0
for i = 0, n1 - 1 do for j = 0, n1 - 1 do for k = 0, n1 - 1 do
  local nb = 1
  for _, d in ipairs{{1,0,0},{0,1,0},{0,0,1},{1,1,0},{0,1,1},{1,0,1},{1,1,1}} do
    for _, s in ipairs{1, -1} do
      local a, b, e = i + s*d[1], j + s*d[2], k + s*d[3]
      if a >= 0 and a < n1 and b >= 0 and b < n1 and e >= 0 and e < n1 then nb = nb + 1 end
    end
  end
  count = count + nb
end end end
T.check(tonumber(nnz) == count, "Laplacian nonzeros %s, the Freudenthal grid's %d", nnz, count)
T.check(tonumber(c) < 1e-10, "the Laplacian annihilates constants (%s)", c)
T.check(one == two, "1 and 2 threads give the same matrices to the bit:\n%s\n%s", one, two)
T.check(one == three, "1 and 3 threads give the same matrices to the bit:\n%s\n%s", one, three)
print("sparsity threads: the same matrices with 1, 2 and 3 threads; " .. one:gsub("\n", "; "))
