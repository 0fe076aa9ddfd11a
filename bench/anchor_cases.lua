-- bench/anchor_cases.lua — what the comparisons with other untanglers share
-- (untangle_anchor2d.lua, untangle_anchor3d.lua, untangle_tlc.lua): the hard tangles of
-- bench/untangle_hard.lua in 2D (Tutte-started spiral strips, random interiors of star
-- domains) and 3D (twisted tetrahedral bars), and the simplices of a mesh as vertex lists.
package.path = arg[0]:match("(.*/)") .. "../tests/lua/?.lua;" .. package.path
local H = require "hard_meshes"
local lg = require "lugal"
local A = {}

A.cases2d = {
  {"spiral 30x10", function() return H.spiral(30, 10, 0.7) end},
  {"spiral 40x16", function() return H.spiral(40, 16, 0.75) end},
  {"spiral 100x20", function() return H.spiral(100, 20, 0.7) end},
  {"spiral 200x30", function() return H.spiral(200, 30, 0.75) end},
  {"star 12x60, random interior", function() return H.star(12, 60, 7) end},
  {"star 20x100, random interior", function() return H.star(20, 100, 3) end},
  {"star 40x200, random interior", function() return H.star(40, 200, 5) end},
}

-- larger ones (bench/untangle_anchor2d.lua ... large): how the ratios scale
A.cases2d_large = {
  {"spiral 400x60", function() return H.spiral(400, 60, 0.75) end},
  {"star 80x400, random interior", function() return H.star(80, 400, 5) end},
}

-- about a million cells (bench/untangle_anchor2d.lua ... 1m, untangle_anchor3d.lua ... 1m):
-- the size at which issue 13 states its speed target. The spiral's Tutte embedding is solved
-- exactly (hard_meshes.lua's spiral_tutte)
A.spiral_tutte = H.spiral_tutte

A.cases2d_1m = {
  {"spiral 2000x250 (Tutte solved)", function() return A.spiral_tutte(2000, 250, 0.75) end},
}

-- about 100 000 vertices (bench/untangle_anchor2d.lua ... 100k): issue 13's "every 100k-vertex
-- case under 2 s". The strip of 640 x 160 cells is more anisotropic than the million-cell
-- one (cells about 3:1 against 1.7:1): 29% of its cells are inverted, where the million's 3%
A.cases2d_100k = {
  {"spiral 640x160 (Tutte solved)", function() return A.spiral_tutte(640, 160, 0.75) end},
}

A.cases3d_1m = {
  {"bar 40, 1 turn", function() return H.twisted_bar(40, 6, 1) end},
}

A.cases3d = {
  {"bar 4, 1 turn", function() return H.twisted_bar(4, 6, 1) end},
  {"bar 6, 1 turn", function() return H.twisted_bar(6, 6, 1) end},
  {"bar 8, 1 turn", function() return H.twisted_bar(8, 6, 1) end},
  {"bar 12, 1 turn", function() return H.twisted_bar(12, 6, 1) end},
  {"bar 6, 1.5 turns", function() return H.twisted_bar(6, 6, 1.5) end},
  {"bar 16, 1 turn", function() return H.twisted_bar(16, 6, 1) end},
}

-- the simplices of a mesh, 1-based vertex lists, from its Gmsh file written to path
-- (mesh:write writes MSH 2.2: element type 2 triangles, 4 tetrahedra, then the tag count,
-- the tags and the vertices)
function A.simplices(mesh, path)
  mesh:write(path)
  local cells, f = {}, assert(io.open(path))
  local inside, want, nv = false, mesh:dim() == 2 and 2 or 4, mesh:dim() + 1
  for line in f:lines() do
    if line == "$Elements" then inside = true
    elseif line == "$EndElements" then inside = false
    elseif inside then
      local w = {}
      for t in line:gmatch("%S+") do w[#w + 1] = tonumber(t) end
      if #w > 2 and w[2] == want then
        local k, c = 3 + w[3], {}
        for j = 1, nv do c[j] = w[k + j] end
        cells[#cells + 1] = c
      end
    end
  end
  f:close()
  return cells
end

return A
