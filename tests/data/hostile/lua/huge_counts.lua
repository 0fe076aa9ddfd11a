-- expect-ok: a mesh too large to make is refused with its true counts (they were capped at
-- 4000000000 and printed as if exact)
local lg = require "lugal"
local ok, err = pcall(lg.mesh.box, {nx = 2000, ny = 2000, nz = 2000})
assert(not ok and err:find("(8012006001 vertices and 48000000000 cells;", 1, true), err)
ok, err = pcall(lg.mesh.box, {nx = 2000, ny = 2000, nz = 2000, cell = "hexahedron"})
assert(not ok and err:find("(8012006001 vertices and 8000000000 cells;", 1, true), err)
ok, err = pcall(lg.mesh.rectangle, {nx = 100000, ny = 100000})
assert(not ok and err:find("(10000200001 vertices and 20000000000 cells;", 1, true), err)
print("true counts")
