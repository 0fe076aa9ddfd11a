-- bench/smooth_slide.lua — the energy smoother with sliding boundaries in 3D (issue 13): the
-- perturbed tetrahedral and hexahedral boxes of bench/perturbed.lua (interior vertices moved
-- by up to 20% / 15% of a cell in every direction, boundary vertices within their faces),
-- smooth{method = "energy"} with the default boundary = "slide": a pass with the boundary fixed,
-- then one with the boundary vertices sliding inside the optimizer (docs/mesh.md). Per case: rounds, iterations,
-- minimum and mean quality before and after, time.
-- Run: lugal bench/smooth_slide.lua [sizes...]   (cells per direction; default 16 24 32)
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local perturbed = require "perturbed"
local sizes = {}
for i = 1, #arg do sizes[#sizes + 1] = tonumber(arg[i]) end
if #sizes == 0 then sizes = {16, 24, 32} end
print("| case | vertices | rounds | iterations | min before | min after | mean after | s |")
print("|---|---|---|---|---|---|---|---|")
for _, cell in ipairs{"tetrahedron", "hexahedron"} do
  for _, n in ipairs(sizes) do
    local m = perturbed(cell, n)
    local r = m:smooth{method = "energy", quiet = true}
    print(string.format("| %s box %d | %d | %d | %d | %.4f | %.4f | %.4f | %.2f |", cell, n, m:nvertices(), r.sweeps,
                        r.iterations, r.min_before, r.min_after, r.mean_after, r.seconds))
    io.stdout:flush()
  end
end
