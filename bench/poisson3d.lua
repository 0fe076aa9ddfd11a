-- bench/poisson3d.lua [N] [default|tuned|lu] — the 3D Poisson benchmark of issue 11, whole process: -Δu = f on
-- the unit cube in N×N×N cubes × 6 tetrahedra, u = sin(πx) sin(πy) sin(πz), u = 0 on the
-- boundary, P1, CG + GAMG to a relative residual of 1e-8 (symmetric elimination keeps the
-- matrix symmetric), then the L2 error (quadrature degree 6 on both sides). bench/poisson3d_fenicsx.py solves the same problem
-- with the same solver; `time` both for the whole-process comparison. A second argument
-- "default" writes the problem as a user would with no options (lugal's default solver, no
-- symmetric=), "lu" the same with -lugal_iterative 0 (the direct solver); "tuned" (the
-- default here) as above.
local lg = require "lugal"
local N = tonumber(arg and arg[1]) or 64
local x, y, z, pi = lg.x, lg.y, lg.z, math.pi
local mesh = lg.mesh.box{nx = N, ny = N, nz = N}
local P1 = lg.lagrange(1)
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
local exact = lg.sin(pi*x)*lg.sin(pi*y)*lg.sin(pi*z)
local mode = arg and arg[2] or "tuned"
assert(mode == "default" or mode == "tuned" or mode == "lu", "mode: default | tuned | lu")
if mode == "tuned" then lg.options("-ksp_type cg -pc_type gamg -ksp_rtol 1e-8") end
if mode == "lu" then lg.options("-lugal_iterative 0") end
local t0 = lg.wtime()
local prob = lg.linear_problem{mesh = mesh, test = v, unknown = u, symmetric = mode == "tuned",
                               eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) - 3*pi^2*exact*v),
                               bc = lg.essential_bc(mesh:boundary(), v*u)}
local uh, info = prob:solve()
local tsolve = lg.wtime() - t0
local l2 = math.sqrt(lg.integrate(mesh, (uh - exact)^2, {order = 6}))
-- the peak resident memory of the largest rank (VmHWM), and the matrix and right-hand side
-- assembly time (its slowest rank)
local f = io.open("/proc/self/status")
local hwm = f and tonumber(f:read("a"):match("VmHWM:%s*(%d+)")) or 0
if f then f:close() end
-- (and of the smallest: with -lugal_distribute rank 0 reads or generates the whole mesh, the
-- others never hold it)
print(string.format("lugal poisson3d N=%d P1 %s solver=%s dofs=%d iterations=%d L2=%.6e ranks=%d setup_solve_s=%.3f assemble_s=%.3f peak_rss_mb_rank=%.0f (smallest %.0f)",
                    N, mode, info.solver, uh:ndof(), info and info.iterations or -1, l2, lg.size(), tsolve,
                    lg.allreduce(info.assemble_ms / 1000, "max"), lg.allreduce(hwm / 1024, "max"), lg.allreduce(hwm / 1024, "min")))
