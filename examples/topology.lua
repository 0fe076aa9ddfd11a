-- Topology optimization of a cantilever (SIMP): where to put half of the material so that
-- the beam is stiffest under a load at the middle of its free end.
--   min_rho  C = int_load t . u     (the compliance)
--   E(rho_f) = E_min + rho_f^3 (1 - E_min),  -r^2 lap rho_f + rho_f = rho (a Helmholtz filter),
--   div(E(rho_f) sigma(u)) = 0, u = 0 on the left, traction t on the right,
--   0 <= rho <= 1, int rho <= V |Omega|.
-- The density rho is piecewise constant (P0), the filter and the displacement (two scalar
-- unknowns, plane strain) are P1, all in one coupled nonlinear problem; the volume bound is
-- a functional constraint (TAO's augmented Lagrangian, almm) and the box bounds are bounds.
--   lugal examples/topology.lua [nx] [maxit] [gatol]
local lg = require "lugal"
local nx = tonumber(arg and arg[1]) or 20
local maxit = tonumber(arg and arg[2]) or 60
local gatol = tonumber(arg and arg[3]) or 1e-4
local L, H, V = 2.0, 1.0, 0.5
local mesh = lg.mesh.rectangle{nx = nx, ny = nx // 2, x1 = L, y1 = H}
local P0, P1 = lg.lagrange(0), lg.lagrange(1)
local x, y = lg.x, lg.y

local rho = lg.control(P0, mesh, "rho", V + 0*x)
local rf, w = lg.unknown(P1, "rho_f"), lg.test(P1, "w")
local ux, uy = lg.unknown(P1, "ux"), lg.unknown(P1, "uy")
local vx, vy = lg.test(P1, "vx"), lg.test(P1, "vy")
local nu, Emin, r = 0.3, 1e-3, 0.04
local mu, lam = 1/(2*(1 + nu)), nu/((1 + nu)*(1 - 2*nu))
local E = Emin + (1 - Emin)*rf^3
local exx, eyy, exy = lg.dx(ux, 1), lg.dx(uy, 2), 0.5*(lg.dx(ux, 2) + lg.dx(uy, 1))
local sxx, syy, sxy = 2*mu*exx + lam*(exx + eyy), 2*mu*eyy + lam*(exx + eyy), 2*mu*exy
local ty = -lg.exp(-((y - 0.5*H)/0.05)^2)        -- a downward load near the middle of the end
local eqn = lg.integral(mesh:cells(), r^2*lg.dot(lg.grad(w), lg.grad(rf)) + (rf - rho)*w
                        + E*(sxx*lg.dx(vx, 1) + syy*lg.dx(vy, 2) + sxy*(lg.dx(vx, 2) + lg.dx(vy, 1))))
          - lg.integral(mesh:boundary("right"), ty*vy)
local state = lg.nonlinear_problem{mesh = mesh, eqn = eqn, test = {w, vx, vy}, unknown = {rf, ux, uy},
                                   bc = {lg.essential_bc(mesh:boundary("left"), vx*ux), lg.essential_bc(mesh:boundary("left"), vy*uy)},
                                   initial = {V + 0*x, 0*x, 0*x}}
local compliance = lg.reduced_functional{problem = state, control = rho,
                                         functional = lg.functional(lg.integral(mesh:boundary("right"), ty*uy))}
local volume = lg.reduced_functional{problem = state, control = rho, functional = lg.functional(lg.integral(mesh:cells(), rho))}

local C0 = compliance:value()
local t = lg.taylor_test(compliance, V + 0.1*lg.sin(3*x)*y, lg.cos(2*x)*lg.sin(3*y), {h = 0.02})
print(t)
assert(math.abs(t.rates1[#t.rates1] - 2) < 0.1, "the compliance gradient fails its Taylor test")
rho:assign(V + 0*x)

local c0 = lg.wtime()
local rho_opt, info = lg.minimize(compliance, {bounds = {0, 1}, constraints = {{volume, "<=", V*L*H}}, maxit = maxit, gatol = gatol,
                                               monitor = false})
local vol = volume:value()
-- how black and white the design is: the share of cells with rho < 0.1 or > 0.9
local vals, crisp = rho_opt:values(), 0
for _, val in ipairs(vals) do if val < 0.1 or val > 0.9 then crisp = crisp + 1 end end
print(string.format("topology: %dx%d cells, compliance %.5f -> %.5f (%s after %d iterations, %d evaluations, %.1f s), "
                    .. "volume %.4f (bound %.2f, multiplier %.4g), %.0f%% of cells below 0.1 or above 0.9",
                    nx, nx // 2, C0, info.J, info.reason, info.iterations, info.evaluations, lg.wtime() - c0, vol, V*L*H,
                    info.multipliers[1], 100*crisp/#vals))
assert(info.J < 0.7*C0, "the optimized design is not stiffer than the uniform one")
assert(vol <= V*L*H*(1 + 1e-4), "the volume bound is violated")
local rho_f, u_x, u_y = compliance:state()
mesh:write("topology.vtu", {rho = rho_opt, rho_f = rho_f, ux = u_x, uy = u_y})
mesh:write("topology.svg", {rho = rho_opt})
