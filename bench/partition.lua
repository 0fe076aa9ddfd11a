-- bench/partition.lua [N] — what the partition of the rows does for a mesh numbered without
-- locality (issue 14): the unit cube in N×N×N cubes × 6 tetrahedra (the Kuhn split, as
-- lg.mesh.box), its cells and vertices listed in a shuffled order (a fixed seed), P1,
-- −Δu + u = f with natural conditions, CG + GAMG to 1e-8. Run it under mpiexec with the
-- default partitioner (PTScotch is chosen: the numbering splits poorly) and with
-- -lugal_partitioner natural (the rows in the numbering's order); bench/partition.sh does.
-- Prints the ranks' rows and ghost columns (summed), the iterations, the solve's wall time
-- and the solution's norm.
local lg = require "lugal"
local N = tonumber(arg and arg[1]) or 32
local t0 = lg.wtime()
local seed = 2024
local function rnd(i)
  seed = (seed * 1103515245 + 12345) % 2147483648
  return seed % i + 1
end
local verts, cells = {}, {}
local function id(i, j, k) return (k * (N + 1) + j) * (N + 1) + i + 1 end
for k = 0, N do for j = 0, N do for i = 0, N do verts[#verts + 1] = {i / N, j / N, k / N} end end end
local perms = {{1, 2, 3}, {1, 3, 2}, {2, 1, 3}, {2, 3, 1}, {3, 1, 2}, {3, 2, 1}}
for k = 0, N - 1 do
  for j = 0, N - 1 do
    for i = 0, N - 1 do
      for _, p in ipairs(perms) do
        local c, at = {id(i, j, k)}, {i, j, k}
        for s = 1, 2 do at[p[s]] = at[p[s]] + 1; c[#c + 1] = id(at[1], at[2], at[3]) end
        c[4] = id(i + 1, j + 1, k + 1)
        -- positive orientation: the Kuhn tetrahedra of odd permutations are reversed
        local a, b, d = verts[c[2]], verts[c[3]], verts[c[4]]
        local o = verts[c[1]]
        local ux, uy, uz = a[1] - o[1], a[2] - o[2], a[3] - o[3]
        local vx, vy, vz = b[1] - o[1], b[2] - o[2], b[3] - o[3]
        local wx, wy, wz = d[1] - o[1], d[2] - o[2], d[3] - o[3]
        if ux * (vy * wz - vz * wy) - uy * (vx * wz - vz * wx) + uz * (vx * wy - vy * wx) < 0 then c[2], c[3] = c[3], c[2] end
        cells[#cells + 1] = c
      end
    end
  end
end
for i = #cells, 2, -1 do local r = rnd(i); cells[i], cells[r] = cells[r], cells[i] end
local perm, nv = {}, {}
for i = 1, #verts do perm[i] = i end
for i = #perm, 2, -1 do local r = rnd(i); perm[i], perm[r] = perm[r], perm[i] end
for i = 1, #verts do nv[perm[i]] = verts[i] end
for _, c in ipairs(cells) do for q = 1, 4 do c[q] = perm[c[q]] end end
local mesh = lg.mesh.new{cell = "tetrahedron", vertices = nv, cells = cells}
verts, cells, nv = nil, nil, nil
local tmesh = lg.wtime() - t0
local x, y, z, pi = lg.x, lg.y, lg.z, math.pi
local P1 = lg.lagrange(1)
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
lg.options("-ksp_type cg -pc_type gamg -ksp_rtol 1e-8")
t0 = lg.wtime()
local prob = lg.linear_problem{mesh = mesh, test = v, unknown = u,
                               eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) + u*v - lg.sin(pi*x)*lg.cos(y + z)*v)}
local tsetup = lg.wtime() - t0
t0 = lg.wtime()
local uh, info = prob:solve()
local tsolve = lg.wtime() - t0
local o = prob:ownership()
print(string.format("partition N=%d dofs=%d ranks=%d rows_max=%d ghosts=%d iterations=%d mesh_s=%.2f setup_s=%.3f solve_s=%.3f norm=%.10e",
                    N, uh:ndof(), lg.size(), lg.allreduce(o.rows, "max"), lg.allreduce(o.ghosts), info.iterations, tmesh,
                    lg.allreduce(tsetup, "max"), lg.allreduce(tsolve, "max"), math.sqrt(lg.integrate(mesh, uh*uh))))
