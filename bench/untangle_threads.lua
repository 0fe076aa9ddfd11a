-- bench/untangle_threads.lua [N] [cell] — the global energy stages on OpenMP threads (issue
-- 13): energy smoothing of an N x N perturbed square (2 N² triangles, or N² quadrilaterals)
-- and the untangling of a Tutte-started 100x20 spiral (its global stage), with the time and
-- a digest of the coordinates, which must not depend on the thread count. Run:
--   for t in 1 2; do OMP_NUM_THREADS=$t ./lugal bench/untangle_threads.lua 300; done
package.path = arg[0]:match("(.*/)") .. "../tests/lua/?.lua;" .. package.path
local lg = require "lugal"
local H = require "hard_meshes"
local N = tonumber(arg[1]) or 300
local cell = arg[2] or "triangle"
local m = lg.mesh.rectangle{nx = N, cell = cell}
math.randomseed(3)
for k = 1, m:nvertices() do
  local x, y = m:coordinates(k)
  if x > 1e-9 and x < 1-1e-9 and y > 1e-9 and y < 1-1e-9 then m:set_coordinates(k, x + 0.3/N*(math.random()-0.5), y + 0.3/N*(math.random()-0.5)) end
end
local s = m:smooth{quiet = true, method = "energy", iterations = 5}
local h = 0
for k = 1, m:nvertices(), 7 do local x, y = m:coordinates(k); h = h + x*1.1 + y*0.7 end
print(string.format("%s %d: smooth energy %.3f s (report), min %.6f -> %.17g, hash %.17g", cell, m:ncells(), s.seconds, s.min_before, s.min_after, h))
local sp = H.spiral(100, 20, 0.7)
local r = sp:untangle{quiet = true}
local h2 = 0
for k = 1, sp:nvertices() do local x, y = sp:coordinates(k); h2 = h2 + x*1.1 + y*0.7 end
print(string.format("spiral: %s %.3f s, hash %.17g", tostring(r.success), r.seconds, h2))
