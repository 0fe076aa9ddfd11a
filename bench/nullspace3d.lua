-- bench/nullspace3d.lua [N] [neumann|rigid|cavity] — problems with a null space on the unit
-- cube (N×N×N cubes × 6 tetrahedra), solve and one gradient, whole process (issue 56):
--   neumann: a pure Neumann Poisson problem, P1, nullspace = u, -div((k + x) grad u) = g;
--   rigid:   a free elastic body, vector P1, nullspace = "rigid", stiffness k + y, a load
--            orthogonal to the rigid motions;
--   cavity:  the lid-driven cavity, Taylor–Hood, nullspace = p, viscosity k + x.
-- The control is the parameter k; prints the solver, its iterations, J, dJ/dk and times.
local lg = require "lugal"
local N = tonumber(arg[1]) or 48
local kind = arg[2] or "neumann"
local x, y, z, pi = lg.x, lg.y, lg.z, math.pi
local mesh = lg.mesh.box{nx = N}
local k = lg.parameter("k", 1.5)
local t0 = lg.wtime()
local prob, J
if kind == "neumann" then
  local P1 = lg.lagrange(1)
  local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
  prob = lg.linear_problem{mesh = mesh, test = v, unknown = u, nullspace = u,
    eqn = lg.integral(mesh:cells(), (k + x)*lg.dot(lg.grad(v), lg.grad(u)) - lg.cos(pi*x)*lg.cos(pi*y)*v)}
  J = lg.functional(lg.integral(mesh:cells(), (u - y)^2))
elseif kind == "rigid" then
  local V = lg.vector(lg.lagrange(1))
  local u, v = lg.unknown(V, "u"), lg.test(V, "v")
  local function eps(a) return lg.sym(lg.grad(a)) end
  prob = lg.linear_problem{mesh = mesh, test = v, unknown = u, nullspace = "rigid",
    eqn = lg.integral(mesh:cells(), (k + y)*(2*lg.inner(eps(u), eps(v)) + 1.25*lg.div(u)*lg.div(v)) -
                      lg.dot(v, {lg.cos(2*pi*x)*lg.cos(pi*y), lg.cos(pi*x)*lg.cos(2*pi*y), lg.cos(pi*z)*lg.cos(pi*x)}))}
  J = lg.functional(lg.integral(mesh:cells(), lg.dot(u, u)*(1 + x)))
elseif kind == "cavity" then
  local V, Q = lg.vector(lg.lagrange(2)), lg.lagrange(1)
  local u, p = lg.unknown(V, "u"), lg.unknown(Q, "p")
  local v, q = lg.test(V, "v"), lg.test(Q, "q")
  prob = lg.linear_problem{mesh = mesh, test = {v, q}, unknown = {u, p}, nullspace = p,
    eqn = lg.integral(mesh:cells(), (k + x)*lg.inner(lg.grad(v), lg.grad(u)) - lg.div(v)*p - q*lg.div(u)),
    bc = lg.essential_bc(mesh:boundary(), lg.dot(v, u - {16*x*(1 - x)*y*(1 - y)*z*z, 0, 0}))}
  J = lg.functional(lg.integral(mesh:cells(), lg.dot(u, u) + p*x))
else
  error("bench/nullspace3d.lua: the second argument is neumann, rigid or cavity, got " .. kind)
end
local rf = lg.reduced_functional{problem = prob, control = k, functional = J}
local j = rf:value()
local t1 = lg.wtime()
local g = rf:gradient()
local t2 = lg.wtime()
local res = {prob:solve()} -- after the timings: the solver's name and iterations
local info = res[#res]
print(string.format("%s N=%d unknowns=%d solver=%s iterations=%s J=%.12e dJdk=%.12e solve_s=%.3f gradient_s=%.3f",
                    kind, N, prob:size(), info.solver, tostring(info.iterations), j, g, t1 - t0, t2 - t1))
