-- mpi_cases.lua — quantities that a run on any number of ranks must give as the serial run
-- does; tests/sh/test_mpi.sh runs it serially and under mpiexec -n 2 and -n 3 and compares.
-- Each line: name, tolerance class (direct: 1e-10 relative; iter: iterative solvers and
-- optimization, 1e-8; count: integers within 1), value (%.17g).
local lg = require "lugal"
local x, y, pi = lg.x, lg.y, math.pi
local function out(name, class, v) print(string.format("%s %s %.17g", name, class, v)) end

-- the 2D Poisson demo: P1 and P2, direct solves, error norms
for _, p in ipairs{1, 2} do
  local mesh = lg.mesh.rectangle{nx = 24}
  local V = lg.lagrange(p)
  local u, v = lg.unknown(V, "u"), lg.test(V, "v")
  local exact = lg.sin(pi*x)*lg.sin(pi*y)
  local uh = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) - 2*pi^2*exact*v),
                               bc = lg.essential_bc(mesh:boundary(), v*u), test = v, unknown = u}:solve()
  local e = uh - exact
  out("poisson_P" .. p .. "_L2", "direct", math.sqrt(lg.integrate(mesh, e^2)))
  out("poisson_P" .. p .. "_H1", "direct", math.sqrt(lg.integrate(mesh, lg.dot(lg.grad(e), lg.grad(e)))))
  if p == 1 then
    mesh:write(arg[1] .. "/poisson.vtu", {u = uh})
    -- a piece per rank (the parts of the partition), with each cell's number
    local id = {}
    for i = 1, mesh:ncells() do id[i] = i end
    mesh:write(arg[1] .. "/poisson.pvtu", {u = uh, q = mesh:quality("mean_ratio"), id = id}, {format = "ascii"})
  end
end

-- Stokes (Taylor-Hood, a mixed system with the pressure's constant as null space)
do
  local mesh = lg.mesh.rectangle{nx = 12}
  local V, Q = lg.vector(lg.lagrange(2)), lg.lagrange(1)
  local u, p = lg.unknown(V, "us"), lg.unknown(Q, "ps")
  local v, q = lg.test(V, "vs"), lg.test(Q, "qs")
  local eqn = lg.integral(mesh:cells(), lg.inner(lg.grad(u), lg.grad(v)) - p*lg.div(v) - q*lg.div(u))
  local bc = {lg.essential_bc(mesh:boundary("left", "right", "bottom"), lg.dot(v, u)),
              lg.essential_bc(mesh:boundary("top"), lg.dot(v, u - {16*x^2*(1 - x)^2, 0}))}
  local uh, ph = lg.linear_problem{mesh = mesh, eqn = eqn, bc = bc, test = {v, q}, unknown = {u, p}, nullspace = p}:solve()
  out("stokes_energy", "direct", 0.5*lg.integrate(mesh, lg.dot(uh, uh)))
  out("stokes_pressure2", "direct", lg.integrate(mesh, ph*ph))
end

package.path = (arg[0]:match("(.*/)") or "./") .. "?.lua;" .. package.path -- beside this script
require("mpi_shared")(lg, out)


-- reductions
out("allreduce_sum", "direct", lg.allreduce(1) / lg.size())
out("allreduce_max", "direct", lg.allreduce(lg.rank(), "max") - (lg.size() - 1))

-- time-dependent reduced functionals on the ranks (mpi_time_cases.lua, shared with the other script)
dofile((arg[0]:match("(.*/)") or "./") .. "mpi_time_cases.lua")(lg, out)
