-- mpi_partition.lua — a P2 problem on a grid whose cells and vertices are numbered in a
-- shuffled order and on the generator's grid (tests/sh/test_mpi.sh runs it on 1, 2 and 3
-- ranks, with the default partitioner and with -lugal_partitioner natural). Prints the L2
-- norm of the solution, the ranks' rows and the other ranks' columns they read
-- (problem:ownership), summed over the ranks.
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local T = require "testlib"
local lg = require "lugal"
local P2 = lg.lagrange(2)
local u, v = lg.unknown(P2, "u"), lg.test(P2, "v")
local x, y = lg.x, lg.y
local f = lg.sin(math.pi*x)*lg.cos(2*y)
-- the shuffled grid (PTScotch), then the generator's grid (split along its vertex
-- numbering: a P2 field's dof order, vertex nodes first, would give each rank rows all over it)
for _, case in ipairs{{"", T.shuffled_grid(lg, 32, true)}, {"grid ", lg.mesh.rectangle{nx = 32}}} do
  local mesh = case[2]
  local prob = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(u), lg.grad(v)) + u*v - f*v),
                                 test = v, unknown = u}
  local uh = prob:solve()
  local o = prob:ownership()
  local rows, ghosts = lg.allreduce(o.rows), lg.allreduce(o.ghosts)
  print(string.format("%snorm %.17g", case[1], math.sqrt(lg.integrate(mesh, uh*uh))))
  print(string.format("%srows %d ghosts %d", case[1], rows, ghosts))
end
