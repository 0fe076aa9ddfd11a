-- bench/smooth.lua — local against global smoothing (issue 4). Structured meshes whose
-- vertices are perturbed by up to 20% of a cell (15% for hexahedra) — interior vertices in
-- every direction, boundary vertices within their faces — then smoothed with the default
-- measure (mean ratio for simplices, corner condition for quadrilaterals and hexahedra) by
-- each method, boundary sliding. Per run: min and mean quality before and after, sum of 1/q
-- (the objective), sweeps or rounds, time.
-- Run: lugal bench/smooth.lua [n2d] [n3d]   (cells per direction; default 30 and 8)
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local perturbed = require "perturbed"
local n2, n3 = tonumber(arg[1]) or 30, tonumber(arg[2]) or 8

print("| mesh | method | min before | min after | mean before | mean after | sum 1/q after | sweeps/rounds | time s |")
print("|---|---|---|---|---|---|---|---|---|")
for _, cell in ipairs{"triangle", "quadrilateral", "tetrahedron", "hexahedron"} do
  for _, method in ipairs{"local", "global"} do
    local m = perturbed(cell, cell:match("hedron") and n3 or n2)
    assert(m:check() == 0, "perturbed mesh must be valid")
    local r = m:smooth{method = method, iterations = 50, quiet = true}
    local q, inv = m:quality(r.measure), 0
    for c = 1, #q do inv = inv + 1 / q[c] end
    print(string.format("| %s %d cells | %s | %.4f | %.4f | %.4f | %.4f | %.6g | %d | %.3f |", cell, m:ncells(), method,
                        r.min_before, r.min_after, r.mean_before, r.mean_after, inv, r.sweeps, r.seconds))
    io.stdout:flush()
  end
end
