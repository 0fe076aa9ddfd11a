-- bench/smooth.lua — local against global smoothing (issue 4). Structured meshes whose
-- vertices are perturbed by up to 20% of a cell (15% for hexahedra) — interior vertices in
-- every direction, boundary vertices within their faces — then smoothed with the default
-- measure (mean ratio for simplices, corner condition for quadrilaterals and hexahedra) by
-- each method, boundary sliding. Per run: min and mean quality before and after, sum of 1/q
-- (the objective), sweeps or rounds, time.
-- Run: lugal bench/smooth.lua [n2d] [n3d]   (cells per direction; default 30 and 8)
local lg = require "lugal"
local n2, n3 = tonumber(arg[1]) or 30, tonumber(arg[2]) or 8

print("| mesh | method | min before | min after | mean before | mean after | sum 1/q after | sweeps/rounds | time s |")
print("|---|---|---|---|---|---|---|---|---|")
for _, cell in ipairs{"triangle", "quadrilateral", "tetrahedron", "hexahedron"} do
  for _, method in ipairs{"local", "global"} do
    local solid = cell:match("hedron")
    local n = solid and n3 or n2
    local m = solid and lg.mesh.box{nx = n, cell = cell} or lg.mesh.rectangle{nx = n, cell = cell}
    local seed = 7
    local function rand() seed = (seed * 1103515245 + 12345) % 2147483648; return seed / 2147483648 end
    local amp = (cell == "hexahedron" and 0.15 or 0.2) / n
    for i = 1, m:nvertices() do
      local p = {m:coordinates(i)}
      for k = 1, #p do if p[k] > 0 and p[k] < 1 then p[k] = p[k] + amp * (2 * rand() - 1) end end
      m:set_coordinates(i, table.unpack(p))
    end
    assert(m:check() == 0, "perturbed mesh must be valid")
    local r = m:smooth{method = method, iterations = 50, quiet = true}
    local q, inv = m:quality(r.measure), 0
    for c = 1, #q do inv = inv + 1 / q[c] end
    print(string.format("| %s %d cells | %s | %.4f | %.4f | %.4f | %.4f | %.6g | %d | %.3f |", cell, m:ncells(), method,
                        r.min_before, r.min_after, r.mean_before, r.mean_after, inv, r.sweeps, r.seconds))
    io.stdout:flush()
  end
end
