-- bench/read_parts.lua FILE.msh — reading a Gmsh file on every rank of a run: the time of
-- lg.mesh.read (the slowest rank's) and each rank's peak resident memory (VmHWM, largest and
-- smallest), with the cells each rank holds. bench/read_parts.sh runs it on 1 and 2 ranks,
-- with the file read in parts (the default) and whole by rank 0 (-lugal_read_parts 0).
local lg = require "lugal"
local t0 = lg.wtime()
local mesh = lg.mesh.read(arg[1])
local t = lg.allreduce(lg.wtime() - t0, "max")
local f = io.open("/proc/self/status")
local hwm = f and tonumber(f:read("a"):match("VmHWM:%s*(%d+)")) or 0
if f then f:close() end
local held = mesh:info().local_cells or mesh:ncells()
print(string.format("read %s: %d cells, ranks=%d read_s=%.2f peak_rss_mb_rank=%.0f (smallest %.0f)", arg[1]:match("[^/]+$"),
                    mesh:ncells(), lg.size(), t, lg.allreduce(hwm / 1024, "max"), lg.allreduce(hwm / 1024, "min")))
