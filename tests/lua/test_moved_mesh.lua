-- A problem made before its mesh moved, solved again after, gives what a problem made on
-- the moved mesh gives: every cache that depends on the coordinates or the data follows
-- them (the matrix's fingerprint, the rigid body modes, an assembled operator, the point
-- caches). tests/lua/mpi_shared.lua runs the same on 2 and 3 ranks against the serial run
-- (the fingerprint's combination over the ranks cancelled on 2: the first matrix stayed).
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local T = require "testlib"
local lg = require "lugal"
local x, y = lg.x, lg.y

local function J(mesh, prob) local uh = prob:solve() return lg.integrate(mesh, uh) end

local function poisson(mesh, k)
  local P1 = lg.lagrange(1)
  local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
  return lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), k*lg.dot(lg.grad(v), lg.grad(u)) - v),
                           bc = lg.essential_bc(mesh:boundary(), v*u), test = v, unknown = u}
end

-- J = ∫u, -Δu = 1, the unit square moved by 0.2 (x y (1 - y), 0)
do
  local mesh = lg.mesh.rectangle{nx = 32}
  local k = lg.parameter("k", 1)
  local prob = poisson(mesh, k)
  local J0 = J(mesh, prob)
  T.close(J0, 3.503301954217e-02, 1e-11, "J on the unit square")
  mesh:displace(function(x, y) return 0.2*x*y*(1 - y), 0 end)
  local again = J(mesh, prob)
  local fresh = J(mesh, poisson(mesh, k))
  print(string.format("moved: re-solved %.15e, new problem %.15e", again, fresh))
  T.close(again, fresh, 1e-13, "the old problem on the moved mesh")
  T.close(fresh, 3.791251385758e-02, 1e-11, "J on the moved square")
  -- a parameter the matrix reads
  k:set(2)
  T.close(J(mesh, prob), fresh / 2, 1e-13, "k = 2")
  -- moved back by mesh:set_coordinates, vertex by vertex
  k:set(1)
  local m0 = lg.mesh.rectangle{nx = 32}
  for i = 1, m0:nvertices() do mesh:set_coordinates(i, m0:coordinates(i)) end
  T.close(J(mesh, prob), J0, 1e-13, "moved back")
end

-- pure-traction elasticity with the rigid body modes as null space: the modes are the moved
-- nodes' rotations (the old ones left a rotation in the solution)
do
  local function elasticity(mesh)
    local V = lg.vector(lg.lagrange(1), 2)
    local u, v = lg.unknown(V, "ue"), lg.test(V, "ve")
    local eps = function(w) return lg.sym(lg.grad(w)) end
    -- the load of the displacement g: balanced on any mesh (a rigid motion has no strain)
    local w = u - {lg.sin(3*x)*y, lg.cos(2*y)*x}
    return lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), 2*lg.inner(eps(w), eps(v)) + lg.div(w)*lg.div(v)),
                             test = v, unknown = u, nullspace = "rigid"}
  end
  local mesh = lg.mesh.rectangle{nx = 12}
  local prob = elasticity(mesh)
  prob:solve()
  mesh:displace(function(x, y) return 0.3*y*y, 0.1*x end)
  local a = prob:solve()
  local b = elasticity(mesh):solve()
  local d = math.sqrt(lg.integrate(mesh, lg.dot(a - b, a - b)))
  local n = math.sqrt(lg.integrate(mesh, lg.dot(b, b)))
  print(string.format("rigid modes: |old - new| = %.3e of %.3e", d, n))
  T.check(d <= 1e-11 * n, "the old problem's solution differs from the new one's by %.3e (of %.3e)", d, n)
end

-- an assembled operator follows the mesh: its norm is the moved mesh's
do
  local mesh = lg.mesh.rectangle{nx = 8}
  local P1 = lg.lagrange(1)
  local u, v = lg.unknown(P1, "um"), lg.test(P1, "vm")
  local A = lg.assemble(lg.integral(mesh:cells(), u*v))
  local n0 = A:norm()
  mesh:displace(function(x, y) return x, y end) -- doubled: the mass matrix 4 times larger
  T.close(A:norm(), 4*n0, 1e-13, "the mass matrix's norm on the doubled mesh")
end

-- a sensitivity asked after the mesh moved, before a new solve, is refused (the state and its
-- Jacobian are the old mesh's)
do
  local mesh = lg.mesh.rectangle{nx = 8}
  local P1 = lg.lagrange(1)
  local u, v = lg.unknown(P1, "ua"), lg.test(P1, "va")
  local a = lg.parameter("a", 2)
  local state = lg.nonlinear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) + u^3*v - a*v),
                                     bc = lg.essential_bc(mesh:boundary(), v*u), test = v, unknown = u}
  state:solve()
  local s0 = state:sensitivity(a)
  T.check(s0:values()[41] > 0, "du/da at the centre: %g", s0:values()[41])
  mesh:displace(function(x, y) return 0.1*x*y, 0 end)
  T.fails(function() return state:sensitivity(a) end, "the mesh has moved since the problem's last solve")
  state:solve()
  T.check(state:sensitivity(a):values()[41] > 0, "du/da after a new solve")
end
print("moved meshes: re-solved problems follow them")
