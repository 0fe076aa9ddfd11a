-- The sparsity pattern pass and the element loop on OpenMP threads
-- (src/assemble/problem/sparsity.c, pattern_rows: the node rows in contiguous blocks, one
-- per thread, put end to end; src/assemble/assemble.c, lg_assemble_chunks: windows of
-- items whose rows each window adds). Matrices big enough to take the threaded paths (a P1
-- Laplacian on 82 944 tetrahedra, a vector P1 elasticity operator on the same mesh, a P2
-- Laplacian, whose vertex dofs come before its edge dofs), a P2 load vector and a Newton
-- solve (residuals and Jacobians) must be the same to the bit with 1, 2 and 3 threads: this
-- script runs itself as a child with OMP_NUM_THREADS set and compares the nonzero counts,
-- norms and bilinear forms the children print; and the Laplacian annihilates constants,
-- its nonzero count that of the tetrahedral grid.
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
  local coarse = lg.mesh.box{nx = 14}
  local P2 = lg.lagrange(2)
  local u2, v2 = lg.unknown(P2, "u2"), lg.test(P2, "v2")
  local A2 = lg.assemble(lg.integral(coarse:cells(), lg.dot(lg.grad(v2), lg.grad(u2)) + u2*v2))
  local b2 = lg.assemble(lg.integral(coarse:cells(), lg.sin(3*x)*y*v2 + z*z*v2))
  print(string.format("P2 %d %a %a %a", A2:nnz(), A2:norm(), b2:norm(), b2:dot(lg.interpolate(P2, coarse, x - y*z, "h"))))
  local F = lg.integral(mesh:cells(), (1 + u*u)*lg.dot(lg.grad(v), lg.grad(u)) - 10*lg.sin(3*x)*v)
  local prob = lg.nonlinear_problem{mesh = mesh, eqn = F, bc = lg.essential_bc(mesh:boundary(), v*u), test = v, unknown = u}
  local uh, info = prob:solve()
  print(string.format("newton %d %a %a", info.iterations, lg.integrate(mesh, uh*uh), info.residuals[2]))
  os.exit(0)
end

local function run(threads) return T.child("child", "OMP_NUM_THREADS=" .. threads) end
local one, two, three = run(1), run(2), run(3)
local nnz, norm, fg, c = one:match("laplace (%d+) (%S+) (%S+) (%S+)")
T.check(nnz ~= nil and one:find("elasticity %d+") and one:find("newton [2-9] "), "the child printed its matrices and Newton solve:\n%s", one)
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
print("sparsity and assembly threads: the same matrices, vectors and Newton iterates with 1, 2 and 3 threads; " .. one:gsub("\n", "; "))
