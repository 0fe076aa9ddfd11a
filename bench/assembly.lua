-- bench/assembly.lua N degree [repeats] [form] — time of reassembling the stiffness matrix
-- of -Δ (form "laplace", the default) or of linear elasticity with a vector P<degree>
-- displacement (form "elasticity": 2 mu eps(u):eps(v) + lambda div u div v) on the unit
-- cube with N×N×N cubes, 6 tetrahedra each, into an existing PETSc matrix (median of the
-- repeats; compilation and sparsity excluded and reported separately). Prints one line of
-- key=value pairs.
local lg = require "lugal"
local N = tonumber(arg[1]) or 32
local p = tonumber(arg[2]) or 1
local reps = tonumber(arg[3]) or 5
local form = arg[4] or "laplace"
assert(form == "laplace" or form == "elasticity", "form: laplace | elasticity")

local clock = os.clock
local t0 = clock()
local mesh = lg.mesh.box{nx = N, ny = N, nz = N}
local tmesh = clock() - t0
local P = form == "elasticity" and lg.vector(lg.lagrange(p)) or lg.lagrange(p)
local u, v = lg.unknown(P, "u"), lg.test(P, "v")
local a
if form == "elasticity" then
  local mu, lambda = 1.0, 1.25
  local function eps(w) return lg.sym(lg.grad(w)) end
  a = 2*mu*lg.inner(eps(u), eps(v)) + lambda*lg.div(u)*lg.div(v)
else
  a = lg.dot(lg.grad(v), lg.grad(u))
end
t0 = clock()
local prob = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), a), test = v, unknown = u}
local tsetup = clock() - t0
local times, nnz = {}, 0
for r = 1, reps do
  local s
  s, nnz = prob:assemble()
  times[r] = s
end
table.sort(times)
local st = lg.stats()
print(string.format("lugal " .. form .. " N=%d P%d cells=%d dofs=%d nnz=%d assemble_median_s=%.4f assemble_min_s=%.4f setup_s=%.3f mesh_s=%.3f jit_ms=%.2f",
                    N, p, mesh:ncells(), prob:size(), nnz, times[math.ceil(reps / 2)], times[1], tsetup, tmesh, st.kernel_ms))
