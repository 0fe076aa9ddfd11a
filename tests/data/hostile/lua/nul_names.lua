-- expect-ok: names and paths with a zero byte are refused with the name of the function
-- ("p\0x" and "p\0y" were written as two arrays named "p"; a boundary name with a zero byte
-- gave Lua's "attempt to get length of a nil value")
local lg = require "lugal"
local function refused(f, ...)
  local ok, err = pcall(f, ...)
  assert(not ok, "accepted")
  assert(err:find("holds a zero byte", 1, true), err)
  return err
end
local mesh = lg.mesh.rectangle{nx = 2}
local P1 = lg.lagrange(1)
local f1 = lg.interpolate(P1, mesh, lg.x, "px")
local e = refused(mesh.write, mesh, os.tmpname() .. ".vtu", {["p\0x"] = f1, ["p\0y"] = f1})
assert(e:find("mesh:write: field name", 1, true), e)
e = refused(lg.mesh.new, {cell = "triangle", vertices = {{0, 0}, {1, 0}, {0, 1}, {1, 1}}, cells = {{1, 2, 3}, {2, 4, 3}},
                          boundary = {["a\0b"] = {{1, 2}, {2, 4}, {4, 3}, {3, 1}}}})
assert(e:find("lg.mesh.new: boundary name", 1, true), e)
refused(mesh.boundary, mesh, "left\0junk")
refused(mesh.cells, mesh, "all\0")
refused(lg.interpolate, P1, mesh, lg.x, "p\0x")
refused(lg.unknown, P1, "u\0")
refused(lg.parameter, "k\0k", 1)
refused(lg.mesh.read, "/tmp/x.msh\0.txt")
refused(mesh.write, mesh, "/tmp/x.vtu\0.txt")
refused(mesh.write, mesh, "/tmp/x.vtu", {}, {format = "ascii\0"})
refused(lg.options, "-ksp_type\0 cg")
print("zero bytes refused")
