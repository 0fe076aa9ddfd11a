-- mpi_read.lua FILE... — quantities of meshes read from files that a distributed run (each
-- rank reading its part of the file, read_dist.c, or rank 0 the whole file where that path
-- cannot take it) must give as the serial run does; tests/sh/test_mpi_read.sh runs it
-- serially and on 2 and 3 ranks and compares. Each line: name, tolerance class (direct:
-- 1e-10 relative; count: integers within 1), value (%.17g).
local lg = require "lugal"
local x, y = lg.x, lg.y
local function out(name, class, v) print(string.format("%s %s %.17g", name, class, v)) end

for i = 1, #arg do
  local path = arg[i]
  local tag = path:match("([^/]+)%.msh$") -- the files; the PETSc options are not
  if tag then
    local mesh = lg.mesh.read(path)
    local info = mesh:info()
    out(tag .. "_cells", "count", mesh:ncells())
    out(tag .. "_vertices", "count", info.vertices)
    out(tag .. "_measure", "direct", lg.integrate(mesh, 1 + 0*x))
    out(tag .. "_moment", "direct", lg.integrate(mesh, x*y + x))
    local q = mesh:quality("mean_ratio")
    out(tag .. "_qmin", "direct", q:min())
    out(tag .. "_qmean", "direct", q:mean())
    out(tag .. "_boundary_names", "count", #info.boundaries)
    for _, b in ipairs(info.boundaries) do
      out(tag .. "_boundary_" .. b, "direct", lg.integrate(mesh:boundary(b), 1 + x + 2*y))
    end
    for _, r in ipairs{"domain", 5} do
      local ok, region = pcall(mesh.cells, mesh, r)
      if ok then out(tag .. "_region_" .. r, "direct", lg.integrate(region, 1 + x*x)) end
    end
    local P1 = lg.lagrange(1)
    local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
    local uh = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) - (1 + x)*v),
                                 bc = lg.essential_bc(mesh:boundary(), v*u), test = v, unknown = u}:solve()
    out(tag .. "_poisson", "direct", lg.integrate(mesh, uh*uh))
    out(tag .. "_ndof", "count", uh:ndof())
  end
end
