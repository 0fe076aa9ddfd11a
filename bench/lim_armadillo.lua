-- bench/lim_armadillo.lua INIT.vtk REST.vtk — a Locally Injective Mappings Benchmark sample
-- (the armadillo 3D deformation, 23 982 tetrahedra, shipped with ssloy/invertible-maps as
-- cpp/armadillo-598-{init,rest}.vtk): untangled by lugal with the boundary fixed, as the
-- benchmark asks, with each placement and with the rest shapes as reference shapes; prints
-- success, invalid cells, time and the quality after (the minimum and mean relative mean
-- ratio against the rest shapes, and the minimum mean ratio); with a third file, another
-- untangler's result (ssloy/invertible-maps's untangle3d writes one), the same measures of it.
-- Run:
--   ./lugal bench/lim_armadillo.lua armadillo-598-init.vtk armadillo-598-rest.vtk [result3d.vtk]
local lg = require "lugal"

-- an ASCII legacy VTK unstructured grid of tetrahedra (POINTS and CELLS only)
local function read_vtk(path)
  local f = assert(io.open(path, "r"), "cannot open " .. path)
  local text = f:read("a")
  f:close()
  local np, rest = text:match("POINTS%s+(%d+)%s+%a+%s+(.*)")
  assert(np, path .. ": no POINTS")
  np = tonumber(np)
  local nums = {}
  for w in rest:gmatch("%S+") do
    if w == "CELLS" then break end
    nums[#nums + 1] = tonumber(w)
  end
  local verts = {}
  for i = 1, np do verts[i] = {nums[3*i - 2], nums[3*i - 1], nums[3*i]} end
  local nc, crest = text:match("CELLS%s+(%d+)%s+%d+%s+(.*)")
  nc = tonumber(nc)
  local cells, it = {}, crest:gmatch("%S+")
  for c = 1, nc do
    local k = tonumber(it())
    assert(k == 4, path .. ": only tetrahedra")
    local cell = {}
    for j = 1, 4 do cell[j] = tonumber(it()) + 1 end
    cell[1], cell[2] = cell[2], cell[1] -- the benchmark's tetrahedra turn the other way round
    cells[c] = cell
  end
  return lg.mesh.new{cell = "tetrahedron", vertices = verts, cells = cells}
end

local init, rest, other = arg[1], arg[2], arg[3]
assert(init and rest, "usage: lugal bench/lim_armadillo.lua INIT.vtk REST.vtk [OTHER_RESULT.vtk]")
local ref = read_vtk(rest)
print(string.format("| run | tetrahedra | inverted before | after | s | min rel. mean ratio | mean rel. | min mean ratio |"))
print("|---|---|---|---|---|---|---|---|")
for _, run in ipairs{{"chebyshev"}, {"corners"}, {"chebyshev", true}} do
  local m = read_vtk(init)
  local r = m:untangle{quiet = true, boundary = "fixed", placement = run[1], reference = run[2] and ref or nil}
  local q = m:quality("deformation_quality", {reference = ref})
  local name = run[1] .. (run[2] and " + reference" or "") .. (r.fallback_placement and (" (then " .. r.fallback_placement .. ")") or "")
  print(string.format("| %s | %d | %d | %d | %.2f | %.4f | %.4f | %.4g |", name, m:ncells(), r.invalid_before, r.invalid_after,
                      r.seconds, q:min(), q:mean(), m:quality("mean_ratio"):min()))
end
-- untangling towards the rest shapes, then smoothing towards them (boundary fixed)
do
  local m = read_vtk(init)
  local r = m:untangle{quiet = true, boundary = "fixed", reference = ref}
  local sm = m:smooth{quiet = true, reference = ref, boundary = "fixed"}
  local q = m:quality("deformation_quality", {reference = ref})
  print(string.format("| chebyshev + reference, then smooth{reference} | %d | %d | %d | %.2f | %.4f | %.4f | %.4g |", m:ncells(),
                      r.invalid_before, r.invalid_after, r.seconds + sm.seconds, q:min(), q:mean(), m:quality("mean_ratio"):min()))
end
print(string.format("| the rest mesh itself | %d | | | | 1 | 1 | %.4g |", ref:ncells(), ref:quality("mean_ratio"):min()))
if other then
  local m = read_vtk(other)
  local q = m:quality("deformation_quality", {reference = ref})
  local inv = 0
  local sm = m:quality("signed_measure")
  for i = 1, #sm do if not (sm[i] > 0) then inv = inv + 1 end end
  print(string.format("| %s | %d | | %d | | %.4f | %.4f | %.4g |", other:match("[^/]*$"), m:ncells(), inv, q:min(), q:mean(),
                      m:quality("mean_ratio"):min()))
end
