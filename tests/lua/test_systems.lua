-- Coupled systems (two unknowns with different bases), symmetric elimination of boundary
-- conditions, parameters, region integrals and discrete coefficients.
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local T = require "testlib"
local lg = require "lugal"

-- -Δu + (u - w) = f1, -Δw + (w - u) = f2 with u = sin(πx)sin(πy), w = x(1-x)y(1-y);
-- u in P2, w in P1: errors must fall at the rates of each basis
local function coupled(n)
  local mesh = lg.mesh.rectangle{nx = n, ny = n}
  local P1, P2 = lg.lagrange(1), lg.lagrange(2)
  local u, w = lg.unknown(P2, "u"), lg.unknown(P1, "w")
  local v, q = lg.test(P2, "v"), lg.test(P1, "q")
  local pi, x, y = math.pi, lg.x, lg.y
  local ue = lg.sin(pi*x)*lg.sin(pi*y)
  local we = x*(1 - x)*y*(1 - y)
  local lap_w = -2*y*(1 - y) - 2*x*(1 - x)
  local f1 = 2*pi^2*ue + (ue - we)
  local f2 = -lap_w + (we - ue)
  local eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) + (u - w)*v - f1*v
                                      + lg.dot(lg.grad(q), lg.grad(w)) + (w - u)*q - f2*q)
  local bc = {lg.essential_bc(mesh:boundary(), v*u), lg.essential_bc(mesh:boundary(), q*w)}
  local prob = lg.linear_problem{mesh = mesh, eqn = eqn, bc = bc, test = {v, q}, unknown = {u, w}}
  local uh, wh, info = prob:solve()
  T.check(info.dofs == uh:ndof() + wh:ndof(), "dofs %d", info.dofs)
  return math.sqrt(lg.integrate(mesh, (uh - ue)^2)), math.sqrt(lg.integrate(mesh, (wh - we)^2))
end
local eu1, ew1 = coupled(8)
local eu2, ew2 = coupled(16)
local ru, rw = math.log(eu1/eu2, 2), math.log(ew1/ew2, 2)
print(string.format("coupled P2/P1: u rate %.2f, w rate %.2f", ru, rw))
T.check(math.abs(ru - 3) < 0.15, "P2 field rate %.3f", ru)
T.check(math.abs(rw - 2) < 0.15, "P1 field rate %.3f", rw)

-- symmetric elimination gives the same solution and a symmetric matrix (CG works)
local mesh = lg.mesh.rectangle{nx = 12, ny = 12}
local P1 = lg.lagrange(1)
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
local g = 1 + lg.x*lg.y
local eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) - v)
local a = lg.linear_problem{mesh = mesh, eqn = eqn, bc = lg.essential_bc(mesh:boundary(), v*(u - g)), test = v, unknown = u}
local b = lg.linear_problem{mesh = mesh, eqn = eqn, bc = lg.essential_bc(mesh:boundary(), v*(u - g)), test = v, unknown = u,
                            symmetric = true, prefix = "sym_"}
lg.options("-sym_ksp_type cg -sym_pc_type jacobi -sym_ksp_rtol 1e-12")
local ua, ub = a:solve(), b:solve()
local d = math.sqrt(lg.integrate(mesh, (ua - ub)^2))
print(string.format("symmetric elimination: difference %.2e", d))
T.check(d < 1e-9, "symmetric and plain elimination differ by %.3e", d)
local _, info = b:solve()
T.check(info.iterations > 1, "CG ran %d iterations", info.iterations)

-- region integrals, parameters and discrete coefficients
local k = lg.parameter("k", 2)
T.close(lg.integrate(mesh, k*lg.x), 1.0, 1e-13, "∫ 2x")
k:set(4)
T.close(lg.integrate(mesh, k*lg.x), 2.0, 1e-13, "∫ 4x after k:set(4)")
T.close(lg.integrate(mesh:boundary("left", "bottom"), lg.x + lg.y), 1.0, 1e-13, "boundary integral")
local P2 = lg.lagrange(2)
local quad = lg.interpolate(P2, mesh, lg.x^2 + lg.y)
T.close(lg.integrate(mesh, quad), 1/3 + 1/2, 1e-13, "P2 interpolant of a quadratic is exact")
T.close(lg.integrate(mesh, lg.dot(lg.grad(quad), lg.grad(quad))), 4/3 + 1, 1e-12, "∫|grad q|^2")
local c = lg.interpolate(P1, mesh, 3)
local m = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), c*u*v - c*lg.x*v), test = v, unknown = u}
local proj = m:solve()
T.close(lg.integrate(mesh, proj), 0.5, 1e-12, "L2 projection of x")

-- named cell regions and boundaries from Gmsh physical names
local data = arg[0]:match("(.*/)") .. "../data/"
local g = lg.mesh.read(data .. "square_unstructured.msh")
T.close(lg.integrate(g:cells("domain"), 1), 1.0, 1e-13, "area of the physical surface 'domain'")
T.close(lg.integrate(g:cells(), lg.x), 0.5, 1e-13, "∫ x over the Gmsh square")
T.close(lg.integrate(g:boundary("left", "top"), 1), 2.0, 1e-13, "length of left + top")
T.fails(function() return g:cells("steel") end, "unknown region name \"steel\"", "\"domain\"")
print("regions: ok")
