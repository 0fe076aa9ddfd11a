-- bench/untangle_bars.lua [n ...] — twisted tetrahedral bars (n × n × 3n cubes × 6
-- tetrahedra, one turn, tests/lua/hard_meshes.lua) untangled with the boundary fixed, then
-- smoothed by the energy method, as bench/untangle_anchor3d.lua does for lugal: per bar the
-- cells, the inverted cells, the untangle time and minimum / mean mean ratio after it, the
-- smoothing time and the same after it, and the rest mesh's minimum.
-- Run: lugal bench/untangle_bars.lua 16 20 24 28
package.path = arg[0]:match("(.*/)") .. "../tests/lua/?.lua;" .. package.path
local H = require "hard_meshes"
local lg = require "lugal"
local sizes = {}
for i = 1, #arg do sizes[#sizes + 1] = assert(tonumber(arg[i]), "bar sizes are numbers") end
if #sizes == 0 then sizes = {16, 20, 24, 28} end
print("| bar | cells | inverted | untangle s | min q | mean q | smooth s | min q | mean q | rest min q |")
print("|---|---|---|---|---|---|---|---|---|---|")
for _, n in ipairs(sizes) do
  local tangled, rest = H.twisted_bar(n, 6, 1)
  local t0 = lg.wtime()
  local r = tangled:untangle{quiet = true, boundary = "fixed"}
  local tu = lg.wtime() - t0
  local qu = tangled:quality("mean_ratio")
  t0 = lg.wtime()
  if r.success then tangled:smooth{quiet = true, method = "energy", iterations = 50, boundary = "fixed"} end
  local ts = lg.wtime() - t0
  local qs = tangled:quality("mean_ratio")
  print(string.format("| %d | %d | %d | %.2f | %.4f | %.4f | %.2f | %.4f | %.4f | %.4f |", n, tangled:ncells(), r.invalid_before,
                      tu, qu:min(), qu:mean(), ts, qs:min(), qs:mean(), rest:quality("mean_ratio"):min()))
end
