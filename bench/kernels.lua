-- bench/kernels.lua [reps] — nanoseconds per element of the element loop for each kernel
-- shape that issue 11 names: the matrix of a constant-coefficient form (exact reference
-- tensors), a Jacobian with a varying coefficient at the quadrature points, a right-hand side
-- with a transcendental source, L2 and H1 error functionals (lg.integrate, degree-12 rules),
-- a bilinear map's matrix (quadrilaterals) and the P2 vector Neo-Hookean Jacobian. Each case
-- is timed in the steady state (median of reps; the first call, which fills the point cache,
-- is left out) and includes gathering coordinates and coefficients and adding into the
-- matrix or vector. Run with -lugal_jit tcc (libtcc's code) and -lugal_jit cc (the system
-- compiler's, from its disk cache after a first run) to compare the tiers:
--   ./lugal bench/kernels.lua 7 -lugal_jit tcc
local lg = require "lugal"
local reps = tonumber(arg[1]) or 7
local clock = lg.wtime
local x, y, z, pi = lg.x, lg.y, lg.z, math.pi

local function median(f)
  f() -- the first call: compilation, the point cache filled
  local t = {}
  for r = 1, reps do
    local t0 = clock()
    f()
    t[r] = clock() - t0
  end
  table.sort(t)
  return t[math.ceil(reps / 2)]
end

local function report(name, cells, s)
  print(string.format("%-44s %9d cells %8.1f ns/element", name, cells, s / cells * 1e9))
end

local function matrix_case(name, mesh, V, a_of, order)
  local u, v = lg.unknown(V, "u"), lg.test(V, "v")
  local w = lg.interpolate(V, mesh, mesh:dim() == 2 and lg.sin(x) + y*y or lg.sin(x) + y*z, "w")
  local prob = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), a_of(u, v, w), order and {order = order} or nil),
                                 test = v, unknown = u}
  report(name, mesh:ncells(), median(function() return prob:assemble() end))
end

-- 2D, 256×256 squares × 2 triangles
local tri = lg.mesh.rectangle{nx = 256, ny = 256}
local P1 = lg.lagrange(1)
matrix_case("P1 triangles, grad u . grad v", tri, P1, function(u, v) return lg.dot(lg.grad(u), lg.grad(v)) end)
matrix_case("P1 triangles, (1 + w^2) grad u . grad v", tri, P1,
            function(u, v, w) return (1 + w^2)*lg.dot(lg.grad(u), lg.grad(v)) end)
do
  local v = lg.test(P1, "v")
  local f = lg.integral(tri:cells(), lg.sin(pi*x)*lg.sin(pi*y)*v)
  report("P1 triangles, sin(pi x) sin(pi y) v (vector)", tri:ncells(), median(function()
    local t0 = clock(); lg.assemble(f); return clock() - t0 end))
  local uh = lg.interpolate(P1, tri, x*y, "uh")
  local e = uh - lg.sin(pi*x)*lg.sin(pi*y)
  report("P1 triangles, L2 error (degree 12)", tri:ncells(), median(function() return lg.integrate(tri, e^2) end))
  report("P1 triangles, H1 error (degree 12)", tri:ncells(),
         median(function() return lg.integrate(tri, lg.dot(lg.grad(e), lg.grad(e))) end))
end
local P2 = lg.lagrange(2)
matrix_case("P2 triangles, (1 + w^2) grad u . grad v", tri, P2,
            function(u, v, w) return (1 + w^2)*lg.dot(lg.grad(u), lg.grad(v)) end)
local quad = lg.mesh.rectangle{nx = 256, ny = 256, cell = "quadrilateral"}
matrix_case("Q1 quadrilaterals, grad u . grad v", quad, P1, function(u, v) return lg.dot(lg.grad(u), lg.grad(v)) end)

-- 3D, 32^3 cubes × 6 tetrahedra
local tet = lg.mesh.box{nx = 32, ny = 32, nz = 32}
matrix_case("P1 tetrahedra, grad u . grad v", tet, P1, function(u, v) return lg.dot(lg.grad(u), lg.grad(v)) end)
matrix_case("P1 tetrahedra, (1 + w^2) grad u . grad v", tet, P1,
            function(u, v, w) return (1 + w^2)*lg.dot(lg.grad(u), lg.grad(v)) end)
matrix_case("P2 tetrahedra, grad u . grad v", tet, P2, function(u, v) return lg.dot(lg.grad(u), lg.grad(v)) end)
local nh = lg.mesh.box{nx = 12, ny = 12, nz = 12}
do
  local V = lg.vector(P2)
  local u, v = lg.unknown(V, "u"), lg.test(V, "v")
  local u0 = lg.interpolate(V, nh, {0.1*x*y, -0.05*y*z, 0.08*x*z}, "u0")
  local F = lg.identity(3) + lg.grad(u0)
  local J = lg.det(F)
  local psi = 0.5*(lg.tr(lg.dot(lg.transpose(F), F)) - 3) - lg.log(J) + 0.625*lg.log(J)^2
  local prob = lg.linear_problem{mesh = nh, eqn = lg.integral(nh:cells(), lg.derivative(lg.derivative(psi, u0, v), u0, u), {order = 4}),
                                 test = v, unknown = u}
  report("P2 vector tetrahedra, Neo-Hookean Jacobian", nh:ncells(), median(function() return prob:assemble() end))
end
