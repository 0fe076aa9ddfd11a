-- bench/optimization.lua CASE N — PDE-constrained optimization, the lugal side of the
-- comparison with pyadjoint on legacy FEniCS (bench/optimization_pyadjoint.py, the same
-- problems, meshes, controls and stopping rules). CPU time (os.clock), kernels warm.
-- A third argument (lmvm, blmvm, nls, bnls) runs that optimization alone.
--   CASE mother:    -lap u = f, u = 0 on the boundary, J = 1/2 |u - d|^2 + alpha/2 |f|^2,
--                   d = sin(pi x) sin(pi y) / (2 pi^2), alpha = 1e-6, P1 state and control
--   CASE mother0:   the same with a P0 (piecewise constant) control
--   CASE nonlinear: the same with -div((1 + u^2) grad u) = f
--   CASE inversion: -div(k grad u) = 1, J = 1/2 |u - u_obs|^2 + beta/2 |grad k|^2, k >= 1
-- Prints one line per measurement: the median of 3 of one state solve (a new problem:
-- assembly, factorization, solve and J), one gradient after it (the raw dual vector, as
-- pyadjoint's default), one Hessian action, and the whole optimization from the initial
-- control (L-BFGS, and Newton-CG with Hessian actions), with iterations and J*.
local lg = require "lugal"
local case = arg and arg[1] or "mother"
local N = tonumber(arg and arg[2]) or 32
assert(case == "mother" or case == "mother0" or case == "nonlinear" or case == "inversion",
       "case: mother | mother0 | nonlinear | inversion")

local pi, x, y = math.pi, lg.x, lg.y
local mesh = lg.mesh.rectangle{nx = N}
local P1 = lg.lagrange(1)
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
local bc = lg.essential_bc(mesh:boundary(), v*u)

local uobs, beta, kmin = nil, 1e-8, 1.0
if case == "inversion" then
  local kt = lg.interpolate(P1, mesh, 1 + lg.exp(-40*((x - 0.4)^2 + (y - 0.6)^2)), "k_true")
  local ut = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), kt*lg.dot(lg.grad(v), lg.grad(u)) - v),
                               bc = bc, test = v, unknown = u}:solve()
  local peak = 0
  for _, val in ipairs(ut:values()) do peak = math.max(peak, math.abs(val)) end
  uobs = lg.interpolate(P1, mesh, 0.01*peak*lg.sin(37*x)*lg.cos(23*y), "u_obs")
  uobs:assign(uobs + ut)
end

-- a new state problem and reduced functional (a new factorization; kernels stay compiled)
local function build()
  if case == "inversion" then
    local k = lg.control(P1, mesh, "k", 1 + 0*x)
    -- a symmetric form: symmetric elimination keeps the matrix symmetric (Cholesky)
    local st = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), k*lg.dot(lg.grad(v), lg.grad(u)) - v),
                                 bc = bc, test = v, unknown = u, symmetric = true}
    local J = lg.functional(lg.integral(mesh:cells(), 0.5*(u - uobs)^2 + beta/2*lg.dot(lg.grad(k), lg.grad(k))))
    return lg.reduced_functional{problem = st, functional = J, control = k}
  end
  local f = lg.control(case == "mother0" and lg.lagrange(0) or P1, mesh, "f")
  local kappa = case == "nonlinear" and (1 + u^2) or 1
  local mk = case == "nonlinear" and lg.nonlinear_problem or lg.linear_problem
  local st = mk{mesh = mesh, eqn = lg.integral(mesh:cells(), kappa*lg.dot(lg.grad(v), lg.grad(u)) - f*v),
                bc = bc, test = v, unknown = u}
  local d = lg.sin(pi*x)*lg.sin(pi*y)/(2*pi^2)
  local J = lg.functional(lg.integral(mesh:cells(), 0.5*(u - d)^2 + 1e-6/2*f^2))
  return lg.reduced_functional{problem = st, functional = J, control = f}
end

local m = case == "inversion" and 1 + 0.3*x*y or 1 + x
local dm = lg.sin(pi*x)*lg.sin(pi*y)
build():value(m)                                   -- compiles every kernel once
-- a third argument names one method to run alone (for -log_view of the optimization only)
local only = arg and arg[3]
if only and only:sub(1, 1) == "-" then only = nil end -- an option (-lugal_jit tcc), not a method
local function median(t) table.sort(t); return t[(#t + 1) // 2] end
local ts, tg, th = {}, {}, {}
for _ = 1, only and 0 or 3 do
  local rf = build()
  local c = os.clock(); rf:value(m); ts[#ts + 1] = os.clock() - c
  c = os.clock(); rf:gradient(nil, {riesz = "none"}); tg[#tg + 1] = os.clock() - c
  c = os.clock(); rf:hessian(dm, nil, {riesz = "none"}); th[#th + 1] = os.clock() - c
end
local s = only and 0 or median(ts)
if not only then print(string.format("lugal %s %d: state %.4f s, gradient %.4f s (%.2fx state), Hessian action %.4f s (%.2fx state)",
                    case, N, s, median(tg), median(tg)/s, median(th), median(th)/s)) end

local methods = case == "inversion" and {"blmvm", "bnls"} or {"lmvm", "nls"}
if only then methods = {only} end
for _, method in ipairs(methods) do
  local rf = build()
  local c = os.clock()
  local _, info = lg.minimize(rf, {method = method, bounds = case == "inversion" and {kmin, nil} or nil,
                                   gttol = case == "inversion" and 1e-6 or 1e-8, gatol = 0, grtol = 0,
                                   maxit = 2000, monitor = false})
  print(string.format("lugal %s %d: optimization %s %.3f s, %d iterations, %d Hessian products, J* = %.10e (%s)",
                      case, N, method, os.clock() - c, info.iterations, info.hessian_products, info.J, info.reason))
end
