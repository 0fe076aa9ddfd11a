-- mpi_partition.lua — a P2 problem on a grid whose cells and vertices are numbered in a
-- shuffled order (tests/sh/test_mpi.sh runs it on 1, 2 and 3 ranks, with PTScotch and with
-- -lugal_partitioner natural). Prints the L2 norm of the solution, this rank's rows and the
-- other ranks' columns they read (problem:ownership), summed over the ranks.
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local T = require "testlib"
local lg = require "lugal"
local mesh = T.shuffled_grid(lg, 32, true)
local P2 = lg.lagrange(2)
local u, v = lg.unknown(P2, "u"), lg.test(P2, "v")
local x, y = lg.x, lg.y
local f = lg.sin(math.pi*x)*lg.cos(2*y)
local prob = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(u), lg.grad(v)) + u*v - f*v),
                               test = v, unknown = u}
local uh = prob:solve()
local o = prob:ownership()
local rows, ghosts = lg.allreduce(o.rows), lg.allreduce(o.ghosts)
print(string.format("norm %.17g", math.sqrt(lg.integrate(mesh, uh*uh))))
print(string.format("rows %d ghosts %d", rows, ghosts))
