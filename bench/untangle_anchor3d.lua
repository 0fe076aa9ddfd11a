-- bench/untangle_anchor3d.lua ANCHOR [DIR] — tetrahedral bars twisted about their axis
-- (bench/untangle_hard.lua's 3D hard tangles: boundary vertices at their twisted places,
-- interior vertices left straight) with the boundary fixed, untangled by lugal (untangle,
-- then smooth{method = "energy"}) and by ssloy/invertible-maps's untangle3d (foldover-free
-- maps, Garanzha et al. 2021), built beside lugal, never part of it: it reads the tangled
-- mesh and the rest (twisted, valid) mesh as Medit .mesh files, fixes the boundary, and
-- writes the result. DIR holds the files (a temporary folder by default). Per case: inverted
-- cells, then for each untangler success, time, and the minimum and mean mean ratio of the
-- result, and the rest mesh's own.
-- Run: lugal bench/untangle_anchor3d.lua /path/to/untangle3d [dir] [1m|small] [newton|lbfgs]
--   ("1m": a 1 152 000-tetrahedron bar; the last argument: the smoother's optimizer, auto by default)
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local A = require "anchor_cases"
local lg = require "lugal"
local anchor = assert(arg[1], "usage: lugal bench/untangle_anchor3d.lua /path/to/untangle3d [dir]")
local dir = arg[2] or os.tmpname() .. ".d"
os.execute("mkdir -p '" .. dir .. "'")

local function write_medit(path, mesh, tets)
  local f = assert(io.open(path, "w"))
  f:write("MeshVersionFormatted 2\nDimension 3\nVertices\n", mesh:nvertices(), "\n")
  for i = 1, mesh:nvertices() do
    local x, y, z = mesh:coordinates(i)
    f:write(string.format("%.17g %.17g %.17g 0\n", x, y, z))
  end
  f:write("Tetrahedra\n", #tets, "\n")
  for _, t in ipairs(tets) do f:write(string.format("%d %d %d %d 0\n", t[1], t[2], t[3], t[4])) end
  f:write("End\n")
  f:close()
end

-- the result's vertices (a Medit file: the count after "Vertices", then x y z ref lines)
local function read_result(path, mesh)
  local f = io.open(path)
  if not f then return false end
  local n, i, state = 0, 0, nil
  for line in f:lines() do
    if state == "count" then n = tonumber(line); state = n and "verts" or nil
    elseif state == "verts" and i < n then
      local x, y, z = line:match("^%s*(%S+)%s+(%S+)%s+(%S+)")
      i = i + 1
      mesh:set_coordinates(i, tonumber(x), tonumber(y), tonumber(z))
      if i == n then state = nil end
    elseif line:match("^%s*Vertices") then state = "count" end
  end
  f:close()
  return n == mesh:nvertices() and i == n
end

print("| case | cells | inverted | lugal | s | min q | mean q | anchor | s | min q | mean q | rest mesh min q |")
print("|---|---|---|---|---|---|---|---|---|---|---|---|")
for k, c in ipairs(arg[3] == "1m" and A.cases3d_1m or A.cases3d) do
  local tangled, rest = c[2]()
  local inv = tangled:check()
  -- lugal: untangle with the boundary fixed, then the energy smoother
  local m = tangled:copy()
  local t0 = lg.wtime()
  local r = m:untangle{quiet = true, boundary = "fixed"}
  if r.success then m:smooth{quiet = true, method = "energy", iterations = 50, boundary = "fixed", optimizer = arg[4]} end
  local tl = lg.wtime() - t0
  local ql = m:quality("mean_ratio")
  local linv = m:check()
  -- the anchor
  local tets = A.simplices(rest, string.format("%s/case%d.msh", dir, k))
  local init, ref, output = string.format("%s/case%d-init.mesh", dir, k), string.format("%s/case%d-rest.mesh", dir, k),
                            string.format("%s/case%d-result.mesh", dir, k)
  write_medit(init, tangled, tets)
  write_medit(ref, rest, tets)
  os.remove(output)
  local a = tangled:copy()
  t0 = lg.wtime()
  os.execute(string.format("'%s' '%s' '%s' '%s' > '%s/case%d.log' 2>&1", anchor, init, ref, output, dir, k))
  local ta = lg.wtime() - t0
  local ok = read_result(output, a)
  local ainv = ok and a:check() or -1
  local qa = ok and a:quality("mean_ratio")
  print(string.format("| %s | %d | %d | %s | %.3f | %.4f | %.4f | %s | %.3f | %s | %s | %.4f |", c[1], tangled:ncells(), inv,
                      r.success and linv == 0 and "yes" or "no", tl, ql:min(), ql:mean(),
                      ok and (ainv == 0 and "yes" or (ainv .. " inverted")) or "no result", ta,
                      ok and string.format("%.4f", qa:min()) or "—", ok and string.format("%.4f", qa:mean()) or "—",
                      rest:quality("mean_ratio"):min()))
end
