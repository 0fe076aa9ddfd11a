-- bench/newton3d.lua [n] [pull] [options...] — Newton on a compressible Neo-Hookean beam
-- (1 × 0.2 × 0.2, 5n × n × n cubes × 6 tetrahedra, vector P1), clamped on the left, its end
-- pulled by `pull` (default 0: no pull) along x, under a weight of 0.5 per volume; then the
-- gradient of J = ∫ u_z² with respect to the pull and the load (one adjoint solve). Newton's
-- default linear solver against any options given after the pull (-lugal_iterative 0: the
-- direct solver). Prints the solver, Newton and linear iterations, the solve and gradient
-- times, J and the gradient.
local lg = require "lugal"
local n = tonumber(arg[1]) or 12
local mesh = lg.mesh.box{nx = 5*n, ny = n, nz = n, x1 = 1, y1 = 0.2, z1 = 0.2}
local V = lg.vector(lg.lagrange(1))
local u, v = lg.unknown(V, "u"), lg.test(V, "v")
local load, pull = lg.parameter("load", 0.5), lg.parameter("pull", tonumber(arg[2]) or 0)
local E, nu = 1e3, 0.3
local mu, lambda = E/(2*(1 + nu)), E*nu/((1 + nu)*(1 - 2*nu))
local F = lg.identity(3) + lg.grad(u)
local J = lg.det(F)
local psi = mu/2*(lg.tr(lg.dot(lg.transpose(F), F)) - 3) - mu*lg.log(J) + lambda/2*lg.log(J)^2
local t0 = lg.wtime()
local problem = lg.nonlinear_problem{mesh = mesh, test = v, unknown = u,
  eqn = lg.derivative(lg.integral(mesh:cells(), psi - lg.dot({0, 0, -load}, u)), u, v),
  bc = {lg.essential_bc(mesh:boundary("left"), lg.dot(v, u)), lg.essential_bc(mesh:boundary("right"), v[1]*(u[1] - pull))}}
local uh, info = problem:solve()
local t1 = lg.wtime()
local rf = lg.reduced_functional{problem = problem, functional = lg.functional(lg.integral(mesh:cells(), u[3]^2)), control = {pull, load}}
local val = rf:value()
local gp, gl = rf:gradient()
print(string.format("%s dofs=%d newton=%d linear=%d solve_s=%.3f gradient_s=%.3f J=%.12e dpull=%.12e dload=%.12e",
                    info.solver, uh:ndof(), info.iterations, info.linear_iterations, t1 - t0, lg.wtime() - t1, val, gp, gl))
