-- bench/placement.lua — where to put a vertex inside its feasible set (issue 4, stage 1):
-- the Chebyshev centre (lugal's default) against the paper's mean of LP corners, on the
-- same tangles. Per case: cells stage 1 leaves invalid, cells below beta after stage 1,
-- total time, minimum shape quality after the whole untangling.
-- Run: lugal bench/placement.lua
local lg = require "lugal"
print("| case | placement | invalid after stage 1 | below beta after stage 1 | ok | time s | min quality |")
print("|---|---|---|---|---|---|---|")
for _, cell in ipairs{"triangle", "quadrilateral", "tetrahedron"} do
  for _, n in ipairs(cell == "tetrahedron" and {9, 21} or {31, 99}) do
    for _, placement in ipairs{"chebyshev", "corners"} do
      local seed = 777
      local function rand() seed = (seed * 1103515245 + 12345) % 2147483648; return seed / 2147483648 end
      local m = cell == "tetrahedron" and lg.mesh.box{nx = n, cell = cell} or lg.mesh.rectangle{nx = n, cell = cell}
      local d = m:dim()
      for i = 1, m:nvertices() do
        local p = {m:coordinates(i)}
        local inside = true
        for k = 1, d do inside = inside and p[k] > 0 and p[k] < 1 end
        if inside and rand() < 0.05 then
          for k = 1, d do p[k] = p[k] + 0.2 * (2 * rand() - 1) end
          m:set_coordinates(i, table.unpack(p))
        end
      end
      local r = m:untangle{placement = placement, quiet = true}
      local q = m:quality(cell == "quadrilateral" and "corner_condition" or "mean_ratio")
      print(string.format("| %s %d vertices | %s | %d | %d | %s | %.3f | %.3g |", cell, m:nvertices(), placement,
                          r.stages[1].invalid_after, r.stages[1].below_beta, r.success and "yes" or "NO", r.seconds, q:min()))
    end
  end
end
