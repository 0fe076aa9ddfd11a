-- bench/untangle_tlc.lua FINDINJECTIVE [DIR] — the hard tangles of bench/untangle_hard.lua
-- (Tutte-started spiral strips, random interiors of star domains, twisted tetrahedral bars)
-- with the boundary fixed, untangled by lugal and by TLC (Du et al., "Lifting simplices to
-- find injectivity", SIGGRAPH 2020: duxingyi-charles/lifting_simplices_to_find_injectivity's
-- findInjective, TLC-QN on NLopt's L-BFGS), built beside lugal, never part of it. TLC reads
-- the rest (valid) mesh as its source, the tangled one as its initial embedding and the
-- boundary vertices as handles, and stops as soon as no simplex is inverted (its "all_good"
-- stop, the repository's example options). lugal's untangle alone is the like-for-like
-- comparison; untangle + smooth{method = "energy"} is shown too. DIR holds the files (a
-- temporary folder by default). Quality: the mean ratio, measured by lugal on both results.
-- Run: lugal bench/untangle_tlc.lua /path/to/findInjective [dir] [seconds per TLC run, 600]
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local A = require "anchor_cases"
local lg = require "lugal"
local tlc = assert(arg[1], "usage: lugal bench/untangle_tlc.lua /path/to/findInjective [dir]")
local dir = arg[2] or os.tmpname() .. ".d"
local limit = tonumber(arg[3]) or 600 -- seconds per TLC run
os.execute("mkdir -p '" .. dir .. "'")

-- the boundary vertices: those of the facets in one simplex only
local function boundary_vertices(cells, dim)
  local count, facets = {}, {}
  for _, c in ipairs(cells) do
    for skip = 1, dim + 1 do
      local f = {}
      for j = 1, dim + 1 do if j ~= skip then f[#f + 1] = c[j] end end
      table.sort(f)
      local key = table.concat(f, ",")
      count[key] = (count[key] or 0) + 1
      facets[key] = f
    end
  end
  local on, list = {}, {}
  for key, n in pairs(count) do
    if n == 1 then for _, v in ipairs(facets[key]) do on[v] = true end end
  end
  for v in pairs(on) do list[#list + 1] = v end
  table.sort(list)
  return list
end

local function coords(mesh, i)
  local x, y, z = mesh:coordinates(i)
  return mesh:dim() == 2 and string.format("%.17g %.17g", x, y) or string.format("%.17g %.17g %.17g", x, y, z)
end

local function write_input(path, tangled, rest, cells)
  local dim, f = rest:dim(), assert(io.open(path, "w"))
  f:write(rest:nvertices(), " ", dim, "\n")
  for i = 1, rest:nvertices() do f:write(coords(rest, i), "\n") end
  f:write(tangled:nvertices(), " ", dim, "\n")
  for i = 1, tangled:nvertices() do f:write(coords(tangled, i), "\n") end
  f:write(#cells, " ", dim + 1, "\n")
  for _, c in ipairs(cells) do
    local z = {}
    for j = 1, #c do z[j] = c[j] - 1 end
    f:write(table.concat(z, " "), "\n")
  end
  local b = boundary_vertices(cells, dim)
  f:write(#b, "\n")
  for _, v in ipairs(b) do f:write(v - 1, "\n") end
  f:close()
end

-- the repository's example options (Tutte-form lifted content, alpha = 1e-6 of the rest
-- content, L-BFGS, stop when every simplex is positive) with nothing recorded
local function write_options(path)
  local f = assert(io.open(path, "w"))
  f:write("form\nTutte\nalphaRatio\n1e-6\nalpha\n-1\nftol_abs\n1e-8\nftol_rel\n1e-8\nxtol_abs\n1e-8\nxtol_rel\n1e-8\n",
          "algorithm\nLBFGS\nmaxeval\n10000\nstopCode\nall_good\nrecord\nvert\t0\nenergy\t0\nminArea\t0\n")
  f:close()
end

-- the result: "name rows cols" headers followed by a matrix; the "resV" one holds the vertices
local function read_result(path, mesh)
  local f = io.open(path)
  if not f then return false end
  local words = {}
  for w in f:read("a"):gmatch("%S+") do words[#words + 1] = w end
  f:close()
  for i = 1, #words - 2 do
    if words[i] == "resV" then
      local n, d = tonumber(words[i + 1]), tonumber(words[i + 2])
      if n ~= mesh:nvertices() then return false end
      for v = 1, n do
        local b = i + 2 + (v - 1) * d
        if d == 2 then mesh:set_coordinates(v, tonumber(words[b + 1]), tonumber(words[b + 2]))
        else mesh:set_coordinates(v, tonumber(words[b + 1]), tonumber(words[b + 2]), tonumber(words[b + 3])) end
      end
      return true
    end
  end
  return false
end

local options = dir .. "/solver_options"
write_options(options)
print("| case | cells | inverted | lugal untangle s | min q | + smooth s | min q | TLC | s | min q | mean q | rest mesh min q |")
print("|---|---|---|---|---|---|---|---|---|---|---|---|")
local cases = {}
for _, c in ipairs(A.cases2d) do cases[#cases + 1] = c end
for _, c in ipairs(A.cases3d) do cases[#cases + 1] = c end
for k, c in ipairs(cases) do
  local tangled, rest = c[2]()
  local inv = tangled:check()
  local m = tangled:copy()
  local t0 = lg.wtime()
  local r = m:untangle{quiet = true, boundary = "fixed"}
  local tu = lg.wtime() - t0
  local qu = m:quality("mean_ratio")
  if r.success then m:smooth{quiet = true, method = "energy", iterations = 50, boundary = "fixed"} end
  local ts = lg.wtime() - t0
  local qs = m:quality("mean_ratio")
  local input, output = string.format("%s/case%d.in", dir, k), string.format("%s/case%d.result", dir, k)
  write_input(input, tangled, rest, A.simplices(rest, string.format("%s/case%d.msh", dir, k)))
  os.remove(output)
  local a = tangled:copy()
  t0 = lg.wtime()
  os.execute(string.format("timeout %d '%s' '%s' '%s' '%s' > '%s/case%d.log' 2>&1", limit, tlc, input, options, output, dir, k))
  local ta = lg.wtime() - t0
  local ok = read_result(output, a)
  local ainv = ok and a:check() or -1
  local qa = ok and a:quality("mean_ratio")
  print(string.format("| %s | %d | %d | %s %.3f | %.4f | %.3f | %.4f | %s | %.3f | %s | %s | %.4f |", c[1], tangled:ncells(), inv,
                      r.success and "yes" or "no", tu, qu:min(), ts, qs:min(),
                      ok and (ainv == 0 and "yes" or (ainv .. " inverted")) or "no result", ta,
                      ok and string.format("%.4f", qa:min()) or "—", ok and string.format("%.4f", qa:mean()) or "—",
                      rest:quality("mean_ratio"):min()))
end
