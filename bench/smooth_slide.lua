-- bench/smooth_slide.lua — the energy smoother with sliding boundaries (issue 13):
-- smooth{method = "energy"} with the default boundary = "slide", which after one round with
-- the boundary fixed runs a pass where the boundary vertices slide inside the optimizer and
-- one where they take guarded local steps between rounds, and keeps the higher minimum
-- (docs/mesh.md). Cases: the perturbed tetrahedral and hexahedral boxes and the perturbed
-- 256² triangle and quadrilateral grids of bench/perturbed.lua (interior vertices moved by up
-- to 20% / 15% of a cell in every direction, boundary vertices within their faces), and the
-- Tutte-started spiral strips of tests/lua/hard_meshes.lua after a default (sliding)
-- untangle. Per case: the pass kept, rounds, iterations, minimum and mean quality before
-- and after, time.
-- Run: lugal bench/smooth_slide.lua [sliding=best|optimizer|local] [sizes...]
--      (the smoother's sliding option, default best; box cells per direction, default 16 24 32)
local dir = arg[0]:match("(.*/)") or "./"
package.path = dir .. "?.lua;" .. dir .. "../tests/lua/?.lua;" .. package.path
local perturbed = require "perturbed"
local H = require "hard_meshes"
local sizes, sliding = {}, nil
for i = 1, #arg do
  local v = arg[i]:match("^sliding=(%a+)$")
  if v then sliding = v else sizes[#sizes + 1] = assert(tonumber(arg[i]), "a size or sliding=...: " .. arg[i]) end
end
if #sizes == 0 then sizes = {16, 24, 32} end
local cases = {}
for _, cell in ipairs{"tetrahedron", "hexahedron"} do
  for _, n in ipairs(sizes) do
    cases[#cases + 1] = {string.format("%s box %d", cell, n), function() return perturbed(cell, n) end}
  end
end
for _, cell in ipairs{"triangle", "quadrilateral"} do
  cases[#cases + 1] = {cell .. " grid 256", function() return perturbed(cell, 256) end}
end
for _, s in ipairs{{30, 10, 0.7}, {40, 16, 0.75}, {100, 20, 0.7}, {200, 30, 0.75}, {400, 60, 0.75}} do
  for _, cell in ipairs{"triangle", "quadrilateral"} do
    if cell == "triangle" or s[1] ~= 100 and s[1] ~= 400 then
      cases[#cases + 1] = {string.format("%s spiral %dx%d", cell, s[1], s[2]), function()
        local m = H.spiral(s[1], s[2], s[3], 1.5, cell)
        assert(m:untangle{quiet = true}.success)
        return m
      end}
    end
  end
end
print("| case | vertices | pass kept | rounds | iterations | min before | min after | mean after | s |")
print("|---|---|---|---|---|---|---|---|---|")
for _, c in ipairs(cases) do
  local m = c[2]()
  local r = m:smooth{method = "energy", quiet = true, sliding = sliding}
  print(string.format("| %s | %d | %s | %d | %d | %.4f | %.4f | %.4f | %.2f |", c[1], m:nvertices(), r.sliding or "—",
                      r.sweeps, r.iterations, r.min_before, r.min_after, r.mean_after, r.seconds))
  io.stdout:flush()
end
