-- expect-stderr: the option -ksp_tpye cg was not used
-- args: -ksp_tpye cg
local lg = require "lugal"
local mesh = lg.mesh.rectangle{nx = 2}
local P1 = lg.lagrange(1)
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), u*v - v), test = v, unknown = u}:solve()
