-- elasticity.lua — a 3D cantilever under its own weight: linear elasticity with a vector P2
-- displacement, clamped at x = 0, solved by CG preconditioned with PETSc's algebraic
-- multigrid (GAMG). lugal gives the matrix its block size and the six rigid body modes as
-- GAMG's near null space, so the iteration count stays low as the mesh is refined.
-- Checks the CG solution against a direct (LU) solve and the tip deflection against
-- Euler-Bernoulli beam theory, w = q L^4 / (8 E I) (at L/H = 5 shear deformation, which
-- that theory leaves out, adds a few per cent).
-- Run: lugal examples/elasticity.lua [n]   (n cells across, 5n along)
local lg = require "lugal"
local n = tonumber(arg and arg[1]) or 3
local L, H = 1.0, 0.2
local E, nu, rho_g = 1e4, 0.3, 1.0
local mu, lambda = E/(2*(1 + nu)), E*nu/((1 + nu)*(1 - 2*nu))

local mesh = lg.mesh.box{nx = 5*n, ny = n, nz = n, x1 = L, y1 = H, z1 = H}
local V = lg.vector(lg.lagrange(2))
local u, v = lg.unknown(V, "u"), lg.test(V, "v")
local function eps(w) return lg.sym(lg.grad(w)) end
local function sigma(w) return 2*mu*eps(w) + lambda*lg.tr(eps(w))*lg.identity(3) end
local f = {0, 0, -rho_g}
local eqn = lg.integral(mesh:cells(), lg.inner(sigma(u), eps(v)) - lg.dot(f, v))
local bc = lg.essential_bc(mesh:boundary("left"), lg.dot(v, u))

local t0 = lg.wtime()
local iterative = lg.linear_problem{mesh = mesh, eqn = eqn, bc = bc, test = v, unknown = u, prefix = "el_",
                                      symmetric = true}  -- CG needs the symmetric elimination
lg.options("-el_ksp_type cg -el_pc_type gamg -el_ksp_rtol 1e-10")
local uh, info = iterative:solve()
local t_cg = lg.wtime() - t0
t0 = lg.wtime()
local direct = lg.linear_problem{mesh = mesh, eqn = eqn, bc = bc, test = v, unknown = u}
local ud = direct:solve()
local t_lu = lg.wtime() - t0

local diff = math.sqrt(lg.integrate(mesh, lg.dot(uh - ud, uh - ud)) / lg.integrate(mesh, lg.dot(ud, ud)))
-- the tip deflection: the mean of u_z over the free end
local tip = lg.integrate(mesh:boundary("right"), uh[3]) / (H*H)
local I = H^4/12
local beam = -rho_g*H*H*L^4/(8*E*I)
mesh:write("elasticity.vtu", {displacement = ud})   -- the direct solve (bench/compare_fenicsx.py reads it)
print(string.format("elasticity: %d tetrahedra, %d dofs; CG + GAMG %d iterations (%.2f s), LU %.2f s, relative difference %.1e",
                    mesh:ncells(), uh:ndof(), info.iterations, t_cg, t_lu, diff))
print(string.format("elasticity: tip deflection %.5f, beam theory %.5f (ratio %.3f)", tip, beam, tip/beam))
assert(info.iterations < 60, "GAMG with rigid body modes needs few CG iterations")
assert(diff < 1e-6, "CG and LU agree")
assert(tip/beam > 0.95 and tip/beam < 1.08, "tip deflection near beam theory")
