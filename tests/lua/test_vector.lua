-- Vector-valued spaces (lg.vector) and tensor algebra: a vector Laplacian equals the scalar
-- one per component, P2 elasticity converges at rates 3 (L2) and 2 (H1), componentwise
-- essential conditions reproduce an affine plane-strain solution exactly, a Neo-Hookean
-- residual from lg.derivative gives quadratic Newton convergence, the tensor operators give
-- the right numbers, an elastic state differentiates (Taylor rates 2 and 3), and bad
-- input is refused with messages.
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local T = require "testlib"
local lg = require "lugal"
local x, y, pi = lg.x, lg.y, math.pi

-- a vector Laplacian is the scalar Laplacian per component
do
  local mesh = lg.mesh.rectangle{nx = 6}
  local P2 = lg.lagrange(2)
  local V = lg.vector(P2)
  T.check(tostring(V) == "Lagrange P2, 2 components", "basis name: %s", tostring(V))
  local u, v = lg.unknown(V, "u"), lg.test(V, "v")
  T.check(#u == 2 and #v == 2, "a vector unknown is a 2-vector")
  local f = {2*pi^2*lg.sin(pi*x)*lg.sin(pi*y), 1 + x*y}
  local uh = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.inner(lg.grad(v), lg.grad(u)) - lg.dot(v, f)),
                               bc = lg.essential_bc(mesh:boundary(), lg.dot(v, u)), test = v, unknown = u}:solve()
  local s, w = lg.unknown(P2, "s"), lg.test(P2, "w")
  for k = 1, 2 do
    local sh = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(w), lg.grad(s)) - w*f[k]),
                                 bc = lg.essential_bc(mesh:boundary(), w*s), test = w, unknown = s}:solve()
    local d = math.sqrt(lg.integrate(mesh, (uh[k] - sh)^2) / lg.integrate(mesh, sh^2))
    T.check(d < 1e-12, "component %d equals the scalar solution (relative difference %.2e)", k, d)
    -- interlaced dofs: component k of scalar dof i is dof 2(i-1) + k
    local uv, sv = uh:values(), sh:values()
    T.check(#uv == 2*#sv, "%d vector dofs for %d scalar ones", #uv, #sv)
    local worst = 0
    for i = 1, #sv do worst = math.max(worst, math.abs(uv[2*(i - 1) + k] - sv[i])) end
    T.check(worst < 1e-12, "component %d interlaced in the dof vector (%.2e)", k, worst)
  end
  T.check(#uh == 2 and uh:ndof() == 2*lg.interpolate(P2, mesh, 0*x):ndof(), "vector function size")
  local path = os.tmpname() .. ".vtu"
  mesh:write(path, {u = uh})
  local fh = io.open(path)
  local text = fh:read("a")
  fh:close()
  os.remove(path)
  T.check(text:find('Name="u" NumberOfComponents="3"', 1, true) ~= nil, "a 2D vector is written with 3 components for ParaView")
end

-- P2 elasticity, manufactured solution: L2 rate 3, H1 rate 2
local mu, lam = 1.0, 1.25
local function eps(w) return lg.sym(lg.grad(w)) end
local function sigma(w, d) return 2*mu*eps(w) + lam*lg.tr(eps(w))*lg.identity(d or 2) end
do
  local ue = {lg.sin(pi*x)*lg.sin(pi*y), x*y*(1 - x)*(1 - y)}
  local f = -lg.div(sigma(ue))
  local l2, h1 = {}, {}
  for _, n in ipairs{8, 16} do
    local mesh = lg.mesh.rectangle{nx = n}
    local V = lg.vector(lg.lagrange(2))
    local u, v = lg.unknown(V, "u"), lg.test(V, "v")
    local uh = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.inner(sigma(u), eps(v)) - lg.dot(f, v)),
                                 bc = lg.essential_bc(mesh:boundary(), lg.dot(v, u)), test = v, unknown = u}:solve()
    local e = uh - ue
    l2[#l2 + 1] = math.sqrt(lg.integrate(mesh, lg.dot(e, e)))
    h1[#h1 + 1] = math.sqrt(lg.integrate(mesh, lg.inner(lg.grad(e), lg.grad(e))))
  end
  local r2, r1 = math.log(l2[1]/l2[2], 2), math.log(h1[1]/h1[2], 2)
  print(string.format("vector P2 elasticity: L2 rate %.2f, H1 rate %.2f", r2, r1))
  T.check(math.abs(r2 - 3) < 0.1, "L2 rate %.3f", r2)
  T.check(math.abs(r1 - 2) < 0.1, "H1 rate %.3f", r1)
end

-- Taylor-Hood Stokes with the pressure's constant as null space: velocity L2 rate 3,
-- pressure L2 rate 2 (a divergence-free manufactured velocity, a mean-zero pressure)
do
  local psi = x^2*(1 - x)^2*y^2*(1 - y)^2
  local ue = {lg.dx(psi, 2), -lg.dx(psi, 1)}
  local pe = lg.sin(pi*x)*lg.cos(pi*y)
  local f = {-lg.div(lg.grad(ue[1])) + lg.dx(pe, 1), -lg.div(lg.grad(ue[2])) + lg.dx(pe, 2)}
  local eu, ep = {}, {}
  for _, n in ipairs{16, 32} do
    local mesh = lg.mesh.rectangle{nx = n}
    local u, p = lg.unknown(lg.vector(lg.lagrange(2)), "u"), lg.unknown(lg.lagrange(1), "p")
    local v, q = lg.test(lg.vector(lg.lagrange(2)), "v"), lg.test(lg.lagrange(1), "q")
    local eqn = lg.integral(mesh:cells(), lg.inner(lg.grad(u), lg.grad(v)) - p*lg.div(v) - q*lg.div(u) - lg.dot(f, v))
    local uh, ph = lg.linear_problem{mesh = mesh, eqn = eqn, bc = lg.essential_bc(mesh:boundary(), lg.dot(v, u)),
                                     test = {v, q}, unknown = {u, p}, nullspace = p}:solve()
    T.check(math.abs(lg.integrate(mesh, ph)) < 1e-12, "Stokes: mean-zero pressure")
    eu[#eu + 1] = math.sqrt(lg.integrate(mesh, lg.dot(uh - ue, uh - ue)))
    ep[#ep + 1] = math.sqrt(lg.integrate(mesh, (ph - pe)^2))
  end
  local ru, rp = math.log(eu[1]/eu[2], 2), math.log(ep[1]/ep[2], 2)
  print(string.format("Taylor-Hood Stokes: velocity L2 rate %.2f, pressure L2 rate %.2f", ru, rp))
  T.check(math.abs(ru - 3) < 0.15, "Stokes velocity L2 rate %.3f", ru)
  T.check(rp > 1.9, "Stokes pressure L2 rate %.3f (at least 2)", rp)
end

-- a pinned pressure (Sundance's way: an essential condition at one vertex) gives the
-- velocity of the null-space solve and its pressure up to the constant
do
  local mesh = lg.mesh.rectangle{nx = 8}
  local u, p = lg.unknown(lg.vector(lg.lagrange(2)), "u"), lg.unknown(lg.lagrange(1), "p")
  local v, q = lg.test(lg.vector(lg.lagrange(2)), "v"), lg.test(lg.lagrange(1), "q")
  local eqn = lg.integral(mesh:cells(), lg.inner(lg.grad(u), lg.grad(v)) - p*lg.div(v) - q*lg.div(u))
  local walls = {lg.essential_bc(mesh:boundary("left", "right", "bottom"), lg.dot(v, u)),
                 lg.essential_bc(mesh:boundary("top"), lg.dot(v, u - {16*x^2*(1 - x)^2, 0}))}
  local pin = {walls[1], walls[2], lg.essential_bc(mesh:vertices{near = {0.01, -0.02}}, q*(p - 0.25))}
  local u1, p1 = lg.linear_problem{mesh = mesh, eqn = eqn, bc = pin, test = {v, q}, unknown = {u, p}}:solve()
  local u2, p2 = lg.linear_problem{mesh = mesh, eqn = eqn, bc = walls, test = {v, q}, unknown = {u, p}, nullspace = p}:solve()
  T.close(p1(0, 0), 0.25, 1e-14, "the pressure pinned at the vertex nearest to (0.01, -0.02)")
  local du = math.sqrt(lg.integrate(mesh, lg.dot(u1 - u2, u1 - u2)))
  local dp = math.sqrt(lg.integrate(mesh, (p1 - p2 - (0.25 - p2(0, 0)))^2))
  T.check(du < 1e-12 and dp < 1e-10, "pinned and null-space pressures agree up to the constant (%.1e, %.1e)", du, dp)
  T.fails(function() return lg.integral(mesh:vertices{near = {0, 0}}, p*q) end, "has no measure")
  T.fails(function() return lg.integrate(mesh:vertices{near = {0, 0}}, x) end, "has no measure")
  T.fails(function() return mesh:vertices{near = {0}} end, "must be a table of 2 coordinates")
  local r0 = lg.unknown(lg.lagrange(0), "r")
  local s0 = lg.test(lg.lagrange(0), "s")
  T.fails(function() return lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), r0*s0 - s0), test = s0, unknown = r0,
                                              bc = lg.essential_bc(mesh:vertices{near = {0, 0}}, s0*r0)}:solve() end,
          "has no vertex values")
end

-- componentwise conditions (rollers) and a traction: plane-strain uniaxial tension, an
-- affine solution that P1 reproduces to round-off
do
  local E, nu, t = 10.0, 0.3, 0.7
  local lm, mm = E*nu/((1 + nu)*(1 - 2*nu)), E/(2*(1 + nu))
  local mesh = lg.mesh.rectangle{nx = 5, ny = 3}
  local V = lg.vector(lg.lagrange(1))
  local u, v = lg.unknown(V, "u"), lg.test(V, "v")
  local s = 2*mm*eps(u) + lm*lg.tr(eps(u))*lg.identity(2)
  local eqn = lg.integral(mesh:cells(), lg.inner(s, eps(v))) - lg.integral(mesh:boundary("right"), t*v[1])
  local bc = {lg.essential_bc(mesh:boundary("left"), v[1]*u[1]), lg.essential_bc(mesh:boundary("bottom"), v[2]*u[2])}
  local uh = lg.linear_problem{mesh = mesh, eqn = eqn, bc = bc, test = v, unknown = u}:solve()
  local exx, eyy = (1 - nu^2)/E*t, -nu*(1 + nu)/E*t
  local err = math.sqrt(lg.integrate(mesh, (uh[1] - exx*x)^2 + (uh[2] - eyy*y)^2))
  T.check(err < 1e-12, "rollers + traction: the affine plane-strain solution (error %.2e)", err)
end

-- Neo-Hookean residual by lg.derivative: quadratic Newton convergence
do
  local mesh = lg.mesh.rectangle{nx = 8, ny = 4, x1 = 2}
  local V = lg.vector(lg.lagrange(2))
  local u, v = lg.unknown(V, "u"), lg.test(V, "v")
  local F = lg.identity(2) + lg.grad(u)
  local J = lg.det(F)
  local psi = mu/2*(lg.tr(lg.dot(lg.transpose(F), F)) - 2) - mu*lg.log(J) + lam/2*lg.log(J)^2
  local Pi = lg.integral(mesh:cells(), psi) - lg.integral(mesh:boundary("right"), 0.05*u[2])
  local prob = lg.nonlinear_problem{mesh = mesh, eqn = lg.derivative(Pi, u, v), test = v, unknown = u,
                                    bc = lg.essential_bc(mesh:boundary("left"), lg.dot(v, u)), prefix = "nh_"}
  lg.options("-nh_snes_rtol 1e-14 -nh_snes_atol 1e-13")
  local uh, info = prob:solve()
  local r = info.residuals
  T.check(info.iterations <= 7 and r[#r] < 1e-12, "Neo-Hookean: %d Newton iterations, |F| %.2e", info.iterations, r[#r])
  local checked = 0
  for k = 2, #r do
    if r[k] > 1e-11 and r[k - 1] < 1e-2 then
      T.check(r[k]/r[k - 1]^2 < 100, "Neo-Hookean step %d: |F_k|/|F_k-1|^2 = %.3g", k - 1, r[k]/r[k - 1]^2)
      checked = checked + 1
    end
  end
  T.check(checked >= 1, "a step in the quadratic regime was checked")
  local tip = lg.integrate(mesh:boundary("right"), uh[2])
  T.check(tip > 0.02, "the beam bends up under the upward traction (%.3f)", tip)
end

-- tensor algebra, numbers
do
  local mesh = lg.mesh.rectangle{nx = 1}
  local function val(e) return lg.integrate(mesh, e) end
  local A = {{2, 1, 0}, {1, 3, 1}, {0, 1, 4}}
  T.close(val(lg.det(A)), 18, 1e-14, "det of a 3x3")
  T.close(val(lg.tr(A)), 9, 1e-14, "trace")
  local P = lg.dot(lg.inv(A), A)
  local off = 0
  for i = 1, 3 do for j = 1, 3 do off = off + math.abs(val(P[i][j]) - (i == j and 1 or 0)) end end
  T.check(off < 1e-14, "inv(A) A = I (%.2e)", off)
  local B = {{1, 2}, {3, 4}}
  T.close(val(lg.transpose(B)[1][2]), 3, 1e-14, "transpose")
  T.close(val(lg.skew(B)[1][2]), -0.5, 1e-14, "skew")
  T.close(val(lg.sym(B)[1][2]), 2.5, 1e-14, "sym")
  T.close(val(lg.dev(B)[1][1]), -1.5, 1e-14, "dev")
  T.close(val(lg.outer({1, 2}, {3, 4, 5})[2][3]), 10, 1e-14, "outer")
  local c = lg.cross({1, 0, 0}, {0, 1, 0})
  T.close(val(c[3]), 1, 1e-14, "cross")
  T.close(val(lg.cross({1, 2}, {3, 4})), -2, 1e-14, "2D cross")
  -- d det(F) = cof(F) : dF (the engine differentiates the formula)
  local V = lg.vector(lg.lagrange(1))
  local uh = lg.interpolate(V, mesh, {0.3*x + 0.1*y, 0.2*x - 0.4*y})
  local dh = lg.interpolate(V, mesh, {0.5*y, x})
  local F = lg.identity(2) + lg.grad(uh)
  local dd = val(lg.derivative(lg.det(F), uh, dh))
  local G = lg.grad(dh)
  local Fv = {{1.3, 0.1}, {0.2, 0.6}}
  local Gv = {{0, 0.5}, {1, 0}}
  local cof = Fv[2][2]*Gv[1][1] - Fv[2][1]*Gv[1][2] - Fv[1][2]*Gv[2][1] + Fv[1][1]*Gv[2][2]
  T.close(dd, cof, 1e-13, "derivative of det F")
  T.check(G ~= nil, "gradient of a vector function")
end

-- an elastic state under a control: Taylor rates 2 and 3
do
  local mesh = lg.mesh.rectangle{nx = 6}
  local V = lg.vector(lg.lagrange(2))
  local u, v = lg.unknown(V, "u"), lg.test(V, "v")
  local f = lg.control(lg.lagrange(1), mesh, "f")
  local st = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.inner(sigma(u), eps(v)) - f*v[2] - 0.1*v[1]),
                               bc = lg.essential_bc(mesh:boundary("left"), lg.dot(v, u)), test = v, unknown = u}
  -- (u.u)^2: a functional that is not quadratic in the control, so the Hessian's rate shows
  local J = lg.functional(lg.integral(mesh:cells(), 10*lg.dot(u, u)^2 + 1e-3*f^2) + lg.integral(mesh:boundary("right"), u[2]^2))
  local rf = lg.reduced_functional{problem = st, functional = J, control = f}
  local t = lg.taylor_test(rf, 1 + x, lg.sin(pi*y), {hessian = true})
  for k = 1, #t.rates1 do T.close(t.rates1[k], 2, 0.05, "elastic state: first-order rate") end
  for k = 1, #t.rates2 do T.close(t.rates2[k], 3, 0.1 / 3, "elastic state: second-order rate") end
  local dm = lg.interpolate(lg.lagrange(1), mesh, x*y)
  local g = rf:gradient(1 + x, {riesz = "none"})
  local gd, dv = 0, g:values()
  for i, w in ipairs(dm:values()) do gd = gd + dv[i]*w end
  T.close(gd, rf:derivative(dm), 1e-12, "gradient . dm = derivative")
end

-- bad input
T.fails(function() lg.vector(lg.lagrange(1), 4) end, "lg.vector")
T.fails(function() lg.vector(lg.vector(lg.lagrange(1))) end, "already a vector basis")
T.fails(function() lg.lagrange(1, 3) end, "takes one argument")
T.fails(function() lg.unknown(lg.lagrange(1), "u", 3) end, "takes a basis and a name")
T.fails(function() lg.zero_function(lg.lagrange(1), lg.mesh.rectangle{nx = 1}, "f", 2) end, "takes a basis, a mesh and a name")
local mesh = lg.mesh.rectangle{nx = 2}
T.fails(function() lg.interpolate(lg.vector(lg.lagrange(1)), mesh, x) end, "the function has 2 components, the expression is a scalar")
T.fails(function() lg.interpolate(lg.lagrange(1), mesh, {x, y}) end, "the function is a scalar")
T.fails(function() lg.det({{1, 2, 3}, {4, 5, 6}}) end, "square matrix")
T.fails(function() lg.inv({{1, 2}, {2, 4}}) end, "singular")
T.fails(function() lg.derivative(x*y, x, lg.test(lg.lagrange(1))) end, "argument 2")
T.fails(function() lg.derivative(lg.unknown(lg.lagrange(1))^2, lg.unknown(lg.lagrange(1)), lg.test(lg.vector(lg.lagrange(1)))) end,
        "components")
T.fails(function() return lg.interpolate(lg.lagrange(1), mesh, x)[1] end, "cannot be indexed")
do
  local V = lg.vector(lg.lagrange(1))
  local u, v = lg.unknown(V, "u"), lg.test(V, "v")
  local nl = lg.nonlinear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.inner(lg.grad(u), lg.grad(v)) + lg.dot(u, u)*lg.dot(u, v) - v[1]),
                                  test = v, unknown = u, bc = lg.essential_bc(mesh:boundary(), lg.dot(v, u))}
  T.fails(function() return nl:solve(lg.interpolate(lg.lagrange(1), mesh, x)) end, "initial guess for unknown 1 must be", "2 components")
end
print("vector spaces and tensor algebra: all checks passed")
