-- expect-ok-lua5.4: a field named _CLIBS used to replace the registry's C library table (a segfault at exit in lua5.4)
local lg = require "lugal"
local m = lg.mesh.rectangle{nx = 2}
local v = {}
for i = 1, m:nvertices() do v[i] = i end
local path = os.tmpname()
m:write(path .. ".vtu", {_CLIBS = v, _LOADED = v, ["lugal.Mesh"] = v, ["lugal.env"] = v})
os.remove(path .. ".vtu")
os.remove(path)
print(m)
