-- gmsh_domain.lua — potential flow past a hole in a plate, on a Gmsh mesh with named
-- boundaries (examples/domain.msh, made from examples/domain.geo): Δφ = 0, φ = 1 on
-- "inflow", φ = 0 on "outflow", no flux through "wall" and "hole". The flux in equals the
-- flux out; both are printed. Writes gmsh_domain.vtu.
-- Run: lugal examples/gmsh_domain.lua [degree]
local lg = require "lugal"
local here = arg[0]:match("(.*/)") or "./"
local p = tonumber(arg[1]) or 2

local mesh = lg.mesh.read(here .. "domain.msh")
local info = mesh:info()
print(string.format("gmsh_domain: %d %ss, %d vertices, boundaries: %s", info.cells, info.cell,
                    info.vertices, table.concat(info.boundaries, ", ")))

local P = lg.lagrange(p)
local phi, v = lg.unknown(P, "phi"), lg.test(P, "v")
local eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(phi)))
local bc = {lg.essential_bc(mesh:boundary("inflow"), v*(phi - 1)),
            lg.essential_bc(mesh:boundary("outflow"), v*phi)}
local ph = lg.linear_problem{mesh = mesh, eqn = eqn, bc = bc, test = v, unknown = phi}:solve()

local n = lg.normal()
-- the velocity is -grad(phi): inflow flux -∫ u·n, outflow flux ∫ u·n
local flux_in = lg.integrate(mesh:boundary("inflow"), lg.dot(lg.grad(ph), n))
local flux_out = lg.integrate(mesh:boundary("outflow"), -lg.dot(lg.grad(ph), n))
local flux_wall = lg.integrate(mesh:boundary("wall", "hole"), lg.dot(lg.grad(ph), n))
print(string.format("  P%d: flux in %.6f, flux out %.6f, through walls and hole %.2e", p, flux_in, flux_out, flux_wall))
mesh:write("gmsh_domain.vtu", {phi = ph})
