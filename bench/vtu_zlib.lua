-- bench/vtu_zlib.lua [N] [prefix] — a tetrahedral box of N³ cubes with a P1 field and a quality
-- array written as binary VTU and as zlib-compressed VTU (format = "zlib"): sizes and times (issue 57:
-- src/mesh/io/deflate.c on zlib). Writes prefix_b.vtu and prefix_z.vtu (default prefix /tmp/vtu_zlib).
local lg = require "lugal"
local N = tonumber(arg[1]) or 40
local mesh = lg.mesh.box{nx = N}
local f = lg.interpolate(lg.lagrange(1), mesh, lg.sin(3*lg.x)*lg.y + lg.z, "f")
local q = mesh:quality("mean_ratio")
local t0 = lg.wtime(); mesh:write((arg[2] or "/tmp/vtu_zlib") .. "_b.vtu", {f = f, q = q}); local tb = lg.wtime() - t0
t0 = lg.wtime(); mesh:write((arg[2] or "/tmp/vtu_zlib") .. "_z.vtu", {f = f, q = q}, {format = "zlib"}); local tz = lg.wtime() - t0
local function size(p) local h = io.open(p, "rb"); local n = h:seek("end"); h:close(); return n end
print(string.format("N=%d binary %d bytes %.3f s, zlib %d bytes %.3f s, ratio %.3f", N, size((arg[2] or "/tmp/vtu_zlib") .. "_b.vtu"), tb, size((arg[2] or "/tmp/vtu_zlib") .. "_z.vtu"), tz, size((arg[2] or "/tmp/vtu_zlib") .. "_z.vtu")/size((arg[2] or "/tmp/vtu_zlib") .. "_b.vtu")))
