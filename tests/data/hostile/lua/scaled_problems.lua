-- expect-ok: well-posed problems at extreme scales. k = f = 1e200 (and 1e300) in a Poisson
-- problem gives the answer of k = f = 1 (the essential rows' 1 beside a diagonal of 1e200
-- was taken for a null pivot: "the matrix is singular"); a mesh whose cells' measure leaves
-- the range of doubles is refused up front, saying so (a 2D mesh at 1e-155 gave NaN
-- matrices, a 3D one at 1e-110 was called inverted); a mesh at 1e-100 solves
local lg = require "lugal"
local function solve(s, L, dim)
  local mesh = dim == 3 and lg.mesh.box{nx = 4, x1 = L, y1 = L, z1 = L} or lg.mesh.rectangle{nx = 8, x1 = L, y1 = L}
  local P1 = lg.lagrange(1)
  local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
  local prob = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), s*lg.dot(lg.grad(v), lg.grad(u)) - s*v),
                                 bc = lg.essential_bc(mesh:boundary(), v*u), test = v, unknown = u}
  local uh = prob:solve()
  return math.max(table.unpack(uh:values())) / L^2
end
local ref = solve(1, 1)
for _, s in ipairs{1e200, 1e300, 1e-200} do
  local m = solve(s, 1)
  assert(math.abs(m - ref) <= 1e-13 * ref, string.format("k = f = %g: max u %.17g, expected %.17g", s, m, ref))
end
local m = solve(1, 1e-100)
assert(math.abs(m - ref) <= 1e-12 * ref, string.format("a mesh at 1e-100: %.17g, expected %.17g", m, ref))
for _, c in ipairs{{1e-155, 2}, {1e150, 2}, {1e-110, 3}} do
  local ok, err = pcall(solve, 1, c[1], c[2])
  assert(not ok and err:find("the mesh's cells are about", 1, true) and err:find("leaves the range of doubles", 1, true), err)
end
print("scaled problems: solved, or refused saying why")
