-- bench/smooth_optimizers.lua — the energy smoother's two optimizers in 3D (issue 13):
-- projected Newton against L-BFGS on perturbed tetrahedral and hexahedral boxes (interior
-- vertices moved by up to 20% / 15% of a cell) and on untangled twisted tetrahedral bars,
-- boundary fixed. Per run: time, minimum and mean quality (mean ratio; corner condition on
-- hexahedra). Auto picks L-BFGS in 3D.
-- Run: lugal bench/smooth_optimizers.lua
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. arg[0]:match("(.*/)") .. "../tests/lua/?.lua;" .. package.path
local perturbed = require "perturbed"
local H = require "hard_meshes"
local lg = require "lugal"
local cases = {}
local function box(cell, n) return function() return perturbed(cell, n) end end
for _, n in ipairs{8, 16, 32} do
  cases[#cases + 1] = {"tet box " .. n, box("tetrahedron", n), "fixed"}
  cases[#cases + 1] = {"hex box " .. n, box("hexahedron", n), "fixed"}
end
for _, n in ipairs{8, 16, 24, 32} do
  cases[#cases + 1] = {"bar " .. n, function()
    local t = H.twisted_bar(n, 6, 1)
    t:untangle{quiet = true, boundary = "fixed"}
    return t
  end, "fixed"}
end
print("| case | cells | optimizer | s | min | mean |")
for _, c in ipairs(cases) do
  local m0 = c[2]()
  for _, opt in ipairs{"lbfgs", "newton"} do
    local m = m0:copy()
    local t0 = lg.wtime()
    local r = m:smooth{method = "energy", iterations = 50, boundary = c[3], optimizer = opt, quiet = true}
    local t = lg.wtime() - t0
    print(string.format("| %s | %d | %s | %.3f | %.4f | %.4f |", c[1], m:ncells(), opt, t, r.min_after, r.mean_after))
  end
end
