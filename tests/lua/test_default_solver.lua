-- The default linear solver (src/assemble/problem/problem_solve.c, choose_solver): CG with
-- GAMG for a large symmetric positive definite system (3D, at least 20 000 unknowns), GMRES
-- with GAMG for an unsymmetric one with a positive diagonal (convection-diffusion), the
-- direct solver below that size, after a Krylov solver fails (an indefinite matrix, strong
-- convection), and with -lugal_iterative 0. The solutions agree with the direct solver's to the
-- tolerance CG is given (1e-10 of the residual); the adjoint gradient of a Dirichlet
-- control and a source parameter (the essential columns eliminated for CG and corrected
-- for in the adjoint, problem_solve.c, column_correction) agrees with the direct solver's.
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local T = require "testlib"
local lg = require "lugal"
local x, y, z, pi = lg.x, lg.y, lg.z, math.pi
local P1 = lg.lagrange(1)
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")

-- -Δu + k u = f, u = c (1 + x) on the boundary; J = ∫ (u - 1/2)² over the cube
local c, s = lg.parameter("c", 0.3), lg.parameter("s", 1.0)
local meshes = {}
local function solve(N, k, extra)
  meshes[N] = meshes[N] or lg.mesh.box{nx = N}
  local mesh = meshes[N]
  local f = s*3*pi^2*lg.sin(pi*x)*lg.sin(pi*y)*lg.sin(pi*z)
  local prob = lg.linear_problem{mesh = mesh, test = v, unknown = u,
    eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) + k*u*v - f*v + (extra or 0)*lg.grad(u)[1]*v),
    bc = lg.essential_bc(mesh:boundary(), v*(u - c*(1 + x)))}
  local uh, info = prob:solve()
  local J = lg.functional(lg.integral(mesh:cells(), (u - 0.5)^2))
  return prob, uh, info, mesh, J
end

local function gradient(prob, J)
  local rf = lg.reduced_functional{problem = prob, functional = J, control = {c, s}}
  local g1, g2 = rf:gradient()
  return rf:value(), g1, g2
end

-- below the size: direct
local _, _, small = solve(16, 0)
T.check(not small.solver:find("cg"), "16³ cubes (4 913 unknowns) keep the direct solver, got %s", small.solver)

-- above it: CG with GAMG, against the direct solver
local prob, uh, info, mesh, J = solve(28, 0)
T.check(info.solver == "cg/gamg", "28³ cubes (24 389 unknowns) get CG with GAMG, got %s", info.solver)
T.check(info.iterations > 3 and info.iterations < 40, "GAMG's CG iterations %d", info.iterations)
local J1, gc1, gs1 = gradient(prob, J)
lg.options("-lugal_iterative 0")
local prob2, uh2, info2, _, J2 = solve(28, 0)
T.check(not info2.solver:find("cg"), "-lugal_iterative 0 gives the direct solver, got %s", info2.solver)
local d = math.sqrt(lg.integrate(mesh, (uh - uh2)^2) / lg.integrate(mesh, uh2^2))
T.check(d < 1e-8, "CG's solution is the direct solver's to 1e-8 (relative L2 %.2e)", d)
local J0, gc0, gs0 = gradient(prob2, J2)
T.check(math.abs(J1 - J0) < 1e-9 * math.abs(J0), "J %.12e against %.12e", J1, J0)
T.check(math.abs(gc1 - gc0) < 1e-7 * math.abs(gc0), "dJ/dc (a Dirichlet control) %.12e against the direct solver's %.12e", gc1, gc0)
T.check(math.abs(gs1 - gs0) < 1e-7 * math.abs(gs0), "dJ/ds %.12e against %.12e", gs1, gs0)
lg.options("-lugal_iterative 1")

-- unsymmetric (convection): GMRES with GAMG, against the direct solver, gradients too (the
-- transposed solve); strongly convective: GMRES fails, the direct solver takes over
local pc, uc, conv, _, Jc = solve(28, 0, 5)
T.check(conv.solver == "gmres/gamg", "a convection term gets GMRES with GAMG, got %s", conv.solver)
local Jc1, gcc1, gsc1 = gradient(pc, Jc)
local _, ub, strong = solve(28, 0, 200)
T.check(not strong.solver:find("gmres"), "strong convection falls back to the direct solver, got %s", strong.solver)
lg.options("-lugal_iterative 0")
local pc2, uc2, conv2, _, Jc2 = solve(28, 0, 5)
T.check(not conv2.solver:find("gmres"), "-lugal_iterative 0: direct, got %s", conv2.solver)
local Jc0, gcc0, gsc0 = gradient(pc2, Jc2)
local dc = math.sqrt(lg.integrate(mesh, (uc - uc2)^2) / lg.integrate(mesh, uc2^2))
T.check(dc < 1e-8, "GMRES's solution is the direct solver's to 1e-8 (relative L2 %.2e)", dc)
T.check(math.abs(Jc1 - Jc0) < 1e-9 * math.abs(Jc0) and math.abs(gcc1 - gcc0) < 1e-7 * math.abs(gcc0) and
        math.abs(gsc1 - gsc0) < 1e-7 * math.abs(gsc0), "GMRES's J and gradient %.12e %.12e %.12e against %.12e %.12e %.12e",
        Jc1, gcc1, gsc1, Jc0, gcc0, gsc0)
local _, ub2 = solve(28, 0, 200)
local db = math.sqrt(lg.integrate(mesh, (ub - ub2)^2) / lg.integrate(mesh, ub2^2))
T.check(db < 1e-10, "the fallback's solution is the direct solver's (relative L2 %.2e)", db)
lg.options("-lugal_iterative 1")

-- indefinite (Helmholtz, -Δu - k² u with a positive diagonal): CG fails, the direct solver
-- takes over and solves it
local _, uk, ik = solve(28, -60)
lg.options("-lugal_iterative 0")
local _, uk2 = solve(28, -60)
local dk = math.sqrt(lg.integrate(mesh, (uk - uk2)^2) / lg.integrate(mesh, uk2^2))
T.check(dk < 1e-8, "the indefinite system's solution after the fallback is the direct solver's (relative L2 %.2e, %s)", dk, ik.solver)
print(string.format("default solver: %s, %d iterations at 24 389 unknowns; dJ/dc %.10e (direct %.10e), dJ/ds %.10e (%.10e); convection: %s, %d iterations; strong convection: %s; Helmholtz: %s",
                    info.solver, info.iterations, gc1, gc0, gs1, gs0, conv.solver, conv.iterations, strong.solver, ik.solver))

-- a saddle point (Taylor–Hood Stokes, the second unknown's diagonal block zero): GMRES with a
-- Schur complement fieldsplit (the size lowered by -lugal_iterative_min), against the direct
-- solver: the solution, and the gradient of the dissipation with respect to the inflow's
-- amplitude (a Dirichlet value) and the viscosity (the transposed solve)
local box = lg.mesh.box{nx = 5}
local V2, Q1 = lg.vector(lg.lagrange(2)), P1
local su, sp = lg.unknown(V2, "su"), lg.unknown(Q1, "sp")
local sv, sq = lg.test(V2, "sv"), lg.test(Q1, "sq")
local amp, visc = lg.parameter("amp", 1.0), lg.parameter("visc", 1.0)
local function stokes(prefix)
  local prob = lg.linear_problem{mesh = box, test = {sv, sq}, unknown = {su, sp}, prefix = prefix,
    eqn = lg.integral(box:cells(), visc*lg.inner(lg.grad(su), lg.grad(sv)) - sp*lg.div(sv) - sq*lg.div(su)),
    bc = {lg.essential_bc(box:boundary("left"), lg.dot(sv, su - {amp*16*y*(1 - y)*z*(1 - z), 0, 0})),
          lg.essential_bc(box:boundary("front", "back", "bottom", "top"), lg.dot(sv, su))}}
  local uh, ph, sinfo = prob:solve()
  local rf = lg.reduced_functional{problem = prob, control = {amp, visc},
    functional = lg.functional(lg.integral(box:cells(), lg.inner(lg.grad(su), lg.grad(su)) + sp^2))}
  local ga, gv = rf:gradient()
  local _, _, after = prob:solve() -- the adjoint kept the fieldsplit (a forward solve: the matrix is symmetric)
  return uh, ph, sinfo, rf:value(), ga, gv, after
end
lg.options("-lugal_iterative 1 -lugal_iterative_min 2000")
local su1, sp1, si1, sJ1, sga1, sgv1, safter = stokes()
lg.options("-lugal_iterative 0")
local su0, sp0, si0, sJ0, sga0, sgv0 = stokes()
-- the user's own fieldsplit gets the unknowns as its splits ("0" the velocity, "1" the pressure)
lg.options("-lugal_iterative 1 -fs_ksp_type fgmres -fs_ksp_rtol 1e-12 -fs_pc_type fieldsplit -fs_pc_fieldsplit_type schur " ..
           "-fs_pc_fieldsplit_schur_precondition selfp -fs_fieldsplit_0_pc_type lu -fs_fieldsplit_1_pc_type jacobi")
local suf, spf, sif = stokes("fs_")
T.check(sif.solver == "fgmres/fieldsplit", "the user's fieldsplit, got %s", sif.solver)
local dsf = math.sqrt(lg.integrate(box, lg.dot(suf - su0, suf - su0)) / lg.integrate(box, lg.dot(su0, su0)))
T.check(dsf < 1e-9, "the user's fieldsplit's velocity is the direct solver's (relative L2 %.2e)", dsf)
T.check(si1.solver == "gmres/fieldsplit" and si1.iterations < 60, "Stokes gets GMRES with a Schur fieldsplit, got %s (%d iterations)", si1.solver, si1.iterations)
T.check(not si0.solver:find("fieldsplit"), "-lugal_iterative 0: direct, got %s", si0.solver)
T.check(safter.solver == "gmres/fieldsplit", "after the gradient Stokes keeps the fieldsplit (the adjoint did not fail), got %s", safter.solver)
local dsu = math.sqrt(lg.integrate(box, lg.dot(su1 - su0, su1 - su0)) / lg.integrate(box, lg.dot(su0, su0)))
local dsp = math.sqrt(lg.integrate(box, (sp1 - sp0)^2) / lg.integrate(box, sp0^2))
T.check(dsu < 1e-8 and dsp < 1e-8, "the fieldsplit's velocity and pressure are the direct solver's (relative L2 %.2e, %.2e)", dsu, dsp)
T.check(math.abs(sJ1 - sJ0) < 1e-9 * math.abs(sJ0) and math.abs(sga1 - sga0) < 1e-7 * math.abs(sga0) and
        math.abs(sgv1 - sgv0) < 1e-7 * math.abs(sgv0), "Stokes J %.12e and gradient %.12e %.12e against %.12e %.12e %.12e",
        sJ1, sga1, sgv1, sJ0, sga0, sgv0)
print(string.format("Stokes (%d unknowns): %s, %d iterations; dJ/damp %.10e (direct %.10e), dJ/dnu %.10e (%.10e)", si1.dofs,
                    si1.solver, si1.iterations, sga1, sga0, sgv1, sgv0))

-- null spaces (the size lowered by -lugal_iterative_min): a pure Neumann problem and a free
-- elastic body get CG with GAMG, an enclosed flow (nullspace = p) the fieldsplit; solutions,
-- J and the gradients (the adjoint's right side projected, problem_solve.c,
-- null_project) against the direct solver
local kk = lg.parameter("kk", 1.5)
local nbox = lg.mesh.box{nx = 12}
local function null_cases()
  local g = lg.cos(pi*x)*lg.cos(pi*y)
  local pn = lg.linear_problem{mesh = nbox, test = v, unknown = u, nullspace = u,
    eqn = lg.integral(nbox:cells(), (kk + x)*lg.dot(lg.grad(v), lg.grad(u)) - g*v)}
  local un, ni = pn:solve()
  local rn = lg.reduced_functional{problem = pn, control = kk, functional = lg.functional(lg.integral(nbox:cells(), (u - y)^2))}
  local W, Wt = lg.unknown(lg.vector(P1), "W"), lg.test(lg.vector(P1), "Wt")
  local function eps(a) return lg.sym(lg.grad(a)) end
  local pe = lg.linear_problem{mesh = nbox, test = Wt, unknown = W, nullspace = "rigid",
    eqn = lg.integral(nbox:cells(), (kk + y)*(2*lg.inner(eps(W), eps(Wt)) + lg.div(W)*lg.div(Wt)) -
                      lg.dot(Wt, {lg.cos(2*pi*x)*lg.cos(pi*y), lg.cos(pi*x)*lg.cos(2*pi*y), lg.cos(pi*z)*lg.cos(pi*x)}))}
  local ue, ei = pe:solve()
  local re = lg.reduced_functional{problem = pe, control = kk, functional = lg.functional(lg.integral(nbox:cells(), lg.dot(W, W)*(1 + x)))}
  local pc = lg.linear_problem{mesh = box, test = {sv, sq}, unknown = {su, sp}, nullspace = sp,
    eqn = lg.integral(box:cells(), (kk + x)*lg.inner(lg.grad(su), lg.grad(sv)) - sp*lg.div(sv) - sq*lg.div(su)),
    bc = lg.essential_bc(box:boundary(), lg.dot(sv, su - {16*x*(1 - x)*y*(1 - y)*z*z, 0, 0}))}
  local uc, pcv, ci = pc:solve()
  local rc = lg.reduced_functional{problem = pc, control = kk, functional = lg.functional(lg.integral(box:cells(), lg.dot(su, su) + sp*x))}
  return {un, ue, uc, pcv}, {ni.solver, ei.solver, ci.solver}, {rn:value(), re:value(), rc:value()}, {rn:gradient(), re:gradient(), rc:gradient()}
end
lg.options("-lugal_iterative 1 -lugal_iterative_min 2000")
local s1, k1, j1, g1 = null_cases()
lg.options("-lugal_iterative 0")
local s0, k0, j0, g0 = null_cases()
lg.options("-lugal_iterative 1 -lugal_iterative_min 20000")
T.check(k1[1] == "cg/gamg" and k1[2] == "cg/gamg" and k1[3] == "gmres/fieldsplit",
        "null spaces: CG with GAMG, CG with GAMG, the fieldsplit, got %s, %s, %s", k1[1], k1[2], k1[3])
T.check(not k0[1]:find("gamg") and not k0[3]:find("fieldsplit"), "-lugal_iterative 0: direct, got %s, %s", k0[1], k0[3])
for i, what in ipairs{"Neumann", "rigid", "cavity velocity", "cavity pressure"} do
  local mesh_i = i <= 2 and nbox or box
  local diff = s1[i] - s0[i]
  local scalar = i == 1 or i == 4
  local d2 = scalar and diff^2 or lg.dot(diff, diff)
  local n2 = scalar and s0[i]^2 or lg.dot(s0[i], s0[i])
  local rel = math.sqrt(lg.integrate(mesh_i, d2) / lg.integrate(mesh_i, n2))
  T.check(rel < 1e-8, "%s: the iterative solution is the direct solver's (relative L2 %.2e)", what, rel)
end
for i, what in ipairs{"Neumann", "rigid", "cavity"} do
  T.close(j1[i], j0[i], 1e-9, what .. ": J against the direct solver's")
  T.close(g1[i], g0[i], 1e-7, what .. ": dJ/dk against the direct solver's")
end
print(string.format("null spaces: %s, %s, %s; dJ/dk %.10e %.10e %.10e (direct %.10e %.10e %.10e)",
                    k1[1], k1[2], k1[3], g1[1], g1[2], g1[3], g0[1], g0[2], g0[3]))
