-- expect: the direct solver MUMPS was given less working memory than it needs (ICNTL(23)) (INFOG(1) = -19
-- args: -pc_factor_mat_solver_type mumps -mat_mumps_icntl_23 1
-- (MUMPS out of memory was reported as DIVERGED_PC_FAILED: now its own error, the memory it
-- wanted and the advice to use an iterative solver)
local lg = require "lugal"
local box = lg.mesh.box{nx = 10}
local P1 = lg.lagrange(1)
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
lg.linear_problem{mesh = box, eqn = lg.integral(box:cells(), lg.dot(lg.grad(v), lg.grad(u)) - v),
                  bc = lg.essential_bc(box:boundary(), v*u), test = v, unknown = u}:solve()
