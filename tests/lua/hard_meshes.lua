-- hard_meshes.lua — generators of hard tangles with a known valid solution (issue 13), for
-- tests/lua/test_untangle_hard.lua and bench/untangle_hard.lua. Each returns the tangled
-- mesh and the valid mesh it came from (same connectivity and boundary).
local lg = require "lugal"
local M = {}

-- a strip of ns x nt squares (two triangles each, or quadrilaterals with cell =
-- "quadrilateral") along a spiral of `turns` turns, r = 0.3 + 1.2 s + width t; the interior
-- started from the Tutte embedding (each interior vertex the mean of its four grid
-- neighbours, `sweeps` Gauss-Seidel sweeps, 2000 by default), the boundary at its place
function M.spiral(ns, nt, width, turns, cell, sweeps)
  turns = turns or 1.5
  cell = cell or "triangle"
  local function pos(s, t)
    local th, r = 2*math.pi*turns*s, 0.3 + 1.2*s + width*t
    return r*math.cos(th), r*math.sin(th)
  end
  local verts, cells, bnd = {}, {}, {}
  local function id(i, j) return j*(ns + 1) + i + 1 end
  for j = 0, nt do for i = 0, ns do local a, b = pos(i/ns, j/nt); verts[#verts + 1] = {a, b} end end
  for j = 0, nt - 1 do for i = 0, ns - 1 do
    local a, b, c, d = id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)
    if cell == "quadrilateral" then cells[#cells + 1] = {a, d, c, b}
    else cells[#cells + 1] = {a, c, b}; cells[#cells + 1] = {a, d, c} end
  end end
  for i = 0, ns - 1 do bnd[#bnd + 1] = {id(i, 0), id(i + 1, 0)}; bnd[#bnd + 1] = {id(i, nt), id(i + 1, nt)} end
  for j = 0, nt - 1 do bnd[#bnd + 1] = {id(0, j), id(0, j + 1)}; bnd[#bnd + 1] = {id(ns, j), id(ns, j + 1)} end
  local mesh = lg.mesh.new{cell = cell, vertices = verts, cells = cells, boundary = {wall = bnd}}
  local ref = mesh:copy()
  -- the sweeps on two flat arrays: a table per vertex and update made the 400 x 60 strip's
  -- 2000 sweeps take 30 s
  local X, Y, w = {}, {}, ns + 1
  for k, v in ipairs(verts) do X[k], Y[k] = v[1], v[2] end
  for _ = 1, sweeps or 2000 do
    for j = 1, nt - 1 do
      local k = j*w + 1
      for _ = 1, ns - 1 do
        k = k + 1
        X[k] = (X[k - 1] + X[k + 1] + X[k - w] + X[k + w])/4
        Y[k] = (Y[k - 1] + Y[k + 1] + Y[k - w] + Y[k + w])/4
      end
    end
  end
  for j = 1, nt - 1 do for i = 1, ns - 1 do local k = id(i, j); mesh:set_coordinates(k, X[k], Y[k]) end end
  return mesh, ref
end

-- a star domain r(t) = 1 + 0.4 cos(5 t) (non-convex) meshed in nr rings of nt triangles
-- around its centre, every interior vertex then placed at random in [-1.4, 1.4]^2 (a
-- linear congruential generator from seed): half the cells inverted, some vertices
-- outside the domain
function M.star(nr, nt, seed)
  local verts, cells, bnd = {{0, 0}}, {}, {}
  local function r(t) return 1 + 0.4*math.cos(5*t) end
  local function id(i, j) return 1 + (i - 1)*nt + (j % nt) + 1 end
  for i = 1, nr do for j = 0, nt - 1 do
    local t, s = 2*math.pi*j/nt, i/nr
    verts[#verts + 1] = {s*r(t)*math.cos(t), s*r(t)*math.sin(t)}
  end end
  for j = 0, nt - 1 do cells[#cells + 1] = {1, id(1, j), id(1, j + 1)} end
  for i = 1, nr - 1 do for j = 0, nt - 1 do
    local a, b, c, d = id(i, j), id(i, j + 1), id(i + 1, j + 1), id(i + 1, j)
    cells[#cells + 1] = {a, d, c}; cells[#cells + 1] = {a, c, b}
  end end
  for j = 0, nt - 1 do bnd[#bnd + 1] = {id(nr, j), id(nr, j + 1)} end
  local mesh = lg.mesh.new{cell = "triangle", vertices = verts, cells = cells, boundary = {wall = bnd}}
  local ref = mesh:copy()
  local st = seed
  local function rnd() st = (st*1103515245 + 12345) % 2147483648; return st/2147483648 end
  for k = 1, #verts - nt do mesh:set_coordinates(k, 2.8*rnd() - 1.4, 2.8*rnd() - 1.4) end
  return mesh, ref
end

-- a bar of 3n x n x n cubes (6 tetrahedra each), length L, twisted by `turns` turns about
-- its axis: boundary vertices at their twisted places, interior vertices left straight
function M.twisted_bar(n, L, turns)
  local mesh = lg.mesh.box{nx = 3*n, ny = n, nz = n}
  local ref = mesh:copy()
  for k = 1, mesh:nvertices() do
    local x, y, z = mesh:coordinates(k)
    local th, cy, cz = 2*math.pi*(turns or 1)*x, y - 0.5, z - 0.5
    local X, Y, Z = L*x, 0.5 + cy*math.cos(th) - cz*math.sin(th), 0.5 + cy*math.sin(th) + cz*math.cos(th)
    ref:set_coordinates(k, X, Y, Z)
    if x == 0 or x == 1 or y == 0 or y == 1 or z == 0 or z == 1 then mesh:set_coordinates(k, X, Y, Z)
    else mesh:set_coordinates(k, L*x, y, z) end
  end
  return mesh, ref
end

-- M.spiral's strip with its Tutte embedding solved exactly (two discrete Laplace problems on
-- the strip's parameter grid, whose P1 stencil on unit squares is the four-neighbour mean)
-- instead of M.spiral's Gauss-Seidel sweeps in Lua, which would take minutes at a million
-- cells and not converge (bench/anchor_cases.lua's large cases)
function M.spiral_tutte(ns, nt, width, turns, cell)
  turns = turns or 1.5
  local _, rest = M.spiral(ns, nt, width, turns, cell or "triangle", 0)
  local grid = lg.mesh.rectangle{nx = ns, ny = nt, x1 = ns, y1 = nt}
  local s, t = lg.x/ns, lg.y/nt
  local th, r = 2*math.pi*turns*s, 0.3 + 1.2*s + width*t
  local P = lg.lagrange(1)
  local u, v = lg.unknown(P, "u"), lg.test(P, "v")
  local X = {}
  for c, g in ipairs{r*lg.cos(th), r*lg.sin(th)} do
    local prob = lg.linear_problem{mesh = grid, test = v, unknown = u,
      eqn = lg.integral(grid:cells(), lg.dot(lg.grad(v), lg.grad(u))),
      bc = lg.essential_bc(grid:boundary("left", "right", "bottom", "top"), v*(u - g))}
    X[c] = prob:solve():values()
  end
  local tangled = rest:copy()
  for k = 1, grid:nvertices() do
    local a, b = grid:coordinates(k)
    local i, j = math.floor(a + 0.5), math.floor(b + 0.5)
    if i > 0 and i < ns and j > 0 and j < nt then tangled:set_coordinates(j*(ns + 1) + i + 1, X[1][k], X[2][k]) end
  end
  return tangled, rest
end

return M
