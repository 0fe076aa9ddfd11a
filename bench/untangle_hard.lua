-- bench/untangle_hard.lua — hard tangles with a known valid solution (issue 13): spiral
-- strips of 1.5 turns (triangles, quadrilaterals) started from their Tutte embedding and tetrahedral bars twisted by
-- one turn with straight interiors (tests/lua/hard_meshes.lua). Per case: the inverted
-- cells, whether the default untangle repairs them and in what time, the minimum mean ratio
-- (corner condition on quadrilaterals) after untangling and after smoothing by each method
-- (local, global, energy; time of the energy method), and the valid mesh's own minimum.
-- Run: lugal bench/untangle_hard.lua
package.path = arg[0]:match("(.*/)") .. "../tests/lua/?.lua;" .. package.path
local H = require "hard_meshes"

local cases = {
  {"spiral 30x10", function() return H.spiral(30, 10, 0.7) end, "slide"},
  {"spiral 40x16", function() return H.spiral(40, 16, 0.75) end, "slide"},
  {"spiral 100x20", function() return H.spiral(100, 20, 0.7) end, "slide"},
  {"spiral 200x30", function() return H.spiral(200, 30, 0.75) end, "slide"},
  {"spiral 400x60", function() return H.spiral(400, 60, 0.75) end, "slide"},
  {"quad spiral 30x10", function() return H.spiral(30, 10, 0.7, 1.5, "quadrilateral") end, "slide"},
  {"quad spiral 40x16", function() return H.spiral(40, 16, 0.75, 1.5, "quadrilateral") end, "slide"},
  {"quad spiral 200x30", function() return H.spiral(200, 30, 0.75, 1.5, "quadrilateral") end, "slide"},
  {"star 12x60, random interior", function() return H.star(12, 60, 7) end, "fixed"},
  {"star 20x100, random interior", function() return H.star(20, 100, 3) end, "fixed"},
  {"star 40x200, random interior", function() return H.star(40, 200, 5) end, "fixed"},
  {"twisted bar 4", function() return H.twisted_bar(4, 6, 1) end, "fixed"},
  {"twisted bar 6", function() return H.twisted_bar(6, 6, 1) end, "fixed"},
  {"twisted bar 8", function() return H.twisted_bar(8, 6, 1) end, "fixed"},
}
print("| case | cells | inverted | untangled | untangle s | min q after untangle | local | global | energy | energy s | valid mesh's |")
print("|---|---|---|---|---|---|---|---|---|---|---|")
for _, c in ipairs(cases) do
  local mesh, ref = c[2]()
  local r = mesh:untangle{quiet = true, boundary = c[3]}
  local row = {c[1], mesh:ncells(), r.invalid_before, r.success and "yes" or ("no (" .. r.invalid_after .. " left)"),
               string.format("%.3f", r.seconds)}
  local qm = c[1]:match("^quad") and "corner_condition" or "mean_ratio"
  if r.success then
    row[#row + 1] = string.format("%.4f", mesh:quality(qm):min())
    local es
    for _, method in ipairs{"local", "global", "energy"} do
      local m = mesh:copy()
      local s = m:smooth{quiet = true, method = method, iterations = 50, boundary = c[3]}
      row[#row + 1] = string.format("%.4f", s.min_after)
      if method == "energy" then es = s.seconds end
    end
    row[#row + 1] = string.format("%.3f", es)
  else
    for _ = 1, 5 do row[#row + 1] = "—" end
  end
  row[#row + 1] = string.format("%.4f", ref:quality(qm):min())
  print("| " .. table.concat(row, " | ") .. " |")
end
