-- bench/untangle.lua — tangled-mesh generator and untangler benchmark (issue 4).
-- Meshes of about 1k, 10k and 100k vertices (triangles, quadrilaterals, tetrahedra) whose
-- interior vertices are displaced by up to 20% of the domain size in each coordinate (the
-- seed's Texas experiment): a fraction of them (5%) or all of them; plus a quadrilateral
-- mesh advected by the single-vortex flow until it tangles. The original meshes are valid,
-- so every case should be untangled. Per case: success, time, vertices moved, mean
-- displacement, minimum shape quality afterwards (mean ratio for simplices, corner
-- condition = min corner mean ratio for quadrilaterals).
-- Run: lugal bench/untangle.lua [maxsize]   (maxsize 1, 2 or 3 for 1k / 10k / 100k)
local lg = require "lugal"
local maxsize = tonumber(arg[1]) or 3

local seed = 20261123
local function rand() seed = (seed * 1103515245 + 12345) % 2147483648; return seed / 2147483648 end

local function make(cell, nv)
  if cell == "tetrahedron" then
    local n = math.floor(nv^(1/3) + 0.5) - 1
    return lg.mesh.box{nx = n, cell = cell}
  end
  local n = math.floor(math.sqrt(nv) + 0.5) - 1
  return lg.mesh.rectangle{nx = n, cell = cell}
end

local function tangle(m, frac)
  local d = m:dim()
  for i = 1, m:nvertices() do
    local p = {m:coordinates(i)}
    local inside = true
    for k = 1, d do inside = inside and p[k] > 0 and p[k] < 1 end
    if inside and rand() < frac then
      for k = 1, d do p[k] = p[k] + 0.2 * (2 * rand() - 1) end
      m:set_coordinates(i, table.unpack(p))
    end
  end
end

local function vortex(n)
  local m = lg.mesh.rectangle{nx = n, cell = "quadrilateral"}
  local pi, sin, dt = math.pi, math.sin, 0.025
  local function vel(x, y) return -sin(pi*x)^2 * sin(2*pi*y), sin(2*pi*x) * sin(pi*y)^2 end
  for k = 1, 200 do
    local inv = m:displace(function(x, y)
      local u, v = vel(x, y)
      local um, vm = vel(x + 0.5*dt*u, y + 0.5*dt*v)
      return dt*um, dt*vm
    end)
    if inv > 0 then return m, k end
  end
  return m, 200
end

local function row(name, m)
  local inv = m:check()
  local r = m:untangle{quiet = true}
  local q = m:quality(m:dim() == 3 and m:info().cell == "tetrahedron" and "mean_ratio"
                      or (m:info().cell == "triangle" and "mean_ratio" or "corner_condition"))
  print(string.format("| %-34s | %7d | %7d | %6d | %-4s | %7.3f | %7d | %9.2e | %9.2e |", name, m:nvertices(),
                      m:ncells(), inv, r.success and "yes" or "NO", r.seconds, r.moved, r.mean_displacement, q:min()))
  io.stdout:flush()
end

print("| case | vertices | cells | invalid | ok | time s | moved | mean disp | min quality |")
print("|---|---|---|---|---|---|---|---|---|")
local sizes = {1000, 10000, 100000}
for s = 1, maxsize do
  for _, cell in ipairs{"triangle", "quadrilateral", "tetrahedron"} do
    for _, frac in ipairs{0.05, 1.0} do
      do
        local m = make(cell, sizes[s])
        tangle(m, frac)
        row(string.format("%s %s, %d%% moved", cell, sizes[s] >= 1e5 and "100k" or sizes[s] >= 1e4 and "10k" or "1k",
                          math.floor(frac * 100 + 0.5)), m)
      end
    end
  end
end
for _, n in ipairs{31, 99, 315} do
  local m, k = vortex(n)
  row(string.format("vortex quad %dx%d, step %d", n, n, k), m)
end
