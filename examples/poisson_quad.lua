-- poisson_quad.lua — -Δu = f with Q1 and Q2 elements on quadrilaterals (straight and
-- distorted: the bilinear map's Jacobian then varies inside every cell) and Q2 on
-- hexahedra, u = sin(πx) sin(πy) [sin(πz)]. Prints the L2 errors on two meshes and their
-- rates, and checks them (p + 1).
-- Run: lugal examples/poisson_quad.lua [n]
local lg = require "lugal"
local n = tonumber(arg and arg[1]) or 8
local x, y, z, pi = lg.x, lg.y, lg.z, math.pi

local function solve(cell, p, m, distorted)
  local mesh = cell == "hexahedron" and lg.mesh.box{nx = m, cell = cell} or lg.mesh.rectangle{nx = m, cell = cell}
  if distorted then
    for i = 1, mesh:nvertices() do
      local a, b = mesh:coordinates(i)
      if a then -- (on a distributed mesh, as under mpiexec, a rank has its part's vertices only)
        local s = 0.04*math.sin(2*pi*a)*math.sin(2*pi*b)
        mesh:set_coordinates(i, a + s, b + 0.5*s)
      end
    end
  end
  local P = lg.lagrange(p)
  local u, v = lg.unknown(P, "u"), lg.test(P, "v")
  local d = mesh:dim()
  local ue = d == 3 and lg.sin(pi*x)*lg.sin(pi*y)*lg.sin(pi*z) or lg.sin(pi*x)*lg.sin(pi*y)
  local uh = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) - d*pi^2*ue*v),
                               bc = lg.essential_bc(mesh:boundary(), v*(u - ue)), test = v, unknown = u}:solve()
  if m == n and p == 2 and d == 2 and distorted then mesh:write("poisson_quad.vtu", {u = uh}) end
  return math.sqrt(lg.integrate(mesh, (uh - ue)^2))
end

for _, case in ipairs{{"quadrilateral", 1, false}, {"quadrilateral", 2, false}, {"quadrilateral", 2, true},
                      {"hexahedron", 2, false}} do
  local cell, p, dist = case[1], case[2], case[3]
  local m = cell == "hexahedron" and math.max(2, n // 2) or n
  local e1, e2 = solve(cell, p, m, dist), solve(cell, p, 2*m, dist)
  local rate = math.log(e1/e2, 2)
  print(string.format("poisson_quad: Q%d on %s%s, %d and %d cells across: L2 errors %.3e %.3e, rate %.2f",
                      p, cell == "hexahedron" and "hexahedra" or "quadrilaterals", dist and " (distorted)" or "", m, 2*m, e1, e2, rate))
  assert(math.abs(rate - (p + 1)) < 0.15, "the L2 rate is p + 1")
end
