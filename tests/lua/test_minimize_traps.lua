-- lg.minimize's arguments and results, as a new user meets them: bounds with the lower one
-- above the upper one, NaN bounds and tolerances are argument errors (blmvm returned 0 and
-- bnls 1 everywhere, with converged = true after 0 iterations); a run that stops without
-- converging (the iteration limit, a line search failing at rounding level) returns its last
-- iterate with converged = false and a warning line instead of raising (the user lost the
-- result); one return convention (each control, then info) for one and for several
-- controls; the info table never taken for options (lg.integrate(mesh, prob:solve()));
-- f:assign({e1, e2}) on a vector function is the vector expression, not dof values.
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local T = require "testlib"
local lg = require "lugal"
local x, y, pi = lg.x, lg.y, math.pi

local mesh = lg.mesh.rectangle{nx = 32}
local P1 = lg.lagrange(1)
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
local f = lg.control(P1, mesh, "f")
local d = lg.sin(pi*x)*lg.sin(pi*y) / (2*pi^2)
local state = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) - f*v),
                                bc = lg.essential_bc(mesh:boundary(), v*u), test = v, unknown = u}
local rf = lg.reduced_functional{problem = state, control = f,
                                 functional = lg.functional(lg.integral(mesh:cells(), 0.5*(u - d)^2 + 1e-6/2*f^2))}

-- argument errors, each naming the function and the argument
T.fails(function() return lg.minimize(rf, {bounds = {1, 0}, monitor = false}) end,
        "lg.minimize: the lower bound of control 1 is above its upper bound at dof 1 (1.0 > 0.0)")
T.fails(function() return lg.minimize(rf, {bounds = {0/0, 1}, monitor = false}) end, "the lower bound of control 1 is nan")
local lo = lg.interpolate(P1, mesh, x, "lo")
T.fails(function() return lg.minimize(rf, {bounds = {lo, 0.5}, monitor = false}) end, "is above its upper bound at dof")
for _, tol in ipairs{"gatol", "grtol", "gttol"} do
  T.fails(function() return lg.minimize(rf, {[tol] = 0/0, monitor = false}) end, "option '" .. tol .. "' must be a number, got nan")
  T.fails(function() return lg.minimize(rf, {[tol] = -1, monitor = false}) end, "option '" .. tol .. "' must be a finite number >= 0")
  T.fails(function() return lg.minimize(rf, {[tol] = math.huge, monitor = false}) end, "must be a finite number >= 0")
end
-- the bounds still work: an upper bound that binds
local fb, ib = lg.minimize(rf, {bounds = {0, 0.5}, monitor = false})
T.check(ib.converged, "the bounded run: %s", ib.reason)
T.check(math.max(table.unpack(fb:values())) <= 0.5 + 1e-12, "the upper bound 0.5 holds")

-- the iteration limit: the last iterate, converged = false, a warning line
if arg[1] == "limit" then
  f:assign(0*x)
  local m, info = lg.minimize(rf, {maxit = 3, monitor = false})
  print(string.format("limit %s %d %s %.10e", tostring(info.converged), info.iterations, info.reason, info.J))
  return
end
local out = T.child("limit")
local conv, its, reason, J = out:match("limit (%a+) (%d+) (%S+) (%S+)")
T.check(conv == "false" and tonumber(its) == 3 and reason == "DIVERGED_MAXITS", "the limited run: %s", out)
T.check(tonumber(J) < rf:value(0*x), "J after 3 iterations is below J(0): %s", out)
T.check(out:find("lg.minimize: stopped without converging: DIVERGED_MAXITS after 3 iterations", 1, true), "no warning line: %s", out)
-- TAO's default tolerances relative to |J| end in a line search at rounding level on this
-- problem (J ~ 1e-5, |g| ~ 1e-13): a result, not an error
f:assign(0*x)
local m, info = lg.minimize(rf, {monitor = false})
T.check(m == f and info.J < 1e-5, "the default run returned the control and J = %g (%s)", info.J, info.reason)
print(string.format("defaults: %s after %d iterations, J = %.6e", info.reason, info.iterations, info.J))

-- several controls: each control, then info (as problem:solve returns each unknown, then info)
local c = lg.parameter("c", 0.3)
local state2 = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) - (f + c)*v),
                                 bc = lg.essential_bc(mesh:boundary(), v*u), test = v, unknown = u}
local rf2 = lg.reduced_functional{problem = state2, control = {f, c},
                                  functional = lg.functional(lg.integral(mesh:cells(), 0.5*(u - d)^2 + 1e-3/2*f^2 + 1e-3/2*c^2))}
f:assign(0*x)
local m1, m2, info2 = lg.minimize(rf2, {monitor = false, gttol = 1e-8, gatol = 0, grtol = 0})
T.check(m1 == f and type(m2) == "number" and type(info2) == "table" and info2.converged,
        "two controls: %s, %s, %s", tostring(m1), tostring(m2), tostring(info2))

-- the info table after the solution is not an options table
local s = lg.integrate(mesh, state:solve())
T.close(s, lg.integrate(mesh, (state:solve())), 1e-15, "lg.integrate(mesh, problem:solve())")
T.fails(function() return mesh:quality("mean_ratio", select(2, state:solve())) end, "the info table a solve or lg.minimize returns")

-- a vector function assigned a table of expressions
local V = lg.vector(lg.lagrange(1), 2)
local w = lg.zero_function(V, mesh, "w")
w:assign({x, 2*y})
T.close(lg.integrate(mesh, w[1] + w[2]), 1.5, 1e-13, "the assigned vector function")
T.close(lg.integrate(mesh, lg.dot(w, w)), 1/3 + 4/3, 1e-3, "its square")
w:assign({1, 2})
T.close(lg.integrate(mesh, w[2]), 2, 1e-13, "a table of two numbers on a 2-vector function")
print("lg.minimize and the return conventions: as documented")
