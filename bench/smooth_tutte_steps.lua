-- bench/smooth_tutte_steps.lua [NSxNT ...] — the energy smoother's Newton steps on Tutte-solved
-- spiral strips (issue 13): hard_meshes.lua's spiral_tutte(NS, NT, 0.75) (an NS × NT grid
-- whose Tutte embedding on a 1.5-turn spiral strip is solved exactly; 3% of the triangles of
-- the 8:1 strips inverted), untangled with the boundary fixed, then smoothed by the energy
-- method with the defaults. Per strip: triangles, the untangled minimum mean ratio, Newton
-- steps, the smoothing's seconds, and the minimum and mean after. Default sizes 200x25 400x50
-- 600x75 800x100 (10 000 to 160 000 triangles); 2000x250 is the million-triangle spiral.
-- Run: lugal bench/smooth_tutte_steps.lua [NSxNT ...]
package.path = arg[0]:match("(.*/)") .. "../tests/lua/?.lua;" .. package.path
local H = require "hard_meshes"
local lg = require "lugal"
local sizes = {}
for i = 1, #arg do
  local a, b = arg[i]:match("^(%d+)x(%d+)$")
  assert(a, "bench/smooth_tutte_steps.lua: a size NSxNT expected, got " .. arg[i])
  sizes[#sizes + 1] = {tonumber(a), tonumber(b)}
end
if #sizes == 0 then sizes = {{200, 25}, {400, 50}, {600, 75}, {800, 100}} end
print("| strip | triangles | untangled min q | Newton steps | smoothing s | min q | mean q |")
print("|---|---|---|---|---|---|---|")
for _, sz in ipairs(sizes) do
  local m = H.spiral_tutte(sz[1], sz[2], 0.75)
  local r = m:untangle{quiet = true, boundary = "fixed"}
  local q0 = m:quality("mean_ratio"):min()
  local t0 = lg.wtime()
  local s = r.success and m:smooth{quiet = true, method = "energy", boundary = "fixed"}
  local ts = lg.wtime() - t0
  local q = m:quality("mean_ratio")
  print(string.format("| %d x %d | %d | %.4f | %s | %.3f | %.4f | %.4f |", sz[1], sz[2], m:ncells(), q0,
                      s and tostring(s.iterations) or "not untangled", ts, q:min(), q:mean()))
end
