-- A kept factorization (src/assemble/problem/solver.c, lg_keep): a symmetric linear problem whose
-- matrix changes (a coefficient, an optimization's control) is solved by CG preconditioned
-- with its last Cholesky factor (GMRES with the LU factor of its first factorization) while
-- that costs less than refactoring, and refactored when that fails. The answers must be those of a new problem factored afresh; the sequence of
-- choices (direct, kept, fallback, pause, kept) is checked, and an unsymmetric matrix's LU
-- is kept by GMRES; the adjoint and Hessian solves
-- with a kept factor must pass Taylor tests; an inversion with the control in the stiffness
-- must reach the same optimum as with -lugal_keep_factor 0 (this script's child run), and
-- two runs the same optimum to the bit.
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local T = require "testlib"
local lg = require "lugal"

local x, y = lg.x, lg.y
local mesh = lg.mesh.rectangle{nx = 24}
local P1 = lg.lagrange(1)
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
local bc = lg.essential_bc(mesh:boundary(), v*u)
local child = arg[1] == "child"

local function inversion(sym)
  local kt = lg.interpolate(P1, mesh, 1 + lg.exp(-40*((x - 0.4)^2 + (y - 0.6)^2)), "k_true")
  local ut = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), kt*lg.dot(lg.grad(v), lg.grad(u)) - v),
                               bc = bc, test = v, unknown = u, symmetric = true}:solve()
  local k = lg.control(P1, mesh, "k", 1 + 0*x)
  local st = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), k*lg.dot(lg.grad(v), lg.grad(u)) - v),
                               bc = bc, test = v, unknown = u, symmetric = sym}
  local J = lg.functional(lg.integral(mesh:cells(), 0.5*(u - ut)^2 + 1e-8/2*lg.dot(lg.grad(k), lg.grad(k))))
  return lg.reduced_functional{problem = st, functional = J, control = k}
end

if child then
  local rf = inversion(true)
  local _, info = lg.minimize(rf, {method = "blmvm", bounds = {1.0, nil}, gttol = 1e-6, gatol = 0, grtol = 0,
                                   maxit = 500, monitor = false})
  print(string.format("J* %.17g iterations %d", info.J, info.iterations))
  os.exit(0)
end

-- a coefficient a in the stiffness, changed between solves
local a = lg.parameter("a", 0.1)
local function problem(sym)
  return lg.linear_problem{mesh = mesh, test = v, unknown = u, symmetric = sym,
                           eqn = lg.integral(mesh:cells(), (1 + a*x*y)*lg.dot(lg.grad(v), lg.grad(u)) - (1 + x)*v), bc = bc}
end
local p, pu = problem(true), nil
local function solve_and_compare(val, want, what)
  a:set(val)
  local uh, info = p:solve()
  local ref = problem(p ~= pu):solve()          -- factored afresh, eliminated the same way
  local dmax, umax = 0, 0
  local rv = ref:values()
  for i, w in ipairs(uh:values()) do dmax = math.max(dmax, math.abs(w - rv[i])); umax = math.max(umax, math.abs(rv[i])) end
  T.check(info.solver == want, "%s (a = %g): solved by %s (want %s)", what, val, info.solver, want)
  T.check(dmax <= 1e-10*umax, "%s (a = %g): max difference %.2e from a new factorization (max |u| %.3g)", what, val, dmax, umax)
  return info
end
-- the first factorization is LU (faster once: PETSc's Cholesky has a slow symbolic phase),
-- kept by GMRES; the second and later ones of the symmetric matrix Cholesky, kept by CG
solve_and_compare(0.1, "lu/petsc", "first solve")
local ki = solve_and_compare(0.12, "gmres/lu-kept", "a small change")
T.check(ki.iterations >= 1 and ki.iterations <= 20, "a small change: %d GMRES iterations with the old factor", ki.iterations)
-- a coefficient ratio of 10^7 over the domain: GMRES with the old factor does not reach the
-- tolerance within its iterations, and the matrix is refactored at once, by Cholesky
solve_and_compare(1e7, "cholesky/petsc", "a change too large for the old factor")
-- that attempt did not pay: the next factorization is made without trying
solve_and_compare(1.01e7, "cholesky/petsc", "the pause after a failed attempt")
solve_and_compare(1.02e7, "cg/cholesky-kept", "kept again after the pause")
-- a parameter of the right-hand side only (a source's time): the matrix and its factor stay
-- (matrix_fingerprint mixes in the parameters the matrix reads, not every parameter): the
-- direct solve again, no kept-factor iterations, and u scales with the source
local src = lg.parameter("src", 1)
local pr = lg.linear_problem{mesh = mesh, test = v, unknown = u,
                             eqn = lg.integral(mesh:cells(), (1 + a*x*y)*lg.dot(lg.grad(v), lg.grad(u)) - src*(1 + x)*v), bc = bc}
a:set(0.5)
local u1, i1 = pr:solve()
local v1 = u1:values()
src:set(3)
local u3, i3 = pr:solve()
T.check(i1.solver == "lu/petsc" and i3.solver == "lu/petsc", "a source parameter changed: the factor reused directly (%s, then %s)",
        i1.solver, i3.solver)
local smax = 0
for i, w in ipairs(u3:values()) do smax = math.max(smax, math.abs(w - 3*v1[i])) end
T.check(smax < 1e-12, "a source parameter changed: u three times the first (max difference %.2e)", smax)
a:set(0.6) -- a parameter of the matrix: the matrix changed, solved with the kept factor
local _, i6 = pr:solve()
T.check(i6.solver == "gmres/lu-kept", "a matrix parameter changed: the kept factor (%s)", i6.solver)

-- a symmetric P2 stiffness-plus-mass matrix on 40²: entries the stiffness parts cancel down
-- to the mass part differ between the triangles by rounding only (3.5e-18 at 2.7e-6 next to
-- diagonals of 4), which solver.c's symmetry test must accept: refactored after a change
-- too large for the kept factor, it is factored by Cholesky (it stayed LU before)
local sq40 = lg.mesh.rectangle{nx = 40}
local P2 = lg.lagrange(2)
local u2, v2 = lg.unknown(P2, "u2"), lg.test(P2, "v2")
local c2 = lg.parameter("c2", 1)
local p2 = lg.linear_problem{mesh = sq40, test = v2, unknown = u2, symmetric = true,
                             eqn = lg.integral(sq40:cells(), (1 + c2*x*y)*lg.dot(lg.grad(v2), lg.grad(u2)) + u2*v2 - v2),
                             bc = lg.essential_bc(sq40:boundary(), v2*u2)}
local _, s1 = p2:solve()
c2:set(1e7)
local _, s2 = p2:solve()
T.check(s1.solver == "lu/petsc" and s2.solver == "cholesky/petsc", "symmetric P2 on 40²: %s, then %s after a large change",
        s1.solver, s2.solver)

-- row elimination (an unsymmetric matrix): LU, kept by GMRES; an advection term too
pu = problem(false)
p = pu
solve_and_compare(0.1, "lu/petsc", "row elimination, first solve")
local gi = solve_and_compare(0.12, "gmres/lu-kept", "row elimination, a small change")
T.check(gi.iterations >= 1 and gi.iterations <= 20, "row elimination: %d GMRES iterations with the old factor", gi.iterations)

-- gradients and Hessian actions through kept factors (transposed solves: the adjoints): the
-- control is in the stiffness, so every evaluation of the Taylor test changes the matrix
local function rates(t, what, order, want)
  local r = (order == 1 and t.rates1 or t.rates2)
  r = r[#r]
  T.check(math.abs(r - want) < 0.1, "%s: Taylor rate %.3f (want %.1f)\n%s", what, r, want, tostring(t))
end
local rf = inversion(true)
rf:value(1 + 0.3*x*y)
local t1 = lg.taylor_test(rf, 1 + 0.3*x*y, lg.sin(3*x)*y)
rates(t1, "gradient with kept factors", 1, 2)
local t2 = lg.taylor_test(rf, 1 + 0.3*x*y, lg.sin(3*x)*y, {hessian = true, h = 0.1})
rates(t2, "Hessian action with kept factors", 2, 3)
-- and with row elimination, where the adjoint is a transposed GMRES solve
local rfu = inversion(false)
rfu:value(1 + 0.3*x*y)
rates(lg.taylor_test(rfu, 1 + 0.3*x*y, lg.sin(3*x)*y), "gradient with kept LU factors", 1, 2)
rates(lg.taylor_test(rfu, 1 + 0.3*x*y, lg.sin(3*x)*y, {hessian = true, h = 0.1}), "Hessian with kept LU factors", 2, 3)

-- the whole inversion: the same optimum as without keeping factors
local function run(opts)
  local out = T.child("child " .. opts)
  local j, it = out:match("J%* (%S+) iterations (%d+)")
  T.check(j ~= nil, "child run (%s) printed its optimum: %s", opts, out)
  return tonumber(j), tonumber(it)
end
local jk, ik = run("")
local jk2, ik2 = run("")
local jd, id = run("-lugal_keep_factor 0")
-- the choices are counted in operations, never timed: a run repeats its results to the bit
T.check(jk == jk2 and ik == ik2, "two runs: J* %.17g and %.17g, %s and %s iterations", jk or 0, jk2 or 0, ik, ik2)
if jk and jd then
  T.close(jk, jd, 1e-6, "the inversion's optimum with and without kept factors")
  T.check(math.abs(ik - id) <= 2, "iterations %d with kept factors, %d without", ik, id)
end
print(string.format("kept factorizations: answers as new ones to 1e-10, Taylor rates %.2f and %.2f, inversion J* %.6g in %d iterations (%d without)",
                    t1.rates1[#t1.rates1], t2.rates2[#t2.rates2], jk or 0, ik or 0, id or 0))
