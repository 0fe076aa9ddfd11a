-- mpi_dist.lua — quantities that a run on a distributed mesh (mpiexec -n N with
-- -lugal_distribute: each rank holds its part of the mesh and a ghost layer) must give as
-- the serial run on the whole mesh does; tests/sh/test_mpi_dist.sh runs it serially and on
-- 2 and 3 ranks and compares. Each line: name, tolerance class (direct: 1e-10 relative;
-- iter: iterative solvers, 1e-8; count: integers within 1), value (%.17g).
local lg = require "lugal"
local x, y, z, pi = lg.x, lg.y, lg.z, math.pi
local function out(name, class, v) print(string.format("%s %s %.17g", name, class, v)) end
local function sum(t) local s = 0 for _, v in ipairs(t) do s = s + v end return s end

-- the 2D Poisson demo: P1 and P2, direct solves, error norms; the whole counts
for _, p in ipairs{1, 2} do
  local mesh = lg.mesh.rectangle{nx = 24}
  local V = lg.lagrange(p)
  local u, v = lg.unknown(V, "u"), lg.test(V, "v")
  local exact = lg.sin(pi*x)*lg.sin(pi*y)
  local prob = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) - 2*pi^2*exact*v),
                                 bc = lg.essential_bc(mesh:boundary(), v*u), test = v, unknown = u}
  local uh = prob:solve()
  local e = uh - exact
  out("poisson_P" .. p .. "_L2", "direct", math.sqrt(lg.integrate(mesh, e^2)))
  out("poisson_P" .. p .. "_H1", "direct", math.sqrt(lg.integrate(mesh, lg.dot(lg.grad(e), lg.grad(e)))))
  out("poisson_P" .. p .. "_ndof", "count", uh:ndof())
  out("poisson_P" .. p .. "_size", "count", prob:size())
  -- the values over the whole mesh, whatever the order (P2's edges are ordered by their
  -- vertices' global numbers, not by the whole mesh's edge numbering)
  local vals = uh:values()
  out("poisson_P" .. p .. "_nvalues", "count", #vals)
  out("poisson_P" .. p .. "_sum", "direct", sum(vals))
  out("poisson_P" .. p .. "_max", "direct", math.max(table.unpack(vals)))
  local xy, s = uh:dof_coordinates(), 0
  for i, c in ipairs(xy) do s = s + c[1] * vals[i] + c[2]^2 * vals[i] end
  out("poisson_P" .. p .. "_moments", "direct", s)
  local at = uh:eval{{0.3, 0.7}, {0.5, 0.5}}
  out("poisson_P" .. p .. "_eval", "direct", at[1] + 2 * at[2])
  out("boundary_integral_P" .. p, "direct", lg.integrate(mesh:boundary("left", "top"), lg.dot(lg.grad(uh), lg.grad(uh))))
  out("interior_facets_P" .. p, "direct", lg.integrate(mesh:interior_facets(), lg.avg(uh)^2))
  if p == 1 then
    out("cells", "count", mesh:ncells())
    out("vertices", "count", mesh:nvertices())
    mesh:write(arg[1] .. "/poisson.vtu", {u = uh})
    local id = {}
    for i = 1, mesh:ncells() do id[i] = i end
    mesh:write(arg[1] .. "/poisson.pvtu", {u = uh, id = id, q = mesh:quality("mean_ratio")}, {format = "ascii"})
  end
end

package.path = (arg[0]:match("(.*/)") or "./") .. "?.lua;" .. package.path -- beside this script
require("mpi_shared")(lg, out)


-- Taylor-Hood Stokes with the pressure pinned by a boundary condition at a corner (a
-- mixed system of two fields with different degrees)
do
  local mesh = lg.mesh.rectangle{nx = 12}
  local V, Q = lg.vector(lg.lagrange(2)), lg.lagrange(1)
  local u, p = lg.unknown(V, "us"), lg.unknown(Q, "ps")
  local v, q = lg.test(V, "vs"), lg.test(Q, "qs")
  local eqn = lg.integral(mesh:cells(), lg.inner(lg.grad(u), lg.grad(v)) - p*lg.div(v) - q*lg.div(u))
  local bc = {lg.essential_bc(mesh:boundary("left", "right", "bottom"), lg.dot(v, u)),
              lg.essential_bc(mesh:boundary("top"), lg.dot(v, u - {16*x^2*(1 - x)^2, 0})),
              lg.essential_bc(mesh:vertices{near = {0.52, 0.49}}, q*(p - 0.25))}
  local uh, ph = lg.linear_problem{mesh = mesh, eqn = eqn, bc = bc, test = {v, q}, unknown = {u, p}}:solve()
  out("stokes_energy", "direct", 0.5*lg.integrate(mesh, lg.dot(uh, uh)))
  out("stokes_divergence", "direct", lg.integrate(mesh, lg.div(uh)^2))
  out("stokes_pressure", "direct", lg.integrate(mesh, ph))
end


-- P3 on tetrahedra (face nodes) and a mesh read from a file (rank 0 reads, each rank
-- receives its part only)
do
  local mesh = lg.mesh.box{nx = 2}
  local V = lg.lagrange(3)
  local u, v = lg.unknown(V, "u3"), lg.test(V, "v3")
  local exact = lg.sin(x + 2*y + 3*z)
  local uh = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) + u*v - 15*exact*v),
                               bc = lg.essential_bc(mesh:boundary(), v*(u - exact)), test = v, unknown = u}:solve()
  out("p3_tet_L2", "direct", math.sqrt(lg.integrate(mesh, (uh - exact)^2)))
  out("p3_tet_ndof", "count", uh:ndof())
  local read = lg.mesh.read(arg[2] .. "/examples/domain.msh")
  local P1 = lg.lagrange(1)
  local w, t = lg.unknown(P1, "wr"), lg.test(P1, "tr")
  local wh = lg.linear_problem{mesh = read, eqn = lg.integral(read:cells(), lg.dot(lg.grad(t), lg.grad(w)) - t),
                               bc = lg.essential_bc(read:boundary(), t*w), test = t, unknown = w}:solve()
  out("read_integral", "direct", lg.integrate(read, wh))
  out("read_cells", "count", read:ncells())
end


-- mesh quality: each rank its owned cells, reduced (the read mesh: unstructured)
do
  local mesh = lg.mesh.read(arg[2] .. "/examples/domain.msh")
  local q = mesh:quality("mean_ratio")
  local mn, imn = q:min()
  local mx, imx = q:max()
  out("quality_n", "count", #q)
  out("quality_min", "direct", mn)
  out("quality_argmin", "count", imn)
  out("quality_argmax", "count", imx)
  out("quality_mean", "direct", q:mean())
  local h = q:histogram(4)
  for i, c in ipairs(h.counts) do out("quality_histogram_" .. i, "count", c) end
  local w = q:worst(3)
  out("quality_worst", "count", w[1].cell + 10000 * w[2].cell)
  local t, s = q:totable(), 0
  for i, v in ipairs(t) do s = s + i * v end
  out("quality_totable", "direct", s)
  local r = mesh:quality_report(true)
  out("report_cells", "count", r.cells)
  out("report_angle", "direct", r.min_angle.min + r.min_angle.mean)
  out("report_worst", "count", r.min_angle.worst)
  local info = mesh:info()
  out("info_boundary_facets", "count", info.boundary_facets)
  local near = mesh:vertices{near = {0.3, 0.2}}
  out("near_vertex", "direct", lg.integrate(mesh, x)) -- a region made on every rank, no hang
end

-- moving vertices by their global numbers (each rank moves the ones it holds), the check of
-- a tangled mesh, hmax
do
  local mesh = lg.mesh.rectangle{nx = 8}
  for i = 1, mesh:nvertices() do
    local a, b = mesh:coordinates(i)
    if a then mesh:set_coordinates(i, a + 0.02*math.sin(2*pi*b), b) end
  end
  out("moved_hmax", "direct", mesh:hmax())
  out("moved_area_x", "direct", lg.integrate(mesh, x))
  mesh:set_coordinates(41, 0.8, 0.8) -- past its neighbours: some cells inverted
  local n, ids = mesh:check()
  out("tangled_cells", "count", n)
  out("tangled_first", "count", ids[1] + 1000 * ids[#ids])
end

-- untangling and smoothing a distributed mesh: on rank 0's gathered whole mesh, the new
-- coordinates back to every rank (the serial result)
do
  local mesh = lg.mesh.rectangle{nx = 12}
  for i = 1, mesh:nvertices() do
    local a, b = mesh:coordinates(i)
    if a and a > 0.3 and a < 0.6 and b > 0.3 and b < 0.6 then mesh:set_coordinates(i, 1 - b * 0.9, a * 1.05) end
  end
  local r = mesh:untangle{quiet = true}
  out("untangle_invalid_before", "count", r.invalid_before)
  out("untangle_invalid_after", "count", mesh:check())
  out("untangle_moved", "count", r.moved)
  local q = mesh:quality("mean_ratio")
  out("untangle_min_quality", "direct", q:min())
  local s = mesh:smooth{quiet = true, method = "energy"}
  out("smooth_min_quality", "direct", mesh:quality("mean_ratio"):min())
  out("smooth_report_min", "direct", s.min_after)
  out("smooth_x_moment", "direct", lg.integrate(mesh, x*x*y))
end

-- reference shapes and metrics on a distributed mesh: quality relative to a copy made
-- before a motion (each rank its part of both), a constant metric and one per vertex by
-- global vertex numbers, a tangle untangled and smoothed towards the rest shapes (rank 0's
-- gathered mesh and reference)
do
  local rest = lg.mesh.rectangle{nx = 10}
  for i = 1, rest:nvertices() do
    local a, b = rest:coordinates(i)
    if a then rest:set_coordinates(i, 0.5*a*a + 0.5*a, b) end
  end
  local mesh = rest:copy()
  for i = 1, mesh:nvertices() do
    local a, b = mesh:coordinates(i)
    if a then mesh:set_coordinates(i, a + 0.08*math.sin(2*pi*b)*a*(1 - a), b) end
  end
  local d = mesh:quality("deformation_quality", {reference = rest})
  out("deformation_max", "direct", d:max())
  out("deformation_mean", "direct", d:mean())
  out("deformation_inf", "direct", mesh:quality("deformation_quality", {reference = rest, p = math.huge}):mean())
  out("metric_const_mean", "direct", mesh:quality("mean_ratio", {metric = {{2, 0.3}, {0.3, 1}}}):mean())
  local M = {}
  for i = 1, mesh:nvertices() do M[i] = {{1 + (i % 7)/7, 0.1}, {0.1, 1}} end
  local qm = mesh:quality("mean_ratio", {metric = M})
  local mn, imn = qm:min()
  out("metric_vertex_mean", "direct", qm:mean())
  out("metric_vertex_min", "direct", mn)
  out("metric_vertex_argmin", "count", imn)
  -- a tangle untangled towards the rest shapes, then smoothed towards them
  for i = 1, mesh:nvertices() do
    local a, b = mesh:coordinates(i)
    if a and a > 0.3 and a < 0.6 and b > 0.3 and b < 0.6 then mesh:set_coordinates(i, 1 - b*0.9, a*1.05) end
  end
  local r = mesh:untangle{quiet = true, reference = rest}
  out("ref_untangle_invalid_before", "count", r.invalid_before)
  out("ref_untangle_invalid_after", "count", mesh:check())
  out("ref_untangle_moved", "count", r.moved)
  out("ref_untangle_deformation", "direct", mesh:quality("deformation_quality", {reference = rest}):mean())
  local s = mesh:smooth{quiet = true, reference = rest}
  out("ref_smooth_min", "direct", s.min_after)
  out("ref_smooth_mean", "direct", s.mean_after)
  out("ref_smooth_x_moment", "direct", lg.integrate(mesh, x*x*y))
end

-- refining (rank 0 refines the whole mesh and distributes it), copying (each rank its
-- part), a Gmsh file written from the gathered mesh and read back, a table assigned to a
-- function in f:values()'s order
do
  local mesh = lg.mesh.read(arg[2] .. "/examples/domain.msh")
  local fine = mesh:refine()
  out("refined_cells", "count", fine:ncells())
  out("refined_moment", "direct", lg.integrate(fine, x*y*y))
  local c = fine:copy()
  for i = 1, c:nvertices() do local a, b = c:coordinates(i); if a then c:set_coordinates(i, 2*a, b) end end
  out("copy_moment", "direct", lg.integrate(c, x*y*y))
  out("copy_untouched", "direct", lg.integrate(fine, x*y*y))
  fine:write(arg[1] .. "/fine.msh")
  local back = lg.mesh.read(arg[1] .. "/fine.msh")
  out("msh_boundary_facets", "count", back:info().boundary_facets)
  out("msh_hole_length", "direct", lg.integrate(back:boundary("hole"), 1 + 0*x))
  local P2 = lg.lagrange(2)
  local f = lg.interpolate(P2, mesh, x + y*y, "ft")
  local vals = f:values()
  for i = 1, #vals do vals[i] = vals[i] * vals[i] end
  f:assign(vals)
  out("assigned_integral", "direct", lg.integrate(mesh, f))
end

-- mesh motion: displace by a function on every rank's vertices; Laplacian motion of the
-- interior from a boundary displacement (rank 0 on the gathered mesh)
do
  local mesh = lg.mesh.rectangle{nx = 10}
  local n = mesh:displace(function(a, b) return 0.03*math.sin(pi*a)*math.sin(pi*b), 0 end)
  out("displaced_invalid", "count", n)
  out("displaced_moment", "direct", lg.integrate(mesh, x*x))
  local r = mesh:move{displacement = function(a, b) return 0.05*b*(1 - b)*(a > 0.99 and 1 or 0), 0 end, quiet = true}
  out("moved_iterations", "count", r.iterations)
  out("moved_invalid", "count", r.invalid_after)
  out("moved_moment", "direct", lg.integrate(mesh, x*x*y))
end

-- continuous interior penalty: gradient jumps on interior facets with a continuous P2 test
-- function, whose rows on a distributed mesh need a second ghost layer (-lugal_ghost_layers
-- 2, given before the mesh is made); solution, facet integral and the dense matrix
do
  if lg.size() > 1 then -- a count out of 1 to 8 is reported, on every rank, not clamped
    lg.options("-lugal_ghost_layers 0")
    local ok, err = pcall(lg.mesh.rectangle, {nx = 4})
    assert(not ok and err:find("-lugal_ghost_layers: expected a whole number from 1 to 8, got 0", 1, true), tostring(err))
  end
  lg.options("-lugal_ghost_layers 2")
  local mesh = lg.mesh.rectangle{nx = 12}
  local V = lg.lagrange(2)
  local u, v = lg.unknown(V, "u"), lg.test(V, "v")
  local n, h = lg.normal(), 1/12
  local exact = lg.sin(pi*x)*lg.sin(pi*y)
  local eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) + 10*v*lg.grad(u)[1] - (2*pi^2*exact + 10*pi*lg.cos(pi*x)*lg.sin(pi*y))*v)
    + lg.integral(mesh:interior_facets(), 0.1*h^2*lg.dot(lg.jump(lg.grad(u)), n)*lg.dot(lg.jump(lg.grad(v)), n))
  local prob = lg.linear_problem{mesh = mesh, eqn = eqn, bc = lg.essential_bc(mesh:boundary(), v*u), test = v, unknown = u}
  local uh = prob:solve()
  out("cip_L2", "direct", math.sqrt(lg.integrate(mesh, (uh - exact)^2)))
  out("cip_jumps", "direct", lg.integrate(mesh:interior_facets(), lg.dot(lg.jump(lg.grad(uh)), n)^2))
  local A = prob:matrix()
  local s = 0
  local c = uh:dof_coordinates()
  for i = 1, #A do for j = 1, #A do s = s + A[i][j]^2*(1 + c[i][1] + 2*c[j][2] + c[i][1]*c[j][2]) end end
  out("cip_matrix", "direct", s)
end

-- time-dependent reduced functionals on the ranks (mpi_time_cases.lua, shared with the other script)
dofile((arg[0]:match("(.*/)") or "./") .. "mpi_time_cases.lua")(lg, out)
