-- A non-finite element matrix, vector or Jacobian stops the element loop on every thread at
-- the same chunk and reports the cell: the loop's threads once left it at different chunks
-- (one saw the stop its neighbour set in the next chunk's scatter and left while the others
-- waited at the barrier), and about half the runs hung with 2 threads, 35 of 40 with 4.
-- Each case runs in a child process many times, with 2 and with 4 threads, and on 2 ranks,
-- under a timeout.
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local T = require "testlib"
local lg = require "lugal"

if arg[1] == "case" then
  local mesh = lg.mesh.rectangle{nx = 64} -- 8192 cells: several chunks of element tensors
  local P1 = lg.lagrange(1)
  local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
  local bc = lg.essential_bc(mesh:boundary(), v*u)
  local which = arg[2]
  local prob
  if which == "jacobian" then -- sqrt(u) from u = 0: an infinite Jacobian in every cell
    prob = lg.nonlinear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) + lg.sqrt(u)*v - v),
                                bc = bc, test = v, unknown = u}
  elseif which == "matrix" then -- the square root of a negative number where x > 1/2
    prob = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.sqrt(0.5 - lg.x)*lg.dot(lg.grad(v), lg.grad(u)) - v),
                             bc = bc, test = v, unknown = u}
  else -- the right-hand side: the logarithm of a negative number where y > 1/2 (later chunks)
    prob = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) - lg.log(0.5 - lg.y)*v),
                             bc = bc, test = v, unknown = u}
  end
  local ok, err = pcall(function() local uh = prob:solve() return uh end)
  print(ok and "solved" or err)
  return
end

local runs = tonumber(arg[1]) or 20
for _, which in ipairs{"jacobian", "matrix", "vector"} do
  for _, threads in ipairs{2, 4} do
    for r = 1, runs do
      local out = T.child("case " .. which, "OMP_NUM_THREADS=" .. threads .. " timeout 60")
      T.check(out:find("not finite", 1, true), "%s with %d threads, run %d: %s", which, threads, r,
              out == "" and "no output (killed by the timeout: a hang)" or out)
    end
  end
  -- two ranks of 2 threads each: every rank leaves the element loop and the run reports (the
  -- child starts without this run's Open MPI singleton settings, which its environment holds)
  local mpi = string.format("sh -c 'for v in $(env | sed -n \"s/^\\(OMPI_[A-Za-z_]*\\|PMIX_[A-Za-z_]*\\)=.*/\\1/p\"); do " ..
                            "unset $v; done; export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 " ..
                            "OMPI_MCA_rmaps_base_oversubscribe=1 OMP_NUM_THREADS=2; exec timeout 60 mpiexec -n 2 \"$0\" \"$@\"' '%s' '%s' case %s 2>&1",
                            arg[-1], arg[0], which)
  for r = 1, 3 do
    local h = io.popen(mpi)
    local out = h:read("a")
    h:close()
    T.check(out:find("not finite", 1, true), "%s on 2 ranks, run %d: %s", which, r,
            out == "" and "no output (killed by the timeout: a hang)" or out)
  end
  print(string.format("%s: %d runs with 2 and with 4 threads, and 3 on 2 ranks, each reported the cell", which, runs))
end
