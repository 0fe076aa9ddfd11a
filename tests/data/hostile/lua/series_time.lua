-- expect-ok: a NaN or infinite time in series:write is refused (it was written into the
-- .pvd); a series path longer than 500 bytes is taken (it was refused as "too long")
local lg = require "lugal"
local dir = os.tmpname()
os.remove(dir)
assert(os.execute("mkdir -p '" .. dir .. "'"))
local mesh = lg.mesh.rectangle{nx = 2}
local s = lg.series(dir .. "/s.pvd")
for _, t in ipairs{0/0, math.huge, -math.huge} do
  local ok, err = pcall(s.write, s, mesh, {}, t)
  assert(not ok and err:find("series:write: argument 3 (the time) must be a finite number", 1, true), tostring(err))
end
assert(s:write(mesh, {}, 0.5):find("s_0000.vtu", 1, true))
local pvd = assert(io.open(dir .. "/s.pvd")):read("a")
assert(pvd:find('timestep="0.5"', 1, true) and not pvd:find("nan") and not pvd:find("inf"), pvd)
local deep = dir .. "/" .. string.rep("d", 200) .. "/" .. string.rep("e", 200) .. "/" .. string.rep("f", 120)
assert(os.execute("mkdir -p '" .. deep .. "'"))
local long = lg.series(deep .. "/steps.pvd")
assert(long:write(mesh, {}, 1):find("steps_0000.vtu", 1, true))
assert(io.open(deep .. "/steps_0000.vtu"), "the step of a long path")
os.execute("rm -rf '" .. dir .. "'")
print("series times and long paths: as documented")
