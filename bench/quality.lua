-- bench/quality.lua N — the mean ratio and the scaled Jacobian on lg.mesh.box{nx = N}
-- (6N^3 tetrahedra; N = 119 gives 10.1 million), single-threaded; prints cells per second
-- (wall clock, best of 5) and the means, to compare with bench/quality_vtk.py on the same mesh.
local lg = require "lugal"
local N = tonumber(arg[1]) or 119
local t0 = lg.wtime()
local mesh = lg.mesh.box{nx = N}
print(string.format("lugal: %d tetrahedra built in %.1f s", mesh:ncells(), lg.wtime() - t0))
for _, name in ipairs{"mean_ratio", "scaled_jacobian"} do
  local best, q = math.huge, nil
  for _ = 1, 5 do
    q = nil
    collectgarbage()          -- release the previous 80 MB result, as a script would
    t0 = lg.wtime()
    q = mesh:quality(name)
    best = math.min(best, lg.wtime() - t0)
  end
  print(string.format("lugal %-34s %.3f s  %.1f M cells/s  mean %.12f  min %.12f", name, best,
                      mesh:ncells() / best / 1e6, q:mean(), (q:min())))
end
