-- bench/assembly.lua N degree [repeats] [form] [cell] — time of reassembling the stiffness matrix
-- of -Δ (form "laplace", the default), of linear elasticity with a vector P<degree>
-- displacement (form "elasticity": 2 mu eps(u):eps(v) + lambda div u div v) or the Jacobian
-- of a compressible Neo-Hookean energy at a given displacement u0 (form "neohookean": the
-- second Gateaux derivative of psi = mu/2 (tr C - 3) - mu ln J + lambda/2 (ln J)^2, at
-- quadrature degree 4 as FEniCSx is told too) on the unit
-- cube with N×N×N cubes, 6 tetrahedra each, into an existing PETSc matrix (median of the
-- repeats, after the tiered JIT's background builds; compilation and sparsity excluded and
-- reported separately; first_s: the time to the first matrix, setup and first assembly).
-- Prints one line of key=value pairs.
local lg = require "lugal"
local N = tonumber(arg[1]) or 32
local p = tonumber(arg[2]) or 1
local reps = tonumber(arg[3]) or 5
local form = arg[4] or "laplace"
local cell = arg[5] or "tetrahedron" -- or "hexahedron" (N^3 cubes, Q<degree>)
assert(form == "laplace" or form == "elasticity" or form == "neohookean", "form: laplace | elasticity | neohookean")

local clock = lg.wtime -- wall time: with OpenMP threads os.clock counts every thread
local t0 = clock()
local mesh = lg.mesh.box{nx = N, ny = N, nz = N, cell = cell}
local tmesh = clock() - t0
local P = form ~= "laplace" and lg.vector(lg.lagrange(p)) or lg.lagrange(p)
local u, v = lg.unknown(P, "u"), lg.test(P, "v")
local a, order
if form == "neohookean" then
  local x, y, z = lg.x, lg.y, lg.z
  local u0 = lg.interpolate(P, mesh, {0.1*x*y, -0.05*y*z, 0.08*x*z}, "u0")
  local mu, lambda = 1.0, 1.25
  local F = lg.identity(3) + lg.grad(u0)
  local J = lg.det(F)
  local psi = mu/2*(lg.tr(lg.dot(lg.transpose(F), F)) - 3) - mu*lg.log(J) + lambda/2*lg.log(J)^2
  a = lg.derivative(lg.derivative(psi, u0, v), u0, u)
  order = 4
elseif form == "elasticity" then
  local mu, lambda = 1.0, 1.25
  local function eps(w) return lg.sym(lg.grad(w)) end
  a = 2*mu*lg.inner(eps(u), eps(v)) + lambda*lg.div(u)*lg.div(v)
else
  a = lg.dot(lg.grad(v), lg.grad(u))
end
t0 = clock()
local prob = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), a, order and {order = order} or nil), test = v, unknown = u}
local tsetup = clock() - t0
-- the first matrix (libtcc's code, or the system compiler's from the disk cache), then the
-- reassemblies in the steady state: after the background builds of the tiered JIT, as
-- FEniCSx's are timed after its compiler ran (its JIT time is excluded)
local t1, nnz = prob:assemble()
local first = tsetup + t1 -- time to the first matrix: problem setup and first assembly
lg.jit_status(true)
local times = {}
for r = 1, reps do times[r] = prob:assemble() end
table.sort(times)
local st = lg.stats()
print(string.format("lugal " .. form .. (cell == "hexahedron" and " hex" or "") .. " N=%d P%d cells=%d dofs=%d nnz=%d assemble_median_s=%.4f assemble_min_s=%.4f setup_s=%.3f first_s=%.3f mesh_s=%.3f jit_ms=%.2f",
                    N, p, mesh:ncells(), prob:size(), nnz, times[math.ceil(reps / 2)], times[1], tsetup, first, tmesh, st.kernel_ms))
