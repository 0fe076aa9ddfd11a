-- bench/perturbed.lua — the perturbed structured meshes of bench/smooth.lua and
-- bench/smooth_optimizers.lua: a unit square or cube in n cells per direction whose vertices
-- move by up to 20% of a cell (15% for hexahedra), interior vertices in every direction and
-- boundary vertices within their faces, by a fixed linear congruential sequence (seed 7)
local lg = require "lugal"
return function(cell, n)
  local solid = cell:match("hedron")
  local m = solid and lg.mesh.box{nx = n, cell = cell} or lg.mesh.rectangle{nx = n, cell = cell}
  local seed = 7
  local function rand() seed = (seed * 1103515245 + 12345) % 2147483648; return seed / 2147483648 end
  local amp = (cell == "hexahedron" and 0.15 or 0.2) / n
  for i = 1, m:nvertices() do
    local p = {m:coordinates(i)}
    for k = 1, #p do if p[k] > 0 and p[k] < 1 then p[k] = p[k] + amp * (2 * rand() - 1) end end
    m:set_coordinates(i, table.unpack(p))
  end
  return m
end
