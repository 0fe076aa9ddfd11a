-- Gradients and sensitivities of problems with a null space (nullspace = u, "rigid", the
-- pressure of an enclosed flow). The state is projected (problem_solve.c, remove_null: the
-- constants to mean zero, the rigid motions out), so the adjoint's right side is projected
-- with the projection's transpose (null_project) and a tangent's solution with
-- it. Without that the gradient was silently wrong: the Taylor test's first-order
-- remainder fell at rate 1, dJ(m; dm) -0.0113 where it is 0.0002 for the first case.
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local T = require "testlib"
local lg = require "lugal"
local x, y, z, pi = lg.x, lg.y, lg.z, math.pi

local function rate_ok(t, what)
  local r = t.rates1[#t.rates1]
  T.check(math.abs(r - 2) < 0.05, "%s: Taylor rate %.3f (want 2.00 +- 0.05)\n%s", what, r, tostring(t))
  return r
end

-- a pure Neumann problem -div((1 + f²) grad u) = g (∫g = 0), u with mean zero; J = ∫(u - d)²
local box = lg.mesh.box{nx = 5}
local P1 = lg.lagrange(1)
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
local f = lg.control(P1, box, "f")
local g = lg.cos(pi*x)*lg.cos(pi*y)
local prob = lg.linear_problem{mesh = box, test = v, unknown = u, nullspace = u,
  eqn = lg.integral(box:cells(), (1 + f^2)*lg.dot(lg.grad(v), lg.grad(u)) - g*v)}
local rf = lg.reduced_functional{problem = prob, control = f,
  functional = lg.functional(lg.integral(box:cells(), (u - lg.cos(pi*x)*y - 3)^2))}
local r1 = rate_ok(lg.taylor_test(rf, 0.5 + x*y + z, x - y*z), "pure Neumann, nullspace = u")

-- the same with a parameter in the operator: the sensitivity du/dk (mean zero, as the state)
-- against central differences of the solution
local k = lg.parameter("k", 1.3)
local pk = lg.linear_problem{mesh = box, test = v, unknown = u, nullspace = u,
  eqn = lg.integral(box:cells(), (k + x)*lg.dot(lg.grad(v), lg.grad(u)) - g*v)}
local function sol(kv) k:set(kv); return pk:solve() end
local h = 1e-4
local up, um = sol(1.3 + h), sol(1.3 - h)
sol(1.3)
local du = pk:sensitivity(k)
local fd = math.sqrt(lg.integrate(box, ((up - um)/(2*h) - du)^2))
local nrm = math.sqrt(lg.integrate(box, du^2))
T.check(fd < 1e-6*nrm, "du/dk against central differences: %.2e relative to %.2e", fd, nrm)
T.check(math.abs(lg.integrate(box, du)) < 1e-12*nrm, "du/dk has mean zero (%.2e)", lg.integrate(box, du))

-- a vector unknown with its constants (one per component) in the null space
local V = lg.vector(lg.lagrange(1))
local w, q = lg.unknown(V, "w"), lg.test(V, "q")
local fv = lg.control(P1, box, "fv")
local pv = lg.linear_problem{mesh = box, test = q, unknown = w, nullspace = w,
  eqn = lg.integral(box:cells(), (1 + fv^2)*lg.inner(lg.grad(q), lg.grad(w)) - lg.dot(q, {g, lg.cos(pi*z), g*lg.cos(pi*z)}))}
local rfv = lg.reduced_functional{problem = pv, control = fv,
  functional = lg.functional(lg.integral(box:cells(), lg.dot(w, w) + w[1]*x))}
local r2 = rate_ok(lg.taylor_test(rfv, 0.5 + x, y*z), "vector, nullspace = w")

-- linear elasticity with traction-free boundaries, the rigid body modes as null space and
-- a load orthogonal to them; the stiffness E = 1 + e² the control
local sq = lg.mesh.rectangle{nx = 8}
local U, W = lg.unknown(lg.vector(P1), "U"), lg.test(lg.vector(P1), "W")
local e = lg.control(P1, sq, "e")
local function eps(a) return lg.sym(lg.grad(a)) end
local load = {lg.cos(2*pi*x)*lg.cos(pi*y), lg.cos(pi*x)*lg.cos(2*pi*y)}
local pe = lg.linear_problem{mesh = sq, test = W, unknown = U, nullspace = "rigid",
  eqn = lg.integral(sq:cells(), (1 + e^2)*(2*lg.inner(eps(U), eps(W)) + lg.div(U)*lg.div(W)) - lg.dot(W, load))}
local rfe = lg.reduced_functional{problem = pe, control = e,
  functional = lg.functional(lg.integral(sq:cells(), lg.dot(U, U)*(1 + x) + U[2]))}
local r3 = rate_ok(lg.taylor_test(rfe, 0.7 + x*y, lg.sin(pi*x)), "elasticity, nullspace = rigid")

-- an enclosed Stokes flow (the lid-driven cavity, Taylor-Hood), nullspace = p; the
-- viscosity's field the control, J mixes the velocity and the pressure
local Vh, Q = lg.vector(lg.lagrange(2)), lg.lagrange(1)
local uu, pp = lg.unknown(Vh, "uu"), lg.unknown(Q, "pp")
local vv, qq = lg.test(Vh, "vv"), lg.test(Q, "qq")
local nu = lg.control(P1, sq, "nu")
local ps = lg.linear_problem{mesh = sq, test = {vv, qq}, unknown = {uu, pp}, nullspace = pp,
  eqn = lg.integral(sq:cells(), (1 + nu^2)*lg.inner(lg.grad(vv), lg.grad(uu)) - lg.div(vv)*pp - qq*lg.div(uu)),
  bc = lg.essential_bc(sq:boundary(), lg.dot(vv, uu - {16*x*x*(1 - x)*(1 - x)*y, 0}))}
local rfs = lg.reduced_functional{problem = ps, control = nu,
  functional = lg.functional(lg.integral(sq:cells(), lg.dot(uu, uu) + pp^2*x + pp))}
local r4 = rate_ok(lg.taylor_test(rfs, 0.8 + x, lg.cos(pi*y)), "Stokes cavity, nullspace = p")

print(string.format("null space gradients: Taylor rates %.3f (Neumann), %.3f (vector), %.3f (rigid), %.3f (Stokes cavity); du/dk %.1e from differences",
                    r1, r2, r3, r4, fd/nrm))
