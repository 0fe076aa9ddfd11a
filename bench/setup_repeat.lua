-- bench/setup_repeat.lua [N] [runs] — the setup of a P1 Laplacian on the unit cube (N×N×N
-- cubes × 6 tetrahedra): the mesh once, then lg.linear_problem (validity check, dof maps,
-- sparsity pattern, PETSc matrix) timed [runs] times in one process, one line each
-- ("setup <s>"); add -lugal_verbose for its phases. The first run's memory is new to the
-- process, the later ones reuse what the one before freed.
local lg = require "lugal"
local N = tonumber(arg[1]) or 64
local runs = tonumber(arg[2]) or 1
local mesh = lg.mesh.box{nx = N, ny = N, nz = N, cell = "tetrahedron"}
local P = lg.lagrange(1)
local u, v = lg.unknown(P, "u"), lg.test(P, "v")
local a = lg.dot(lg.grad(v), lg.grad(u))
for _ = 1, runs do
  local t0 = lg.wtime()
  local prob = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), a), test = v, unknown = u}
  print(string.format("setup %.3f", lg.wtime() - t0))
  prob = nil -- luacheck: ignore
  collectgarbage()
end
