-- Convergence rates of the Poisson solution with a manufactured solution: L2 rate p+1 and
-- H1 rate p (±0.1) for Lagrange P1, P2, P3 on triangles and tetrahedra (generated meshes)
-- and on an unstructured Gmsh mesh refined uniformly.
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local T = require "testlib"
local lg = require "lugal"
local data = arg[0]:match("(.*/)") .. "../data/"

local function solve(mesh, p)
  local P = lg.lagrange(p)
  local u, v = lg.unknown(P, "u"), lg.test(P, "v")
  local pi = math.pi
  local dim = mesh:dim()
  -- 2D: u = sin(πx) sin(πy); 3D: u = e^x sin(y) cos(z) (-Δu = u), smooth enough to be in
  -- the asymptotic regime on the meshes used here
  local exact, f
  if dim == 2 then
    exact = lg.sin(pi*lg.x) * lg.sin(pi*lg.y)
    f = 2*pi^2 * exact
  else
    exact = lg.exp(lg.x) * lg.sin(lg.y) * lg.cos(lg.z)
    f = exact
  end
  local eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) - f*v)
  local bc = lg.essential_bc(mesh:boundary(), v*(u - exact))
  local uh = lg.linear_problem{mesh = mesh, eqn = eqn, bc = bc, test = v, unknown = u}:solve()
  local e = uh - exact
  local q = {order = 2*p + 4 <= (dim == 2 and 12 or 8) and 2*p + 4 or (dim == 2 and 12 or 8)}
  return math.sqrt(lg.integrate(mesh, e^2, q)), math.sqrt(lg.integrate(mesh, lg.dot(lg.grad(e), lg.grad(e)), q))
end

-- h: the mesh sizes; uniform refinement halves them (the diagonal chosen inside each
-- tetrahedron by Bey's subdivision is not half as long, so hmax() would mislead)
local function study(name, meshes, p, h)
  local l2, h1 = {}, {}
  for i, m in ipairs(meshes) do l2[i], h1[i] = solve(m, p) end
  local n = #meshes
  local rl2 = T.rate(l2[n-1], l2[n], h[n-1], h[n])
  local rh1 = T.rate(h1[n-1], h1[n], h[n-1], h[n])
  print(string.format("%-28s P%d: L2 %.3e -> %.3e rate %.2f | H1 %.3e -> %.3e rate %.2f", name, p,
                      l2[n-1], l2[n], rl2, h1[n-1], h1[n], rh1))
  T.check(math.abs(rl2 - (p + 1)) <= 0.1, "%s P%d: L2 rate %.3f, expected %d", name, p, rl2, p + 1)
  T.check(math.abs(rh1 - p) <= 0.1, "%s P%d: H1 rate %.3f, expected %d", name, p, rh1, p)
end

local function rects(ns) local t = {} for i, n in ipairs(ns) do t[i] = lg.mesh.rectangle{nx = n, ny = n} end return t, {1/ns[1], 1/ns[2]} end
local function boxes(ns) local t = {} for i, n in ipairs(ns) do t[i] = lg.mesh.box{nx = n, ny = n, nz = n} end return t, {1/ns[1], 1/ns[2]} end
local halves = {1, 0.5}

do local ms, h = rects{16, 32}; study("triangles", ms, 1, h) end
do local ms, h = rects{8, 16}; study("triangles", ms, 2, h) end
do local ms, h = rects{4, 8}; study("triangles", ms, 3, h) end
do local ms, h = boxes{6, 12}; study("tetrahedra", ms, 1, h) end
do local ms, h = boxes{4, 8}; study("tetrahedra", ms, 2, h) end
do local ms, h = boxes{4, 8}; study("tetrahedra", ms, 3, h) end

-- an unstructured Gmsh mesh (MSH 4.1) and its uniform refinements
local g = lg.mesh.read(data .. "square_unstructured.msh")
local g1 = g:refine()
local g2 = g1:refine()
study("gmsh triangles", {g1, g2}, 1, halves)
study("gmsh triangles", {g, g1}, 2, halves)
study("gmsh triangles", {g, g1}, 3, halves)
local gt = lg.mesh.read(data .. "cube_unstructured.msh")
local gt1 = gt:refine()
print(string.format("gmsh cube: %d tetrahedra", gt:ncells()))
study("gmsh tetrahedra", {gt1, gt1:refine()}, 1, halves)
study("gmsh tetrahedra", {gt, gt1}, 2, halves)
study("gmsh tetrahedra", {gt, gt1}, 3, halves)
