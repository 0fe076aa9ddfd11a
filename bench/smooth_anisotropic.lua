-- bench/smooth_anisotropic.lua [NS NT] — the energy smoother on anisotropic strips (issue 13):
-- A.spiral_tutte(NS, NT, 0.75) (an NS × NT grid harmonically mapped onto a 1.5-turn spiral
-- strip, rest cells about NT/NS · 14 : 1, a fifth or more of the triangles inverted),
-- untangled with the boundary fixed (its Tutte-disk run repairs it), then smoothed by
-- method = "energy" (projected Newton in 2D). Prints both times, the Newton steps and rounds,
-- the minimum and mean mean ratio before and after smoothing, and the rest strip's own
-- minimum. Default 80 250 (40 000 triangles).
-- Run: lugal bench/smooth_anisotropic.lua [NS NT]
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local A = require "anchor_cases"
local lg = require "lugal"
local ns, nt = tonumber(arg[1] or 80), tonumber(arg[2] or 250)
local m, rest = A.spiral_tutte(ns, nt, 0.75)
local t0 = lg.wtime()
local u = m:untangle{quiet = true, boundary = "fixed"}
local tu = lg.wtime() - t0
assert(u.success, "the strip was not untangled")
t0 = lg.wtime()
local s = m:smooth{method = "energy", boundary = "fixed", quiet = true}
local ts = lg.wtime() - t0
print("| strip | triangles | untangle s | smooth s | Newton steps | rounds | min q before | min q after | mean q after | rest strip's min q |")
print("|---|---|---|---|---|---|---|---|---|---|")
print(string.format("| %d × %d | %d | %.1f | %.2f | %d | %d | %.4f | %.4f | %.4f | %.4f |", ns, nt, m:ncells(), tu, ts,
                    s.iterations, s.sweeps, s.min_before, s.min_after, s.mean_after, rest:quality("mean_ratio"):min()))
