-- 1D meshes (lg.mesh.interval): P1-P3 converge at L2 rate p + 1 and H1 rate p, boundary
-- points carry the normal (a flux through "right"), point values, VTU and Gmsh output that
-- reads back, the 2D/3D-only tools refuse with a message.
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local T = require "testlib"
local lg = require "lugal"
local x, pi = lg.x, math.pi

for p = 1, 3 do
  local l2, h1 = {}, {}
  for _, n in ipairs{8, 16} do
    local mesh = lg.mesh.interval{n = n, x0 = -1, x1 = 2}
    local P = lg.lagrange(p)
    local u, v = lg.unknown(P, "u"), lg.test(P, "v")
    local ue = lg.sin(pi*x) + x^2
    local uh = lg.linear_problem{mesh = mesh, test = v, unknown = u,
                                 eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) - (pi^2*lg.sin(pi*x) - 2)*v),
                                 bc = lg.essential_bc(mesh:boundary(), v*(u - ue))}:solve()
    local e = uh - ue
    l2[#l2 + 1] = math.sqrt(lg.integrate(mesh, e^2))
    h1[#h1 + 1] = math.sqrt(lg.integrate(mesh, lg.dot(lg.grad(e), lg.grad(e))))
  end
  local r2, r1 = math.log(l2[1]/l2[2], 2), math.log(h1[1]/h1[2], 2)
  print(string.format("P%d on intervals: L2 rate %.2f, H1 rate %.2f", p, r2, r1))
  T.check(math.abs(r2 - (p + 1)) < 0.1, "P%d interval L2 rate %.3f", p, r2)
  T.check(math.abs(r1 - p) < 0.1, "P%d interval H1 rate %.3f", p, r1)
end

-- a Neumann condition at "right" (the outward normal is +1 there): -u'' = 0, u(0) = 1,
-- u'(1) = 2 gives u = 1 + 2x; the flux at "left" through the normal -1 is -2
do
  local mesh = lg.mesh.interval{n = 5}
  local P2 = lg.lagrange(2)
  local u, v = lg.unknown(P2, "u"), lg.test(P2, "v")
  local uh = lg.linear_problem{mesh = mesh, test = v, unknown = u,
                               eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u))) - lg.integral(mesh:boundary("right"), 2*v),
                               bc = lg.essential_bc(mesh:boundary("left"), v*(u - 1))}:solve()
  T.close(uh(0.7), 2.4, 1e-13, "the Neumann solution 1 + 2x at 0.7")
  T.close(lg.integrate(mesh:boundary("left"), lg.dot(lg.grad(uh), lg.normal())), -2, 1e-12, "the flux through left")
  T.close(lg.integrate(mesh:boundary(), 1 + 0*x), 2, 1e-15, "two boundary points")
  T.fails(function() return uh(1.5) end, "the point")
  -- VTU (line cells, type 3) and Gmsh (lines and points) output; the Gmsh file reads back
  local vtu, msh = os.tmpname() .. ".vtu", os.tmpname() .. ".msh"
  mesh:write(vtu, {u = uh}, {format = "ascii"})
  local f = io.open(vtu)
  local text = f:read("a")
  f:close()
  T.check(text:find("\n3\n", 1, true) ~= nil, "VTU cells of type 3 (VTK_LINE)")
  mesh:write(vtu, {u = uh})
  f = io.open(vtu)
  text = f:read("a")
  f:close()
  T.check(text:find('header_type="UInt64"', 1, true) and text:find('format="binary"', 1, true), "binary VTU by default")
  -- the cell types array: 8 bytes of count (5) then five 3s, base64 "BQAAAAAAAAADAwMDAw=="
  T.check(text:find("BQAAAAAAAAADAwMDAw==", 1, true) ~= nil, "the binary types array of 5 lines")
  T.fails(function() return mesh:write(vtu, {u = uh}, {format = "hdf5"}) end, "must be \"binary\", \"ascii\" or \"zlib\"")
  mesh:write(msh)
  local back = lg.mesh.read(msh)
  T.check(back:dim() == 1 and back:ncells() == 5, "the Gmsh file reads back as 5 intervals")
  T.close(lg.integrate(back:boundary("right"), x), 1, 1e-15, "its boundary point \"right\" at x = 1")
  os.remove(vtu)
  os.remove(msh)
  T.fails(function() return mesh:untangle{quiet = true} end, "not intervals")
  T.fails(function() return mesh:quality("min_angle") end, "does not apply to intervals")
end
T.fails(function() return lg.mesh.interval{n = 0} end, "nx must be at least 1")
T.fails(function() return lg.mesh.interval{x0 = 1, x1 = 0} end, "x0 < x1")
T.fails(function() return lg.mesh.interval{n = 4, ny = 2} end, "ny")
print("intervals: all checks passed")
