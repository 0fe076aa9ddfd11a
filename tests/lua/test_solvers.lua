-- The default direct solvers: PETSc's LU for small single-unknown systems falls back to
-- MUMPS where it cannot pivot (a zero diagonal), a user's choice of package is kept (and
-- then fails with a message), a badly scaled matrix is not mistaken for a singular one,
-- and a nonlinear state resolved with chord steps (kept Jacobians) is as accurate as a
-- fresh Newton solve.
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local T = require "testlib"
local lg = require "lugal"
local x, y = lg.x, lg.y

-- u' = 1, u(0) = 0 by Galerkin P1: the matrix has a zero diagonal (central differences);
-- in nested dissection's order PETSc's LU, which does not pivot, meets a zero pivot, in
-- minimum degree's (lugal's choice for rows this short) the essential row comes first and
-- the factorization goes through; the solution x is exact at the nodes either way
local function first_order(prefix)
  local mesh = lg.mesh.interval{n = 10}
  local P1 = lg.lagrange(1)
  local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
  return mesh, lg.linear_problem{mesh = mesh, test = v, unknown = u, prefix = prefix,
                                 eqn = lg.integral(mesh:cells(), v*lg.grad(u)[1] - v),
                                 bc = lg.essential_bc(mesh:boundary("left"), v*u)}
end
local function nodal_error(mesh, uh, exact)
  local err = 0
  for i, val in ipairs(uh:values()) do err = math.max(err, math.abs(val - exact(mesh:coordinates(i)))) end
  return err
end
local mesh, pr = first_order()
local uh, info = pr:solve()
T.check(info.solver == "lu/petsc", "the 1D zero-diagonal system in minimum degree order: PETSc's LU (%s)", info.solver)
T.check(nodal_error(mesh, uh, function(t) return t end) < 1e-13, "and its solution is x at the nodes")
lg.options("-nd_pc_factor_mat_ordering_type nd")
mesh, pr = first_order("nd_")
uh, info = pr:solve()
T.check(info.solver == "lu/mumps", "in nested dissection order: MUMPS after PETSc's LU (%s)", info.solver)
T.check(nodal_error(mesh, uh, function(t) return t end) < 1e-13, "and its solution is x at the nodes")
-- u_x + u_y = x + y, u = 0 on the inflow sides: zero diagonals inside, which PETSc's LU
-- meets in minimum degree order too; MUMPS (given its own ordering, not lugal's) solves it,
-- near u = xy
local function advection(prefix)
  local sq = lg.mesh.rectangle{nx = 16}
  local P1 = lg.lagrange(1)
  local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
  return sq, lg.linear_problem{mesh = sq, test = v, unknown = u, prefix = prefix,
                               eqn = lg.integral(sq:cells(), v*(lg.grad(u)[1] + lg.grad(u)[2]) - v*(x + y)),
                               bc = lg.essential_bc(sq:boundary("left", "bottom"), v*u)}
end
local sq0, adv = advection()
uh, info = adv:solve()
T.check(info.solver == "lu/mumps", "the zero-diagonal advection system was solved by MUMPS (%s)", info.solver)
local aerr = nodal_error(sq0, uh, function(a, b) return a*b end)
T.check(aerr < 2e-3, "advection: max nodal error %.2e against xy", aerr)
-- the same system with PETSc's LU asked for by the user: no switch, the zero pivot is reported
lg.options("-zd_pc_factor_mat_solver_type petsc")
local _, prz = advection("zd_")
T.fails(function() return prz:solve() end, "problem:solve", "zero pivot")

-- a Poisson problem in tiny units (the stiffness scaled by 1e-20): no false zero pivot,
-- the same nodal values as at scale 1
local sq = lg.mesh.rectangle{nx = 12}
local P1 = lg.lagrange(1)
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
local function poisson(s)
  local uh, info = lg.linear_problem{mesh = sq, test = v, unknown = u,
                           eqn = lg.integral(sq:cells(), s*lg.dot(lg.grad(v), lg.grad(u)) - s*v),
                           bc = lg.essential_bc(sq:boundary(), v*u)}:solve()
  T.check(info.solver == "lu/petsc", "scale %g: PETSc's LU, no false zero pivot (%s)", s, info.solver)
  return uh
end
local u1, us = poisson(1), poisson(1e-20)
T.close(us(0.5, 0.5), u1(0.5, 0.5), 1e-12, "scaled stiffness: u(1/2, 1/2) as at scale 1")
T.check(u1(0.5, 0.5) > 0.07 and u1(0.5, 0.5) < 0.075, "u(1/2, 1/2) = %.6f (0.0737 exact)", u1(0.5, 0.5))

-- symmetric elimination of a symmetric form: LU first (Cholesky from its second
-- factorization on: test_keep_factor.lua); a second solve with other essential
-- values and the same matrix reuses the factorization, its right side corrected with the
-- eliminated columns kept from the first: the same solution as a new problem
local g = lg.interpolate(P1, sq, x + 2*y, "g")
local function dirichlet()
  return lg.linear_problem{mesh = sq, test = v, unknown = u, symmetric = true,
                           eqn = lg.integral(sq:cells(), (1 + x)*lg.dot(lg.grad(v), lg.grad(u)) - v),
                           bc = lg.essential_bc(sq:boundary(), v*(u - g))}
end
local ds = dirichlet()
local _, di = ds:solve()
T.check(di.solver == "lu/petsc", "symmetric = true on a symmetric form, first factorization: LU (%s)", di.solver)
g:assign(3*(x + 2*y))
local ua = ds:solve()
local ub = dirichlet():solve()
local dmax = 0
for i, val in ipairs(ua:values()) do dmax = math.max(dmax, math.abs(val - ub:values()[i])) end
T.check(dmax < 1e-12, "new essential values, reused factorization: as a new problem (max difference %.2e)", dmax)
T.close(ua(0.5, 0.5), ub(0.5, 0.5), 1e-12, "u(1/2, 1/2)")
T.check(ua(0.5, 0.5) > 3*1.5*0.9, "u(1/2, 1/2) = %.4f follows the essential values", ua(0.5, 0.5))
-- an advection term makes the form unsymmetric: LU even with symmetric elimination
local _, ni = lg.linear_problem{mesh = sq, test = v, unknown = u, symmetric = true,
                                eqn = lg.integral(sq:cells(), lg.dot(lg.grad(v), lg.grad(u)) + v*lg.grad(u)[1] - v),
                                bc = lg.essential_bc(sq:boundary(), v*u)}:solve()
T.check(ni.solver == "lu/petsc", "an unsymmetric form: LU (%s)", ni.solver)

-- a mixed system (Stokes, a zero pressure block) goes to MUMPS at once
local V, Q = lg.vector(lg.lagrange(2)), lg.lagrange(1)
local w, q = lg.unknown(V, "w"), lg.unknown(Q, "q")
local z, r = lg.test(V, "z"), lg.test(Q, "r")
local _, _, st_info = lg.linear_problem{mesh = sq, test = {z, r}, unknown = {w, q}, nullspace = q,
  eqn = lg.integral(sq:cells(), lg.inner(lg.grad(z), lg.grad(w)) - lg.div(z)*q - r*lg.div(w)),
  bc = lg.essential_bc(sq:boundary(), lg.dot(z, w - {y*(1 - y)*x*(1 - x)*16, 0}))}:solve()
T.check(st_info.solver == "lu/mumps", "Stokes: MUMPS (%s)", st_info.solver)

-- a nonlinear state: J at a control reached by resolves (chord steps from the last
-- solution) equals J of a new problem solved by Newton from zero at the same control
local function rf_new()
  local f = lg.control(P1, sq, "f")
  local st = lg.nonlinear_problem{mesh = sq, test = v, unknown = u,
                                  eqn = lg.integral(sq:cells(), (1 + u^2)*lg.dot(lg.grad(v), lg.grad(u)) - f*v),
                                  bc = lg.essential_bc(sq:boundary(), v*u)}
  return lg.reduced_functional{problem = st, control = f,
                               functional = lg.functional(lg.integral(sq:cells(), 0.5*(u - 0.1)^2 + 1e-4*f^2))}
end
local rf = rf_new()
local Js = {}
for k = 0, 4 do Js[k] = rf:value(20 + 10*k*x*y) end          -- each a resolve from the last state
local J4 = rf_new():value(20 + 40*x*y)
T.close(Js[4], J4, 1e-10, "J after four resolves with kept Jacobians = J of a fresh Newton solve")
T.check(Js[4] ~= Js[3], "the resolves changed the state (J %.6e, %.6e)", Js[3], Js[4])
-- a preconditioner used alone is named as no solver (it was blamed on a singular matrix);
-- MUMPS's own errors: tests/data/hostile/lua/mumps_memory.lua
do
  local box = lg.mesh.box{nx = 6}
  local P1b = lg.lagrange(1)
  local ub, vb = lg.unknown(P1b, "ub"), lg.test(P1b, "vb")
  local function poisson(prefix)
    return lg.linear_problem{mesh = box, eqn = lg.integral(box:cells(), lg.dot(lg.grad(vb), lg.grad(ub)) - vb),
                             bc = lg.essential_bc(box:boundary(), vb*ub), test = vb, unknown = ub, prefix = prefix}
  end
  lg.options("-pj_ksp_type preonly -pj_pc_type jacobi")
  T.fails(function() return poisson("pj_"):solve() end, "-ksp_type preonly applies the preconditioner jacobi once")
end
print("solvers: all checks passed")
