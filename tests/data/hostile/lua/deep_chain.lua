-- expect-ok: a 100 000-deep chain overflowed the C stack when printed, differentiated or collected
local lg = require "lugal"
local mesh = lg.mesh.rectangle{nx = 2}
local e = lg.x
for i = 1, 100000 do e = lg.sin(e + 0.001) end
print(#tostring(e), #tostring(lg.grad(e)[1]) > 0)
print(lg.integrate(mesh, e))
