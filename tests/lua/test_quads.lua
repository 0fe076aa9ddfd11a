-- Quadrilaterals and hexahedra: Q1 and Q2 (lg.lagrange on a quadrilateral or hexahedral
-- mesh) converge at L2 rate p + 1 and H1 rate p, also on distorted, non-affine meshes (the
-- bilinear / trilinear map's Jacobian varies inside each cell); the Q1 stiffness matrices of
-- the unit square and cube are right entry by entry; boundary integrals on curved
-- hexahedron faces satisfy the divergence theorem; vector Q2 elasticity runs.
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local T = require "testlib"
local lg = require "lugal"
local x, y, z, pi = lg.x, lg.y, lg.z, math.pi

local function distort(mesh, amp)
  for i = 1, mesh:nvertices() do
    local a, b, c = mesh:coordinates(i)
    local s = amp*math.sin(2*pi*a)*math.sin(2*pi*b)
    if c then mesh:set_coordinates(i, a + s, b - s, c + s*math.sin(pi*c)) else mesh:set_coordinates(i, a + s, b + 0.5*s) end
  end
end

local function poisson(cell, p, n, amp)
  local mesh = cell == "hexahedron" and lg.mesh.box{nx = n, cell = cell} or lg.mesh.rectangle{nx = n, cell = cell}
  if amp then distort(mesh, amp) end
  local P = lg.lagrange(p)
  local u, v = lg.unknown(P, "u"), lg.test(P, "v")
  local d = cell == "hexahedron" and 3 or 2
  local ue = d == 3 and lg.sin(pi*x)*lg.sin(pi*y)*lg.sin(pi*z) or lg.sin(pi*x)*lg.sin(pi*y)
  local uh = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) - d*pi^2*ue*v),
                               bc = lg.essential_bc(mesh:boundary(), v*(u - ue)), test = v, unknown = u}:solve()
  local e = uh - ue
  return math.sqrt(lg.integrate(mesh, e^2)), math.sqrt(lg.integrate(mesh, lg.dot(lg.grad(e), lg.grad(e))))
end

for _, c in ipairs{{"quadrilateral", 1, 8}, {"quadrilateral", 2, 8}, {"hexahedron", 1, 6}, {"hexahedron", 2, 4}} do
  for _, amp in ipairs{false, 0.03} do
    local l1, h1 = poisson(c[1], c[2], c[3], amp)
    local l2, h2 = poisson(c[1], c[2], 2*c[3], amp)
    local r0, r1 = math.log(l1/l2, 2), math.log(h1/h2, 2)
    print(string.format("Q%d on %s%s: L2 rate %.2f, H1 rate %.2f", c[2], c[1], amp and " (distorted)" or "", r0, r1))
    T.check(math.abs(r0 - (c[2] + 1)) < 0.1 + (c[1] == "hexahedron" and c[2] == 1 and 0.05 or 0), "Q%d %s L2 rate %.3f", c[2], c[1], r0)
    T.check(math.abs(r1 - c[2]) < 0.1, "Q%d %s H1 rate %.3f", c[2], c[1], r1)
  end
end

-- the Q1 stiffness matrices of the unit square and the unit cube
do
  local sq = lg.mesh.rectangle{nx = 1, cell = "quadrilateral"}
  local P1 = lg.lagrange(1)
  local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
  local A = lg.linear_problem{mesh = sq, eqn = lg.integral(sq:cells(), lg.dot(lg.grad(v), lg.grad(u))), test = v, unknown = u}:matrix()
  -- vertices (0,0), (1,0), (0,1), (1,1) in some order: the entry depends on how the two
  -- vertices are related (the same, an edge apart, a diagonal apart)
  local worst = 0
  for i = 1, 4 do
    for j = 1, 4 do
      local xi, yi = sq:coordinates(i)
      local xj, yj = sq:coordinates(j)
      local dist = math.abs(xi - xj) + math.abs(yi - yj)
      local want = dist == 0 and 2/3 or dist == 1 and -1/6 or -1/3
      worst = math.max(worst, math.abs(A[i][j] - want))
    end
  end
  T.check(worst < 1e-14, "Q1 stiffness of the unit square entry by entry (%.2e)", worst)
  local cube = lg.mesh.box{nx = 1, cell = "hexahedron"}
  local B = lg.linear_problem{mesh = cube, eqn = lg.integral(cube:cells(), lg.dot(lg.grad(v), lg.grad(u))), test = v, unknown = u}:matrix()
  worst = 0
  for i = 1, 8 do
    for j = 1, 8 do
      local a = {cube:coordinates(i)}
      local b = {cube:coordinates(j)}
      local dist = math.abs(a[1] - b[1]) + math.abs(a[2] - b[2]) + math.abs(a[3] - b[3])
      local want = ({[0] = 1/3, [1] = 0, [2] = -1/12, [3] = -1/12})[math.floor(dist + 0.5)]
      worst = math.max(worst, math.abs(B[i][j] - want))
    end
  end
  T.check(worst < 1e-14, "Q1 stiffness of the unit cube entry by entry (%.2e)", worst)
  -- Q1 mass matrix of the unit square: 1/36 (4, 2, 1 by the same relation)
  local M = lg.linear_problem{mesh = sq, eqn = lg.integral(sq:cells(), u*v), test = v, unknown = u}:matrix()
  worst = 0
  for i = 1, 4 do
    for j = 1, 4 do
      local xi, yi = sq:coordinates(i)
      local xj, yj = sq:coordinates(j)
      local dist = math.abs(xi - xj) + math.abs(yi - yj)
      worst = math.max(worst, math.abs(M[i][j] - ({[0] = 4, [1] = 2, [2] = 1})[math.floor(dist + 0.5)]/36))
    end
  end
  T.check(worst < 1e-15, "Q1 mass matrix of the unit square (%.2e)", worst)
end

-- boundary integrals on distorted cells: the divergence theorem, int x.n = dim |Omega|
do
  local mesh = lg.mesh.box{nx = 3, cell = "hexahedron"}
  distort(mesh, 0.05)
  local n = lg.normal()
  local vol = lg.integrate(mesh, 1 + 0*x)
  local flux = lg.integrate(mesh:boundary(), n[1]*x + n[2]*y + n[3]*z)
  T.close(flux, 3*vol, 1e-12, "hexahedra: the flux of x through the boundary is 3 |Omega|")
  local flux2 = lg.integrate(mesh:boundary(), n[1]*x^2)
  T.close(flux2, lg.integrate(mesh, 2*x), 1e-10, "hexahedra: the flux of (x^2, 0, 0) is the integral of 2x")
  local q = lg.mesh.rectangle{nx = 4, cell = "quadrilateral"}
  distort(q, 0.05)
  local m = lg.normal()
  T.close(lg.integrate(q:boundary(), m[1]*x + m[2]*y), 2*lg.integrate(q, 1 + 0*x), 1e-12, "quadrilaterals: divergence theorem")
end

-- vector Q2 elasticity on quadrilaterals against a manufactured solution
do
  local mu, lam = 1.0, 1.25
  local function eps(w) return lg.sym(lg.grad(w)) end
  local function sigma(w) return 2*mu*eps(w) + lam*lg.tr(eps(w))*lg.identity(2) end
  local ue = {lg.sin(pi*x)*lg.sin(pi*y), x*y*(1 - x)*(1 - y)}
  local f = -lg.div(sigma(ue))
  local errs = {}
  for _, n in ipairs{6, 12} do
    local mesh = lg.mesh.rectangle{nx = n, cell = "quadrilateral"}
    local V = lg.vector(lg.lagrange(2))
    local u, v = lg.unknown(V, "u"), lg.test(V, "v")
    local uh = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.inner(sigma(u), eps(v)) - lg.dot(f, v)),
                                 bc = lg.essential_bc(mesh:boundary(), lg.dot(v, u)), test = v, unknown = u}:solve()
    errs[#errs + 1] = math.sqrt(lg.integrate(mesh, lg.dot(uh - ue, uh - ue)))
  end
  local r = math.log(errs[1]/errs[2], 2)
  print(string.format("vector Q2 elasticity on quadrilaterals: L2 rate %.2f", r))
  T.check(math.abs(r - 3) < 0.15, "vector Q2 elasticity rate %.3f", r)
end

-- point values on quadrilaterals and hexahedra (Newton's method on the cell's map): at the
-- dof points of distorted meshes the dof values, and a bilinear function exactly
do
  local m2 = lg.mesh.rectangle{nx = 5, ny = 4, cell = "quadrilateral"}
  distort(m2, 0.04)
  local g = lg.interpolate(lg.lagrange(2), m2, x*x*y - y + 2)
  local pts, vals, w2 = g:dof_coordinates(), g:values(), 0
  for i, pt in ipairs(pts) do w2 = math.max(w2, math.abs(g(pt[1], pt[2]) - vals[i])) end
  T.check(w2 < 1e-12, "Q2 on distorted quadrilaterals: at the dof points the dof values (%.2e)", w2)
  local h = lg.mesh.box{nx = 3, cell = "hexahedron"}
  distort(h, 0.03)
  local gh = lg.interpolate(lg.lagrange(1), h, 1 + x - y + 2*z)
  local hp, hv, w3 = gh:dof_coordinates(), gh:values(), 0
  for i, pt in ipairs(hp) do w3 = math.max(w3, math.abs(gh(pt[1], pt[2], pt[3]) - hv[i])) end
  T.check(w3 < 1e-12, "Q1 on distorted hexahedra: at the vertices the dof values (%.2e)", w3)
  local bil = function(a, b) return 1 + a - 2*b + 3*a*b end
  local u1 = lg.interpolate(lg.lagrange(1), lg.mesh.rectangle{nx = 3, cell = "quadrilateral"}, bil(x, y))
  T.close(u1(0.37, 0.81), bil(0.37, 0.81), 1e-13, "Q1 reproduces a bilinear function on a square mesh")
end

-- what is not there yet says so
local q = lg.mesh.rectangle{nx = 2, cell = "quadrilateral"}
T.fails(function() return lg.interpolate(lg.lagrange(3), q, x) end, "degree 3 is not available on quadrilaterals")
T.fails(function() return lg.interpolate(lg.lagrange(1), q, x)(1.5, 0.5) end, "outside the mesh")
print("quadrilaterals and hexahedra: all checks passed")
