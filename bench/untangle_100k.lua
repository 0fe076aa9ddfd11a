-- bench/untangle_100k.lua — issue 13's "every 100 000-vertex case under 2 s": the hard
-- tangle classes at about 100 000 vertices, untangled and then smoothed by the energy method
-- with the defaults and the boundary fixed, in this process (mesh generation and file
-- input not counted). Per case: inverted cells, the untangle's and the smoothing's seconds,
-- their sum, and the mean ratio (corner condition on quadrilaterals) after both.
-- Run: lugal bench/untangle_100k.lua [bar]   ("bar": also the twisted bar of 589 824
--      tetrahedra, 105 633 vertices, which takes about 15 s)
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. arg[0]:match("(.*/)") .. "../tests/lua/?.lua;" .. package.path
local A = require "anchor_cases"
local H = require "hard_meshes"
local lg = require "lugal"

local cases = {
  {"Tutte spiral 640x160, triangles", function() return A.spiral_tutte(640, 160, 0.75) end},
  {"Tutte spiral 640x160, quadrilaterals", function() return A.spiral_tutte(640, 160, 0.75, nil, "quadrilateral") end},
  {"star 160x640, random interior", function() return H.star(160, 640, 5) end},
}
if arg[1] == "bar" then cases[#cases + 1] = {"twisted bar 32, 1 turn", function() return H.twisted_bar(32, 6, 1) end} end

print("| case | vertices | cells | inverted | untangle s | smoothing s | total s | min q | mean q |")
print("|---|---|---|---|---|---|---|---|---|")
for _, c in ipairs(cases) do
  local m = c[2]()
  local inv = m:check()
  local t0 = lg.wtime()
  local r = m:untangle{quiet = true, boundary = "fixed"}
  local t1 = lg.wtime()
  if r.success then m:smooth{quiet = true, method = "energy", iterations = 50, boundary = "fixed"} end
  local t2 = lg.wtime()
  local q = m:quality(m:info().cell == "quadrilateral" and "corner_condition" or "mean_ratio")
  print(string.format("| %s | %d | %d | %d | %.2f | %.2f | %.2f | %.4f | %.4f |", c[1], m:nvertices(), m:ncells(), inv,
                      t1 - t0, t2 - t1, t2 - t0, r.success and q:min() or 0, q:mean()))
end
