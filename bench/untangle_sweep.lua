-- bench/untangle_sweep.lua [FILTER] — the hard tangles of tests/lua/hard_meshes.lua in many
-- sizes and shapes (issue 13), each untangled with its boundary ("slide" or "fixed") and then
-- smoothed by the energy method with the defaults: sliding and fixed spirals of 1.5 turns
-- (triangles, quadrilaterals), random interiors of star domains (five seeds and sizes),
-- tetrahedral bars twisted by one turn, and Tutte-solved spiral strips of several sizes and
-- widths (triangles, quadrilaterals). Per case: inverted cells, success, untangle seconds, the
-- minimum quality after untangling, Newton steps (or L-BFGS iterations) of the smoothing, its
-- seconds, and the minimum and mean quality after (mean ratio; corner condition on
-- quadrilaterals). The check that a change to the untangler or smoother keeps the results
-- (compare two builds' outputs with the times stripped) or says where it moves them.
-- FILTER: only the cases whose name contains it.
-- Run: lugal bench/untangle_sweep.lua [FILTER]
package.path = arg[0]:match("(.*/)") .. "../tests/lua/?.lua;" .. package.path
local H = require "hard_meshes"
local lg = require "lugal"
local cases = {}
local function add(name, f, bnd) cases[#cases + 1] = {name, f, bnd} end
for _, s in ipairs{{30, 10, 0.7}, {40, 16, 0.75}, {100, 20, 0.7}, {200, 30, 0.75}, {400, 60, 0.75}} do
  add(string.format("spiral %dx%d", s[1], s[2]), function() return H.spiral(s[1], s[2], s[3]) end, "slide")
  add(string.format("spiral %dx%d fixed", s[1], s[2]), function() return H.spiral(s[1], s[2], s[3]) end, "fixed")
end
for _, s in ipairs{{30, 10, 0.7}, {40, 16, 0.75}, {200, 30, 0.75}} do
  add(string.format("qspiral %dx%d", s[1], s[2]), function() return H.spiral(s[1], s[2], s[3], 1.5, "quadrilateral") end,
      "slide")
end
for _, s in ipairs{{12, 60, 7}, {20, 100, 3}, {40, 200, 5}, {30, 150, 11}, {60, 300, 2}} do
  add(string.format("star %dx%d s%d", s[1], s[2], s[3]), function() return H.star(s[1], s[2], s[3]) end, "fixed")
end
for _, n in ipairs{4, 6, 8, 12} do add("bar " .. n, function() return H.twisted_bar(n, 6, 1) end, "fixed") end
for _, s in ipairs{{100, 12, 0.75}, {200, 25, 0.75}, {300, 40, 0.75}, {400, 50, 0.75}, {160, 40, 0.75}, {320, 80, 0.75},
                   {640, 160, 0.75}, {200, 25, 0.5}, {400, 50, 0.9}, {600, 75, 0.75}} do
  add(string.format("tutte %dx%d w%.2f", s[1], s[2], s[3]), function() return H.spiral_tutte(s[1], s[2], s[3]) end, "fixed")
end
for _, s in ipairs{{100, 12, 0.75}, {200, 25, 0.75}, {320, 80, 0.75}} do
  add(string.format("qtutte %dx%d", s[1], s[2]), function() return H.spiral_tutte(s[1], s[2], s[3], nil, "quadrilateral") end,
      "fixed")
end
local only = arg[1]
local tu_all, ts_all = 0, 0
print("| case | inverted | untangled | untangle s | min q after untangle | steps | smoothing s | min q | mean q |")
print("|---|---|---|---|---|---|---|---|---|")
for _, c in ipairs(cases) do
  if not only or c[1]:find(only, 1, true) then
    local m = c[2]()
    local inv = m:check()
    local meas = m:info().cell == "quadrilateral" and "corner_condition" or "mean_ratio"
    local t0 = lg.wtime()
    local r = m:untangle{quiet = true, boundary = c[3]}
    local tu = lg.wtime() - t0
    local q0 = r.success and m:quality(meas):min() or 0
    t0 = lg.wtime()
    local s = r.success and m:smooth{quiet = true, method = "energy", boundary = c[3]}
    local ts = lg.wtime() - t0
    local q = m:quality(meas)
    tu_all, ts_all = tu_all + tu, ts_all + ts
    print(string.format("| %s | %d | %s | %.3f | %.4f | %s | %.3f | %.4f | %.4f |", c[1], inv, r.success and "yes" or "no", tu, q0,
                        s and tostring(s.iterations) or "-", ts, q:min(), q:mean()))
  end
end
print(string.format("total: untangle %.2f s, smoothing %.2f s", tu_all, ts_all))
