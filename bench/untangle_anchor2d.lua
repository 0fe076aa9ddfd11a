-- bench/untangle_anchor2d.lua ANCHOR [DIR] — the 2D hard tangles of bench/untangle_hard.lua
-- (Tutte-started spiral strips, random interiors of star domains) with the boundary fixed,
-- untangled by lugal (untangle, then smooth{method = "energy"}) and by another untangler
-- that reads an OBJ whose v lines are the valid (rest) mesh and vt lines the tangled one and
-- writes the result's v lines: ssloy/invertible-maps's untangle2d (foldover-free maps,
-- Garanzha et al. 2021), built beside lugal, never part of it. DIR holds the files (a
-- temporary folder by default). Per case: inverted cells, then for each untangler success,
-- time, and the minimum and mean mean ratio of the result, and the rest mesh's own.
-- Run: lugal bench/untangle_anchor2d.lua /path/to/untangle2d [dir] [large|100k|1m]   ("large": a 48 000-cell spiral and a 63 600-cell star;
--      "100k": a 204 800-triangle spiral (103 000 vertices); "1m": a 1 000 000-triangle spiral)
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local A = require "anchor_cases"
local lg = require "lugal"
local anchor = assert(arg[1], "usage: lugal bench/untangle_anchor2d.lua /path/to/untangle2d [dir]")
local dir = arg[2] or os.tmpname() .. ".d"
local cases = arg[3] == "large" and A.cases2d_large or arg[3] == "1m" and A.cases2d_1m or arg[3] == "100k" and A.cases2d_100k
              or A.cases2d
os.execute("mkdir -p '" .. dir .. "'")

local function write_obj(path, tangled, rest, tris)
  local f = assert(io.open(path, "w"))
  for i = 1, rest:nvertices() do local x, y = rest:coordinates(i); f:write(string.format("v %.17g %.17g 0\n", x, y)) end
  for i = 1, tangled:nvertices() do local x, y = tangled:coordinates(i); f:write(string.format("vt %.17g %.17g\n", x, y)) end
  for _, t in ipairs(tris) do
    f:write(string.format("f %d/%d %d/%d %d/%d\n", t[1], t[1], t[2], t[2], t[3], t[3]))
  end
  f:close()
end

local function read_result(path, mesh)
  local f = io.open(path)
  if not f then return false end
  local i = 0
  local finite = true
  for line in f:lines() do
    local x, y = line:match("^v%s+(%S+)%s+(%S+)")
    if x then
      i = i + 1
      x, y = tonumber(x), tonumber(y) -- nil for "nan" or "-nan"
      if x and y then mesh:set_coordinates(i, x, y) else finite = false end
    end
  end
  f:close()
  return i == mesh:nvertices() and finite
end

print("| case | cells | inverted | lugal | s | min q | mean q | anchor | s | min q | mean q | rest mesh min q |")
print("|---|---|---|---|---|---|---|---|---|---|---|---|")
for k, c in ipairs(cases) do
  local tangled, rest = c[2]()
  local inv = tangled:check()
  -- lugal: untangle with the boundary fixed, then the energy smoother
  local m = tangled:copy()
  local t0 = lg.wtime()
  local r = m:untangle{quiet = true, boundary = "fixed"}
  if r.success then m:smooth{quiet = true, method = "energy", iterations = 50, boundary = "fixed"} end
  local tl = lg.wtime() - t0
  local ql = m:quality("mean_ratio")
  -- the anchor
  local input, output = string.format("%s/case%d.obj", dir, k), string.format("%s/case%d-result.obj", dir, k)
  write_obj(input, tangled, rest, A.simplices(rest, string.format("%s/case%d.msh", dir, k)))
  os.remove(output)
  local a = tangled:copy()
  t0 = lg.wtime()
  os.execute(string.format("'%s' '%s' '%s' > '%s/case%d.log' 2>&1", anchor, input, output, dir, k))
  local ta = lg.wtime() - t0
  local ok = read_result(output, a)
  local ainv = ok and a:check() or -1
  local qa = ok and a:quality("mean_ratio")
  print(string.format("| %s | %d | %d | %s | %.3f | %.4f | %.4f | %s | %.3f | %s | %s | %.4f |", c[1], tangled:ncells(), inv,
                      r.success and "yes" or "no", tl, ql:min(), ql:mean(),
                      ok and (ainv == 0 and "yes" or (ainv .. " inverted")) or "no finite result", ta,
                      ok and string.format("%.4f", qa:min()) or "—", ok and string.format("%.4f", qa:mean()) or "—",
                      rest:quality("mean_ratio"):min()))
end
